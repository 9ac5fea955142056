//! The sequence format: round trip, and a clear error for each kind of broken input.

use std::fs;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use polymap::sequence::{
    Sequence, SequenceErrorKind, SequenceWriter, StairTruth, Truth, TruthPolygon, parse_stamp, write_png16,
};
use polymap::types::{Intrinsics, Pose};

const W: u32 = 8;
const H: u32 = 6;

fn intrinsics() -> Intrinsics {
    Intrinsics { width: W, height: H, fx: 5.0, fy: 5.0, cx: 3.5, cy: 2.5, depth_scale: 0.00025 }
}

fn depth(k: usize) -> Vec<u16> {
    (0..W * H).map(|i| if i % 7 == 0 { 0 } else { 4000 + i as u16 * 3 + k as u16 }).collect()
}

fn pose(k: usize) -> Pose {
    Pose {
        stamp_ns: 1_700_000_000_123_456_789 + k as u64 * 33_333_333,
        transform: Isometry3::from_parts(
            Translation3::new(0.1 * k as f64, -0.25, 1.0),
            UnitQuaternion::from_euler_angles(0.01 * k as f64, -0.8, 0.3),
        ),
    }
}

fn truth() -> Truth {
    Truth {
        stair: Some(StairTruth { kind: "straight".into(), steps: 1, rise: 0.15, going: 0.28, width: 1.0 }),
        pose_drift_per_frame: 0.0,
        pose_drift: None,
        polygons: vec![TruthPolygon {
            label: "tread".into(),
            step: Some(1),
            height: 0.15,
            boundary: vec![[0.0, 0.0, 0.15], [1.0, 0.0, 0.15], [1.0, 1.0, 0.15]],
        }],
    }
}

/// A valid 3-frame sequence with labels and truth.
fn make(dir: &Path) -> PathBuf {
    let seq = dir.join("seq");
    let mut w = SequenceWriter::create(&seq, intrinsics(), true).unwrap();
    for k in 0..3 {
        let labels: Vec<u16> = depth(k).iter().map(|&d| (d != 0) as u16).collect();
        w.push(&depth(k), pose(k), Some(&labels)).unwrap();
    }
    w.finish(Some(&truth())).unwrap();
    seq
}

fn open_err(seq: &Path) -> polymap::sequence::SequenceError {
    Sequence::open(seq).expect_err("a broken sequence must not open")
}

fn edit_poses(seq: &Path, f: impl FnOnce(&mut Vec<String>)) {
    let path = seq.join("poses.txt");
    let mut lines: Vec<String> = fs::read_to_string(&path).unwrap().lines().map(String::from).collect();
    f(&mut lines);
    fs::write(&path, lines.join("\n") + "\n").unwrap();
}

#[test]
fn round_trip_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    let s = Sequence::open(make(dir.path())).unwrap();
    assert_eq!((s.len(), s.intrinsics), (3, intrinsics()));
    assert!(s.has_labels);
    assert_eq!(s.truth.as_ref().unwrap(), &truth());
    for k in 0..3 {
        let f = s.depth(k).unwrap();
        assert_eq!(f.pixels, depth(k));
        assert_eq!(f.stamp_ns, pose(k).stamp_ns, "stamps survive the text file to the nanosecond");
        let (a, b) = (s.poses[k].transform, pose(k).transform);
        assert!((a.translation.vector - b.translation.vector).norm() < 1e-9);
        assert!(a.rotation.angle_to(&b.rotation) < 1e-8);
        assert_eq!(
            s.labels(k).unwrap().iter().filter(|&&l| l == 1).count(),
            depth(k).iter().filter(|&&d| d != 0).count()
        );
    }
}

#[test]
fn comments_and_blank_lines_in_poses_are_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let seq = make(dir.path());
    edit_poses(&seq, |l| {
        l.insert(2, "   ".into());
        l.insert(3, "# a comment in the middle".into());
    });
    assert_eq!(Sequence::open(&seq).unwrap().len(), 3);
}

#[test]
fn missing_frame() {
    let dir = tempfile::tempdir().unwrap();
    let seq = make(dir.path());
    fs::remove_file(seq.join("depth/000001.png")).unwrap();
    let e = open_err(&seq);
    assert_eq!(e.kind, SequenceErrorKind::MissingFrame);
    assert!(e.path.ends_with("depth/000001.png"), "{e}");
    assert!(e.to_string().contains("missing"), "{e}");
}

#[test]
fn eight_bit_png() {
    let dir = tempfile::tempdir().unwrap();
    let seq = make(dir.path());
    image::GrayImage::new(W, H).save(seq.join("depth/000002.png")).unwrap();
    let e = open_err(&seq);
    assert_eq!(e.kind, SequenceErrorKind::BitDepth);
    assert!(e.path.ends_with("depth/000002.png"));
    assert!(e.to_string().contains("8-bit"), "{e}");
}

#[test]
fn size_mismatch() {
    let dir = tempfile::tempdir().unwrap();
    let seq = make(dir.path());
    write_png16(&seq.join("depth/000001.png"), W + 1, H, &vec![1; ((W + 1) * H) as usize]).unwrap();
    let e = open_err(&seq);
    assert_eq!(e.kind, SequenceErrorKind::SizeMismatch);
    assert!(e.to_string().contains("9x6 but camera.toml says 8x6"), "{e}");
}

