//! Time-indexed odometry poses: each depth frame gets the pose at its own stamp, linearly
//! interpolated in position and slerped in rotation between the two poses around it.
//! A frame before the first pose, after the last, in a gap wider than `max_gap`, or across a
//! jump of the odometry gets no pose: it is never mapped with a stale, extrapolated or
//! blended one.
//!
//! Poses come from outside (VINS over Zenoh), so each one is checked on the way in: a bad
//! one is refused with what was wrong, counted, and leaves the buffer as it was. Checked:
//! a finite position within reach of the origin, a unit quaternion, a stamp after the newest
//! and not ahead of the local clock. An odometry that starts over (stamps going back after a
//! silence: VINS restarted) is followed: the buffer starts again from its first pose.

use std::collections::VecDeque;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::Serialize;

use crate::types::{Pose, StampNs};

/// A pose as a message carries it, before any check.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawPose {
    pub stamp_ns: StampNs,
    pub position: [f64; 3],
    pub quat_xyzw: [f64; 4],
}

impl From<&Pose> for RawPose {
    fn from(p: &Pose) -> RawPose {
        let (t, q) = (p.transform.translation, p.transform.rotation);
        RawPose { stamp_ns: p.stamp_ns, position: [t.x, t.y, t.z], quat_xyzw: [q.i, q.j, q.k, q.w] }
    }
}

/// Why a pose was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PoseRejected {
    #[error("pose at {stamp_ns} ns has a non-finite position {position:?}")]
    BadPosition { stamp_ns: StampNs, position: [f64; 3] },
    #[error("pose at {stamp_ns} ns has quaternion {quat_xyzw:?} of norm {norm}, not a rotation")]
    BadQuaternion { stamp_ns: StampNs, quat_xyzw: [f64; 4], norm: f64 },
    #[error("pose stamp {stamp_ns} ns is not after the previous one, {last_ns} ns")]
    StampNotIncreasing { stamp_ns: StampNs, last_ns: StampNs },
    #[error("pose at {stamp_ns} ns is {distance_m:.3e} m from the origin, beyond the {max_m} m the map reaches")]
    OutOfReach { stamp_ns: StampNs, distance_m: f64, max_m: f64 },
    #[error("pose stamp {stamp_ns} ns is {ahead_ms:.1} ms ahead of this machine's clock (at most {max_ms:.1} ms)")]
    FromTheFuture { stamp_ns: StampNs, ahead_ms: f64, max_ms: f64 },
}

/// What a pose from outside may be.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseLimits {
    /// Frames between two poses further apart than this get no pose, ns.
    pub max_gap_ns: u64,
    /// Positions further than this from the origin are refused, m (never above
    /// [`crate::types::MAX_COORDINATE_M`]).
    pub max_radius_m: f64,
    /// Stamps further than this ahead of the local clock are refused, ns; None: not checked
    /// (poses from a recording).
    pub max_ahead_ns: Option<u64>,
    /// After this long without a pose, one stamped before the newest is the odometry
    /// starting over, ns; None: never (it is refused as going back).
    pub restart_after_ns: Option<u64>,
}

impl PoseLimits {
    /// Only the gap, and the world polymap maps: for poses polymap made itself.
    pub fn gap_only(max_gap_ns: u64) -> PoseLimits {
        PoseLimits {
            max_gap_ns,
            max_radius_m: crate::types::MAX_COORDINATE_M,
            max_ahead_ns: None,
            restart_after_ns: None,
        }
    }

    /// As the config says, for odometry from outside.
    pub fn from_config(c: &crate::config::PosesConfig) -> PoseLimits {
        let ns = |s: f64| (s * 1e9) as u64;
        PoseLimits {
            max_gap_ns: ns(c.max_gap_s),
            max_radius_m: c.max_radius_m.min(crate::types::MAX_COORDINATE_M),
            max_ahead_ns: Some(ns(c.max_ahead_s)),
            restart_after_ns: Some(ns(c.restart_after_s)),
        }
    }
}

