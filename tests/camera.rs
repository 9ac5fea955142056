//! The camera logic without hardware: the emitter switched off against a fake options
//! interface, picking a camera by serial, IMU uniting, reconnecting, and the mock D435i
//! (its IMU integrated back to its trajectory, its IR images).

use std::collections::HashMap;
use std::time::Duration;

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use polymap::camera::{
    CamOption, CameraError, D435iSample, DeviceEntry, DeviceOptions, ImuUniter, pick_device, stream_with_reconnect,
    switch_emitter_off,
};
use polymap::mock::d435i::{GRAVITY, MockD435i, Trajectory, ir_intrinsics};
use polymap::synth::{Scene, SceneKind, path::trajectory, stamp_ns};

/// A sensor's options as a map; `stuck` options ignore writes, as a faulty firmware would.
struct FakeSensor {
    values: HashMap<&'static str, f32>,
    stuck: Vec<&'static str>,
}

impl FakeSensor {
    fn with(options: &[(CamOption, f32)]) -> FakeSensor {
        FakeSensor { values: options.iter().map(|(o, v)| (o.name(), *v)).collect(), stuck: vec![] }
    }
}

impl DeviceOptions for FakeSensor {
    fn sensor_name(&self) -> String {
        "Stereo Module".into()
    }
    fn supports(&self, o: CamOption) -> bool {
        self.values.contains_key(o.name())
    }
    fn get(&self, o: CamOption) -> Option<f32> {
        self.values.get(o.name()).copied()
    }
    fn set(&mut self, o: CamOption, v: f32) -> Result<(), String> {
        if !self.stuck.contains(&o.name()) {
            self.values.insert(o.name(), v);
        }
        Ok(())
    }
}

#[test]
fn the_emitter_is_switched_off_and_read_back() {
    let mut on = FakeSensor::with(&[(CamOption::EmitterEnabled, 1.0)]);
    switch_emitter_off(&mut on).expect("a sensor that obeys");
    assert_eq!(on.get(CamOption::EmitterEnabled), Some(0.0));

    let mut stuck = FakeSensor::with(&[(CamOption::EmitterEnabled, 1.0)]);
    stuck.stuck.push("emitter_enabled");
    let e = switch_emitter_off(&mut stuck).expect_err("an emitter that stays on must stop start-up").to_string();
    assert!(e.contains("emitter_enabled") && e.contains("still on") && e.contains("Stereo Module"), "{e}");

    let mut without = FakeSensor::with(&[(CamOption::LaserPower, 150.0)]);
    let e = switch_emitter_off(&mut without).expect_err("a sensor without the option").to_string();
    assert!(e.contains("emitter_enabled") && e.contains("not supported"), "{e}");
}

#[test]
fn l515_options_from_the_config_reach_the_sensor() {
    let toml = "[sources.depth.options]\nvisual_preset = 5\nlaser_power = 80\nmin_distance = 190\n";
    let cfg = polymap::config::Config::parse(toml, "t.toml".as_ref()).unwrap();
    let list = cfg.sources.depth.options.as_list();
    assert_eq!(list[0], (CamOption::VisualPreset, 5.0), "the preset goes first: it resets the others");
    assert_eq!(list.len(), 3);
    let bad = polymap::config::Config::parse("[sources.depth.options]\nlaser_power = 300\n", "t.toml".as_ref());
    assert!(bad.unwrap_err().to_string().contains("sources.depth.options.laser_power"));
    let unknown = polymap::config::Config::parse("[sources.depth.options]\nlazer_power = 3\n", "t.toml".as_ref());
    assert!(unknown.unwrap_err().to_string().contains("lazer_power"));
}

