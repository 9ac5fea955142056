//! The GPU twin against the CPU twin, stage by stage, on every mock sequence.
//!
//! These run on whatever Vulkan adapter there is: a real GPU, or Mesa's lavapipe on a
//! machine without one. With CI=true a missing adapter fails the test; elsewhere the
//! test says why it did not run and passes, so a laptop without Vulkan can still run
//! the rest of the suite.

use std::sync::{Mutex, OnceLock};

use nalgebra::Vector3;
use polymap::config::PipelineConfig;
use polymap::extract::cpu::components::{components_oracle, dense_from_roots};
use polymap::extract::cpu::{self, classify, diffusion, gradient, hysteresis, morphology, normals, ransac};
use polymap::extract::gpu::{DepthUpload, Gpu};
use polymap::extract::params::{Stage, stages_run};
use polymap::extract::regions::Segmentation;
use polymap::extract::{Extraction, Grid, Images, MIN_REGION_PIXELS, depth_metres, extract_cpu, extract_gpu};
use polymap::grid::label_components;
use polymap::sequence::Sequence;
use polymap::types::{DepthFrame, Intrinsics};

/// One device for the whole test binary: opening one costs more than a frame.
fn gpu() -> Option<&'static Mutex<Gpu>> {
    static GPU: OnceLock<Option<Mutex<Gpu>>> = OnceLock::new();
    GPU.get_or_init(|| match Gpu::new() {
        Ok(g) => {
            eprintln!("GPU twin on {}", g.describe());
            Some(Mutex::new(g))
        }
        Err(e) if std::env::var("CI").is_ok_and(|v| v == "true") => panic!("CI=true and no GPU adapter: {e}"),
        Err(e) => {
            eprintln!("skipping the GPU twin tests (set CI=true to make this a failure): {e}");
            None
        }
    })
    .as_ref()
}