/// Why a frame has no pose.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum NoPose {
    #[error("no pose received yet")]
    Empty,
    #[error("frame at {stamp_ns} ns is before the oldest pose kept ({first_ns} ns)")]
    TooOld { stamp_ns: StampNs, first_ns: StampNs },
    #[error("frame at {stamp_ns} ns is after the newest pose ({last_ns} ns): not extrapolated")]
    NotYet { stamp_ns: StampNs, last_ns: StampNs },
    #[error("frame at {stamp_ns} ns falls in a {gap_ms:.1} ms gap between poses (at most {max_ms:.1} ms)")]
    Gap { stamp_ns: StampNs, gap_ms: f64, max_ms: f64 },
    #[error("frame at {stamp_ns} ns falls in a jump of the odometry ({speed:.1} m/s or {turn:.1} rad/s)")]
    Jump { stamp_ns: StampNs, speed: f64, turn: f64 },
}

/// Faster than this between two poses is a jump (a relocalisation, a reset, a replayed
/// sequence starting over), not motion: nothing is interpolated across it.
pub const MAX_SPEED_M_S: f64 = 5.0;
pub const MAX_TURN_RAD_S: f64 = 10.0;

/// Running totals of what came in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct PoseCounters {
    /// Optimised poses kept.
    pub accepted: u64,
    /// Propagated (IMU-rate) poses kept.
    pub propagated: u64,
    /// Decoded but refused by the checks.
    pub rejected: u64,
    /// Messages that did not decode at all.
    pub undecodable: u64,
    /// Lookups that found no pose (each skipped frame).
    pub missing: u64,
    /// Times the odometry started over (stamps going back after a silence).
    pub restarts: u64,
}

/// One stream of poses, oldest first.
struct Track {
    poses: VecDeque<Pose>,
    capacity: usize,
    /// Local clock when the newest pose arrived.
    last_arrival_ns: Option<StampNs>,
}

impl Track {
    fn new(capacity: usize) -> Track {
        Track {
            poses: VecDeque::with_capacity(capacity.clamp(2, 1 << 16)),
            capacity: capacity.max(2),
            last_arrival_ns: None,
        }
    }

    /// Checks and keeps one pose arriving at `now_ns`; true when the stream started over.
    fn push_at(&mut self, raw: &RawPose, limits: &PoseLimits, now_ns: StampNs) -> Result<bool, PoseRejected> {
        let newest = self.poses.back().map(|p| p.stamp_ns);
        // Stamps going back after a silence: the odometry started over (VINS restarted).
        let restarted = match (newest, limits.restart_after_ns, self.last_arrival_ns) {
            (Some(n), Some(after), Some(arrived)) => raw.stamp_ns <= n && now_ns.saturating_sub(arrived) >= after,
            _ => false,
        };
        let pose = check(raw, if restarted { None } else { newest }, limits, now_ns)?;
        if restarted {
            tracing::warn!(
                "the odometry started over: a pose at {} ns after {:.1} s of silence, before the newest ({} ns); poses start again from it",
                raw.stamp_ns,
                now_ns.saturating_sub(self.last_arrival_ns.unwrap_or(now_ns)) as f64 * 1e-9,
                newest.unwrap_or(0)
            );
            self.poses.clear();
        }
        if self.poses.len() == self.capacity {
            self.poses.pop_front();
        }
        self.poses.push_back(pose);
        self.last_arrival_ns = Some(now_ns);
        Ok(restarted)
    }