#[test]
fn label_size_mismatch() {
    let dir = tempfile::tempdir().unwrap();
    let seq = make(dir.path());
    write_png16(&seq.join("labels/000000.png"), W, H + 1, &vec![1; (W * (H + 1)) as usize]).unwrap();
    let e = open_err(&seq);
    assert_eq!(e.kind, SequenceErrorKind::SizeMismatch);
    assert!(e.path.ends_with("labels/000000.png"));
}

#[test]
fn non_unit_quaternion() {
    let dir = tempfile::tempdir().unwrap();
    let seq = make(dir.path());
    // Line 1 is the header comment; line 3 is frame 1.
    edit_poses(&seq, |l| l[2] = "1.5 0 0 1 0 0 0 0.9".into());
    let e = open_err(&seq);
    assert_eq!((e.kind, e.line), (SequenceErrorKind::NonUnitQuaternion, Some(3)));
    assert!(e.to_string().contains("poses.txt:3:") && e.to_string().contains("norm 0.9"), "{e}");
}

#[test]
fn stamps_out_of_order() {
    let dir = tempfile::tempdir().unwrap();
    let seq = make(dir.path());
    edit_poses(&seq, |l| l.swap(2, 3));
    let e = open_err(&seq);
    assert_eq!((e.kind, e.line), (SequenceErrorKind::StampOrder, Some(4)));
    assert!(e.to_string().contains("not after the previous"), "{e}");
}

#[test]
fn short_poses_file() {
    let dir = tempfile::tempdir().unwrap();
    let seq = make(dir.path());
    edit_poses(&seq, |l| {
        l.pop();
    });
    let e = open_err(&seq);
    assert_eq!(e.kind, SequenceErrorKind::PoseCount);
    assert!(e.to_string().contains("2 poses but depth/ has 3 frames"), "{e}");
}

#[test]
fn long_poses_file() {
    let dir = tempfile::tempdir().unwrap();
    let seq = make(dir.path());
    edit_poses(&seq, |l| l.push("99.0 0 0 0 0 0 0 1".into()));
    assert_eq!(open_err(&seq).kind, SequenceErrorKind::PoseCount);
}

#[test]
fn malformed_pose_lines() {
    for (line, why) in [
        ("0.5 0 0 1 0 0 0", "8 fields"),
        ("0.5 0 0 nan 0 0 0 1", "field 4"),
        ("-1.0 0 0 1 0 0 0 1", "stamp"),
        ("abc 0 0 1 0 0 0 1", "stamp"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let seq = make(dir.path());
        edit_poses(&seq, |l| l[1] = line.into());
        let e = open_err(&seq);
        assert_eq!((e.kind, e.line), (SequenceErrorKind::BadPoseLine, Some(2)), "{line}: {e}");
        assert!(e.reason.contains(why), "{line}: {e}");
    }
}

#[test]
fn bad_camera_file() {
    let dir = tempfile::tempdir().unwrap();
    let seq = make(dir.path());
    let text = fs::read_to_string(seq.join("camera.toml")).unwrap();
    fs::write(seq.join("camera.toml"), text.replace("fx = 5.0", "fx = 0.0")).unwrap();
    let e = open_err(&seq);
    assert_eq!(e.kind, SequenceErrorKind::BadCamera);
    assert!(e.to_string().contains("fx"), "{e}");
    fs::write(seq.join("camera.toml"), text.replace("depth_scale", "depth_scal")).unwrap();
    assert!(open_err(&seq).to_string().contains("depth_scal"));
}

#[test]
fn badly_named_frame() {
    let dir = tempfile::tempdir().unwrap();
    let seq = make(dir.path());
    fs::copy(seq.join("depth/000000.png"), seq.join("depth/frame3.png")).unwrap();
    assert_eq!(open_err(&seq).kind, SequenceErrorKind::BadFrameName);
}

#[test]
fn corrupt_png_and_bad_label() {
    let dir = tempfile::tempdir().unwrap();
    let seq = make(dir.path());
    fs::write(seq.join("depth/000001.png"), b"not a png at all").unwrap();
    assert_eq!(open_err(&seq).kind, SequenceErrorKind::BadPng);

    let dir = tempfile::tempdir().unwrap();
    let seq = make(dir.path());
    write_png16(&seq.join("labels/000001.png"), W, H, &vec![2; (W * H) as usize]).unwrap();
    let s = Sequence::open(&seq).unwrap();
    let e = s.labels(1).unwrap_err();
    assert_eq!(e.kind, SequenceErrorKind::BadTruth);
    assert!(e.to_string().contains("label 2 but truth.json has 1"), "{e}");
}

#[test]
fn exact_stamp_parsing() {
    assert_eq!(parse_stamp("1700000000.123456789"), Some(1_700_000_000_123_456_789));
    assert_eq!(parse_stamp("12.5"), Some(12_500_000_000));
    assert_eq!(parse_stamp("7"), Some(7_000_000_000));
    assert_eq!(parse_stamp("1.5e-3"), Some(1_500_000));
    assert_eq!(parse_stamp("-1"), None);
    assert_eq!(parse_stamp("1.2.3"), None);
}

#[test]
fn real_sensor_frames_read() {
    // Two real sensors' frames in this format (tests/data/real/SOURCE.md): the reader must
    // take real data.
    let real = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/real");
    for name in ["tum-fr3-office", "cape-room"] {
        let s = Sequence::open(real.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        let f = s.depth(0).unwrap();
        let valid = f.pixels.iter().filter(|&&d| d != 0).count();
        assert!(valid > f.pixels.len() / 2, "{name}: only {valid} valid pixels");
    }
}
