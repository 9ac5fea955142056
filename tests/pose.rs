//! The pose buffer: interpolation at a frame's stamp, no pose where there is none, and every
//! kind of bad pose refused, counted, and kept out.

use nalgebra::{UnitQuaternion, Vector3};
use polymap::pose::{NoPose, PoseBuffer, PoseLimits, PoseRejected, RawPose};

const MS: u64 = 1_000_000;

fn yaw(stamp_ms: u64, x: f64, yaw_deg: f64) -> RawPose {
    let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_deg.to_radians());
    RawPose { stamp_ns: stamp_ms * MS, position: [x, 0.0, 1.0], quat_xyzw: [q.i, q.j, q.k, q.w] }
}

#[test]
fn the_pose_at_a_stamp_is_interpolated_between_its_neighbours() {
    let mut buf = PoseBuffer::new(100, 100 * MS);
    buf.push(&yaw(1000, 0.0, 0.0)).unwrap();
    buf.push(&yaw(1040, 0.04, 20.0)).unwrap();
    let t = buf.at(1010 * MS).unwrap();
    assert!((t.translation.x - 0.01).abs() < 1e-12, "{}", t.translation.x);
    assert!((t.rotation.angle().to_degrees() - 5.0).abs() < 1e-9, "slerp: {}", t.rotation.angle().to_degrees());
    let exact = buf.at(1040 * MS).unwrap();
    assert!((exact.translation.x - 0.04).abs() < 1e-15);
}

#[test]
fn no_pose_before_after_or_in_a_gap() {
    let mut buf = PoseBuffer::new(100, 100 * MS);
    assert_eq!(buf.at(5).unwrap_err(), NoPose::Empty);
    buf.push(&yaw(1000, 0.0, 0.0)).unwrap();
    buf.push(&yaw(1050, 0.1, 0.0)).unwrap();
    buf.push(&yaw(1300, 0.2, 0.0)).unwrap();
    assert!(matches!(buf.at(990 * MS), Err(NoPose::TooOld { .. })));
    // After the newest pose: never extrapolated, even by a millisecond.
    assert!(matches!(buf.at(1301 * MS), Err(NoPose::NotYet { .. })));
    let gap = buf.at(1100 * MS).unwrap_err();
    assert!(matches!(gap, NoPose::Gap { .. }), "{gap}");
    assert!(gap.to_string().contains("250.0 ms gap"), "{gap}");
    assert!(buf.at(1025 * MS).is_ok());
    assert_eq!(buf.counters.missing, 4);
    // The odometry jumps 2 m in 10 ms (a relocalisation): nothing in between is blended.
    buf.push(&yaw(1310, 2.2, 0.0)).unwrap();
    let jump = buf.at(1305 * MS).unwrap_err();
    assert!(matches!(jump, NoPose::Jump { .. }), "{jump}");
}

#[test]
fn bad_poses_are_refused_counted_and_kept_out() {
    let mut buf = PoseBuffer::new(100, 100 * MS);
    buf.push(&yaw(1000, 0.0, 0.0)).unwrap();
    buf.push(&yaw(1040, 0.04, 0.0)).unwrap();
    let mut nan_position = yaw(1050, 0.0, 0.0);
    nan_position.position[1] = f64::NAN;
    let mut nan_quaternion = yaw(1050, 0.0, 0.0);
    nan_quaternion.quat_xyzw[3] = f64::NAN;
    let mut not_unit = yaw(1050, 0.0, 0.0);
    not_unit.quat_xyzw = [0.0, 0.0, 0.0, 0.9];
    let mut zero = yaw(1050, 0.0, 0.0);
    zero.quat_xyzw = [0.0; 4];
    let cases = [
        (nan_position, "non-finite position"),
        (nan_quaternion, "not a rotation"),
        (not_unit, "norm 0.9"),
        (zero, "norm 0"),
        (yaw(1040, 9.0, 0.0), "not after"),
        (yaw(900, 9.0, 0.0), "not after"),
    ];
    for (raw, says) in &cases {
        let err = buf.push(raw).unwrap_err();
        assert!(err.to_string().contains(says), "{err} should say {says}");
    }
    assert!(matches!(buf.push(&yaw(1040, 9.0, 0.0)), Err(PoseRejected::StampNotIncreasing { .. })));
    assert_eq!(buf.counters.rejected, cases.len() as u64 + 1);
    assert_eq!(buf.counters.accepted, 2);
    assert_eq!(buf.len(), 2, "nothing bad got in");
    let t = buf.at(1020 * MS).unwrap();
    assert!((t.translation.x - 0.02).abs() < 1e-12 && t.translation.y == 0.0);
}

#[test]
fn a_flood_of_poses_keeps_memory_bounded_and_lookups_right() {
    let mut buf = PoseBuffer::new(1000, 100 * MS);
    for k in 0..10_000u64 {
        buf.push(&yaw(k, k as f64 * 0.001, 0.0)).unwrap();
    }
    assert_eq!(buf.len(), 1000, "only the newest are kept");
    assert_eq!(buf.counters.accepted, 10_000);
    let t = buf.at(9_500 * MS + MS / 2).unwrap();
    assert!((t.translation.x - 9.5005).abs() < 1e-9);
    assert!(matches!(buf.at(8_000 * MS), Err(NoPose::TooOld { .. })));
}

