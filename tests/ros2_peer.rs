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

use common::{root, wait_for_listener};

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
    wait_for_listener(port, Duration::from_secs(60));
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

/// An independent ROS 2 node: zenoh-ros2-sdk (ROBOTIS's rmw_zenoh client on PyPI, pinned in
/// scripts/test.sh), through its public API only, on the message definitions of the packages
/// that define them (polymap_msgs/ as it is; ROS 2 Jazzy's, grid_map's and
/// convex_plane_decomposition's .msg files in tests/peer/ros2_interfaces/). Its type hashes are
/// polymap's, so its keys meet polymap's: it receives every topic, the latched map though it
/// joins late, finds polymap in the graph from its liveliness tokens, calls both services,
/// and its odometry is what polymap maps with. tests/peer/ros2_sdk_peer.py says where it works
/// around the SDK.
#[test]
fn an_independent_ros_2_client_zenoh_ros2_sdk_receives_polymap_s_topics_calls_its_services_and_feeds_it_odometry() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_loopback_port().unwrap();
    let mut mapper = mapper(dir.path(), port, "", 60);
    // No sleep: the SDK's session waits for polymap's port, and the peer for polymap's first status.
    let out = Command::new(python())
        .arg(root().join("tests/peer/ros2_sdk_peer.py"))
        .args(["--connect", &format!("tcp/127.0.0.1:{port}"), "--seconds", "15", "--sequence"])
        .arg(root().join("mock_frames/straight_320"))
        .output()
        .unwrap();
    let _ = mapper.kill();
    let _ = mapper.wait();
    let log = std::fs::read_to_string(dir.path().join("mapper.log")).unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "peer failed: {stdout}\n{stderr}\n{log}");
    eprint!("{stderr}");
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();

    // The hashes the SDK computes from the definitions are polymap's.
    use polymap::ros2::msg;
    use polymap::ros2::msg::service_hash;
    use polymap::ros2::types::message_hash;
    let ours = [
        ("polymap_msgs/msg/FramePolygons", message_hash::<msg::FramePolygons>()),
        ("polymap_msgs/msg/MapUpdate", message_hash::<msg::MapUpdate>()),
        ("polymap_msgs/msg/Status", message_hash::<msg::Status>()),
        ("polymap_msgs/msg/Map", message_hash::<msg::Map>()),
        ("tf2_msgs/msg/TFMessage", message_hash::<msg::TfMessage>()),
        ("convex_plane_decomposition_msgs/msg/PlanarTerrain", message_hash::<msg::PlanarTerrain>()),
        ("visualization_msgs/msg/MarkerArray", message_hash::<msg::MarkerArray>()),
        ("sensor_msgs/msg/Image", message_hash::<msg::Image>()),
        ("sensor_msgs/msg/CameraInfo", message_hash::<msg::CameraInfo>()),
        ("sensor_msgs/msg/Imu", message_hash::<msg::Imu>()),
        ("nav_msgs/msg/Odometry", message_hash::<msg::Odometry>()),
        ("polymap_msgs/srv/GetMap", service_hash::<msg::GetMap>()),
        ("polymap_msgs/srv/GetFoothold", service_hash::<msg::GetFoothold>()),
    ];
    for (ty, hash) in &ours {
        assert_eq!(v["hashes"][ty], *hash, "{ty}: the SDK's hash, then polymap's");
    }
    let hash = |ty: &str| ours.iter().find(|(t, _)| *t == ty).unwrap().1.clone();

    // Every topic arrives on the keys the SDK makes (status each second; map and markers at
    // most each second, when the map changed; the IMU at 200 Hz; the rest each frame, 8 Hz when
    // the machine is idle, fewer when it is loaded, or five times a second, the terrain).
    for (topic, count) in v["counts"].as_object().unwrap() {
        let least = if topic.ends_with("imu") {
            500
        } else if topic.ends_with("/map") {
            2
        } else if topic.ends_with("status") || topic.ends_with("markers") {
            5
        } else {
            10
        };
        assert!(count.as_u64().unwrap() >= least, "{topic}: {count} samples");
    }
    // map_updates is keep-all: every update starts from the version the one before made.
    assert_eq!(v["map_updates"]["breaks"], 0, "{}", v["map_updates"]);

    // Joining /polymap/leju/map late, the SDK's transient-local subscriber gets the latched map
    // from polymap's cache before its constructor returns.
    let late = &v["late_map"];
    assert!(late["at_join"].as_u64().unwrap() >= 1, "the latched map on joining late: {late}");
    assert_eq!(late["first"]["frame_id"], "map", "{late}");
    assert!(late["first"]["polygons"].as_u64().unwrap() > 0, "{late}");
    assert!(v["counts"]["/polymap/leju/map"].as_u64().unwrap() > late["at_join"].as_u64().unwrap(), "and later maps");

    // First samples, decoded from the definitions.
    assert_eq!(
        v["image_first"],
        serde_json::json!({"width": 320, "height": 240, "encoding": "mono8", "bytes": 320 * 240})
    );
    assert_eq!((&v["camera_info_first"]["width"], &v["camera_info_first"]["height"]), (&320.into(), &240.into()));
    assert_eq!(v["imu_first"]["angular_velocity_covariance"][0], 0.01);
    assert_eq!(v["terrain_first"]["frame_id"], "map", "{}", v["terrain_first"]);
    assert_eq!(v["terrain_first"]["layers"], serde_json::json!(["elevation", "smooth_planar", "region"]));
    assert!(v["markers_last"]["markers"].as_u64().unwrap() > 0, "{}", v["markers_last"]);
    assert_eq!((&v["tf_last"]["parent"], &v["tf_last"]["child"]), (&"map".into(), &"world".into()), "{}", v["tf_last"]);

    // The graph as the SDK's discovery reads polymap's liveliness tokens: polymap's node in
    // its namespace publishes each topic, subscribes to the odometry and serves both services,
    // with the types and hashes above.
    let graph = &v["graph"];
    let polymap_has = |name: &str, side: &str, ty: &str| {
        graph[name][side].as_array().is_some_and(|es| {
            es.iter().any(|e| {
                e["node"] == "polymap" && e["namespace"] == "/polymap/leju" && e["type"] == ty && e["hash"] == hash(ty)
            })
        })
    };
    for (name, ty) in [
        ("/polymap/leju/frame_polygons", "polymap_msgs/msg/FramePolygons"),
        ("/polymap/leju/map_updates", "polymap_msgs/msg/MapUpdate"),
        ("/polymap/leju/markers", "visualization_msgs/msg/MarkerArray"),
        ("/polymap/leju/status", "polymap_msgs/msg/Status"),
        ("/polymap/leju/map", "polymap_msgs/msg/Map"),
        ("/tf", "tf2_msgs/msg/TFMessage"),
        ("/convex_plane_decomposition_ros/planar_terrain", "convex_plane_decomposition_msgs/msg/PlanarTerrain"),
        ("/camera/camera/infra1/image_rect_raw", "sensor_msgs/msg/Image"),
        ("/camera/camera/infra1/camera_info", "sensor_msgs/msg/CameraInfo"),
        ("/camera/camera/imu", "sensor_msgs/msg/Imu"),
    ] {
        assert!(polymap_has(name, "publishers", ty), "polymap publishing {name}: {}", graph[name]);
    }
    assert!(polymap_has("/odometry", "subscribers", "nav_msgs/msg/Odometry"), "{}", graph["/odometry"]);
    for (name, ty) in [
        ("/polymap/leju/get_map", "polymap_msgs/srv/GetMap"),
        ("/polymap/leju/get_foothold", "polymap_msgs/srv/GetFoothold"),
    ] {
        assert!(polymap_has(name, "servers", ty), "polymap serving {name}: {}", graph[name]);
    }
    // The latched map announced as such (reliable, transient local, keep last 1).
    let map_pubs = graph["/polymap/leju/map"]["publishers"].as_array().unwrap();
    assert!(map_pubs.iter().any(|e| e["node"] == "polymap" && e["qos"] == ":1:,1:,:,:,,"), "{map_pubs:?}");

    // Both services answer.
    assert_eq!(v["map"]["frame_id"], "map", "{}", v["map"]);
    assert!(v["map"]["treads"].as_u64().unwrap() >= 3, "{}", v["map"]);
    assert_eq!(v["foothold"], serde_json::json!({"found": true, "contains": true, "label": 2}));

    // The SDK's publisher was polymap's VINS: once its odometry flowed, every frame had a pose.
    let (early, last) = (&v["status_early"], &v["status_last"]);
    assert!(v["odometry_published"].as_u64().unwrap() >= 300, "{v}");
    assert!(early["poses_accepted"].as_u64().unwrap() > 0, "{early}");
    assert!(
        last["processed"].as_u64().unwrap() >= early["processed"].as_u64().unwrap() + 10,
        "frames mapped with the SDK's poses: {early} -> {last}"
    );
    assert_eq!(
        last["without_pose"],
        early["without_pose"],
        "no frame without a pose once odometry flowed (the VINS held up [at, for] s: {}); polymap said:\n{}",
        v["odometry_stalls"],
        log.lines().filter(|l| l.contains("without pose")).collect::<Vec<_>>().join("\n")
    );
    assert_eq!(last["poses_refused"], 0, "{last}");
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
    // The first status may go out before the camera's first frame: wait for one that counts frames.
    let counting = async {
        loop {
            let sample = status.recv_async().await.expect("the status subscriber closed");
            let decoded: polymap::ros2::msg::Status =
                polymap::ros2::cdr::from_slice(&sample.payload().to_bytes()).unwrap();
            if decoded.frames_in > 0 {
                return sample;
            }
        }
    };
    let sample = tokio::time::timeout(Duration::from_secs(60), counting)
        .await
        .expect("a status on the bridge's key counting the camera's frames");
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
    wait_for_listener(port, Duration::from_secs(60));
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

