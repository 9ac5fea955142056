//! Per-frame extraction on the CPU: each stage on small images with known answers,
//! the batched RANSAC on planted planes, and whole frames of the synthetic stairs.

use nalgebra::Vector3;
use polymap::config::PipelineConfig;
use polymap::extract::cpu::{canny, diffusion, normals, ransac};
use polymap::extract::{ExtractError, Grid, extract_cpu};
use polymap::synth::{NoiseModel, Scene, SceneKind, noisy_depth, path::trajectory, render};
use polymap::types::{DepthFrame, Intrinsics};

fn intr(w: u32, h: u32) -> Intrinsics {
    Intrinsics::L515_320X240.scaled_to(w, h)
}

/// Depth of the plane n . p + d = 0 seen through every pixel.
fn plane_depth(i: &Intrinsics, n: Vector3<f64>, d: f64) -> Grid<f32> {
    let data = (0..i.pixel_count())
        .map(|k| {
            let ray = i.ray((k % i.width as usize) as f64, (k / i.width as usize) as f64);
            (-d / n.dot(&ray)) as f32
        })
        .collect();
    Grid { width: i.width as usize, height: i.height as usize, data }
}

#[test]
fn diffusion_keeps_a_constant_plane_and_never_touches_holes() {
    let mut g = Grid { width: 40, height: 30, data: vec![1.5f32; 1200] };
    for k in [0, 17, 300, 301, 331, 1199] {
        g.data[k] = 0.0;
    }
    let out = diffusion::diffuse(&g, 60, 0.0335, 0.2);
    for (a, b) in g.data.iter().zip(&out.data) {
        assert_eq!(a, b, "no flux into, out of or across invalid pixels");
    }
}

#[test]
fn diffusion_smooths_noise_but_keeps_a_step() {
    // Left half at 1.0 m, right half at 1.15 m, with +-2 mm alternating noise.
    let (w, h) = (60usize, 40usize);
    let data: Vec<f32> = (0..w * h)
        .map(|k| {
            let (u, v) = (k % w, k / w);
            (if u < w / 2 { 1.0 } else { 1.15 }) + if (u + v) % 2 == 0 { 0.002 } else { -0.002 }
        })
        .collect();
    let out = diffusion::diffuse(&Grid { width: w, height: h, data }, 60, 0.0335, 0.2);
    let v = h / 2;
    for u in [5, 20, w / 2 - 2] {
        assert!((out.data[v * w + u] - 1.0).abs() < 5e-4, "left ({u}): {}", out.data[v * w + u]);
    }
    for u in [w / 2 + 1, 40, 55] {
        assert!((out.data[v * w + u] - 1.15).abs() < 5e-4, "right ({u}): {}", out.data[v * w + u]);
    }
}

#[test]
fn diffusion_of_nothing_is_nothing() {
    let out = diffusion::diffuse(&Grid { width: 16, height: 12, data: vec![0.0; 192] }, 60, 0.0335, 0.2);
    assert!(out.data.iter().all(|&z| z == 0.0));
}

#[test]
fn normals_of_a_tilted_plane_are_exact() {
    let i = intr(320, 240);
    // Tilted 30 deg to the optical axis, all of it within 0.7..2.3 m.
    let n = Vector3::new(0.15, -0.45, -0.88).normalize();
    let depth = plane_depth(&i, n, 1.2);
    for kernel in [3, 5, 7] {
        let out = normals::normals(&depth, &i, kernel);
        let r = kernel as usize / 2;
        for v in (r..240 - r).step_by(7) {
            for u in (r..320 - r).step_by(7) {
                let m = out.data[v * 320 + u];
                let err = (Vector3::new(m[0] as f64, m[1] as f64, m[2] as f64) - n).norm();
                // Depth is not linear in pixels on a tilted plane, so the Sobel taps see a
                // little curvature: under 0.03 deg.
                assert!(err < 5e-4, "kernel {kernel} ({u},{v}): {m:?} vs {n:?}");
            }
        }
        // The border, where taps fall off the image, has no normal.
        assert_eq!(out.data[0], [0.0; 3]);
    }
}

