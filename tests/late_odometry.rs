//! Mapping with the odometry VINS-Fusion really delivers (10-20 Hz, 50 ms late, jittery), on
//! a simulated clock stepped a millisecond at a time, so nothing depends on this machine's
//! speed: the mock camera's frames at 30 Hz (the looped walk, forward and back), each taking
//! the extractor 20 ms of simulated time, poses published as the mock VINS times them. The
//! extractor's thread is modelled step by step as `runtime::worker` runs it: a newest-frame
//! slot, an extraction when idle, the waiting frames settled after every step.
//!
//! Beside the model, the real worker (`runtime::worker::spawn`, its threads and slot) fed
//! faster than it extracts: the newest frame wins and every frame replaced is counted.

use std::sync::Arc;

use parking_lot::Mutex;
use polymap::config::{Backend, Config};
use polymap::extract::{Extractor, FramePolygons, Grid};
use polymap::map::{Label, PolygonMap};
use polymap::mock::SequenceClock;
use polymap::mock::vins::{MockVinsOptions, PoseTiming};
use polymap::pose::{PoseBuffer, PoseLimits, RawPose};
use polymap::runtime::slot::Slot;
use polymap::runtime::status::Counters;
use polymap::runtime::worker::{Extracted, FrameMapper, Shared};
use polymap::sequence::Sequence;
use polymap::types::{Pose, StampNs};

const MS: StampNs = 1_000_000;
/// Simulated time the extractor takes a frame.
const EXTRACT_MS: StampNs = 20;
/// Simulated length of a run: the 1 s walk three times forward and back.
const RUN_MS: StampNs = 6000;
/// Poses keep coming this long after the last frame, so every frame can get one.
const TAIL_MS: StampNs = 500;

struct Outcome {
    frames: u64,
    /// Frames whose stamp has poses on both sides, within the gap bound.
    bracketed: u64,
    processed: u64,
    report: polymap::runtime::status::Report,
    map: PolygonMap,
}

/// Each of the walk's frames extracted once (the simulation reuses them).
fn extracted(seq: &Sequence, config: &Config) -> Vec<(FramePolygons, Grid<f32>)> {
    let mut extractor = Extractor::new(&config.pipeline).unwrap();
    (0..seq.len())
        .map(|k| {
            let extraction = extractor.extract(&seq.depth(k).unwrap(), &seq.intrinsics).unwrap();
            (extraction.polygons, extraction.depth)
        })
        .collect()
}

fn simulate(seq: &Sequence, frames: &[(FramePolygons, Grid<f32>)], config: &Config, vins: MockVinsOptions) -> Outcome {
    let clock = SequenceClock::new(seq).unwrap();
    let stamps: Vec<StampNs> = seq.poses.iter().map(|p| p.stamp_ns).collect();
    let mut truth = PoseBuffer::new(seq.len(), u64::MAX);
    for p in &seq.poses {
        truth.push(&RawPose::from(p)).unwrap();
    }
    // Wall time starts at a loop's start (forward and back: twice the walk), days after the epoch.
    let t0 = 1_000_000 * 2 * (stamps[stamps.len() - 1] - stamps[0]);
    let limits = PoseLimits::from_config(&config.poses);
    let poses = Arc::new(Mutex::new(PoseBuffer::with_limits(4096, limits)));
    let map = Arc::new(Mutex::new(PolygonMap::new(&config.map)));
    let counters = Arc::new(Counters::default());
    let mut mapper = FrameMapper::new(config, poses.clone(), map.clone(), counters.clone());

    let mut timing = PoseTiming::new(&vins, t0);
    let mut next_pose = timing.next_pose();
    let mut propagated = vins.propagated().map(|p| PoseTiming::new(&p, t0));
    let mut next_propagated = propagated.as_mut().map(|p| p.next_pose());
    let mut pose_stamps = Vec::new();
    let mut next_frame = clock.next_frame(t0, &stamps);
    let mut frame_stamps = Vec::new();
    let mut slot: Option<(StampNs, usize)> = None;
    let mut busy: Option<(StampNs, StampNs, usize)> = None;
    for t in (t0..=t0 + (RUN_MS + TAIL_MS) * MS).step_by(MS as usize) {
        while next_pose.1 <= t {
            let (stamp, _) = next_pose;
            let pose = truth.at(clock.sequence_time(stamp)).unwrap();
            poses.lock().push_at(&RawPose::from(&Pose { stamp_ns: stamp, transform: pose }), t).unwrap();
            pose_stamps.push(stamp);
            next_pose = timing.next_pose();
        }
        while let (Some(p), Some((stamp, at))) = (propagated.as_mut(), next_propagated)
            && at <= t
        {
            let pose = truth.at(clock.sequence_time(stamp)).unwrap();
            poses.lock().push_propagated_at(&RawPose::from(&Pose { stamp_ns: stamp, transform: pose }), t).unwrap();
            next_propagated = Some(p.next_pose());
        }
        if next_frame.0 <= t && t <= t0 + RUN_MS * MS {
            frame_stamps.push(next_frame.0);
            // The extractor is idle whenever a frame comes (20 of every 33 ms busy).
            assert!(slot.replace((next_frame.0, next_frame.1)).is_none(), "the modelled slot replaced a frame");
            next_frame = clock.next_frame(next_frame.0, &stamps);
        }
        if let Some((stamp, _, k)) = busy.filter(|&(_, done, _)| done <= t) {
            let (mut polygons, depth) = frames[k].clone();
            polygons.stamp_ns = stamp;
            mapper.queue(Extracted { polygons, depth, intrinsics: seq.intrinsics, raw: None }, t);
            busy = None;
        }
        if busy.is_none()
            && let Some((stamp, k)) = slot.take()
        {
            busy = Some((stamp, t + EXTRACT_MS * MS, k));
        }
        mapper.map_ready(t).unwrap_or_else(|_| panic!("the map update panicked"));
    }
    let max_gap = (config.poses.max_gap_s * 1e9) as StampNs;
    let bracketed = frame_stamps
        .iter()
        .filter(|&&s| {
            let after = pose_stamps.partition_point(|&p| p < s);
            after > 0 && after < pose_stamps.len() && pose_stamps[after] - pose_stamps[after - 1] <= max_gap
        })
        .count() as u64;
    let report = counters.report(Default::default(), poses.lock().counters, 0.0, 0);
    drop(mapper);
    Outcome {
        frames: frame_stamps.len() as u64,
        bracketed,
        processed: report.processed,
        report,
        map: Arc::try_unwrap(map).ok().unwrap().into_inner(),
    }
}

