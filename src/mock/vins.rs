//! The mock VINS: a sequence's poses published as VINS-Fusion's ROS 2 port publishes its
//! odometry (nav_msgs/Odometry on `/odometry`, or PoseStamped if the config says so), from a
//! ROS 2 node of its own (`/vins_estimator`), body frame = camera frame. The sequence loops
//! on the wall clock ([`super::SequenceClock`]), as the mock camera replays it.

use std::time::Duration;

use anyhow::{Result, anyhow, bail};
use nalgebra::Isometry3;

use super::SequenceClock;
use crate::clock::now_ns;
use crate::config::Config;
use crate::interface::{Interface, OdometryTopic, convert};
use crate::pose::{PoseBuffer, RawPose};
use crate::ros2::{Node, NodeOptions, RosName};
use crate::sequence::Sequence;

#[derive(Clone, Copy, Debug)]
pub struct MockVinsOptions {
    /// Poses per second.
    pub rate_hz: f64,
    /// Vertical drift added to the published poses, mm per second.
    pub drift_mm_per_s: f64,
    /// Stop after this long (None: run until stopped).
    pub duration: Option<Duration>,
}

impl MockVinsOptions {
    /// Why these options cannot run, naming the command-line option.
    pub fn problem(&self) -> Option<String> {
        if !(self.rate_hz >= 0.1 && self.rate_hz <= 10_000.0) {
            return Some(format!("--rate {} must be within 0.1..=10000 Hz", self.rate_hz));
        }
        if !(self.drift_mm_per_s.is_finite() && self.drift_mm_per_s.abs() <= 1e3) {
            return Some(format!("--drift {} must be within -1000..=1000 mm/s", self.drift_mm_per_s));
        }
        None
    }
}

/// The frames VINS-Fusion names its odometry's pose in, and the pose's body.
pub const WORLD_FRAME: &str = "world";
pub const BODY_FRAME: &str = "body";

/// Publishes until `opts.duration` is over; returns how many poses went out.
pub async fn run(seq: &Sequence, config: &Config, opts: MockVinsOptions) -> Result<u64> {
    if let Some(p) = opts.problem() {
        bail!("{p}");
    }
    let clock = SequenceClock::new(seq)?;
    let mut poses = PoseBuffer::new(seq.len(), u64::MAX);
    for p in &seq.poses {
        poses.push(&RawPose::from(p)).map_err(|e| anyhow!("{}: {e}", seq.dir.display()))?;
    }
    let last_ns = seq.poses.last().map_or(0, |p| p.stamp_ns);

    let session = crate::ros2::session::open(crate::ros2::session::config(&config.zenoh.config_file)?).await?;
    let options =
        NodeOptions { namespace: RosName::root(), name: "vins_estimator".into(), ..config.ros2.node_options() };
    let node = Node::new(&session, options).await?;
    let interface = Interface::new(config);
    let publisher = match &interface.odometry {
        OdometryTopic::Odometry(t) => Publish::Odometry(node.publisher(t).await?),
        OdometryTopic::PoseStamped(t) => Publish::PoseStamped(node.publisher(t).await?),
    };
    tracing::info!("mock VINS: {} looped on {} at {} Hz", seq.dir.display(), interface.odometry_name(), opts.rate_hz);
    let started = now_ns();
    let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / opts.rate_hz));
    let mut sent = 0u64;
    loop {
        tick.tick().await;
        let t = now_ns();
        if opts.duration.is_some_and(|d| t.saturating_sub(started) >= d.as_nanos() as u64) {
            break;
        }
        let tau = clock.sequence_time(t).min(last_ns);
        let pose: Isometry3<f64> = poses.at(tau).map_err(|e| anyhow!("sequence pose at {tau}: {e}"))?;
        let drift = opts.drift_mm_per_s * 1e-3 * (t - started) as f64 * 1e-9;
        let mut raw = RawPose::from(&crate::types::Pose { stamp_ns: t, transform: pose });
        raw.position[2] += drift;
        let odometry = convert::odometry(&raw, WORLD_FRAME, BODY_FRAME);
        match &publisher {
            Publish::Odometry(p) => p.put(&odometry).await?,
            Publish::PoseStamped(p) => {
                let stamped = crate::ros2::msg::PoseStamped { header: odometry.header, pose: odometry.pose.pose };
                p.put(&stamped).await?
            }
        }
        sent += 1;
    }
    Ok(sent)
}

enum Publish {
    Odometry(crate::ros2::Publisher<crate::ros2::msg::Odometry>),
    PoseStamped(crate::ros2::Publisher<crate::ros2::msg::PoseStamped>),
}
