//! ROS 2 on the wire, checked against what the peers define: CDR as ROS 2 lays it out; the
//! type hashes (REP 2016) of standard types equal their published values; keys, liveliness
//! tokens, QoS strings and attachments exactly as rmw_zenoh's design document writes its
//! examples; zenoh-bridge-ros2dds's announcements as its liveliness_mgt.rs parses them.

use polymap::interface::convert;
use polymap::pose::RawPose;
use polymap::ros2::attachment::{Attachment, gid_of};
use polymap::ros2::graph::{self, Endpoint, EntityKind, NodeId};
use polymap::ros2::msg::service_hash;
use polymap::ros2::msg::{self, MapUpdate, Odometry, Polygon, Status};
use polymap::ros2::qos::{Durability, History, Qos, Reliability};
use polymap::ros2::types::{RosService, dds_type_name, message_hash};
use polymap::ros2::{Distro, Mode, RosName, cdr};

#[test]
fn odometry_bytes_are_laid_out_as_ros_2_cdr() {
    let pose =
        RawPose { stamp_ns: 12 * 1_000_000_000 + 345, position: [1.5, -2.0, 0.25], quat_xyzw: [0.0, 0.0, 0.0, 1.0] };
    let bytes = cdr::to_vec(&convert::odometry(&pose, "world", "body"));
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
    let back: Odometry = cdr::from_slice(&bytes).unwrap();
    assert_eq!(back.pose.pose.position.z, 0.25);
    assert_eq!(convert::pose_of_odometry(&back).unwrap(), pose);
    // The same message big-endian, as a big-endian writer would send it, reads the same.
    let mut be = vec![0, 0, 0, 0];
    be.extend(bytes[4..8].iter().rev());
    be.extend(bytes[8..12].iter().rev());
    be.extend(bytes[12..16].iter().rev());
    be.extend(&bytes[16..24]);
    be.extend(bytes[24..28].iter().rev());
    be.extend(&bytes[28..36]);
    for chunk in bytes[36..].chunks(8) {
        be.extend(chunk.iter().rev());
    }
    assert_eq!(cdr::from_slice::<Odometry>(&be).unwrap(), back);
}

#[test]
fn a_string_s_cdr_is_as_rmw_zenoh_s_design_writes_it() {
    // docs/design.md: std_msgs/String{data: "hi"} is 00 01 00 00 03 00 00 00 68 69 00.
    let bytes = cdr::to_vec(&msg::StringMsg { data: "hi".into() });
    assert_eq!(bytes, [0, 1, 0, 0, 3, 0, 0, 0, b'h', b'i', 0]);
}

#[test]
fn own_messages_round_trip_and_json_is_readable() {
    let update = MapUpdate {
        header: convert::header(5, "map"),
        epoch: 1_790_000_000_000_000_000,
        from_version: 41,
        version: 42,
        added: vec![Polygon {
            id: 7,
            label: Polygon::LABEL_TREAD,
            step: 2,
            normal: [0.0, 0.0, 1.0],
            ..Polygon::default()
        }],
        changed: vec![],
        removed: vec![3, 4],
        drift_z: 0.01,
        drift_var: 1e-6,
    };
    let back: MapUpdate = cdr::from_slice(&cdr::to_vec(&update)).unwrap();
    assert_eq!(back, update);
    let json: serde_json::Value = serde_json::to_value(&update).unwrap();
    assert_eq!(json["added"][0]["label"], Polygon::LABEL_TREAD);
    assert_eq!(json["removed"], serde_json::json!([3, 4]));
    let status = Status { frames_in: 9, ..Status::default() };
    assert_eq!(cdr::from_slice::<Status>(&cdr::to_vec(&status)).unwrap(), status);
    let map = msg::Map { header: update.header.clone(), polygons: update.added.clone(), ..msg::Map::default() };
    let markers = convert::whole_map_markers(&map);
    assert_eq!(markers.markers.len(), 2, "a DELETEALL, then the one outline");
    assert_eq!(markers.markers[0].action, convert::MARKER_DELETEALL);
    assert_eq!(markers.markers[1].action, convert::MARKER_ADD);
    let back: msg::MarkerArray = cdr::from_slice(&cdr::to_vec(&markers)).unwrap();
    assert_eq!(back, markers);
}

