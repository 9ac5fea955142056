//! The pose buffer: interpolation at a frame's stamp, no pose where there is none, and every
//! kind of bad pose refused, counted, and kept out.

use nalgebra::{UnitQuaternion, Vector3};
use polymap::pose::{NoPose, PoseBuffer, PoseRejected, RawPose};

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