/// A ROS 2 follower on rmw_zenoh (tests/peer/ros2_follower.py: zenoh-ros2-sdk, rosbags,
/// polymap_msgs' .msg files, the README's contract written out again), a peer of the mapper
/// on `port`; `drop_every` > 0 loses every n-th update it receives, as a lossy link would.
fn sdk_follower(dir: &Path, port: u16, name: &str, drop_every: u32) -> common::PeerFollower {
    let mut cmd = Command::new(python());
    cmd.arg(root().join("tests/peer/ros2_follower.py")).args([
        "--port",
        &port.to_string(),
        "--name",
        name,
        "--drop-every",
        &drop_every.to_string(),
    ]);
    common::PeerFollower::spawn(cmd, name, dir)
}

/// The mock VINS on the mapper's peer for `seconds`, waited for: then no frame has a pose
/// and the map stops changing.
fn vins_for(vins_config: &Path, seconds: u32) {
    let status = Command::new(env!("CARGO_BIN_EXE_polymap"))
        .args(["mock-vins", root().join("mock_frames/straight_320").to_str().unwrap(), "--rate", "100"])
        .arg("--config")
        .arg(vins_config)
        .args(["--duration", &seconds.to_string()])
        .stderr(std::process::Stdio::null())
        .status()
        .unwrap();
    assert!(status.success(), "mock-vins: {status}");
}

