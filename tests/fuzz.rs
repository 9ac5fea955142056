//! The fuzz targets (polymap::fuzz; cargo-fuzz runs them for long in `fuzz/`), bounded for
//! every test run: each committed input (`fuzz/corpus/<target>/`: the valid seeds, `seed-*`,
//! and small inputs the fuzzer found new paths with, `found-*`; the rest of what cargo-fuzz
//! grows stays out of git), then proptest's mutations of them (bytes flipped, set, cut,
//! repeated, spliced). None may panic; a hang would stop the test.

use std::path::Path;

use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

fn corpus(target: &str) -> Vec<Vec<u8>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus").join(target);
    let mut inputs: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|path| {
            path.file_name().is_some_and(|name| {
                let name = name.to_string_lossy();
                name.starts_with("seed-") || name.starts_with("found-")
            })
        })
        .map(|path| std::fs::read(path).unwrap())
        .collect();
    inputs.sort();
    assert!(!inputs.is_empty(), "{target}: an empty corpus");
    inputs
}

#[derive(Clone, Debug)]
enum Mutation {
    Flip { at: usize, bit: u8 },
    Set { at: usize, byte: u8 },
    Cut { at: usize },
    Repeat { at: usize, len: usize },
    Splice { at: usize, from: usize, seed: usize },
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), 0..8u8).prop_map(|(at, bit)| Mutation::Flip { at, bit }),
        (any::<usize>(), prop_oneof![Just(0u8), Just(0xff), Just(0x7f), Just(0x80), any::<u8>()])
            .prop_map(|(at, byte)| Mutation::Set { at, byte }),
        any::<usize>().prop_map(|at| Mutation::Cut { at }),
        (any::<usize>(), 1..64usize).prop_map(|(at, len)| Mutation::Repeat { at, len }),
        (any::<usize>(), any::<usize>(), any::<usize>()).prop_map(|(at, from, seed)| Mutation::Splice {
            at,
            from,
            seed
        }),
    ]
}

fn apply(seeds: &[Vec<u8>], seed: usize, mutations: &[Mutation]) -> Vec<u8> {
    let mut data = seeds[seed % seeds.len()].clone();
    for m in mutations {
        let n = data.len().max(1);
        match *m {
            Mutation::Flip { at, bit } if !data.is_empty() => data[at % n] ^= 1 << bit,
            Mutation::Set { at, byte } if !data.is_empty() => data[at % n] = byte,
            Mutation::Cut { at } => data.truncate(at % n),
            Mutation::Repeat { at, len } if !data.is_empty() => {
                let at = at % n;
                let piece: Vec<u8> = data[at..(at + len).min(data.len())].to_vec();
                data.splice(at..at, piece);
            }
            Mutation::Splice { at, from, seed } => {
                let other = &seeds[seed % seeds.len()];
                let tail = &other[from % other.len().max(1)..];
                data.truncate(at % n);
                data.extend_from_slice(tail);
            }
            _ => {}
        }
    }
    data
}

fn fuzz(target: &str, cases: u32) {
    let (_, run) = polymap::fuzz::TARGETS.iter().find(|(name, _)| *name == target).expect("a target");
    let seeds = corpus(target);
    for input in &seeds {
        run(input);
    }
    let mut runner = TestRunner::new(Config { cases, failure_persistence: None, ..Config::default() });
    runner
        .run(&(any::<usize>(), proptest::collection::vec(mutation(), 1..8)), |(seed, mutations)| {
            run(&apply(&seeds, seed, &mutations));
            Ok(())
        })
        .unwrap();
}

#[test]
fn odometry_messages() {
    fuzz("odometry", 20_000);
}

#[test]
fn service_requests() {
    fuzz("service_request", 20_000);
}

#[test]
fn config_files() {
    fuzz("config", 3_000);
}

#[test]
fn sequences() {
    fuzz("sequence", 500);
}

#[test]
fn snapshots() {
    fuzz("snapshot", 1_000);
}

