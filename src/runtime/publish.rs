//! Publishing what the extractor thread made, the whole map, the terrain and the status on
//! polymap's topics. Every frame: its polygons, its map update (versioned), the drift on /tf.
//! When the map changed, at most every period: the whole map and its markers (transient
//! local: a late subscriber gets the latest at once), and the planar terrain around the robot.

use parking_lot::Mutex;

use super::status::Report;
use super::worker::FrameEvent;
use crate::config::{Config, PlanarTerrainConfig};
use crate::interface::{Interface, convert, terrain};
use crate::map::PolygonMap;
use crate::map::elevation::GridSpec;
use crate::ros2::msg::{FramePolygons, Map, MapUpdate, MarkerArray, PlanarTerrain, Status, TfMessage};
use crate::ros2::{Node, Publisher, Ros2Error};

pub struct Publishers {
    frame_polygons: Publisher<FramePolygons>,
    map_updates: Publisher<MapUpdate>,
    map: Publisher<Map>,
    markers: Publisher<MarkerArray>,
    tf: Publisher<TfMessage>,
    planar_terrain: Option<Publisher<PlanarTerrain>>,
    status: Publisher<Status>,
    /// This run of the mapper (its start, ns): versions count within it.
    epoch: u64,
    map_frame: String,
    odometry_frame: String,
    terrain: PlanarTerrainConfig,
    /// The map version last sent whole; the (version, grid centre) of the last terrain.
    whole_map_sent: Option<u64>,
    terrain_sent: Option<(u64, [f64; 2])>,
}

impl Publishers {
    pub async fn new(node: &Node, interface: &Interface, config: &Config, epoch: u64) -> Result<Publishers, Ros2Error> {
        Ok(Publishers {
            frame_polygons: node.publisher(&interface.frame_polygons).await?,
            map_updates: node.publisher(&interface.map_updates).await?,
            map: node.publisher(&interface.map).await?,
            markers: node.publisher(&interface.markers).await?,
            tf: node.publisher(&interface.tf).await?,
            planar_terrain: match config.planar_terrain.enabled {
                true => Some(node.publisher(&interface.planar_terrain).await?),
                false => None,
            },
            status: node.publisher(&interface.status).await?,
            epoch,
            map_frame: config.ros2.map_frame.clone(),
            odometry_frame: config.ros2.odometry_frame.clone(),
            terrain: config.planar_terrain.clone(),
            whole_map_sent: None,
            terrain_sent: None,
        })
    }

    /// A frame's polygons, the map update it made, and the drift it left.
    pub async fn frame(&self, e: &FrameEvent) -> Result<(), Ros2Error> {
        self.frame_polygons.put(&convert::frame_polygons(e.stamp_ns, &self.map_frame, &e.polygons)).await?;
        let delta = convert::MapDelta {
            stamp_ns: e.stamp_ns,
            epoch: self.epoch,
            from_version: e.from_version,
            version: e.version,
            added: &e.added,
            changed: &e.changed,
            removed: &e.removed,
            drift_z: e.drift_z,
            drift_var: e.drift_var,
        };
        self.map_updates.put(&convert::map_update(&delta, &self.map_frame)).await?;
        self.tf.put(&convert::drift_transform(e.stamp_ns, &self.map_frame, &self.odometry_frame, e.drift_z)).await
    }

    /// The whole map and its markers, if the map changed since they last went.
    pub async fn whole_map(&mut self, map: &Mutex<PolygonMap>) -> Result<(), Ros2Error> {
        if self.whole_map_sent == Some(map.lock().version()) {
            return Ok(());
        }
        let snapshot = map.lock().snapshot();
        let whole = convert::map(&snapshot, crate::clock::now_ns(), self.epoch, &self.map_frame);
        self.map.put(&whole).await?;
        self.markers.put(&convert::whole_map_markers(&whole)).await?;
        self.whole_map_sent = Some(snapshot.version);
        Ok(())
    }

    /// The planar terrain around `robot` (map frame), if the map changed or the grid moved.
    pub async fn terrain(&mut self, map: &Mutex<PolygonMap>, robot: [f64; 3]) -> Result<(), Ros2Error> {
        let Some(publisher) = &self.planar_terrain else { return Ok(()) };
        let t = &self.terrain;
        let centre = GridSpec::around([robot[0], robot[1]], t.resolution_m, [t.length_x_m, t.length_y_m]).centre;
        if self.terrain_sent == Some((map.lock().version(), centre)) {
            return Ok(());
        }
        let snapshot = map.lock().snapshot();
        let now = crate::clock::now_ns();
        publisher.put(&terrain::planar_terrain(&snapshot, centre, t, now, &self.map_frame)).await?;
        self.terrain_sent = Some((snapshot.version, centre));
        Ok(())
    }

    pub async fn status(&self, report: &Report) -> Result<(), Ros2Error> {
        self.status.put(&report.message(crate::clock::now_ns(), &self.map_frame)).await
    }
}