/// Planners on ROS 2 that share nothing with polymap keep their own copy of the map from
/// `map_updates` and the transient-local `map`, and each ends with get_map's map, polygon by
/// polygon and field by field:
/// - through a burst of changes (the camera at 30 Hz), one following every update and one
///   losing every fourth (it notices the gaps and takes a whole map);
/// - through a crash and restart of polymap (SIGKILL, a new run on the same port: a new
///   epoch, the map built again from empty by a shorter walk): both reconnect by themselves
///   and drop the old map for the new one;
/// - and one that joins once the map is built.
#[test]
fn ros_2_followers_end_with_get_map_s_map_after_a_burst_a_restart_and_a_late_join() {
    struct Sdk {
        dir: tempfile::TempDir,
        port: u16,
        mapper: Option<(std::process::Child, std::path::PathBuf)>,
    }
    impl common::FollowerRig for Sdk {
        fn start(&mut self, run: &str) {
            let run_dir = self.dir.path().join(run);
            std::fs::create_dir_all(&run_dir).unwrap();
            let seq = root().join("mock_frames/straight_320");
            self.mapper = Some(common::start_mapper(&run_dir, &seq, self.port, 30, "", 900));
            wait_for_listener(self.port, Duration::from_secs(60));
        }
        // A crash: SIGKILL, and the next run on the same port.
        fn stop(&mut self) {
            let (mapper, _) = self.mapper.as_mut().unwrap();
            let _ = mapper.kill();
            let _ = mapper.wait();
        }
        fn walk(&mut self, seconds: u32) {
            vins_for(&self.mapper.as_ref().unwrap().1, seconds);
        }
        fn follower(&mut self, name: &str, drop_every: u32) -> common::PeerFollower {
            sdk_follower(self.dir.path(), self.port, name, drop_every)
        }
    }
    let mut rig = Sdk { dir: tempfile::tempdir().unwrap(), port: free_loopback_port().unwrap(), mapper: None };
    common::followers_end_with_get_map(&mut rig, "transient-local");
}
