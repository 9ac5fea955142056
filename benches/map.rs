//! Map update cost with 300, 3,000 and 30,000 polygons in the map: the camera looks at the
//! same 300 tiles whatever the size (the rest of the map lies beyond its view, as in a
//! building mapped room by room), each timed frame re-observes 12 of them (merge, drift
//! measurement, relabelling) and clears against a 320x240 depth image. Prints median and
//! p99 over 1000 frames per size, then the cost of publishing the changed polygons (convex
//! pieces and insets), which happens only when they are sent.
//!
//! cargo bench --bench map

use std::time::Instant;

use nalgebra::Isometry3;
use polymap::config::MapConfig;
use polymap::extract::{Grid, Polygon, VertexKind};
use polymap::map::PolygonMap;
use polymap::stats::spread;
use polymap::synth::path::camera_pose;
use polymap::types::{Intrinsics, Pose};

/// Tiles 0..300: a 20 x 15 grid of 0.2 m tiles, 0.1 m apart, at heights cycling through 7
/// steps, in front of the camera. The others: the same, 200 a row, from 20 m further on.
fn tile(i: usize) -> ([f64; 2], f64) {
    let (col, row, x0) = if i < 300 { (i % 20, i / 20, 0.0) } else { ((i - 300) % 200, (i - 300) / 200, 20.0) };
    ([x0 + col as f64 * 0.3, row as f64 * 0.3 - 2.25], (i % 7) as f64 * 0.15)
}

fn seen(i: usize, t_camera_world: &Isometry3<f64>) -> Polygon {
    let ([x, y], z) = tile(i);
    let world = Polygon {
        id: i as u32,
        normal: [0.0, 0.0, 1.0],
        offset: -z,
        area: 0.04,
        boundary: vec![[x, y, z], [x + 0.2, y, z], [x + 0.2, y + 0.2, z], [x + 0.1, y + 0.25, z], [x, y + 0.2, z]],
        holes: vec![],
        boundary_kinds: vec![VertexKind::Inside; 5],
        hole_kinds: vec![],
        pixel_count: 2000,
        inlier_ratio: 1.0,
        rms: 0.002,
        uncertainty: Default::default(),
        footing: polymap::extract::Footing::Steppable,
    };
    world.transformed(t_camera_world)
}

fn main() {
    // `cargo test --all-targets` runs benches without --bench: a short smoke run then.
    let frames = if std::env::args().any(|a| a == "--bench") { 1000 } else { 20 };
    for size in [300, 3_000, 30_000] {
        run(size, frames);
    }
}

fn run(size: usize, frames: usize) {
    let intr = Intrinsics::L515_320X240;
    let pose = camera_pose(nalgebra::Point3::new(-1.0, 0.0, 1.5), 0.0, 40f64.to_radians(), 0.0);
    let inv = pose.inverse();
    let mut map = PolygonMap::new(&MapConfig::default());
    let all: Vec<Polygon> = (0..size).map(|i| seen(i, &inv)).collect();
    map.update(&all, &Pose { stamp_ns: 0, transform: pose }, &intr, None);
    assert_eq!(map.len(), size, "the tiles stay apart");
    // Every sample of every polygon in view is projected and looked up; the depth is 1 m
    // nearer than anything (it hides the tiles, which says nothing of them) so that nothing
    // is cleared and the map keeps its polygons.
    let depth = Grid { width: 320, height: 240, data: vec![0.5f32; 320 * 240] };
    let (mut update_ms, mut publish_ms) = (Vec::with_capacity(frames), Vec::with_capacity(frames));
    for k in 0..frames {
        let polys: Vec<Polygon> = (0..12).map(|j| seen((k * 7 + j * 25) % 300, &inv)).collect();
        let t = Instant::now();
        let update =
            map.update(&polys, &Pose { stamp_ns: k as u64 * 33_333_333, transform: pose }, &intr, Some(&depth));
        update_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        for id in update.changed.iter().chain(&update.added) {
            std::hint::black_box(map.polygon(*id));
        }
        publish_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let (u, p) = (spread(&update_ms), spread(&publish_ms));
    println!(
        "map update, {size} polygons, 12 observed per frame, clearing on: median {:.3} ms, p99 {:.3} ms",
        u.median, u.p99
    );
    println!("publishing the changed polygons (convex pieces, insets): median {:.3} ms, p99 {:.3} ms", p.median, p.p99);
    assert_eq!(map.len(), size);
}
