//! `[ros1.drop_in]`: what `/polygon_new_markers` carries and in which frame
//! (`interface::drop_in` builds it).

use serde::{Deserialize, Serialize};

use super::{Invalid, check_frame_id, check_range};

/// `[ros1.drop_in]`: the frame and the selection of `/polygon_new_markers`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DropInConfig {
    /// The markers' frame: the robot's odometry frame, z = 0 at the soles, x forward.
    pub frame: String,
    /// Where the map's origin (VINS's: the IMU where it started) lies in `frame`, m. On a
    /// Kuavo: the IMU's offset from the point between the soles at start, z its height.
    pub map_origin_xyz: [f64; 3],
    /// The map's x axis turned by this about z in `frame`, degrees (0 when VINS's world
    /// starts facing where the robot's odometry does).
    pub map_origin_yaw_deg: f64,
    /// Send the floor too (the planner takes a floor marker first as its first step).
    pub floor: bool,
    /// Polygons tilted more than this are not sent, degrees (the authors' node: 25).
    pub max_tilt_deg: f64,
}

impl Default for DropInConfig {
    fn default() -> Self {
        DropInConfig {
            frame: "odom".into(),
            map_origin_xyz: [0.0; 3],
            map_origin_yaw_deg: 0.0,
            floor: false,
            max_tilt_deg: 25.0,
        }
    }
}

impl DropInConfig {
    pub fn validate(&self) -> Result<(), Invalid> {
        check_frame_id("ros1.drop_in.frame", &self.frame)?;
        for (axis, v) in ["x", "y", "z"].into_iter().zip(self.map_origin_xyz) {
            let key = "ros1.drop_in.map_origin_xyz";
            check_range(key, v, -1000.0, 1000.0).map_err(|(key, why)| (key, format!("{axis}: {why}")))?;
        }
        check_range("ros1.drop_in.map_origin_yaw_deg", self.map_origin_yaw_deg, -360.0, 360.0)?;
        check_range("ros1.drop_in.max_tilt_deg", self.max_tilt_deg, 0.0, 45.0)
    }

    /// A map point in `frame`.
    pub fn to_frame(&self, [x, y, z]: [f64; 3]) -> [f64; 3] {
        let (s, c) = self.map_origin_yaw_deg.to_radians().sin_cos();
        let [ox, oy, oz] = self.map_origin_xyz;
        [ox + c * x - s * y, oy + s * x + c * y, oz + z]
    }
}
