//! What VINS gets from polymap's mock D435i, received by examples/python/vins_feed.py as a
//! ROS 2 node on rmw_zenoh (eclipse-zenoh and rosbags) on realsense-ros's topics: the IR
//! pair, their camera infos (infra2's with the baseline) and the united IMU, bit for bit the
//! mock's, at its rate, with realsense-ros's covariances.
//!
//! scripts/test.sh makes the virtualenv (eclipse-zenoh, rosbags) and sets POLYMAP_PYTHON.

use std::path::Path;
use std::process::Command;

#[test]
fn vins_gets_the_d435i_s_ir_pair_camera_infos_and_imu_as_realsense_ros_sends_them() {
    let python = std::env::var("POLYMAP_PYTHON")
        .expect("POLYMAP_PYTHON: a python with eclipse-zenoh and rosbags (scripts/test.sh)");
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let seq = root.join("mock_frames/straight_320");
    let port = polymap::ros2::session::free_loopback_port().unwrap();
    let zenoh_file = dir.path().join("mapper.json5");
    std::fs::write(&zenoh_file, polymap::ros2::session::loopback_json5(Some(port), &[])).unwrap();
    let mapper_cfg = dir.path().join("mapper.toml");
    std::fs::write(
        &mapper_cfg,
        format!(
            "[sources.depth]\nsequence = {:?}\n[sources.d435i]\nkind = \"mock\"\nir_width = 320\nir_height = 240\n\
             [pipeline]\nbackend = \"cpu\"\n[zenoh]\nconfig_file = {:?}\n",
            seq.display().to_string(),
            zenoh_file.display().to_string()
        ),
    )
    .unwrap();
    let mut mapper = Command::new(env!("CARGO_BIN_EXE_polymap"))
        .args(["run", "--duration", "300", "--config"])
        .arg(&mapper_cfg)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // The feed waits for the mapper's streams (its timeout fails only on a hang).
    let feed = Command::new(&python)
        .arg(root.join("examples/python/vins_feed.py"))
        .args(["--connect", &format!("tcp/127.0.0.1:{port}"), "--timeout", "120"])
        .output()
        .unwrap();
    let _ = mapper.kill();
    let _ = mapper.wait();
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
    // rmw_zenoh's attachment on every sample, sequence numbers counting up.
    for (topic, ok) in v["attachments_ok"].as_object().unwrap() {
        assert_eq!(ok, true, "{topic}: {stdout}");
    }
    // infra2's projection carries the 50 mm baseline: P[3] = -fx * 0.05.
    let (fx, tx) =
        (s["infra2/camera_info"]["k"][0].as_f64().unwrap(), s["infra2/camera_info"]["p"][3].as_f64().unwrap());
    assert!((tx + fx * 0.05).abs() < 1e-9 && fx > 100.0, "{stdout}");
    assert_eq!(s["infra1/camera_info"]["p"][3].as_f64(), Some(0.0));
    // The IMU sample decoded in Python is the mock's, bit for bit: recompute it from its stamp.
    let imu = &s["imu"];
    let seq_read = polymap::sequence::Sequence::open(&seq).unwrap();
    let mock = polymap::mock::d435i::MockD435i::from_sequence(
        &seq_read,
        &nalgebra::Isometry3::identity(),
        &polymap::config::D435iConfig::default(),
    )
    .unwrap();
    let clock = polymap::mock::SequenceClock::new(&seq_read).unwrap();
    let want = mock.trajectory.imu_looped(&clock, imu["stamp_ns"].as_u64().unwrap());
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
    // The IMU's stamps lie on gyro_hz's (200 Hz) grid, as a D435i's do: read from the stamps,
    // not the wall clock, so a loaded machine cannot change it.
    let period = v["imu_median_interval_s"].as_f64().unwrap();
    assert!((period - 1.0 / 200.0).abs() < 1e-8, "IMU period {period} s, not 5 ms");
}
