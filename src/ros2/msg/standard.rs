//! The ROS 2 common interfaces polymap sends or receives, laid out as their .msg files define
//! them (Jazzy; Humble's are the same for these). Their type hashes are checked against the
//! published ones in tests/ros2.rs.

use serde_big_array::BigArray;

use crate::ros_message;

ros_message! {
    /// builtin_interfaces/Time
    #[derive(Copy, Default)]
    pub struct Time = "builtin_interfaces/msg/Time" {
        pub sec: i32,
        pub nanosec: u32,
    }

    /// builtin_interfaces/Duration
    #[derive(Copy, Default)]
    pub struct Duration = "builtin_interfaces/msg/Duration" {
        pub sec: i32,
        pub nanosec: u32,
    }

    /// std_msgs/Header
    #[derive(Default)]
    pub struct Header = "std_msgs/msg/Header" {
        pub stamp: Time,
        pub frame_id: String,
    }

    /// std_msgs/ColorRGBA
    #[derive(Copy, Default)]
    pub struct ColorRgba = "std_msgs/msg/ColorRGBA" {
        pub r: f32,
        pub g: f32,
        pub b: f32,
        pub a: f32,
    }

    /// std_msgs/String
    #[derive(Default)]
    pub struct StringMsg = "std_msgs/msg/String" {
        pub data: String,
    }

    /// geometry_msgs/Point
    #[derive(Copy, Default)]
    pub struct Point = "geometry_msgs/msg/Point" {
        pub x: f64,
        pub y: f64,
        pub z: f64,
    }

    /// geometry_msgs/Vector3
    #[derive(Copy, Default)]
    pub struct Vector3 = "geometry_msgs/msg/Vector3" {
        pub x: f64,
        pub y: f64,
        pub z: f64,
    }

    /// geometry_msgs/Quaternion
    #[derive(Copy)]
    pub struct Quaternion = "geometry_msgs/msg/Quaternion" {
        pub x: f64,
        pub y: f64,
        pub z: f64,
        pub w: f64,
    }

    /// geometry_msgs/Pose
    #[derive(Copy, Default)]
    pub struct Pose = "geometry_msgs/msg/Pose" {
        pub position: Point,
        pub orientation: Quaternion,
    }

    /// geometry_msgs/PoseStamped
    #[derive(Default)]
    pub struct PoseStamped = "geometry_msgs/msg/PoseStamped" {
        pub header: Header,
        pub pose: Pose,
    }

    /// geometry_msgs/PoseWithCovariance
    pub struct PoseWithCovariance = "geometry_msgs/msg/PoseWithCovariance" {
        pub pose: Pose,
        #[serde(with = "BigArray")]
        pub covariance: [f64; 36],
    }

    /// geometry_msgs/Twist
    #[derive(Copy, Default)]
    pub struct Twist = "geometry_msgs/msg/Twist" {
        pub linear: Vector3,
        pub angular: Vector3,
    }

    /// geometry_msgs/TwistWithCovariance
    pub struct TwistWithCovariance = "geometry_msgs/msg/TwistWithCovariance" {
        pub twist: Twist,
        #[serde(with = "BigArray")]
        pub covariance: [f64; 36],
    }

    /// geometry_msgs/Transform
    #[derive(Copy, Default)]
    pub struct Transform = "geometry_msgs/msg/Transform" {
        pub translation: Vector3,
        pub rotation: Quaternion,
    }

    /// geometry_msgs/TransformStamped
    #[derive(Default)]
    pub struct TransformStamped = "geometry_msgs/msg/TransformStamped" {
        pub header: Header,
        pub child_frame_id: String,
        pub transform: Transform,
    }

    /// nav_msgs/Odometry, as VINS-Fusion publishes its odometry.
    pub struct Odometry = "nav_msgs/msg/Odometry" {
        pub header: Header,
        pub child_frame_id: String,
        pub pose: PoseWithCovariance,
        pub twist: TwistWithCovariance,
    }

    /// sensor_msgs/Image
    #[derive(Default)]
    pub struct Image = "sensor_msgs/msg/Image" {
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

    /// sensor_msgs/CompressedImage
    #[derive(Default)]
    pub struct CompressedImage = "sensor_msgs/msg/CompressedImage" {
        pub header: Header,
        pub format: String,
        pub data: Vec<u8>,
    }

    /// sensor_msgs/RegionOfInterest
    #[derive(Copy, Default)]
    pub struct RegionOfInterest = "sensor_msgs/msg/RegionOfInterest" {
        pub x_offset: u32,
        pub y_offset: u32,
        pub height: u32,
        pub width: u32,
        pub do_rectify: bool,
    }

    /// sensor_msgs/CameraInfo
    #[derive(Default)]
    pub struct CameraInfo = "sensor_msgs/msg/CameraInfo" {
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
    pub struct Imu = "sensor_msgs/msg/Imu" {
        pub header: Header,
        pub orientation: Quaternion,
        pub orientation_covariance: [f64; 9],
        pub angular_velocity: Vector3,
        pub angular_velocity_covariance: [f64; 9],
        pub linear_acceleration: Vector3,
        pub linear_acceleration_covariance: [f64; 9],
    }

    /// visualization_msgs/UVCoordinate
    #[derive(Copy, Default)]
    pub struct UvCoordinate = "visualization_msgs/msg/UVCoordinate" {
        pub u: f32,
        pub v: f32,
    }

    /// visualization_msgs/MeshFile
    #[derive(Default)]
    pub struct MeshFile = "visualization_msgs/msg/MeshFile" {
        pub filename: String,
        pub data: Vec<u8>,
    }

    /// visualization_msgs/Marker
    pub struct Marker = "visualization_msgs/msg/Marker" {
        pub header: Header,
        pub ns: String,
        pub id: i32,
        pub r#type: i32,
        pub action: i32,
        pub pose: Pose,
        pub scale: Vector3,
        pub color: ColorRgba,
        pub lifetime: Duration,
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
    #[derive(Default)]
    pub struct MarkerArray = "visualization_msgs/msg/MarkerArray" {
        pub markers: Vec<Marker>,
    }

    /// tf2_msgs/TFMessage
    #[derive(Default)]
    pub struct TfMessage = "tf2_msgs/msg/TFMessage" {
        pub transforms: Vec<TransformStamped>,
    }

    /// service_msgs/ServiceEventInfo: part of every service type's description (and hash).
    #[derive(Copy, Default)]
    pub struct ServiceEventInfo = "service_msgs/msg/ServiceEventInfo" {
        pub event_type: u8,
        pub stamp: Time,
        /// `char[16]` in the .msg, which ROS 2 maps to uint8.
        pub client_gid: [u8; 16],
        pub sequence_number: i64,
    }
}

impl Default for Quaternion {
    /// The identity rotation, as the .msg's defaults have it.
    fn default() -> Self {
        Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }
    }
}

impl Time {
    pub fn from_ns(ns: crate::types::StampNs) -> Time {
        Time { sec: (ns / 1_000_000_000).min(i32::MAX as u64) as i32, nanosec: (ns % 1_000_000_000) as u32 }
    }

    /// Nanoseconds, or None for a stamp before 1970 or a nanosecond field out of range.
    pub fn to_ns(self) -> Option<crate::types::StampNs> {
        (self.sec >= 0 && self.nanosec < 1_000_000_000).then(|| self.sec as u64 * 1_000_000_000 + self.nanosec as u64)
    }
}

impl From<[f64; 3]> for Point {
    fn from([x, y, z]: [f64; 3]) -> Point {
        Point { x, y, z }
    }
}

impl From<[f64; 3]> for Vector3 {
    fn from([x, y, z]: [f64; 3]) -> Vector3 {
        Vector3 { x, y, z }
    }
}

impl Default for PoseWithCovariance {
    fn default() -> Self {
        PoseWithCovariance { pose: Pose::default(), covariance: [0.0; 36] }
    }
}

impl Default for TwistWithCovariance {
    fn default() -> Self {
        TwistWithCovariance { twist: Twist::default(), covariance: [0.0; 36] }
    }
}