/// The limits `polymap run` uses by default, with "now" at `NOW`.
fn live_buffer() -> PoseBuffer {
    PoseBuffer::with_limits(100, PoseLimits::from_config(&polymap::config::PosesConfig::default()))
}

const NOW: u64 = 1_800_000_000 * 1_000_000_000;

fn at(stamp_ns: u64, position: [f64; 3], quat_xyzw: [f64; 4]) -> RawPose {
    RawPose { stamp_ns, position, quat_xyzw }
}

#[test]
fn implausible_poses_are_refused_counted_and_never_move_the_newest_stamp() {
    let mut buf = live_buffer();
    let id = [0.0, 0.0, 0.0, 1.0];
    buf.push_at(&at(NOW - 20 * MS, [1.0, 0.0, 0.5], id), NOW).unwrap();
    buf.push_at(&at(NOW - 10 * MS, [1.01, 0.0, 0.5], id), NOW).unwrap();
    let year_2038 = 2_147_483_647u64 * 1_000_000_000;
    let s = (0.6f64).sqrt();
    let cases = [
        (at(NOW - 5 * MS, [1e308, 0.0, 0.5], id), "beyond"),
        (at(NOW - 5 * MS, [1.0, 1e150, 0.5], id), "beyond"),
        (at(NOW - 5 * MS, [1.0, 0.0, -2e4], id), "beyond the 10000 m"),
        (at(NOW - 5 * MS, [1.0, 0.0, 0.5], [1e200, 0.0, 0.0, 1.0]), "not a rotation"),
        (at(NOW - 5 * MS, [1.0, 0.0, 0.5], [s, s, 0.0, 0.0]), "norm 1.09"),
        (at(NOW - 5 * MS, [1.0, 0.0, 0.5], [1e-200, 0.0, 0.0, 0.0]), "not a rotation"),
        (at(year_2038, [1.0, 0.0, 0.5], id), "ahead of this machine's clock"),
        (at(NOW + 30_000 * MS, [1.0, 0.0, 0.5], id), "ahead of this machine's clock"),
    ];
    for (raw, says) in &cases {
        let err = buf.push_at(raw, NOW).unwrap_err();
        assert!(err.to_string().contains(says), "{err} should say {says}");
    }
    assert_eq!(buf.counters.rejected, cases.len() as u64);
    // The newest stamp is still the real one: the real stream goes on.
    buf.push_at(&at(NOW, [1.02, 0.0, 0.5], id), NOW).unwrap();
    let t = buf.at(NOW - 5 * MS).unwrap();
    assert!((t.translation.x - 1.015).abs() < 1e-12);
    // A stamp just ahead of the clock (within max_ahead_s) is a clock's jitter, not a lie.
    buf.push_at(&at(NOW + 100 * MS, [1.03, 0.0, 0.5], id), NOW).unwrap();
    assert_eq!(buf.counters.accepted, 4);
}

#[test]
fn an_odometry_that_starts_over_is_followed_after_a_silence() {
    let mut buf = live_buffer();
    let id = [0.0, 0.0, 0.0, 1.0];
    for k in 0..10u64 {
        buf.push_at(&at(NOW - 1000 * MS + 10 * k * MS, [k as f64 * 0.01, 0.0, 0.5], id), NOW - 1000 * MS + 10 * k * MS)
            .unwrap();
    }
    // Going back right away is a bad pose, refused.
    let back = at(NOW - 2000 * MS, [0.0, 0.0, 0.5], id);
    assert!(matches!(buf.push_at(&back, NOW - 900 * MS), Err(PoseRejected::StampNotIncreasing { .. })));
    // After 1 s of silence (poses.restart_after_s), it is VINS starting over: followed.
    let restart = NOW - 900 * MS + 1100 * MS;
    buf.push_at(&at(NOW - 2000 * MS, [5.0, 0.0, 0.5], id), restart).unwrap();
    buf.push_at(&at(NOW - 1990 * MS, [5.01, 0.0, 0.5], id), restart + 10 * MS).unwrap();
    assert_eq!(buf.counters.restarts, 1);
    assert_eq!(buf.len(), 2, "the old odometry's poses are gone");
    let t = buf.at(NOW - 1995 * MS).unwrap();
    assert!((t.translation.x - 5.005).abs() < 1e-12);
    assert!(matches!(buf.at(NOW - 950 * MS), Err(NoPose::NotYet { .. })), "nothing of the old odometry answers");
}

/// A body bobbing 12 mm at 8 Hz while it walks 0.5 m/s along x, yawing 2 deg at 4 Hz.
fn bobbing(stamp_ms: u64) -> RawPose {
    let t = stamp_ms as f64 * 1e-3;
    let q = UnitQuaternion::from_axis_angle(
        &Vector3::z_axis(),
        (2.0 * (8.0 * std::f64::consts::PI * t).sin()).to_radians(),
    );
    let z = 1.0 + 0.012 * (8.0 * std::f64::consts::PI * t).sin().powi(2);
    RawPose { stamp_ns: stamp_ms * MS, position: [0.5 * t, 0.0, z], quat_xyzw: [q.i, q.j, q.k, q.w] }
}

