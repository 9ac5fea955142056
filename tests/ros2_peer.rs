//! polymap as ROS 2 nodes see it. A ROS 2 peer that shares none of polymap's code
//! (tests/peer/ros2_peer.py on examples/python/rmw_zenoh.py: eclipse-zenoh and rosbags,
//! written from rmw_zenoh's design document) meets a running `polymap run` (mock camera, mock
//! D435i) on rmw_zenoh's keys: it receives every topic with valid attachments, finds polymap
//! in the ROS graph with types and hashes, calls both services, and is polymap's VINS: its
//! odometry on /odometry is what polymap maps with. In bridge mode, polymap announces itself
//! as zenoh-bridge-ros2dds's announcements look and publishes on the ROS names.
//!
//! scripts/test.sh makes the virtualenv (eclipse-zenoh, rosbags) and sets POLYMAP_PYTHON.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use polymap::ros2::session::{free_loopback_port, loopback, loopback_json5};

mod common;

use common::root;

fn python() -> String {
    std::env::var("POLYMAP_PYTHON").expect("POLYMAP_PYTHON: a python with eclipse-zenoh and rosbags (scripts/test.sh)")
}

/// `polymap run` with the mock camera at 8 Hz and the mock D435i, listening on `port`;
/// `extra` is more TOML.
fn mapper(dir: &Path, port: u16, extra: &str, seconds: u32) -> std::process::Child {
    let zenoh = dir.join("mapper.json5");
    std::fs::write(&zenoh, loopback_json5(Some(port), &[])).unwrap();
    let config = dir.join("mapper.toml");
    std::fs::write(
        &config,
        format!(
            "[sources.depth]\nsequence = {:?}\nfps = 8\n[sources.d435i]\nkind = \"mock\"\nir_width = 320\nir_height = 240\n\
             [pipeline]\nbackend = \"cpu\"\n[zenoh]\nconfig_file = {:?}\n{extra}",
            root().join("mock_frames/straight_320").display().to_string(),
            zenoh.display().to_string(),
        ),
    )
    .unwrap();
    Command::new(env!("CARGO_BIN_EXE_polymap"))
        .args(["run", "--duration", &seconds.to_string(), "--config"])
        .arg(&config)
        .stderr(std::fs::File::create(dir.join("mapper.log")).unwrap())
        .spawn()
        .unwrap()
}

