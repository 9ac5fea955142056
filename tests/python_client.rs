//! Python clients (eclipse-zenoh from PyPI, rosbags for CDR) decode the live map and a
//! MarkerArray, and the mock D435i's IR images, camera infos and IMU: the bytes polymap
//! sends are what ROS 2 tools read.
//!
//! scripts/test.sh makes a virtualenv with both packages and points POLYMAP_PYTHON at it.
//! Without it the test says so and passes only outside CI.

use std::path::Path;
use std::process::Command;

fn python() -> Option<String> {
    let python = std::env::var("POLYMAP_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&python).args(["-c", "import zenoh, rosbags"]).status().is_ok_and(|s| s.success());
    ok.then_some(python)
}

#[test]
fn python_clients_decode_the_map_markers_ir_and_imu() {
    let Some(python) = python() else {
        assert!(std::env::var("CI").is_err(), "CI needs eclipse-zenoh and rosbags: run scripts/test.sh");
        eprintln!("skipped: no python with eclipse-zenoh and rosbags (scripts/test.sh makes one)");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let seq = root.join("mock_frames/straight_320");
    let port = polymap::live::free_loopback_port().unwrap();
    let zenoh_file = |name: &str, listen: Option<u16>, connect: Option<u16>| {
        let path = dir.path().join(format!("{name}.json5"));
        std::fs::write(&path, polymap::live::loopback_json5(listen, connect)).unwrap();
        path.display().to_string()
    };
    let mapper_cfg = dir.path().join("mapper.toml");
    std::fs::write(
        &mapper_cfg,
        format!(
            "[sources.depth]\nsequence = {:?}\n[sources.d435i]\nkind = \"mock\"\nir_width = 320\nir_height = 240\n\
             [pipeline]\nbackend = \"cpu\"\n[zenoh]\nconfig_file = {:?}\n",
            seq.display().to_string(),
            zenoh_file("mapper", Some(port), None)
        ),
    )
    .unwrap();
    let vins_cfg = dir.path().join("vins.toml");
    std::fs::write(&vins_cfg, format!("[zenoh]\nconfig_file = {:?}\n", zenoh_file("vins", None, Some(port)))).unwrap();
    let bin = env!("CARGO_BIN_EXE_polymap");
    let mut mapper = Command::new(bin)
        .args(["run", "--duration", "25", "--config"])
        .arg(&mapper_cfg)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut vins = Command::new(bin)
        .args(["mock-vins", seq.to_str().unwrap(), "--rate", "100", "--duration", "25", "--config"])
        .arg(&vins_cfg)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_secs(3));
    let out = Command::new(&python)
        .arg(root.join("examples/python/client.py"))
        .args(["--connect", &format!("tcp/127.0.0.1:{port}"), "--timeout", "20"])
        .output()
        .unwrap();
    let feed = Command::new(&python)
        .arg(root.join("examples/python/vins_feed.py"))
        .args(["--connect", &format!("tcp/127.0.0.1:{port}"), "--timeout", "15"])
        .output()
        .unwrap();
    let _ = (mapper.kill(), vins.kill());
    let _ = (mapper.wait(), vins.wait());
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "client failed: {stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    let polygons = v["map"]["polygons"].as_array().unwrap();
    assert!(polygons.iter().filter(|p| p["label"] == "tread").count() >= 4, "{stdout}");
    let tread = polygons.iter().find(|p| p["label"] == "tread").unwrap();
    assert!(tread["vertices"].as_u64().unwrap() >= 4 && tread["convex_pieces"].as_u64().unwrap() >= 1);
    assert!(tread["step"].as_i64().unwrap() >= 1);
    assert_eq!(v["markers"]["ns"], "polymap");
    assert_eq!(v["markers"]["type"], 4, "line strips");
    assert_eq!(v["markers"]["frame_id"], "world");

    let stdout = String::from_utf8_lossy(&feed.stdout);
    assert!(feed.status.success(), "vins_feed failed: {stdout}\n{}", String::from_utf8_lossy(&feed.stderr));
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    let s = &v["streams"];
    assert_eq!(
        (s["infra1/image_rect_raw"]["width"].as_u64(), s["infra1/image_rect_raw"]["height"].as_u64()),
        (Some(320), Some(240))
    );
    assert_eq!(s["infra2/image_rect_raw"]["encoding"], "mono8");
    assert_eq!(s["infra1/image_rect_raw"]["bytes"], 320 * 240);
    assert!(s["infra1/image_rect_raw"]["grey_levels"].as_u64().unwrap() > 50, "textured IR: {stdout}");
    assert_eq!(s["imu"]["frame_id"], "camera_imu_optical_frame");
    // infra2's projection carries the 50 mm baseline: P[3] = -fx * 0.05.
    let (fx, tx) =
        (s["infra2/camera_info"]["k"][0].as_f64().unwrap(), s["infra2/camera_info"]["p"][3].as_f64().unwrap());
    assert!((tx + fx * 0.05).abs() < 1e-9 && fx > 100.0, "{stdout}");
    assert_eq!(s["infra1/camera_info"]["p"][3].as_f64(), Some(0.0));
    // The IMU sample decoded in Python is the mock's, bit for bit: recompute it from its stamp.
    let imu = &s["imu"];
    let seq_read = polymap::sequence::Sequence::open(&seq).unwrap();
    let mock = polymap::camera::mock_d435i::MockD435i::from_sequence(
        &seq_read,
        &nalgebra::Isometry3::identity(),
        &polymap::config::D435iConfig::default(),
    )
    .unwrap();
    let clock = polymap::mock_vins::SequenceClock::new(&seq_read).unwrap();
    let want = mock.trajectory.imu(clock.sequence_time(imu["stamp_ns"].as_u64().unwrap()));
    for i in 0..3 {
        assert_eq!(imu["accel"][i].as_f64(), Some(want.accel[i]), "{stdout}");
        assert_eq!(imu["gyro"][i].as_f64(), Some(want.gyro[i]), "{stdout}");
    }
    // Covariances as realsense-ros publishes them: no orientation, 0.01 on the diagonals.
    let cov = |name: &str| -> Vec<f64> { imu[name].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect() };
    assert_eq!(cov("orientation_covariance")[0], -1.0, "{stdout}");
    for name in ["angular_velocity_covariance", "linear_acceleration_covariance"] {
        assert_eq!(cov(name), vec![0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.01], "{name}: {stdout}");
    }
    // The IMU streams at about gyro_hz (200).
    let rate = v["imu_rate_hz"].as_f64().unwrap();
    assert!((120.0..260.0).contains(&rate), "IMU rate {rate} Hz");
}
