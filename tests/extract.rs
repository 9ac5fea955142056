//! Per-frame extraction on the CPU: each stage on small images with known answers,
//! the batched RANSAC on planted planes, and whole frames of the synthetic stairs.

use nalgebra::Vector3;
use polymap::config::PipelineConfig;
use polymap::extract::cloud::Cloud;
use polymap::extract::cpu::{diffusion, gradient, hysteresis, morphology, normals, ransac};
use polymap::extract::{ExtractError, Extraction, Grid, extract_cpu};
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
    let out = diffusion::diffuse(&g, 12.0, 4, 0.0335);
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
    let out = diffusion::diffuse(&Grid { width: w, height: h, data }, 12.0, 4, 0.0335);
    let v = h / 2;
    for u in [5, 20, w / 2 - 2] {
        assert!((out.data[v * w + u] - 1.0).abs() < 5e-4, "left ({u}): {}", out.data[v * w + u]);
    }
    for u in [w / 2 + 1, 40, 55] {
        assert!((out.data[v * w + u] - 1.15).abs() < 5e-4, "right ({u}): {}", out.data[v * w + u]);
    }
}

/// The reference's scheme by its definition: `steps` explicit steps of `gamma`, each pixel
/// moved by the conductance-weighted differences to its valid 4-neighbours.
fn explicit_diffusion(g: &Grid<f32>, steps: u32, gamma: f32, kappa: f32) -> Grid<f32> {
    let (w, h) = (g.width as isize, g.height as isize);
    let mut cur = g.data.clone();
    for _ in 0..steps {
        let prev = cur.clone();
        for v in 0..h {
            for u in 0..w {
                let z = prev[(v * w + u) as usize];
                if z == 0.0 {
                    continue;
                }
                let mut sum = 0.0;
                for (du, dv) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                    let (nu, nv) = (u + du, v + dv);
                    if nu < 0 || nv < 0 || nu >= w || nv >= h || prev[(nv * w + nu) as usize] == 0.0 {
                        continue;
                    }
                    let d = prev[(nv * w + nu) as usize] - z;
                    sum += (-(d / kappa).powi(2)).exp() * d;
                }
                cur[(v * w + u) as usize] = z + gamma * sum;
            }
        }
    }
    Grid { width: g.width, height: g.height, data: cur }
}

#[test]
fn four_semi_implicit_steps_smooth_as_the_reference_s_sixty_explicit_ones() {
    // Two levels 15 cm apart, +-2 mm of hashed noise, and holes. (Level, as near a hole or the
    // image's edge both schemes bend a slope alike: no flux comes from outside.)
    let (w, h) = (80usize, 60usize);
    let data: Vec<f32> = (0..w * h)
        .map(|k| {
            if k % 97 == 0 {
                return 0.0;
            }
            let noise = 0.004 * ((k * 7919 % 101) as f32 / 100.0 - 0.5);
            1.0 + if k % w < w / 2 { 0.0 } else { 0.15 } + noise
        })
        .collect();
    let depth = Grid { width: w, height: h, data };
    let reference = explicit_diffusion(&depth, 60, 0.2, 0.0335);
    let ours = diffusion::diffuse(&depth, 12.0, 4, 0.0335);
    let truth = |k: usize| 1.0 + if k % w < w / 2 { 0.0 } else { 0.15 };
    let rms = |g: &Grid<f32>, near_step: bool| {
        let e: Vec<f32> = (0..w * h)
            .filter(|&k| g.data[k] != 0.0 && (((k % w) as isize - (w / 2) as isize).abs() < 3) == near_step)
            .map(|k| g.data[k] - truth(k))
            .collect();
        (e.iter().map(|x| x * x).sum::<f32>() / e.len() as f32).sqrt()
    };
    let (input, ours_flat, reference_flat) = (rms(&depth, false), rms(&ours, false), rms(&reference, false));
    assert!(input > 0.001, "the input is noisy: {input}");
    // Both take the noise down over twenty times, and ours leaves at most 1.5 times the
    // reference's residual (1.1 times, when written).
    assert!(
        ours_flat < input / 20.0 && reference_flat < input / 20.0,
        "{input} -> ours {ours_flat}, reference {reference_flat}"
    );
    assert!(ours_flat < 1.5 * reference_flat, "ours {ours_flat}, reference {reference_flat}");
    // The step stays a step: beside it neither scheme has moved a pixel by a centimetre.
    let (ours_step, reference_step) = (rms(&ours, true), rms(&reference, true));
    assert!(ours_step < 0.01 && reference_step < 0.01, "at the step: ours {ours_step}, reference {reference_step}");
    // Holes stay holes in both.
    assert!((0..w * h).all(|k| (ours.data[k] == 0.0) == (depth.data[k] == 0.0)));
}