/// Frames of every mock sequence, every `step`-th.
fn mock_frames(step: usize) -> Vec<(String, Sequence, usize)> {
    let mut out = Vec::new();
    for name in ["straight_320", "spiral_320", "straight_640"] {
        let seq = Sequence::open(format!("mock_frames/{name}")).unwrap();
        for k in (0..seq.len()).step_by(step) {
            out.push((name.to_string(), seq.clone(), k));
        }
    }
    out
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

/// The GPU's stages of one frame with their images read back.
fn gpu_images(gpu: &mut Gpu, depth: DepthUpload, seq: &Sequence, cfg: &PipelineConfig) -> (Images, Segmentation) {
    let (g, ()) = gpu.image_stages(depth, &seq.intrinsics, cfg, true, || ()).unwrap();
    (g.images.expect("asked for the images"), g.regions)
}

/// Share of pixels where two masks differ.
fn share_differing(a: &Grid<u8>, b: &Grid<u8>) -> f64 {
    a.data.iter().zip(&b.data).filter(|(x, y)| x != y).count() as f64 / a.data.len() as f64
}

#[test]
fn image_stages_agree_with_the_cpu_twin_on_every_mock_sequence() {
    let Some(gpu) = gpu() else { return };
    let mut gpu = gpu.lock().unwrap_or_else(|e| e.into_inner());
    let cfg = PipelineConfig::default();
    let mut worst_depth = 0.0f32;
    for (name, seq, k) in mock_frames(5) {
        // The GPU from the raw frame, as a frame runs; the CPU from its metres.
        let frame = seq.depth(k).unwrap();
        let depth = depth_metres(&frame, &seq.intrinsics).unwrap();
        let (g, regions) = gpu_images(&mut gpu, DepthUpload::Raw(&frame), &seq, &cfg);
        let c = cpu::image_stages(&depth, &seq.intrinsics, &cfg, &mut Default::default(), &mut || 0.0);
        let d = max_abs_diff(&g.smoothed.data, &c.smoothed.data);
        // A few ulps of depth (0.5 µm when written): the GPU may fuse multiply-adds.
        assert!(d <= 2e-6, "{name} frame {k}: diffusion differs by {d} m");
        worst_depth = worst_depth.max(d);
        // Zeros (invalid) must agree exactly: holes are never filled by either twin.
        assert!(g.smoothed.data.iter().zip(&c.smoothed.data).all(|(a, b)| (*a == 0.0) == (*b == 0.0)));

        let d = max_abs_diff(&g.normals.data, &c.normals.data);
        assert!(d <= 1e-4, "{name} frame {k}: normals differ by {d}");

        // Edges and boundary from each twin's own inputs, as the pipelines run them.
        let share = share_differing(&c.canny, &g.canny);
        assert!(share < 0.005, "{name} frame {k}: edge maps differ in {:.3} % of pixels", share * 100.0);
        assert!(c.canny.data.iter().any(|&e| e != 0), "{name} frame {k}: the stairs have edges");
        let share = share_differing(&c.boundary, &g.boundary);
        assert!(share < 0.005, "{name} frame {k}: boundaries differ in {:.3} % of pixels", share * 100.0);
        // The GPU's regions, numbered in its mapped readback buffer, are the CPU twin's
        // regions of the GPU's own boundary, pixel lists and all.
        let want = Segmentation::components(&g.boundary, MIN_REGION_PIXELS);
        assert!(want.pixels.len() > 3, "{name} frame {k}: {} regions", want.pixels.len());
        assert_eq!(regions.labels, want.labels, "{name} frame {k}: region labels");
        assert_eq!(regions.pixels, want.pixels, "{name} frame {k}: region pixels");
    }
    eprintln!("worst smoothed depth difference {worst_depth:e} m");
}

#[test]
fn both_twins_run_the_stages_in_the_one_order() {
    let Some(device) = gpu() else { return };
    let mut device = device.lock().unwrap_or_else(|e| e.into_inner());
    let cfg = PipelineConfig::default();
    let (name, seq, k) = &mock_frames(10)[0];
    let frame = seq.depth(*k).unwrap();
    let (cpu, cpu_order) = stages_run(|| extract_cpu(&frame, &seq.intrinsics, &cfg).unwrap());
    let (gpu, gpu_order) = stages_run(|| extract_gpu(&mut device, &frame, &seq.intrinsics, &cfg, false).unwrap());
    assert!(!cpu.polygons.polygons.is_empty() && !gpu.polygons.polygons.is_empty(), "{name} frame {k}");
    assert_eq!(cpu_order, Stage::ORDER, "the CPU twin");
    assert_eq!(gpu_order, Stage::ORDER, "the GPU twin");
    // Nothing is noted outside a listening `stages_run`.
    extract_cpu(&frame, &seq.intrinsics, &cfg).unwrap();
    assert_eq!(stages_run(|| ()).1, []);
}

#[test]
fn whole_frames_give_the_same_polygons_on_both_twins() {
    let Some(gpu) = gpu() else { return };
    let mut gpu = gpu.lock().unwrap_or_else(|e| e.into_inner());
    let cfg = PipelineConfig::default();
    let mut compared = 0;
    for (name, seq, k) in mock_frames(5) {
        let frame = seq.depth(k).unwrap();
        let c = extract_cpu(&frame, &seq.intrinsics, &cfg).unwrap().polygons;
        let Extraction { polygons: g, stages, times, .. } =
            extract_gpu(&mut gpu, &frame, &seq.intrinsics, &cfg, false).unwrap();
        assert!(stages.images.is_none(), "{name} frame {k}: images read back unasked");
        if gpu.has_timestamps() {
            // The submit's span holds its stages (and the gaps between them).
            let stages = times.diffusion + times.normals + times.edges;
            assert!(times.gpu_busy > 0.0 && times.gpu_busy >= stages * (1.0 - 1e-9), "{name} frame {k}: {times:?}");
        }
        assert_eq!(c.polygons.len(), g.polygons.len(), "{name} frame {k}: polygon counts");
        for (a, b) in c.polygons.iter().zip(&g.polygons) {
            let angle = Vector3::from(a.normal).angle(&Vector3::from(b.normal)).to_degrees();
            assert!(angle <= 0.2, "{name} frame {k} polygon {}: normals {angle} deg apart", a.id);
            assert!((a.offset - b.offset).abs() <= 0.002, "{name} frame {k} polygon {}: offsets", a.id);
            let (ca, cb) = (a.centroid(), b.centroid());
            let shift = (Vector3::from(ca) - Vector3::from(cb)).norm();
            assert!(shift <= 0.002, "{name} frame {k} polygon {}: centroids {shift} m apart", a.id);
            compared += 1;
        }
    }
    assert!(compared > 50, "only {compared} polygons compared");
}

#[test]
fn an_image_wider_than_the_diffusion_solves_is_refused_not_cut() {
    let Some(gpu) = gpu() else { return };
    let mut gpu = gpu.lock().unwrap_or_else(|e| e.into_inner());
    let seq = Sequence::open("mock_frames/straight_320").unwrap();
    let cfg = PipelineConfig::default();
    let wide = Grid { width: 2049, height: 8, data: vec![1.5f32; 2049 * 8] };
    let err = gpu.image_stages(DepthUpload::Metres(&wide), &seq.intrinsics, &cfg, false, || ()).err().expect("refused");
    assert!(err.to_string().contains("2049x8"), "{err}");
    // The device is still good for the next frame.
    let frame = seq.depth(0).unwrap();
    assert!(gpu.image_stages(DepthUpload::Raw(&frame), &seq.intrinsics, &cfg, false, || ()).is_ok());
}

#[test]
fn a_frame_whose_pixels_do_not_fill_it_is_refused_not_read_past() {
    let Some(gpu) = gpu() else { return };
    let mut gpu = gpu.lock().unwrap_or_else(|e| e.into_inner());
    let (cfg, intr) = (PipelineConfig::default(), Intrinsics::L515_320X240);
    for len in [320 * 240 - 1, 320 * 240 + 2] {
        let frame = DepthFrame { stamp_ns: 0, width: 320, height: 240, depth_scale: 0.00025, pixels: vec![4000; len] };
        let err = gpu.image_stages(DepthUpload::Raw(&frame), &intr, &cfg, false, || ()).err().expect("refused");
        assert_eq!(err.to_string(), format!("a 320x240 image of {len} pixels"));
        assert!(gpu.metres_alone(&frame).is_err(), "{len} pixels converted");
    }
    let short = Grid { width: 320, height: 240, data: vec![1.0f32; 100] };
    assert!(gpu.image_stages(DepthUpload::Metres(&short), &intr, &cfg, false, || ()).is_err());
}

#[test]
fn the_raw_depth_s_metres_are_the_cpu_twin_s_bit_for_bit() {
    // The conversion alone, from the same raw frame: one product a pixel on both twins.
    let Some(gpu) = gpu() else { return };
    let mut gpu = gpu.lock().unwrap_or_else(|e| e.into_inner());
    let mut valid = 0;
    for (name, seq, k) in mock_frames(5) {
        let frame = seq.depth(k).unwrap();
        let want = depth_metres(&frame, &seq.intrinsics).unwrap();
        let got = gpu.metres_alone(&frame).unwrap();
        assert_eq!(got.data.len(), want.data.len(), "{name} frame {k}: pixels");
        let bits = |d: &[f32]| d.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&got.data), bits(&want.data), "{name} frame {k}: metres");
        valid += want.data.iter().filter(|&&z| z > 0.0).count();
    }
    assert!(valid > 1_000_000, "{valid} valid pixels compared");
    // An odd pixel count (the last word half padding), the extremes of 16 bits, and a
    // scale that is not a power of two.
    let pixels: Vec<u16> = (0..5 * 3).map(|i| [0, 1, 65535, 4000, 12345][i % 5]).collect();
    let frame = DepthFrame { stamp_ns: 0, width: 5, height: 3, depth_scale: 0.00025, pixels };
    let intr = Intrinsics { width: 5, height: 3, ..Intrinsics::L515_320X240 };
    let want = depth_metres(&frame, &intr).unwrap();
    assert_eq!(gpu.metres_alone(&frame).unwrap().data, want.data, "5 x 3 frame");
    assert_eq!(want.data[2], 65535.0 * 0.00025f32, "the largest value");
}

