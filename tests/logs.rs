//! Robot teams' own logs as input: ROS 1 bags written by Debian's rosbag (Noetic's Python
//! API, sharing no code with polymap) and replayed with `polymap replay FILE.bag`.
//!
//! scripts/test.sh installs Debian's python3-rosbag.

mod common;

use std::path::Path;
use std::process::Command;

use common::root;
use polymap::map::MapSnapshot;
use polymap::sequence::Sequence;

/// tests/peer/ros1_bags.py with Debian's python (rosbag is not on PyPI).
fn bags(args: &[&str]) {
    let out = Command::new("/usr/bin/python3")
        .arg(root().join("tests/peer/ros1_bags.py"))
        .args(args)
        .output()
        .expect("Debian's python3 with python3-rosbag (scripts/test.sh)");
    assert!(out.status.success(), "ros1_bags.py {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

/// `polymap replay` with the CPU twin: (succeeded, stdout, stderr).
fn replay(input: &Path, out: &Path) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_polymap"))
        .arg("replay")
        .arg(input)
        .arg("--out")
        .arg(out)
        .args(["--backend", "cpu"])
        .output()
        .unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn map_of(path: &Path) -> MapSnapshot {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The bundled stairs as a bag (16UC1 in millimetres, REP 118, as realsense-ros records
/// them; camera_info; VINS's odometry), each chunk compression rosbag writes: every image
/// mapped, and the map the sequence's own replay makes, within the millimetre rounding.
#[test]
fn a_bag_of_the_mock_stairs_replays_to_the_sequence_s_map() {
    let dir = tempfile::tempdir().unwrap();
    let seq_dir = root().join("mock_frames/straight_320");
    let seq = Sequence::open(&seq_dir).unwrap();
    let (ok, _, err) = replay(&seq_dir, &dir.path().join("sequence.json"));
    assert!(ok, "{err}");
    let (truth, _) = polymap::eval::map::score_map(&map_of(&dir.path().join("sequence.json")), &seq, false).unwrap();
    for compression in ["none", "bz2", "lz4"] {
        let bag = dir.path().join(format!("stairs_{compression}.bag"));
        bags(&["write-sequence", bag.to_str().unwrap(), seq_dir.to_str().unwrap(), compression]);
        let out = dir.path().join(format!("{compression}.json"));
        let (ok, stdout, err) = replay(&bag, &out);
        assert!(ok, "{compression}: {err}");
        let n = seq.len();
        assert!(stdout.contains(&format!("{n} depth images: {n} mapped")), "{compression}: {stdout}");
        let (scores, _) = polymap::eval::map::score_map(&map_of(&out), &seq, false).unwrap();
        assert_eq!(scores.len(), truth.len());
        let (mut worst_iou, mut worst_height) = (0.0f64, 0.0f64);
        for (b, s) in scores.iter().zip(&truth) {
            assert_eq!(b.found, s.found, "{compression}: tread {}", b.step);
            worst_iou = worst_iou.max((b.iou - s.iou).abs());
            if let (Some(hb), Some(hs)) = (b.height, s.height) {
                worst_height = worst_height.max((hb - hs).abs());
            }
        }
        eprintln!(
            "{compression}: {} treads, IOU within {worst_iou:.4} and heights within {:.2} mm of the sequence's replay",
            scores.len(),
            worst_height * 1e3
        );
        assert!(worst_iou <= 0.02 && worst_height <= 0.002, "{compression}: IOU {worst_iou}, height {worst_height} m");
    }
}

/// A bag cut short, a bag without the asked topics, and a file that is no bag: each stops
/// with a line that says what is wrong (and, for the topics, what the bag has).
#[test]
fn truncated_topicless_and_foreign_bags_are_refused_saying_why() {
    let dir = tempfile::tempdir().unwrap();
    let seq_dir = root().join("mock_frames/straight_320");
    let whole = dir.path().join("whole.bag");
    bags(&["write-sequence", whole.to_str().unwrap(), seq_dir.to_str().unwrap(), "none"]);
    let bytes = std::fs::read(&whole).unwrap();
    let cut = dir.path().join("cut.bag");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 5]).unwrap();
    let (ok, _, err) = replay(&cut, &dir.path().join("cut.json"));
    assert!(!ok && err.contains("truncated at byte"), "{err}");

    let topicless = dir.path().join("topicless.bag");
    bags(&["write-topicless", topicless.to_str().unwrap()]);
    let (ok, _, err) = replay(&topicless, &dir.path().join("t.json"));
    assert!(!ok && err.contains("no messages on /l515/depth/image_rect_raw"), "{err}");
    assert!(err.contains("/tf (tf2_msgs/TFMessage): 3"), "{err}");

    let foreign = dir.path().join("foreign.bag");
    std::fs::write(&foreign, b"PK\x03\x04 not a bag at all").unwrap();
    let (ok, _, err) = replay(&foreign, &dir.path().join("f.json"));
    assert!(!ok && err.contains("not a ROS 1 bag"), "{err}");
}
