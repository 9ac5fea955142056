//! Robot teams' own logs as polymap's input: ROS 1 bags ([`bag`]) and ROS 2 bags in MCAP
//! ([`mcap`]), replayed as live frames are mapped: each depth image with the newest
//! camera_info before it, its pose interpolated from the odometry at the image's stamp,
//! through the same decoders and checks as live. Both are streamed, so memory does not
//! grow with the log.

pub mod bag;
pub mod mcap;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use nalgebra::Isometry3;
use serde::Deserialize;

use crate::config::Config;
use crate::extract::{Extraction, Extractor};
use crate::interface::convert;
use crate::map::PolygonMap;
use crate::pose::{PoseBuffer, PoseLimits, RawPose};
use crate::ros1::Ros1Message;
use crate::ros2::cdr;
use crate::ros2::msg::{CameraInfo, Image, Odometry, PoseStamped};
use crate::types::Pose;
use bag::BagReader;
use mcap::McapReader;

/// How a log's messages are serialized.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Encoding {
    /// ROS 1's (rosbag; an MCAP channel with `ros1` encoding).
    Ros1,
    /// ROS 2's CDR, with its 4-byte encapsulation header.
    Cdr,
    Other(String),
}

/// A connection (ROS 1) or channel (MCAP): the topic and type messages on it have.
#[derive(Clone, Debug)]
pub struct Connection {
    pub topic: String,
    /// As the log names it: `sensor_msgs/Image` (ROS 1) or `sensor_msgs/msg/Image` (ROS 2).
    pub message_type: String,
    pub encoding: Encoding,
}

/// A message: its connection, its receive time and its serialized bytes.
#[derive(Debug)]
pub struct Message {
    pub connection: Arc<Connection>,
    pub time_ns: u64,
    pub data: Vec<u8>,
}

/// The kinds of log polymap reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LogKind {
    /// A ROS 1 bag (format 2.0): `FILE.bag`.
    Ros1Bag,
    /// A ROS 2 bag in MCAP: `FILE.mcap`, or a rosbag2 directory of them.
    Mcap,
}

/// A log on disk: its kind and its files (a rosbag2 directory may be split into several).
#[derive(Clone, Debug)]
pub struct Log {
    pub path: PathBuf,
    pub kind: LogKind,
    pub files: Vec<PathBuf>,
}

