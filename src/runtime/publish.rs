//! Publishing what the extractor thread made, and the status, on polymap's topics.

use crate::interface::{Interface, convert};
use crate::ros2::msg::{FramePolygons, MapUpdate, MarkerArray, Status};
use crate::ros2::{Node, Publisher, Ros2Error};

use super::status::Report;
use super::worker::FrameEvent;

/// The frame polymap's polygons and map are in.
pub use super::services::MAP_FRAME;

pub struct Publishers {
    frame_polygons: Publisher<FramePolygons>,
    map_updates: Publisher<MapUpdate>,
    markers: Publisher<MarkerArray>,
    status: Publisher<Status>,
}

impl Publishers {
    pub async fn new(node: &Node, interface: &Interface) -> Result<Publishers, Ros2Error> {
        Ok(Publishers {
            frame_polygons: node.publisher(&interface.frame_polygons).await?,
            map_updates: node.publisher(&interface.map_updates).await?,
            markers: node.publisher(&interface.markers).await?,
            status: node.publisher(&interface.status).await?,
        })
    }

    /// A frame's polygons, the map update it made, and the markers of what changed.
    pub async fn frame(&self, e: &FrameEvent) -> Result<(), Ros2Error> {
        self.frame_polygons.put(&convert::frame_polygons(e.stamp_ns, MAP_FRAME, &e.polygons)).await?;
        let delta = convert::MapDelta {
            stamp_ns: e.stamp_ns,
            added: &e.added,
            changed: &e.changed,
            removed: &e.removed,
            drift_z: e.drift_z,
            drift_var: e.drift_var,
        };
        let update = convert::map_update(&delta, MAP_FRAME);
        self.map_updates.put(&update).await?;
        self.markers.put(&convert::update_markers(&update)).await
    }

    pub async fn status(&self, report: &Report) -> Result<(), Ros2Error> {
        self.status.put(&convert::status(report, crate::clock::now_ns(), MAP_FRAME)).await
    }
}
