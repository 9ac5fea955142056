//! ROS 2 messages as CDR bytes (little-endian, with the 4-byte encapsulation header), the
//! way rclcpp, rmw_zenoh and zenoh-bridge-ros2dds carry them. Field order and types follow
//! the .msg definitions exactly: serde's derive writes fields in declaration order.

use serde::{Deserialize, Serialize};
use serde_big_array::BigArray;

use crate::pose::RawPose;
use crate::types::StampNs;

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    pub fn from_ns(ns: StampNs) -> Time {
        Time { sec: (ns / 1_000_000_000) as i32, nanosec: (ns % 1_000_000_000) as u32 }
    }

    /// Nanoseconds, or None for a stamp before 1970 or a nanosecond field out of range.
    pub fn to_ns(self) -> Option<StampNs> {
        (self.sec >= 0 && self.nanosec < 1_000_000_000).then(|| self.sec as u64 * 1_000_000_000 + self.nanosec as u64)
    }
}

/// std_msgs/Header
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

/// geometry_msgs/Point (and Vector3: the same three float64)
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// geometry_msgs/Quaternion
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

/// geometry_msgs/Pose
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseMsg {
    pub position: Point,
    pub orientation: Quaternion,
}

/// geometry_msgs/PoseWithCovariance
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    pub pose: PoseMsg,
    #[serde(with = "BigArray")]
    pub covariance: [f64; 36],
}

/// geometry_msgs/Twist
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    pub linear: Point,
    pub angular: Point,
}

/// geometry_msgs/TwistWithCovariance
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    pub twist: Twist,
    #[serde(with = "BigArray")]
    pub covariance: [f64; 36],
}

/// nav_msgs/Odometry, as VINS-Fusion publishes its odometry.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}

/// geometry_msgs/PoseStamped
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    pub header: Header,
    pub pose: PoseMsg,
}

/// sensor_msgs/Image
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Image {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    /// "mono8" for the IR images.
    pub encoding: String,
    pub is_bigendian: u8,
    /// Bytes per row.
    pub step: u32,
    pub data: Vec<u8>,
}

/// sensor_msgs/RegionOfInterest
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RegionOfInterest {
    pub x_offset: u32,
    pub y_offset: u32,
    pub height: u32,
    pub width: u32,
    pub do_rectify: bool,
}

/// sensor_msgs/CameraInfo
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraInfo {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub distortion_model: String,
    pub d: Vec<f64>,
    pub k: [f64; 9],
    pub r: [f64; 9],
    pub p: [f64; 12],
    pub binning_x: u32,
    pub binning_y: u32,
    pub roi: RegionOfInterest,
}

/// sensor_msgs/Imu
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Imu {
    pub header: Header,
    pub orientation: Quaternion,
    pub orientation_covariance: [f64; 9],
    pub angular_velocity: Point,
    pub angular_velocity_covariance: [f64; 9],
    pub linear_acceleration: Point,
    pub linear_acceleration_covariance: [f64; 9],
}

/// The IR image of infra`index` as realsense-ros publishes it.
pub fn ir_image(stamp_ns: StampNs, index: u8, intr: &crate::types::Intrinsics, pixels: Vec<u8>) -> Image {
    Image {
        header: Header { stamp: Time::from_ns(stamp_ns), frame_id: format!("camera_infra{index}_optical_frame") },
        height: intr.height,
        width: intr.width,
        encoding: "mono8".into(),
        is_bigendian: 0,
        step: intr.width,
        data: pixels,
    }
}

