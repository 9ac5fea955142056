//! Odometry in over real Zenoh sessions on loopback (multicast scouting off), through
//! polymap's ROS 2 layer: good odometry on `/odometry` reaches the pose buffer, whatever
//! type hash (or none, from Humble) its key carries; every kind of garbage on the topic is
//! counted and kept out; PoseStamped is understood when configured; the mock VINS, a
//! separate process, publishes a sequence's poses.

use polymap::interface::wires::{Held, Wires};
use std::sync::Arc;
use std::time::Duration;

use nalgebra::{UnitQuaternion, Vector3};
use parking_lot::Mutex;
use polymap::config::{Config, OdometryType};
use polymap::interface::{Interface, convert};
use polymap::pose::{PoseBuffer, PoseCounters, RawPose};
use polymap::ros2::graph::{self, Endpoint};
use polymap::ros2::session::{free_loopback_port, loopback};
use polymap::ros2::{Node, cdr, types};
use zenoh::qos::CongestionControl;

const MS: u64 = 1_000_000;

async fn wait_for_peer(session: &zenoh::Session) {
    for _ in 0..200 {
        if session.info().peers_zid().await.next().is_some() {
            return;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    panic!("the peers never saw each other");
}

struct Pair {
    publisher: zenoh::Session,
    _mapper: (zenoh::Session, Wires, Vec<Held>),
    buffer: Arc<Mutex<PoseBuffer>>,
    /// The key rmw_zenoh (Jazzy) puts /odometry's nav_msgs/Odometry on.
    key: String,
}

/// polymap's side (listening, its odometry subscription as `config` says) and a bare Zenoh
/// peer connected to it, to put any bytes anywhere.
async fn pair(config: &Config, capacity: usize) -> Pair {
    let port = free_loopback_port().unwrap();
    let mapper = polymap::ros2::session::open(loopback(Some(port), &[])).await.unwrap();
    let node = Arc::new(Node::new(&mapper, config.ros2.node_options()).await.unwrap());
    let buffer = Arc::new(Mutex::new(PoseBuffer::new(capacity, 200 * MS)));
    let interface = Interface::new(config);
    let wires = Wires { ros2: Some(Wires::ros2(config, node.clone())), ros1: None };
    let subscription = polymap::runtime::odometry::subscribe(&wires, buffer.clone()).await.unwrap();
    let publisher = polymap::ros2::session::open(loopback(None, &[port])).await.unwrap();
    wait_for_peer(&publisher).await;
    wait_for_peer(&mapper).await;
    let hash = types::message_hash::<polymap::ros2::msg::Odometry>();
    let e = Endpoint { name: interface.odometry_name(), type_name: "nav_msgs/msg/Odometry", type_hash: &hash };
    let key = node.data_key(&e);
    // Ready once the subscription's declaration (of the configured type) has reached the
    // publisher's side.
    let stamped_hash = types::message_hash::<polymap::ros2::msg::PoseStamped>();
    let probe_key = match config.ros2.odometry_type {
        OdometryType::PoseStamped => node.data_key(&Endpoint {
            name: interface.odometry_name(),
            type_name: "geometry_msgs/msg/PoseStamped",
            type_hash: &stamped_hash,
        }),
        OdometryType::Odometry => key.clone(),
    };
    let probe = publisher.declare_publisher(probe_key).await.unwrap();
    for _ in 0..6000 {
        if probe.matching_status().await.unwrap().matching() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    assert!(
        probe.matching_status().await.unwrap().matching(),
        "polymap's odometry subscription never reached the peer"
    );
    drop(probe);
    Pair { publisher, _mapper: (mapper, wires, subscription), buffer, key }
}

impl Pair {
    async fn put(&self, key: &str, bytes: Vec<u8>) {
        self.publisher.put(key, bytes).congestion_control(CongestionControl::Block).await.unwrap();
    }

    /// Waits until `n` messages have been handled, then returns the counters.
    async fn handled(&self, n: u64) -> PoseCounters {
        for _ in 0..800 {
            let c = self.buffer.lock().counters;
            if c.accepted + c.rejected + c.undecodable >= n {
                return c;
            }
            tokio::time::sleep(Duration::from_millis(25)).await;
        }
        panic!("only {:?} of {n} messages arrived", self.buffer.lock().counters);
    }
}

fn pose(stamp_ms: u64, x: f64) -> RawPose {
    let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.3);
    RawPose { stamp_ns: stamp_ms * MS, position: [x, 0.5, 1.0], quat_xyzw: [q.i, q.j, q.k, q.w] }
}

fn odometry_bytes(p: &RawPose) -> Vec<u8> {
    cdr::to_vec(&convert::odometry(p, "world", "body"))
}

/// Two good poses, then `bad`, then a third good one: only the good ones are in the buffer.
async fn refused(bad: Vec<u8>) -> PoseCounters {
    let pair = pair(&Config::default(), 100).await;
    pair.put(&pair.key, odometry_bytes(&pose(1000, 0.0))).await;
    pair.put(&pair.key, odometry_bytes(&pose(1010, 0.01))).await;
    pair.put(&pair.key, bad).await;
    pair.put(&pair.key, odometry_bytes(&pose(1020, 0.02))).await;
    let c = pair.handled(4).await;
    let mut buf = pair.buffer.lock();
    assert_eq!(buf.len(), 3, "only the good poses are kept");
    let t = buf.at(1015 * MS).unwrap();
    assert!((t.translation.x - 0.015).abs() < 1e-12, "the bad message did not touch the poses");
    c
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn good_odometry_reaches_the_pose_buffer_under_jazzy_and_humble_keys() {
    let pair = pair(&Config::default(), 100).await;
    assert!(pair.key.starts_with("0/odometry/nav_msgs::msg::dds_::Odometry_/RIHS01_"), "{}", pair.key);
    // A Humble VINS writes no hash: TypeHashNotSupported where the hash goes.
    let humble = format!("0/odometry/nav_msgs::msg::dds_::Odometry_/{}", graph::NO_TYPE_HASH);
    for k in 0..5 {
        let key = if k % 2 == 0 { &pair.key } else { &humble };
        pair.put(key, odometry_bytes(&pose(1000 + 10 * k, 0.01 * k as f64))).await;
    }
    let c = pair.handled(5).await;
    assert_eq!((c.accepted, c.rejected, c.undecodable), (5, 0, 0));
    let t = pair.buffer.lock().at(1025 * MS).unwrap();
    assert!((t.translation.x - 0.025).abs() < 1e-12);
    assert!((t.rotation.angle() - 0.3).abs() < 1e-12);
    // Another topic, or another type on this one, is not odometry.
    pair.put("0/other/nav_msgs::msg::dds_::Odometry_/x", odometry_bytes(&pose(2000, 0.0))).await;
    pair.put("0/odometry/geometry_msgs::msg::dds_::PoseStamped_/x", odometry_bytes(&pose(2000, 0.0))).await;
    pair.put(&pair.key, odometry_bytes(&pose(1100, 0.1))).await;
    let c = pair.handled(6).await;
    assert_eq!((c.accepted, c.rejected, c.undecodable), (6, 0, 0), "only the last was for polymap");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn truncated_cdr_is_counted_and_kept_out() {
    let mut bytes = odometry_bytes(&pose(1015, 9.0));
    bytes.truncate(60);
    let c = refused(bytes).await;
    assert_eq!((c.undecodable, c.rejected), (1, 0));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wrong_message_type_is_counted_and_kept_out() {
    // A PoseStamped where Odometry belongs: too short to be one.
    let p = pose(1015, 9.0);
    let odometry = convert::odometry(&p, "world", "");
    let stamped = polymap::ros2::msg::PoseStamped { header: odometry.header, pose: odometry.pose.pose };
    let c = refused(cdr::to_vec(&stamped)).await;
    assert_eq!(c.undecodable, 1);
    let c = refused(b"{\"x\": 1}".to_vec()).await;
    assert_eq!(c.undecodable, 1);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nan_and_non_unit_quaternions_are_counted_and_kept_out() {
    let mut nan = pose(1015, 9.0);
    nan.quat_xyzw[0] = f64::NAN;
    assert_eq!(refused(odometry_bytes(&nan)).await.rejected, 1);
    let mut long = pose(1015, 9.0);
    long.quat_xyzw = [0.0, 0.0, 0.6, 1.0];
    assert_eq!(refused(odometry_bytes(&long)).await.rejected, 1);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stamps_going_backwards_are_counted_and_kept_out() {
    assert_eq!(refused(odometry_bytes(&pose(1005, 9.0))).await.rejected, 1);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_of_ten_thousand_messages_is_survived() {
    let pair = pair(&Config::default(), 1000).await;
    let mut truncated = odometry_bytes(&pose(1, 0.0));
    truncated.truncate(30);
    for k in 0..10_000u64 {
        // Every tenth message is garbage.
        let bytes = if k % 10 == 9 { truncated.clone() } else { odometry_bytes(&pose(1000 + k, k as f64 * 1e-3)) };
        pair.put(&pair.key, bytes).await;
    }
    let c = pair.handled(10_000).await;
    assert_eq!((c.accepted, c.undecodable, c.rejected), (9_000, 1_000, 0));
    let mut buf = pair.buffer.lock();
    assert_eq!(buf.len(), 1000, "memory stays bounded");
    let t = buf.at((1000 + 9_990) * MS).unwrap();
    assert!((t.translation.x - 9.99).abs() < 1e-9);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pose_stamped_is_understood_when_configured() {
    let mut config = Config::default();
    config.ros2.odometry = polymap::ros2::RosName::parse("/vins_estimator/pose").unwrap();
    config.ros2.odometry_type = OdometryType::PoseStamped;
    let pair = pair(&config, 100).await;
    let hash = types::message_hash::<polymap::ros2::msg::PoseStamped>();
    let e = Endpoint { name: &config.ros2.odometry, type_name: "geometry_msgs/msg/PoseStamped", type_hash: &hash };
    let key = graph::data_key(config.ros2.mode(), 0, &e);
    assert!(key.starts_with("0/vins_estimator/pose/geometry_msgs::msg::dds_::PoseStamped_/"), "{key}");
    for (stamp, x) in [(1000, 1.0), (1010, 1.01)] {
        let odometry = convert::odometry(&pose(stamp, x), "world", "");
        let stamped = polymap::ros2::msg::PoseStamped { header: odometry.header, pose: odometry.pose.pose };
        pair.put(&key, cdr::to_vec(&stamped)).await;
    }
    let c = pair.handled(2).await;
    assert_eq!(c.accepted, 2, "{c:?}");
    let t = pair.buffer.lock().at(1005 * MS).unwrap();
    assert!((t.translation.x - 1.005).abs() < 1e-12);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mock_vins_publishes_the_sequence_poses() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_loopback_port().unwrap();
    let mapper = polymap::ros2::session::open(loopback(Some(port), &[])).await.unwrap();
    let config = Config::default();
    let node = Arc::new(Node::new(&mapper, config.ros2.node_options()).await.unwrap());
    let buffer = Arc::new(Mutex::new(PoseBuffer::new(1000, 200 * MS)));
    let wires = Wires { ros2: Some(Wires::ros2(&config, node)), ros1: None };
    let _sub = polymap::runtime::odometry::subscribe(&wires, buffer.clone()).await.unwrap();
    let zenoh_file = dir.path().join("vins.json5");
    std::fs::write(&zenoh_file, polymap::ros2::session::loopback_json5(None, &[port])).unwrap();
    let vins_config = dir.path().join("vins.toml");
    std::fs::write(&vins_config, format!("[zenoh]\nconfig_file = {:?}\n", zenoh_file.display().to_string())).unwrap();
    let seq_dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("mock_frames/straight_320");
    let mut vins = std::process::Command::new(env!("CARGO_BIN_EXE_polymap"));
    vins.args(["mock-vins", seq_dir.to_str().unwrap(), "--rate", "50", "--duration", "2", "--config"])
        .arg(&vins_config);
    let status = tokio::task::spawn_blocking(move || vins.status()).await.unwrap().unwrap();
    assert!(status.success());
    let c = buffer.lock().counters;
    assert!(c.accepted >= 40, "about 100 poses in 2 s at 50 Hz, got {c:?}");
    assert_eq!((c.rejected, c.undecodable), (0, 0));
    // Each pose is the sequence's pose at its looped time.
    let seq = polymap::sequence::Sequence::open(&seq_dir).unwrap();
    let clock = polymap::mock::SequenceClock::new(&seq).unwrap();
    let mut truth = PoseBuffer::new(seq.len(), u64::MAX);
    for p in &seq.poses {
        truth.push(&RawPose::from(p)).unwrap();
    }
    let last = seq.poses.last().unwrap().stamp_ns;
    let received = buffer.lock();
    for p in received.poses() {
        let want = truth.at(clock.sequence_time(p.stamp_ns).min(last)).unwrap();
        let err = (p.transform.translation.vector - want.translation.vector).norm();
        assert!(err < 1e-9, "pose at {} is {err} m off the sequence", p.stamp_ns);
        assert!(p.transform.rotation.angle_to(&want.rotation) < 1e-9);
    }
}