    /// The pose at `stamp_ns`, interpolated between its neighbours no further apart than
    /// `max_gap_ns`, and not across a jump.
    fn at(&self, stamp_ns: StampNs, max_gap_ns: u64) -> Result<Isometry3<f64>, NoPose> {
        let (first, last) = match (self.poses.front(), self.poses.back()) {
            (Some(f), Some(l)) => (f, l),
            _ => return Err(NoPose::Empty),
        };
        if stamp_ns < first.stamp_ns {
            return Err(NoPose::TooOld { stamp_ns, first_ns: first.stamp_ns });
        }
        if stamp_ns > last.stamp_ns {
            return Err(NoPose::NotYet { stamp_ns, last_ns: last.stamp_ns });
        }
        // The first pose at or after the stamp, and the one before it.
        let i = self.poses.partition_point(|p| p.stamp_ns < stamp_ns);
        let b = &self.poses[i];
        if b.stamp_ns == stamp_ns {
            return Ok(b.transform);
        }
        let a = &self.poses[i - 1];
        let gap = b.stamp_ns - a.stamp_ns;
        if gap > max_gap_ns {
            return Err(NoPose::Gap { stamp_ns, gap_ms: gap as f64 * 1e-6, max_ms: max_gap_ns as f64 * 1e-6 });
        }
        jumped(a, b, stamp_ns)?;
        Ok(blend(&a.transform, &b.transform, (stamp_ns - a.stamp_ns) as f64 / gap as f64))
    }

    /// The newest pose at or before `stamp_ns`, unless it jumped from the one before it
    /// (however long before: a restart clears the track): a single wild pose must not pose
    /// the frames after it.
    fn settled_at_or_before(&self, stamp_ns: StampNs) -> Result<&Pose, NoPose> {
        let i = self.poses.partition_point(|p| p.stamp_ns <= stamp_ns);
        let last = i.checked_sub(1).map(|i| &self.poses[i]).ok_or(NoPose::Empty)?;
        match i.checked_sub(2).map(|i| &self.poses[i]) {
            Some(before) => jumped(before, last, stamp_ns).map(|_| last),
            None => Ok(last),
        }
    }
}

/// A jump between two poses (faster than anything walks or turns), for a frame at `stamp_ns`.
fn jumped(a: &Pose, b: &Pose, stamp_ns: StampNs) -> Result<(), NoPose> {
    let dt = (b.stamp_ns - a.stamp_ns) as f64 * 1e-9;
    let speed = (b.transform.translation.vector - a.transform.translation.vector).norm() / dt;
    let turn = a.transform.rotation.angle_to(&b.transform.rotation) / dt;
    match speed > MAX_SPEED_M_S || turn > MAX_TURN_RAD_S {
        true => Err(NoPose::Jump { stamp_ns, speed, turn }),
        false => Ok(()),
    }
}

/// `a` moved a fraction `t` of the way to `b`: lerp in position, slerp in rotation.
fn blend(a: &Isometry3<f64>, b: &Isometry3<f64>, t: f64) -> Isometry3<f64> {
    let p = a.translation.vector.lerp(&b.translation.vector, t);
    Isometry3::from_parts(Translation3::from(p), a.rotation.slerp(&b.rotation, t))
}

/// Propagated poses further apart than this are not interpolated: the IMU-rate stream
/// comes every few milliseconds.
pub const MAX_PROPAGATED_GAP_NS: u64 = 50_000_000;

/// The odometry's poses: the optimised ones (VINS-Fusion's `odometry`, 10-20 Hz), and,
/// when VINS sends them, the IMU-rate propagated ones between them (`imu_propagate`).
///
/// A frame's pose is interpolated between the optimised poses around it. With propagated
/// poses around the frame and around those optimised poses, the motion between them is
/// taken from the propagated stream instead of a straight line: the pose is the
/// propagated one, corrected by the optimised poses' offsets from the propagated stream
/// (blended between the two); after the newest optimised pose, by its offset alone, so a
/// frame need not wait for the next optimised pose (at most `max_gap` after the last).
pub struct PoseBuffer {
    optimised: Track,
    propagated: Track,
    limits: PoseLimits,
    pub counters: PoseCounters,
}