#[test]
fn an_option_named_as_librealsense_or_as_realsense_ros_sets_the_same_option() {
    let parse = |toml: &str| polymap::config::Config::parse(toml, "t.toml".as_ref()).map(|c| c.sources.depth.options);
    let plain = parse("[sources.depth.options]\nlaser_power = 80\ndigital_gain = 2\nreceiver_gain = 18\n").unwrap();
    // `depth_module.laser_power` as pasted from a realsense-ros launch file (a TOML dotted
    // key), or quoted whole.
    let ros = parse("[sources.depth.options]\ndepth_module.laser_power = 80\n\"depth_module.digital_gain\" = 2\ndepth_module.receiver_gain = 18\n").unwrap();
    assert_eq!(plain, ros);
    assert_eq!(
        plain.as_list(),
        vec![(CamOption::LaserPower, 80.0), (CamOption::DigitalGain, 2.0), (CamOption::ReceiverGain, 18.0)]
    );
    // The two spellings of one option at once is a mistake, not a choice.
    let twice =
        parse("[sources.depth.options]\nlaser_power = 80\ndepth_module.laser_power = 90\n").unwrap_err().to_string();
    assert!(twice.contains("laser_power is set twice"), "{twice}");
    // What the camera gets: digital_gain is librealsense's Digital Gain, receiver_gain its
    // APD "Receiver Gain".
    let mut sensor = FakeSensor::with(&[
        (CamOption::GlobalTimeEnabled, 0.0),
        (CamOption::LaserPower, 100.0),
        (CamOption::DigitalGain, 1.0),
        (CamOption::ReceiverGain, 9.0),
    ]);
    polymap::camera::apply_l515_options(&mut sensor, &ros).unwrap();
    assert_eq!(sensor.get(CamOption::DigitalGain), Some(2.0));
    assert_eq!(sensor.get(CamOption::ReceiverGain), Some(18.0));
    assert_eq!(sensor.get(CamOption::LaserPower), Some(80.0));
}

#[test]
fn receiver_gain_as_the_digital_gain_is_refused_saying_what_to_use() {
    // polymap once set librealsense's Digital Gain under the name receiver_gain (0 auto,
    // 1 high, 2 low); librealsense's "Receiver Gain" is the APD gain. Such a config stops.
    for text in ["receiver_gain = 2", "depth_module.receiver_gain = 1", "receiver_gain = 0"] {
        let e = polymap::config::Config::parse(&format!("[sources.depth.options]\n{text}\n"), "t.toml".as_ref())
            .unwrap_err();
        assert_eq!(e.key, "sources.depth.options.receiver_gain", "{e}");
        assert!(e.reason.contains("APD") && e.reason.contains("set digital_gain ="), "{e}");
    }
}

#[test]
fn the_library_check_refuses_an_l515_on_2_55_or_later_and_accepts_2_54() {
    use polymap::camera::{LibraryVersion, check_library};
    let v = |major, minor, patch| LibraryVersion { major, minor, patch };
    assert_eq!(LibraryVersion::from_api(25402), v(2, 54, 2));
    assert_eq!(LibraryVersion::from_api(25605).to_string(), "2.56.5");
    let headers = v(2, 54, 2);
    // The pinned release, and any 2.54 patch, open the L515.
    check_library(v(2, 54, 2), headers, true).unwrap();
    check_library(v(2, 54, 1), headers, true).unwrap();
    for newer in [v(2, 55, 1), v(2, 56, 5), v(2, 57, 0)] {
        let e = check_library(newer, headers, true).unwrap_err().to_string();
        assert!(!e.contains('\n'), "one line: {e}");
        assert!(e.contains(&newer.to_string()) && e.contains("2.54.2") && e.contains("L515"), "{e}");
        // A newer minor is compatible for everything but the L515 (the D435i, a recording).
        check_library(newer, headers, false).unwrap();
    }
    // What librealsense itself refuses, said plainly: an older minor than the headers', or
    // another major.
    for refused in [v(2, 53, 1), v(3, 0, 0)] {
        let e = check_library(refused, headers, false).unwrap_err().to_string();
        assert!(!e.contains('\n') && e.contains(&refused.to_string()) && e.contains("built against 2.54.2"), "{e}");
    }
}

#[test]
fn a_camera_is_picked_by_serial_or_as_the_only_one_of_its_kind() {
    let found = vec![
        DeviceEntry { name: "Intel RealSense D435I".into(), serial: "843112071234".into() },
        DeviceEntry { name: "Intel RealSense L515".into(), serial: "f0220315".into() },
    ];
    assert_eq!(pick_device(&found, "L515", "").unwrap(), 1);
    assert_eq!(pick_device(&found, "D435I", "843112071234").unwrap(), 0);
    let e = pick_device(&found, "L515", "f0999999").unwrap_err().to_string();
    assert!(e.contains("L515") && e.contains("f0999999") && e.contains("f0220315"), "names wanted and found: {e}");
    let e = pick_device(&[], "L515", "").unwrap_err().to_string();
    assert!(e.contains("no L515") && e.contains("no RealSense camera"), "{e}");
    let two = vec![found[1].clone(), DeviceEntry { name: "Intel RealSense L515".into(), serial: "f0220316".into() }];
    assert!(matches!(pick_device(&two, "L515", ""), Err(CameraError::Ambiguous { count: 2, .. })));
}

