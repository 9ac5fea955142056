//! polymap's ROS 2 interface, typed once: every topic and service it offers or takes, with
//! its name, message type and QoS ([`Interface`]), and the conversions between polymap's own
//! types and those messages ([`convert`]). The runtime, the mocks, the tests and the examples
//! all take names from here.

pub mod convert;
pub mod follower;
pub mod terrain;

use crate::config::{Config, OdometryType};
use crate::ros2::msg::{
    CameraInfo, FramePolygons, GetFoothold, GetMap, Image, Imu, Map, MapUpdate, MarkerArray, Odometry, PlanarTerrain,
    PoseStamped, Status, TfMessage,
};
use crate::ros2::{Qos, RosName, Service, Topic};

/// The IR stream of infra1 or infra2, as realsense-ros names it.
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
}

impl Interface {
    pub fn new(config: &Config) -> Interface {
        let ns = &config.ros2.namespace;
        let own = |name: &str| ns.join(name).expect("polymap's topic names are valid ROS names");
        let camera = &config.sources.d435i.namespace;
        let cam = |name: &str| camera.join(name).expect("realsense-ros's topic names are valid ROS names");
        let odometry = config.ros2.odometry.clone();
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
            tf: Topic::new(config.ros2.tf_topic.clone(), Qos::reliable(100)),
            // Its consumers subscribe reliable, keep last 1; transient local serves them and
            // a late one at once.
            planar_terrain: Topic::new(config.planar_terrain.topic.clone(), Qos::latched(1)),
            status: Topic::new(own("status"), Qos::reliable(10)),
            get_map: Service::new(own("get_map")),
            get_foothold: Service::new(own("get_foothold")),
            odometry: match config.ros2.odometry_type {
                OdometryType::Odometry => OdometryTopic::Odometry(Topic::new(odometry, Qos::reliable(100))),
                OdometryType::PoseStamped => OdometryTopic::PoseStamped(Topic::new(odometry, Qos::reliable(100))),
            },
            imu_propagate: config.ros2.imu_propagate.clone().map(|name| Topic::new(name, Qos::reliable(400))),
            infra: [infra(1), infra(2)],
            imu: Topic::new(cam("imu"), Qos::reliable(400)),
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