impl PoseBuffer {
    /// Keeps the newest `capacity` poses; frames between poses further apart than
    /// `max_gap_ns` get none. Checks no stamp against the local clock ([`PoseLimits::gap_only`]).
    pub fn new(capacity: usize, max_gap_ns: u64) -> PoseBuffer {
        PoseBuffer::with_limits(capacity, PoseLimits::gap_only(max_gap_ns))
    }

    pub fn with_limits(capacity: usize, limits: PoseLimits) -> PoseBuffer {
        PoseBuffer {
            optimised: Track::new(capacity),
            propagated: Track::new(capacity),
            limits,
            counters: PoseCounters::default(),
        }
    }

    /// Optimised poses kept.
    pub fn len(&self) -> usize {
        self.optimised.poses.len()
    }

    pub fn is_empty(&self) -> bool {
        self.optimised.poses.is_empty()
    }

    /// The optimised poses kept, oldest first.
    pub fn poses(&self) -> impl Iterator<Item = &Pose> {
        self.optimised.poses.iter()
    }

    /// Checks and keeps one pose arriving now; the oldest is dropped when full.
    pub fn push(&mut self, raw: &RawPose) -> Result<(), PoseRejected> {
        self.push_at(raw, crate::clock::now_ns())
    }

    /// Checks and keeps one optimised pose arriving at local time `now_ns`.
    pub fn push_at(&mut self, raw: &RawPose, now_ns: StampNs) -> Result<(), PoseRejected> {
        let pushed = self.optimised.push_at(raw, &self.limits, now_ns);
        self.count(pushed, false)
    }

    /// Checks and keeps one propagated (IMU-rate) pose arriving at local time `now_ns`.
    pub fn push_propagated_at(&mut self, raw: &RawPose, now_ns: StampNs) -> Result<(), PoseRejected> {
        let pushed = self.propagated.push_at(raw, &self.limits, now_ns);
        self.count(pushed, true)
    }

    fn count(&mut self, pushed: Result<bool, PoseRejected>, propagated: bool) -> Result<(), PoseRejected> {
        match pushed {
            Ok(restarted) => {
                self.counters.restarts += restarted as u64;
                if propagated {
                    self.counters.propagated += 1;
                } else {
                    self.counters.accepted += 1;
                }
                Ok(())
            }
            Err(e) => {
                self.counters.rejected += 1;
                Err(e)
            }
        }
    }

    /// The pose at `stamp_ns`; a miss is counted.
    pub fn at(&mut self, stamp_ns: StampNs) -> Result<Isometry3<f64>, NoPose> {
        let found = self.lookup(stamp_ns);
        if found.is_err() {
            self.counters.missing += 1;
        }
        found
    }

    /// The pose at `stamp_ns` without counting a miss: for a frame that may ask again once
    /// newer poses arrive (it counts its final miss with [`PoseBuffer::count_missing`]).
    pub fn lookup(&self, stamp_ns: StampNs) -> Result<Isometry3<f64>, NoPose> {
        let max_gap = self.limits.max_gap_ns;
        match self.optimised.at(stamp_ns, max_gap) {
            Ok(straight) => Ok(self.densified(stamp_ns).unwrap_or(straight)),
            Err(e @ NoPose::NotYet { last_ns, .. }) if stamp_ns - last_ns <= max_gap => {
                self.propagated_after(stamp_ns).unwrap_or(Err(e))
            }
            Err(e) => Err(e),
        }
    }

    /// The offset of optimised pose `p` from the propagated stream at its stamp.
    fn correction(&self, p: &Pose) -> Option<Isometry3<f64>> {
        let propagated = self.propagated.at(p.stamp_ns, MAX_PROPAGATED_GAP_NS).ok()?;
        Some(p.transform * propagated.inverse())
    }

