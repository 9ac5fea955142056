//! Writes the valid inputs the fuzz corpora grow from (`fuzz/corpus/<target>/seed-*`): real
//! odometry and service requests in CDR, the shipped configs, a small sequence, a small map.
//!
//! ```sh
//! cargo run --example fuzz_seeds
//! ```

use std::path::Path;

use polymap::interface::convert;
use polymap::pose::RawPose;
use polymap::ros2::cdr;
use polymap::ros2::msg::{GetFootholdRequest, GetMapRequest, Point, PoseStamped};

fn write(target: &str, name: &str, bytes: &[u8]) -> anyhow::Result<()> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus").join(target);
    std::fs::create_dir_all(&dir)?;
    std::fs::write(dir.join(format!("seed-{name}")), bytes)?;
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let now = 1_790_000_000_000_000_000u64;
    for (k, (position, quat)) in
        [([1.0, 2.0, 0.5], [0.0, 0.0, 0.0, 1.0]), ([-3.5, 0.25, 1.0], [0.0, 0.0, 0.38268343, 0.92387953])]
            .into_iter()
            .enumerate()
    {
        let raw = RawPose { stamp_ns: now + k as u64 * 10_000_000, position, quat_xyzw: quat };
        let odometry = convert::odometry(&raw, "world", "body");
        write("odometry", &format!("odometry-{k}"), &cdr::to_vec(&odometry))?;
        let stamped = PoseStamped { header: odometry.header.clone(), pose: odometry.pose.pose };
        write("odometry", &format!("pose-stamped-{k}"), &cdr::to_vec(&stamped))?;
    }
    write("service_request", "get-map", &cdr::to_vec(&GetMapRequest::default()))?;
    for (k, (x, y, z)) in [(0.42, 0.0, 0.3), (-1.0, 2.0, 0.0), (0.14, 0.0, 0.15)].into_iter().enumerate() {
        write(
            "service_request",
            &format!("get-foothold-{k}"),
            &cdr::to_vec(&GetFootholdRequest { point: Point { x, y, z } }),
        )?;
    }
    for name in ["default.toml", "leju.toml"] {
        write("config", name, &std::fs::read(root.join("config").join(name))?)?;
    }
    write(
        "config",
        "small.toml",
        b"[pipeline]\nbackend = \"cpu\"\n[map]\nsnapshot_period_s = 2.0\n[ros2]\nmode = \"bridge\"\n",
    )?;
    // A 32x24 sequence of one frame: its camera, its pose and its depth.
    let seq = polymap::sequence::Sequence::open(root.join("mock_frames/straight_320"))?;
    let intr = seq.intrinsics.scaled_to(32, 24);
    let camera = toml::to_string(&intr)?;
    let poses = polymap::sequence::format_tum_line(&seq.poses[0], false);
    let depth = seq.depth(0)?;
    let small: Vec<u16> =
        (0..24).flat_map(|v| (0..32).map(move |u| (u, v))).map(|(u, v)| depth.pixels[v * 10 * 320 + u * 10]).collect();
    let mut png = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut png, 32, 24);
        encoder.set_color(png::ColorType::Grayscale);
        encoder.set_depth(png::BitDepth::Sixteen);
        let mut w = encoder.write_header()?;
        w.write_image_data(&small.iter().flat_map(|d| d.to_be_bytes()).collect::<Vec<u8>>())?;
    }
    let sep = polymap::fuzz::SEQUENCE_SEPARATOR;
    write(
        "sequence",
        "straight-32x24",
        &[camera.as_bytes(), sep, format!("{poses}\n").as_bytes(), sep, &png].concat(),
    )?;
    // A small map: what replaying three frames of the bundled stairs makes.
    let mut config = polymap::config::Config::default();
    config.pipeline.backend = polymap::config::Backend::Cpu;
    let mut map = polymap::map::persist::initial_map(&config.map);
    let mut extractor = polymap::extract::Extractor::new(&config.pipeline)?;
    for k in [0, 10, 20] {
        let extraction = extractor.extract(&seq.depth(k)?, &seq.intrinsics)?;
        let polygons = &extraction.polygons.polygons;
        map.update(polygons, &seq.poses[k], &seq.intrinsics, Some(&extraction.depth));
    }
    let mut snapshot = map.snapshot();
    snapshot.polygons.truncate(3);
    write("snapshot", "straight-3-polygons", &serde_json::to_vec(&snapshot)?)?;
    println!("seeds written under fuzz/corpus/");
    Ok(())
}
