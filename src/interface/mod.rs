//! polymap's ROS 2 interface, typed once: every topic and service it offers or takes, with
//! its name, message type and QoS ([`Interface`]), and the conversions between polymap's own
//! types and those messages ([`convert`]). The runtime, the mocks, the tests and the examples
//! all take names from here.

pub mod convert;

use crate::config::{Config, OdometryType};
use crate::ros2::msg::{
    CameraInfo, FramePolygons, GetFoothold, GetMap, Image, Imu, MapUpdate, MarkerArray, Odometry, PoseStamped, Status,
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
    /// `<namespace>/map_updates`: what each frame changed in the map; none may be lost.
    pub map_updates: Topic<MapUpdate>,
    /// `<namespace>/markers`: the map's outlines for RViz.
    pub markers: Topic<MarkerArray>,
    /// `<namespace>/status`: health, once a second.
    pub status: Topic<Status>,
    /// `<namespace>/get_map`: the whole map.
    pub get_map: Service<GetMap>,
    /// `<namespace>/get_foothold`: the convex piece under a point.
    pub get_foothold: Service<GetFoothold>,
    /// VINS's odometry in (`/odometry` by default, as VINS-Fusion's ROS 2 port publishes it).
    pub odometry: OdometryTopic,
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
            markers: Topic::new(own("markers"), Qos::reliable(10)),
            status: Topic::new(own("status"), Qos::reliable(10)),
            get_map: Service::new(own("get_map")),
            get_foothold: Service::new(own("get_foothold")),
            odometry: match config.ros2.odometry_type {
                OdometryType::Odometry => OdometryTopic::Odometry(Topic::new(odometry, Qos::reliable(100))),
                OdometryType::PoseStamped => OdometryTopic::PoseStamped(Topic::new(odometry, Qos::reliable(100))),
            },
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
