//! Poses over real Zenoh sessions on loopback (multicast scouting off): good odometry reaches
//! the pose buffer; every kind of garbage on the pose key is counted and kept out; the mock
//! VINS, a separate process, publishes a sequence's poses.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use nalgebra::{UnitQuaternion, Vector3};
use polymap::config::ZenohConfig;
use polymap::pose::{PoseBuffer, PoseCounters, RawPose};
use polymap::ros;
use zenoh::qos::CongestionControl;

const KEY: &str = "vins_estimator/odometry";
const MS: u64 = 1_000_000;

/// A loopback zenoh peer's config file: listening on `listen` and/or connecting to `connect`.
fn zenoh_config(dir: &std::path::Path, name: &str, listen: Option<u16>, connect: Option<u16>) -> ZenohConfig {
    let path = dir.join(format!("{name}.json5"));
    std::fs::write(&path, polymap::live::loopback_json5(listen, connect)).unwrap();
    ZenohConfig { config_file: path, ..ZenohConfig::default() }
}

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
    _dir: tempfile::TempDir,
    publisher: zenoh::Session,
    _mapper: zenoh::Session,
    _subscriber: zenoh::pubsub::Subscriber<()>,
    buffer: Arc<Mutex<PoseBuffer>>,
}

/// The mapper's side (listening, subscribed on `sub_key`) and a publisher peer connected to it.
async fn pair(sub_key: &str, capacity: usize) -> Pair {
    let dir = tempfile::tempdir().unwrap();
    let port = polymap::live::free_loopback_port().unwrap();
    let mapper = polymap::bus::open_session(&zenoh_config(dir.path(), "mapper", Some(port), None)).await.unwrap();
    let buffer = Arc::new(Mutex::new(PoseBuffer::new(capacity, 200 * MS)));
    let subscriber = polymap::bus::subscribe_poses(&mapper, sub_key, buffer.clone()).await.unwrap();
    let publisher = polymap::bus::open_session(&zenoh_config(dir.path(), "vins", None, Some(port))).await.unwrap();
    wait_for_peer(&publisher).await;
    wait_for_peer(&mapper).await;
    // Give the subscription's declaration time to reach the publisher.
    tokio::time::sleep(Duration::from_millis(300)).await;
    Pair { _dir: dir, publisher, _mapper: mapper, _subscriber: subscriber, buffer }
}

impl Pair {
    async fn put(&self, key: &str, bytes: Vec<u8>) {
        self.publisher.put(key, bytes).congestion_control(CongestionControl::Block).await.unwrap();
    }

    /// Waits until `n` messages have been handled, then returns the counters.
    async fn handled(&self, n: u64) -> PoseCounters {
        for _ in 0..800 {
            let c = self.buffer.lock().unwrap().counters;
            if c.accepted + c.rejected + c.undecodable >= n {
                return c;
            }
            tokio::time::sleep(Duration::from_millis(25)).await;
        }
        panic!("only {:?} of {n} messages arrived", self.buffer.lock().unwrap().counters);
    }
}

fn pose(stamp_ms: u64, x: f64) -> RawPose {
    let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.3);
    RawPose { stamp_ns: stamp_ms * MS, position: [x, 0.5, 1.0], quat_xyzw: [q.i, q.j, q.k, q.w] }
}

fn odometry_bytes(p: &RawPose) -> Vec<u8> {
    ros::encode(&ros::odometry(p, "world", "body"))
}

