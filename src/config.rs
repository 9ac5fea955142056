//! TOML configuration and its validation.
//!
//! Every field, its unit and its default are documented in `config/default.toml`;
//! the defaults in code below are the same values (a test keeps the two equal).
//! Unknown keys are rejected, and a bad value stops start-up with the file, the
//! dotted key and the reason.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

pub use crate::ros2::{Distro, Encoding, RosName};
mod drop_in;
mod map;
pub use drop_in::DropInConfig;
pub use map::MapConfig;

/// A configuration problem: which file, which key, why.
#[derive(Debug, thiserror::Error)]
#[error("{}: {key}: {reason}", file.display())]
pub struct ConfigError {
    pub file: PathBuf,
    /// Dotted path of the offending key, e.g. `pipeline.diffusion_kappa_m`.
    pub key: String,
    pub reason: String,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    pub sources: SourcesConfig,
    pub pipeline: PipelineConfig,
    pub map: MapConfig,
    pub poses: PosesConfig,
    pub zenoh: ZenohConfig,
    pub ros2: Ros2Config,
    pub ros1: Ros1Config,
    pub planar_terrain: PlanarTerrainConfig,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SourcesConfig {
    pub depth: DepthSourceConfig,
    pub d435i: D435iConfig,
    pub extrinsics: ExtrinsicsConfig,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DepthSourceKind {
    /// Replays a sequence's depth at its frame rate, stamped on the live clock.
    Mock,
    /// Reads a sequence with its own stamps and poses (offline work).
    Sequence,
    /// The L515 through librealsense (needs the `realsense` feature).
    Realsense,
    /// A librealsense `.bag` recording (`bag` key), played once through the same driver.
    Bag,
    /// A ROS image topic and its camera_info, where realsense-ros (or anything) owns the
    /// camera: over ROS 2, and over ROS 1 when `[ros1]` is enabled.
    Ros,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DepthSourceConfig {
    pub kind: DepthSourceKind,
    /// Sequence directory for `mock` and `sequence`; relative paths are relative to the working directory.
    pub sequence: PathBuf,
    /// L515 serial number; empty = the only L515 present.
    pub serial: String,
    /// Recording for `kind = "bag"`.
    pub bag: PathBuf,
    /// Depth profile, pixels and frames per second.
    pub width: u32,
    pub height: u32,
    pub fps: u32,
    /// L515 options; unset = the camera's own value.
    pub options: L515Options,
    /// `kind = "ros"`: the depth image topic (sensor_msgs/Image, 16UC1, mono16 or 32FC1) and
    /// its camera_info, as realsense-ros (ROS 1) names the L515's.
    pub image_topic: RosName,
    pub camera_info_topic: RosName,
    /// Metres per unit of a 16-bit image; 0 = REP 118's millimetres. The L515's own unit
    /// (0.00025) keeps its full resolution.
    pub image_unit_m: f64,
}

/// The options polymap sets, each named as librealsense names it (`rs2_option_to_string`,
/// lower case with underscores), which is also realsense-ros's parameter name
/// (`depth_module.<name>`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum CamOption {
    /// The L515's visual preset. First in this order: setting a preset resets the others.
    VisualPreset,
    LaserPower,
    ConfidenceThreshold,
    PreProcessingSharpening,
    /// The L515's "Digital Gain" (RS2_OPTION_DIGITAL_GAIN): 0 auto, 1 high, 2 low.
    DigitalGain,
    /// The L515's "Receiver Gain": librealsense's name for the avalanche photodiode's gain
    /// (RS2_OPTION_AVALANCHE_PHOTO_DIODE), not the digital gain.
    ReceiverGain,
    MinDistance,
    EmitterEnabled,
    GlobalTimeEnabled,
}

impl CamOption {
    pub fn name(self) -> &'static str {
        match self {
            CamOption::VisualPreset => "visual_preset",
            CamOption::LaserPower => "laser_power",
            CamOption::ConfidenceThreshold => "confidence_threshold",
            CamOption::PreProcessingSharpening => "pre_processing_sharpening",
            CamOption::DigitalGain => "digital_gain",
            CamOption::ReceiverGain => "receiver_gain",
            CamOption::MinDistance => "min_distance",
            CamOption::EmitterEnabled => "emitter_enabled",
            CamOption::GlobalTimeEnabled => "global_time_enabled",
        }
    }

    /// The L515 options a user may set in `[sources.depth.options]`, in the order they are applied.
    pub const L515: [CamOption; 7] = [
        CamOption::VisualPreset,
        CamOption::LaserPower,
        CamOption::ConfidenceThreshold,
        CamOption::PreProcessingSharpening,
        CamOption::DigitalGain,
        CamOption::ReceiverGain,
        CamOption::MinDistance,
    ];

    /// An L515 option by its librealsense / realsense-ros name.
    pub fn l515_by_name(name: &str) -> Option<CamOption> {
        CamOption::L515.into_iter().find(|o| o.name() == name)
    }

    /// The values an L515 accepts (librealsense 2.54's L500 options; the camera reports its
    /// own range too, and refuses what is outside it), and what they mean.
    pub fn l515_range(self) -> (f32, f32, &'static str) {
        match self {
            CamOption::VisualPreset => {
                (0.0, 5.0, "0 custom, 1 default, 2 no ambient light, 3 low ambient light, 4 max range, 5 short range")
            }
            CamOption::LaserPower => (0.0, 100.0, "%"),
            CamOption::ConfidenceThreshold => (0.0, 3.0, ""),
            CamOption::PreProcessingSharpening => (0.0, 5.0, ""),
            CamOption::DigitalGain => (0.0, 2.0, "0 auto, 1 high, 2 low"),
            CamOption::ReceiverGain => (9.0, 18.0, "the APD gain"),
            CamOption::MinDistance => (0.0, 2000.0, "mm"),
            CamOption::EmitterEnabled | CamOption::GlobalTimeEnabled => (0.0, 1.0, "0 off, 1 on"),
        }
    }
}

/// The L515 options to set; the others keep the camera's own values. Keys are librealsense's
/// option names (`laser_power`) or realsense-ros's parameter names (`depth_module.laser_power`,
/// which TOML reads as a `depth_module` table), so values can be pasted from a realsense-ros
/// launch file. Applied in [`CamOption`]'s order: the visual preset first, since it resets
/// the others.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct L515Options(pub BTreeMap<CamOption, f32>);

impl L515Options {
    /// The options that are set, in the order they are applied.
    pub fn as_list(&self) -> Vec<(CamOption, f32)> {
        self.0.iter().map(|(&o, &v)| (o, v)).collect()
    }

