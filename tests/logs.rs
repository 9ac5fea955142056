//! Robot teams' own logs as input: ROS 1 bags written by Debian's rosbag (Noetic's Python
//! API) and ROS 2 bags in MCAP written by rosbags (PyPI), neither sharing code with polymap,
//! replayed with `polymap replay`; and `polymap record`, whose recording replays to the
//! live session's map.
//!
//! scripts/test.sh installs Debian's python3-rosbag and makes the virtualenv with rosbags.

mod common;

use std::path::Path;
use std::process::{Command, Stdio};

use common::{json5, root};
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

/// tests/peer/ros2_mcap.py with the virtualenv's python (rosbags).
fn mcaps(args: &[&str]) {
    let python = std::env::var("POLYMAP_PYTHON").expect("POLYMAP_PYTHON: a python with rosbags (scripts/test.sh)");
    let out = Command::new(python).arg(root().join("tests/peer/ros2_mcap.py")).args(args).output().unwrap();
    assert!(out.status.success(), "ros2_mcap.py {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

/// `polymap ARGS`: (succeeded, stdout, stderr).
fn polymap(args: &[&std::ffi::OsStr]) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_polymap")).args(args).output().unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// `polymap replay` with the CPU twin: (succeeded, stdout, stderr).
fn replay(input: &Path, out: &Path) -> (bool, String, String) {
    polymap(&["replay".as_ref(), input.as_ref(), "--out".as_ref(), out.as_ref(), "--backend".as_ref(), "cpu".as_ref()])
}

/// The treads of a replayed map against those of the sequence's own replay: the worst
/// differences of IOU and height, every tread found in both or in neither.
fn against(map: &Path, truth: &[polymap::eval::map::MapTreadScore], seq: &Sequence, what: &str) -> (f64, f64) {
    let (scores, _) = polymap::eval::map::score_map(&map_of(map), seq, false).unwrap();
    assert_eq!(scores.len(), truth.len());
    let (mut worst_iou, mut worst_height) = (0.0f64, 0.0f64);
    for (b, s) in scores.iter().zip(truth) {
        assert_eq!(b.found, s.found, "{what}: tread {}", b.step);
        worst_iou = worst_iou.max((b.iou - s.iou).abs());
        if let (Some(hb), Some(hs)) = (b.height, s.height) {
            worst_height = worst_height.max((hb - hs).abs());
        }
    }
    eprintln!(
        "{what}: {} treads, IOU within {worst_iou:.4} and heights within {:.3} mm of the sequence's replay",
        scores.len(),
        worst_height * 1e3
    );
    (worst_iou, worst_height)
}

fn map_of(path: &Path) -> MapSnapshot {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The bundled stairs, and the treads of the map their own replay makes.
fn stairs_replayed(dir: &Path) -> (std::path::PathBuf, Sequence, Vec<polymap::eval::map::MapTreadScore>) {
    let seq_dir = root().join("mock_frames/straight_320");
    let seq = Sequence::open(&seq_dir).unwrap();
    let (ok, _, err) = replay(&seq_dir, &dir.join("sequence.json"));
    assert!(ok, "{err}");
    let (truth, _) = polymap::eval::map::score_map(&map_of(&dir.join("sequence.json")), &seq, false).unwrap();
    (seq_dir, seq, truth)
}

/// The bundled stairs as a bag (16UC1 in millimetres, REP 118, as realsense-ros records
/// them; camera_info; VINS's odometry), each chunk compression rosbag writes: every image
/// mapped, and the map the sequence's own replay makes, within the millimetre rounding.
#[test]
fn a_bag_of_the_mock_stairs_replays_to_the_sequence_s_map() {
    let dir = tempfile::tempdir().unwrap();
    let (seq_dir, seq, truth) = stairs_replayed(dir.path());
    for compression in ["none", "bz2", "lz4"] {
        let bag = dir.path().join(format!("stairs_{compression}.bag"));
        bags(&["write-sequence", bag.to_str().unwrap(), seq_dir.to_str().unwrap(), compression]);
        let out = dir.path().join(format!("{compression}.json"));
        let (ok, stdout, err) = replay(&bag, &out);
        assert!(ok, "{compression}: {err}");
        let n = seq.len();
        assert!(stdout.contains(&format!("{n} depth images: {n} mapped")), "{compression}: {stdout}");
        let (worst_iou, worst_height) = against(&out, &truth, &seq, compression);
        // Millimetre rounding moves the odd tread's outline by a few percent of its IOU.
        assert!(worst_iou <= 0.03 && worst_height <= 0.002, "{compression}: IOU {worst_iou}, height {worst_height} m");
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

/// The bundled stairs as a rosbag2 directory in MCAP, as a ROS 2 robot records them
/// (realsense-ros's default names, depth as 32FC1 in metres; odometry on /odometry): every
/// image mapped, the map the sequence's own replay makes. The directory and its .mcap file
/// both replay.
#[test]
fn an_mcap_of_the_mock_stairs_replays_to_the_sequence_s_map() {
    let dir = tempfile::tempdir().unwrap();
    let (seq_dir, seq, truth) = stairs_replayed(dir.path());
    let rosbag2 = dir.path().join("stairs");
    mcaps(&["write-sequence", rosbag2.to_str().unwrap(), seq_dir.to_str().unwrap()]);
    let n = seq.len();
    for input in [rosbag2.clone(), rosbag2.join("stairs.mcap")] {
        let out = dir.path().join("mcap.json");
        let (ok, stdout, err) = replay(&input, &out);
        assert!(ok, "{}: {err}", input.display());
        assert!(stdout.contains(&format!("{n} depth images: {n} mapped")), "{stdout}");
        // 32FC1 metres of the sequence's 0.25 mm units come back to the same units.
        let (worst_iou, worst_height) = against(&out, &truth, &seq, "mcap");
        assert!(worst_iou <= 0.005 && worst_height <= 0.0002, "IOU {worst_iou}, height {worst_height} m");
    }

    let (ok, stdout, err) = polymap(&["inspect".as_ref(), rosbag2.as_ref()]);
    assert!(ok, "{err}");
    for line in [
        "/camera/camera/depth/image_rect_raw (sensor_msgs/msg/Image): 30 messages",
        "/odometry (nav_msgs/msg/Odometry): 30 messages",
        "30 poses (0 refused)",
    ] {
        assert!(stdout.contains(line), "inspect says {line:?}: {stdout}");
    }

    // Cut short, and a depth topic of another type: each says what is wrong.
    let bytes = std::fs::read(rosbag2.join("stairs.mcap")).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let (ok, _, err) = replay(&cut, &dir.path().join("cut.json"));
    assert!(!ok && err.contains("cut.mcap: not a readable MCAP file"), "{err}");
    let wrong = dir.path().join("wrong");
    mcaps(&["write-wrong-type", wrong.to_str().unwrap()]);
    let (ok, _, err) = replay(&wrong, &dir.path().join("wrong.json"));
    assert!(
        !ok && err.contains("carries sensor_msgs/msg/CompressedImage, where polymap reads sensor_msgs/Image"),
        "{err}"
    );
}

/// A live session (the mock camera and a mock VINS over Zenoh) recorded with a frame limit:
/// the session ends at the limit, and the recording replays to the live session's map bit
/// for bit.
#[test]
fn a_recorded_session_replays_to_the_live_map_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let seq_dir = root().join("mock_frames/straight_320");
    let port = polymap::ros2::session::free_loopback_port().unwrap();
    let mapper_cfg = dir.path().join("mapper.toml");
    let toml = format!(
        "[sources.depth]\nsequence = {:?}\nfps = 15\n[pipeline]\nbackend = \"cpu\"\n[zenoh]\nconfig_file = {:?}\n",
        seq_dir.display().to_string(),
        json5(dir.path(), "mapper", Some(port), &[])
    );
    std::fs::write(&mapper_cfg, toml).unwrap();
    let vins_cfg = dir.path().join("vins.toml");
    std::fs::write(&vins_cfg, format!("[zenoh]\nconfig_file = {:?}\n", json5(dir.path(), "vins", None, &[port])))
        .unwrap();
    let recording = dir.path().join("recording");
    let bin = env!("CARGO_BIN_EXE_polymap");
    let mapper = Command::new(bin)
        .args(["record", recording.to_str().unwrap(), "--max-frames", "40", "--duration", "60", "--config"])
        .arg(&mapper_cfg)
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(dir.path().join("mapper.log")).unwrap())
        .spawn()
        .unwrap();
    let mut vins = Command::new(bin)
        .args(["mock-vins", seq_dir.to_str().unwrap(), "--rate", "100", "--duration", "60", "--config"])
        .arg(&vins_cfg)
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let out = mapper.wait_with_output().unwrap();
    vins.kill().unwrap();
    vins.wait().unwrap();
    let log = std::fs::read_to_string(dir.path().join("mapper.log")).unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{log}");
    assert!(stdout.contains("recorded 40 frames"), "{stdout}");
    assert!(log.contains("the recording is full"), "the limit ends the session: {log}");

    let recorded = Sequence::open(&recording).unwrap();
    assert_eq!(recorded.len(), 40);
    let replayed = dir.path().join("replayed.json");
    let (ok, stdout, err) = replay(&recording, &replayed);
    assert!(ok, "{err}");
    assert!(stdout.contains("40 frames"), "{stdout}");
    let (live, again) = (map_of(&recording.join("map.json")), map_of(&replayed));
    assert!(live.polygons.len() >= 5, "the live session mapped the stairs: {} polygons", live.polygons.len());
    assert_eq!(
        serde_json::to_value(&live).unwrap(),
        serde_json::to_value(&again).unwrap(),
        "the replayed map is the live one"
    );
}

/// A 400 MB bag, made in the test's temporary directory as a robot records one (the D435i's
/// IR images beside the L515's depth, the stairs walked forward and back): replayed whole,
/// every depth image mapped, with a peak resident set under 150 MB.
#[test]
fn a_bag_larger_than_the_replay_s_memory_streams_through_it() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("large.bag");
    bags(&["write-large", bag.to_str().unwrap(), root().join("mock_frames/straight_320").to_str().unwrap(), "400"]);
    let size = std::fs::metadata(&bag).unwrap().len();
    assert!(size >= 400_000_000, "{size} bytes");
    // Reaped by wait4 below, not by Child::wait.
    #[allow(clippy::zombie_processes)]
    let child = Command::new(env!("CARGO_BIN_EXE_polymap"))
        .arg("replay")
        .arg(&bag)
        .args(["--backend", "cpu"])
        .stdout(std::fs::File::create(dir.path().join("stdout")).unwrap())
        .stderr(std::fs::File::create(dir.path().join("stderr")).unwrap())
        .spawn()
        .unwrap();
    // wait4: the child's own peak resident set (getrusage's would be every child's).
    let mut status = 0;
    // SAFETY: a plain struct of integers, filled in by the kernel.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: the pid is this test's own child, waited for once, here.
    let waited = unsafe { libc::wait4(child.id() as libc::pid_t, &mut status, 0, &mut usage) };
    assert_eq!(waited, child.id() as libc::pid_t);
    let stdout = std::fs::read_to_string(dir.path().join("stdout")).unwrap();
    let stderr = std::fs::read_to_string(dir.path().join("stderr")).unwrap();
    assert!(libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0, "{stderr}");
    let images: u64 = stdout.split(" depth images").next().and_then(|s| s.rsplit(' ').next()?.parse().ok()).unwrap();
    assert!(images >= 400 && stdout.contains(&format!("{images} depth images: {images} mapped")), "{stdout}");
    let peak_mb = usage.ru_maxrss as f64 * 1024.0 / 1e6; // KiB on Linux
    eprintln!("{:.0} MB bag, {images} depth images mapped: peak resident set {peak_mb:.0} MB", size as f64 / 1e6);
    assert!(peak_mb < 150.0, "peak resident set {peak_mb:.0} MB");
}