/// The CameraInfo beside it: rectified images, so no distortion and R = I; infra2's
/// projection carries the baseline (P[3] = -fx * baseline), as realsense-ros writes it.
pub fn ir_camera_info(stamp_ns: StampNs, index: u8, intr: &crate::types::Intrinsics, baseline_m: f64) -> CameraInfo {
    let (fx, fy, cx, cy) = (intr.fx, intr.fy, intr.cx, intr.cy);
    let tx = if index == 2 { -fx * baseline_m } else { 0.0 };
    CameraInfo {
        header: Header { stamp: Time::from_ns(stamp_ns), frame_id: format!("camera_infra{index}_optical_frame") },
        height: intr.height,
        width: intr.width,
        distortion_model: "plumb_bob".into(),
        d: vec![0.0; 5],
        k: [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: [fx, 0.0, cx, tx, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        binning_x: 0,
        binning_y: 0,
        roi: RegionOfInterest::default(),
    }
}

/// One united IMU sample as realsense-ros publishes it: no orientation (covariance[0] = -1,
/// the ROS convention), and the configured variances on the rates' diagonals.
pub fn imu(sample: &crate::camera::ImuSample, angular_velocity_cov: f64, linear_accel_cov: f64) -> Imu {
    let v = |a: [f64; 3]| Point { x: a[0], y: a[1], z: a[2] };
    let diagonal = |c: f64| [c, 0.0, 0.0, 0.0, c, 0.0, 0.0, 0.0, c];
    Imu {
        header: Header { stamp: Time::from_ns(sample.stamp_ns), frame_id: "camera_imu_optical_frame".into() },
        orientation: Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 },
        orientation_covariance: [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        angular_velocity: v(sample.gyro),
        angular_velocity_covariance: diagonal(angular_velocity_cov),
        linear_acceleration: v(sample.accel),
        linear_acceleration_covariance: diagonal(linear_accel_cov),
    }
}

/// Largest message accepted, bytes: a bound on what garbage can make the decoder allocate.
pub const MAX_MESSAGE_BYTES: u64 = 1 << 20;

/// CDR bytes of a message.
pub fn encode<T: Serialize>(msg: &T) -> Vec<u8> {
    cdr::serialize::<_, _, cdr::CdrLe>(msg, cdr::Infinite).expect("plain message types always serialise")
}

/// A message in the configured encoding: CDR, or JSON for debugging.
pub fn encode_as<T: Serialize>(msg: &T, encoding: crate::config::Encoding) -> Vec<u8> {
    match encoding {
        crate::config::Encoding::Cdr => encode(msg),
        crate::config::Encoding::Json => serde_json::to_vec(msg).expect("plain message types always serialise"),
    }
}

/// A message from CDR bytes, with a bounded size.
pub fn decode<T: for<'de> Deserialize<'de>>(bytes: &[u8]) -> Result<T, String> {
    cdr::deserialize_from(bytes, cdr::Bounded(MAX_MESSAGE_BYTES)).map_err(|e| e.to_string())
}

/// Which message a pose key carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseType {
    Odometry,
    PoseStamped,
}

impl PoseType {
    /// rmw_zenoh puts the type name in the key (`.../nav_msgs::msg::dds_::Odometry_/...`);
    /// zenoh-bridge-ros2dds does not, and VINS publishes Odometry.
    pub fn of_key(key: &str) -> PoseType {
        if key.contains("PoseStamped") { PoseType::PoseStamped } else { PoseType::Odometry }
    }
}

/// The pose a message on `key` carries (not yet checked: the pose buffer does that).
pub fn decode_pose(key: &str, bytes: &[u8]) -> Result<RawPose, String> {
    let ty = PoseType::of_key(key);
    let (header, pose) = match ty {
        PoseType::Odometry => decode::<Odometry>(bytes).map(|m| (m.header, m.pose.pose)),
        PoseType::PoseStamped => decode::<PoseStamped>(bytes).map(|m| (m.header, m.pose)),
    }
    .map_err(|e| format!("not a {ty:?} in CDR ({} bytes): {e}", bytes.len()))?;
    let stamp_ns = header.stamp.to_ns().ok_or_else(|| format!("stamp {:?} is not a time", header.stamp))?;
    let (p, q) = (pose.position, pose.orientation);
    Ok(RawPose { stamp_ns, position: [p.x, p.y, p.z], quat_xyzw: [q.x, q.y, q.z, q.w] })
}

/// An Odometry message of a pose, as VINS would send it.
pub fn odometry(pose: &RawPose, frame_id: &str, child_frame_id: &str) -> Odometry {
    let [x, y, z] = pose.position;
    let [qx, qy, qz, qw] = pose.quat_xyzw;
    Odometry {
        header: Header { stamp: Time::from_ns(pose.stamp_ns), frame_id: frame_id.into() },
        child_frame_id: child_frame_id.into(),
        pose: PoseWithCovariance {
            pose: PoseMsg { position: Point { x, y, z }, orientation: Quaternion { x: qx, y: qy, z: qz, w: qw } },
            covariance: [0.0; 36],
        },
        twist: TwistWithCovariance { twist: Twist::default(), covariance: [0.0; 36] },
    }
}

// polymap's own messages (msg/*.msg define them for ROS 2 tools).

/// polymap_msgs/Ring
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Ring {
    pub points: Vec<Point>,
}

/// polymap_msgs/Polygon: a planar polygon in the world frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PolygonMsg {
    pub id: u64,
    /// floor, tread, landing, riser, wall, slope; "" for a frame's polygon.
    pub label: String,
    /// Step index, -1 for none.
    pub step: i32,
    pub normal: [f64; 3],
    pub offset: f64,
    pub area: f64,
    pub centroid: Point,
    pub boundary: Vec<Point>,
    pub holes: Vec<Ring>,
    pub convex_pieces: Vec<Ring>,
    pub inset: Vec<Point>,
    pub observations: u32,
}

