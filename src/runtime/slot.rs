//! The newest-frame slot between the camera and the extractor thread: a frame still waiting
//! when the next arrives is replaced (and counted dropped), so a slow frame never queues up
//! stale ones behind it.

use std::sync::atomic::Ordering;
use std::time::Duration;

use parking_lot::{Condvar, Mutex};

use super::status::Counters;
use crate::types::{DepthFrame, Intrinsics};

#[derive(Default)]
pub struct Slot {
    frame: Mutex<Option<(DepthFrame, Intrinsics)>>,
    ready: Condvar,
}

impl Slot {
    /// Puts a camera's frame in, counting it and the one it replaces.
    pub fn offer(&self, frame: (DepthFrame, Intrinsics), counters: &Counters) {
        counters.frames_in.fetch_add(1, Ordering::Relaxed);
        let replaced = self.frame.lock().replace(frame).is_some();
        self.ready.notify_one();
        if replaced {
            counters.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// The waiting frame, after at most `wait`.
    pub fn take(&self, wait: Duration) -> Option<(DepthFrame, Intrinsics)> {
        let mut frame = self.frame.lock();
        if frame.is_none() {
            self.ready.wait_for(&mut frame, wait);
        }
        frame.take()
    }
}