    fn validate(&self) -> Result<(), Invalid> {
        for (&option, &v) in &self.0 {
            let key = format!("sources.depth.options.{}", option.name());
            let (lo, hi, meaning) = option.l515_range();
            if option == CamOption::ReceiverGain && v.is_finite() && v < lo {
                return Err((
                    key,
                    format!(
                        "{v}: librealsense's \"Receiver Gain\" is the L515's APD gain ({lo}..{hi}); \
                         for the digital gain (0 auto, 1 high, 2 low), which polymap once called receiver_gain, \
                         set digital_gain = {v}"
                    ),
                ));
            }
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                let meaning = if meaning.is_empty() { String::new() } else { format!(" ({meaning})") };
                return Err((key, format!("{v} must be within [{lo}, {hi}]{meaning}")));
            }
        }
        Ok(())
    }
}

impl Serialize for L515Options {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_map(self.0.iter().map(|(o, v)| (o.name(), v)))
    }
}

impl<'de> Deserialize<'de> for L515Options {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Options;
        impl<'de> serde::de::Visitor<'de> for Options {
            type Value = L515Options;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a table of L515 options, e.g. laser_power = 100")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<L515Options, A::Error> {
                use serde::de::Error;
                let mut out = BTreeMap::new();
                let mut set = |option: CamOption, value: f32, key: &str| match out.insert(option, value) {
                    None => Ok(()),
                    Some(_) => Err(A::Error::custom(format!("{} is set twice (again as {key})", option.name()))),
                };
                while let Some(key) = map.next_key::<String>()? {
                    if key == "depth_module" {
                        for (option, value) in map.next_value::<L515Options>()?.0 {
                            set(option, value, &format!("depth_module.{}", option.name()))?;
                        }
                        continue;
                    }
                    let name = key.strip_prefix("depth_module.").unwrap_or(&key);
                    let option = CamOption::l515_by_name(name).ok_or_else(|| {
                        let known: Vec<_> = CamOption::L515.iter().map(|o| o.name()).collect();
                        A::Error::custom(format!("unknown L515 option {key:?}; known: {}", known.join(", ")))
                    })?;
                    set(option, map.next_value()?, &key)?;
                }
                Ok(L515Options(out))
            }
        }
        d.deserialize_map(Options)
    }
}