#[test]
fn diffusion_of_nothing_is_nothing() {
    let out = diffusion::diffuse(&Grid { width: 16, height: 12, data: vec![0.0; 192] }, 12.0, 4, 0.0335);
    assert!(out.data.iter().all(|&z| z == 0.0));
    // And an image of no pixels is no image, not a panic.
    for (width, height) in [(0, 0), (7, 0), (0, 7)] {
        assert!(diffusion::diffuse(&Grid { width, height, data: Vec::new() }, 12.0, 4, 0.0335).data.is_empty());
    }
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
    let edges = hysteresis::canny(&gradient::normal_gradient(&n), 0.05, 0.1);
    assert_eq!(edges.data.iter().filter(|&&e| e != 0).count(), 0, "a plane has no edges");

    // A valley: two planes tilted 30 deg either way, meeting along the optical axis's column.
    let a = plane_depth(&i, Vector3::new(0.5, 0.0, -0.866), 1.0);
    let b = plane_depth(&i, Vector3::new(-0.5, 0.0, -0.866), 1.0);
    let roof = Grid { data: a.data.iter().zip(&b.data).map(|(x, y)| x.max(*y)).collect(), ..a };
    let n = normals::normals(&roof, &i, 5);
    let edges = hysteresis::canny(&gradient::normal_gradient(&n), 0.05, 0.1);
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
    let closed = morphology::close(&Grid { width: w, height: h, data: data.clone() }, 7);
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
    let out = extract_cpu(&depth, &i, &PipelineConfig::default()).unwrap().polygons;
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
fn every_vertex_says_what_it_lies_on_and_does_lie_there() {
    use polymap::extract::{VertexKind, polygon::BORDER_PX};
    let (depth, i, _, _) = frame(SceneKind::Straight, 320, 20, 2.0);
    let out = extract_cpu(&depth, &i, &PipelineConfig::default()).unwrap().polygons;
    let (mut cuts, mut borders, mut inside) = (0, 0, 0);
    for p in &out.polygons {
        assert_eq!(p.boundary_kinds.len(), p.boundary.len(), "polygon {}", p.id);
        assert_eq!(p.hole_kinds.len(), p.holes.len());
        let rings = std::iter::once((&p.boundary, &p.boundary_kinds)).chain(p.holes.iter().zip(&p.hole_kinds));
        for (ring, kinds) in rings {
            assert_eq!(ring.len(), kinds.len());
            for (v, kind) in ring.iter().zip(kinds) {
                let (u, r) = i.project(&nalgebra::Point3::from(*v));
                // A vertex lies half a pixel outside its region's pixel centres; a border
                // vertex pulled onto its pixel's point moves by a few pixels at most.
                let margin = |edge: f64| {
                    u < edge || r < edge || u > i.width as f64 - 1.0 - edge || r > i.height as f64 - 1.0 - edge
                };
                match kind {
                    // A neighbour too small to publish leaves None: nothing to check it against.
                    VertexKind::Cut { neighbour: None } => {}
                    VertexKind::Cut { neighbour: Some(n) } => {
                        cuts += 1;
                        let q = &out.polygons[*n as usize];
                        let off = Vector3::from(q.normal).dot(&Vector3::from(*v)) + q.offset;
                        assert!(off.abs() < 1e-9, "a cut vertex of {} lies on {}'s plane: {off} m off", p.id, q.id);
                    }
                    VertexKind::ImageBorder => {
                        borders += 1;
                        assert!(margin(BORDER_PX as f64 + 4.0), "border vertex at ({u:.1}, {r:.1})");
                    }
                    VertexKind::Inside => {
                        inside += 1;
                        assert!(!margin(BORDER_PX as f64 - 1.0), "inside vertex at ({u:.1}, {r:.1})");
                    }
                }
            }
        }
    }
    // Treads cut at their risers, outlines running off the image, and pixel outlines.
    assert!(cuts >= 6 && borders >= 6 && inside >= 6, "cut {cuts}, border {borders}, inside {inside}");
}

#[test]
fn a_tread_running_off_the_top_of_the_image_ends_near_its_back_edge() {
    // Frame 45 of the 180-frame walk: tread 2 (x 0.28..0.56, z 0.30) runs off the top of
    // the image, where the next riser begins; its outline's pixels there can be the riser's
    // first, within the inlier distance of the tread's plane, which ray-cast onto it at
    // this grazing angle land 4-6 cm past the back edge. Kept to the tread's plane, they
    // end within 3 cm of it (the crease's pixels go to whichever plane their noise puts
    // them nearer, a few millimetres up the riser at most).
    let scene = Scene::build(SceneKind::Straight);
    let i = intr(320, 240);
    let pose = trajectory(&scene, 180)[45];
    let pixels = noisy_depth(&render(&scene, &i, &pose), &NoiseModel::l515(2.0), 4, 45);
    let depth = DepthFrame { stamp_ns: 0, width: i.width, height: i.height, depth_scale: i.depth_scale, pixels };
    let out = extract_cpu(&depth, &i, &PipelineConfig::default()).unwrap().polygons;
    let tread = out
        .polygons
        .iter()
        .map(|p| p.transformed(&pose))
        .find(|w| w.normal[2] > 0.99 && (w.centroid()[2] - 0.30).abs() < 0.01)
        .expect("tread 2 is found");
    let mut far: Vec<f64> = tread.boundary.iter().map(|v| v[0]).filter(|&x| x > 0.45).collect();
    far.sort_by(f64::total_cmp);
    assert!(far.len() >= 2, "the outline reaches the back edge: {:?}", tread.boundary);
    let median = far[far.len() / 2];
    assert!((0.55..0.59).contains(&median), "the far edge's vertices end near x = 0.56: {far:?}");
}

#[test]
fn all_invalid_frame_gives_no_polygons_and_a_bad_frame_an_error() {
    let i = intr(64, 48);
    let empty = DepthFrame { stamp_ns: 5, width: 64, height: 48, depth_scale: 0.00025, pixels: vec![0; 64 * 48] };
    let Extraction { polygons: out, stages, .. } = extract_cpu(&empty, &i, &PipelineConfig::default()).unwrap();
    assert!(out.polygons.is_empty());
    assert!(stages.images.expect("the CPU keeps its images").smoothed.data.iter().all(|z| *z == 0.0));
    let short = DepthFrame { pixels: vec![0; 100], ..empty.clone() };
    assert!(matches!(extract_cpu(&short, &i, &PipelineConfig::default()), Err(ExtractError::SizeMismatch { .. })));
    let bad_scale = DepthFrame { depth_scale: f64::NAN, ..empty };
    assert!(matches!(extract_cpu(&bad_scale, &i, &PipelineConfig::default()), Err(ExtractError::BadDepthScale(_))));
}

/// A frame whose left part sees a floor and right part a step above it, with no edge
/// between them in the boundary map: one region that leaks across two surfaces.
#[test]
fn a_region_leaking_across_two_planes_is_split_and_both_are_fitted() {
    use polymap::extract::regions::Segmentation;
    let i = intr(160, 120);
    let floor = plane_depth(&i, Vector3::new(0.0, -0.8, -0.6), 1.0);
    // A step 20 cm up: parallel, so the two planes never meet in view.
    let wall = plane_depth(&i, Vector3::new(0.0, -0.8, -0.6), 0.8);
    let depth = Grid {
        data: floor
            .data
            .iter()
            .zip(&wall.data)
            .enumerate()
            .map(|(k, (f, w))| if k % 160 < 100 { *f } else { *w })
            .collect(),
        ..floor
    };
    let boundary = Grid { width: 160, height: 120, data: vec![0u8; 160 * 120] };
    let mut seg = Segmentation::components(&boundary, 30);
    assert_eq!(seg.pixels.len(), 1);
    let mut fits = ransac::fit_planes(&seg.points(&[0], &Cloud::new(&depth, &i)), 20, 0.01);
    assert!(fits[0].unwrap().inlier_ratio() < 0.9, "one plane cannot fit both surfaces");
    let leaks = seg.split_leaks(&mut fits, &Cloud::new(&depth, &i), 0.01, 0.9, 30);
    assert_eq!(leaks.split, vec![0], "the region that leaked is cut back");
    let pieces = leaks.pieces;
    assert_eq!(
        pieces,
        vec![1],
        "the other surface becomes a new region ({:?})",
        seg.pixels.iter().map(|p| p.len()).collect::<Vec<_>>()
    );
    let refit = ransac::fit_planes(&seg.points(&pieces, &Cloud::new(&depth, &i)), 20, 0.01);
    fits[1] = refit[0];
    let kept = fits[0].unwrap();
    assert!(
        kept.inlier_ratio() > 0.99 && kept.normal.angle(&Vector3::new(0.0, -0.8, -0.6)) < 1e-3,
        "the larger part keeps the floor"
    );
    assert!(seg.pixels[0].iter().all(|&p| p % 160 < 100), "and only the floor's pixels");
    let new = fits[1].unwrap();
    assert!(new.normal.angle(&Vector3::new(0.0, -0.8, -0.6)) < 1e-3 && (new.offset - 0.8).abs() < 1e-3);
    assert_eq!(seg.pixels[0].len() + seg.pixels[1].len(), 160 * 120);
}

/// The joins' scan runs beside the first fits, on the labels as the edges left them. A
/// leak split changes them: the pairs are then found again, and the piece cut off joins
/// the region of its own plane beyond a gap that pre-split pairs never saw it meet.
#[test]
fn a_piece_split_off_a_leak_joins_its_own_plane_across_a_gap() {
    use polymap::extract::cpu::ransac::PointBatch;
    use polymap::extract::{
        MIN_REGION_PIXELS, StageTimes,
        regions::{Segmentation, segment_and_fit},
    };
    let (w, h) = (160usize, 120usize);
    let i = intr(w as u32, h as u32);
    let floor = plane_depth(&i, Vector3::new(0.0, -0.8, -0.6), 1.0);
    // A step 20 cm up (parallel to the floor) from column 100 on, cut by a boundary band
    // in columns 120..126 whose middle four are dropouts: the step's near part leaks into
    // the floor's region, its far part is a region of its own.
    let step = plane_depth(&i, Vector3::new(0.0, -0.8, -0.6), 0.8);
    let depth = Grid {
        data: (0..w * h)
            .map(|k| match k % w {
                0..100 => floor.data[k],
                121..125 => 0.0,
                _ => step.data[k],
            })
            .collect(),
        ..floor
    };
    let boundary =
        Grid { width: w, height: h, data: (0..w * h).map(|k| u8::from((120..126).contains(&(k % w)))).collect() };
    let seg = Segmentation::components(&boundary, MIN_REGION_PIXELS);
    assert_eq!(seg.pixels.len(), 2, "the floor with the step's near part, and the step's far part");
    let (cloud, cfg) = (Cloud::new(&depth, &i), PipelineConfig::default());
    let fit =
        |batch: &PointBatch| Ok(ransac::fit_planes(batch, cfg.ransac_hypotheses, cfg.ransac_inlier_distance_m as f32));
    let (seg, _, fits, _) = segment_and_fit(seg, &cloud, &cfg, fit, &mut StageTimes::default(), &mut || 0.0).unwrap();
    let label = |u: usize| seg.labels.data[60 * w + u];
    assert_ne!(label(50), label(110), "the leak split: the floor keeps its own pixels");
    assert_eq!(label(110), label(140), "the step's two parts joined across the dropouts");
    let joined = fits[label(110) as usize - 1].expect("the joined step has a plane");
    assert!((joined.offset - 0.8).abs() < 1e-3, "on the step's plane: {joined:?}");
}

#[test]
fn regions_grow_back_over_their_own_plane_but_not_onto_another() {
    use polymap::extract::regions::Segmentation;
    let i = intr(100, 80);
    // A floor with a 10 cm step up beyond column 60.
    let low = plane_depth(&i, Vector3::new(0.0, -0.8, -0.6), 1.0);
    let high = plane_depth(&i, Vector3::new(0.0, -0.8, -0.6), 0.9);
    let depth = Grid {
        data: low
            .data
            .iter()
            .zip(&high.data)
            .enumerate()
            .map(|(k, (l, h))| if k % 100 < 60 { *l } else { *h })
            .collect(),
        ..low
    };
    // Boundary: a band of columns 50..66 around the step, as edges and closing would leave.
    let boundary =
        Grid { width: 100, height: 80, data: (0..8000).map(|k| (50..66).contains(&(k % 100)) as u8).collect() };
    let mut seg = Segmentation::components(&boundary, 30);
    assert_eq!(seg.pixels.len(), 2);
    let fits = ransac::fit_planes(&seg.points(&[0, 1], &Cloud::new(&depth, &i)), 20, 0.01);
    seg.grow(&fits, &[true, true], &Cloud::new(&depth, &i), 0.01, 4);
    let columns = |r: usize| {
        let mut c: Vec<u32> = seg.pixels[r].iter().map(|p| p % 100).collect();
        c.sort_unstable();
        c.dedup();
        (c[0], *c.last().unwrap())
    };
    assert_eq!(columns(0), (0, 53), "the low floor takes back 4 columns of its own plane");
    assert_eq!(columns(1), (62, 99), "so does the high one");
    let mut both = seg.pixels[0].clone();
    both.extend(&seg.pixels[1]);
    assert!(both.iter().all(|&p| (p % 100 < 60) == seg.pixels[0].contains(&p)), "no pixel crosses the step");
}

#[test]
fn at_an_inner_corner_each_region_takes_back_only_its_own_surface() {
    use polymap::extract::regions::Segmentation;
    let i = intr(320, 240);
    // A floor 1 m below the camera (tilted 37 deg down) and a riser-like wall facing
    // the camera, meeting in a horizontal line through the image centre.
    let up = Vector3::new(0.0, -0.8, -0.6);
    let ahead = Vector3::new(0.0, -0.6, 0.8);
    let corner = 1.0 / 0.6 * 0.8;
    let floor = plane_depth(&i, up, 1.0);
    let wall = plane_depth(&i, -ahead, corner);
    let on_wall: Vec<bool> = (0..i.pixel_count())
        .map(|k| {
            let ray = i.ray((k % 320) as f64, (k / 320) as f64);
            ahead.dot(&(ray * floor.data[k] as f64)) > corner
        })
        .collect();
    let depth = Grid {
        data: (0..i.pixel_count()).map(|k| if on_wall[k] { wall.data[k] } else { floor.data[k] }).collect(),
        ..floor.clone()
    };
    let corner_row = (0..240).find(|&v| !on_wall[v * 320]).unwrap();
    assert!((100..140).contains(&corner_row), "corner at row {corner_row}");
    // Edges and closing leave a band of rows around the corner, here reaching further
    // up the wall than down the floor, so the floor gets to the corner first.
    let band = corner_row - 5..=corner_row + 1;
    let boundary =
        Grid { width: 320, height: 240, data: (0..i.pixel_count()).map(|k| band.contains(&(k / 320)) as u8).collect() };
    let mut seg = Segmentation::components(&boundary, 30);
    assert_eq!(seg.pixels.len(), 2);
    let before: Vec<usize> = seg.pixels.iter().map(Vec::len).collect();
    // 2 cm: the wall's lowest rows lie within it of the floor's plane and the floor's
    // highest within it of the wall's; the nearer plane must still win them.
    let fits = ransac::fit_planes(&seg.points(&[0, 1], &Cloud::new(&depth, &i)), 20, 0.02);
    seg.grow(&fits, &[true, true], &Cloud::new(&depth, &i), 0.02, 4);
    for (r, surface) in [(0, true), (1, false)] {
        assert!(seg.pixels[r].len() > before[r], "region {r} grew back over its own surface");
        let strays = seg.pixels[r].iter().filter(|&&k| on_wall[k as usize] != surface).count();
        assert_eq!(strays, 0, "region {r} took {strays} pixels of the other surface");
    }
}

#[test]
fn outlines_cover_their_pixels_squares_and_holes_shrink() {
    use polymap::extract::regions::contours::offset_ring;
    use polymap::ring::fill_rings;
    // A 10 x 6 block of pixels has its centres' outline from (2,3) to (11,8).
    let centres = vec![[2.0, 3.0], [11.0, 3.0], [11.0, 8.0], [2.0, 8.0]];
    let outer = offset_ring(&centres, 0.5);
    let area = |r: &[[f32; 2]]| {
        (0..r.len()).map(|k| r[k][0] * r[(k + 1) % r.len()][1] - r[(k + 1) % r.len()][0] * r[k][1]).sum::<f32>().abs()
            / 2.0
    };
    assert!((area(&outer) - 60.0).abs() < 1e-4, "the squares' area, {}", area(&outer));
    let mask = fill_rings(&[outer.iter().map(|p| [p[0] as f64, p[1] as f64]).collect()], 20, 12);
    assert_eq!(mask.iter().filter(|&&m| m).count(), 60, "filled at pixel centres: exactly the block");
    // Reversed orientation moves the same way: offset is by inside, not by winding.
    let reversed: Vec<[f32; 2]> = centres.iter().rev().copied().collect();
    assert!((area(&offset_ring(&reversed, 0.5)) - 60.0).abs() < 1e-4);
    // A hole ring through the centres (4,4)..(7,7) of the pixels around 2 x 2 missing
    // ones shrinks by half a pixel to the missing pixels' squares: area 4.
    let hole = offset_ring(&[[4.0, 4.0], [7.0, 4.0], [7.0, 7.0], [4.0, 7.0]], -0.5);
    assert!((area(&hole) - 4.0).abs() < 1e-4);
    let rings: Vec<Vec<[f64; 2]>> =
        [outer, hole].iter().map(|r| r.iter().map(|p| [p[0] as f64, p[1] as f64]).collect()).collect();
    assert_eq!(fill_rings(&rings, 20, 12).iter().filter(|&&m| m).count(), 56, "even-odd: the hole's pixels are out");
}

#[test]
fn a_polygon_is_cut_at_a_neighbour_plane_that_meets_it_and_bounds_its_points_and_nowhere_else() {
    use polymap::extract::{Polygon, VertexKind, trim::trim_at_neighbour_planes};
    let rect = |x0: f64, x1: f64| vec![[x0, 0.0, 0.0], [x1, 0.0, 0.0], [x1, 1.0, 0.0], [x0, 1.0, 0.0]];
    let polygon = |normal: [f64; 3], offset: f64, boundary: Vec<[f64; 3]>| Polygon {
        id: 0,
        normal,
        offset,
        area: 0.0,
        boundary_kinds: vec![VertexKind::Inside; boundary.len()],
        boundary,
        holes: Vec::new(),
        hole_kinds: Vec::new(),
        pixel_count: 0,
        inlier_ratio: 1.0,
        rms: 0.0,
        uncertainty: Default::default(),
        footing: polymap::extract::Footing::Steppable,
    };
    let grid = |x0: f32, x1: f32, f: &dyn Fn(f32, f32) -> [f32; 3]| -> Vec<[f32; 3]> {
        (0..=20)
            .flat_map(|i| (0..=20).map(move |j| (i, j)))
            .map(|(i, j)| f(x0 + (x1 - x0) * i as f32 / 20.0, j as f32 / 20.0))
            .collect()
    };
    // A tread (z = 0) whose outline overshoots its points (x <= 0.28) by 2 cm, and the
    // riser (x = 0.28, facing -x) rising from its back edge.
    let riser =
        polygon([-1.0, 0.0, 0.0], 0.28, vec![[0.28, 0.0, 0.0], [0.28, 1.0, 0.0], [0.28, 1.0, 0.15], [0.28, 0.0, 0.15]]);
    let riser_points = grid(0.0, 0.15, &|z, y| [0.28, y, z]);
    let mut polygons = vec![polygon([0.0, 0.0, 1.0], 0.0, rect(0.0, 0.30)), riser.clone()];
    let tread_points = grid(0.0, 0.28, &|x, y| [x, y, 0.0]);
    let meet = |_: usize, _: usize| true;
    trim_at_neighbour_planes(&mut polygons, &[&tread_points, &riser_points], meet, 0.01);
    let max_x = polygons[0].boundary.iter().map(|v| v[0]).fold(f64::MIN, f64::max);
    assert!((max_x - 0.28).abs() < 1e-9, "the tread ends at the riser's plane, not at {max_x}");
    // The vertices on the cut say so, and name the riser; the others are as they were.
    for (v, kind) in polygons[0].boundary.iter().zip(&polygons[0].boundary_kinds) {
        let want = if v[0] == max_x { VertexKind::Cut { neighbour: Some(1) } } else { VertexKind::Inside };
        assert_eq!(*kind, want, "vertex {v:?}");
    }
    assert_eq!(polygons[0].boundary_kinds.len(), polygons[0].boundary.len());
    // A floor with points on both sides of a box face's plane: the plane does not bound it.
    let mut polygons = vec![polygon([0.0, 0.0, 1.0], 0.0, rect(0.0, 0.52)), riser];
    let floor_points = grid(0.0, 0.5, &|x, y| [x, y, 0.0]);
    trim_at_neighbour_planes(&mut polygons, &[&floor_points, &riser_points], meet, 0.01);
    let max_x = polygons[0].boundary.iter().map(|v| v[0]).fold(f64::MIN, f64::max);
    assert_eq!(max_x, 0.52, "the floor is left whole");
    // Two boxes side by side, 1 cm apart. Box A's top (z = 0.25, points up to x = 0.30),
    // seen at a grazing angle, has an outline overshooting to x = 0.315; box B's side
    // facing it is the plane x = 0.31. A's points all lie on one side of that plane and its
    // outline crosses it, but the two faces do not meet: nothing is cut.
    let top = vec![[0.0, 0.0, 0.25], [0.315, 0.0, 0.25], [0.315, 1.0, 0.25], [0.0, 1.0, 0.25]];
    let side = vec![[0.31, 0.0, 0.0], [0.31, 1.0, 0.0], [0.31, 1.0, 0.2], [0.31, 0.0, 0.2]];
    let boxes = vec![polygon([0.0, 0.0, 1.0], -0.25, top), polygon([-1.0, 0.0, 0.0], 0.31, side)];
    let points = [grid(0.0, 0.30, &|x, y| [x, y, 0.25]), grid(0.0, 0.2, &|z, y| [0.31, y, z])];
    let mut apart = boxes.clone();
    trim_at_neighbour_planes(&mut apart, &[&points[0], &points[1]], |_, _| false, 0.01);
    assert_eq!(apart, boxes, "faces that do not meet are left as they are");
    // Had they met (the rule before creases were asked for), A's top was cut there.
    let mut meeting = boxes.clone();
    trim_at_neighbour_planes(&mut meeting, &[&points[0], &points[1]], meet, 0.01);
    let max_x = meeting[0].boundary.iter().map(|v| v[0]).fold(f64::MIN, f64::max);
    assert!((max_x - 0.31).abs() < 1e-9, "{max_x}");
}

#[test]
fn regions_meet_along_a_crease_not_across_a_wide_gap_a_depth_step_or_a_corner() {
    use polymap::extract::regions::Segmentation;
    // Region A: columns 0..15, region B: from column 15 + gap on, both 20 rows; `far` puts
    // B that much further from the camera than A's 1 m; the gap's pixels have the depth
    // `between` gives the k-th of them.
    let meet_with = |gap: usize, far: f32, between: &dyn Fn(usize) -> f32| {
        let (w, h) = (40, 20);
        let boundary = Grid {
            width: w,
            height: h,
            data: (0..w * h).map(|i| u8::from((15..15 + gap).contains(&(i % w)))).collect(),
        };
        let seg = Segmentation::components(&boundary, 10);
        assert_eq!(seg.pixels.len(), if gap == 0 { 1 } else { 2 });
        let depth = |u: usize| match u {
            ..15 => 1.0,
            u if u < 15 + gap => between(u - 15),
            _ => 1.0 + far,
        };
        let depth = Grid { width: w, height: h, data: (0..w * h).map(|i| depth(i % w)).collect() };
        seg.creases(&Cloud::new(&depth, &intr(w as u32, h as u32)), 0.03).meet(1, 2)
    };
    // The gap ramps evenly from one face's depth to the other's, as across a crease.
    let meet = |gap: usize, far: f32| meet_with(gap, far, &|k| 1.0 + far * (k + 1) as f32 / (gap + 1) as f32);
    assert!(meet(1, 0.0), "a one-pixel edge line between two faces");
    assert!(meet(4, 0.0), "the widest band growth may leave");
    assert!(!meet(6, 0.0), "too far apart in the image");
    assert!(meet(3, 0.05), "a crease seen at an angle: 5 cm over 4 pixels is no depth step");
    assert!(!meet(3, 0.5), "an occluding edge: half a metre further is a depth step");
    // An occluding edge 4 cm in front of the face behind, the gap the occluder's last pixel then that
    // face: within 4 pixels' allowance end to end, but a step between two neighbours.
    assert!(!meet_with(3, 0.04, &|k| [1.0, 1.04, 1.04][k]), "a step inside the gap is a depth step");
    // The same ends across dropouts: nothing to say where the depth stepped.
    assert!(meet_with(3, 0.04, &|_| 0.0), "dropouts between the faces");
    // Two blocks touching at a corner only.
    let (w, h) = (20, 20);
    let block = |i: usize| {
        let (u, v) = (i % w, i / w);
        (u < 10 && v < 10) || (u >= 10 && v >= 10)
    };
    let boundary = Grid { width: w, height: h, data: (0..w * h).map(|i| u8::from(!block(i))).collect() };
    let seg = Segmentation::components(&boundary, 10);
    // 8-connected components join at the corner: split them by hand.
    let mut labels = seg.labels.clone();
    for (i, l) in labels.data.iter_mut().enumerate() {
        if *l != 0 {
            *l = if i % w < 10 { 1 } else { 2 };
        }
    }
    let seg = Segmentation { labels, pixels: vec![Vec::new(), Vec::new()] };
    let depth = Grid { width: w, height: h, data: vec![1.0; w * h] };
    assert!(!seg.creases(&Cloud::new(&depth, &intr(w as u32, h as u32)), 0.03).meet(1, 2), "a corner is no crease");
}

#[test]
fn bench_runs_the_cpu_stages_on_the_threads_and_vectors_it_is_given() {
    use polymap::extract::cpu::simd::Level;
    // Without POLYMAP_SIMD the widest vectors the CPU has; with it, no wider than it says.
    for (threads, simd) in [(1, None), (2, Some(Level::Baseline)), (1, Some(Level::Avx2))] {
        let mut bench = std::process::Command::new(env!("CARGO_BIN_EXE_polymap"));
        bench.args(["bench", "mock_frames/straight_320", "--backend", "cpu", "--frames", "3", "--json", "--threads"]);
        bench.arg(threads.to_string()).env_remove("POLYMAP_SIMD");
        if let Some(level) = simd {
            bench.env("POLYMAP_SIMD", level.name());
        }
        let run = bench.output().unwrap();
        assert!(run.status.success(), "{}: {}", run.status, String::from_utf8_lossy(&run.stderr));
        let v: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
        let level = simd.unwrap_or(Level::Avx512).min(Level::detected());
        assert_eq!(v["threads"], threads, "{v}");
        assert_eq!(v["simd"], level.name(), "{v}");
        assert_eq!(v["device"], format!("CPU twin, {threads} threads, {} vectors", level.name()));
        for stage in ["upload", "diffusion", "normals", "edges", "contours", "ransac", "polygons", "total"] {
            let median = v["stages_ms"][stage]["median"].as_f64().unwrap();
            assert!(median.is_finite() && median >= 0.0, "{stage}: {v}");
        }
        assert!(v["stages_ms"]["total"]["median"].as_f64().unwrap() > 0.0);
    }
}

#[test]
fn a_frame_is_the_same_on_any_number_of_threads() {
    use polymap::config::Backend;
    use polymap::extract::Extractor;
    let (depth, i, _, _) = frame(SceneKind::Straight, 320, 20, 2.0);
    let cfg = PipelineConfig { backend: Backend::Cpu, ..PipelineConfig::default() };
    // Three frames in a row on a pool of `threads`: a frame keeps the pool's other workers
    // busy until it ends, and must let them go (or the next frame never starts).
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let mut extractor = Extractor::new(&cfg).unwrap();
        (0..3).map(|_| pool.install(|| extractor.extract(&depth, &i).unwrap().polygons)).collect::<Vec<_>>()
    };
    let one = run(1);
    assert!(one[0].polygons.len() >= 3, "{} polygons", one[0].polygons.len());
    for threads in [2, 3, 4] {
        assert_eq!(run(threads), one, "{threads} threads");
    }
}

