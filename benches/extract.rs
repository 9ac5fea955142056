//! Per-stage cost of extraction on the CPU twin, and the whole frame on the GPU twin
//! when there is an adapter, at 320x240, 640x480 and 1024x768 on a synthetic stair frame.
//! `polymap bench SEQ` gives the same per frame over a sequence, with p99.

use criterion::{Criterion, criterion_group, criterion_main};
use polymap::config::PipelineConfig;
use polymap::extract::cloud::Cloud;
use polymap::extract::cpu::{boundary, diffusion, gradient, hysteresis, normals, ransac};
use polymap::extract::{depth_metres, extract_cpu, extract_gpu, gpu::Gpu, regions::Segmentation};
use polymap::synth::{NoiseModel, Scene, SceneKind, noisy_depth, path::trajectory, render};
use polymap::types::{DepthFrame, Intrinsics};

fn bench(c: &mut Criterion) {
    polymap::keep_freed_memory();
    let scene = Scene::build(SceneKind::Straight);
    let pose = trajectory(&scene, 30)[20];
    let cfg = PipelineConfig::default();
    let mut gpu = Gpu::new().ok();
    for width in [320u32, 640, 1024] {
        let intr = Intrinsics::L515_320X240.scaled_to(width, width * 3 / 4);
        let pixels = noisy_depth(&render(&scene, &intr, &pose), &NoiseModel::l515(2.0), 1, 0);
        let frame = DepthFrame { stamp_ns: 0, width, height: intr.height, depth_scale: intr.depth_scale, pixels };
        let size = format!("{width}x{}", intr.height);
        let depth = depth_metres(&frame, &intr).unwrap();
        let kappa = cfg.diffusion_kappa_m as f32;
        c.bench_function(&format!("cpu diffusion {size}"), |b| b.iter(|| diffusion::diffuse(&depth, 12.0, 4, kappa)));
        let smoothed = diffusion::diffuse(&depth, 12.0, 4, kappa);
        c.bench_function(&format!("cpu normals {size}"), |b| b.iter(|| normals::normals(&smoothed, &intr, 5)));
        let planes = normals::normal_planes(&smoothed, &intr, 5);
        c.bench_function(&format!("cpu edges {size}"), |b| {
            b.iter(|| {
                let e = hysteresis::canny(&gradient::gradient_of_planes(&planes), 0.05, 0.1);
                boundary::boundary(&e, &smoothed, 0.03, &planes, cfg.closing_kernel_px, 5)
            })
        });
        let e = hysteresis::canny(&gradient::gradient_of_planes(&planes), 0.05, 0.1);
        let boundary = boundary::boundary(&e, &smoothed, 0.03, &planes, cfg.closing_kernel_px, 5);
        c.bench_function(&format!("cpu regions {size}"), |b| b.iter(|| Segmentation::components(&boundary, 30)));
        let seg = Segmentation::components(&boundary, 30);
        let all: Vec<usize> = (0..seg.pixels.len()).collect();
        let batch = seg.points(&all, &Cloud::new(&depth, &intr));
        c.bench_function(&format!("cpu ransac {size}"), |b| b.iter(|| ransac::fit_planes(&batch, 20, 0.01)));
        c.bench_function(&format!("cpu frame {size}"), |b| b.iter(|| extract_cpu(&frame, &intr, &cfg).unwrap()));
        if let Some(g) = gpu.as_mut() {
            c.bench_function(&format!("gpu frame {size}"), |b| {
                b.iter(|| extract_gpu(g, &frame, &intr, &cfg, false).unwrap())
            });
        }
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench
}
criterion_main!(benches);