#[test]
fn gyro_samples_get_the_accel_interpolated_at_their_stamps() {
    let mut u = ImuUniter::default();
    u.push_gyro(500, [9.0; 3]); // before any accel: dropped
    assert!(u.push_accel(1_000, [0.0, 0.0, 10.0]).is_empty());
    u.push_gyro(1_250, [1.0, 0.0, 0.0]);
    u.push_gyro(1_250, [1.0, 0.0, 0.0]); // a pipeline's repeat: dropped
    u.push_gyro(1_750, [2.0, 0.0, 0.0]);
    u.push_gyro(1_500, [7.0, 0.0, 0.0]); // back in time: dropped
    u.push_gyro(2_500, [3.0, 0.0, 0.0]);
    let out = u.push_accel(2_000, [0.0, 0.0, 14.0]);
    assert_eq!(out.len(), 2, "the gyro after the new accel waits for the next one");
    assert_eq!((out[0].stamp_ns, out[0].gyro[0], out[0].accel[2]), (1_250, 1.0, 11.0));
    assert_eq!((out[1].stamp_ns, out[1].gyro[0], out[1].accel[2]), (1_750, 2.0, 13.0));
    assert!(u.push_accel(1_900, [0.0; 3]).is_empty(), "an accel going back in time is ignored");
    u.push_gyro(1_750, [2.0, 0.0, 0.0]); // already united: dropped
    let out = u.push_accel(3_000, [0.0, 0.0, 16.0]);
    assert_eq!(out.len(), 1);
    assert_eq!((out[0].stamp_ns, out[0].accel[2]), (2_500, 15.0));
}

/// A camera that sends `frames` frames and then fails, as an unplugged cable does.
struct Flaky {
    left: u32,
}

#[test]
fn a_stopped_stream_is_reopened_with_backoff_and_frames_resume() {
    let mut opens = 0;
    let mut received = Vec::new();
    let open = || {
        opens += 1;
        // Unplugged for the first two retries, then back.
        if opens <= 2 { Err(CameraError::Driver("no device".into())) } else { Ok(Flaky { left: 3 }) }
    };
    let next = |c: &mut Flaky| {
        if c.left == 0 {
            return Err(CameraError::Timeout(Duration::from_secs(2)));
        }
        c.left -= 1;
        Ok(c.left)
    };
    let backoff = (Duration::from_millis(1), Duration::from_millis(4));
    let stats = stream_with_reconnect(
        Flaky { left: 2 },
        open,
        next,
        backoff,
        || true,
        |f| {
            received.push(f);
            received.len() < 5
        },
    );
    assert_eq!(received, vec![1, 0, 2, 1, 0], "frames before the unplug, then after it");
    assert_eq!((stats.frames, stats.reconnects), (5, 1));
    assert_eq!(opens, 3, "two failed retries, then the camera came back");
}

#[test]
fn a_recording_that_ends_stops_the_stream_without_retrying() {
    let stats = stream_with_reconnect(
        0u32,
        || -> Result<u32, CameraError> { panic!("a recording's end is not a failure to retry") },
        |c: &mut u32| if *c < 3 { Ok(std::mem::replace(c, *c + 1)) } else { Err(CameraError::Ended) },
        (Duration::from_millis(1), Duration::from_millis(1)),
        || true,
        |_| true,
    );
    assert_eq!((stats.frames, stats.reconnects), (3, 0));
}

/// The straight-stairs walk at 30 Hz for 5 s, as the body trajectory.
fn walk() -> (Vec<u64>, Vec<Isometry3<f64>>) {
    let scene = Scene::build(SceneKind::Straight);
    let poses = trajectory(&scene, 150);
    ((0..poses.len()).map(|k| stamp_ns(k, 30.0)).collect(), poses)
}

#[test]
fn the_spline_stays_near_the_poses_it_was_made_from() {
    let (stamps, poses) = walk();
    let t = Trajectory::new(&stamps, poses.clone()).unwrap();
    let mut worst = (0.0f64, 0.0f64);
    for k in 1..poses.len() - 1 {
        let d = t.pose(stamps[k]).inverse() * poses[k];
        worst.0 = worst.0.max(d.translation.vector.norm());
        worst.1 = worst.1.max(d.rotation.angle().to_degrees());
    }
    // A B-spline smooths its control points by about a sixth of their second difference.
    assert!(worst.0 < 0.003 && worst.1 < 0.2, "spline vs poses: {:.2} mm, {:.3} deg", worst.0 * 1e3, worst.1);
    assert!(Trajectory::new(&stamps[..3], poses[..3].to_vec()).is_err());
    let mut uneven = stamps.clone();
    uneven[10] += 5_000_000;
    assert!(Trajectory::new(&uneven, poses).unwrap_err().contains("pose 10"));
}

