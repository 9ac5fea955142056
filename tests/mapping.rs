//! Whole sequences through extraction and the map, scored against the synthetic truth:
//! drift compensation on straight stairs, wedge shapes on spiral stairs, clearing a moved box,
//! and recovery from a snapshot after kill -9.

use std::path::Path;
use std::process::Command;

use polymap::config::{Backend, Config};
use polymap::eval::map::{MapSummary, score_map, summarise};
use polymap::extract::{Extraction, Extractor, depth_metres};
use polymap::map::{Label, PolygonMap};
use polymap::sequence::Sequence;
use polymap::synth::{self, JumpOptions, NoiseModel, SceneKind, SynthOptions, scene};
use polymap::types::DepthFrame;

fn cpu_config() -> Config {
    let mut c = Config::default();
    // The CPU twin is the faster one on CI's software Vulkan; the map does not care which.
    c.pipeline.backend = Backend::Cpu;
    c
}

fn make(dir: &Path, opts: &SynthOptions) -> Sequence {
    synth::generate(opts, dir, |_, _| {}).unwrap();
    Sequence::open(dir).unwrap()
}

/// Extracts every frame once and feeds each map, returning their summaries.
fn map_sequence(seq: &Sequence, configs: &[Config]) -> Vec<(PolygonMap, MapSummary)> {
    let mut extractor = Extractor::new(&configs[0].pipeline).unwrap();
    let mut maps: Vec<PolygonMap> = configs.iter().map(|c| PolygonMap::new(&c.map)).collect();
    for k in 0..seq.len() {
        let Extraction { polygons: frame, depth, .. } =
            extractor.extract(&seq.depth(k).unwrap(), &seq.intrinsics).unwrap();
        for map in &mut maps {
            let update = map.update(&frame.polygons, &seq.poses[k], &seq.intrinsics, Some(&depth));
            assert!(update.rejected.is_empty(), "{:?}", update.rejected);
        }
    }
    maps.into_iter()
        .map(|mut m| {
            let snap = m.snapshot();
            let (scores, _) = score_map(&snap, seq, false).unwrap();
            for s in &scores {
                eprintln!("step {} IOU {:.3} height error {:?}", s.step, s.iou, s.height_error);
            }
            let summary = summarise(&scores, &snap, seq);
            eprintln!("{summary:?}");
            (m, summary)
        })
        .collect()
}

#[test]
fn straight_stairs_with_drift_map_true_to_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let opts = SynthOptions { width: 640, frames: 40, drift_mm_per_frame: 2.0, seed: 11, ..SynthOptions::default() };
    let seq = make(dir.path(), &opts);
    let filtered = cpu_config();
    let mut unfiltered = cpu_config();
    unfiltered.map.drift_filter = false;
    let results = map_sequence(&seq, &[filtered, unfiltered]);
    let (map, with) = &results[0];
    let (_, without) = &results[1];

    assert!(with.treads_seen >= 6, "the walk sees most of the flight: {}", with.treads_seen);
    assert_eq!(with.treads_found, with.treads_seen, "every tread seen is in the map");
    assert!(with.iou_mean >= 0.95, "IOU mean {:.3}", with.iou_mean);
    // The top tread seen is seen well only by the last frame or two.
    assert!(with.iou_min >= 0.94, "IOU min {:.3}", with.iou_min);
    assert!(with.step_error_mean_mm <= 1.0, "step-height error {:.2} mm", with.step_error_mean_mm);
    assert!(with.height_error_max_mm <= 5.0, "height error {:.2} mm", with.height_error_max_mm);
    assert!(with.drift_error_mm.abs() <= 5.0, "drift estimate off by {:.2} mm", with.drift_error_mm);
    assert!(map.drift.var() > 0.0 && map.drift.var() < 1e-5);

    // Without the filter the drift (78 mm by the end) lands in the map.
    assert!(without.height_error_mean_mm > 5.0 * with.height_error_mean_mm.max(2.0), "{without:?}");
    assert!(without.step_error_mean_mm > 3.0 * with.step_error_mean_mm.max(1.0), "{without:?}");

    let stair = map.stair().expect("a stair is recognised");
    assert!((stair.step_height - 0.15).abs() < 0.003, "step height {}", stair.step_height);
    assert!((stair.tread_depth.unwrap() - 0.28).abs() < 0.01, "tread depth {:?}", stair.tread_depth);
}

