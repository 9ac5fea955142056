//! polymap_msgs: the messages and services polymap offers, as `polymap_msgs/msg/*.msg` and
//! `polymap_msgs/srv/*.srv` define them for ROS 2 (field for field, in order).

use super::standard::{Header, Point};
use crate::ros_message;
use crate::ros2::types::RosService;

ros_message! {
    /// polymap_msgs/Ring: a closed ring of points (the first is not repeated at the end).
    #[derive(Default)]
    pub struct Ring = "polymap_msgs/msg/Ring" {
        pub points: Vec<Point>,
    }

    /// polymap_msgs/Region: a polygon with holes on a map polygon's plane.
    #[derive(Default)]
    pub struct Region = "polymap_msgs/msg/Region" {
        /// Counter-clockwise seen from above the plane.
        pub boundary: Vec<Point>,
        /// Clockwise.
        pub holes: Vec<Ring>,
    }

    /// polymap_msgs/Polygon: a planar polygon, `normal . p + offset = 0`, in the frame of the
    /// message that carries it.
    #[derive(Default)]
    pub struct Polygon = "polymap_msgs/msg/Polygon" {
        pub id: u64,
        /// One of the `LABEL_*` constants.
        pub label: u8,
        /// Step index, -1 for none.
        pub step: i32,
        pub normal: [f64; 3],
        pub offset: f64,
        /// m^2, holes excluded.
        pub area: f64,
        pub centroid: Point,
        pub boundary: Vec<Point>,
        pub holes: Vec<Ring>,
        /// Convex pieces whose union is the insets.
        pub convex_pieces: Vec<Ring>,
        /// The polygon shrunk by the foot margin: every piece left, with its holes.
        pub insets: Vec<Region>,
        pub observations: u32,
        /// Covariance of (normal x, y, z, offset), row-major; all zero when unknown.
        pub plane_covariance: [f64; 16],
        /// `footing == FOOTING_STEPPABLE`: planners may put a foot on it.
        pub steppable: bool,
        /// One of the `FOOTING_*` constants.
        pub footing: u8,
        /// The most pixels one frame saw it with.
        pub pixels: u32,
    }

    /// polymap_msgs/FramePolygons: one depth frame's polygons, as extracted.
    #[derive(Default)]
    pub struct FramePolygons = "polymap_msgs/msg/FramePolygons" {
        pub header: Header,
        pub polygons: Vec<Polygon>,
    }

    /// polymap_msgs/MapUpdate: what one frame changed in the map.
    #[derive(Default)]
    pub struct MapUpdate = "polymap_msgs/msg/MapUpdate" {
        pub header: Header,
        /// The mapper's run (its start, ns); versions count within it.
        pub epoch: u64,
        /// The map version this update applies to, and the one it makes.
        pub from_version: u64,
        pub version: u64,
        pub added: Vec<Polygon>,
        pub changed: Vec<Polygon>,
        pub removed: Vec<u64>,
        /// Estimated vertical drift of the odometry, m, and its variance, m^2.
        pub drift_z: f64,
        pub drift_var: f64,
    }

    /// polymap_msgs/Map: the whole map.
    #[derive(Default)]
    pub struct Map = "polymap_msgs/msg/Map" {
        pub header: Header,
        pub epoch: u64,
        pub version: u64,
        pub drift_z: f64,
        pub drift_var: f64,
        pub polygons: Vec<Polygon>,
    }

    /// polymap_msgs/Foothold: a convex region where a foot fits around a point, or the nearest.
    #[derive(Default)]
    pub struct Foothold = "polymap_msgs/msg/Foothold" {
        pub header: Header,
        pub found: bool,
        /// The point lies in the inset the piece was grown in, seen from above.
        pub contains: bool,
        pub polygon_id: u64,
        pub label: u8,
        pub normal: [f64; 3],
        pub offset: f64,
        pub piece: Vec<Point>,
        /// Horizontal distance from the point to that inset, m (0 when it lies in it).
        pub distance: f64,
    }

    /// polymap_msgs/Status: the mapper's health, once a second.
    #[derive(Default)]
    pub struct Status = "polymap_msgs/msg/Status" {
        pub header: Header,
        pub frames_in: u64,
        pub frames_processed: u64,
        /// Replaced by a newer frame before they were processed.
        pub frames_dropped: u64,
        /// Skipped: no odometry pose within the gap.
        pub frames_without_pose: u64,
        /// Refused by the extractor (a malformed frame).
        pub frames_not_extracted: u64,
        /// Frame stamp to published, over the last second.
        pub latency_median_ms: f64,
        pub latency_p99_ms: f64,
        pub poses_accepted: u64,
        pub poses_refused: u64,
        /// Times the odometry started over (stamps going back after a silence) and was followed.
        pub odometry_restarts: u64,
        /// Service requests that did not decode.
        pub requests_refused: u64,
        /// Map snapshots that could not be written (each retried the next period).
        pub snapshots_failed: u64,
        pub drift_z: f64,
        pub map_polygons: u32,
    }

    /// polymap_msgs/GetMap's request: nothing (rosidl gives an empty request this one byte).
    #[derive(Copy, Default)]
    pub struct GetMapRequest = "polymap_msgs/srv/GetMap_Request" {
        pub structure_needs_at_least_one_member: u8,
    }

    /// polymap_msgs/GetMap's response.
    #[derive(Default)]
    pub struct GetMapResponse = "polymap_msgs/srv/GetMap_Response" {
        pub map: Map,
    }

    /// polymap_msgs/GetFoothold's request: a point in the map's frame.
    #[derive(Copy, Default)]
    pub struct GetFootholdRequest = "polymap_msgs/srv/GetFoothold_Request" {
        pub point: Point,
    }

    /// polymap_msgs/GetFoothold's response.
    #[derive(Default)]
    pub struct GetFootholdResponse = "polymap_msgs/srv/GetFoothold_Response" {
        pub foothold: Foothold,
    }
}

impl Polygon {
    /// A frame's polygon, not labelled yet.
    pub const LABEL_NONE: u8 = 0;
    pub const LABEL_FLOOR: u8 = 1;
    pub const LABEL_TREAD: u8 = 2;
    pub const LABEL_LANDING: u8 = 3;
    pub const LABEL_RISER: u8 = 4;
    pub const LABEL_WALL: u8 = 5;
    pub const LABEL_SLOPE: u8 = 6;
    /// Its tilt is known to 1 deg at 95 %: a foot may trust it.
    pub const FOOTING_STEPPABLE: u8 = 0;
    /// Its tilt is not (its noise, or the lean of a narrow support).
    pub const FOOTING_TILT_UNKNOWN: u8 = 1;
    /// No frame saw it with enough pixels to tell.
    pub const FOOTING_FEW_PIXELS: u8 = 2;
}

/// polymap_msgs/srv/GetMap: the whole map.
#[derive(Debug)]
pub struct GetMap;

impl RosService for GetMap {
    const TYPE_NAME: &'static str = "polymap_msgs/srv/GetMap";
    const EVENT_TYPE_NAME: &'static str = "polymap_msgs/srv/GetMap_Event";
    type Request = GetMapRequest;
    type Response = GetMapResponse;
}

/// polymap_msgs/srv/GetFoothold: the convex piece under a point.
#[derive(Debug)]
pub struct GetFoothold;

impl RosService for GetFoothold {
    const TYPE_NAME: &'static str = "polymap_msgs/srv/GetFoothold";
    const EVENT_TYPE_NAME: &'static str = "polymap_msgs/srv/GetFoothold_Event";
    type Request = GetFootholdRequest;
    type Response = GetFootholdResponse;
}