/// `p` moved by a constant offset: the optimised estimate, off the propagated one.
fn offset(mut p: RawPose, dz: f64) -> RawPose {
    p.position[2] += dz;
    p
}

#[test]
fn propagated_poses_carry_the_motion_between_optimised_ones() {
    let mut straight = PoseBuffer::new(1000, 250 * MS);
    let mut dense = PoseBuffer::new(1000, 250 * MS);
    // Optimised at 10 Hz, 3 mm above the propagated stream (200 Hz), which follows the bob.
    for k in 0..=10u64 {
        let p = offset(bobbing(1000 + 100 * k), 0.003);
        straight.push_at(&p, 0).unwrap();
        dense.push_at(&p, 0).unwrap();
    }
    for k in 0..=200u64 {
        dense.push_propagated_at(&bobbing(1000 + 5 * k), 0).unwrap();
    }
    let mut worst = (0.0f64, 0.0f64);
    for stamp_ms in (1000..2000).step_by(7) {
        let want = offset(bobbing(stamp_ms), 0.003);
        let err = |b: &PoseBuffer| (b.lookup(stamp_ms * MS).unwrap().translation.z - want.position[2]).abs();
        worst = (worst.0.max(err(&straight)), worst.1.max(err(&dense)));
        let yaw = dense.lookup(stamp_ms * MS).unwrap().rotation.euler_angles().2;
        let want_yaw = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            want.quat_xyzw[3],
            want.quat_xyzw[0],
            want.quat_xyzw[1],
            want.quat_xyzw[2],
        ))
        .euler_angles()
        .2;
        assert!((yaw - want_yaw).abs() < 1e-3, "yaw at {stamp_ms} ms: {yaw} vs {want_yaw}");
    }
    assert!(worst.0 > 0.005, "straight lines miss the bob: {} m", worst.0);
    assert!(worst.1 < 2e-4, "the propagated stream follows it: {} m", worst.1);
    // After the newest optimised pose (2000 ms), the propagated one with its offset, up to
    // a gap after it; beyond the propagated stream, none yet.
    for k in 201..=210u64 {
        dense.push_propagated_at(&bobbing(1000 + 5 * k), 0).unwrap();
    }
    let after = dense.lookup(2030 * MS).unwrap();
    assert!((after.translation.z - offset(bobbing(2030), 0.003).position[2]).abs() < 1e-9);
    assert!(matches!(dense.lookup(2060 * MS), Err(NoPose::NotYet { .. })));
    assert!(matches!(straight.lookup(2030 * MS), Err(NoPose::NotYet { .. })));
    assert_eq!(dense.counters.propagated, 211);
}

/// The bobbing walk's odometry from 1.0 to 2.0 s at 10 Hz, its propagated poses at 200 Hz
/// up to `propagated_until_ms`.
fn walked(propagated_until_ms: u64) -> PoseBuffer {
    let mut buf = PoseBuffer::new(1000, 250 * MS);
    for k in 0..=10u64 {
        buf.push_at(&bobbing(1000 + 100 * k), 0).unwrap();
    }
    for stamp_ms in (1000..=propagated_until_ms).step_by(5) {
        buf.push_propagated_at(&bobbing(stamp_ms), 0).unwrap();
    }
    buf
}

#[test]
fn one_wild_pose_poses_no_frame_after_it() {
    // Then one optimised pose 9 km away, stamped ahead of the stream (a fake publisher's, or
    // a corrupt one).
    let mut buf = walked(2200);
    buf.push_at(&RawPose { position: [9000.0, 0.0, 1.0], ..bobbing(2100) }, 0).unwrap();
    for stamp_ms in [2110, 2150, 2190] {
        let posed = buf.lookup(stamp_ms * MS);
        assert!(matches!(posed, Err(NoPose::Jump { .. })), "{stamp_ms} ms: {posed:?}");
    }
    // Between the last plausible pose and the wild one, nothing either.
    assert!(matches!(buf.lookup(2050 * MS), Err(NoPose::Jump { .. })));
    // Without it, the same frames are posed through the propagated stream.
    let posed = walked(2200).lookup(2110 * MS).unwrap();
    assert!((posed.translation.x - 0.5 * 2.11).abs() < 1e-6, "{}", posed.translation.x);
}

#[test]
fn a_wild_pose_long_after_the_last_poses_nothing_either() {
    // Stamped 0.45 s after the last plausible pose (more than the gap interpolation bridges),
    // the propagated stream running on: still a jump from the pose before it.
    let mut buf = walked(2500);
    buf.push_at(&RawPose { position: [9000.0, 0.0, 1.0], ..bobbing(2450) }, 0).unwrap();
    assert!(matches!(buf.lookup(2460 * MS), Err(NoPose::Jump { .. })), "{:?}", buf.lookup(2460 * MS));
}
