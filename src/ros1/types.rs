//! ROS 1 message and service types: their names, MD5 sums and definitions, as genmsg
//! computes them from the .msg and .srv files.
//!
//! The structs are ROS 2's ([`crate::ros2::msg`]): ROS 1 lays the same fields out without
//! alignment (the codec's ROS 1 flavour, [`crate::ros2::cdr::to_ros1_vec`]). The few types
//! whose fields differ between the two (Marker, GridMap) convert on the way ([`super::msg`]).
//! The definitions are polymap_msgs' own files and, for the others, their Noetic .msg files
//! without comments (`definitions/`; grid_map's from ANYbotics/grid_map master, the
//! terrain's from leggedrobotics/elevation_mapping_cupy's plane_segmentation): a peer checks the MD5 sum at connection,
//! so a sum that differs from genmsg's means no connection (tests/ros1.rs compares them).

use std::collections::BTreeMap;
use std::sync::OnceLock;

use md5::{Digest, Md5};

use crate::ros2::cdr::{self, CdrError};

/// A type that travels on ROS 1.
pub trait Ros1Message: Sized + Send + Sync + 'static {
    /// `pkg/Name`, as ROS 1 spells it.
    const TYPE: &'static str;
    /// Largest message taken from a peer, bytes.
    const MAX_BYTES: usize = cdr::MAX_MESSAGE_BYTES;
    fn to_ros1(&self) -> Vec<u8>;
    fn from_ros1(bytes: &[u8]) -> Result<Self, CdrError>;
}

/// A ROS 1 service type (`pkg/Name`; its request and response are `pkg/NameRequest`, ...).
pub trait Ros1Service: Send + Sync + 'static {
    const TYPE: &'static str;
    type Request: Ros1Message;
    type Response: Ros1Message;
}

/// Gives ROS 2 structs whose fields ROS 1 lays out the same their ROS 1 names.
macro_rules! same_layout {
    ($($t:ty => $name:literal),* $(,)?) => {$(
        impl Ros1Message for $t {
            const TYPE: &'static str = $name;
            fn to_ros1(&self) -> Vec<u8> {
                cdr::to_ros1_vec(self)
            }
            fn from_ros1(bytes: &[u8]) -> Result<Self, CdrError> {
                cdr::from_ros1_slice(bytes)
            }
        }
    )*};
}

mod same {
    use super::*;
    use crate::ros2::msg::*;
    same_layout!(
        Odometry => "nav_msgs/Odometry",
        PoseStamped => "geometry_msgs/PoseStamped",
        TfMessage => "tf2_msgs/TFMessage",
        Imu => "sensor_msgs/Imu",
        CameraInfo => "sensor_msgs/CameraInfo",
        FramePolygons => "polymap_msgs/FramePolygons",
        MapUpdate => "polymap_msgs/MapUpdate",
        Map => "polymap_msgs/Map",
        Status => "polymap_msgs/Status",
        GetMapRequest => "polymap_msgs/GetMapRequest",
        GetMapResponse => "polymap_msgs/GetMapResponse",
        GetFootholdRequest => "polymap_msgs/GetFootholdRequest",
        GetFootholdResponse => "polymap_msgs/GetFootholdResponse",
    );

    /// Images are the one message polymap takes that can pass the decoder's 1 MiB.
    impl Ros1Message for Image {
        const TYPE: &'static str = "sensor_msgs/Image";
        /// A 16-bit 1920 x 1080 image, with room for its header.
        const MAX_BYTES: usize = 1920 * 1080 * 2 + 4096;
        fn to_ros1(&self) -> Vec<u8> {
            cdr::to_ros1_vec(self)
        }
        fn from_ros1(bytes: &[u8]) -> Result<Self, CdrError> {
            cdr::from_ros1_slice_unlimited(bytes)
        }
    }

    impl Ros1Service for GetMap {
        const TYPE: &'static str = "polymap_msgs/GetMap";
        type Request = GetMapRequest;
        type Response = GetMapResponse;
    }

    impl Ros1Service for GetFoothold {
        const TYPE: &'static str = "polymap_msgs/GetFoothold";
        type Request = GetFootholdRequest;
        type Response = GetFootholdResponse;
    }
}

/// A message or service definition, as its file has it.
struct Definition {
    /// `pkg/Name`
    name: String,
    text: String,
}