#[test]
fn decoding_refuses_lengths_the_bytes_cannot_hold() {
    // A string length of 4 GiB in 16 bytes: refused before anything is made of it.
    let bomb = [0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0xf0, 0xff, 0xff, 0xff];
    let e = cdr::from_slice::<Odometry>(&bomb).unwrap_err();
    assert!(matches!(e, cdr::CdrError::LengthTooLong { claimed: 0xffff_fff0, .. }), "{e}");
    // A sequence claiming more elements than bytes left.
    let mut seq = cdr::to_vec(&msg::TfMessage::default());
    seq[4..8].copy_from_slice(&1_000_000u32.to_le_bytes());
    assert!(matches!(cdr::from_slice::<msg::TfMessage>(&seq), Err(cdr::CdrError::LengthTooLong { .. })));
    // No header, a bad bool, trailing bytes, an oversized message.
    assert!(matches!(cdr::from_slice::<msg::Time>(&[1, 2]), Err(cdr::CdrError::Header(_))));
    let mut bad_bool = cdr::to_vec(&msg::RegionOfInterest::default());
    *bad_bool.last_mut().unwrap() = 7;
    assert!(cdr::from_slice::<msg::RegionOfInterest>(&bad_bool).is_err());
    let mut long = cdr::to_vec(&msg::Time::default());
    long.extend([0; 8]);
    assert!(matches!(cdr::from_slice::<msg::Time>(&long), Err(cdr::CdrError::Trailing(8))));
    let huge = vec![0u8; cdr::MAX_MESSAGE_BYTES + 1];
    assert!(matches!(cdr::from_slice::<msg::Time>(&huge), Err(cdr::CdrError::TooLarge(_))));
}

polymap::ros_message! {
    /// example_interfaces/AddTwoInts's request (the service rmw_zenoh's design document keys).
    #[derive(Default)]
    pub struct AddTwoIntsRequest = "example_interfaces/srv/AddTwoInts_Request" { pub a: i64, pub b: i64 }
    #[derive(Default)]
    pub struct AddTwoIntsResponse = "example_interfaces/srv/AddTwoInts_Response" { pub sum: i64 }
}

struct AddTwoInts;

impl RosService for AddTwoInts {
    const TYPE_NAME: &'static str = "example_interfaces/srv/AddTwoInts";
    const EVENT_TYPE_NAME: &'static str = "example_interfaces/srv/AddTwoInts_Event";
    type Request = AddTwoIntsRequest;
    type Response = AddTwoIntsResponse;
}

#[test]
fn type_hashes_equal_the_published_ones() {
    // Published by rosidl for ROS 2 Jazzy (rmw_zenoh's design document, rosbag2 metadata,
    // `ros2 topic info -v`).
    let published = [
        (message_hash::<msg::StringMsg>(), "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"),
        (message_hash::<msg::Time>(), "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197"),
        (message_hash::<msg::Header>(), "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01"),
        (message_hash::<msg::Odometry>(), "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"),
        (message_hash::<msg::Imu>(), "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b"),
        (message_hash::<msg::PoseStamped>(), "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8"),
        (message_hash::<msg::Image>(), "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47"),
        (message_hash::<msg::CameraInfo>(), "RIHS01_b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275"),
        (message_hash::<msg::MarkerArray>(), "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf"),
        (message_hash::<msg::TfMessage>(), "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"),
        (service_hash::<AddTwoInts>(), "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"),
    ];
    for (computed, want) in published {
        assert_eq!(computed, want);
    }
}