#[test]
fn the_mock_imu_integrates_back_to_its_trajectory() {
    // Strapdown integration at 200 Hz (trapezoid rule on rates and world acceleration)
    // from the true start state over the whole covered walk, 4.8 s.
    let (stamps, poses) = walk();
    let t = Trajectory::new(&stamps, poses).unwrap();
    let (lo, hi) = t.time_range_ns();
    let dt_ns = 5_000_000u64;
    let start = lo + 10_000_000;
    let n = ((hi - 10_000_000 - start) / dt_ns) as usize;
    let p0 = t.pose(start);
    let v0 = (t.pose(start + 1_000_000).translation.vector - t.pose(start - 1_000_000).translation.vector) / 2e-3;
    let (mut rot, mut pos, mut vel) = (p0.rotation, p0.translation.vector, v0);
    let gravity = Vector3::new(0.0, 0.0, -GRAVITY);
    let dt = dt_ns as f64 * 1e-9;
    let mut prev = t.imu(start);
    let mut worst = (0.0f64, 0.0f64);
    for k in 1..=n {
        let now = t.imu(start + k as u64 * dt_ns);
        let gyro = (Vector3::from(prev.gyro) + Vector3::from(now.gyro)) / 2.0;
        let next_rot = rot * UnitQuaternion::from_scaled_axis(gyro * dt);
        let acc0 = rot * Vector3::from(prev.accel) + gravity;
        let acc1 = next_rot * Vector3::from(now.accel) + gravity;
        pos += vel * dt + (2.0 * acc0 + acc1) / 6.0 * dt * dt;
        vel += (acc0 + acc1) / 2.0 * dt;
        rot = next_rot;
        prev = now;
        let truth = t.pose(now.stamp_ns);
        worst.0 = worst.0.max((truth.translation.vector - pos).norm());
        worst.1 = worst.1.max((truth.rotation.inverse() * rot).angle().to_degrees());
    }
    // At rest the accelerometer reads +g up in the body frame (the specific force).
    assert!(n > 900, "integrated {n} samples");
    assert!(worst.0 < 0.01, "position error {:.2} mm over {:.1} s", worst.0 * 1e3, n as f64 * dt);
    assert!(worst.1 < 0.1, "orientation error {:.3} deg", worst.1);
    eprintln!("IMU dead reckoning over {:.1} s: {:.2} mm, {:.4} deg", n as f64 * dt, worst.0 * 1e3, worst.1);
}

#[test]
fn the_mock_accelerometer_reads_gravity_up_when_still() {
    let still = Isometry3::translation(0.0, 0.0, 1.0) * UnitQuaternion::from_euler_angles(0.3, -0.2, 0.1);
    let t = Trajectory::new(&[0, 10, 20, 30, 40].map(|k| k * 1_000_000), vec![still; 5]).unwrap();
    let s = t.imu(20_000_000);
    let up_in_body = still.rotation.inverse() * Vector3::new(0.0, 0.0, GRAVITY);
    assert!((Vector3::from(s.accel) - up_in_body).norm() < 1e-6, "{:?}", s.accel);
    assert!(Vector3::from(s.gyro).norm() < 1e-9);
}

#[test]
fn the_mock_ir_pair_sees_textured_stairs_with_the_stereo_baseline() {
    let (stamps, poses) = walk();
    let mock = MockD435i {
        scene: Scene::build(SceneKind::Straight),
        trajectory: Trajectory::new(&stamps, poses).unwrap(),
        intrinsics: ir_intrinsics(160, 120),
    };
    let t = stamps[60];
    let images = [1u8, 2].map(|i| match mock.infrared(t, i) {
        D435iSample::Infrared { index, stamp_ns, pixels, .. } => {
            assert_eq!((index, stamp_ns, pixels.len()), (i, t, 160 * 120));
            pixels
        }
        D435iSample::Imu(_) => unreachable!(),
    });
    let distinct = images[0].iter().collect::<std::collections::HashSet<_>>().len();
    assert!(distinct > 50, "texture for feature tracking: {distinct} grey levels");
    assert_ne!(images[0], images[1], "two viewpoints");
    let offset = mock.infrared_pose(t, 1).inverse() * mock.infrared_pose(t, 2);
    assert!((offset.translation.vector - Vector3::new(0.05, 0.0, 0.0)).norm() < 1e-9);
}