impl Default for DepthSourceConfig {
    fn default() -> Self {
        DepthSourceConfig {
            kind: DepthSourceKind::Mock,
            sequence: PathBuf::from("mock_frames/straight_320"),
            serial: String::new(),
            bag: PathBuf::new(),
            width: 320,
            height: 240,
            fps: 30,
            options: L515Options::default(),
            image_topic: RosName::parse("/l515/depth/image_rect_raw").expect("a valid name"),
            camera_info_topic: RosName::parse("/l515/depth/camera_info").expect("a valid name"),
            image_unit_m: 0.0,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum D435iKind {
    /// No IR/IMU streaming (VINS gets its images elsewhere).
    None,
    /// Synthetic IR images and IMU consistent with the mock camera's trajectory.
    Mock,
    /// The D435i through librealsense, IR emitter forced off.
    Realsense,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct D435iConfig {
    pub kind: D435iKind,
    /// D435i serial number; empty = the only D435i present.
    pub serial: String,
    /// Infrared (infra1 + infra2, Y8) profile.
    pub ir_width: u32,
    pub ir_height: u32,
    pub ir_fps: u32,
    /// IMU rates, Hz (D435i: gyro 200 or 400, accel 63 or 250).
    pub gyro_hz: u32,
    pub accel_hz: u32,
    /// Variances on the diagonal of the published Imu's covariances, (rad/s)^2 and (m/s^2)^2:
    /// realsense-ros's `angular_velocity_cov` and `linear_accel_cov`, with its defaults.
    pub angular_velocity_cov: f64,
    pub linear_accel_cov: f64,
    /// ROS 2 namespace of the IR images, camera infos and IMU, as realsense-ros names them
    /// (`/camera/camera/infra1/image_rect_raw`, `/camera/camera/imu`).
    pub namespace: RosName,
}

impl Default for D435iConfig {
    fn default() -> Self {
        D435iConfig {
            kind: D435iKind::None,
            serial: String::new(),
            ir_width: 640,
            ir_height: 480,
            ir_fps: 30,
            gyro_hz: 200,
            accel_hz: 250,
            angular_velocity_cov: 0.01,
            linear_accel_cov: 0.01,
            namespace: RosName::parse("/camera/camera").expect("a valid name"),
        }
    }
}

/// T_body_camera: the depth camera's optical frame in the odometry's body frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExtrinsicsConfig {
    /// Translation, m.
    pub xyz: [f64; 3],
    /// Rotation quaternion, x y z w (unit).
    pub quat_xyzw: [f64; 4],
}

impl Default for ExtrinsicsConfig {
    fn default() -> Self {
        ExtrinsicsConfig { xyz: [0.0; 3], quat_xyzw: [0.0, 0.0, 0.0, 1.0] }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// The GPU when one is there and faster, else the CPU twin.
    Auto,
    Gpu,
    Cpu,
}

impl std::fmt::Display for Backend {
    /// As the config and the command line name it (clap's lowercase names, serde's too).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use clap::ValueEnum;
        f.write_str(self.to_possible_value().expect("no variant is skipped").get_name())
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PipelineConfig {
    pub backend: Backend,
    /// Perona-Malik diffusion time, in the reference's units (its 60 explicit steps of 0.2: 12).
    pub diffusion_time: f64,
    /// Semi-implicit steps taking that time (stable at any length; 0 = no diffusion).
    pub diffusion_steps: u32,
    /// Edge-stopping constant of c = exp(-(|grad|/kappa)^2), m.
    pub diffusion_kappa_m: f64,
    /// Sobel kernel size for normals: 3, 5 or 7.
    pub normal_kernel: u32,
    /// Canny thresholds on the normal field's gradient, unitless (change of the unit normal per pixel).
    pub canny_low: f64,
    pub canny_high: f64,
    /// A depth step between neighbours larger than this fraction of the depth is an edge too.
    pub depth_edge_ratio: f64,
    /// Side of the square morphological closing of the edge map, pixels (odd).
    pub closing_kernel_px: u32,
    /// Regions smaller than this on their fitted plane are dropped, m^2.
    pub min_polygon_area_m2: f64,
    /// Douglas-Peucker tolerance when simplifying contours, pixels.
    pub simplify_tolerance_px: f64,
    /// RANSAC hypotheses per polygon.
    pub ransac_hypotheses: u32,
    /// Point-to-plane distance that counts as an inlier, m.
    pub ransac_inlier_distance_m: f64,
    /// A polygon is kept when at least this fraction of its pixels are inliers.
    pub ransac_min_inlier_ratio: f64,
    /// After the fits, regions take back border pixels on their plane up to this deep, pixels.
    pub region_grow_px: u32,
    /// A polygon whose two halves' planes bend by more than this (or their noise's 3 sigma
    /// if that is more) is two surfaces, held back; under it, published, the bend counted
    /// in its covariance. Degrees.
    pub max_halves_bend_deg: f64,
    /// After growth, each blob of pixels no region took (opened by a pixel, 2 px wide and
    /// more across, 30 pixels and more) becomes a region of its own: small faces the edges
    /// took whole. Off for stairs: it adds far floor patches of a few hundred pixels.
    pub seed_leftover_blobs: bool,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        PipelineConfig {
            backend: Backend::Auto,
            diffusion_time: 12.0,
            diffusion_steps: 4,
            diffusion_kappa_m: 0.0335,
            normal_kernel: 5,
            canny_low: 0.05,
            canny_high: 0.1,
            depth_edge_ratio: 0.03,
            closing_kernel_px: 7,
            min_polygon_area_m2: 0.01,
            simplify_tolerance_px: 1.5,
            ransac_hypotheses: 20,
            ransac_inlier_distance_m: 0.01,
            ransac_min_inlier_ratio: 0.9,
            region_grow_px: 4,
            max_halves_bend_deg: 8.0,
            seed_leftover_blobs: false,
        }
    }
}

/// How odometry poses are taken in.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PosesConfig {
    /// A frame between two poses further apart than this gets no pose and is skipped, s.
    pub max_gap_s: f64,
    /// How long an extracted frame waits for the pose after its stamp, from its stamp, s.
    pub max_wait_s: f64,
    /// Poses further than this from the odometry's origin are refused, m.
    pub max_radius_m: f64,
    /// Poses stamped further than this ahead of this machine's clock are refused, s.
    pub max_ahead_s: f64,
    /// A pose stamped before the newest after this long without poses is the odometry
    /// starting over (VINS restarted): the buffer starts again from it, s.
    pub restart_after_s: f64,
}

impl Default for PosesConfig {
    fn default() -> Self {
        PosesConfig { max_gap_s: 0.25, max_wait_s: 0.3, max_radius_m: 1e4, max_ahead_s: 0.5, restart_after_s: 1.0 }
    }
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ZenohConfig {
    /// Zenoh JSON5 configuration file; empty = `ZENOH_SESSION_CONFIG_URI` or `ZENOH_CONFIG`
    /// when set, else rmw_zenoh's session defaults (a peer of the rmw_zenohd router on this
    /// machine, loopback only, multicast off).
    pub config_file: PathBuf,
}

/// Which ROS 2 conventions polymap's topics and services follow on Zenoh.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WireMode {
    /// rmw_zenoh, ROS 2's Zenoh middleware.
    RmwZenoh,
    /// Beside a zenoh-bridge-ros2dds (ROS 2 nodes on DDS).
    Bridge,
}

/// What VINS's odometry topic carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OdometryType {
    /// nav_msgs/Odometry, as VINS-Fusion publishes it.
    Odometry,
    /// geometry_msgs/PoseStamped.
    PoseStamped,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ros2Config {
    pub mode: WireMode,
    /// rmw_zenoh's key format: jazzy (type hashes; also Kilted and Rolling) or humble (none).
    pub distro: Distro,
    /// ROS_DOMAIN_ID.
    pub domain_id: u32,
    /// polymap's node and its topics live here: `<namespace>/map_updates`, ...
    pub namespace: RosName,
    /// The node's name.
    pub node: String,
    /// VINS's odometry topic.
    pub odometry: RosName,
    pub odometry_type: OdometryType,
    /// VINS-Fusion's IMU-rate propagated odometry (nav_msgs/Odometry): the motion between
    /// the optimised poses, and a pose for a frame before the next optimised one comes;
    /// None: not used.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub imu_propagate: Option<RosName>,
    /// How polymap's topics are encoded: ROS 2 CDR, or JSON for looking at them with plain
    /// Zenoh tools.
    pub encoding: Encoding,
    /// polymap's frame (REP 105's `map`): VINS's frame with the drift taken out. Polygons,
    /// the map and the terrain are in it.
    pub map_frame: String,
    /// VINS's frame, the odometry's header frame (VINS-Fusion: `world`). /tf carries the
    /// drift as the transform from the map frame to it.
    pub odometry_frame: String,
    /// Where the map-to-odometry transform goes.
    pub tf_topic: RosName,
    /// The whole map (topic `map`) and the RViz markers of all of it go out at most this
    /// often, when the map changed, s.
    pub whole_map_period_s: f64,
}

impl Default for Ros2Config {
    fn default() -> Self {
        Ros2Config {
            mode: WireMode::RmwZenoh,
            distro: Distro::Jazzy,
            domain_id: 0,
            namespace: RosName::parse("/polymap/leju").expect("a valid name"),
            node: "polymap".into(),
            odometry: RosName::parse("/odometry").expect("a valid name"),
            odometry_type: OdometryType::Odometry,
            imu_propagate: Some(RosName::parse("/imu_propagate").expect("a valid name")),
            encoding: Encoding::Cdr,
            map_frame: "map".into(),
            odometry_frame: "world".into(),
            tf_topic: RosName::parse("/tf").expect("a valid name"),
            whole_map_period_s: 1.0,
        }
    }
}

/// ROS 1 (Noetic), beside ROS 2: the robot's own rosmaster, its VINS-Fusion and planners.
/// The master is the one `ROS_MASTER_URI` names; `ROS_HOSTNAME` or `ROS_IP` say where peers
/// reach polymap, as for roscpp nodes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ros1Config {
    pub enabled: bool,
    /// The node's name; polymap's own topics and services are under it: `/polymap/map`, ...
    pub node: RosName,
    /// VINS-Fusion's odometry, and its IMU-rate propagated odometry (None: not used).
    pub odometry: RosName,
    pub odometry_type: OdometryType,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub imu_propagate: Option<RosName>,
    /// Each frame's polygons as the paper authors' node publishes them (closed LINE_STRIP
    /// markers, visualization_msgs/MarkerArray), for nodes written for it; None: not sent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub polygon_markers: Option<RosName>,
    /// Their frame and what goes on them (`[ros1.drop_in]`).
    pub drop_in: DropInConfig,
    /// Where the D435i's IR images and IMU go, as realsense-ros (ROS 1) names them.
    pub camera_namespace: RosName,
    /// Where the transform from the map frame to VINS's goes (the frames are `[ros2]`'s:
    /// each message is built once for both layers).
    pub tf_topic: RosName,
}

impl Default for Ros1Config {
    fn default() -> Self {
        let name = |n: &str| RosName::parse(n).expect("a valid name");
        Ros1Config {
            enabled: false,
            node: name("/polymap"),
            odometry: name("/vins_estimator/odometry"),
            odometry_type: OdometryType::Odometry,
            imu_propagate: Some(name("/vins_estimator/imu_propagate")),
            polygon_markers: Some(name("/polygon_new_markers")),
            drop_in: Default::default(),
            camera_namespace: name("/camera"),
            tf_topic: name("/tf"),
        }
    }
}

impl Ros1Config {
    /// The node's fully qualified name.
    pub fn node_name(&self) -> String {
        self.node.to_string()
    }
}

/// The map as convex_plane_decomposition_msgs/PlanarTerrain, for legged planners that read it
/// (OCS2's perceptive locomotion, elevation_mapping_cupy's plane segmentation consumers).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlanarTerrainConfig {
    pub enabled: bool,
    /// Where those planners listen by default.
    pub topic: RosName,
    /// Sent at most this often, when the map changed, s.
    pub period_s: f64,
    /// The grid map: cell size and extent (x, y) around the robot, m.
    pub resolution_m: f64,
    pub length_x_m: f64,
    pub length_y_m: f64,
    /// Surfaces tilted more than this are not regions (nor in the elevation layer), degrees.
    pub max_tilt_deg: f64,
}

impl Default for PlanarTerrainConfig {
    fn default() -> Self {
        PlanarTerrainConfig {
            enabled: true,
            topic: RosName::parse("/convex_plane_decomposition_ros/planar_terrain").expect("a valid name"),
            period_s: 0.2,
            resolution_m: 0.04,
            length_x_m: 4.0,
            length_y_m: 4.0,
            max_tilt_deg: 30.0,
        }
    }
}

impl Ros2Config {
    /// The wire conventions this config asks for.
    pub fn mode(&self) -> crate::ros2::Mode {
        match self.mode {
            WireMode::RmwZenoh => crate::ros2::Mode::RmwZenoh(self.distro),
            WireMode::Bridge => crate::ros2::Mode::Bridge,
        }
    }