/// polymap_msgs/FramePolygons: one frame's polygons, as extracted, in the world frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FramePolygonsMsg {
    pub header: Header,
    pub polygons: Vec<PolygonMsg>,
}

/// polymap_msgs/MapUpdate: what one frame changed in the map.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MapUpdateMsg {
    pub header: Header,
    pub added: Vec<PolygonMsg>,
    pub changed: Vec<PolygonMsg>,
    pub removed: Vec<u64>,
    pub drift_z: f64,
    pub drift_var: f64,
}

/// polymap_msgs/Map: the whole map.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MapMsg {
    pub header: Header,
    pub drift_z: f64,
    pub drift_var: f64,
    pub polygons: Vec<PolygonMsg>,
}

/// polymap_msgs/Foothold: the convex piece under a queried point (or the nearest).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FootholdMsg {
    pub header: Header,
    pub found: bool,
    /// The piece contains the point (seen from above) rather than being the nearest.
    pub contains: bool,
    pub polygon_id: u64,
    pub label: String,
    pub normal: [f64; 3],
    pub offset: f64,
    pub piece: Vec<Point>,
    /// Horizontal distance from the point to the piece, m (0 when it contains it).
    pub distance: f64,
}

/// polymap_msgs/Status: once a second.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StatusMsg {
    pub header: Header,
    pub frames_in: u64,
    pub frames_processed: u64,
    pub frames_dropped: u64,
    pub frames_without_pose: u64,
    pub latency_median_ms: f64,
    pub latency_p99_ms: f64,
    pub poses_accepted: u64,
    pub poses_refused: u64,
    pub drift_z: f64,
    pub map_polygons: u32,
}

pub fn point(p: &[f64; 3]) -> Point {
    Point { x: p[0], y: p[1], z: p[2] }
}

fn ring(r: &[[f64; 3]]) -> Ring {
    Ring { points: r.iter().map(point).collect() }
}

impl PolygonMsg {
    pub fn of_map(p: &crate::map::MapPolygon) -> PolygonMsg {
        PolygonMsg {
            id: p.id,
            label: serde_json::to_value(p.label).ok().and_then(|v| v.as_str().map(String::from)).unwrap_or_default(),
            step: p.step.map_or(-1, |s| s as i32),
            normal: p.normal,
            offset: p.offset,
            area: p.area,
            centroid: point(&p.centroid),
            boundary: p.boundary.iter().map(point).collect(),
            holes: p.holes.iter().map(|h| ring(h)).collect(),
            convex_pieces: p.convex_pieces.iter().map(|h| ring(h)).collect(),
            inset: p.inset.iter().map(point).collect(),
            observations: p.observations,
        }
    }

