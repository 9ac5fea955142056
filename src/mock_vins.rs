//! The mock VINS: a sequence's poses published as nav_msgs/Odometry over Zenoh on the VINS
//! key, as the real VINS would (body frame = camera frame). The sequence loops on the wall
//! clock: at UNIX time t it is at sequence time `first + t mod period`, so a mock camera
//! replaying the same sequence on the same clock sees the same poses without talking to it.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::{Result, anyhow, bail};
use nalgebra::Isometry3;

use crate::config::ZenohConfig;
use crate::pose::{PoseBuffer, RawPose};
use crate::ros;
use crate::sequence::Sequence;
use crate::types::StampNs;

#[derive(Clone, Copy, Debug)]
pub struct MockVinsOptions {
    /// Poses per second.
    pub rate_hz: f64,
    /// Vertical drift added to the published poses, mm per second.
    pub drift_mm_per_s: f64,
    /// Stop after this long (None: run until stopped).
    pub duration: Option<Duration>,
}

/// Nanoseconds since the UNIX epoch: the clock the mock camera and the mock VINS share.
pub fn now_ns() -> StampNs {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos() as StampNs)
}

/// The looped sequence's clock: which sequence time a wall-clock time shows.
pub struct SequenceClock {
    first_ns: StampNs,
    period_ns: StampNs,
}

impl SequenceClock {
    pub fn new(seq: &Sequence) -> Result<SequenceClock> {
        let (Some(first), Some(last)) = (seq.poses.first(), seq.poses.last()) else {
            bail!("{} has no frames", seq.dir.display());
        };
        // One frame interval after the last frame, the loop starts again.
        let step = if seq.len() > 1 { (last.stamp_ns - first.stamp_ns) / (seq.len() as u64 - 1) } else { 33_333_333 };
        Ok(SequenceClock { first_ns: first.stamp_ns, period_ns: last.stamp_ns - first.stamp_ns + step.max(1) })
    }

    /// The sequence stamp shown at wall time `t_ns`.
    pub fn sequence_time(&self, t_ns: StampNs) -> StampNs {
        self.first_ns + t_ns % self.period_ns
    }

    /// The first frame shown after wall time `t_ns`: its wall time and index, given the
    /// sequence's frame stamps (ascending, the first at the loop's start).
    pub fn next_frame(&self, t_ns: StampNs, stamps: &[StampNs]) -> (StampNs, usize) {
        let tau = self.sequence_time(t_ns);
        let loop_start = t_ns - (tau - self.first_ns);
        match stamps.iter().position(|&s| s > tau) {
            Some(k) => (loop_start + (stamps[k] - self.first_ns), k),
            None => (loop_start + self.period_ns, 0),
        }
    }
}

/// Publishes until `opts.duration` is over; returns how many poses went out.
pub async fn run(seq: &Sequence, zenoh_cfg: &ZenohConfig, opts: MockVinsOptions) -> Result<u64> {
    if !(opts.rate_hz > 0.0 && opts.rate_hz <= 10_000.0) {
        bail!("--rate {} must be within (0, 10000] Hz", opts.rate_hz);
    }
    if !opts.drift_mm_per_s.is_finite() {
        bail!("--drift {} must be finite", opts.drift_mm_per_s);
    }
    let clock = SequenceClock::new(seq)?;
    let mut poses = PoseBuffer::new(seq.len(), u64::MAX);
    for p in &seq.poses {
        poses.push(&RawPose::from(p)).map_err(|e| anyhow!("{}: {e}", seq.dir.display()))?;
    }
    let last_ns = seq.poses.last().map_or(0, |p| p.stamp_ns);

    let session = crate::bus::open_session(zenoh_cfg).await?;
    let publisher = session
        .declare_publisher(zenoh_cfg.pose_key.clone())
        .await
        .map_err(|e| anyhow!("declaring the publisher on {}: {e}", zenoh_cfg.pose_key))?;
    tracing::info!("mock VINS: {} looped on {} at {} Hz", seq.dir.display(), zenoh_cfg.pose_key, opts.rate_hz);
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
        let bytes = ros::encode(&ros::odometry(&raw, "world", "camera"));
        publisher.put(bytes).await.map_err(|e| anyhow!("publishing a pose: {e}"))?;
        sent += 1;
    }
    Ok(sent)
}
