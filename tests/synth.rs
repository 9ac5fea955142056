//! The synthetic world: exact ray casting, truth that matches the scene, labels that
//! match the hits, a noise model that does what it says, determinism.

use std::f64::consts::FRAC_PI_2;
use std::fs;
use std::path::Path;

use nalgebra::{Point3, Vector3};
use polymap::sequence::{Sequence, TruthPolygon};
use polymap::synth::path::{camera_pose, trajectory};
use polymap::synth::scene::{SpiralStair, StraightStair};
use polymap::synth::{self, NoiseModel, Scene, SceneKind, SynthOptions, noisy_depth, render};
use polymap::types::Intrinsics;

fn small() -> Intrinsics {
    Intrinsics::L515_320X240.scaled_to(64, 48)
}

#[test]
fn looking_straight_down_sees_the_floor_at_camera_height() {
    let scene = Scene::build(SceneKind::Straight);
    let h = 1.234_567;
    let pose = camera_pose(Point3::new(-3.0, 0.2, h), 0.3, FRAC_PI_2, 0.0);
    let r = render(&scene, &small(), &pose);
    assert!(r.labels.iter().all(|&l| scene.surfaces[l as usize - 1].label == "floor"));
    for d in &r.depth_m {
        assert!((d - h).abs() < 1e-6, "depth {d} vs height {h}");
    }
}

#[test]
fn tilted_camera_depth_matches_the_analytic_floor_distance() {
    // Camera at height h, optical axis `pitch` below the horizon: a pixel whose
    // normalised image row is y sees the floor at depth h / (sin(pitch) + y cos(pitch)).
    let scene = Scene::build(SceneKind::Straight);
    let (h, pitch) = (0.95, 0.8);
    let intr = Intrinsics::L515_320X240;
    let pose = camera_pose(Point3::new(-4.0, 0.0, h), 0.0, pitch, 0.0);
    let r = render(&scene, &intr, &pose);
    let mut checked = 0;
    for &(u, v) in &[(0u32, 239u32), (160, 120), (319, 200), (10, 150), (300, 130), (157, 239)] {
        let i = (v * intr.width + u) as usize;
        assert_eq!(scene.surfaces[r.labels[i] as usize - 1].label, "floor", "pixel ({u},{v})");
        let y = (v as f64 - intr.cy) / intr.fy;
        let expected = h / (pitch.sin() + y * pitch.cos());
        assert!((r.depth_m[i] - expected).abs() < 1e-6, "pixel ({u},{v}): {} vs {expected}", r.depth_m[i]);
        checked += 1;
    }
    assert_eq!(checked, 6);
}

#[test]
fn depth_over_a_tread_is_height_above_it() {
    let p = StraightStair::default();
    let scene = Scene::build(SceneKind::Straight);
    let h = 2.0;
    // Above the middle of tread 3, looking straight down: the centre ray hits tread 3.
    let x = 2.5 * p.going;
    let intr = small();
    let pose = camera_pose(Point3::new(x, 0.0, h), 0.0, FRAC_PI_2, 0.0);
    let r = render(&scene, &intr, &pose);
    // The pixel whose ray is closest to the optical axis.
    let (u, v) = (intr.cx.round() as u32, intr.cy.round() as u32);
    let i = (v * intr.width + u) as usize;
    let hit = &scene.surfaces[r.labels[i] as usize - 1];
    assert_eq!((hit.label, hit.step), ("tread", Some(3)));
    assert!((r.depth_m[i] - (h - 3.0 * p.rise)).abs() < 1e-6);
}

fn polygon_area_xy(b: &[[f64; 3]]) -> f64 {
    (0..b.len()).map(|i| b[i][0] * b[(i + 1) % b.len()][1] - b[(i + 1) % b.len()][0] * b[i][1]).sum::<f64>() / 2.0
}

fn extent(b: &[[f64; 3]], axis: usize) -> f64 {
    let vals = b.iter().map(|p| p[axis]);
    vals.clone().fold(f64::MIN, f64::max) - vals.fold(f64::MAX, f64::min)
}