#[test]
fn an_invalid_tap_removes_the_normal_and_nothing_is_nan() {
    let i = intr(32, 24);
    let mut depth = plane_depth(&i, Vector3::new(0.0, -0.6, -0.8), 1.2);
    depth.data[12 * 32 + 16] = 0.0;
    let out = normals::normals(&depth, &i, 5);
    for v in 10..=14 {
        for u in 14..=18 {
            assert_eq!(out.data[v * 32 + u], [0.0; 3], "({u},{v}) sees the hole");
        }
    }
    assert_ne!(out.data[12 * 32 + 19], [0.0; 3]);
    assert!(out.data.iter().flatten().all(|c| c.is_finite()));
}

#[test]
fn canny_finds_the_fold_between_two_planes_and_nothing_on_one() {
    let i = intr(80, 60);
    let flat = plane_depth(&i, Vector3::new(0.0, -0.6, -0.8), 1.2);
    let n = normals::normals(&flat, &i, 5);
    let edges = canny::canny(&canny::normal_gradient(&n), 0.05, 0.1);
    assert_eq!(edges.data.iter().filter(|&&e| e != 0).count(), 0, "a plane has no edges");

    // A valley: two planes tilted 30 deg either way, meeting along the optical axis's column.
    let a = plane_depth(&i, Vector3::new(0.5, 0.0, -0.866), 1.0);
    let b = plane_depth(&i, Vector3::new(-0.5, 0.0, -0.866), 1.0);
    let roof = Grid { data: a.data.iter().zip(&b.data).map(|(x, y)| x.max(*y)).collect(), ..a };
    let n = normals::normals(&roof, &i, 5);
    let edges = canny::canny(&canny::normal_gradient(&n), 0.05, 0.1);
    for v in 5..55 {
        let row: Vec<usize> = (0..80).filter(|&u| edges.data[v * 80 + u] != 0).collect();
        assert!(!row.is_empty() && row.iter().all(|&u| (36..=43).contains(&u)), "row {v}: edges at {row:?}");
    }
}

#[test]
fn closing_bridges_gaps_and_keeps_the_border() {
    let (w, h) = (30usize, 20usize);
    let mut data = vec![0u8; w * h];
    for u in (0..w).filter(|u| !(12..16).contains(u)) {
        data[10 * w + u] = 1; // a line with a 4-pixel gap
    }
    let closed = canny::close(&Grid { width: w, height: h, data: data.clone() }, 7);
    assert!((0..w).all(|u| closed.data[10 * w + u] == 1), "the gap is bridged");
    assert_eq!(closed.data.iter().filter(|&&e| e != 0).count(), w, "and nothing else is added");
}

