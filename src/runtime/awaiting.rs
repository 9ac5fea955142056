//! Extracted frames waiting for their odometry pose. VINS-Fusion publishes each pose 30-80 ms
//! after the image it belongs to, so a frame is usually extracted before the pose after its
//! stamp exists. The extractor never waits for it: the frame joins this short queue and is
//! mapped as soon as a pose after its stamp arrives, or skipped (with the reason) when that
//! cannot happen any more or it has waited `poses.max_wait_s`.
//!
//! Frames leave in the order they came, so the map sees them in stamp order. When the queue
//! is full the oldest frame goes: the newest are the ones still likely to get a pose.

use std::collections::VecDeque;

use nalgebra::Isometry3;

use crate::pose::{NoPose, PoseBuffer};
use crate::types::StampNs;

/// Why a frame was not mapped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Skip {
    /// It waited `max_wait` and no odometry had come at all.
    NoOdometry,
    /// It waited `max_wait` and no pose after its stamp came.
    TooLate,
    /// The poses around it are further apart than `poses.max_gap_s`.
    Gap,
    /// The odometry jumped between the poses around it (a relocalisation).
    Jump,
    /// It is older than the oldest pose kept (before the odometry started).
    BeforeOdometry,
    /// The queue was full and newer frames took its place.
    Overflow,
}

impl Skip {
    pub const ALL: [Skip; 6] =
        [Skip::NoOdometry, Skip::TooLate, Skip::Gap, Skip::Jump, Skip::BeforeOdometry, Skip::Overflow];

    /// What the status line calls it.
    pub fn name(self) -> &'static str {
        match self {
            Skip::NoOdometry => "no odometry",
            Skip::TooLate => "pose too late",
            Skip::Gap => "gap",
            Skip::Jump => "jump",
            Skip::BeforeOdometry => "before odometry",
            Skip::Overflow => "queue full",
        }
    }

    /// The lookup's answer as a final reason; None while a pose may still come.
    fn of(no_pose: &NoPose) -> Option<Skip> {
        match no_pose {
            NoPose::Empty | NoPose::NotYet { .. } => None,
            NoPose::TooOld { .. } => Some(Skip::BeforeOdometry),
            NoPose::Gap { .. } => Some(Skip::Gap),
            NoPose::Jump { .. } => Some(Skip::Jump),
        }
    }
}

/// A frame's way out of the queue.
#[derive(Debug)]
pub enum Settled<T> {
    /// Its pose (T_world_body at its stamp).
    Posed(T, Isometry3<f64>),
    Skipped(T, Skip),
}

struct Waiting<T> {
    stamp_ns: StampNs,
    /// When it may wait no longer (local clock).
    deadline_ns: StampNs,
    frame: T,
}

/// The queue; `T` is whatever the caller maps a frame from.
pub struct AwaitingPose<T> {
    frames: VecDeque<Waiting<T>>,
    capacity: usize,
    max_wait_ns: u64,
}