#[test]
fn straight_truth_matches_the_stair_dimensions() {
    let p = StraightStair::default();
    let truth = Scene::build(SceneKind::Straight).truth();
    let st = truth.stair.as_ref().unwrap();
    assert_eq!((st.steps, st.rise, st.going, st.width), (p.steps, p.rise, p.going, p.width));
    let treads: Vec<&TruthPolygon> = truth.polygons.iter().filter(|t| t.label == "tread").collect();
    assert_eq!(treads.len() as u32, p.steps - 1);
    for (k, t) in treads.iter().enumerate() {
        let step = k as u32 + 1;
        assert_eq!(t.step, Some(step));
        assert!(t.boundary.iter().all(|v| (v[2] - step as f64 * p.rise).abs() < 1e-12));
        assert!((t.height - step as f64 * p.rise).abs() < 1e-12);
        assert!((extent(&t.boundary, 0) - p.going).abs() < 1e-12);
        assert!((extent(&t.boundary, 1) - p.width).abs() < 1e-12);
        assert!(polygon_area_xy(&t.boundary) > 0.0, "counter-clockwise seen from above");
    }
    let risers: Vec<&TruthPolygon> = truth.polygons.iter().filter(|t| t.label == "riser").collect();
    assert_eq!(risers.len() as u32, p.steps);
    for r in risers {
        assert!((extent(&r.boundary, 2) - p.rise).abs() < 1e-12);
        assert!(extent(&r.boundary, 0) < 1e-12, "risers are vertical, across the stair");
    }
    let landing = truth.polygons.iter().find(|t| t.label == "landing").unwrap();
    assert!((landing.height - p.steps as f64 * p.rise).abs() < 1e-12);
}

#[test]
fn spiral_truth_has_wedge_treads() {
    let p = SpiralStair::default();
    let truth = Scene::build(SceneKind::Spiral).truth();
    let treads: Vec<&TruthPolygon> = truth.polygons.iter().filter(|t| t.label == "tread").collect();
    assert_eq!(treads.len() as u32, p.steps - 1);
    // An annular sector of the step angle, drawn with straight segments: area within 1 %.
    let sector = 0.5 * p.step_angle * (p.outer_radius.powi(2) - p.post_radius.powi(2));
    for (k, t) in treads.iter().enumerate() {
        let area = polygon_area_xy(&t.boundary);
        assert!((area / sector - 1.0).abs() < 0.01, "tread {}: area {area} vs sector {sector}", k + 1);
        assert!((t.height - (k + 1) as f64 * p.rise).abs() < 1e-12);
        let radii: Vec<f64> = t.boundary.iter().map(|v| v[0].hypot(v[1])).collect();
        assert!(radii.iter().all(|r| (r - p.outer_radius).abs() < 1e-9 || (r - p.post_radius).abs() < 1e-9));
        // Wedge: the tread starts where the previous one ends, k step angles round.
        let start = k as f64 * p.step_angle;
        let turned = |v: &[f64; 3]| (v[1].atan2(v[0]) - start).rem_euclid(std::f64::consts::TAU);
        assert!(t.boundary.iter().any(|v| turned(v) < 1e-9 || turned(v) > std::f64::consts::TAU - 1e-9));
    }
}

/// Checks that each labelled pixel's back-projected hit lies on its truth polygon.
fn assert_labels_match_hits(
    scene: &Scene,
    intr: &Intrinsics,
    labels: &[u16],
    depth_m: &[f64],
    pose: &nalgebra::Isometry3<f64>,
) -> usize {
    let truth = scene.truth();
    let mut on_surface = 0;
    for v in 0..intr.height {
        for u in 0..intr.width {
            let i = (v * intr.width + u) as usize;
            assert_eq!(labels[i] == 0, depth_m[i] == 0.0, "pixel ({u},{v}): label {} depth {}", labels[i], depth_m[i]);
            if labels[i] == 0 {
                continue;
            }
            let p = pose * intr.back_project(u as f64, v as f64, depth_m[i]);
            let poly = &truth.polygons[labels[i] as usize - 1];
            let b: Vec<Vector3<f64>> = poly.boundary.iter().map(|c| Vector3::new(c[0], c[1], c[2])).collect();
            let n = (b[1] - b[0]).cross(&(b[2] - b[0])).normalize();
            assert!(n.dot(&(p.coords - b[0])).abs() < 1e-6, "pixel ({u},{v}) is off the plane of {} ", poly.label);
            assert!(inside(&p.coords, &b, &n), "pixel ({u},{v}) hit {} outside its outline", poly.label);
            on_surface += 1;
        }
    }
    on_surface
}

