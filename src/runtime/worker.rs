//! The extractor thread takes the newest frame from the slot and extracts its polygons; the
//! map thread queues each extracted frame until the odometry pose at its stamp has arrived
//! ([`super::awaiting`]), updates the map, and sends a [`FrameEvent`] in polymap's own types
//! (the publisher turns it into messages). Extraction never waits for a pose or the map.
//! CPU and GPU work stay off the async runtime.
//!
//! The extractor is made on its thread before start-up goes on, so a backend that cannot
//! run (`backend = "gpu"` without a GPU) stops start-up with the reason. A panic in either
//! thread ends both at once with what it was doing: the runtime then stops, saving the map
//! unless the panic came in the middle of changing it.

use std::panic::AssertUnwindSafe;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Result, anyhow};
use nalgebra::Isometry3;
use parking_lot::Mutex;

use super::awaiting::{AwaitingPose, Settled, Skip};
use super::record::Recorder;
use super::slot::Slot;
use super::status::Counters;
use crate::clock::now_ns;
use crate::config::{Backend, Config};
use crate::extract::{Extraction, Extractor, FramePolygons, Polygon};
use crate::grid::Grid;
use crate::map::{Label, MapPolygon, PolygonMap};
use crate::pose::PoseBuffer;
use crate::types::{DepthFrame, Intrinsics, Pose, StampNs};

/// What one frame made: its polygons in the map's frame, and what it changed in the map.
pub struct FrameEvent {
    pub stamp_ns: StampNs,
    /// The map's version before and after this frame.
    pub from_version: u64,
    pub version: u64,
    /// Where the robot (the odometry's body) was, in the map's frame.
    pub robot: [f64; 3],
    pub polygons: Vec<Polygon>,
    /// Each polygon's label in the map it went into (None: it did not go in).
    pub labels: Vec<Option<Label>>,
    pub added: Vec<MapPolygon>,
    pub changed: Vec<MapPolygon>,
    pub removed: Vec<u64>,
    pub drift_z: f64,
    pub drift_var: f64,
    /// The odometry's frame seen from the map's: the drift taken out (what /tf carries).
    pub map_from_odometry: Isometry3<f64>,
}