    /// polymap's node.
    pub fn node_options(&self) -> crate::ros2::NodeOptions {
        crate::ros2::NodeOptions {
            mode: self.mode(),
            domain: self.domain_id,
            namespace: self.namespace.clone(),
            name: self.node.clone(),
            encoding: self.encoding,
        }
    }
}

impl Config {
    /// Reads, parses and validates a config file.
    pub fn load(path: impl AsRef<Path>) -> Result<Config, ConfigError> {
        let path = path.as_ref();
        // A config is a few kilobytes; anything much larger (or not a file) is a mistake.
        let text = crate::files::read_text_capped(path, 1 << 20).map_err(|e| ConfigError {
            file: path.to_owned(),
            key: "(file)".into(),
            reason: e.to_string(),
        })?;
        Config::parse(&text, path)
    }

    /// Parses and validates TOML text; `file` only names it in errors.
    pub fn parse(text: &str, file: &Path) -> Result<Config, ConfigError> {
        let fail = |key: String, reason: String| ConfigError { file: file.to_owned(), key, reason };
        let de = toml::Deserializer::parse(text).map_err(|e| fail("(syntax)".into(), one_line(&e.to_string())))?;
        let config: Config = serde_path_to_error::deserialize(de).map_err(|e| {
            let key = e.path().to_string();
            fail(if key == "." { "(top level)".into() } else { key }, one_line(&e.into_inner().to_string()))
        })?;
        config.validate().map_err(|(key, reason)| fail(key, reason))?;
        Ok(config)
    }