/// Every definition polymap knows, by `pkg/Name`: messages, and services' requests and
/// responses (`pkg/NameRequest`, `pkg/NameResponse`).
fn definitions() -> &'static BTreeMap<String, Definition> {
    static ALL: OnceLock<BTreeMap<String, Definition>> = OnceLock::new();
    ALL.get_or_init(|| {
        let mut all = BTreeMap::new();
        let mut add = |name: &str, text: &str| {
            all.insert(name.to_string(), Definition { name: name.to_string(), text: text.to_string() });
        };
        macro_rules! standard {
            ($($pkg:literal / $name:literal),* $(,)?) => {$(
                add(concat!($pkg, "/", $name), include_str!(concat!("definitions/", $pkg, "/", $name, ".msg")));
            )*};
        }
        standard!(
            "std_msgs" / "Header",
            "std_msgs" / "ColorRGBA",
            "std_msgs" / "Float32MultiArray",
            "std_msgs" / "MultiArrayLayout",
            "std_msgs" / "MultiArrayDimension",
            "geometry_msgs" / "Point",
            "geometry_msgs" / "Vector3",
            "geometry_msgs" / "Quaternion",
            "geometry_msgs" / "Pose",
            "geometry_msgs" / "PoseStamped",
            "geometry_msgs" / "PoseWithCovariance",
            "geometry_msgs" / "Twist",
            "geometry_msgs" / "TwistWithCovariance",
            "geometry_msgs" / "Transform",
            "geometry_msgs" / "TransformStamped",
            "nav_msgs" / "Odometry",
            "sensor_msgs" / "Image",
            "sensor_msgs" / "CameraInfo",
            "sensor_msgs" / "RegionOfInterest",
            "sensor_msgs" / "Imu",
            "visualization_msgs" / "Marker",
            "visualization_msgs" / "MarkerArray",
            "tf2_msgs" / "TFMessage",
            "grid_map_msgs" / "GridMap",
            "grid_map_msgs" / "GridMapInfo",
            "convex_plane_decomposition_msgs" / "PlanarTerrain",
            "convex_plane_decomposition_msgs" / "PlanarRegion",
            "convex_plane_decomposition_msgs" / "BoundingBox2d",
            "convex_plane_decomposition_msgs" / "Point2d",
            "convex_plane_decomposition_msgs" / "Polygon2d",
            "convex_plane_decomposition_msgs" / "PolygonWithHoles2d",
        );
        macro_rules! polymap {
            ($($name:literal),* $(,)?) => {$(
                add(concat!("polymap_msgs/", $name), include_str!(concat!("../../polymap_msgs/msg/", $name, ".msg")));
            )*};
        }
        polymap!("Ring", "Region", "Polygon", "FramePolygons", "MapUpdate", "Map", "Foothold", "Status");
        macro_rules! polymap_services {
            ($($name:literal),* $(,)?) => {$(
                let text = include_str!(concat!("../../polymap_msgs/srv/", $name, ".srv"));
                let (request, response) = split_service(text);
                add(concat!("polymap_msgs/", $name, "Request"), request);
                add(concat!("polymap_msgs/", $name, "Response"), response);
            )*};
        }
        polymap_services!("GetMap", "GetFoothold");
        all
    })
}

/// A .srv's request and response: the lines before and after its `---`.
fn split_service(text: &str) -> (&str, &str) {
    let mut at = 0;
    for line in text.split_inclusive('\n') {
        if line.trim() == "---" {
            return (&text[..at], &text[at + line.len()..]);
        }
        at += line.len();
    }
    (text, "")
}

/// One line of a definition, comments gone.
enum Line<'a> {
    Constant { ty: &'a str, name: &'a str, value: &'a str },
    Field { ty: &'a str, name: &'a str },
}

fn lines(text: &str) -> impl Iterator<Item = Line<'_>> {
    text.lines().filter_map(|raw| {
        let (ty, rest) = raw.trim_start().split_once(char::is_whitespace)?;
        if ty.starts_with('#') {
            return None;
        }
        // A string constant's value runs to the end of the line, '#' included (genmsg).
        if ty == "string"
            && let Some((name, value)) = rest.split_once('=')
        {
            return Some(Line::Constant { ty, name: name.trim(), value: value.trim() });
        }
        let rest = rest.split('#').next().unwrap_or("").trim();
        match rest.split_once('=') {
            Some((name, value)) => Some(Line::Constant { ty, name: name.trim(), value: value.trim() }),
            None if !rest.is_empty() => Some(Line::Field { ty, name: rest.split_whitespace().next()? }),
            None => None,
        }
    })
}

const BUILTIN: &[&str] = &[
    "bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "float32",
    "float64", "string", "time", "duration",
];

/// A field's type without its array suffix, and the `pkg/Name` it refers to when nested.
fn nested_name(ty: &str, package: &str) -> Option<String> {
    let bare = ty.split('[').next().unwrap_or(ty);
    if BUILTIN.contains(&bare) {
        None
    } else if bare == "Header" {
        Some("std_msgs/Header".to_string())
    } else if bare.contains('/') {
        Some(bare.to_string())
    } else {
        Some(format!("{package}/{bare}"))
    }
}

/// Why a type has no ROS 1 definition here.
#[derive(Debug, thiserror::Error)]
#[error("no ROS 1 definition of {0}")]
pub struct Unknown(pub String);