#[test]
fn pieces_of_one_plane_cut_apart_by_dropouts_are_joined_into_one_region_and_nothing_else_is() {
    use polymap::grid::label_components;
    // A 160 x 12 strip of a tread seen from 1.2 m (the nearest tread, cut by the image's
    // bottom edge), columns 70..76 spoiled by dropouts (no depth in 71..75). `right` makes
    // the right piece another plane.
    let i = intr(160, 12);
    let tread = Vector3::new(0.0, -0.8, -0.6).normalize();
    let run = |right: Option<(Vector3<f64>, f64)>| {
        let left = plane_depth(&i, tread, 1.2);
        let other = right.map(|(n, d)| plane_depth(&i, n, d));
        join_strip(160, 12, &[70], |u, k| match &other {
            Some(o) if u >= 73 => o.data[k],
            _ => left.data[k],
        })
    };
    let (joins, seg, fits) = run(None);
    assert_eq!(joins, 1);
    assert!(seg.pixels[1].is_empty() && fits[1].is_none(), "the right piece went into the left");
    assert!(fits[0].unwrap().normal.dot(&tread).abs() > 0.9999, "the joined plane is the tread's");
    // The dropouts between are bridged: one connected region, the gap included.
    let inside: Vec<bool> = seg.labels.data.iter().map(|&l| l == 1).collect();
    assert_eq!(label_components(&inside, 160, 12).1, 1, "one connected region");
    assert_eq!(seg.pixels[0].len(), 160 * 12, "both pieces and the bridged gap");
    // A parallel plane 3 cm further (no depth step at this range, but not the same plane).
    let (joins, seg, _) = run(Some((tread, 1.23)));
    assert_eq!(joins, 0);
    assert!(!seg.pixels[1].is_empty());
    // A plane 10 degrees off, meeting the tread at the gap.
    let tilted = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 10f64.to_radians()) * tread;
    let (joins, _, _) = run(Some((tilted, 1.2)));
    assert_eq!(joins, 0);
}

