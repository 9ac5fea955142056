//! polymap's ROS interface, typed once: every topic and service it offers or takes, with
//! its name, message type and QoS ([`Interface`]; ROS 2's names, or ROS 1's), and the conversions between polymap's own
//! types and those messages ([`convert`]). The runtime, the mocks, the tests and the examples
//! all take names from here.

pub mod convert;
pub mod drop_in;
pub mod follower;
pub mod terrain;
pub mod wires;

use crate::config::{Config, OdometryType};
use crate::ros2::msg::{
    CameraInfo, FramePolygons, GetFoothold, GetMap, Image, Imu, Map, MapUpdate, MarkerArray, Odometry, PlanarTerrain,
    PoseStamped, Status, TfMessage,
};
use crate::ros2::{Qos, RosName, Service, Topic};

/// A camera stream: its images and their camera_info (the D435i's infra1 or infra2, the
/// L515's depth), as realsense-ros names them.
#[derive(Clone, Debug)]
pub struct InfraTopics {
    pub image: Topic<Image>,
    pub camera_info: Topic<CameraInfo>,
}

/// Where VINS's odometry comes in, as the type VINS sends.
#[derive(Clone, Debug)]
pub enum OdometryTopic {
    Odometry(Topic<Odometry>),
    PoseStamped(Topic<PoseStamped>),
}

/// Every topic and service of polymap, named from the config.
#[derive(Clone, Debug)]
pub struct Interface {
    /// `<namespace>/frame_polygons`: each frame's polygons.
    pub frame_polygons: Topic<FramePolygons>,
    /// `<namespace>/map_updates`: what each frame changed in the map, versioned; none may be
    /// lost (reliable, keep all: the publisher waits rather than drop one).
    pub map_updates: Topic<MapUpdate>,
    /// `<namespace>/map`: the whole map when it changed, at most every
    /// `ros2.whole_map_period_s`; transient local, so a late subscriber gets it at once.
    pub map: Topic<Map>,
    /// `<namespace>/markers`: the whole map's outlines for RViz, as `map` (transient local).
    pub markers: Topic<MarkerArray>,
    /// `/tf` (`ros2.tf_topic`): the drift, as the transform from the map frame to VINS's.
    pub tf: Topic<TfMessage>,
    /// `planar_terrain.topic`: the map as convex_plane_decomposition_msgs/PlanarTerrain.
    pub planar_terrain: Topic<PlanarTerrain>,
    /// `<namespace>/status`: health, once a second.
    pub status: Topic<Status>,
    /// `<namespace>/get_map`: the whole map.
    pub get_map: Service<GetMap>,
    /// `<namespace>/get_foothold`: the convex piece under a point.
    pub get_foothold: Service<GetFoothold>,
    /// VINS's odometry in (`/odometry` by default, as VINS-Fusion's ROS 2 port publishes it).
    pub odometry: OdometryTopic,
    /// VINS's IMU-rate propagated odometry in (`/imu_propagate`), when used.
    pub imu_propagate: Option<Topic<Odometry>>,
    /// The D435i's streams for VINS, under realsense-ros's names (`/camera/camera/...`).
    pub infra: [InfraTopics; 2],
    pub imu: Topic<Imu>,
    /// `sources.depth.kind = "ros"`: the depth image and its camera_info, on either layer.
    pub depth: InfraTopics,
    /// ROS 1: each frame's polygons as the paper authors' node sends them
    /// (`/polygon_new_markers`), when configured.
    pub polygon_markers: Option<Topic<MarkerArray>>,
}

/// The names that differ between the ROS 2 and ROS 1 interfaces.
struct Names<'a> {
    namespace: &'a RosName,
    camera: &'a RosName,
    odometry: &'a RosName,
    odometry_type: OdometryType,
    imu_propagate: Option<&'a RosName>,
    tf: &'a RosName,
    polygon_markers: Option<&'a RosName>,
}

impl Interface {
    /// ROS 2's names.
    pub fn new(config: &Config) -> Interface {
        let r = &config.ros2;
        Interface::named(
            config,
            Names {
                namespace: &r.namespace,
                camera: &config.sources.d435i.namespace,
                odometry: &r.odometry,
                odometry_type: r.odometry_type,
                imu_propagate: r.imu_propagate.as_ref(),
                tf: &r.tf_topic,
                polygon_markers: None,
            },
        )
    }

    /// ROS 1's names: polymap's own under its node, VINS-Fusion's and realsense-ros's as
    /// their ROS 1 versions name them.
    pub fn ros1(config: &Config) -> Interface {
        let r = &config.ros1;
        Interface::named(
            config,
            Names {
                namespace: &r.node,
                camera: &r.camera_namespace,
                odometry: &r.odometry,
                odometry_type: r.odometry_type,
                imu_propagate: r.imu_propagate.as_ref(),
                tf: &r.tf_topic,
                polygon_markers: r.polygon_markers.as_ref(),
            },
        )
    }

    fn named(config: &Config, names: Names) -> Interface {
        let own = |name: &str| names.namespace.join(name).expect("polymap's topic names are valid ROS names");
        let cam = |name: &str| names.camera.join(name).expect("realsense-ros's topic names are valid ROS names");
        let odometry = names.odometry.clone();
        let infra = |i: u8| InfraTopics {
            image: Topic::new(cam(&format!("infra{i}/image_rect_raw")), Qos::reliable(5)),
            camera_info: Topic::new(cam(&format!("infra{i}/camera_info")), Qos::reliable(5)),
        };
        Interface {
            frame_polygons: Topic::new(own("frame_polygons"), Qos::reliable(10)),
            map_updates: Topic::new(own("map_updates"), Qos::every_sample()),
            map: Topic::new(own("map"), Qos::latched(1)),
            markers: Topic::new(own("markers"), Qos::latched(1)),
            // tf2's listeners subscribe reliable, volatile, keep last 100.
            tf: Topic::new(names.tf.clone(), Qos::reliable(100)),
            // Its consumers subscribe reliable, keep last 1; transient local serves them and
            // a late one at once.
            planar_terrain: Topic::new(config.planar_terrain.topic.clone(), Qos::latched(1)),
            status: Topic::new(own("status"), Qos::reliable(10)),
            get_map: Service::new(own("get_map")),
            get_foothold: Service::new(own("get_foothold")),
            odometry: match names.odometry_type {
                OdometryType::Odometry => OdometryTopic::Odometry(Topic::new(odometry, Qos::reliable(100))),
                OdometryType::PoseStamped => OdometryTopic::PoseStamped(Topic::new(odometry, Qos::reliable(100))),
            },
            imu_propagate: names.imu_propagate.map(|name| Topic::new(name.clone(), Qos::reliable(400))),
            infra: [infra(1), infra(2)],
            imu: Topic::new(cam("imu"), Qos::reliable(400)),
            // The authors' markers live 0.5 s: only the newest frame's matter.
            polygon_markers: names.polygon_markers.map(|name| Topic::new(name.clone(), Qos::reliable(2))),
            depth: InfraTopics {
                image: Topic::new(config.sources.depth.image_topic.clone(), Qos::reliable(2)),
                camera_info: Topic::new(config.sources.depth.camera_info_topic.clone(), Qos::reliable(2)),
            },
        }
    }

    /// The odometry topic's name.
    pub fn odometry_name(&self) -> &RosName {
        match &self.odometry {
            OdometryTopic::Odometry(t) => &t.name,
            OdometryTopic::PoseStamped(t) => &t.name,
        }
    }
}
