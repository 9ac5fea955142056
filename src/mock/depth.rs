//! The mock depth camera: a sequence's frames looped on the wall clock ([`super::SequenceClock`]),
//! each delivered when the loop shows it and stamped then, as a camera would.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Result;

use super::SequenceClock;
use crate::clock::now_ns;
use crate::sequence::Sequence;
use crate::types::{DepthFrame, Intrinsics, StampNs};

/// Delivers frames at about `fps` to `deliver` until `stop` is set.
pub fn spawn(
    seq: &Sequence,
    fps: u32,
    stop: Arc<AtomicBool>,
    mut deliver: impl FnMut((DepthFrame, Intrinsics)) + Send + 'static,
) -> Result<tokio::task::JoinHandle<()>> {
    let clock = SequenceClock::new(seq)?;
    let stamps: Vec<StampNs> = seq.poses.iter().map(|p| p.stamp_ns).collect();
    let frames: Vec<DepthFrame> = (0..seq.len()).map(|k| seq.depth(k)).collect::<Result<_, _>>()?;
    let intrinsics = seq.intrinsics;
    Ok(tokio::spawn(async move {
        let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / fps as f64));
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        while !stop.load(Ordering::Relaxed) {
            tick.tick().await;
            // A frame is delivered when the loop shows it, not held back until the next
            // tick of an unrelated timer.
            let now = now_ns();
            let (shown, k) = clock.next_frame(now, &stamps);
            tokio::time::sleep(Duration::from_nanos(shown.saturating_sub(now))).await;
            let mut frame = frames[k].clone();
            frame.stamp_ns = shown;
            deliver((frame, intrinsics));
        }
    }))
}