#[test]
fn spiral_wedges_keep_their_shape_and_stay_apart() {
    let dir = tempfile::tempdir().unwrap();
    let opts = SynthOptions { scene: SceneKind::Spiral, width: 640, frames: 30, seed: 5, ..SynthOptions::default() };
    let seq = make(dir.path(), &opts);
    let results = map_sequence(&seq, &[cpu_config()]);
    let (mut map, summary) = results.into_iter().next().unwrap();
    assert!(summary.treads_seen >= 8, "{summary:?}");
    assert_eq!(summary.treads_found, summary.treads_seen);
    assert!(summary.iou_mean >= 0.9, "IOU mean {:.3}", summary.iou_mean);
    assert!(summary.iou_min >= 0.85, "IOU min {:.3}", summary.iou_min);
    // No two treads in one polygon: each tread's best match is its own.
    let (scores, _) = score_map(&map.snapshot(), &seq, false).unwrap();
    let mut ids: Vec<u64> = scores.iter().filter_map(|s| s.polygon).collect();
    let n = ids.len();
    ids.sort_unstable();
    ids.dedup();
    assert_eq!(ids.len(), n, "two treads matched the same map polygon");
    let treads = map.snapshot().polygons.iter().filter(|p| p.label == Label::Tread).count();
    assert!(treads >= 7, "{treads} polygons labelled tread");
}

#[test]
fn a_moved_box_is_cleared_within_five_frames() {
    let intr = SynthOptions::default().intrinsics();
    let before = scene::box_scene();
    let moved_to = [1.0, 0.45];
    let after = scene::box_scene_at(moved_to);
    let poses = synth::path::trajectory(&before, 24);
    let noise = NoiseModel::l515(2.0);
    let mut extractor = Extractor::new(&cpu_config().pipeline).unwrap();
    let mut map = PolygonMap::new(&cpu_config().map);
    let top_at = |map: &mut PolygonMap, xy: [f64; 2]| {
        map.snapshot().polygons.iter().any(|p| {
            p.label.is_horizontal()
                && (p.centroid[2] - scene::BOX_SIZE[2]).abs() < 0.03
                && (p.centroid[0] - xy[0]).hypot(p.centroid[1] - xy[1]) < 0.15
        })
    };
    const MOVE_AT: usize = 12;
    let mut cleared_at = None;
    for (k, pose) in poses.iter().enumerate() {
        let scene = if k < MOVE_AT { &before } else { &after };
        let render = synth::render(scene, &intr, pose);
        let frame = DepthFrame {
            stamp_ns: synth::stamp_ns(k, 30.0),
            width: intr.width,
            height: intr.height,
            depth_scale: intr.depth_scale,
            pixels: synth::noisy_depth(&render, &noise, 3, k),
        };
        let polys = extractor.extract(&frame, &intr).unwrap().polygons;
        let depth = depth_metres(&frame, &intr).unwrap();
        let pose = polymap::types::Pose { stamp_ns: frame.stamp_ns, transform: *pose };
        map.update(&polys.polygons, &pose, &intr, Some(&depth));
        if k == MOVE_AT - 1 {
            assert!(top_at(&mut map, scene::BOX_CENTER), "the box top is mapped before it moves");
        }
        if k >= MOVE_AT && cleared_at.is_none() && !top_at(&mut map, scene::BOX_CENTER) {
            cleared_at = Some(k);
        }
    }
    let cleared_at = cleared_at.expect("the old box top is never cleared");
    eprintln!("old box top cleared {} frames after the move", cleared_at - MOVE_AT + 1);
    assert!(cleared_at < MOVE_AT + 5, "cleared {} frames after the move", cleared_at - MOVE_AT + 1);
    assert!(top_at(&mut map, moved_to), "the box top is mapped where it went");
    assert!(map.counters.cleared >= 1);
}