#[test]
fn pieces_of_one_plane_cut_apart_across_the_rows_are_bridged_down_the_columns() {
    use polymap::extract::regions::Segmentation;
    use polymap::grid::label_components;
    // A wall strip 12 wide and 160 tall, rows 70..76 boundary and 71..75 without depth:
    // the pieces above and below face each other down the columns only.
    let (w, h) = (12usize, 160usize);
    let i = intr(w as u32, h as u32);
    let mut depth = plane_depth(&i, Vector3::new(0.1, 0.0, -1.0).normalize(), 1.2);
    depth.data[71 * w..75 * w].fill(0.0);
    let boundary =
        Grid { width: w, height: h, data: (0..w * h).map(|k| u8::from((70..76).contains(&(k / w)))).collect() };
    let mut seg = Segmentation::components(&boundary, 30);
    assert_eq!(seg.pixels.len(), 2);
    let cloud = Cloud::new(&depth, &i);
    let mut fits = ransac::fit_planes(&seg.points(&[0, 1], &cloud), 64, 0.01);
    assert_eq!(seg.join_coplanar(seg.join_candidates(&cloud, 0.03), &mut fits, &cloud, 0.01, 0.9), 1);
    let inside: Vec<bool> = seg.labels.data.iter().map(|&l| l == 1).collect();
    assert_eq!(label_components(&inside, w, h).1, 1, "one connected region");
    assert_eq!(seg.pixels[0].len(), w * h, "both pieces and the bridged rows");
    assert!(seg.pixels[0].windows(2).all(|p| p[0] < p[1]), "pixels ascending");
}

