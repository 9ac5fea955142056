//! The extractor thread: the newest frame from the slot, its polygons, the odometry pose at
//! its stamp, the map update; out goes a [`FrameEvent`] in polymap's own types (the publisher
//! turns it into messages). CPU and GPU work stay off the async runtime.
//!
//! The extractor is made on this thread before start-up goes on, so a backend that cannot
//! run (`backend = "gpu"` without a GPU) stops start-up with the reason. A panic here ends
//! the thread at once with what it was doing: the runtime then stops, saving the map unless
//! the panic came in the middle of changing it.

use std::panic::AssertUnwindSafe;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Result, anyhow};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use parking_lot::Mutex;

use super::slot::Slot;
use super::status::Counters;
use crate::config::{Backend, Config};
use crate::extract::{Extractor, Polygon};
use crate::map::{MapPolygon, PolygonMap};
use crate::pose::{NoPose, PoseBuffer};
use crate::types::StampNs;

/// What one frame made: its polygons in the map's frame, and what it changed in the map.
pub struct FrameEvent {
    pub stamp_ns: StampNs,
    /// The map's version before and after this frame.
    pub from_version: u64,
    pub version: u64,
    /// Where the robot (the odometry's body) was, in the map's frame.
    pub robot: [f64; 3],
    pub polygons: Vec<Polygon>,
    pub added: Vec<MapPolygon>,
    pub changed: Vec<MapPolygon>,
    pub removed: Vec<u64>,
    pub drift_z: f64,
    pub drift_var: f64,
}

/// How the thread ended.
#[derive(Debug)]
pub enum WorkerEnd {
    /// Asked to stop, or nobody listens any more.
    Stopped,
    /// A panic: where, and whether the map is as the last frame left it.
    Panicked { during: &'static str, message: String, map_intact: bool },
}

/// What the thread shares with the runtime.
pub struct Shared {
    pub slot: Arc<Slot>,
    pub stop: Arc<AtomicBool>,
    pub poses: Arc<Mutex<PoseBuffer>>,
    pub map: Arc<Mutex<PolygonMap>>,
    pub counters: Arc<Counters>,
}

/// Starts the thread once its extractor is made; an extractor that cannot be made is the error.
pub fn spawn(
    config: &Config,
    shared: Shared,
    out: tokio::sync::mpsc::Sender<FrameEvent>,
) -> Result<std::thread::JoinHandle<WorkerEnd>> {
    let config = config.clone();
    let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<Backend, String>>();
    let thread = std::thread::Builder::new().name("extractor".into()).spawn(move || {
        let mut extractor = match Extractor::new(&config.pipeline) {
            Ok(e) => {
                let _ = ready_tx.send(Ok(e.backend()));
                e
            }
            Err(e) => {
                let _ = ready_tx.send(Err(format!("{e:#}")));
                return WorkerEnd::Stopped;
            }
        };
        let body_camera = extrinsic(&config);
        let gap_ns = (config.poses.max_gap_s * 1e9) as u64;
        let Shared { slot, stop, poses, map, counters } = shared;
        while !stop.load(Ordering::Relaxed) {
            let Some((frame, intrinsics)) = slot.take(Duration::from_millis(100)) else { continue };
            let extracted = std::panic::catch_unwind(AssertUnwindSafe(|| extractor.extract(&frame, &intrinsics)));
            let (polys, stages, _) = match extracted {
                Ok(Ok(r)) => r,
                Ok(Err(e)) => {
                    counters.extraction_failed.fetch_add(1, Ordering::Relaxed);
                    tracing::warn!("frame at {} ns not extracted: {e:#}", frame.stamp_ns);
                    continue;
                }
                Err(panic) => return panicked("extracting a frame", panic, true),
            };
            let Some(world_body) = pose_at(&poses, frame.stamp_ns, gap_ns, &stop) else {
                counters.without_pose.fetch_add(1, Ordering::Relaxed);
                continue;
            };
            let t_world_camera = world_body * body_camera;
            let mut m = map.lock();
            let updated = std::panic::catch_unwind(AssertUnwindSafe(|| {
                let from_version = m.version();
                let update = m.update(&polys.polygons, &t_world_camera, &intrinsics, Some(&stages.depth));
                let corrected = m.corrected(&t_world_camera);
                let robot = m.corrected(&world_body).translation.vector;
                let version = m.version();
                let mut polygons_of = |ids: &[u64]| ids.iter().filter_map(|&id| m.polygon(id)).collect::<Vec<_>>();
                FrameEvent {
                    stamp_ns: frame.stamp_ns,
                    from_version,
                    version,
                    robot: [robot.x, robot.y, robot.z],
                    polygons: polys.polygons.iter().map(|p| p.transformed(&corrected)).collect(),
                    added: polygons_of(&update.added),
                    changed: polygons_of(&update.changed),
                    removed: update.removed,
                    drift_z: m.drift.z,
                    drift_var: m.drift.var,
                }
            }));
            drop(m);
            let event = match updated {
                Ok(event) => event,
                Err(panic) => return panicked("updating the map", panic, false),
            };
            counters.processed.fetch_add(1, Ordering::Relaxed);
            if out.blocking_send(event).is_err() {
                break;
            }
        }
        WorkerEnd::Stopped
    })?;
    match ready_rx.recv() {
        Ok(Ok(backend)) => {
            tracing::info!("extractor ready: {backend} backend");
            Ok(thread)
        }
        Ok(Err(why)) => Err(anyhow!("the extractor could not start: {why}")),
        Err(_) => Err(anyhow!("the extractor thread ended before it started")),
    }
}

fn panicked(during: &'static str, panic: Box<dyn std::any::Any + Send>, map_intact: bool) -> WorkerEnd {
    let message = panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(no message)".into());
    tracing::error!("the extractor thread panicked {during}: {message}");
    WorkerEnd::Panicked { during, message, map_intact }
}

/// The odometry pose at a frame's stamp, waiting up to one gap for it to arrive.
fn pose_at(poses: &Mutex<PoseBuffer>, stamp_ns: StampNs, gap_ns: u64, stop: &AtomicBool) -> Option<Isometry3<f64>> {
    let waited = Instant::now();
    loop {
        let found = poses.lock().at(stamp_ns);
        match found {
            Ok(t) => return Some(t),
            Err(NoPose::NotYet { .. }) | Err(NoPose::Empty)
                if waited.elapsed() < Duration::from_nanos(gap_ns) && !stop.load(Ordering::Relaxed) =>
            {
                std::thread::sleep(Duration::from_millis(2));
            }
            Err(e) => {
                tracing::debug!("frame skipped: {e}");
                return None;
            }
        }
    }
}

/// T_body_camera from the config.
pub fn extrinsic(config: &Config) -> Isometry3<f64> {
    let e = &config.sources.extrinsics;
    let [x, y, z, w] = e.quat_xyzw;
    Isometry3::from_parts(
        Translation3::from(Vector3::from(e.xyz)),
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
    )
}