/// Point-in-polygon after dropping the normal's dominant axis.
fn inside(p: &Vector3<f64>, b: &[Vector3<f64>], n: &Vector3<f64>) -> bool {
    let drop = n.iamax();
    let (a, c) = match drop {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    let tol = 1e-7;
    let mut winding = false;
    for i in 0..b.len() {
        let (p0, p1) = (b[i], b[(i + 1) % b.len()]);
        // On an edge counts as inside.
        let e = p1 - p0;
        let t = ((p - p0).dot(&e) / e.norm_squared()).clamp(0.0, 1.0);
        if (p0 + e * t - p).norm() < tol {
            return true;
        }
        if (p0[c] > p[c]) != (p1[c] > p[c]) && p[a] < (p1[a] - p0[a]) * (p[c] - p0[c]) / (p1[c] - p0[c]) + p0[a] {
            winding = !winding;
        }
    }
    winding
}

#[test]
fn labels_mark_exactly_the_pixels_the_ray_cast_hit() {
    for kind in [SceneKind::Straight, SceneKind::Spiral, SceneKind::Box] {
        let scene = Scene::build(kind);
        let intr = Intrinsics::L515_320X240.scaled_to(96, 72);
        for pose in trajectory(&scene, 5) {
            let r = render(&scene, &intr, &pose);
            let n = assert_labels_match_hits(&scene, &intr, &r.labels, &r.depth_m, &pose);
            assert!(n > r.labels.len() / 2, "{kind:?}: the camera sees the scene");
        }
    }
}

#[test]
fn written_labels_are_the_ray_cast_labels() {
    let dir = tempfile::tempdir().unwrap();
    let opts = SynthOptions { scene: SceneKind::Spiral, width: 64, frames: 4, ..SynthOptions::default() };
    synth::generate(&opts, dir.path(), |_, _| {}).unwrap();
    let seq = Sequence::open(dir.path()).unwrap();
    let scene = Scene::build(SceneKind::Spiral);
    for (k, pose) in trajectory(&scene, 4).iter().enumerate() {
        let r = render(&scene, &seq.intrinsics, pose);
        assert_eq!(seq.labels(k).unwrap(), r.labels, "frame {k}");
        // Noise never invents a return where the ray hit nothing.
        let depth = seq.depth(k).unwrap();
        assert!(depth.pixels.iter().zip(&r.labels).all(|(&d, &l)| d == 0 || l != 0));
    }
    assert_eq!(seq.truth.unwrap().polygons.len(), scene.surfaces.len());
}

#[test]
fn every_scene_shows_steps_along_the_walk() {
    for kind in [SceneKind::Straight, SceneKind::Spiral, SceneKind::Box] {
        let scene = Scene::build(kind);
        let intr = small();
        let poses = trajectory(&scene, 10);
        let treads_seen: usize = poses
            .iter()
            .map(|p| render(&scene, &intr, p))
            .filter(|r| {
                r.labels.iter().any(|&l| l > 0 && matches!(scene.surfaces[l as usize - 1].label, "tread" | "landing"))
            })
            .count();
        assert!(treads_seen >= 3, "{kind:?}: only {treads_seen} of 10 frames see a tread");
        // The walk climbs (or, for the box scene, stays on the floor).
        let rise = poses.last().unwrap().translation.z - poses[0].translation.z;
        match kind {
            SceneKind::Box => assert!(rise.abs() < 0.05),
            _ => assert!(rise > 0.3, "{kind:?} climbs only {rise} m"),
        }
    }
}

#[test]
fn noise_free_depth_is_the_quantised_truth() {
    let scene = Scene::build(SceneKind::Straight);
    let intr = small();
    let pose = trajectory(&scene, 3)[1];
    let r = render(&scene, &intr, &pose);
    let depth = noisy_depth(&r, &NoiseModel::l515(0.0), 7, 0);
    for (d, t) in depth.iter().zip(&r.depth_m) {
        if *t == 0.0 {
            assert_eq!(*d, 0);
        } else {
            assert!((*d as f64 * intr.depth_scale - t).abs() <= intr.depth_scale / 2.0 + 1e-12);
        }
    }
}

#[test]
fn range_noise_has_the_modelled_spread() {
    // Flat floor at 1 m straight below: range 1 m at the centre, normal incidence.
    let scene = Scene::build(SceneKind::Straight);
    let intr = Intrinsics::L515_320X240;
    let pose = camera_pose(Point3::new(-3.0, 0.0, 1.0), 0.0, FRAC_PI_2, 0.0);
    let r = render(&scene, &intr, &pose);
    let model = NoiseModel::l515(2.0);
    let depth = noisy_depth(&r, &model, 3, 0);
    let mut errs = Vec::new();
    for v in 100..140 {
        for u in 140..180 {
            let i = (v * intr.width + u) as usize;
            if depth[i] != 0 {
                let range_err = (depth[i] as f64 * intr.depth_scale - r.depth_m[i]) * r.ray_length(u as f64, v as f64);
                errs.push(range_err);
            }
        }
    }
    let n = errs.len() as f64;
    let mean = errs.iter().sum::<f64>() / n;
    let std = (errs.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
    assert!(n > 1400.0, "too many dropouts: {n} valid");
    assert!(mean.abs() < 2e-4, "unbiased: mean {mean}");
    // sigma(1 m) = noise at normal incidence (quantisation adds 0.07 mm rms).
    assert!((std / 0.002 - 1.0).abs() < 0.1, "std {std} vs 2 mm");
}

#[test]
fn noise_adds_dropouts_and_mixed_pixels() {
    // The box's top edge against the floor behind it is a depth jump.
    let scene = Scene::build(SceneKind::Box);
    let intr = Intrinsics::L515_320X240;
    let pose = trajectory(&scene, 30)[29];
    let r = render(&scene, &intr, &pose);
    let depth = noisy_depth(&r, &NoiseModel::l515(2.0), 1, 0);
    let hit = r.labels.iter().filter(|&&l| l != 0).count();
    let dropped = depth.iter().zip(&r.labels).filter(|&(&d, &l)| d == 0 && l != 0).count();
    assert!(dropped > hit / 1000, "dropouts: {dropped} of {hit}");
    // Mixed pixels: depths more than 3 cm from the truth, between two surfaces.
    let mixed = depth
        .iter()
        .zip(&r.depth_m)
        .filter(|&(&d, &t)| d != 0 && (d as f64 * intr.depth_scale - t).abs() > 0.03)
        .count();
    assert!(mixed > 10, "mixed pixels at the box edges: {mixed}");
    assert!(mixed < hit / 50, "but only at edges: {mixed}");
}

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for sub in ["", "depth", "labels"] {
        let mut names: Vec<_> =
            fs::read_dir(dir.join(sub)).unwrap().map(|e| e.unwrap().path()).filter(|p| p.is_file()).collect();
        names.sort();
        out.extend(
            names.into_iter().map(|p| (p.strip_prefix(dir).unwrap().display().to_string(), fs::read(&p).unwrap())),
        );
    }
    out
}

#[test]
fn synth_is_deterministic_for_a_seed() {
    let (a, b, c) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let opts = SynthOptions { scene: SceneKind::Box, width: 64, frames: 3, seed: 42, ..SynthOptions::default() };
    synth::generate(&opts, a.path(), |_, _| {}).unwrap();
    synth::generate(&opts, b.path(), |_, _| {}).unwrap();
    synth::generate(&SynthOptions { seed: 43, ..opts.clone() }, c.path(), |_, _| {}).unwrap();
    let (fa, fb, fc) = (files(a.path()), files(b.path()), files(c.path()));
    assert_eq!(fa.len(), 3 + 3 + 3, "camera.toml, poses.txt, truth.json, 3 depth, 3 labels");
    assert!(fa == fb, "same seed, same bytes");
    let depth_differs = fa.iter().zip(&fc).any(|(x, y)| x.0.starts_with("depth") && x.1 != y.1);
    assert!(depth_differs, "another seed, other noise");
}

#[test]
fn horizontal_drift_and_a_step_move_the_written_poses_and_the_truth_undoes_them() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let opts = SynthOptions { width: 32, frames: 6, ..SynthOptions::default() };
    synth::generate(&opts, a.path(), |_, _| {}).unwrap();
    let drifting = SynthOptions {
        drift_xy_mm_per_frame: [1.0, -2.0],
        drift_yaw_deg_per_frame: 0.1,
        jump: Some(synth::JumpOptions { frame: 3, xyz_mm: [50.0, 0.0, 10.0], yaw_deg: 1.0 }),
        ..opts.clone()
    };
    synth::generate(&drifting, b.path(), |_, _| {}).unwrap();
    let (sa, sb) = (Sequence::open(a.path()).unwrap(), Sequence::open(b.path()).unwrap());
    let tb = sb.truth.clone().unwrap();
    let heading = |t: &nalgebra::Isometry3<f64>| {
        let axis = t.rotation * Vector3::z();
        axis.y.atan2(axis.x).to_degrees()
    };
    for k in 0..6 {
        let (exact, written) = (&sa.poses[k].transform, &sb.poses[k].transform);
        let turned = heading(written) - heading(exact);
        let want = 0.1 * k as f64 + if k >= 3 { 1.0 } else { 0.0 };
        // poses.txt keeps its quaternions to about 1e-8.
        assert!((turned - want).abs() < 1e-5, "frame {k}: turned {turned} deg, not {want}");
        let stepped_up = written.translation.z - exact.translation.z;
        assert!((stepped_up - if k >= 3 { 0.01 } else { 0.0 }).abs() < 1e-7, "frame {k}: {stepped_up}");
        let undone = tb.true_pose(k, written);
        assert!(
            (undone.translation.vector - exact.translation.vector).norm() < 1e-6,
            "frame {k}: the true pose is recovered"
        );
        assert!(undone.rotation.angle_to(&exact.rotation) < 1e-6);
    }
    let pivot = tb.pose_drift.as_ref().unwrap().pivot;
    assert_eq!(
        pivot,
        [sa.poses[0].transform.translation.x, sa.poses[0].transform.translation.y],
        "about the walk's start"
    );
}

