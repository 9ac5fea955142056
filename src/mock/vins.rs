//! The mock VINS: a sequence's poses published as VINS-Fusion publishes its odometry
//! (nav_msgs/Odometry, or PoseStamped if the config says so), from a node of its own
//! (`/vins_estimator`), body frame = camera frame: on ROS 1 as the original does
//! (`/vins_estimator/odometry`) when the config's `[ros1]` is enabled, else on ROS 2 as its
//! ROS 2 port does (`/odometry`). The sequence loops
//! on the wall clock ([`super::SequenceClock`]), as the mock camera replays it.
//!
//! Timed as VINS-Fusion on a robot's CPU: a pose per processed image at 10-20 Hz, each
//! published 30-80 ms after the image it belongs to. Pose k is stamped `k / rate` plus a
//! jitter, and published `latency` plus a jitter after its stamp, in order. Beside it, as
//! VINS-Fusion's `imu_propagate`, the pose at every IMU sample, published at once; the
//! mock's propagation is exact (the sequence's own trajectory).

use std::time::Duration;

use anyhow::{Result, anyhow, bail};
use nalgebra::Isometry3;

use super::SequenceClock;
use crate::clock::now_ns;
use crate::config::Config;
use crate::interface::wires::Wires;
use crate::interface::{OdometryTopic, convert};
use crate::pose::{PoseBuffer, RawPose};
use crate::ros2::{Node, NodeOptions, RosName};
use crate::sequence::Sequence;
use crate::types::StampNs;

#[derive(Clone, Copy, Debug)]
pub struct MockVinsOptions {
    /// Poses per second.
    pub rate_hz: f64,
    /// How long after its stamp a pose is published, ms.
    pub latency_ms: f64,
    /// Each stamp and each delay is off its nominal value by up to this, uniformly, ms.
    pub jitter_ms: f64,
    /// IMU-rate propagated poses per second (VINS-Fusion's `imu_propagate`), published on
    /// `ros2.imu_propagate` a moment after their stamps; 0: none.
    pub propagate_hz: f64,
    /// Vertical drift added to the published poses, mm per second.
    pub drift_mm_per_s: f64,
    /// Horizontal drift, mm per second in x and y, and yaw drift about the world's origin,
    /// degrees per second, as a visual-inertial odometry drifts.
    pub drift_xy_mm_per_s: [f64; 2],
    pub drift_yaw_deg_per_s: f64,
    /// Stop after this long (None: run until stopped).
    pub duration: Option<Duration>,
}

impl MockVinsOptions {
    /// The propagated stream's timing: at `propagate_hz`, a moment after each IMU sample.
    pub fn propagated(&self) -> Option<MockVinsOptions> {
        (self.propagate_hz > 0.0).then_some(MockVinsOptions {
            rate_hz: self.propagate_hz,
            latency_ms: PROPAGATE_LATENCY_MS,
            jitter_ms: 0.0,
            ..*self
        })
    }

    /// VINS-Fusion on a robot's CPU: about 15 Hz, 50 ms late, 10 ms of jitter.
    pub const ROBOT: MockVinsOptions = MockVinsOptions {
        rate_hz: 15.0,
        latency_ms: 50.0,
        jitter_ms: 10.0,
        propagate_hz: 200.0,
        drift_mm_per_s: 0.0,
        drift_xy_mm_per_s: [0.0; 2],
        drift_yaw_deg_per_s: 0.0,
        duration: None,
    };