#[test]
fn a_ros_2_peer_on_rmw_zenoh_sees_polymap_s_topics_graph_and_services_and_feeds_its_odometry() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_loopback_port().unwrap();
    let mut mapper = mapper(dir.path(), port, "", 40);
    std::thread::sleep(Duration::from_secs(2));
    let out = Command::new(python())
        .arg(root().join("tests/peer/ros2_peer.py"))
        .args(["--connect", &format!("tcp/127.0.0.1:{port}"), "--seconds", "15", "--sequence"])
        .arg(root().join("mock_frames/straight_320"))
        .output()
        .unwrap();
    let _ = mapper.kill();
    let _ = mapper.wait();
    let log = std::fs::read_to_string(dir.path().join("mapper.log")).unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "peer failed: {stdout}\n{}\n{log}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();

    // Every topic arrives on the peer's own rmw_zenoh keys, each sample with an attachment
    // whose sequence numbers count up by one per publisher. `map_updates` is keep-all (the
    // publisher waits): it loses nothing. Every other topic is keep-last and, as with
    // rmw_zenoh, is sent drop-on-congestion, so a loaded machine may lose a few samples (CI
    // once lost one of 14 markers): a stale sample is worth less than a late one, and the
    // latched map and markers are complete in each sample.
    for (topic, s) in v["streams"].as_object().unwrap() {
        // Status each second, the whole map and its markers at most each second when the
        // map changed; the rest every frame or five times a second (the terrain).
        let least = if topic.ends_with("imu") {
            500
        } else if topic.ends_with("status") || topic.ends_with("/map") || topic.ends_with("markers") {
            5
        } else {
            // Every frame (8 Hz when the machine is idle, fewer under a loaded test run).
            10
        };
        let count = s["count"].as_u64().unwrap();
        assert!(count >= least, "{topic}: {s}");
        assert_eq!(s["bad_attachments"], 0, "{topic}: {s}");
        let gaps = s["gaps"].as_u64().unwrap();
        if topic.ends_with("/map_updates") {
            assert_eq!(gaps, 0, "{topic}: {s}");
        } else {
            assert!(gaps <= 1 + count / 10, "{topic}: {s}");
        }
    }
    assert_eq!(v["image_first"]["width"], 320);
    assert_eq!(v["image_first"]["encoding"], "mono8");
    assert_eq!(v["imu_first"]["angular_velocity_covariance"][0], 0.01);

    // The peer's hashes (rosbags from polymap_msgs/ and ROS 2 Jazzy's definitions) are the
    // ones polymap computes from its own types.
    use polymap::ros2::msg;
    use polymap::ros2::msg::service_hash;
    use polymap::ros2::types::message_hash;
    let hashes = &v["hashes"];
    for (ty, ours) in [
        ("polymap_msgs/msg/FramePolygons", message_hash::<msg::FramePolygons>()),
        ("polymap_msgs/msg/MapUpdate", message_hash::<msg::MapUpdate>()),
        ("polymap_msgs/msg/Status", message_hash::<msg::Status>()),
        ("polymap_msgs/msg/Map", message_hash::<msg::Map>()),
        ("tf2_msgs/msg/TFMessage", message_hash::<msg::TfMessage>()),
        ("convex_plane_decomposition_msgs/msg/PlanarTerrain", message_hash::<msg::PlanarTerrain>()),
        ("visualization_msgs/msg/MarkerArray", message_hash::<msg::MarkerArray>()),
        ("sensor_msgs/msg/Image", message_hash::<msg::Image>()),
        ("sensor_msgs/msg/Imu", message_hash::<msg::Imu>()),
        ("nav_msgs/msg/Odometry", message_hash::<msg::Odometry>()),
        ("polymap_msgs/srv/GetMap", service_hash::<msg::GetMap>()),
        ("polymap_msgs/srv/GetFoothold", service_hash::<msg::GetFoothold>()),
    ] {
        assert_eq!(hashes[ty], ours, "{ty}");
    }

    // The ROS graph: polymap's node, its publishers, its subscription and its services, with
    // types and hashes.
    let graph = v["graph"].as_array().unwrap();
    let polymap: Vec<_> =
        graph.iter().filter(|e| e["node"] == "polymap" && e["namespace"] == "/polymap/leju").collect();
    assert!(polymap.iter().any(|e| e["kind"] == "NN"), "{graph:?}");
    let has = |kind: &str, name: &str, ty: &str| {
        polymap.iter().any(|e| {
            e["kind"] == kind
                && e["name"] == name
                && e["type"] == polymap::ros2::types::dds_type_name(ty)
                && e["hash"] == hashes[ty]
        })
    };
    for (name, ty) in [
        ("/polymap/leju/frame_polygons", "polymap_msgs/msg/FramePolygons"),
        ("/polymap/leju/map_updates", "polymap_msgs/msg/MapUpdate"),
        ("/polymap/leju/markers", "visualization_msgs/msg/MarkerArray"),
        ("/polymap/leju/status", "polymap_msgs/msg/Status"),
        ("/camera/camera/infra1/image_rect_raw", "sensor_msgs/msg/Image"),
        ("/camera/camera/imu", "sensor_msgs/msg/Imu"),
    ] {
        assert!(has("MP", name, ty), "publisher {name}: {polymap:?}");
    }
    assert!(has("MS", "/odometry", "nav_msgs/msg/Odometry"), "{polymap:?}");
    assert!(has("SS", "/polymap/leju/get_map", "polymap_msgs/srv/GetMap"), "{polymap:?}");
    assert!(has("SS", "/polymap/leju/get_foothold", "polymap_msgs/srv/GetFoothold"), "{polymap:?}");
    // The map_updates publisher keeps every sample (reliable, keep all).
    assert!(polymap.iter().any(|e| e["name"] == "/polymap/leju/map_updates" && e["qos"] == "::2,:,:,:,,"));

    // Services: answers, with attachments naming the request.
    assert!(v["map"]["treads"].as_u64().unwrap() >= 3, "{}", v["map"]);
    // Each polygon says whether a foot may trust it, consistently, and the walk's treads are
    // steppable.
    assert_eq!(v["map"]["footing_consistent"], true, "{}", v["map"]);
    assert!(v["map"]["steppable_treads"].as_u64().unwrap() >= 3, "{}", v["map"]);
    assert_eq!(v["map_reply"], serde_json::json!({"attachment": true, "echoes_seq": true, "echoes_gid": true}));
    assert_eq!(v["foothold"], serde_json::json!({"found": true, "contains": true, "label": 2, "echoes": true}));

    // The peer was polymap's VINS: once its odometry flowed, every frame had a pose.
    let (early, last) = (&v["status_early"], &v["status_last"]);
    assert!(v["odometry_published"].as_u64().unwrap() >= 300, "{v}");
    assert!(
        last["processed"].as_u64().unwrap() >= early["processed"].as_u64().unwrap() + 10,
        "frames mapped with the peer's poses: {early} -> {last}"
    );
    assert_eq!(last["without_pose"], early["without_pose"], "no frame without a pose once odometry flowed");
    assert_eq!(last["poses_refused"], 0, "{last}");

    // The planar terrain as rosbags decodes it from the packages' own definitions: a grid
    // map in the map frame, in grid_map's column-major layout, with heights of the stairs,
    // and regions a planner can use (outlines counter-clockwise, holes clockwise, insets).
    let t = &v["terrain"];
    assert_eq!(t["frame_id"], "map", "{t}");
    assert_eq!(t["layers"], serde_json::json!(["elevation", "smooth_planar", "region"]));
    let (rows, cols) = (t["rows"].as_u64().unwrap(), t["cols"].as_u64().unwrap());
    assert_eq!((rows, cols), (100, 100), "4 m at 4 cm");
    assert_eq!(t["dims"], serde_json::json!([["column_index", cols, rows * cols], ["row_index", rows, rows]]));
    assert_eq!(t["data_lengths"], serde_json::json!([rows * cols, rows * cols, rows * cols]));
    assert!(t["finite_cells"].as_u64().unwrap() > 500, "{t}");
    // Heights between the floor and the top tread: how many treads the run reached depends
    // on the machine's speed, so the bound is the stair's own height, not a guess of progress.
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root().join("mock_frames/straight_320/truth.json")).unwrap())
            .unwrap();
    let top = truth["stair"]["steps"].as_f64().unwrap() * truth["stair"]["rise"].as_f64().unwrap();
    let range = &t["elevation_range"];
    assert!(range[0].as_f64().unwrap() > -0.05 && range[1].as_f64().unwrap() < top + 0.05, "top tread {top} m: {t}");
    assert!(range[1].as_f64().unwrap() > 0.25, "at least two treads: {t}");
    assert!(t["regions"].as_u64().unwrap() >= 3 && t["regions"] == t["regions_with_insets"], "{t}");
    for check in ["outlines_ccw", "holes_cw", "unit_quaternions"] {
        assert_eq!(t[check], true, "{check}: {t}");
    }
    // The drift as the transform from the map frame to VINS's.
    assert_eq!((&v["tf_last"]["parent"], &v["tf_last"]["child"]), (&"map".into(), &"world".into()), "{}", v["tf_last"]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn in_bridge_mode_polymap_announces_itself_as_zenoh_bridge_ros2dds_does() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_loopback_port().unwrap();
    let mut mapper = mapper(dir.path(), port, "[ros2]\nmode = \"bridge\"\n", 12);
    let session = polymap::ros2::session::open(loopback(None, &[port])).await.unwrap();
    // Data on the ROS names without their leading '/', as the bridge routes them (the status:
    // it goes out every second, odometry or not).
    let status = session.declare_subscriber("polymap/leju/status").await.unwrap();
    let sample = tokio::time::timeout(Duration::from_secs(8), status.recv_async())
        .await
        .expect("the status on the bridge's key")
        .unwrap();
    let status: polymap::ros2::msg::Status = polymap::ros2::cdr::from_slice(&sample.payload().to_bytes()).unwrap();
    assert!(status.frames_in > 0, "{status:?}");
    assert!(sample.attachment().is_none(), "the bridge sends no attachments");
    // The announcements zenoh-bridge-ros2dds makes of a route: `@/<zid>/@ros2_lv/MP/<key>/<type>/<qos>`.
    let replies = session.liveliness().get("@/*/@ros2_lv/**").await.unwrap();
    let mut tokens = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        tokens.push(reply.result().unwrap().key_expr().to_string());
    }
    let _ = mapper.kill();
    let _ = mapper.wait();
    let expect = |prefix: &str| {
        assert!(tokens.iter().any(|t| t.split('/').nth(3).is_some() && t.contains(prefix)), "{prefix} in {tokens:?}")
    };
    expect("/@ros2_lv/MP/polymap§leju§map_updates/polymap_msgs§msg§MapUpdate/:1:0:1,0:typehash=RIHS01_");
    expect("/@ros2_lv/MP/polymap§leju§frame_polygons/polymap_msgs§msg§FramePolygons/:1:0:0,10");
    expect("/@ros2_lv/MS/odometry/nav_msgs§msg§Odometry/:1:0:0,100");
    expect("/@ros2_lv/SS/polymap§leju§get_map/polymap_msgs§srv§GetMap");
    expect("/@ros2_lv/MP/camera§camera§imu/sensor_msgs§msg§Imu/");
}