#[test]
fn polymap_msgs_hashes_stay_what_they_are() {
    // A change here is a change of polymap's interface: planners built against the old
    // messages no longer match. Update polymap_msgs/ with it (the Python peer in
    // tests/ros2_peer.rs recomputes these from the .msg and .srv files).
    let pinned = [
        (message_hash::<msg::Polygon>(), "RIHS01_0d6e3a296c10c1a1e93a54a657dda2c0505c13168ac1731ecec1cab26e29c791"),
        (
            message_hash::<msg::FramePolygons>(),
            "RIHS01_db2a0223fd51c6b7a2a6bc69f39c3cd93425c16cd965b5904b6ae6691c94c1b4",
        ),
        (message_hash::<msg::MapUpdate>(), "RIHS01_acb4e7b5687d7d674f6ed33e672ad088e44e048c32e25d16924b340c755ac265"),
        (message_hash::<msg::Map>(), "RIHS01_ee0adf25b9639d61e82a4254635b6c1168770a5843090ed2756f069e0c4d1b10"),
        (message_hash::<msg::Foothold>(), "RIHS01_d26115d96a054f501d9035484e44efd87a0dabf66fd8dc041d707ec4e59b8d6a"),
        (message_hash::<msg::Status>(), "RIHS01_60bd89eec0cc25e5fd6f0095ab83e8ed4b63c59a62a5a806ea4970c9aa32b5db"),
        (service_hash::<msg::GetMap>(), "RIHS01_751393063164b025f4401ffccef7f209848155f0bee95456a3ea9b92e97d8fe2"),
        (service_hash::<msg::GetFoothold>(), "RIHS01_160e108c4c57519c6ee265867964cd138069183f4f278b046e095327834391b8"),
        (message_hash::<msg::Region>(), "RIHS01_02f36fb3a034933b83025e74605cb9f8bd8c509fa461641830b6258de7406ae7"),
    ];
    for (computed, want) in pinned {
        assert_eq!(computed, want);
    }
}

/// convex_plane_decomposition_msgs/PlanarTerrain as rosbags 0.11.9 serialises it from the
/// packages' ROS 2 .msg files (PlanarRegion, PolygonWithHoles2d, Polygon2d, Point2d,
/// BoundingBox2d; grid_map_msgs GridMap and GridMapInfo; std_msgs Float32MultiArray): one
/// 0.2 m square region at (1, 2, 0.05) with a 0.1 m inset, and a 3 x 2 grid at 0.1 m in
/// `odom` whose one layer holds 10 r + c with (2, 1) NaN, column-major.
const PLANAR_TERRAIN_CDR: [&str; 25] = [
    "00 01 00 00 01 00 00 00 00 00 00 00 00 00 00 00",
    "00 00 f0 3f 00 00 00 00 00 00 00 40 9a 99 99 99",
    "99 99 a9 3f 00 00 00 00 00 00 00 00 00 00 00 00",
    "00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00",
    "00 00 f0 3f cd cc cc bd cd cc cc bd cd cc cc 3d",
    "cd cc cc 3d 04 00 00 00 cd cc cc bd cd cc cc bd",
    "cd cc cc 3d cd cc cc bd cd cc cc 3d cd cc cc 3d",
    "cd cc cc bd cd cc cc 3d 00 00 00 00 01 00 00 00",
    "04 00 00 00 cd cc 4c bd cd cc 4c bd cd cc 4c 3d",
    "cd cc 4c bd cd cc 4c 3d cd cc 4c 3d cd cc 4c bd",
    "cd cc 4c 3d 00 00 00 00 01 00 00 00 00 65 cd 1d",
    "05 00 00 00 6f 64 6f 6d 00 00 00 00 9a 99 99 99",
    "99 99 b9 3f 33 33 33 33 33 33 d3 3f 9a 99 99 99",
    "99 99 c9 3f 00 00 00 00 00 00 f0 3f 00 00 00 00",
    "00 00 00 40 00 00 00 00 00 00 00 00 00 00 00 00",
    "00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00",
    "00 00 00 00 00 00 00 00 00 00 f0 3f 01 00 00 00",
    "0a 00 00 00 65 6c 65 76 61 74 69 6f 6e 00 00 00",
    "00 00 00 00 01 00 00 00 02 00 00 00 0d 00 00 00",
    "63 6f 6c 75 6d 6e 5f 69 6e 64 65 78 00 00 00 00",
    "02 00 00 00 06 00 00 00 0a 00 00 00 72 6f 77 5f",
    "69 6e 64 65 78 00 00 00 03 00 00 00 03 00 00 00",
    "00 00 00 00 06 00 00 00 00 00 00 00 00 00 20 41",
    "00 00 a0 41 00 00 80 3f 00 00 30 41 00 00 c0 7f",
    "00 00 00 00",
];