#[test]
fn batched_ransac_fits_every_planted_plane() {
    // Three planes, 2000 points each, 5 % of them outliers 5-20 cm off; one region of pure noise.
    let planes = [
        (Vector3::new(0.0, -0.6, -0.8), 1.2),
        (Vector3::new(0.9, 0.0, -0.436), 0.7),
        (Vector3::new(0.0, 0.0, -1.0), 2.0),
    ];
    let mut batch = ransac::PointBatch::default();
    let mut state = 12345u32;
    let mut rnd = || {
        state = ransac::hash(state);
        state as f64 / u32::MAX as f64
    };
    for (n, d) in planes {
        let n: Vector3<f64> = n.normalize();
        let (a, b) = (n.cross(&Vector3::x()).normalize(), n.cross(&n.cross(&Vector3::x())).normalize());
        let start = batch.points.len();
        for k in 0..2000 {
            let (s, t) = (rnd() - 0.5, rnd() - 0.5);
            let off = if k % 20 == 0 { 0.05 + 0.15 * rnd() } else { 0.002 * (rnd() - 0.5) };
            let p = -n * d + a * s + b * t + n * off;
            batch.points.push([p.x as f32, p.y as f32, p.z as f32]);
        }
        batch.ranges.push(start..batch.points.len());
    }
    let start = batch.points.len();
    for _ in 0..500 {
        batch.points.push([rnd() as f32, rnd() as f32, 1.0 + rnd() as f32]);
    }
    batch.ranges.push(start..batch.points.len());

    let fits = ransac::fit_planes(&batch, 20, 0.01);
    assert_eq!(fits.len(), 4);
    for (fit, (n, d)) in fits.iter().zip(planes) {
        let fit = fit.expect("a planted plane is found");
        let angle = fit.normal.angle(&n.normalize()).to_degrees();
        assert!(angle < 0.2, "normal off by {angle} deg");
        assert!((fit.offset - d).abs() < 1e-3, "offset {} vs {d}", fit.offset);
        assert!((fit.inlier_ratio() - 0.95).abs() < 0.01, "inlier ratio {}", fit.inlier_ratio());
        assert!(fit.rms < 0.002);
    }
    assert!(fits[3].is_none_or(|f| f.inlier_ratio() < 0.5), "noise is not a plane");
}

fn frame(
    kind: SceneKind,
    width: u32,
    k: usize,
    noise_mm: f64,
) -> (DepthFrame, Intrinsics, nalgebra::Isometry3<f64>, Scene) {
    let scene = Scene::build(kind);
    let i = intr(width, width * 3 / 4);
    let pose = trajectory(&scene, 30)[k];
    let r = render(&scene, &i, &pose);
    let pixels = noisy_depth(&r, &NoiseModel::l515(noise_mm), 1, k);
    (DepthFrame { stamp_ns: 0, width: i.width, height: i.height, depth_scale: i.depth_scale, pixels }, i, pose, scene)
}

#[test]
fn stair_frame_yields_level_treads_at_the_right_heights() {
    let (depth, i, pose, scene) = frame(SceneKind::Straight, 320, 20, 2.0);
    let (out, _, _) = extract_cpu(&depth, &i, &PipelineConfig::default()).unwrap();
    let rise = scene.stair.as_ref().unwrap().rise;
    let mut treads = 0;
    for p in &out.polygons {
        let w = p.transformed(&pose);
        let tilt = Vector3::from(w.normal).angle(&Vector3::z()).to_degrees();
        if tilt > 10.0 {
            continue;
        }
        treads += 1;
        assert!(tilt < 1.0, "tread tilt {tilt} deg");
        let z = w.centroid()[2];
        let step = (z / rise).round();
        assert!((z - step * rise).abs() < 0.005, "tread at {z} m is not a multiple of the rise");
        assert!(w.boundary.iter().all(|v| (v[2] - z).abs() < 0.01), "vertices lie on the level plane");
        assert!(p.inlier_ratio >= 0.9 && p.rms < 0.005);
    }
    assert!(treads >= 3, "found {treads} treads");
}

#[test]
fn all_invalid_frame_gives_no_polygons_and_a_bad_frame_an_error() {
    let i = intr(64, 48);
    let empty = DepthFrame { stamp_ns: 5, width: 64, height: 48, depth_scale: 0.00025, pixels: vec![0; 64 * 48] };
    let (out, stages, _) = extract_cpu(&empty, &i, &PipelineConfig::default()).unwrap();
    assert!(out.polygons.is_empty());
    assert!(stages.smoothed.data.iter().all(|z| *z == 0.0));
    let short = DepthFrame { pixels: vec![0; 100], ..empty.clone() };
    assert!(matches!(extract_cpu(&short, &i, &PipelineConfig::default()), Err(ExtractError::SizeMismatch { .. })));
    let bad_scale = DepthFrame { depth_scale: f64::NAN, ..empty };
    assert!(matches!(extract_cpu(&bad_scale, &i, &PipelineConfig::default()), Err(ExtractError::BadDepthScale(_))));
}