/// Depth from a ROS 2 image topic (`sources.depth.kind = "ros"`), published by a node on
/// rmw_zenoh as realsense-ros publishes the L515's, with VINS's poses on /odometry: every
/// frame polymap maps has the polygons the same frame of the sequence gives offline, to the
/// micrometre; an RGB image and one that does not fit its camera_info are refused and counted.
#[test]
fn depth_from_a_ros_2_topic_gives_the_sequence_s_polygons_frame_by_frame() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_loopback_port().unwrap();
    let seq_dir = root().join("mock_frames/straight_320");
    let seq = polymap::sequence::Sequence::open(&seq_dir).unwrap();
    let zenoh = dir.path().join("mapper.json5");
    std::fs::write(&zenoh, loopback_json5(Some(port), &[])).unwrap();
    let config = dir.path().join("mapper.toml");
    std::fs::write(
        &config,
        format!(
            // The offline twin rebuilds each frame's map frame from its update's drift_z alone
            // (MapUpdate carries no x, y or yaw yet): the drift is vertical here.
            "[sources.depth]\nkind = \"ros\"\nimage_unit_m = {}\n[sources.d435i]\nkind = \"none\"\n\
             [pipeline]\nbackend = \"cpu\"\n[map]\ndrift_horizontal = false\n[zenoh]\nconfig_file = {:?}\n",
            seq.intrinsics.depth_scale,
            zenoh.display().to_string(),
        ),
    )
    .unwrap();
    let mapper = Command::new(env!("CARGO_BIN_EXE_polymap"))
        .args(["run", "--duration", "20", "--config"])
        .arg(&config)
        .stdout(std::process::Stdio::piped())
        .stderr(std::fs::File::create(dir.path().join("mapper.log")).unwrap())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_secs(2));
    let out = Command::new(python())
        .arg(root().join("tests/peer/ros2_depth.py"))
        .args(["--connect", &format!("tcp/127.0.0.1:{port}"), "--namespace", "/polymap/leju", "--sequence"])
        .arg(&seq_dir)
        .output()
        .unwrap();
    let report = mapper.wait_with_output().unwrap();
    let log = std::fs::read_to_string(dir.path().join("mapper.log")).unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "peer: {stdout}\n{}\n{log}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    let frames = v["frames"].as_array().unwrap();
    eprintln!("{} of {} frames sent were mapped", frames.len(), v["sent"]);
    assert!(frames.len() >= 15, "{} of {} frames mapped:\n{log}", frames.len(), v["sent"]);
    let (polygons, worst) = common::frames_against_sequence(frames, &seq);
    eprintln!("{polygons} polygons in {} frames: worst vertex difference {worst:.2e} m", frames.len());
    assert!(polygons >= 3 * frames.len(), "{polygons} polygons");
    assert!(worst < 1e-6, "a vertex {worst} m off");
    assert!(log.contains("encoding \"rgb8\" is not a depth image"), "{log}");
    assert!(log.contains("but its camera_info says"), "{log}");
    let report = String::from_utf8_lossy(&report.stdout);
    assert!(report.contains("frames not extracted 2"), "{report}");
}