#[test]
fn planar_terrain_bytes_are_as_its_message_definitions_lay_them_out() {
    let want: Vec<u8> = PLANAR_TERRAIN_CDR
        .iter()
        .flat_map(|line| line.split_whitespace().map(|b| u8::from_str_radix(b, 16).unwrap()))
        .collect();
    let square = |h: f32| msg::Polygon2d {
        points: vec![
            msg::Point2d { x: -h, y: -h },
            msg::Point2d { x: h, y: -h },
            msg::Point2d { x: h, y: h },
            msg::Point2d { x: -h, y: h },
        ],
    };
    let (rows, cols) = (3usize, 2usize);
    let data: Vec<f32> = (0..cols)
        .flat_map(|c| (0..rows).map(move |r| if (r, c) == (2, 1) { f32::NAN } else { (10 * r + c) as f32 }))
        .collect();
    let terrain = msg::PlanarTerrain {
        planar_regions: vec![msg::PlanarRegion {
            plane_parameters: msg::Pose {
                position: msg::Point { x: 1.0, y: 2.0, z: 0.05 },
                orientation: msg::Quaternion::default(),
            },
            bbox2d: msg::BoundingBox2d { min_x: -0.1, min_y: -0.1, max_x: 0.1, max_y: 0.1 },
            boundary: msg::PolygonWithHoles2d { outer_boundary: square(0.1), holes: vec![] },
            insets: vec![msg::PolygonWithHoles2d { outer_boundary: square(0.05), holes: vec![] }],
        }],
        gridmap: msg::GridMap {
            header: msg::Header { stamp: msg::Time { sec: 1, nanosec: 500_000_000 }, frame_id: "odom".into() },
            info: msg::GridMapInfo {
                resolution: 0.1,
                length_x: 0.3,
                length_y: 0.2,
                pose: msg::Pose {
                    position: msg::Point { x: 1.0, y: 2.0, z: 0.0 },
                    orientation: msg::Quaternion::default(),
                },
            },
            layers: vec!["elevation".into()],
            basic_layers: vec![],
            data: vec![msg::Float32MultiArray {
                layout: msg::MultiArrayLayout {
                    dim: vec![
                        msg::MultiArrayDimension { label: "column_index".into(), size: 2, stride: 6 },
                        msg::MultiArrayDimension { label: "row_index".into(), size: 3, stride: 3 },
                    ],
                    data_offset: 0,
                },
                data,
            }],
            outer_start_index: 0,
            inner_start_index: 0,
        },
    };
    assert_eq!(cdr::to_vec(&terrain), want);
    let back: msg::PlanarTerrain = cdr::from_slice(&want).unwrap();
    assert!(back.gridmap.data[0].data[5].is_nan());
    assert_eq!(back.planar_regions, terrain.planar_regions);
}