/// How the thread ended.
#[derive(Debug)]
pub enum WorkerEnd {
    /// Asked to stop, or nobody listens any more.
    Stopped,
    /// The recording is full (or its thread stopped): the session ends with it.
    RecordingEnded,
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

/// What the extractor thread hands the map thread.
enum Handoff {
    Frame(Extracted),
    /// The extractor thread ended (a panic, or nobody listens any more).
    Ended(WorkerEnd),
}

/// Starts the extractor and map threads once the extractor is made (an extractor that cannot
/// be made is the error); the handle is the map thread's, which ends with both. Two threads,
/// so that neither a pose still to come nor the map's update ever holds up the next frame.
pub fn spawn(
    config: &Config,
    shared: Shared,
    recorder: Option<Recorder>,
    out: tokio::sync::mpsc::Sender<FrameEvent>,
) -> Result<std::thread::JoinHandle<WorkerEnd>> {
    let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<Backend, String>>();
    let (handoff_tx, handoff_rx) = std::sync::mpsc::sync_channel::<Handoff>(MAX_AWAITING);
    let Shared { slot, stop, poses, map, counters } = shared;
    let pipeline = config.pipeline.clone();
    let (stop_x, counters_x) = (stop.clone(), counters.clone());
    let keep_raw = recorder.is_some();
    let extractor_thread = std::thread::Builder::new().name("extractor".into()).spawn(move || {
        let mut extractor = match Extractor::new(&pipeline) {
            Ok(e) => {
                let _ = ready_tx.send(Ok(e.backend()));
                e
            }
            Err(e) => {
                let _ = ready_tx.send(Err(format!("{e:#}")));
                return;
            }
        };
        let end = extract_frames(&mut extractor, &slot, &stop_x, &counters_x, keep_raw, &handoff_tx);
        let _ = handoff_tx.send(Handoff::Ended(end));
    })?;
    match ready_rx.recv() {
        Ok(Ok(backend)) => tracing::info!("extractor ready: {backend} backend"),
        Ok(Err(why)) => return Err(anyhow!("the extractor could not start: {why}")),
        Err(_) => return Err(anyhow!("the extractor thread ended before it started")),
    }
    let mut mapper = FrameMapper::new(config, poses, map, counters);
    mapper.recorder = recorder;
    let map_thread = std::thread::Builder::new().name("mapper".into()).spawn(move || {
        let end = map_frames(&mut mapper, &handoff_rx, &stop, &out);
        // The extractor stops with the map thread, and is waited for.
        stop.store(true, Ordering::Relaxed);
        drop(handoff_rx);
        let _ = extractor_thread.join();
        end
    })?;
    Ok(map_thread)
}

/// The extractor thread's loop: the newest frame from the slot, extracted, handed on.
fn extract_frames(
    extractor: &mut Extractor,
    slot: &Slot,
    stop: &AtomicBool,
    counters: &Counters,
    keep_raw: bool,
    handoff: &std::sync::mpsc::SyncSender<Handoff>,
) -> WorkerEnd {
    while !stop.load(Ordering::Relaxed) {
        let Some((frame, intrinsics)) = slot.take(IDLE_WAIT) else { continue };
        let extracted = std::panic::catch_unwind(AssertUnwindSafe(|| extractor.extract(&frame, &intrinsics)));
        let Extraction { polygons, depth, .. } = match extracted {
            Ok(Ok(r)) => r,
            Ok(Err(e)) => {
                counters.extraction_failed.fetch_add(1, Ordering::Relaxed);
                tracing::warn!("frame at {} ns not extracted: {e:#}", frame.stamp_ns);
                continue;
            }
            Err(panic) => return panicked("extracting a frame", panic, true),
        };
        let raw = keep_raw.then_some(frame);
        let extracted = Extracted { polygons, depth, intrinsics, raw };
        match handoff.try_send(Handoff::Frame(extracted)) {
            Ok(()) => {}
            // The map thread is a whole queue behind: this frame goes.
            Err(std::sync::mpsc::TrySendError::Full(_)) => counters.count_skip(Skip::Overflow),
            Err(std::sync::mpsc::TrySendError::Disconnected(_)) => break,
        }
    }
    WorkerEnd::Stopped
}

/// The map thread's loop: extracted frames in, each mapped once its pose has arrived.
fn map_frames(
    mapper: &mut FrameMapper,
    handoff: &std::sync::mpsc::Receiver<Handoff>,
    stop: &AtomicBool,
    out: &tokio::sync::mpsc::Sender<FrameEvent>,
) -> WorkerEnd {
    use std::sync::mpsc::RecvTimeoutError;
    while !stop.load(Ordering::Relaxed) {
        // While frames wait for poses, look for new poses often; else sleep until a frame.
        let wait = if mapper.waiting() == 0 { IDLE_WAIT } else { POSE_POLL };
        match handoff.recv_timeout(wait) {
            Ok(Handoff::Frame(f)) => mapper.queue(f, now_ns()),
            Ok(Handoff::Ended(end)) => return end,
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => return WorkerEnd::Stopped,
        }
        let events = match mapper.map_ready(now_ns()) {
            Ok(events) => events,
            Err(end) => return end,
        };
        for event in events {
            if out.blocking_send(event).is_err() {
                return WorkerEnd::Stopped;
            }
        }
        if mapper.recording_ended {
            return WorkerEnd::RecordingEnded;
        }
    }
    WorkerEnd::Stopped
}

/// How long an idle thread sleeps before looking at `stop` again.
const IDLE_WAIT: Duration = Duration::from_millis(100);
/// How often frames waiting for their poses look for them: a pose that arrives is used
/// within this, and a new frame wakes the map thread at once.
const POSE_POLL: Duration = Duration::from_millis(2);
/// Frames that may wait for their poses at once: 0.5 s of a 30 Hz camera, more than
/// `poses.max_wait_s` holds at its default.
pub const MAX_AWAITING: usize = 16;

/// An extracted frame, as it waits for its pose.
pub struct Extracted {
    pub polygons: FramePolygons,
    /// The depth in metres, which clears the map where the frame sees through it.
    pub depth: Grid<f32>,
    pub intrinsics: Intrinsics,
    /// The frame as the camera gave it, kept only while recording.
    pub raw: Option<DepthFrame>,
}

/// Extracted frames to the map: each waits for the pose at its stamp (never holding up the
/// next extraction), then updates the map and becomes a [`FrameEvent`].
pub struct FrameMapper {
    body_camera: Isometry3<f64>,
    awaiting: AwaitingPose<Extracted>,
    poses: Arc<Mutex<PoseBuffer>>,
    map: Arc<Mutex<PolygonMap>>,
    pub counters: Arc<Counters>,
    /// Where mapped frames are recorded, if they are.
    pub recorder: Option<Recorder>,
    /// The recorder took its last frame: no more frames are mapped.
    pub recording_ended: bool,
}

impl FrameMapper {
    pub fn new(
        config: &Config,
        poses: Arc<Mutex<PoseBuffer>>,
        map: Arc<Mutex<PolygonMap>>,
        counters: Arc<Counters>,
    ) -> FrameMapper {
        let max_wait_ns = (config.poses.max_wait_s * 1e9) as u64;
        FrameMapper {
            body_camera: crate::pose::extrinsic(config),
            awaiting: AwaitingPose::new(MAX_AWAITING, max_wait_ns),
            poses,
            map,
            counters,
            recorder: None,
            recording_ended: false,
        }
    }