    /// The first impossible value, as (dotted key, reason).
    pub fn validate(&self) -> Result<(), Invalid> {
        let d = &self.sources.depth;
        let needs_sequence = matches!(d.kind, DepthSourceKind::Mock | DepthSourceKind::Sequence);
        if needs_sequence && d.sequence.as_os_str().is_empty() {
            return Err((
                "sources.depth.sequence".into(),
                "a mock or sequence source needs a sequence directory".into(),
            ));
        }
        if d.kind == DepthSourceKind::Bag && d.bag.as_os_str().is_empty() {
            return Err(("sources.depth.bag".into(), "kind = \"bag\" needs the path of a .bag recording".into()));
        }
        d.options.validate()?;
        check_range("sources.depth.width", d.width as f64, 16.0, 4096.0)?;
        check_range("sources.depth.height", d.height as f64, 16.0, 4096.0)?;
        check_range("sources.depth.fps", d.fps as f64, 1.0, 1000.0)?;
        if d.image_unit_m != 0.0 {
            check_range("sources.depth.image_unit_m", d.image_unit_m, 1e-6, 1.0)?;
        }
        let i = &self.sources.d435i;
        check_range("sources.d435i.ir_width", i.ir_width as f64, 16.0, 4096.0)?;
        check_range("sources.d435i.ir_height", i.ir_height as f64, 16.0, 4096.0)?;
        check_range("sources.d435i.ir_fps", i.ir_fps as f64, 1.0, 1000.0)?;
        check_range("sources.d435i.gyro_hz", i.gyro_hz as f64, 1.0, 2000.0)?;
        check_range("sources.d435i.accel_hz", i.accel_hz as f64, 1.0, 2000.0)?;
        check_range("sources.d435i.angular_velocity_cov", i.angular_velocity_cov, 0.0, 1e3)?;
        check_range("sources.d435i.linear_accel_cov", i.linear_accel_cov, 0.0, 1e3)?;
        let e = &self.sources.extrinsics;
        if e.xyz.iter().any(|v| !(v.is_finite() && v.abs() <= 100.0)) {
            return Err(("sources.extrinsics.xyz".into(), format!("{:?} must be finite metres within 100 m", e.xyz)));
        }
        let qn = e.quat_xyzw.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !((qn - 1.0).abs() <= crate::sequence::QUATERNION_NORM_TOLERANCE) {
            return Err((
                "sources.extrinsics.quat_xyzw".into(),
                format!("norm {qn:.6}, a rotation quaternion must have norm 1"),
            ));
        }

        let p = &self.pipeline;
        check_range("pipeline.diffusion_time", p.diffusion_time, 0.0, 1000.0)?;
        check_range("pipeline.diffusion_steps", p.diffusion_steps as f64, 0.0, 100.0)?;
        check_range("pipeline.diffusion_kappa_m", p.diffusion_kappa_m, 1e-4, 10.0)?;
        if ![3, 5, 7].contains(&p.normal_kernel) {
            return Err(("pipeline.normal_kernel".into(), format!("{} must be 3, 5 or 7", p.normal_kernel)));
        }
        check_range("pipeline.canny_low", p.canny_low, 1e-4, 4.0)?;
        check_range("pipeline.canny_high", p.canny_high, 1e-4, 4.0)?;
        if p.canny_low > p.canny_high {
            return Err((
                "pipeline.canny_low".into(),
                format!("{} must not exceed canny_high = {}", p.canny_low, p.canny_high),
            ));
        }
        check_range("pipeline.depth_edge_ratio", p.depth_edge_ratio, 1e-4, 10.0)?;
        if p.closing_kernel_px.is_multiple_of(2) || p.closing_kernel_px > 63 {
            return Err((
                "pipeline.closing_kernel_px".into(),
                format!("{} must be odd and at most 63", p.closing_kernel_px),
            ));
        }
        check_range("pipeline.min_polygon_area_m2", p.min_polygon_area_m2, 1e-6, 100.0)?;
        check_range("pipeline.simplify_tolerance_px", p.simplify_tolerance_px, 0.01, 100.0)?;
        check_range("pipeline.ransac_hypotheses", p.ransac_hypotheses as f64, 1.0, 1024.0)?;
        check_range("pipeline.ransac_inlier_distance_m", p.ransac_inlier_distance_m, 1e-5, 1.0)?;
        check_range("pipeline.ransac_min_inlier_ratio", p.ransac_min_inlier_ratio, 0.0, 1.0)?;
        check_range("pipeline.region_grow_px", p.region_grow_px as f64, 0.0, 32.0)?;
        check_range("pipeline.max_halves_bend_deg", p.max_halves_bend_deg, 0.0, 45.0)?;

        self.map.validate()?;

        let q = &self.poses;
        check_range("poses.max_gap_s", q.max_gap_s, 0.001, 10.0)?;
        check_range("poses.max_wait_s", q.max_wait_s, 0.0, 10.0)?;
        check_range("poses.max_radius_m", q.max_radius_m, 1.0, crate::types::MAX_COORDINATE_M)?;
        check_range("poses.max_ahead_s", q.max_ahead_s, 0.0, 60.0)?;
        check_range("poses.restart_after_s", q.restart_after_s, 0.1, 3600.0)?;
        let r = &self.ros2;
        check_range("ros2.domain_id", r.domain_id as f64, 0.0, 232.0)?;
        let node_name_ok = r.node.chars().next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
            && r.node.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
        if !node_name_ok {
            return Err(("ros2.node".into(), format!("{:?} is not a ROS node name (letters, digits and '_')", r.node)));
        }
        check_frame_id("ros2.map_frame", &r.map_frame)?;
        check_frame_id("ros2.odometry_frame", &r.odometry_frame)?;
        if r.map_frame == r.odometry_frame {
            return Err((
                "ros2.map_frame".into(),
                format!("{:?} is the odometry's frame too: the drift needs two", r.map_frame),
            ));
        }
        if self.ros1.node.as_str() == "/" {
            return Err(("ros1.node".into(), "\"/\" is a namespace, not a node name (e.g. \"/polymap\")".into()));
        }
        self.ros1.drop_in.validate()?;
        check_range("ros2.whole_map_period_s", r.whole_map_period_s, 0.01, 3600.0)?;
        let t = &self.planar_terrain;
        check_range("planar_terrain.period_s", t.period_s, 0.01, 3600.0)?;
        check_range("planar_terrain.resolution_m", t.resolution_m, 0.005, 1.0)?;
        check_range("planar_terrain.length_x_m", t.length_x_m, t.resolution_m, 100.0)?;
        check_range("planar_terrain.length_y_m", t.length_y_m, t.resolution_m, 100.0)?;
        let cells = (t.length_x_m / t.resolution_m) * (t.length_y_m / t.resolution_m);
        if cells > MAX_TERRAIN_CELLS {
            return Err((
                "planar_terrain.resolution_m".into(),
                format!(
                    "{cells:.0} cells in the grid map; at most {MAX_TERRAIN_CELLS:.0} (a coarser resolution or a smaller extent)"
                ),
            ));
        }
        check_range("planar_terrain.max_tilt_deg", t.max_tilt_deg, 0.0, 89.0)?;
        Ok(())
    }
}

impl Config {
    /// What `validate` cannot see: that the files the config names are there and usable
    /// (`polymap config` checks it). The first problem, as (dotted key, reason).
    pub fn check_files(&self) -> Result<(), Invalid> {
        let z = &self.zenoh.config_file;
        if !z.as_os_str().is_empty() {
            crate::ros2::session::config(z).map_err(|e| ("zenoh.config_file".to_string(), e.to_string()))?;
        }
        let snapshot = &self.map.snapshot_path;
        if !snapshot.as_os_str().is_empty() {
            let why = |reason: String| ("map.snapshot_path".to_string(), format!("{}: {reason}", snapshot.display()));
            if snapshot.is_dir() {
                return Err(why("is a directory; the map is saved as a file".into()));
            }
            let dir = match snapshot.parent() {
                Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
                _ => PathBuf::from("."),
            };
            // The directory is made on the first save if missing; if it is there it must
            // take files (a probe file made and removed at once).
            if dir.exists() {
                let probe = dir.join(format!(".polymap-config-check.{}", std::process::id()));
                std::fs::write(&probe, b"").map_err(|e| why(format!("cannot write in {}: {e}", dir.display())))?;
                let _ = std::fs::remove_file(&probe);
            }
        }
        let d = &self.sources.depth;
        match d.kind {
            DepthSourceKind::Mock | DepthSourceKind::Sequence => {
                crate::sequence::Sequence::open(&d.sequence)
                    .map_err(|e| ("sources.depth.sequence".to_string(), e.to_string()))?;
            }
            DepthSourceKind::Bag if !d.bag.is_file() => {
                return Err(("sources.depth.bag".into(), format!("{}: no such file", d.bag.display())));
            }
            _ => {}
        }
        Ok(())
    }
}

/// The most cells a terrain grid map may have (20 x 20 m at 2 cm: 4 MB a layer).
const MAX_TERRAIN_CELLS: f64 = 1_000_000.0;

/// A config value that cannot be used: its dotted key and why.
pub type Invalid = (String, String);

fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// A tf2 frame id: letters, digits, `_-/.`, not empty, no leading `/`.
pub fn check_frame_id(key: &str, frame: &str) -> Result<(), Invalid> {
    let ok = !frame.is_empty()
        && !frame.starts_with('/')
        && frame.chars().all(|c| c.is_ascii_alphanumeric() || "_-/.".contains(c));
    let why = || format!("{frame:?} is not a tf2 frame id (letters, digits, '_-/.', no leading '/')");
    if ok { Ok(()) } else { Err((key.into(), why())) }
}

pub fn check_range(key: &str, v: f64, lo: f64, hi: f64) -> Result<(), Invalid> {
    let ok = v.is_finite() && (lo..=hi).contains(&v);
    if ok { Ok(()) } else { Err((key.into(), format!("{v} must be within [{lo}, {hi}]"))) }
}