/// The map's treads: step index and height.
fn treads(mut map: PolygonMap) -> Vec<(u32, f64)> {
    let mut t: Vec<(u32, f64)> = map
        .snapshot()
        .polygons
        .iter()
        .filter(|p| p.label == Label::Tread)
        .map(|p| (p.step.unwrap_or(0), p.centroid[2]))
        .collect();
    t.sort_by(|a, b| a.partial_cmp(b).unwrap());
    t
}

fn straight_walk() -> (Sequence, Config, Vec<(FramePolygons, Grid<f32>)>) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let seq = Sequence::open(root.join("mock_frames/straight_320")).unwrap();
    let mut config = Config::default();
    config.pipeline.backend = Backend::Cpu;
    let frames = extracted(&seq, &config);
    (seq, config, frames)
}

const RATES_HZ: [f64; 3] = [10.0, 15.0, 20.0];

fn robot_vins(rate_hz: f64, propagate_hz: f64) -> MockVinsOptions {
    MockVinsOptions { rate_hz, latency_ms: 50.0, jitter_ms: 10.0, propagate_hz, ..MockVinsOptions::ROBOT }
}

#[test]
fn late_jittery_odometry_at_10_to_20_hz_maps_every_frame_without_holding_up_extraction() {
    let (seq, config, frames) = straight_walk();
    for rate_hz in RATES_HZ {
        // The optimised odometry alone: frames wait for the pose after them.
        let run = simulate(&seq, &frames, &config, robot_vins(rate_hz, 0.0));
        let r = &run.report;
        eprintln!(
            "{rate_hz} Hz: {} frames, {} with poses on both sides, {} mapped; {r}",
            run.frames, run.bracketed, run.processed
        );
        assert!(run.frames >= 170, "{rate_hz} Hz: {} frames in 6 s at 30 Hz", run.frames);
        assert!(
            run.processed * 100 >= run.bracketed * 95,
            "{rate_hz} Hz: {} of {} frames with poses around them mapped",
            run.processed,
            run.bracketed
        );
        assert_eq!(r.without_pose + r.processed, run.frames, "{rate_hz} Hz: every frame mapped or counted");
    }
}

#[test]
fn with_vins_propagated_poses_the_map_is_the_prompt_odometrys() {
    let (seq, config, frames) = straight_walk();
    let prompt = MockVinsOptions { latency_ms: 0.0, jitter_ms: 0.0, ..robot_vins(100.0, 0.0) };
    let reference = treads(simulate(&seq, &frames, &config, prompt).map);
    assert!(reference.len() >= 3, "the walk's treads, mapped with prompt odometry: {reference:?}");
    for rate_hz in RATES_HZ {
        // Straight lines between 10-20 Hz poses miss the mock walk's sway (an 8 Hz bob): the
        // map is off by millimetres. Say how far, for the record.
        let straight = treads(simulate(&seq, &frames, &config, robot_vins(rate_hz, 0.0)).map);
        let worst = straight.iter().zip(&reference).map(|(a, b)| (a.1 - b.1).abs()).fold(0.0, f64::max);
        eprintln!("{rate_hz} Hz, optimised poses alone: treads {straight:?}, worst height {:.2} mm off", worst * 1e3);
        // With the propagated stream between them, the map is the prompt odometry's: the
        // same treads, heights within a millimetre.
        let run = simulate(&seq, &frames, &config, robot_vins(rate_hz, 200.0));
        assert!(run.processed * 100 >= run.bracketed * 95, "{rate_hz} Hz: {}", run.report);
        let got = treads(run.map);
        assert_eq!(got.len(), reference.len(), "{rate_hz} Hz: treads {got:?} vs {reference:?}");
        for (a, b) in got.iter().zip(&reference) {
            assert_eq!(a.0, b.0, "{rate_hz} Hz: step indices {got:?} vs {reference:?}");
            assert!((a.1 - b.1).abs() < 1e-3, "{rate_hz} Hz: tread {} at {} m vs {} m", a.0, a.1, b.1);
        }
    }
}