    /// Between two optimised poses: the propagated pose, corrected.
    fn densified(&self, stamp_ns: StampNs) -> Option<Isometry3<f64>> {
        let propagated = self.propagated.at(stamp_ns, MAX_PROPAGATED_GAP_NS).ok()?;
        let i = self.optimised.poses.partition_point(|p| p.stamp_ns < stamp_ns);
        let b = self.optimised.poses.get(i)?;
        let a = i.checked_sub(1).map_or(b, |i| &self.optimised.poses[i]);
        let (ca, cb) = (self.correction(a)?, self.correction(b)?);
        let t = if b.stamp_ns > a.stamp_ns {
            (stamp_ns - a.stamp_ns) as f64 / (b.stamp_ns - a.stamp_ns) as f64
        } else {
            0.0
        };
        Some(blend(&ca, &cb, t) * propagated)
    }

    /// After the newest optimised pose: the propagated pose, corrected by that pose's offset
    /// (None: no propagated pose to carry it; a jump into that pose: no pose).
    fn propagated_after(&self, stamp_ns: StampNs) -> Option<Result<Isometry3<f64>, NoPose>> {
        let propagated = self.propagated.at(stamp_ns, MAX_PROPAGATED_GAP_NS).ok()?;
        match self.optimised.settled_at_or_before(stamp_ns) {
            Ok(last) => Some(Ok(self.correction(last)? * propagated)),
            Err(jump) => Some(Err(jump)),
        }
    }

    /// Counts a frame that ended without a pose.
    pub fn count_missing(&mut self) {
        self.counters.missing += 1;
    }
}

/// A checked pose: finite position within reach, unit quaternion, stamp after `last_ns`
/// and not ahead of the local clock.
fn check(raw: &RawPose, last_ns: Option<StampNs>, limits: &PoseLimits, now_ns: StampNs) -> Result<Pose, PoseRejected> {
    let RawPose { stamp_ns, position, quat_xyzw: q } = *raw;
    if !position.iter().all(|v| v.is_finite()) {
        return Err(PoseRejected::BadPosition { stamp_ns, position });
    }
    let distance_m = Vector3::from(position).norm();
    if !(distance_m <= limits.max_radius_m) {
        return Err(PoseRejected::OutOfReach { stamp_ns, distance_m, max_m: limits.max_radius_m });
    }
    if let Some(max) = limits.max_ahead_ns.filter(|&max| stamp_ns > now_ns.saturating_add(max)) {
        let ahead_ms = (stamp_ns - now_ns) as f64 * 1e-6;
        return Err(PoseRejected::FromTheFuture { stamp_ns, ahead_ms, max_ms: max as f64 * 1e-6 });
    }
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !((norm - 1.0).abs() <= crate::sequence::QUATERNION_NORM_TOLERANCE) {
        return Err(PoseRejected::BadQuaternion { stamp_ns, quat_xyzw: q, norm });
    }
    if let Some(last_ns) = last_ns.filter(|&l| stamp_ns <= l) {
        return Err(PoseRejected::StampNotIncreasing { stamp_ns, last_ns });
    }
    let rotation = UnitQuaternion::from_quaternion(Quaternion::new(q[3], q[0], q[1], q[2]));
    Ok(Pose { stamp_ns, transform: Isometry3::from_parts(Translation3::from(Vector3::from(position)), rotation) })
}

/// T_world_camera of a frame: the body's pose and the camera's mount, the rotation made
/// unit again (a recording writes it, and it must read back as it was used).
pub fn world_camera(world_body: &Isometry3<f64>, body_camera: &Isometry3<f64>) -> Isometry3<f64> {
    let mut t = world_body * body_camera;
    t.rotation.renormalize();
    t
}

/// T_body_camera from the config.
pub fn extrinsic(config: &crate::config::Config) -> Isometry3<f64> {
    let e = &config.sources.extrinsics;
    let [x, y, z, w] = e.quat_xyzw;
    Isometry3::from_parts(
        Translation3::from(Vector3::from(e.xyz)),
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
    )
}