/// Regions of a `w` x `h` strip cut by boundary columns `cuts` (each 6 wide, the middle
/// four without depth), fitted and joined; `depth_of(column)` picks each column's plane.
fn join_strip(
    w: usize,
    h: usize,
    cuts: &[usize],
    depth_of: impl Fn(usize, usize) -> f32,
) -> (usize, polymap::extract::regions::Segmentation, Vec<Option<ransac::PlaneFit>>) {
    use polymap::extract::regions::Segmentation;
    let i = intr(w as u32, h as u32);
    let cut = |u: usize| cuts.iter().any(|&c| (c..c + 6).contains(&u));
    let depth = Grid {
        width: w,
        height: h,
        data: (0..w * h)
            .map(|k| if cuts.iter().any(|&c| (c + 1..c + 5).contains(&(k % w))) { 0.0 } else { depth_of(k % w, k) })
            .collect(),
    };
    let boundary = Grid { width: w, height: h, data: (0..w * h).map(|k| u8::from(cut(k % w))).collect() };
    let mut seg = Segmentation::components(&boundary, 30);
    assert_eq!(seg.pixels.len(), cuts.len() + 1);
    let all: Vec<usize> = (0..seg.pixels.len()).collect();
    let batch = seg.points(&all, &Cloud::new(&depth, &i));
    let mut fits = ransac::fit_planes(&batch, 64, 0.01);
    assert!(fits.iter().all(|f| f.is_some_and(|f| f.inlier_ratio() > 0.95)), "each piece is a plane");
    let cloud = Cloud::new(&depth, &i);
    let joins = seg.join_coplanar(seg.join_candidates(&cloud, 0.03), &mut fits, &cloud, 0.01, 0.9);
    (joins, seg, fits)
}