#[test]
fn drift_moves_the_written_poses_up_not_the_truth() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let opts = SynthOptions { width: 32, frames: 5, ..SynthOptions::default() };
    synth::generate(&opts, a.path(), |_, _| {}).unwrap();
    synth::generate(&SynthOptions { drift_mm_per_frame: 2.0, ..opts }, b.path(), |_, _| {}).unwrap();
    let (sa, sb) = (Sequence::open(a.path()).unwrap(), Sequence::open(b.path()).unwrap());
    let (ta, tb) = (sa.truth.clone().unwrap(), sb.truth.clone().unwrap());
    assert_eq!(ta.polygons, tb.polygons, "the world is the same");
    assert_eq!((ta.pose_drift_per_frame, tb.pose_drift_per_frame), (0.0, 0.002), "the truth records the drift");
    for k in 0..5 {
        let dz = sb.poses[k].transform.translation.z - sa.poses[k].transform.translation.z;
        assert!((dz - 0.002 * k as f64).abs() < 1e-8, "frame {k}: {dz}");
        let undone = tb.true_pose(k, &sb.poses[k].transform).translation.z;
        assert!((undone - sa.poses[k].transform.translation.z).abs() < 1e-12, "the true pose is recovered");
        assert_eq!(sa.depth(k).unwrap(), sb.depth(k).unwrap(), "the depth itself is undrifted");
    }
}