impl<T> AwaitingPose<T> {
    pub fn new(capacity: usize, max_wait_ns: u64) -> AwaitingPose<T> {
        let capacity = capacity.max(1);
        AwaitingPose { frames: VecDeque::with_capacity(capacity), capacity, max_wait_ns }
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Queues a frame stamped `stamp_ns` at local time `now_ns`; when full, the oldest frame
    /// comes back, skipped. The wait runs from the earlier of the stamp and now, so a frame
    /// stamped ahead of this machine's clock cannot hold the queue.
    pub fn push(&mut self, stamp_ns: StampNs, frame: T, now_ns: StampNs) -> Option<Settled<T>> {
        let overflow = (self.frames.len() == self.capacity)
            .then(|| self.frames.pop_front())
            .flatten()
            .map(|w| Settled::Skipped(w.frame, Skip::Overflow));
        let deadline_ns = stamp_ns.min(now_ns).saturating_add(self.max_wait_ns);
        self.frames.push_back(Waiting { stamp_ns, deadline_ns, frame });
        overflow
    }

    /// The frames that are settled at local time `now_ns`, oldest first: those with a pose,
    /// and those that cannot get one. It stops at the first frame still waiting, so frames
    /// leave in order. Each frame that ends without a pose is counted in `poses`.
    pub fn settle(&mut self, poses: &mut PoseBuffer, now_ns: StampNs) -> Vec<Settled<T>> {
        let mut settled = Vec::new();
        while let Some(front) = self.frames.front() {
            let outcome = match poses.lookup(front.stamp_ns) {
                Ok(pose) => Some(Ok(pose)),
                Err(no_pose) => match Skip::of(&no_pose) {
                    Some(skip) => Some(Err(skip)),
                    None if now_ns >= front.deadline_ns => {
                        Some(Err(if poses.is_empty() { Skip::NoOdometry } else { Skip::TooLate }))
                    }
                    None => None,
                },
            };
            let Some(outcome) = outcome else { break };
            let Some(w) = self.frames.pop_front() else { break };
            settled.push(match outcome {
                Ok(pose) => Settled::Posed(w.frame, pose),
                Err(skip) => {
                    poses.count_missing();
                    Settled::Skipped(w.frame, skip)
                }
            });
        }
        settled
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::RawPose;

    const MS: u64 = 1_000_000;

    fn pose(stamp_ms: u64, x: f64) -> RawPose {
        RawPose { stamp_ns: stamp_ms * MS, position: [x, 0.0, 0.0], quat_xyzw: [0.0, 0.0, 0.0, 1.0] }
    }

    fn kinds(settled: &[Settled<u32>]) -> Vec<(u32, Option<Skip>)> {
        settled
            .iter()
            .map(|s| match s {
                Settled::Posed(f, _) => (*f, None),
                Settled::Skipped(f, why) => (*f, Some(*why)),
            })
            .collect()
    }

    #[test]
    fn a_frame_waits_for_the_pose_after_it_and_is_mapped_when_it_comes() {
        let mut poses = PoseBuffer::new(64, 250 * MS);
        let mut q = AwaitingPose::new(8, 300 * MS);
        poses.push_at(&pose(1000, 0.0), 1000 * MS).unwrap();
        assert!(q.push(1040 * MS, 1, 1060 * MS).is_none());
        // The pose after the frame is 50 ms late: the frame waits.
        assert!(q.settle(&mut poses, 1100 * MS).is_empty());
        poses.push_at(&pose(1100, 0.1), 1150 * MS).unwrap();
        let s = q.settle(&mut poses, 1150 * MS);
        assert_eq!(kinds(&s), vec![(1, None)]);
        let Settled::Posed(_, p) = &s[0] else { unreachable!() };
        assert!((p.translation.x - 0.04).abs() < 1e-12, "interpolated at 40 of 100 ms: {p}");
        assert!(q.is_empty());
        assert_eq!(poses.counters.missing, 0, "waiting is not a miss");
    }

    #[test]
    fn frames_leave_in_order_and_say_why_they_were_skipped() {
        let mut poses = PoseBuffer::new(64, 250 * MS);
        let mut q = AwaitingPose::new(8, 300 * MS);
        // Before any odometry, past the wait: no odometry.
        q.push(900 * MS, 0, 900 * MS);
        assert_eq!(kinds(&q.settle(&mut poses, 1201 * MS)), vec![(0, Some(Skip::NoOdometry))]);
        poses.push_at(&pose(1000, 0.0), 1000 * MS).unwrap();
        poses.push_at(&pose(1100, 0.1), 1100 * MS).unwrap();
        // 400 ms without a pose, then a jump of 10 m in 100 ms.
        poses.push_at(&pose(1500, 0.2), 1500 * MS).unwrap();
        poses.push_at(&pose(1600, 10.0), 1600 * MS).unwrap();
        for (k, stamp) in [(1, 950), (2, 1050), (3, 1300), (4, 1550), (5, 1700)] {
            q.push(stamp * MS, k, 1650 * MS);
        }
        let s = q.settle(&mut poses, 1700 * MS);
        assert_eq!(
            kinds(&s),
            vec![(1, Some(Skip::BeforeOdometry)), (2, None), (3, Some(Skip::Gap)), (4, Some(Skip::Jump))]
        );
        // Frame 5 still waits for a pose after it, then gives up 300 ms after it was queued
        // (before its stamp: it is stamped ahead of the clock).
        assert_eq!(q.len(), 1);
        assert!(q.settle(&mut poses, 1949 * MS).is_empty());
        assert_eq!(kinds(&q.settle(&mut poses, 1950 * MS)), vec![(5, Some(Skip::TooLate))]);
        assert_eq!(poses.counters.missing, 5);
    }

    #[test]
    fn a_full_queue_gives_up_its_oldest_frame() {
        let mut poses = PoseBuffer::new(64, 250 * MS);
        let mut q = AwaitingPose::new(3, 300 * MS);
        for k in 0..3 {
            assert!(q.push((1000 + 10 * k) * MS, k as u32, 1000 * MS).is_none());
        }
        let out = q.push(1030 * MS, 3, 1030 * MS).map(|s| kinds(&[s]));
        assert_eq!(out, Some(vec![(0, Some(Skip::Overflow))]));
        poses.push_at(&pose(1000, 0.0), 1000 * MS).unwrap();
        poses.push_at(&pose(1100, 0.0), 1100 * MS).unwrap();
        assert_eq!(kinds(&q.settle(&mut poses, 1100 * MS)), vec![(1, None), (2, None), (3, None)]);
    }

    #[test]
    fn a_frame_stamped_ahead_of_the_clock_waits_no_longer_than_any_other() {
        let mut poses = PoseBuffer::new(64, 250 * MS);
        poses.push_at(&pose(1000, 0.0), 1000 * MS).unwrap();
        let mut q = AwaitingPose::new(4, 300 * MS);
        q.push(1_000_000 * MS, 7, 1000 * MS);
        assert!(q.settle(&mut poses, 1299 * MS).is_empty());
        assert_eq!(kinds(&q.settle(&mut poses, 1300 * MS)), vec![(7, Some(Skip::TooLate))]);
    }
}