#[test]
fn terrain_type_hashes_are_what_rosidl_computes() {
    // Computed by rosidl's own generator (Jazzy, rosidl_generator_type_description) from the
    // .msg files of grid_map (jazzy) and convex_plane_decomposition_msgs (ROS 2), and by
    // rosbags the same: a planner built against those packages matches these keys.
    let pinned = [
        (message_hash::<msg::GridMap>(), "RIHS01_343b0e72887541beda6b035cc053f2d6fffaad9d6dcb2773c15a808dfca31fde"),
        (message_hash::<msg::GridMapInfo>(), "RIHS01_0a36d6b5bc9af8463d1d5a5008ef9fcac0c1373ba090f80c3594e47cc565b745"),
        (
            message_hash::<msg::PlanarTerrain>(),
            "RIHS01_99aee1c3ff6087f377e927f40eb25509760eba180f3cfcc7f479b7c49b23d2dd",
        ),
        (
            message_hash::<msg::PlanarRegion>(),
            "RIHS01_4a3f66cda630b01104964a4294bdb9d9cc9bd7e2f5d650487cde077dd376555f",
        ),
        (
            message_hash::<msg::PolygonWithHoles2d>(),
            "RIHS01_9f8206c6cc32e2e13e0662b5083f86cd95714ed96fc3f3fc87b3513008d6a6d6",
        ),
        (message_hash::<msg::Polygon2d>(), "RIHS01_ca4a091f78d788b4bef74e83d0d1e296a778965124f7eb144e9c394c9cc2a918"),
        (message_hash::<msg::Point2d>(), "RIHS01_f852c21744ddc2dcc1124f3f139ad71f3e4c5eb6dc3a3d4a13db0ff7f2a59694"),
        (
            message_hash::<msg::BoundingBox2d>(),
            "RIHS01_ed20580414a340e081b9655b16fe1e3c7ff99f5d8ac043528c06afe743ae4392",
        ),
        (
            message_hash::<msg::Float32MultiArray>(),
            "RIHS01_0599f6f85b4bfca379873a0b4375a0aca022156bd2d7021275d116ed1fa8bfe0",
        ),
        (
            message_hash::<msg::MultiArrayLayout>(),
            "RIHS01_4c66e6f78e740ac103a94cf63259f968e48c617e7699e829b63c21a5cb50dac6",
        ),
        (
            message_hash::<msg::MultiArrayDimension>(),
            "RIHS01_5e773a60a4c7fc8a54985f307c7837aa2994252a126c301957a24e31282c9cbe",
        ),
    ];
    for (computed, want) in pinned {
        assert_eq!(computed, want);
    }
}

fn name(s: &str) -> RosName {
    RosName::parse(s).unwrap()
}

