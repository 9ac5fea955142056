//! The mapper's health: counters every task adds to, and the status they make once a second
//! (published, and printed).

use std::sync::atomic::{AtomicU64, Ordering};

use crate::pose::PoseCounters;

/// Counts shared by the tasks.
#[derive(Default)]
pub struct Counters {
    pub frames_in: AtomicU64,
    pub processed: AtomicU64,
    /// Replaced in the slot by a newer frame before the extractor took them.
    pub dropped: AtomicU64,
    pub without_pose: AtomicU64,
    /// Frames the extractor refused (a malformed frame).
    pub extraction_failed: AtomicU64,
    /// Service requests that did not decode.
    pub requests_refused: AtomicU64,
    /// Snapshots that could not be written.
    pub snapshots_failed: AtomicU64,
}

/// One status line's worth.
#[derive(Clone, Debug, Default)]
pub struct Report {
    pub frames_in: u64,
    pub processed: u64,
    pub dropped: u64,
    pub without_pose: u64,
    pub extraction_failed: u64,
    pub requests_refused: u64,
    pub snapshots_failed: u64,
    pub latency: crate::bench::Spread,
    pub poses: PoseCounters,
    pub drift_z: f64,
    pub map_polygons: usize,
}

impl Counters {
    /// The counts now, with what the caller knows of the rest.
    pub fn report(
        &self,
        latency: crate::bench::Spread,
        poses: PoseCounters,
        drift_z: f64,
        map_polygons: usize,
    ) -> Report {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        Report {
            frames_in: get(&self.frames_in),
            processed: get(&self.processed),
            dropped: get(&self.dropped),
            without_pose: get(&self.without_pose),
            extraction_failed: get(&self.extraction_failed),
            requests_refused: get(&self.requests_refused),
            snapshots_failed: get(&self.snapshots_failed),
            latency,
            poses,
            drift_z,
            map_polygons,
        }
    }
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "frames in {} processed {} dropped {} without pose {}; latency median {:.1} ms p99 {:.1} ms; poses {} (refused {}); drift {:.1} mm; map {} polygons",
            self.frames_in,
            self.processed,
            self.dropped,
            self.without_pose,
            self.latency.median,
            self.latency.p99,
            self.poses.accepted,
            self.poses.rejected + self.poses.undecodable,
            self.drift_z * 1e3,
            self.map_polygons
        )?;
        for (what, n) in [
            ("frames not extracted", self.extraction_failed),
            ("requests refused", self.requests_refused),
            ("snapshots failed", self.snapshots_failed),
            ("odometry restarts", self.poses.restarts),
        ] {
            if n > 0 {
                write!(f, "; {what} {n}")?;
            }
        }
        Ok(())
    }
}