/// Two good poses, then `bad`, then a third good one: only the good ones are in the buffer.
async fn refused(bad: Vec<u8>) -> PoseCounters {
    let pair = pair(KEY, 100).await;
    pair.put(KEY, odometry_bytes(&pose(1000, 0.0))).await;
    pair.put(KEY, odometry_bytes(&pose(1010, 0.01))).await;
    pair.put(KEY, bad).await;
    pair.put(KEY, odometry_bytes(&pose(1020, 0.02))).await;
    let c = pair.handled(4).await;
    let mut buf = pair.buffer.lock().unwrap();
    assert_eq!(buf.len(), 3, "only the good poses are kept");
    let t = buf.at(1015 * MS).unwrap();
    assert!((t.translation.x - 0.015).abs() < 1e-12, "the bad message did not touch the poses");
    c
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn good_odometry_reaches_the_pose_buffer() {
    let pair = pair(KEY, 100).await;
    for k in 0..5 {
        pair.put(KEY, odometry_bytes(&pose(1000 + 10 * k, 0.01 * k as f64))).await;
    }
    let c = pair.handled(5).await;
    assert_eq!((c.accepted, c.rejected, c.undecodable), (5, 0, 0));
    let t = pair.buffer.lock().unwrap().at(1025 * MS).unwrap();
    assert!((t.translation.x - 0.025).abs() < 1e-12);
    assert!((t.rotation.angle() - 0.3).abs() < 1e-12);
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
    let stamped = ros::PoseStamped {
        header: ros::Header { stamp: ros::Time::from_ns(p.stamp_ns), frame_id: "world".into() },
        pose: ros::odometry(&p, "", "").pose.pose,
    };
    let c = refused(ros::encode(&stamped)).await;
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
    let pair = pair(KEY, 1000).await;
    let mut truncated = odometry_bytes(&pose(1, 0.0));
    truncated.truncate(30);
    for k in 0..10_000u64 {
        // Every tenth message is garbage.
        let bytes = if k % 10 == 9 { truncated.clone() } else { odometry_bytes(&pose(1000 + k, k as f64 * 1e-3)) };
        pair.put(KEY, bytes).await;
    }
    let c = pair.handled(10_000).await;
    assert_eq!((c.accepted, c.undecodable, c.rejected), (9_000, 1_000, 0));
    let mut buf = pair.buffer.lock().unwrap();
    assert_eq!(buf.len(), 1000, "memory stays bounded");
    let t = buf.at((1000 + 9_990) * MS).unwrap();
    assert!((t.translation.x - 9.99).abs() < 1e-9);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rmw_zenoh_keys_and_pose_stamped_are_understood() {
    let pair = pair("0/vins_estimator/**", 100).await;
    let odom_key = "0/vins_estimator/odometry/nav_msgs::msg::dds_::Odometry_/RIHS01_3cc7fe5c";
    pair.put(odom_key, odometry_bytes(&pose(1000, 1.0))).await;
    let p = pose(1010, 1.01);
    let stamped = ros::PoseStamped {
        header: ros::Header { stamp: ros::Time::from_ns(p.stamp_ns), frame_id: "world".into() },
        pose: ros::odometry(&p, "", "").pose.pose,
    };
    pair.put("0/vins_estimator/pose/geometry_msgs::msg::dds_::PoseStamped_/RIHS01_10f3786d", ros::encode(&stamped))
        .await;
    let c = pair.handled(2).await;
    assert_eq!(c.accepted, 2, "{c:?}");
    let t = pair.buffer.lock().unwrap().at(1005 * MS).unwrap();
    assert!((t.translation.x - 1.005).abs() < 1e-12);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mock_vins_publishes_the_sequence_poses() {
    let dir = tempfile::tempdir().unwrap();
    let port = polymap::live::free_loopback_port().unwrap();
    let mapper = polymap::bus::open_session(&zenoh_config(dir.path(), "mapper", Some(port), None)).await.unwrap();
    let buffer = Arc::new(Mutex::new(PoseBuffer::new(1000, 200 * MS)));
    let _sub = polymap::bus::subscribe_poses(&mapper, KEY, buffer.clone()).await.unwrap();
    let vins = zenoh_config(dir.path(), "vins", None, Some(port));
    let config = dir.path().join("vins.toml");
    std::fs::write(&config, format!("[zenoh]\nconfig_file = {:?}\n", vins.config_file.display().to_string())).unwrap();
    let seq_dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("mock_frames/straight_320");
    let mut vins = std::process::Command::new(env!("CARGO_BIN_EXE_polymap"));
    vins.args(["mock-vins", seq_dir.to_str().unwrap(), "--rate", "50", "--duration", "2", "--config"]).arg(&config);
    let status = tokio::task::spawn_blocking(move || vins.status()).await.unwrap().unwrap();
    assert!(status.success());
    let c = buffer.lock().unwrap().counters;
    assert!(c.accepted >= 40, "about 100 poses in 2 s at 50 Hz, got {c:?}");
    assert_eq!((c.rejected, c.undecodable), (0, 0));
    // Each pose is the sequence's pose at its looped time.
    let seq = polymap::sequence::Sequence::open(&seq_dir).unwrap();
    let clock = polymap::mock_vins::SequenceClock::new(&seq).unwrap();
    let mut truth = PoseBuffer::new(seq.len(), u64::MAX);
    for p in &seq.poses {
        truth.push(&RawPose::from(p)).unwrap();
    }
    let last = seq.poses.last().unwrap().stamp_ns;
    let received = buffer.lock().unwrap();
    for p in received.poses() {
        let want = truth.at(clock.sequence_time(p.stamp_ns).min(last)).unwrap();
        let err = (p.transform.translation.vector - want.translation.vector).norm();
        assert!(err < 1e-9, "pose at {} is {err} m off the sequence", p.stamp_ns);
        assert!(p.transform.rotation.angle_to(&want.rotation) < 1e-9);
    }
}