#[test]
fn normals_and_edges_alone_agree_with_the_cpu_twin_on_the_same_input() {
    // No diffusion steps: the GPU's normals and edges are computed from exactly the
    // depth the CPU's are, the CPU twin's smoothed depth, so each stage is compared alone.
    let Some(gpu) = gpu() else { return };
    let mut gpu = gpu.lock().unwrap_or_else(|e| e.into_inner());
    let cfg = PipelineConfig::default();
    let stages_only = PipelineConfig { diffusion_steps: 0, ..cfg.clone() };
    let (mut worst_normal, mut worst_share) = (0.0f32, 0.0f64);
    for (name, seq, k) in mock_frames(5) {
        let depth = depth_metres(&seq.depth(k).unwrap(), &seq.intrinsics).unwrap();
        let smoothed =
            diffusion::diffuse(&depth, cfg.diffusion_time as f32, cfg.diffusion_steps, cfg.diffusion_kappa_m as f32);
        let (g, _) = gpu_images(&mut gpu, DepthUpload::Metres(&smoothed), &seq, &stages_only);
        assert_eq!(g.smoothed.data, smoothed.data, "{name} frame {k}: no steps, no change");

        let n = normals::normal_planes(&smoothed, &seq.intrinsics, cfg.normal_kernel);
        let d = max_abs_diff(&g.normals.data, &n.data);
        assert!(d <= 1e-5, "{name} frame {k}: normals differ by {d}");
        worst_normal = worst_normal.max(d);

        // Canny's edges, from each twin's normals (equal to 1e-5: only a magnitude within
        // rounding of a threshold or a tie may flip a pixel, and hysteresis its line).
        let class = classify::classify(&gradient::gradient_of_planes(&n), cfg.canny_low as f32, cfg.canny_high as f32);
        let share = share_differing(&hysteresis::hysteresis(&class), &g.canny);
        assert!(share < 0.001, "{name} frame {k}: edges differ in {:.3} % of pixels", share * 100.0);
        assert!(class.data.contains(&2), "{name} frame {k}: the stairs have strong edges");
        worst_share = worst_share.max(share);
    }
    eprintln!("worst normal difference {worst_normal:e}, edges differing {:.4} %", worst_share * 100.0);
}