#[test]
fn kill_9_during_replay_then_replay_loads_the_last_snapshot() {
    let dir = tempfile::tempdir().unwrap();
    let snapshot = dir.path().join("map.json");
    let config = dir.path().join("polymap.toml");
    std::fs::write(
        &config,
        format!(
            "[pipeline]\nbackend = \"cpu\"\n[map]\nsnapshot_path = {:?}\nsnapshot_period_s = 0.1\nload_at_start = true\n",
            snapshot.display().to_string()
        ),
    )
    .unwrap();
    let seq = Path::new(env!("CARGO_MANIFEST_DIR")).join("mock_frames/straight_320");
    let replay = || {
        let mut c = Command::new(env!("CARGO_BIN_EXE_polymap"));
        c.arg("replay").arg(&seq).arg("--config").arg(&config);
        c
    };
    let log_path = dir.path().join("first-run.log");
    let mut child = replay().stderr(std::fs::File::create(&log_path).unwrap()).spawn().unwrap();
    // Kill it as soon as a snapshot exists, mid-run.
    let started = std::time::Instant::now();
    while !snapshot.exists() {
        assert!(started.elapsed().as_secs() < 120, "no snapshot written");
        if child.try_wait().unwrap().is_some() {
            panic!("replay ended before it could be killed: {}", std::fs::read_to_string(&log_path).unwrap());
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();

    // Whatever moment it died at, the file is a whole snapshot (written aside, then renamed).
    let text = std::fs::read_to_string(&snapshot).unwrap();
    let snap: polymap::map::MapSnapshot = serde_json::from_str(&text).expect("a whole snapshot");
    assert!(!snap.polygons.is_empty());
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tmp."))
        .collect();
    eprintln!("temporary files left by the kill: {leftovers:?}");

    let out = replay().output().unwrap();
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{log}");
    assert!(log.contains("map loaded from"), "the second run loads the snapshot: {log}");
    let last: polymap::map::MapSnapshot = serde_json::from_str(&std::fs::read_to_string(&snapshot).unwrap()).unwrap();
    let cfg = Config::load(&config).unwrap();
    PolygonMap::from_snapshot(&cfg.map, &last).expect("the final map is valid");
    assert!(last.polygons.iter().any(|p| p.label == Label::Tread));
}

/// Odometry drifting in x, y and yaw as a visual-inertial one does (1 % of the walk seen from
/// above, 0.5 deg of yaw over it), its height as well, and a loop closure's step half way:
/// the map as sharp as with exact poses, and sharper than the vertical filter alone makes it.
#[test]
fn horizontal_and_yaw_drift_and_a_step_are_taken_out_of_the_map() {
    for (scene, seed) in [(SceneKind::Straight, 2), (SceneKind::Spiral, 3)] {
        let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        let exact_opts = SynthOptions { scene, frames: 60, seed, ..SynthOptions::default() };
        let exact = make(a.path(), &exact_opts);
        // Both walks are about 2.5 m long seen from above: 1 % of that over 59 frames.
        let drifting = SynthOptions {
            drift_mm_per_frame: 0.2,
            drift_xy_mm_per_frame: [0.3, 0.3],
            drift_yaw_deg_per_frame: 0.5 / 59.0,
            jump: Some(JumpOptions { frame: 30, xyz_mm: [70.7, 70.7, 0.0], yaw_deg: 1.0 }),
            ..exact_opts
        };
        let seq = make(b.path(), &drifting);
        let (_, reference) = map_sequence(&exact, &[cpu_config()]).remove(0);
        let mut vertical = cpu_config();
        vertical.map.drift_horizontal = false;
        let results = map_sequence(&seq, &[cpu_config(), vertical]);
        let ((map, with), (_, without)) = (&results[0], &results[1]);
        assert_eq!(map.counters.odometry_steps, 1, "{scene:?}: the step is taken in once");
        assert!(
            with.iou_mean >= reference.iou_mean - 0.01,
            "{scene:?}: IOU {:.3} against {:.3}",
            with.iou_mean,
            reference.iou_mean
        );
        assert!(with.height_error_max_mm <= 2.0, "{scene:?}: height error {:.2} mm", with.height_error_max_mm);
        assert!(with.drift_error_xy_mm <= 10.0 && with.drift_error_yaw_deg.abs() <= 0.3, "{scene:?}: {with:?}");
        assert!(without.iou_mean < with.iou_mean - 0.02, "{scene:?}: heights alone leave it smeared: {without:?}");
    }
}