#[test]
fn bad_options_are_refused() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_polymap"))
        .args(["synth", "/tmp/polymap-never-written", "--width", "30"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--width 30"));
    assert!(!Path::new("/tmp/polymap-never-written").exists());
}

#[test]
fn committed_mock_frames_are_what_their_commands_make() {
    // mock_frames/README.md lists the exact command for each sequence: run each
    // again and compare bytes, so the README and the data never drift apart.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = fs::read_to_string(root.join("mock_frames/README.md")).unwrap();
    let mut checked = 0;
    for line in readme.lines().filter(|l| l.contains("-- synth mock_frames/")) {
        let cmd = line.split("-- synth ").nth(1).unwrap().split('`').next().unwrap();
        let mut args: Vec<&str> = cmd.split_whitespace().collect();
        let committed = root.join(args[0]);
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("seq");
        args[0] = out.to_str().unwrap();
        let status =
            std::process::Command::new(env!("CARGO_BIN_EXE_polymap")).arg("synth").args(&args).output().unwrap();
        assert!(status.status.success(), "{cmd}: {}", String::from_utf8_lossy(&status.stderr));
        assert!(files(&out) == files(&committed), "{} differs from what `{cmd}` makes", committed.display());
        checked += 1;
    }
    assert_eq!(checked, 3, "three sequences are documented");
}