/// Per frame of every mock sequence: the CPU twin's classes, edges, smoothed depth and normals.
fn cpu_inputs(step: usize) -> Vec<(String, usize, Grid<u8>, Images)> {
    let cfg = PipelineConfig::default();
    mock_frames(step)
        .into_iter()
        .map(|(name, seq, k)| {
            let depth = depth_metres(&seq.depth(k).unwrap(), &seq.intrinsics).unwrap();
            let images = cpu::image_stages(&depth, &seq.intrinsics, &cfg, &mut Default::default(), &mut || 0.0);
            let grad = gradient::gradient_of_planes(&images.normals);
            (name, k, classify::classify(&grad, cfg.canny_low as f32, cfg.canny_high as f32), images)
        })
        .collect()
}

/// The four stages not yet compared alone: each from the same input on both twins, on
/// every tenth frame of every mock sequence. The diffusion and the gradient are float
/// arithmetic the GPU may fuse (a few ulps); classify and the closing only compare and
/// count, so they are equal exactly.
#[test]
fn diffusion_gradient_classify_and_closing_alone_agree_with_the_cpu_twin() {
    let Some(gpu) = gpu() else { return };
    let mut gpu = gpu.lock().unwrap_or_else(|e| e.into_inner());
    let cfg = PipelineConfig::default();
    let (mut worst_depth, mut worst_magnitude, mut worst_sectors) = (0.0f32, 0.0f32, 0.0f64);
    let mut closed_changed = 0;
    for (name, seq, k) in mock_frames(10) {
        let depth = depth_metres(&seq.depth(k).unwrap(), &seq.intrinsics).unwrap();
        let smoothed =
            diffusion::diffuse(&depth, cfg.diffusion_time as f32, cfg.diffusion_steps, cfg.diffusion_kappa_m as f32);
        let g = gpu.diffusion_alone(&depth, &cfg).unwrap();
        let d = max_abs_diff(&g.data, &smoothed.data);
        assert!(d <= 2e-6, "{name} frame {k}: diffusion differs by {d} m");
        assert!(g.data.iter().zip(&smoothed.data).all(|(a, b)| (*a == 0.0) == (*b == 0.0)), "{name} frame {k}: holes");
        assert!(max_abs_diff(&smoothed.data, &depth.data) > 1e-3, "{name} frame {k}: the diffusion changes the depth");
        worst_depth = worst_depth.max(d);

        let planes = normals::normal_planes(&smoothed, &seq.intrinsics, cfg.normal_kernel);
        let want = gradient::gradient_of_planes(&planes);
        let got = gpu.gradient_alone(&planes.interleaved(), &cfg).unwrap();
        let d = max_abs_diff(&got.magnitude.data, &want.magnitude.data);
        assert!(d <= 1e-5, "{name} frame {k}: gradient magnitudes differ by {d}");
        worst_magnitude = worst_magnitude.max(d);
        // A sector is a comparison of the gradient's sums: only a tie within rounding flips it.
        let share = got.sector.data.iter().zip(&want.sector.data).filter(|(a, b)| a != b).count() as f64
            / want.sector.data.len() as f64;
        assert!(share < 0.001, "{name} frame {k}: sectors differ in {:.3} % of pixels", share * 100.0);
        worst_sectors = worst_sectors.max(share);

        let class = classify::classify(&want, cfg.canny_low as f32, cfg.canny_high as f32);
        assert_eq!(gpu.classify_alone(&want, &cfg).unwrap(), class, "{name} frame {k}: classes");
        assert!(class.data.contains(&1) && class.data.contains(&2), "{name} frame {k}: weak and strong pixels");

        let edges = hysteresis::hysteresis(&class);
        let closed = morphology::close(&edges, cfg.closing_kernel_px);
        assert_eq!(gpu.closing_alone(&edges, &cfg).unwrap(), closed, "{name} frame {k}: closing");
        closed_changed += closed.data.iter().zip(&edges.data).filter(|(a, b)| a != b).count();
    }
    assert!(closed_changed > 100, "the closing fills {closed_changed} pixels, a closing worth comparing");
    eprintln!(
        "worst: smoothed depth {worst_depth:e} m, magnitude {worst_magnitude:e}, sectors differing {:.4} %",
        worst_sectors * 100.0
    );
}