    pub fn of_frame(p: &crate::extract::Polygon) -> PolygonMsg {
        PolygonMsg {
            id: p.id as u64,
            step: -1,
            normal: p.normal,
            offset: p.offset,
            area: p.area,
            centroid: point(&p.centroid()),
            boundary: p.boundary.iter().map(point).collect(),
            holes: p.holes.iter().map(|h| ring(h)).collect(),
            observations: 1,
            ..PolygonMsg::default()
        }
    }
}

// visualization_msgs/MarkerArray (ROS 2 Humble and later), so RViz shows the map.

/// std_msgs/ColorRGBA
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ColorRgba {
    pub r: f32,
    pub g: f32,
    pub b: f32,
    pub a: f32,
}

/// builtin_interfaces/Duration
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DurationMsg {
    pub sec: i32,
    pub nanosec: u32,
}

/// sensor_msgs/CompressedImage
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CompressedImage {
    pub header: Header,
    pub format: String,
    pub data: Vec<u8>,
}

/// visualization_msgs/UVCoordinate
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct UvCoordinate {
    pub u: f32,
    pub v: f32,
}

/// visualization_msgs/MeshFile
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshFile {
    pub filename: String,
    pub data: Vec<u8>,
}

/// visualization_msgs/Marker
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Marker {
    pub header: Header,
    pub ns: String,
    pub id: i32,
    pub r#type: i32,
    pub action: i32,
    pub pose: PoseMsg,
    pub scale: Point,
    pub color: ColorRgba,
    pub lifetime: DurationMsg,
    pub frame_locked: bool,
    pub points: Vec<Point>,
    pub colors: Vec<ColorRgba>,
    pub texture_resource: String,
    pub texture: CompressedImage,
    pub uv_coordinates: Vec<UvCoordinate>,
    pub text: String,
    pub mesh_resource: String,
    pub mesh_file: MeshFile,
    pub mesh_use_embedded_materials: bool,
}

/// visualization_msgs/MarkerArray
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MarkerArray {
    pub markers: Vec<Marker>,
}

pub const MARKER_LINE_STRIP: i32 = 4;
pub const MARKER_ADD: i32 = 0;
pub const MARKER_DELETE: i32 = 2;

impl Marker {
    fn new(header: &Header, id: u64, action: i32) -> Marker {
        Marker {
            header: header.clone(),
            ns: "polymap".into(),
            // RViz ids are int32; map ids count up from 1 and stay far below 2^31.
            id: (id & 0x7fff_ffff) as i32,
            r#type: MARKER_LINE_STRIP,
            action,
            pose: PoseMsg { position: Point::default(), orientation: Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 } },
            scale: Point { x: 0.01, y: 0.0, z: 0.0 },
            color: ColorRgba::default(),
            lifetime: DurationMsg::default(),
            frame_locked: false,
            points: Vec::new(),
            colors: Vec::new(),
            texture_resource: String::new(),
            texture: CompressedImage::default(),
            uv_coordinates: Vec::new(),
            text: String::new(),
            mesh_resource: String::new(),
            mesh_file: MeshFile::default(),
            mesh_use_embedded_materials: false,
        }
    }
}

/// Markers for a map update: each added or changed polygon's outline as a closed line strip
/// coloured by label (the top-down picture's colours), and a delete for each removed one.
pub fn markers(update: &MapUpdateMsg) -> MarkerArray {
    let mut markers: Vec<Marker> = update
        .added
        .iter()
        .chain(&update.changed)
        .map(|p| {
            let mut m = Marker::new(&update.header, p.id, MARKER_ADD);
            let label = serde_json::from_value(serde_json::Value::String(p.label.clone())).ok();
            let [r, g, b] = label
                .map(|l| crate::map::render::label_colour(l, (p.step >= 0).then_some(p.step as u32)).0)
                .unwrap_or([200, 200, 200]);
            m.color = ColorRgba { r: r as f32 / 255.0, g: g as f32 / 255.0, b: b as f32 / 255.0, a: 1.0 };
            m.points = p.boundary.clone();
            m.points.extend(p.boundary.first().copied());
            m
        })
        .collect();
    markers.extend(update.removed.iter().map(|&id| Marker::new(&update.header, id, MARKER_DELETE)));
    MarkerArray { markers }
}
