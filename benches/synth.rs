//! How fast the synthetic world renders and adds noise (the mock camera's cost per frame).

use criterion::{Criterion, criterion_group, criterion_main};
use polymap::synth::{NoiseModel, Scene, SceneKind, noisy_depth, path::trajectory, render};
use polymap::types::Intrinsics;

fn bench(c: &mut Criterion) {
    for kind in [SceneKind::Straight, SceneKind::Spiral] {
        let scene = Scene::build(kind);
        let pose = trajectory(&scene, 30)[15];
        for width in [320u32, 640] {
            let intr = Intrinsics::L515_320X240.scaled_to(width, width * 3 / 4);
            c.bench_function(&format!("render {kind:?} {width}x{}", width * 3 / 4), |b| {
                b.iter(|| render(&scene, &intr, &pose))
            });
            let r = render(&scene, &intr, &pose);
            let model = NoiseModel::l515(2.0);
            c.bench_function(&format!("noise {kind:?} {width}x{}", width * 3 / 4), |b| {
                b.iter(|| noisy_depth(&r, &model, 1, 0))
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