impl Log {
    /// The log at `path`; None where `path` is not one (a polymap sequence directory).
    pub fn find(path: &Path) -> Result<Option<Log>> {
        let log = |kind, files| Ok(Some(Log { path: path.to_owned(), kind, files }));
        match path.extension().and_then(|e| e.to_str()) {
            Some("bag") => return log(LogKind::Ros1Bag, vec![path.to_owned()]),
            Some("mcap") => return log(LogKind::Mcap, vec![path.to_owned()]),
            _ => {}
        }
        if !path.join("metadata.yaml").is_file() {
            return Ok(None);
        }
        // A rosbag2 directory: its files are NAME_0.mcap, NAME_1.mcap, ... in order.
        let mut files: Vec<PathBuf> = std::fs::read_dir(path)
            .with_context(|| format!("reading {}", path.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
            .collect();
        files.sort_by_key(|p| (p.as_os_str().len(), p.clone()));
        if files.is_empty() {
            bail!(
                "{}: a rosbag2 directory without .mcap files (polymap reads MCAP storage; `ros2 bag convert` makes it from sqlite3)",
                path.display()
            );
        }
        log(LogKind::Mcap, files)
    }

    /// Its messages, streamed from the start.
    pub fn messages(&self) -> Result<Messages> {
        Ok(match self.kind {
            LogKind::Ros1Bag => Messages::Bag(BagReader::open(&self.files[0])?),
            LogKind::Mcap => Messages::Mcap(Box::new(McapReader::open(&self.files)?)),
        })
    }
}

/// A log's messages, one at a time.
pub enum Messages {
    Bag(BagReader),
    Mcap(Box<McapReader>),
}

impl Messages {
    pub fn next_message(&mut self) -> Result<Option<Message>> {
        Ok(match self {
            Messages::Bag(r) => r.next_message()?,
            Messages::Mcap(r) => r.next_message()?,
        })
    }
}

/// The topics a log's frames and poses are on.
#[derive(Clone, Debug)]
pub struct LogTopics {
    pub depth: String,
    pub camera_info: String,
    pub odometry: String,
}

impl LogTopics {
    /// The names a robot's logs of that kind use: realsense-ros's (ROS 1, the L515 named
    /// `l515` as the paper's authors launch it; ROS 2, its default `camera` namespace and
    /// name) and VINS-Fusion's odometry (ROS 1) or `/odometry` (ROS 2).
    pub fn defaults(kind: LogKind) -> LogTopics {
        match kind {
            LogKind::Ros1Bag => LogTopics {
                depth: "/l515/depth/image_rect_raw".into(),
                camera_info: "/l515/depth/camera_info".into(),
                odometry: "/vins_estimator/odometry".into(),
            },
            LogKind::Mcap => LogTopics {
                depth: "/camera/camera/depth/image_rect_raw".into(),
                camera_info: "/camera/camera/depth/camera_info".into(),
                odometry: "/odometry".into(),
            },
        }
    }
}

/// One topic of a log.
#[derive(Clone, Debug, Default)]
pub struct TopicStats {
    pub message_type: String,
    pub count: u64,
    pub first_ns: u64,
    pub last_ns: u64,
}

/// A log read once: what each topic holds, and the odometry's poses.
pub struct Scan {
    pub topics: BTreeMap<String, TopicStats>,
    pub poses: Vec<RawPose>,
    pub poses_refused: u64,
}

impl Scan {
    pub fn count(&self, topic: &str) -> u64 {
        self.topics.get(topic).map_or(0, |t| t.count)
    }

    /// "topic (type): count, ..." for an error that says what the log has instead.
    pub fn listing(&self) -> String {
        if self.topics.is_empty() {
            return "no messages".into();
        }
        let held: Vec<String> =
            self.topics.iter().map(|(t, s)| format!("{t} ({}): {}", s.message_type, s.count)).collect();
        held.join(", ")
    }
}

/// Reads the whole log once: each topic's count and span, and the poses on `odometry`.
pub fn scan(log: &Log, odometry: &str) -> Result<Scan> {
    let mut out = Scan { topics: BTreeMap::new(), poses: Vec::new(), poses_refused: 0 };
    let mut messages = log.messages()?;
    while let Some(m) = messages.next_message()? {
        let t = out.topics.entry(m.connection.topic.clone()).or_insert_with(|| TopicStats {
            message_type: m.connection.message_type.clone(),
            first_ns: m.time_ns,
            ..TopicStats::default()
        });
        t.count += 1;
        t.last_ns = m.time_ns;
        if m.connection.topic == odometry {
            match pose_of(&m) {
                Ok(p) => out.poses.push(p),
                Err(why) => {
                    out.poses_refused += 1;
                    if out.poses_refused <= 10 {
                        tracing::warn!("{}: a pose on {odometry} refused: {why}", log.path.display());
                    }
                }
            }
        }
    }
    Ok(out)
}

/// Whether a log's type name is `ros1_type` (`pkg/Name`), as ROS 1 or ROS 2 (`pkg/msg/Name`) spells it.
fn is_type(log_type: &str, ros1_type: &str) -> bool {
    log_type == ros1_type
        || ros1_type.split_once('/').is_some_and(|(pkg, name)| log_type == format!("{pkg}/msg/{name}"))
}

/// A message through the same bounded decoders as live input.
fn decode<T: Ros1Message + for<'a> Deserialize<'a>>(m: &Message) -> Result<T, String> {
    if m.data.len() > T::MAX_BYTES {
        return Err(format!("{} bytes, over the {}-byte limit of a {}", m.data.len(), T::MAX_BYTES, T::TYPE));
    }
    match &m.connection.encoding {
        Encoding::Ros1 => T::from_ros1(&m.data),
        Encoding::Cdr => cdr::from_slice_unlimited(&m.data),
        Encoding::Other(e) => return Err(format!("message encoding {e:?} (polymap reads ros1 and cdr)")),
    }
    .map_err(|e| e.to_string())
}

/// A pose from nav_msgs/Odometry or geometry_msgs/PoseStamped, through the live checks.
fn pose_of(m: &Message) -> Result<RawPose, String> {
    let t = &m.connection.message_type;
    if is_type(t, Odometry::TYPE) {
        convert::pose_of_odometry(&decode::<Odometry>(m)?)
    } else if is_type(t, PoseStamped::TYPE) {
        convert::pose_of_pose_stamped(&decode::<PoseStamped>(m)?)
    } else {
        Err(format!("a {t}, where polymap reads nav_msgs/Odometry or geometry_msgs/PoseStamped"))
    }
}

/// What a log's replay did with its depth images.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LogReplay {
    pub images: u64,
    pub mapped: u64,
    /// Images without a pose at their stamp.
    pub without_pose: u64,
    pub without_camera_info: u64,
    /// Images that are not depth or do not fit their camera_info, or that do not decode.
    pub refused: u64,
    /// Why the first refused image was.
    pub first_refusal: Option<String>,
    pub poses: u64,
    pub poses_refused: u64,
}

impl std::fmt::Display for LogReplay {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} depth images: {} mapped, {} without a pose, {} before any camera_info, {} refused; {} poses ({} refused)",
            self.images,
            self.mapped,
            self.without_pose,
            self.without_camera_info,
            self.refused,
            self.poses,
            self.poses_refused
        )?;
        if let Some(why) = &self.first_refusal {
            write!(f, "; the first image refused: {why}")?;
        }
        Ok(())
    }
}