#[test]
fn a_strip_cut_into_four_pieces_joins_into_one_and_a_neighbour_s_sliver_stays_out() {
    // The nearest tread at the image's bottom edge, 10 rows tall, cut three times: the
    // pairs A-B, B-C, C-D are found before any join, and after A took B, B-C is A-C.
    let (w, h) = (240, 10);
    let i = intr(w as u32, h as u32);
    let tread = Vector3::new(0.0, -0.8, -0.6).normalize();
    let near = plane_depth(&i, tread, 1.2);
    let (joins, seg, fits) = join_strip(w, h, &[55, 115, 175], |_, k| near.data[k]);
    assert_eq!(joins, 3, "four pieces, one region");
    assert_eq!(seg.pixels.iter().filter(|p| !p.is_empty()).count(), 1);
    assert_eq!(fits.iter().flatten().count(), 1);
    // A sliver of a parallel surface 1.5 cm further beside a large piece: under a tenth of
    // the union, so the union alone would pass the 90 % inlier test; the sliver is not on
    // the joined plane, so it stays out.
    let i = intr(260, h as u32);
    let (near, further) = (plane_depth(&i, tread, 1.2), plane_depth(&i, tread, 1.215));
    let (joins, seg, _) = join_strip(260, h, &[230], |u, k| if u >= 236 { further.data[k] } else { near.data[k] });
    assert_eq!(joins, 0, "the sliver is not swallowed");
    assert!(seg.pixels.iter().all(|p| !p.is_empty()));
}