#[test]
fn hysteresis_boundary_and_regions_alone_are_the_cpu_twin_s_bit_for_bit() {
    // Each stage from the same input on both twins: integer results, so equal exactly.
    let Some(gpu) = gpu() else { return };
    let mut gpu = gpu.lock().unwrap_or_else(|e| e.into_inner());
    let cfg = PipelineConfig::default();
    let mut regions_seen = 0;
    for (name, k, class, c) in cpu_inputs(10) {
        let edges = gpu.hysteresis_alone(&class, &cfg).unwrap();
        assert_eq!(edges, c.canny, "{name} frame {k}: hysteresis");
        assert!(
            class.data.iter().zip(&c.canny.data).any(|(&cl, &e)| cl == 1 && e == 0),
            "{name} frame {k}: weak pixels dropped"
        );

        let boundary = gpu.boundary_alone(&c.canny, &c.smoothed, &c.normals.interleaved(), &cfg).unwrap();
        assert_eq!(boundary, c.boundary, "{name} frame {k}: boundary");

        let roots = gpu.regions_alone(&c.boundary).unwrap();
        let free = |i: usize| c.boundary.data[i] == 0;
        assert_eq!(roots.data, components_oracle(roots.width, roots.height, free), "{name} frame {k}: root labels");
        let mut labels = roots.data;
        let count = dense_from_roots(&mut labels);
        let mask: Vec<bool> = (0..labels.len()).map(free).collect();
        assert_eq!((labels, count), label_components(&mask, roots.width, roots.height), "{name} frame {k}: regions");
        regions_seen += count;
    }
    assert!(regions_seen > 50, "{regions_seen} regions compared");
}

