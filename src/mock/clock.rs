//! The looped sequence's clock the mocks share: at UNIX time t a mock is at sequence time
//! `first + t mod period`, so the mock camera, the mock D435i and the mock VINS, in separate
//! processes that never talk to each other, agree on which frame goes with which pose.

use anyhow::{Result, bail};

use crate::sequence::Sequence;
use crate::types::StampNs;

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