#[test]
fn a_plane_s_reported_covariance_is_the_spread_of_its_fits_over_noisy_draws() {
    use polymap::extract::uncertainty::plane_uncertainty;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    // A tread seen from 1.2 m (normal facing the camera), through a 60 x 30 pixel block of
    // an L515-like image; range noise as synth::noise makes it: 2 mm at 1 m, growing with
    // range and at grazing incidence.
    let i = intr(320, 240);
    let n = Vector3::new(0.0, -0.8, -0.6).normalize();
    let d = 1.2;
    let rays: Vec<Vector3<f64>> = (150..180)
        .flat_map(|v| (130..190).map(move |u| (u, v)))
        .map(|(u, v)| i.ray(u as f64, v as f64).normalize())
        .collect();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let draws = 500;
    // Each draw: the truth against the fit, in the fit's terms (what the covariance is of),
    // and the covariance reported.
    let mut errors = Vec::new();
    let mut reported = Vec::new();
    for _ in 0..draws {
        let pts: Vec<[f32; 3]> = rays
            .iter()
            .map(|ray| {
                let range = -d / n.dot(ray);
                let cos = n.dot(ray).abs();
                let sigma = 0.002 * (0.5 + 0.5 * range) / cos.sqrt();
                let p = ray * (range + Normal::new(0.0, sigma).unwrap().sample(&mut rng));
                [p.x as f32, p.y as f32, p.z as f32]
            })
            .collect();
        let fit = ransac::refit(&pts, [n.x as f32, n.y as f32, n.z as f32], d as f32, 0.05).unwrap();
        let (u, _) = plane_uncertainty(&pts, 1, &fit, 0.05).expect("a block of points fixes a plane");
        errors.push(u.error_of(&n, d));
        reported.push(nalgebra::Matrix3::from_fn(|r, c| u.cov[r][c]));
    }
    // The spread of the fits about their mean: x^T C^-1 x of a 3-D Gaussian is chi-square
    // with 3 degrees of freedom, mean 3; the mean of 500 has a standard deviation of 0.11.
    let mean_error = errors.iter().sum::<Vector3<f64>>() / draws as f64;
    let chi2 = errors
        .iter()
        .zip(&reported)
        .map(|(e, c)| {
            let x = e - mean_error;
            (x.transpose() * c.try_inverse().unwrap() * x)[0]
        })
        .sum::<f64>()
        / draws as f64;
    assert!((chi2 - 3.0).abs() < 0.4, "mean chi-square {chi2:.3}, 3 expected");
    // Each parameter alone: measured variance over the mean reported one, 1 within sampling
    // (a variance of 500 draws is good to +-6 % at 1 sd).
    let mean_cov = reported.iter().sum::<nalgebra::Matrix3<f64>>() / draws as f64;
    for k in 0..3 {
        let measured = errors.iter().map(|e| (e[k] - mean_error[k]).powi(2)).sum::<f64>() / (draws - 1) as f64;
        let ratio = measured / mean_cov[(k, k)];
        assert!((ratio - 1.0).abs() < 0.2, "parameter {k}: measured / reported variance {ratio:.3}");
    }
    // A least-squares plane through points noisy along their rays is biased towards the
    // nearer, less noisy points: here 0.04 deg of tilt, about one reported sigma; far
    // under the 1 deg a foot cares about.
    assert!(mean_error[0].abs().max(mean_error[1].abs()) < 0.1f64.to_radians(), "bias {mean_error:?}");
    assert!(mean_error[2].abs() < 0.5e-3, "offset bias {} m", mean_error[2]);
}

#[test]
fn the_same_pixels_three_times_further_give_the_same_tilt_and_three_times_the_offset_uncertainty() {
    use polymap::extract::uncertainty::plane_uncertainty;
    let i = intr(320, 240);
    // Noise-free points jittered by a fixed pattern, so the residuals (the scale) are set.
    let sigma = |n: Vector3<f64>, d: f64| {
        let pts: Vec<[f32; 3]> = (150..180)
            .flat_map(|v| (130..190).map(move |u| (u, v)))
            .map(|(u, v)| {
                let ray = i.ray(u as f64, v as f64);
                let p = ray * (-d / n.dot(&ray)) * (1.0 + 0.002 * (((u * 7 + v * 13) % 5) as f64 - 2.0));
                [p.x as f32, p.y as f32, p.z as f32]
            })
            .collect();
        let fit = ransac::refit(&pts, [n.x as f32, n.y as f32, n.z as f32], d as f32, 0.05).unwrap();
        let (u, _) = plane_uncertainty(&pts, 1, &fit, 0.05).unwrap();
        (u.tilt_sigma_rad(), u.offset_sigma_m())
    };
    // The scale comes from the residuals: these grow with the depth (0.2 % steps).
    // The same block of pixels three times further: three times the noise over three times
    // the size, the same tilt; the offset three times less certain.
    let facing = Vector3::new(0.0, 0.0, -1.0);
    let (near, far) = (sigma(facing, 1.0), sigma(facing, 3.0));
    assert!(far.1 > 2.5 * near.1, "near {near:?}, far {far:?}");
    assert!((far.0 / near.0 - 1.0).abs() < 0.1, "near {near:?}, far {far:?}");
}