    /// Frames waiting for their poses.
    pub fn waiting(&self) -> usize {
        self.awaiting.len()
    }

    /// Queues a frame extracted at local time `now_ns` for its pose.
    pub fn queue(&mut self, frame: Extracted, now_ns: StampNs) {
        if let Some(Settled::Skipped(_, why)) = self.awaiting.push(frame.polygons.stamp_ns, frame, now_ns) {
            self.counters.count_skip(why);
        }
    }

    /// Maps every waiting frame whose pose is known at local time `now_ns`, in stamp order,
    /// and counts those that cannot get one; a panic in the map's update ends the worker.
    pub fn map_ready(&mut self, now_ns: StampNs) -> Result<Vec<FrameEvent>, WorkerEnd> {
        let settled = self.awaiting.settle(&mut self.poses.lock(), now_ns);
        let mut events = Vec::new();
        for s in settled {
            if self.recording_ended {
                break;
            }
            match s {
                Settled::Posed(mut frame, world_body) => {
                    let t_world_camera = crate::pose::world_camera(&world_body, &self.body_camera);
                    let mut map = self.map.lock();
                    let updated = std::panic::catch_unwind(AssertUnwindSafe(|| {
                        update_map(&mut map, &frame, &world_body, &t_world_camera)
                    }));
                    drop(map);
                    match updated {
                        Ok(event) => events.push(event),
                        Err(panic) => return Err(panicked("updating the map", panic, false)),
                    }
                    self.counters.processed.fetch_add(1, Ordering::Relaxed);
                    if let (Some(recorder), Some(raw)) = (&mut self.recorder, frame.raw.take()) {
                        let pose = Pose { stamp_ns: raw.stamp_ns, transform: t_world_camera };
                        self.recording_ended = !recorder.record(raw, frame.intrinsics, pose);
                    }
                }
                Settled::Skipped(frame, why) => {
                    self.counters.count_skip(why);
                    tracing::debug!("frame at {} ns skipped: {}", frame.polygons.stamp_ns, why.name());
                }
            }
        }
        Ok(events)
    }
}

/// One posed frame into the map.
fn update_map(
    m: &mut PolygonMap,
    frame: &Extracted,
    world_body: &Isometry3<f64>,
    t_world_camera: &Isometry3<f64>,
) -> FrameEvent {
    let from_version = m.version();
    let pose = crate::types::Pose { stamp_ns: frame.polygons.stamp_ns, transform: *t_world_camera };
    let update = m.update(&frame.polygons.polygons, &pose, &frame.intrinsics, Some(&frame.depth));
    let corrected = m.corrected(t_world_camera);
    let robot = m.corrected(world_body).translation.vector;
    let version = m.version();
    let labels = (frame.polygons.polygons.iter())
        .map(|p| update.placed.iter().find(|(frame_id, _)| *frame_id == p.id).and_then(|&(_, id)| m.label(id)))
        .collect();
    let mut polygons_of = |ids: &[u64]| ids.iter().filter_map(|&id| m.polygon(id)).collect::<Vec<_>>();
    FrameEvent {
        stamp_ns: frame.polygons.stamp_ns,
        from_version,
        version,
        robot: [robot.x, robot.y, robot.z],
        polygons: frame.polygons.polygons.iter().map(|p| p.transformed(&corrected)).collect(),
        labels,
        added: polygons_of(&update.added),
        changed: polygons_of(&update.changed),
        removed: update.removed,
        drift_z: m.drift.z,
        drift_var: m.drift.var(),
        map_from_odometry: m.drift.transform().inverse(),
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
