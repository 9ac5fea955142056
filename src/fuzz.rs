//! Entry points for fuzzing what polymap reads from outside: each takes any bytes and must
//! return (never panic, never hang, never allocate far beyond its input). The cargo-fuzz
//! targets in `fuzz/` call them for long runs; `tests/fuzz.rs` runs them on the committed
//! corpus (`fuzz/corpus/<target>/`) and on mutations of it in every test run.

use crate::config::Config;
use crate::interface::convert;
use crate::map::{MapSnapshot, PolygonMap};
use crate::pose::{PoseBuffer, PoseLimits};
use crate::ros1::Ros1Message;
use crate::ros1::tcpros::ConnectionHeader;
use crate::ros1::xmlrpc;
use crate::ros2::cdr;
use crate::ros2::msg::{CameraInfo, GetFootholdRequest, GetMapRequest, Image, Odometry, PoseStamped};

/// A fuzz target: takes any bytes, must never panic.
pub type Target = fn(&[u8]);

/// The targets, by name (the folder names under `fuzz/corpus/`).
pub const TARGETS: [(&str, Target); 10] = [
    ("odometry", odometry),
    ("service_request", service_request),
    ("config", config),
    ("sequence", sequence),
    ("snapshot", snapshot),
    ("tcpros_header", tcpros_header),
    ("ros1_message", ros1_message),
    ("xmlrpc", xmlrpc),
    ("bag", bag),
    ("mcap", mcap),
];

/// A message on the odometry topic, as Odometry and as PoseStamped, into a pose buffer with
/// the live limits.
pub fn odometry(data: &[u8]) {
    let mut buffer = PoseBuffer::with_limits(8, PoseLimits::from_config(&Default::default()));
    if let Ok(m) = cdr::from_slice::<Odometry>(data)
        && let Ok(raw) = convert::pose_of_odometry(&m)
        && buffer.push(&raw).is_ok()
    {
        let _ = buffer.at(raw.stamp_ns);
    }
    if let Ok(m) = cdr::from_slice::<PoseStamped>(data)
        && let Ok(raw) = convert::pose_of_pose_stamped(&m)
    {
        let _ = buffer.push(&raw);
    }
}

/// A service request: GetMap's, and GetFoothold's answered on a small map.
pub fn service_request(data: &[u8]) {
    let _ = cdr::from_slice::<GetMapRequest>(data);
    if let Ok(r) = cdr::from_slice::<GetFootholdRequest>(data) {
        let p = [r.point.x, r.point.y, r.point.z];
        if p.iter().all(|v| v.is_finite()) {
            let map = small_map();
            let _ = convert::foothold(&crate::map::foothold::foothold(&map, p), 0, "world");
        }
    }
}

/// A config file's text.
pub fn config(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = Config::parse(text, std::path::Path::new("fuzz.toml"));
    }
}

/// A sequence directory made of the input: camera.toml, poses.txt and one depth PNG, split
/// at [`SEQUENCE_SEPARATOR`]; opened and its frame read as polymap reads any sequence.
pub fn sequence(data: &[u8]) {
    let mut parts = split(data, SEQUENCE_SEPARATOR);
    let (camera, poses, png) = (parts.next().unwrap_or(&[]), parts.next().unwrap_or(&[]), parts.next().unwrap_or(&[]));
    let Ok(dir) = tempfile::tempdir() else { return };
    let write = |name: &str, bytes: &[u8]| std::fs::write(dir.path().join(name), bytes).is_ok();
    if !(write("camera.toml", camera)
        && write("poses.txt", poses)
        && std::fs::create_dir(dir.path().join("depth")).is_ok())
    {
        return;
    }
    if !write("depth/000000.png", png) {
        return;
    }
    if let Ok(seq) = crate::sequence::Sequence::open(dir.path()) {
        let _ = seq.depth(0);
    }
}

/// Between the parts of a `sequence` input.
pub const SEQUENCE_SEPARATOR: &[u8] = b"\n\xff--polymap--\xff\n";

/// A saved map's JSON, loaded as polymap loads a snapshot at start.
pub fn snapshot(data: &[u8]) {
    if let Ok(s) = serde_json::from_slice::<MapSnapshot>(data) {
        let _ = PolygonMap::from_snapshot(&Default::default(), &s);
    }
}