#[test]
fn keys_and_tokens_are_rmw_zenoh_s() {
    // The examples of rmw_zenoh's docs/design.md (Jazzy), rebuilt from their parts.
    let string_hash = message_hash::<msg::StringMsg>();
    let chatter = name("/chatter");
    let e = Endpoint { name: &chatter, type_name: "std_msgs/msg/String", type_hash: &string_hash };
    let jazzy = Mode::RmwZenoh(Distro::Jazzy);
    assert_eq!(
        graph::data_key(jazzy, 0, &e),
        "0/chatter/std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    );
    let in_robot1 = name("/robot1/chatter");
    let e1 = Endpoint { name: &in_robot1, ..e.clone() };
    assert!(graph::data_key(jazzy, 0, &e1).starts_with("0/robot1/chatter/std_msgs::msg::dds_::String_/RIHS01_df66"));
    assert_eq!(
        graph::data_key(Mode::RmwZenoh(Distro::Humble), 0, &e),
        "0/chatter/std_msgs::msg::dds_::String_/TypeHashNotSupported"
    );
    let root = RosName::root();
    let listener =
        NodeId { domain: 0, zid: "aac3178e146ba6f1fc6e6a4085e77f21", id: 0, namespace: &root, name: "listener" };
    assert_eq!(
        graph::rmw_zenoh_token(Distro::Jazzy, &listener, None),
        "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
    );
    assert_eq!(
        graph::rmw_zenoh_token(Distro::Jazzy, &listener, Some((10, EntityKind::Subscription, &e, "::,10:,:,:,,"))),
        "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/\
         RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,10:,:,:,,"
    );
    let add = name("/add_two_ints");
    let add_hash = service_hash::<AddTwoInts>();
    let s = Endpoint { name: &add, type_name: AddTwoInts::TYPE_NAME, type_hash: &add_hash };
    let server = NodeId { zid: "f9980ee0495eaafb3e38f0d19e2eae12", name: "add_two_ints_server", ..listener.clone() };
    assert_eq!(
        graph::rmw_zenoh_token(Distro::Jazzy, &server, Some((10, EntityKind::ServiceServer, &s, "::,10:,:,:,,"))),
        "@ros2_lv/0/f9980ee0495eaafb3e38f0d19e2eae12/0/10/SS/%/%/add_two_ints_server/%add_two_ints/\
         example_interfaces::srv::dds_::AddTwoInts_/RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a/\
         ::,10:,:,:,,"
    );
    assert_eq!(
        graph::data_key(jazzy, 2, &s),
        "2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
    );
    // A node in a namespace: every '/' of the names written '%'.
    let ns = name("/robot1");
    let imu = name("/robot1/imu/data");
    let imu_hash = message_hash::<msg::Imu>();
    let i = Endpoint { name: &imu, type_name: "sensor_msgs/msg/Imu", type_hash: &imu_hash };
    let node = NodeId { domain: 0, zid: "1a2b", id: 0, namespace: &ns, name: "imu_node" };
    let sensor_data =
        Qos { reliability: Reliability::BestEffort, durability: Durability::Volatile, history: History::KeepLast(5) };
    assert_eq!(
        graph::rmw_zenoh_token(
            Distro::Humble,
            &node,
            Some((3, EntityKind::Publisher, &i, &sensor_data.rmw_zenoh_key()))
        ),
        "@ros2_lv/0/1a2b/0/3/MP/%/%robot1/imu_node/%robot1%imu%data/sensor_msgs::msg::dds_::Imu_/TypeHashNotSupported/2::,5:,:,:,,"
    );
    assert_eq!(dds_type_name("nav_msgs/msg/Odometry"), "nav_msgs::msg::dds_::Odometry_");
}

#[test]
fn qos_strings_are_rmw_zenoh_s() {
    assert_eq!(Qos::reliable(10).rmw_zenoh_key(), "::,10:,:,:,,");
    assert_eq!(Qos::reliable(42).rmw_zenoh_key(), "::,:,:,:,,", "the default depth is written empty");
    assert_eq!(Qos::latched(1).rmw_zenoh_key(), ":1:,1:,:,:,,", "/tf_static's");
    assert_eq!(Qos::every_sample().rmw_zenoh_key(), "::2,:,:,:,,");
    let sensor_data =
        Qos { reliability: Reliability::BestEffort, durability: Durability::Volatile, history: History::KeepLast(5) };
    assert_eq!(sensor_data.rmw_zenoh_key(), "2::,5:,:,:,,");
}

#[test]
fn attachments_are_rmw_zenoh_s_in_both_layouts() {
    let gid = gid_of("@ros2_lv/0/1a2b/0/3/MP/%/%/n/%t/std_msgs::msg::dds_::String_/TypeHashNotSupported/::,10:,:,:,,");
    let a = Attachment { sequence_number: 7, source_timestamp_ns: 1_700_000_000_123_456_789, gid };
    let bytes = a.to_bytes();
    assert_eq!(bytes.len(), 33);
    assert_eq!(&bytes[..8], &7i64.to_le_bytes());
    assert_eq!(&bytes[8..16], &1_700_000_000_123_456_789i64.to_le_bytes());
    assert_eq!(bytes[16], 16, "the GID as a sequence of 16");
    assert_eq!(&bytes[17..], &gid);
    assert_eq!(Attachment::from_bytes(&bytes), Some(a));
    // rmw_zenoh before Jazzy 0.2.4 wrote each field after its name.
    let mut keyed = vec![15];
    keyed.extend(b"sequence_number");
    keyed.extend(7i64.to_le_bytes());
    keyed.push(16);
    keyed.extend(b"source_timestamp");
    keyed.extend(1_700_000_000_123_456_789i64.to_le_bytes());
    keyed.push(10);
    keyed.extend(b"source_gid");
    keyed.push(16);
    keyed.extend(gid);
    assert_eq!(keyed.len(), 77);
    assert_eq!(Attachment::from_bytes(&keyed), Some(a));
    assert_eq!(Attachment::from_bytes(&bytes[..32]), None);
    assert_eq!(Attachment::from_bytes(b"rqh0123456789abcdef0"), None, "the bridge's request header is not one");
}

/// zenoh-plugin-ros2dds's `ke_liveliness_pub` (liveliness_mgt.rs, 1.10):
/// `@/${zenoh_id:*}/@ros2_lv/MP/${ke:*}/${typ:*}/${qos_ke:*}`, `§` for `/` in ke and typ, and
/// its `key_expr_to_qos`: `[K]:<rel>:<dur>:<hist>,<depth>[:<user data>]`, DDS's numbers.
fn parse_bridge_announcement(token: &str) -> Option<(String, String, String, [i32; 4])> {
    let parts: Vec<&str> = token.split('/').collect();
    let [at, zid, lv, kind, ke, typ, qos] = parts[..] else { return None };
    if at != "@" || lv != "@ros2_lv" || !["MP", "MS"].contains(&kind) || zid.is_empty() {
        return None;
    }
    let q: Vec<&str> = qos.split(':').collect();
    if q.len() < 4 || !q[0].is_empty() {
        return None;
    }
    let (hist, depth) = q[3].split_once(',')?;
    let numbers = [q[1].parse().ok()?, q[2].parse().ok()?, hist.parse().ok()?, depth.parse().ok()?];
    Some((kind.into(), ke.replace('§', "/"), typ.replace('§', "/"), numbers))
}

#[test]
fn bridge_keys_and_announcements_are_what_zenoh_bridge_ros2dds_parses() {
    let topic = name("/polymap/leju/map_updates");
    let hash = message_hash::<MapUpdate>();
    let e = Endpoint { name: &topic, type_name: "polymap_msgs/msg/MapUpdate", type_hash: &hash };
    assert_eq!(graph::data_key(Mode::Bridge, 0, &e), "polymap/leju/map_updates", "the bridge maps /a/b to a/b");
    let token =
        graph::bridge_token("1a2b3c", EntityKind::Publisher, &e, Some(&Qos::every_sample().bridge_key(Some(&hash))));
    let (kind, key, ty, [rel, dur, hist, _]) = parse_bridge_announcement(&token).expect(&token);
    assert_eq!(
        (kind.as_str(), key.as_str(), ty.as_str()),
        ("MP", "polymap/leju/map_updates", "polymap_msgs/msg/MapUpdate")
    );
    assert_eq!((rel, dur, hist), (1, 0, 1), "reliable, volatile, keep all (DDS's numbers)");
    assert!(token.ends_with(&format!(":typehash={hash};")), "the type hash as ROS 2 puts it in USER_DATA: {token}");
    let latched = graph::bridge_token("1a2b3c", EntityKind::Subscription, &e, Some(&Qos::latched(3).bridge_key(None)));
    assert_eq!(parse_bridge_announcement(&latched).unwrap().3, [1, 1, 0, 3]);
    let service = graph::bridge_token("1a2b3c", EntityKind::ServiceServer, &e, None);
    assert_eq!(service, "@/1a2b3c/@ros2_lv/SS/polymap§leju§map_updates/polymap_msgs§msg§MapUpdate");
}

#[test]
fn ros_names_are_checked() {
    assert_eq!(name("/polymap/leju").join("map_updates").unwrap().as_str(), "/polymap/leju/map_updates");
    assert_eq!(RosName::root().join("odometry").unwrap().as_str(), "/odometry");
    for bad in ["odometry", "/", "/a//b", "/a/", "/1a", "/a b", "/a/*"] {
        assert!(RosName::parse(bad).is_err(), "{bad:?} is not a name");
    }
}
