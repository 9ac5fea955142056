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

/// Largest message accepted, bytes: a bound on what garbage can make the decoder allocate.
pub const MAX_MESSAGE_BYTES: u64 = 1 << 20;

/// CDR bytes of a message.
pub fn encode<T: Serialize>(msg: &T) -> Vec<u8> {
    cdr::serialize::<_, _, cdr::CdrLe>(msg, cdr::Infinite).expect("plain message types always serialise")
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