/// Checks that the log has the topics, of the types, a replay needs.
fn check_topics(log: &Log, scan: &Scan, topics: &LogTopics) -> Result<()> {
    let path = log.path.display();
    for (topic, flag, types) in [
        (&topics.depth, "--depth-topic", &[Image::TYPE][..]),
        (&topics.camera_info, "--camera-info-topic", &[CameraInfo::TYPE]),
        (&topics.odometry, "--odometry-topic", &[Odometry::TYPE, PoseStamped::TYPE]),
    ] {
        let Some(t) = scan.topics.get(topic.as_str()) else {
            bail!("{path}: no messages on {topic} ({flag}); the log has {}", scan.listing());
        };
        if !types.iter().any(|want| is_type(&t.message_type, want)) {
            bail!("{path}: {topic} carries {}, where polymap reads {}", t.message_type, types.join(" or "));
        }
    }
    Ok(())
}

/// Maps every depth image of a log into `map`, streaming the log twice (its odometry first,
/// then its images); `on_image(done, of)` is called after each image.
pub fn replay(
    log: &Log,
    topics: &LogTopics,
    config: &Config,
    map: &mut PolygonMap,
    mut on_image: impl FnMut(u64, u64),
) -> Result<LogReplay> {
    let path = log.path.display();
    let scan = scan(log, &topics.odometry)?;
    check_topics(log, &scan, topics)?;
    let mut out = LogReplay { poses_refused: scan.poses_refused, ..LogReplay::default() };
    let limits = PoseLimits { max_ahead_ns: None, ..PoseLimits::from_config(&config.poses) };
    let mut poses = PoseBuffer::with_limits(scan.poses.len().max(1), limits);
    for p in &scan.poses {
        match poses.push(p) {
            Ok(()) => out.poses += 1,
            Err(e) => {
                out.poses_refused += 1;
                tracing::warn!("{path}: a pose refused: {e}");
            }
        }
    }
    let images = scan.count(&topics.depth);
    drop(scan);

    let body_camera: Isometry3<f64> = crate::pose::extrinsic(config);
    let unit_m = Some(config.sources.depth.image_unit_m).filter(|&u| u > 0.0);
    let mut extractor = Extractor::new(&config.pipeline)?;
    let mut info: Option<CameraInfo> = None;
    let mut messages = log.messages()?;
    while let Some(m) = messages.next_message()? {
        if m.connection.topic == topics.camera_info {
            match decode::<CameraInfo>(&m) {
                Ok(i) => info = Some(i),
                Err(e) => tracing::warn!("{path}: a camera_info refused: {e}"),
            }
            continue;
        }
        if m.connection.topic != topics.depth {
            continue;
        }
        out.images += 1;
        let frame = decode::<Image>(&m).and_then(|image| match &info {
            Some(info) => convert::depth_frame(&image, info, unit_m).map(Some),
            None => Ok(None),
        });
        match frame {
            Ok(Some((frame, intrinsics))) => match poses.lookup(frame.stamp_ns) {
                Ok(world_body) => {
                    let Extraction { polygons, depth, .. } = extractor
                        .extract(&frame, &intrinsics)
                        .with_context(|| format!("{path}: the image stamped {} ns", frame.stamp_ns))?;
                    let t_world_camera = crate::pose::world_camera(&world_body, &body_camera);
                    let pose = Pose { stamp_ns: frame.stamp_ns, transform: t_world_camera };
                    map.update(&polygons.polygons, &pose, &intrinsics, Some(&depth));
                    out.mapped += 1;
                }
                Err(_) => out.without_pose += 1,
            },
            Ok(None) => out.without_camera_info += 1,
            Err(why) => {
                out.refused += 1;
                if out.refused <= 10 {
                    tracing::warn!("{path}: a depth image refused: {why}");
                }
                out.first_refusal.get_or_insert(why);
            }
        }
        on_image(out.images, images);
    }
    Ok(out)
}