fn definition(name: &str) -> Result<&'static Definition, Unknown> {
    definitions().get(name).ok_or_else(|| Unknown(name.to_string()))
}

fn package(name: &str) -> &str {
    name.split('/').next().unwrap_or("")
}

/// genmsg's MD5 text: constants, then fields, a nested type's field as its MD5 and name.
fn md5_text(d: &Definition) -> Result<String, Unknown> {
    let mut constants = String::new();
    let mut fields = String::new();
    for line in lines(&d.text) {
        match line {
            Line::Constant { ty, name, value } => constants += &format!("{ty} {name}={value}\n"),
            Line::Field { ty, name } => match nested_name(ty, package(&d.name)) {
                Some(nested) => fields += &format!("{} {name}\n", md5_of(&nested)?),
                None => fields += &format!("{ty} {name}\n"),
            },
        }
    }
    Ok((constants + &fields).trim().to_string())
}

fn hex_md5(text: &str) -> String {
    Md5::digest(text.as_bytes()).iter().map(|b| format!("{b:02x}")).collect()
}

/// The MD5 sum of a message type, as genmsg computes it.
pub fn md5_of(name: &str) -> Result<String, Unknown> {
    Ok(hex_md5(&md5_text(definition(name)?)?))
}

/// The MD5 sum of a service type: of its request's MD5 text and its response's.
pub fn service_md5_of(name: &str) -> Result<String, Unknown> {
    let request = md5_text(definition(&format!("{name}Request"))?)?;
    let response = md5_text(definition(&format!("{name}Response"))?)?;
    Ok(hex_md5(&(request + &response)))
}

/// The full definition a publisher sends (rosbag keeps it): the type's text, then each
/// type it refers to once, after a line of 80 '=' and `MSG: pkg/Name`.
pub fn full_definition_of(name: &str) -> Result<String, Unknown> {
    let top = definition(name)?;
    let mut out = top.text.trim_end().to_string();
    let mut seen = std::collections::BTreeSet::new();
    let mut todo = vec![top];
    while let Some(d) = todo.pop() {
        let mut nested: Vec<&Definition> = Vec::new();
        for line in lines(&d.text) {
            if let Line::Field { ty, .. } = line
                && let Some(n) = nested_name(ty, package(&d.name))
                && seen.insert(n.clone())
            {
                let def = definition(&n)?;
                out += &format!("\n{}\nMSG: {n}\n{}", "=".repeat(80), def.text.trim_end());
                nested.push(def);
            }
        }
        todo.extend(nested.into_iter().rev());
    }
    Ok(out + "\n")
}

/// Every type with a definition here, by `pkg/Name`.
pub fn known_types() -> impl Iterator<Item = &'static str> {
    definitions().keys().map(String::as_str)
}

/// A type's MD5 and full definition, computed once: what a connection header carries.
#[derive(Clone, Debug)]
pub struct TypeInfo {
    pub name: &'static str,
    pub md5: String,
    pub definition: String,
}

impl TypeInfo {
    pub fn of<T: Ros1Message>() -> TypeInfo {
        TypeInfo {
            name: T::TYPE,
            md5: md5_of(T::TYPE).expect("every Ros1Message has a definition (tests/ros1.rs)"),
            definition: full_definition_of(T::TYPE).expect("every Ros1Message has a definition"),
        }
    }

    pub fn of_service<S: Ros1Service>() -> TypeInfo {
        TypeInfo {
            name: S::TYPE,
            md5: service_md5_of(S::TYPE).expect("every Ros1Service has a definition (tests/ros1.rs)"),
            definition: String::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sums rospy's generated classes carry (`_md5sum`), for types whose definitions nest.
    #[test]
    fn md5_sums_of_nested_types_are_genmsgs() {
        assert_eq!(md5_of("nav_msgs/Odometry").unwrap(), "cd5e73d190d741a2f92e81eda573aca7");
        assert_eq!(md5_of("visualization_msgs/MarkerArray").unwrap(), "d155b9ce5188fbaf89745847fd5882d7");
        assert_eq!(md5_of("std_msgs/Header").unwrap(), "2176decaecbce78abc3b96ef049fabed");
    }

    #[test]
    fn full_definition_lists_each_nested_type_once() {
        let d = full_definition_of("nav_msgs/Odometry").unwrap();
        assert!(d.starts_with("Header header\n"), "{d}");
        for nested in ["std_msgs/Header", "geometry_msgs/PoseWithCovariance", "geometry_msgs/Point"] {
            assert_eq!(d.matches(&format!("MSG: {nested}\n")).count(), 1, "{nested} in\n{d}");
        }
    }

    #[test]
    fn service_definitions_split_at_the_dashes() {
        let (req, resp) = split_service("geometry_msgs/Point point\n---\nFoothold foothold\n");
        assert_eq!((req, resp), ("geometry_msgs/Point point\n", "Foothold foothold\n"));
    }
}
