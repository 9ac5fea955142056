//! The RealSense driver code (realsense-rust over librealsense 2.56.5), without cameras:
//! `.bag` recordings made from the synthetic sequences by librealsense's own recorder
//! (scripts/make_bag.py) play back through the same code the robot runs, and a camera
//! that is not there gives an error naming it.
//!
//! Needs `--features realsense`; scripts/test.sh builds librealsense2 from the pyrealsense2
//! wheel and points POLYMAP_PYTHON at a virtualenv that has it.
#![cfg(feature = "realsense")]

use std::path::{Path, PathBuf};
use std::process::Command;

use polymap::camera::CameraError;
use polymap::camera::realsense::{RealsenseD435i, RealsenseDepth};
use polymap::config::{D435iConfig, DepthSourceConfig, PipelineConfig};
use polymap::sequence::Sequence;
use polymap::types::DepthFrame;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// `seq` recorded as an L515-like bag by pyrealsense2's recorder.
fn make_bag(seq: &Path, out: &Path) -> PathBuf {
    let python = std::env::var("POLYMAP_PYTHON").expect("POLYMAP_PYTHON: a python with pyrealsense2 (scripts/test.sh)");
    let bag = out.join("depth.bag");
    let status = Command::new(python)
        .arg(root().join("scripts/make_bag.py"))
        .args([seq.as_os_str(), bag.as_os_str()])
        .status()
        .expect("running scripts/make_bag.py");
    assert!(status.success(), "make_bag.py failed");
    bag
}

fn play(bag: &Path) -> (polymap::types::Intrinsics, Vec<DepthFrame>) {
    let mut camera = RealsenseDepth::open_bag(bag).expect("bag opens");
    let mut frames = Vec::new();
    loop {
        match camera.next_frame() {
            Ok(f) => frames.push(f),
            Err(CameraError::Ended) => break,
            Err(e) => panic!("playing {}: {e}", bag.display()),
        }
    }
    (camera.intrinsics(), frames)
}

#[test]
fn a_bag_plays_back_with_its_frames_stamps_intrinsics_and_depth_scale() {
    for name in ["straight_320", "straight_640"] {
        let seq = Sequence::open(root().join("mock_frames").join(name)).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let (intr, frames) = play(&make_bag(&seq.dir, dir.path()));
        assert_eq!(frames.len(), seq.len(), "{name}: every frame, once");
        // librealsense keeps intrinsics and depth units as f32.
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs().max(1.0);
        let s = &seq.intrinsics;
        assert_eq!((intr.width, intr.height), (s.width, s.height));
        for (a, b) in
            [(intr.fx, s.fx), (intr.fy, s.fy), (intr.cx, s.cx), (intr.cy, s.cy), (intr.depth_scale, s.depth_scale)]
        {
            assert!(close(a, b), "{name}: intrinsics {a} vs {b}");
        }
        for (k, f) in frames.iter().enumerate() {
            let want = seq.depth(k).unwrap();
            // Stamps travel as f64 milliseconds: equal to well under a microsecond.
            assert!(
                f.stamp_ns.abs_diff(want.stamp_ns) < 1_000,
                "{name} frame {k}: stamp {} vs {}",
                f.stamp_ns,
                want.stamp_ns
            );
            assert!(f.pixels == want.pixels, "{name} frame {k}: depth units differ");
            assert_eq!(f.depth_scale, intr.depth_scale);
        }
    }
}

#[test]
fn the_extractor_finds_the_same_polygons_in_the_bag_as_in_its_sequence() {
    let seq = Sequence::open(root().join("mock_frames/straight_320")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (intr, frames) = play(&make_bag(&seq.dir, dir.path()));
    let cfg = PipelineConfig::default();
    let mut compared = 0;
    for k in [0, 12, 29] {
        let (from_bag, _, _) = polymap::extract::extract_cpu(&frames[k], &intr, &cfg).unwrap();
        let (from_seq, _, _) = polymap::extract::extract_cpu(&seq.depth(k).unwrap(), &seq.intrinsics, &cfg).unwrap();
        assert_eq!(from_bag.polygons.len(), from_seq.polygons.len(), "frame {k}");
        assert!(!from_seq.polygons.is_empty());
        for (a, b) in from_bag.polygons.iter().zip(&from_seq.polygons) {
            let dot: f64 = (0..3).map(|i| a.normal[i] * b.normal[i]).sum();
            assert!(dot.clamp(-1.0, 1.0).acos().to_degrees() < 0.2, "frame {k}: normals");
            assert!((a.offset - b.offset).abs() < 0.002, "frame {k}: offsets");
            assert_eq!(a.boundary.len(), b.boundary.len(), "frame {k}: outline");
            for (p, q) in a.boundary.iter().zip(&b.boundary) {
                let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
                assert!(d < 0.002, "frame {k}: vertex {p:?} vs {q:?}");
            }
            compared += 1;
        }
    }
    assert!(compared >= 10, "compared {compared} polygons");
}

#[test]
fn a_missing_camera_is_named_in_the_error() {
    let depth = DepthSourceConfig { serial: "f0999999".into(), ..DepthSourceConfig::default() };
    let e = RealsenseDepth::open(&depth).err().expect("no L515 here").to_string();
    assert!(e.contains("L515") && e.contains("f0999999"), "{e}");
    let d435i = D435iConfig { serial: "843112079999".into(), ..D435iConfig::default() };
    let e = RealsenseD435i::open(&d435i).err().expect("no D435i here").to_string();
    assert!(e.contains("D435I") && e.contains("843112079999"), "{e}");
    let e = RealsenseDepth::open_bag(Path::new("/nonexistent/stairs.bag")).err().unwrap().to_string();
    assert!(e.contains("/nonexistent/stairs.bag"), "{e}");
}