    /// Why these options cannot run, naming the command-line option.
    pub fn problem(&self) -> Option<String> {
        if !(self.rate_hz >= 0.1 && self.rate_hz <= 10_000.0) {
            return Some(format!("--rate {} must be within 0.1..=10000 Hz", self.rate_hz));
        }
        if !(self.latency_ms >= 0.0 && self.latency_ms <= 10_000.0) {
            return Some(format!("--latency-ms {} must be within 0..=10000 ms", self.latency_ms));
        }
        if !(self.propagate_hz == 0.0 || (self.propagate_hz >= 1.0 && self.propagate_hz <= 1000.0)) {
            return Some(format!("--propagate-hz {} must be 0 (none) or within 1..=1000 Hz", self.propagate_hz));
        }
        if !(self.jitter_ms >= 0.0 && self.jitter_ms <= 1000.0) {
            return Some(format!("--jitter-ms {} must be within 0..=1000 ms", self.jitter_ms));
        }
        if !(self.drift_mm_per_s.is_finite() && self.drift_mm_per_s.abs() <= 1e3) {
            return Some(format!("--drift {} must be within -1000..=1000 mm/s", self.drift_mm_per_s));
        }
        if !self.drift_xy_mm_per_s.iter().all(|v| v.is_finite() && v.abs() <= 1e3) {
            return Some(format!("--drift-xy {:?} must be within -1000..=1000 mm/s", self.drift_xy_mm_per_s));
        }
        if !(self.drift_yaw_deg_per_s.is_finite() && self.drift_yaw_deg_per_s.abs() <= 10.0) {
            return Some(format!("--drift-yaw {} must be within -10..=10 deg/s", self.drift_yaw_deg_per_s));
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

    let wires = match config.ros1.enabled {
        true => Wires { ros2: None, ros1: Some(Wires::ros1(config, "/vins_estimator").await?) },
        false => {
            let session = crate::ros2::session::open(crate::ros2::session::config(&config.zenoh.config_file)?).await?;
            let options =
                NodeOptions { namespace: RosName::root(), name: "vins_estimator".into(), ..config.ros2.node_options() };
            let node = std::sync::Arc::new(Node::new(&session, options).await?);
            Wires { ros2: Some(Wires::ros2(config, node)), ros1: None }
        }
    };
    let names = wires.names().ok_or_else(|| anyhow!("the mock VINS has no ROS layer"))?;
    let odometry = wires.publisher(|i| match &i.odometry {
        OdometryTopic::Odometry(t) => Some(t),
        OdometryTopic::PoseStamped(_) => None,
    });
    let pose_stamped = wires.publisher(|i| match &i.odometry {
        OdometryTopic::PoseStamped(t) => Some(t),
        OdometryTopic::Odometry(_) => None,
    });
    let (odometry, pose_stamped) = (odometry.await?, pose_stamped.await?);
    tracing::info!(
        "mock VINS: {} looped on {} at {} Hz, {} ms late (jitter {} ms)",
        seq.dir.display(),
        names.odometry_name(),
        opts.rate_hz,
        opts.latency_ms,
        opts.jitter_ms
    );
    let started = now_ns();
    // The sequence's pose at a wall-clock stamp, drifted as asked.
    let pose_at = |stamp: StampNs| -> Result<RawPose> {
        let tau = clock.sequence_time(stamp).min(last_ns);
        let pose: Isometry3<f64> = poses.lookup(tau).map_err(|e| anyhow!("sequence pose at {tau}: {e}"))?;
        let t = stamp.saturating_sub(started) as f64 * 1e-9;
        let [x, y] = opts.drift_xy_mm_per_s.map(|v| v * 1e-3 * t);
        let drift = nalgebra::Translation3::new(x, y, opts.drift_mm_per_s * 1e-3 * t)
            * nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, (opts.drift_yaw_deg_per_s * t).to_radians());
        Ok(RawPose::from(&crate::types::Pose { stamp_ns: stamp, transform: drift * pose }))
    };
    let (odometry, pose_stamped, pose_at) = (&odometry, &pose_stamped, &pose_at);
    let optimised = publish_timed(PoseTiming::new(&opts, started), started, opts.duration, |stamp| async move {
        let msg = convert::odometry(&pose_at(stamp)?, WORLD_FRAME, BODY_FRAME);
        if pose_stamped.wanted() {
            pose_stamped
                .put(&crate::ros2::msg::PoseStamped { header: msg.header.clone(), pose: msg.pose.pose })
                .await?;
        }
        odometry.put(&msg).await?;
        Ok(())
    });
    let propagated = async {
        let (true, Some(timing)) = (names.imu_propagate.is_some(), opts.propagated()) else { return Ok(0) };
        let publisher = wires.publisher(|i| i.imu_propagate.as_ref()).await?;
        publish_timed(PoseTiming::new(&timing, started), started, opts.duration, |stamp| {
            let publisher = &publisher;
            async move { Ok(publisher.put(&convert::odometry(&pose_at(stamp)?, WORLD_FRAME, BODY_FRAME)).await?) }
        })
        .await
    };
    let (sent, _) = tokio::try_join!(optimised, propagated)?;
    Ok(sent)
}

/// How long after its IMU sample a propagated pose is published, ms.
const PROPAGATE_LATENCY_MS: f64 = 2.0;

/// Calls `publish(stamp)` at each of `timing`'s publishing times until `duration` after
/// `started`; returns how many went out.
async fn publish_timed<F: std::future::Future<Output = Result<()>>>(
    mut timing: PoseTiming,
    started: StampNs,
    duration: Option<Duration>,
    publish: impl Fn(StampNs) -> F,
) -> Result<u64> {
    let mut sent = 0u64;
    loop {
        let (stamp, publish_at) = timing.next_pose();
        if duration.is_some_and(|d| publish_at.saturating_sub(started) >= d.as_nanos() as u64) {
            return Ok(sent);
        }
        tokio::time::sleep(Duration::from_nanos(publish_at.saturating_sub(now_ns()))).await;
        publish(stamp).await?;
        sent += 1;
    }
}

/// When each pose is stamped and published (wall clock, ns): stamps `k / rate` after the
/// start plus a jitter (always after the stamp before), each published `latency` plus a
/// jitter after its stamp, never before the one before it. Seeded, so a run's timing can
/// be repeated.
pub struct PoseTiming {
    start_ns: StampNs,
    period_ns: f64,
    latency_ns: f64,
    jitter_ns: f64,
    k: u64,
    last_stamp_ns: StampNs,
    last_publish_ns: StampNs,
    rng: rand_chacha::ChaCha8Rng,
}

impl PoseTiming {
    pub fn new(opts: &MockVinsOptions, start_ns: StampNs) -> PoseTiming {
        use rand::SeedableRng;
        PoseTiming {
            // The first stamp one jitter after the start, so no stamp precedes the start.
            start_ns: start_ns + (opts.jitter_ms * 1e6) as StampNs,
            period_ns: 1e9 / opts.rate_hz,
            latency_ns: opts.latency_ms * 1e6,
            jitter_ns: opts.jitter_ms * 1e6,
            k: 0,
            last_stamp_ns: 0,
            last_publish_ns: 0,
            rng: rand_chacha::ChaCha8Rng::seed_from_u64(15),
        }
    }

    /// The next pose's stamp and publishing time.
    pub fn next_pose(&mut self) -> (StampNs, StampNs) {
        use rand::RngExt;
        let j = self.jitter_ns;
        let mut jitter = || if j > 0.0 { self.rng.random_range(-j..j) } else { 0.0 };
        let stamp = (self.start_ns + (self.k as f64 * self.period_ns + jitter()).max(0.0) as StampNs)
            .max(self.last_stamp_ns + 1_000);
        let publish = (stamp + (self.latency_ns + jitter()).max(0.0) as StampNs).max(self.last_publish_ns);
        self.k += 1;
        self.last_stamp_ns = stamp;
        self.last_publish_ns = publish;
        (stamp, publish)
    }
}