#[test]
fn a_sample_of_every_k_th_point_stands_for_all_of_them() {
    use polymap::extract::regions::PointSample;
    use polymap::extract::uncertainty::{halves_agreement, plane_uncertainty};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    // A 200 x 150 pixel patch of floor 1.5 m ahead, 2 mm of noise along the rays: 30 000
    // points, sampled to at most 2048 (every 15th), as a grown region hands them on.
    let i = intr(320, 240);
    let (n, d) = (Vector3::new(0.0, -0.8, -0.6).normalize(), 1.5);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let noise = Normal::new(0.0, 0.002).unwrap();
    let pts: Vec<[f32; 3]> = (60..210)
        .flat_map(|v| (60..260).map(move |u| (u, v)))
        .map(|(u, v)| {
            let ray = i.ray(u as f64, v as f64);
            let p = ray * (-d / n.dot(&ray)) * (1.0 + noise.sample(&mut rng));
            [p.x as f32, p.y as f32, p.z as f32]
        })
        .collect();
    let sample = PointSample::of(&pts, 2048);
    assert_eq!(sample.stride, 15);
    assert_eq!(sample.points, pts.iter().step_by(15).copied().collect::<Vec<_>>(), "every 15th point, in order");
    let fit = ransac::refit(&pts, [n.x as f32, n.y as f32, n.z as f32], d as f32, 0.05).unwrap();
    let (all, all_cut) = plane_uncertainty(&pts, 1, &fit, 0.05).unwrap();
    let (sampled, sampled_cut) = plane_uncertainty(&sample.points, sample.stride, &fit, 0.05).unwrap();
    // Unweighted, the sample's sigmas would be sqrt(15) = 3.9 times all the points'.
    for (s, a) in [(sampled.tilt_sigma_rad(), all.tilt_sigma_rad()), (sampled.offset_sigma_m(), all.offset_sigma_m())] {
        assert!((s / a - 1.0).abs() < 0.1, "sample {s:e} vs all {a:e}");
    }
    // So do the two halves' planes: the noise their angle is held to is all the points'.
    let halves_all = halves_agreement(&pts, 1, &fit, 0.05, &all_cut).unwrap();
    let halves_sampled = halves_agreement(&sample.points, sample.stride, &fit, 0.05, &sampled_cut).unwrap();
    let (s, a) = (halves_sampled.sigma_rad, halves_all.sigma_rad);
    assert!((s / a - 1.0).abs() < 0.1, "halves: sample {s:e} vs all {a:e}");
    let small = PointSample::of(&pts[..1000], 2048);
    assert_eq!((small.stride, small.points.len()), (1, 1000), "a small region whole");
    // The points handed over in parts (as a large region's refit gathers them): the same
    // sample, wherever the cuts fall against the stride.
    for cuts in [vec![0, 30_000], vec![0, 1, 14, 15, 16, 7000, 29_999, 30_000], vec![0, 0, 16_384, 30_000]] {
        let parts: Vec<&[[f32; 3]]> = cuts.windows(2).map(|c| &pts[c[0]..c[1]]).collect();
        assert_eq!(PointSample::of_parts(&parts, 2048), sample, "cut at {cuts:?}");
    }
}

#[test]
fn a_strip_that_took_in_two_rows_of_the_riser_is_two_surfaces_and_a_clean_one_is_one() {
    let max_bend = PipelineConfig::default().max_halves_bend_deg.to_radians();
    use polymap::extract::uncertainty::{halves_agreement, plane_uncertainty};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    // A tread 0.3 m below the camera, seen 1 m ahead as a strip 4 cm deep (the image's top
    // edge cuts it), in 4 mm rows; 1 mm of noise. `riser` rows beyond its back edge go up
    // the riser, 3 mm each: all within the 1 cm inlier band of the tread's plane.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let noise = Normal::new(0.0, 0.001).unwrap();
    let mut strip = |riser: usize| -> Vec<[f32; 3]> {
        let mut pts = Vec::new();
        for x in 0..100 {
            let x = x as f32 * 0.003 - 0.15;
            for row in 0..10 {
                pts.push([x, 0.3 + noise.sample(&mut rng), 1.0 + row as f32 * 0.004]);
            }
            for row in 1..=riser {
                pts.push([x, 0.3 - row as f32 * 0.003, 1.04 + noise.sample(&mut rng)]);
            }
        }
        pts
    };
    let bend_of = |pts: &[[f32; 3]]| {
        let fit = ransac::refit(pts, [0.0, -1.0, 0.0], 0.3, 0.01).unwrap();
        assert!(fit.inlier_ratio() > 0.95, "one plane by the inlier test: {fit:?}");
        let (_, cut) = plane_uncertainty(pts, 1, &fit, 0.01).expect("the strip fixes a plane");
        (fit, halves_agreement(pts, 1, &fit, 0.01, &cut).expect("both halves fix a plane"))
    };
    let (fit, clean) = bend_of(&strip(0));
    assert!(clean.one_surface(max_bend), "{clean:?}");
    assert!(fit.normal.y < -0.9999, "the clean strip's plane is level: {:?}", fit.normal);
    let (fit, mixed) = bend_of(&strip(2));
    assert!(!mixed.one_surface(max_bend), "{mixed:?}");
    assert!(mixed.angle_rad > 10.0 * mixed.sigma_rad, "far beyond the noise: {mixed:?}");
    assert!(fit.normal.y > -0.9998, "and its fit is tilted by over a degree: {:?}", fit.normal);
}

#[test]
fn what_is_held_back_is_recorded_with_its_reason_and_what_is_doubtful_is_marked() {
    use polymap::extract::{Footing, HoldBack};
    // Frame 28 of the straight walk has a region whose halves bend: under the default bar
    // it is published, its bend counted in its covariance (not steppable); with the bar
    // lowered under its bend it is held back, not published, and said why.
    let seq = polymap::sequence::Sequence::open("mock_frames/straight_320").unwrap();
    let default = PipelineConfig::default();
    let strict = PipelineConfig { max_halves_bend_deg: 2.0, ..default.clone() };
    let mut not_one_plane = [0; 2];
    let mut marked = [0; 2];
    for (i, cfg) in [&default, &strict].into_iter().enumerate() {
        let e = extract_cpu(&seq.depth(28).unwrap(), &seq.intrinsics, cfg).unwrap();
        for h in &e.stages.held_back {
            match h.why {
                HoldBack::TooSmall => assert!(h.area < cfg.min_polygon_area_m2, "{h:?}"),
                HoldBack::NotOnePlane | HoldBack::NoPlane => assert!(h.area >= cfg.min_polygon_area_m2, "{h:?}"),
            }
            assert!(!e.polygons.polygons.iter().any(|p| p.normal == h.normal), "held back and published: {h:?}");
            not_one_plane[i] += usize::from(h.why == HoldBack::NotOnePlane && h.pixel_count > 500);
        }
        marked[i] =
            (e.polygons.polygons.iter()).filter(|p| p.footing == Footing::TiltUnknown && p.pixel_count > 500).count();
    }
    assert!(marked[0] >= 1 && not_one_plane[0] == 0, "the bent region is published, not steppable: {marked:?}");
    assert!(not_one_plane[1] >= 1, "and held back under a lower bar: {not_one_plane:?}");
    assert!(marked[1] < marked[0], "which it no longer passes: {marked:?}");
}
