//! Robot teams' own logs as polymap's input: ROS 1 bags ([`bag`]), replayed as live frames
//! are mapped: each depth image with the newest camera_info before it, its pose interpolated
//! from the odometry at the image's stamp, through the same decoders and checks as live.

pub mod bag;

use std::path::Path;

use anyhow::{Context, Result, bail};
use nalgebra::Isometry3;

use crate::config::Config;
use crate::extract::Extractor;
use crate::interface::convert;
use crate::map::PolygonMap;
use crate::pose::{PoseBuffer, PoseLimits, RawPose};
use crate::ros1::Ros1Message;
use crate::ros2::msg::{CameraInfo, Image, Odometry};
use bag::BagReader;

/// The topics a log's frames and poses are on.
#[derive(Clone, Debug)]
pub struct LogTopics {
    pub depth: String,
    pub camera_info: String,
    pub odometry: String,
}

impl LogTopics {
    /// realsense-ros's and VINS-Fusion's ROS 1 names, as the paper authors' setup records them.
    pub fn ros1() -> LogTopics {
        LogTopics {
            depth: "/l515/depth/image_rect_raw".into(),
            camera_info: "/l515/depth/camera_info".into(),
            odometry: "/vins_estimator/odometry".into(),
        }
    }
}

/// What a log's replay did with its depth images.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LogReplay {
    pub images: u64,
    pub mapped: u64,
    /// Images before any camera_info, or without a pose at their stamp.
    pub without_pose: u64,
    pub without_camera_info: u64,
    /// Images that are not depth or do not fit their camera_info, or that do not decode.
    pub refused: u64,
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
        )
    }
}

/// How many messages each topic of a bag has: to say what a bag without the asked topics holds.
fn topics_of(path: &Path) -> Result<std::collections::BTreeMap<String, u64>> {
    let mut reader = BagReader::open(path)?;
    let mut topics = std::collections::BTreeMap::new();
    while let Some(m) = reader.next_message()? {
        *topics.entry(format!("{} ({})", m.connection.topic, m.connection.message_type)).or_insert(0) += 1;
    }
    Ok(topics)
}

/// Maps every depth image of a ROS 1 bag into `map`, streaming the bag twice (its odometry
/// first, then its images); `on_image(done, of)` is called after each image.
pub fn replay_bag(
    path: &Path,
    topics: &LogTopics,
    config: &Config,
    map: &mut PolygonMap,
    mut on_image: impl FnMut(u64, u64),
) -> Result<LogReplay> {
    let mut out = LogReplay::default();
    let mut raw: Vec<RawPose> = Vec::new();
    let mut reader = BagReader::open(path)?;
    let mut images = 0u64;
    while let Some(m) = reader.next_message()? {
        if m.connection.topic == topics.odometry {
            match Odometry::from_ros1(&m.data).map_err(|e| e.to_string()).and_then(|o| convert::pose_of_odometry(&o)) {
                Ok(p) => raw.push(p),
                Err(why) => {
                    out.poses_refused += 1;
                    tracing::warn!("{}: a pose on {} refused: {why}", path.display(), topics.odometry);
                }
            }
        } else if m.connection.topic == topics.depth {
            images += 1;
        }
    }
    if images == 0 {
        let held: Vec<String> = topics_of(path)?.into_iter().map(|(t, n)| format!("{t}: {n}")).collect();
        bail!(
            "{}: no messages on {} (--depth-topic); the bag has {}",
            path.display(),
            topics.depth,
            if held.is_empty() { "no messages".to_string() } else { held.join(", ") }
        );
    }
    let limits = PoseLimits { max_ahead_ns: None, ..PoseLimits::from_config(&config.poses) };
    let mut poses = PoseBuffer::with_limits(raw.len().max(1), limits);
    for p in &raw {
        match poses.push(p) {
            Ok(()) => out.poses += 1,
            Err(e) => {
                out.poses_refused += 1;
                tracing::warn!("{}: a pose refused: {e}", path.display());
            }
        }
    }
    drop(raw);

    let body_camera: Isometry3<f64> = crate::runtime::worker::extrinsic(config);
    let unit_m = Some(config.sources.depth.image_unit_m).filter(|&u| u > 0.0);
    let mut extractor = Extractor::new(&config.pipeline)?;
    let mut info: Option<CameraInfo> = None;
    let mut reader = BagReader::open(path)?;
    while let Some(m) = reader.next_message()? {
        if m.connection.topic == topics.camera_info {
            match CameraInfo::from_ros1(&m.data) {
                Ok(i) => info = Some(i),
                Err(e) => tracing::warn!("{}: a camera_info refused: {e}", path.display()),
            }
            continue;
        }
        if m.connection.topic != topics.depth {
            continue;
        }
        out.images += 1;
        let frame = Image::from_ros1(&m.data).map_err(|e| e.to_string()).and_then(|image| match &info {
            Some(info) => convert::depth_frame(&image, info, unit_m).map(Some),
            None => Ok(None),
        });
        match frame {
            Ok(Some((frame, intrinsics))) => match poses.lookup(frame.stamp_ns) {
                Ok(world_body) => {
                    let (polygons, stages, _) = extractor
                        .extract(&frame, &intrinsics)
                        .with_context(|| format!("{}: the image stamped {} ns", path.display(), frame.stamp_ns))?;
                    map.update(&polygons.polygons, &(world_body * body_camera), &intrinsics, Some(&stages.depth));
                    out.mapped += 1;
                }
                Err(_) => out.without_pose += 1,
            },
            Ok(None) => out.without_camera_info += 1,
            Err(why) => {
                out.refused += 1;
                if out.refused <= 10 {
                    tracing::warn!("{}: a depth image refused: {why}", path.display());
                }
            }
        }
        on_image(out.images, images);
    }
    Ok(out)
}
