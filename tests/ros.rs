//! ROS 2 CDR as ROS 2 lays it out: the encapsulation header, then fields aligned to their
//! size counted from after the header; and the JSON debugging encoding.

use polymap::config::Encoding;
use polymap::pose::RawPose;
use polymap::ros::{self, MapUpdateMsg, Odometry, PolygonMsg, StatusMsg};

#[test]
fn odometry_bytes_are_laid_out_as_ros_2_cdr() {
    let pose =
        RawPose { stamp_ns: 12 * 1_000_000_000 + 345, position: [1.5, -2.0, 0.25], quat_xyzw: [0.0, 0.0, 0.0, 1.0] };
    let bytes = ros::encode(&ros::odometry(&pose, "world", "body"));
    assert_eq!(&bytes[0..4], &[0, 1, 0, 0], "CDR little-endian encapsulation");
    assert_eq!(i32::from_le_bytes(bytes[4..8].try_into().unwrap()), 12, "stamp.sec");
    assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()), 345, "stamp.nanosec");
    assert_eq!(u32::from_le_bytes(bytes[12..16].try_into().unwrap()), 6, "frame_id length with its NUL");
    assert_eq!(&bytes[16..22], b"world\0");
    // child_frame_id: 2 bytes of padding to a 4-byte boundary (counted after the header).
    assert_eq!(u32::from_le_bytes(bytes[24..28].try_into().unwrap()), 5);
    assert_eq!(&bytes[28..33], b"body\0");
    // position.x: padded to an 8-byte boundary, at 32 after the header.
    assert_eq!(f64::from_le_bytes(bytes[36..44].try_into().unwrap()), 1.5);
    // Header, strings, pose (7 doubles), 36 covariances, twist (6), 36 covariances.
    assert_eq!(bytes.len(), 36 + 8 * (7 + 36 + 6 + 36));
    let back: Odometry = ros::decode(&bytes).unwrap();
    assert_eq!(back.pose.pose.position.z, 0.25);
    assert_eq!(ros::decode_pose("vins_estimator/odometry", &bytes).unwrap(), pose);
}

#[test]
fn own_messages_round_trip_and_json_is_readable() {
    let update = MapUpdateMsg {
        header: ros::Header { stamp: ros::Time::from_ns(5), frame_id: "world".into() },
        added: vec![PolygonMsg {
            id: 7,
            label: "tread".into(),
            step: 2,
            normal: [0.0, 0.0, 1.0],
            ..PolygonMsg::default()
        }],
        changed: vec![],
        removed: vec![3, 4],
        drift_z: 0.01,
        drift_var: 1e-6,
    };
    let back: MapUpdateMsg = ros::decode(&ros::encode_as(&update, Encoding::Cdr)).unwrap();
    assert_eq!(back, update);
    let json: serde_json::Value = serde_json::from_slice(&ros::encode_as(&update, Encoding::Json)).unwrap();
    assert_eq!(json["added"][0]["label"], "tread");
    assert_eq!(json["removed"], serde_json::json!([3, 4]));
    let status = StatusMsg { frames_in: 9, ..StatusMsg::default() };
    let json: serde_json::Value = serde_json::from_slice(&ros::encode_as(&status, Encoding::Json)).unwrap();
    assert_eq!(json["frames_in"], 9);
    let markers = ros::markers(&update);
    assert_eq!(markers.markers.len(), 3, "one outline, two deletes");
    assert_eq!(markers.markers[1].action, ros::MARKER_DELETE);
    let back: ros::MarkerArray = ros::decode(&ros::encode(&markers)).unwrap();
    assert_eq!(back, markers);
}