#[test]
fn tcpros_headers() {
    fuzz("tcpros_header", 20_000);
}

#[test]
fn ros1_messages() {
    fuzz("ros1_message", 5_000);
}

#[test]
fn xmlrpc_bodies() {
    fuzz("xmlrpc", 5_000);
}

#[test]
fn ros1_bags() {
    fuzz("bag", 400);
}

#[test]
fn mcap_files() {
    fuzz("mcap", 400);
}

/// The seeds of the ROS 1 and log targets (fuzz/make_seeds.py, with rosbags) are what
/// polymap reads whole, so the mutations start from inputs that reach past the first check.
#[test]
fn the_ros_1_and_log_seeds_are_read_whole() {
    use polymap::ros1::Ros1Message;
    use polymap::ros2::msg::{CameraInfo, Image, Odometry, PoseStamped};
    let seed = |target: &str, name: &str| {
        std::fs::read(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus").join(target).join(format!("seed-{name}")),
        )
        .unwrap()
    };
    let header = polymap::ros1::tcpros::ConnectionHeader::decode(&seed("tcpros_header", "subscriber")).unwrap();
    assert_eq!(header.get("topic"), Some("/polygon_new_markers"));
    let odometry = Odometry::from_ros1(&seed("ros1_message", "odometry")).unwrap();
    assert_eq!((odometry.child_frame_id.as_str(), odometry.pose.pose.position.z), ("body", 0.9));
    assert_eq!(PoseStamped::from_ros1(&seed("ros1_message", "pose_stamped")).unwrap().pose.position.y, 2.0);
    let (image, info) = (
        Image::from_ros1(&seed("ros1_message", "image")).unwrap(),
        CameraInfo::from_ros1(&seed("ros1_message", "camera_info")).unwrap(),
    );
    let (frame, _) = polymap::interface::convert::depth_frame(&image, &info, None).unwrap();
    assert_eq!((frame.width, frame.height, frame.pixels[1]), (8, 6, 907));
    let (method, params) = polymap::ros1::xmlrpc::parse_call(&seed("xmlrpc", "call")).unwrap();
    assert_eq!((method.as_str(), params.len()), ("publisherUpdate", 3));
    assert!(polymap::ros1::xmlrpc::parse_response(&seed("xmlrpc", "response")).is_ok());
    for (target, name) in [("bag", "seed.bag"), ("mcap", "seed.mcap")] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(name);
        std::fs::write(&path, seed(target, "four-topics")).unwrap();
        let log = polymap::logs::Log::find(&path).unwrap().unwrap();
        let scan = polymap::logs::scan(&log, "/odometry").unwrap();
        assert_eq!(
            (scan.topics.len(), scan.poses.len(), scan.poses_refused),
            (4, 1, 0),
            "{target}: {}",
            scan.listing()
        );
    }
    // The fuzzer's find: a record inside an uncompressed chunk longer than the chunk made the
    // mcap crate's reader panic; polymap names it instead.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("past.mcap");
    std::fs::write(
        &path,
        std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus/mcap/found-record-past-its-chunk"))
            .unwrap(),
    )
    .unwrap();
    let log = polymap::logs::Log::find(&path).unwrap().unwrap();
    let Err(err) = polymap::logs::scan(&log, "/odometry") else { panic!("a malformed chunk read") };
    assert!(format!("{err:#}").contains("longer than the chunk holding it"), "{err:#}");
}

#[test]
fn every_target_has_a_corpus_and_a_cargo_fuzz_target() {
    for (name, _) in polymap::fuzz::TARGETS {
        corpus(name);
        let target = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/fuzz_targets").join(format!("{name}.rs"));
        let text = std::fs::read_to_string(&target).unwrap_or_else(|e| panic!("{}: {e}", target.display()));
        assert!(text.contains(&format!("polymap::fuzz::{name}(")), "{} calls polymap::fuzz::{name}", target.display());
    }
}