#[test]
fn frames_between_poses_further_apart_than_the_gap_bound_are_refused_and_counted() {
    let (seq, config, frames) = straight_walk();
    // 3 Hz odometry: poses 333 ms apart, beyond the 250 ms bound.
    let run = simulate(&seq, &frames, &config, robot_vins(3.0, 0.0));
    // A frame whose next pose comes within its wait is refused for the gap; one stamped
    // less than 83 ms after a pose gives up waiting first (the next comes 383 ms after that).
    use polymap::runtime::awaiting::Skip;
    let (gap, late) = (run.report.skipped[Skip::Gap as usize], run.report.skipped[Skip::TooLate as usize]);
    assert!(gap * 3 >= run.frames * 2, "{} of {} frames refused for the gap: {}", gap, run.frames, run.report);
    assert_eq!(gap + late + run.processed, run.frames, "every frame counted: {}", run.report);
    assert!(run.processed * 20 <= run.frames, "only frames on a pose's stamp: {}", run.report);
}

/// The real worker, its camera a stepped source that offers three frames at once, each
/// burst after the last burst's newest frame was mapped: faster than any extraction, whatever
/// the machine. The newest frame of each burst is mapped, the frames mapped come in stamp
/// order, and every frame that came in is mapped or counted dropped.
#[test]
fn the_worker_fed_faster_than_it_extracts_maps_the_newest_frame_and_counts_each_dropped() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let seq = Sequence::open(root.join("mock_frames/straight_320")).unwrap();
    let mut config = Config::default();
    config.pipeline.backend = Backend::Cpu;
    let poses = Arc::new(Mutex::new(PoseBuffer::with_limits(4096, PoseLimits::from_config(&config.poses))));
    for p in &seq.poses {
        poses.lock().push(&RawPose::from(p)).unwrap();
    }
    let (slot, counters) = (Arc::new(Slot::default()), Arc::new(Counters::default()));
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let shared = Shared {
        slot: slot.clone(),
        stop: stop.clone(),
        poses,
        map: Arc::new(Mutex::new(PolygonMap::new(&config.map))),
        counters: counters.clone(),
    };
    let (events_tx, mut events) = tokio::sync::mpsc::channel(64);
    let worker = polymap::runtime::worker::spawn(&config, shared, None, events_tx).unwrap();
    let (mut mapped, mut newest) = (Vec::new(), Vec::new());
    // Frames 1..=27 in bursts of three (frame 0 has no pose before it).
    for burst in (1..seq.len() - 2).step_by(3).take(9) {
        let frames: Vec<_> = (burst..burst + 3).map(|k| seq.depth(k).unwrap()).collect();
        for frame in frames {
            slot.offer((frame, seq.intrinsics), &counters);
        }
        let last = seq.poses[burst + 2].stamp_ns;
        newest.push(last);
        // The bound fails only on a hang: a frame takes well under a second to extract.
        let wait = std::time::Instant::now();
        while mapped.last() != Some(&last) {
            assert!(wait.elapsed() < std::time::Duration::from_secs(120), "burst at frame {burst} never mapped");
            match events.try_recv() {
                Ok(event) => mapped.push(event.stamp_ns),
                Err(tokio::sync::mpsc::error::TryRecvError::Empty) => {
                    std::thread::sleep(std::time::Duration::from_millis(5))
                }
                Err(e) => panic!("the worker ended: {e}"),
            }
        }
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    assert!(matches!(worker.join().unwrap(), polymap::runtime::worker::WorkerEnd::Stopped));
    let r = counters.report(Default::default(), Default::default(), 0.0, 0);
    eprintln!("mapped {mapped:?}; {r}");
    assert!(newest.iter().all(|s| mapped.contains(s)), "each burst's newest frame mapped: {mapped:?}");
    assert!(mapped.windows(2).all(|w| w[0] < w[1]), "frames mapped in stamp order: {mapped:?}");
    assert_eq!(r.frames_in, 27, "{r}");
    assert_eq!(r.processed, mapped.len() as u64, "{r}");
    assert_eq!(r.without_pose + r.extraction_failed, 0, "{r}");
    // Three frames offered at once: the first is taken or replaced, so at least one of each
    // burst's first two is replaced before the extractor is free again.
    assert!(r.dropped >= 9, "at least one frame of each burst dropped: {r}");
    assert_eq!(r.processed + r.dropped, r.frames_in, "every frame mapped or counted dropped: {r}");
}
