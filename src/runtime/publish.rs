//! Publishing what the extractor thread made, the whole map, the terrain and the status on
//! polymap's topics. Every frame: its polygons, its map update (versioned), the drift on /tf.
//! When the map changed, at most every period: the whole map and its markers (transient
//! local: a late subscriber gets the latest at once), and the planar terrain around the robot.
//! Each goes out on ROS 2 and, when enabled, ROS 1 ([`Wires`]); ROS 1 also gets each frame's
//! treads as the vendor's stair planner reads the paper authors' topic ([`drop_in`]).

use parking_lot::Mutex;

use super::status::Report;
use super::worker::FrameEvent;
use crate::config::{Config, DropInConfig, PlanarTerrainConfig};
use crate::interface::drop_in;
use crate::interface::wires::{Out, WireError, Wires};
use crate::interface::{convert, terrain};
use crate::map::PolygonMap;
use crate::map::elevation::GridSpec;
use crate::ros2::msg::{FramePolygons, Map, MapUpdate, MarkerArray, PlanarTerrain, Status, TfMessage};

pub struct Publishers {
    frame_polygons: Out<FramePolygons>,
    map_updates: Out<MapUpdate>,
    map: Out<Map>,
    markers: Out<MarkerArray>,
    tf: Out<TfMessage>,
    planar_terrain: Option<Out<PlanarTerrain>>,
    status: Out<Status>,
    /// ROS 1's `/polygon_new_markers`, and what goes on it.
    polygon_markers: Out<MarkerArray>,
    drop_in: DropInConfig,
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
    pub async fn new(wires: &Wires, config: &Config, epoch: u64) -> Result<Publishers, WireError> {
        Ok(Publishers {
            frame_polygons: wires.publisher(|i| Some(&i.frame_polygons)).await?,
            map_updates: wires.publisher(|i| Some(&i.map_updates)).await?,
            map: wires.publisher(|i| Some(&i.map)).await?,
            markers: wires.publisher(|i| Some(&i.markers)).await?,
            tf: wires.publisher(|i| Some(&i.tf)).await?,
            planar_terrain: match config.planar_terrain.enabled {
                true => Some(wires.publisher(|i| Some(&i.planar_terrain)).await?),
                false => None,
            },
            status: wires.publisher(|i| Some(&i.status)).await?,
            polygon_markers: wires.publisher(|i| i.polygon_markers.as_ref()).await?,
            drop_in: config.ros1.drop_in.clone(),
            epoch,
            map_frame: config.ros2.map_frame.clone(),
            odometry_frame: config.ros2.odometry_frame.clone(),
            terrain: config.planar_terrain.clone(),
            whole_map_sent: None,
            terrain_sent: None,
        })
    }

    /// A frame's polygons, the map update it made, and the drift it left.
    pub async fn frame(&self, e: &FrameEvent) -> Result<(), WireError> {
        if self.polygon_markers.wanted() {
            let markers = drop_in::polygon_new_markers(e.stamp_ns, &e.polygons, &e.labels, e.robot, &self.drop_in);
            self.polygon_markers.put(&markers).await?;
        }
        let polygons = convert::frame_polygons(e.stamp_ns, &self.map_frame, &e.polygons);
        self.frame_polygons.put(&polygons).await?;
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
        self.tf
            .put(&convert::drift_transform(e.stamp_ns, &self.map_frame, &self.odometry_frame, &e.map_from_odometry))
            .await
    }

    /// The whole map and its markers, if the map changed since they last went.
    pub async fn whole_map(&mut self, map: &Mutex<PolygonMap>) -> Result<(), WireError> {
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
    pub async fn terrain(&mut self, map: &Mutex<PolygonMap>, robot: [f64; 3]) -> Result<(), WireError> {
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

    pub async fn status(&self, report: &Report) -> Result<(), WireError> {
        self.status.put(&report.message(crate::clock::now_ns(), &self.map_frame)).await
    }
}