/// A TCPROS connection header, as a subscriber, publisher or service client sends it.
pub fn tcpros_header(data: &[u8]) {
    if let Ok(header) = ConnectionHeader::decode(data) {
        let _ = header.require("md5sum");
    }
}

/// A ROS 1 message body of each type polymap takes from a peer; a depth image with the
/// camera_info read from the same bytes, as the depth topic turns them into a frame.
pub fn ros1_message(data: &[u8]) {
    let _ = Odometry::from_ros1(data);
    let _ = PoseStamped::from_ros1(data);
    let _ = GetMapRequest::from_ros1(data);
    let _ = GetFootholdRequest::from_ros1(data);
    let info = CameraInfo::from_ros1(data);
    if let Ok(image) = Image::from_ros1(data) {
        let info = info.unwrap_or_else(|_| CameraInfo {
            width: image.width,
            height: image.height,
            k: [300.0, 0.0, image.width as f64 / 2.0, 0.0, 300.0, image.height as f64 / 2.0, 0.0, 0.0, 1.0],
            ..Default::default()
        });
        let _ = convert::depth_frame(&image, &info, None);
    }
}

/// An XML-RPC request or response body, as the master and other nodes send them, and a
/// URI from one.
pub fn xmlrpc(data: &[u8]) {
    let _ = xmlrpc::parse_call(data);
    if let Ok(value) = xmlrpc::parse_response(data)
        && let Some(uri) = value.as_array().and_then(|v| v.get(2)).and_then(|v| v.as_str())
    {
        let _ = xmlrpc::host_port(uri);
    }
}

/// A ROS 1 bag file, scanned as `polymap replay` scans a log first.
pub fn bag(data: &[u8]) {
    log_file(data, "fuzz.bag");
}

/// An MCAP file (a ROS 2 bag), scanned as `polymap replay` scans a log first.
pub fn mcap(data: &[u8]) {
    log_file(data, "fuzz.mcap");
}

fn log_file(data: &[u8], name: &str) {
    let Ok(dir) = tempfile::tempdir() else { return };
    let path = dir.path().join(name);
    if std::fs::write(&path, data).is_err() {
        return;
    }
    if let Ok(Some(log)) = crate::logs::Log::find(&path) {
        let _ = crate::logs::scan(&log, "/odometry");
    }
}

fn split<'a>(data: &'a [u8], sep: &'a [u8]) -> impl Iterator<Item = &'a [u8]> {
    let mut rest = Some(data);
    std::iter::from_fn(move || {
        let r = rest?;
        match r.windows(sep.len()).position(|w| w == sep) {
            Some(i) => {
                rest = Some(&r[i + sep.len()..]);
                Some(&r[..i])
            }
            None => {
                rest = None;
                Some(r)
            }
        }
    })
}

/// Two treads and a floor.
fn small_map() -> MapSnapshot {
    use crate::map::{Label, MapPolygon};
    let square = |x: f64, z: f64, id: u64, label: Label| {
        let ring = vec![[x, -0.5, z], [x + 0.28, -0.5, z], [x + 0.28, 0.5, z], [x, 0.5, z]];
        MapPolygon {
            id,
            label,
            normal: [0.0, 0.0, 1.0],
            offset: -z,
            area: 0.28,
            centroid: [x + 0.14, 0.0, z],
            boundary: ring.clone(),
            holes: vec![],
            convex_pieces: vec![ring.clone()],
            insets: vec![crate::map::Region { boundary: ring, holes: vec![] }],
            observations: 2,
            step: Some(id as u32),
            plane_covariance: [0.0; 16],
            footing: crate::extract::Footing::Steppable,
            pixels: 0,
        }
    };
    MapSnapshot {
        version: 0,
        frame: crate::map::MapFrame::World,
        drift_z: 0.0,
        drift_var: 0.0,
        drift_xy: [0.0; 2],
        drift_yaw: 0.0,
        drift_covariance: None,
        stair: None,
        polygons: vec![
            square(-0.3, 0.0, 0, Label::Floor),
            square(0.0, 0.15, 1, Label::Tread),
            square(0.28, 0.3, 2, Label::Tread),
        ],
    }
}
