//! The mapper's health: counters every task adds to, and the status they make once a second
//! (published, and printed).

use std::sync::atomic::{AtomicU64, Ordering};

use super::awaiting::Skip;
use crate::pose::PoseCounters;
use crate::types::StampNs;

/// Counts shared by the tasks.
#[derive(Default)]
pub struct Counters {
    pub frames_in: AtomicU64,
    pub processed: AtomicU64,
    /// Replaced in the slot by a newer frame before the extractor took them.
    pub dropped: AtomicU64,
    /// Extracted frames not mapped, by why ([`Skip`] as the index).
    pub skipped: [AtomicU64; Skip::ALL.len()],
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
    /// Extracted frames that got no pose: every skip but [`Skip::Overflow`].
    pub without_pose: u64,
    /// Extracted frames not mapped, by why ([`Skip`] as the index).
    pub skipped: [u64; Skip::ALL.len()],
    pub extraction_failed: u64,
    pub requests_refused: u64,
    pub snapshots_failed: u64,
    pub latency: crate::stats::Spread,
    pub poses: PoseCounters,
    pub drift_z: f64,
    pub map_polygons: usize,
}

impl Counters {
    pub fn count_skip(&self, why: Skip) {
        self.skipped[why as usize].fetch_add(1, Ordering::Relaxed);
    }

    /// The counts now, with what the caller knows of the rest.
    pub fn report(
        &self,
        latency: crate::stats::Spread,
        poses: PoseCounters,
        drift_z: f64,
        map_polygons: usize,
    ) -> Report {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        let skipped = Skip::ALL.map(|why| get(&self.skipped[why as usize]));
        Report {
            frames_in: get(&self.frames_in),
            processed: get(&self.processed),
            dropped: get(&self.dropped),
            without_pose: Skip::ALL
                .iter()
                .filter(|&&why| why != Skip::Overflow)
                .map(|&why| skipped[why as usize])
                .sum(),
            skipped,
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

impl Report {
    /// As polymap_msgs/Status.
    pub fn message(&self, stamp_ns: StampNs, frame_id: &str) -> crate::ros2::msg::Status {
        crate::ros2::msg::Status {
            header: crate::interface::convert::header(stamp_ns, frame_id),
            frames_in: self.frames_in,
            frames_processed: self.processed,
            frames_dropped: self.dropped,
            frames_without_pose: self.without_pose,
            frames_not_extracted: self.extraction_failed,
            latency_median_ms: self.latency.median,
            latency_p99_ms: self.latency.p99,
            poses_accepted: self.poses.accepted,
            poses_refused: self.poses.rejected + self.poses.undecodable,
            odometry_restarts: self.poses.restarts,
            requests_refused: self.requests_refused,
            snapshots_failed: self.snapshots_failed,
            drift_z: self.drift_z,
            map_polygons: self.map_polygons.min(u32::MAX as usize) as u32,
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
        let skipped: Vec<String> = Skip::ALL
            .iter()
            .filter(|&&why| self.skipped[why as usize] > 0)
            .map(|&why| format!("{} {}", why.name(), self.skipped[why as usize]))
            .collect();
        if !skipped.is_empty() {
            write!(f, "; skipped: {}", skipped.join(", "))?;
        }
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
