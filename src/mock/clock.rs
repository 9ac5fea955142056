//! The looped sequence's clock the mocks share: at UNIX time t a mock is at the sequence time
//! that `t mod period` shows on a loop that walks the sequence forward and then back, so the
//! mock camera, the mock D435i and the mock VINS, in separate processes that never talk to
//! each other, agree on which frame goes with which pose.

use anyhow::{Result, bail};

use crate::sequence::Sequence;
use crate::types::StampNs;

/// The looped sequence's clock: which sequence time a wall-clock time shows. The loop runs the
/// walk forward and then back, so the trajectory it shows is continuous: a loop that jumped
/// back to the start would be a jump of the odometry once a loop, and the frames around it
/// (one a second on the 1 s mock walks) could get no pose.
pub struct SequenceClock {
    first_ns: StampNs,
    /// The walk's length, last stamp minus first.
    span_ns: StampNs,
}

/// The loop of a one-frame sequence: one frame interval.
const SINGLE_FRAME_PERIOD_NS: StampNs = 33_333_333;

impl SequenceClock {
    pub fn new(seq: &Sequence) -> Result<SequenceClock> {
        let (Some(first), Some(last)) = (seq.poses.first(), seq.poses.last()) else {
            bail!("{} has no frames", seq.dir.display());
        };
        Ok(SequenceClock { first_ns: first.stamp_ns, span_ns: last.stamp_ns - first.stamp_ns })
    }

    /// Forward and back.
    fn period_ns(&self) -> StampNs {
        if self.span_ns == 0 { SINGLE_FRAME_PERIOD_NS } else { 2 * self.span_ns }
    }

    /// The sequence stamp shown at wall time `t_ns`.
    pub fn sequence_time(&self, t_ns: StampNs) -> StampNs {
        let u = t_ns % self.period_ns();
        self.first_ns + if u <= self.span_ns { u } else { self.period_ns() - u }
    }

    /// Whether the loop walks the sequence backwards at wall time `t_ns` (rates change sign).
    pub fn backwards(&self, t_ns: StampNs) -> bool {
        t_ns % self.period_ns() > self.span_ns
    }

    /// The first frame shown after wall time `t_ns`: its wall time and index, given the
    /// sequence's frame stamps (ascending, the first at the loop's start).
    pub fn next_frame(&self, t_ns: StampNs, stamps: &[StampNs]) -> (StampNs, usize) {
        let u = t_ns % self.period_ns();
        let loop_start = t_ns - u;
        let offset = |k: usize| stamps[k] - self.first_ns;
        if let Some(k) = (0..stamps.len()).find(|&k| offset(k) > u) {
            return (loop_start + offset(k), k);
        }
        // Back from the last but one to the second; the first starts the next loop.
        let back = (1..stamps.len().saturating_sub(1)).rev().map(|k| (2 * self.span_ns - offset(k), k));
        match back.into_iter().find(|&(o, _)| o > u) {
            Some((o, k)) => (loop_start + o, k),
            None => (loop_start + self.period_ns(), 0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: StampNs = 1_000_000;

    #[test]
    fn the_loop_walks_forward_and_back_without_a_jump() {
        let stamps: Vec<StampNs> = (0..4).map(|k| 1000 * MS + k * 100 * MS).collect();
        let clock = SequenceClock { first_ns: stamps[0], span_ns: 300 * MS };
        // Frames shown from wall time 0: 0 1 2 3 2 1 0 1 ... at 100 ms intervals.
        let mut t = 0;
        let mut shown = Vec::new();
        for _ in 0..8 {
            let (at, k) = clock.next_frame(t, &stamps);
            assert_eq!(clock.sequence_time(at), stamps[k], "frame {k} shown at its own sequence time");
            shown.push(k);
            t = at;
        }
        assert_eq!(shown, vec![1, 2, 3, 2, 1, 0, 1, 2]);
        // The sequence time never jumps: at most 1 ms of it per wall ms.
        for t in (0..2000).map(|ms| ms * MS) {
            let d = clock.sequence_time(t + MS) as i64 - clock.sequence_time(t) as i64;
            assert!(d.abs() <= MS as i64, "at {t}: {d}");
        }
        assert!(!clock.backwards(100 * MS) && clock.backwards(400 * MS));
    }
}