#[test]
fn batched_scores_match_the_cpu_scores_exactly_on_planted_planes() {
    let Some(gpu) = gpu() else { return };
    let mut gpu = gpu.lock().unwrap_or_else(|e| e.into_inner());
    // Several regions of very different sizes (3 points up to past the scoring cap), and an empty one.
    let mut batch = ransac::PointBatch::default();
    let mut state = 7u32;
    let mut rnd = || {
        state = ransac::hash(state);
        state as f32 / u32::MAX as f32
    };
    for (r, n) in [3usize, 40, 1000, 5000, 0, 12000].into_iter().enumerate() {
        let start = batch.points.len();
        for k in 0..n {
            let (s, t) = (rnd() - 0.5, rnd() - 0.5);
            let off = if k % 7 == 0 { 0.1 * rnd() } else { 0.002 * (rnd() - 0.5) };
            batch.points.push([s, t * 0.8 + off * 0.6, 1.0 + r as f32 * 0.1 + t * 0.6 - off * 0.8]);
        }
        batch.ranges.push(start..batch.points.len());
    }
    let cpu = ransac::score_hypotheses(&batch, 20, 0.01);
    let g = gpu.score_hypotheses(&batch, 20, 0.01).unwrap();
    assert_eq!(cpu.len(), 120);
    // Points within float rounding of the inlier distance may count differently.
    for (k, (a, b)) in cpu.iter().zip(&g).enumerate() {
        assert!(a.abs_diff(*b) <= 2, "region {} hypothesis {}: cpu {a} gpu {b}", k / 20, k % 20);
    }
    assert!(cpu[2 * 20..3 * 20].iter().any(|&s| s > 800), "the 1000-point plane has a good hypothesis");
    assert!(g[4 * 20..5 * 20].iter().all(|&s| s == 0), "an empty region scores nothing");
    // The buffers are kept between batches: a smaller batch after it (the larger one's
    // points still lie beyond), then one that outgrows them (more hypotheses, more points).
    let small =
        ransac::PointBatch { points: batch.points[..batch.ranges[2].end].to_vec(), ranges: batch.ranges[..3].to_vec() };
    let mut large = batch.clone();
    for k in 0..30_000 {
        let t = k as f32 / 30_000.0;
        large.points.push([t, 0.5 - t, 2.0 + 0.001 * (k % 3) as f32]);
    }
    large.ranges.push(batch.points.len()..large.points.len());
    for (name, b, hypotheses) in [("smaller", &small, 20), ("larger", &large, 32)] {
        let (cpu, g) =
            (ransac::score_hypotheses(b, hypotheses, 0.01), gpu.score_hypotheses(b, hypotheses, 0.01).unwrap());
        assert_eq!(g.len(), b.ranges.len() * hypotheses as usize, "{name}");
        for (k, (a, c)) in cpu.iter().zip(&g).enumerate() {
            assert!(a.abs_diff(*c) <= 2, "{name} batch, score {k}: cpu {a} gpu {c}");
        }
    }
}
