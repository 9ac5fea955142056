//! The `[map]` section: merging, the drift filter, clearing, snapshots.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::{Invalid, check_range};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MapConfig {
    /// Largest height difference over the overlap for two polygons to merge (the drift tolerance), m.
    pub merge_height_tolerance_m: f64,
    /// Largest angle between normals for two polygons to merge, degrees.
    pub merge_normal_tolerance_deg: f64,
    /// Smallest overlap, as a fraction of the smaller footprint, for two polygons to match.
    pub merge_min_overlap: f64,
    /// Apply the drift Kalman filter.
    pub drift_filter: bool,
    /// Estimate the drift in x, y and yaw as well as in z (off: the paper's vertical filter).
    pub drift_horizontal: bool,
    /// Process noise added to the vertical drift's variance each frame, m^2.
    pub drift_sigma_p: f64,
    /// Process noise added to each horizontal direction's variance each frame, m^2.
    pub drift_sigma_p_xy: f64,
    /// Process noise added to the yaw drift's variance each frame, rad^2.
    pub drift_sigma_p_yaw: f64,
    /// Least variance of one frame's measurement of a shift, m^2.
    pub drift_sigma_m: f64,
    /// Least variance of one frame's measurement of the yaw, rad^2.
    pub drift_sigma_m_yaw: f64,
    /// A corrected pose this far off where the last frames predict it is a step of the
    /// odometry (a loop closure), taken into the drift when the planes agree, m and degrees.
    pub jump_min_m: f64,
    pub jump_min_deg: f64,
    /// Planes within this angle of horizontal are horizontal (tread, floor, landing), degrees.
    pub horizontal_max_tilt_deg: f64,
    /// Planes tilted at least this much are vertical (riser, wall); in between is slope, degrees.
    pub vertical_min_tilt_deg: f64,
    /// Most vertices a map polygon's outline and holes keep together after a merge.
    pub max_vertices: usize,
    /// How far the inset outline (safe footholds) lies inside the polygon, m.
    pub foot_margin_m: f64,
    /// Frames in a row that must contradict a map polygon before it is removed.
    pub clear_after_frames: u32,
    /// Depth disagreement that counts as seeing through or something else in place, m.
    pub clear_tolerance_m: f64,
    /// Where the map is saved (atomically); empty = never saved.
    pub snapshot_path: PathBuf,
    /// Seconds between snapshots while running (one more is written at shutdown).
    pub snapshot_period_s: f64,
    /// Load `snapshot_path` at start when it exists.
    pub load_at_start: bool,
}

impl Default for MapConfig {
    fn default() -> Self {
        MapConfig {
            merge_height_tolerance_m: 0.05,
            merge_normal_tolerance_deg: 10.0,
            merge_min_overlap: 0.1,
            drift_filter: true,
            drift_horizontal: true,
            drift_sigma_p: 4e-6,
            drift_sigma_p_xy: 4e-6,
            drift_sigma_p_yaw: 7.6e-7,
            drift_sigma_m: 1e-6,
            drift_sigma_m_yaw: 3e-7,
            jump_min_m: 0.05,
            jump_min_deg: 1.5,
            horizontal_max_tilt_deg: 25.0,
            vertical_min_tilt_deg: 65.0,
            max_vertices: 64,
            foot_margin_m: 0.05,
            clear_after_frames: 3,
            clear_tolerance_m: 0.04,
            snapshot_path: PathBuf::new(),
            snapshot_period_s: 5.0,
            load_at_start: false,
        }
    }
}

impl MapConfig {
    pub(super) fn validate(&self) -> Result<(), Invalid> {
        let m = self;
        check_range("map.merge_height_tolerance_m", m.merge_height_tolerance_m, 1e-4, 1.0)?;
        check_range("map.merge_normal_tolerance_deg", m.merge_normal_tolerance_deg, 0.0, 90.0)?;
        check_range("map.merge_min_overlap", m.merge_min_overlap, 0.0, 1.0)?;
        check_range("map.drift_sigma_p", m.drift_sigma_p, 1e-12, 1.0)?;
        check_range("map.drift_sigma_m", m.drift_sigma_m, 1e-12, 1.0)?;
        check_range("map.drift_sigma_p_xy", m.drift_sigma_p_xy, 1e-12, 1.0)?;
        check_range("map.drift_sigma_p_yaw", m.drift_sigma_p_yaw, 1e-12, 1.0)?;
        check_range("map.drift_sigma_m_yaw", m.drift_sigma_m_yaw, 1e-12, 1.0)?;
        check_range("map.jump_min_m", m.jump_min_m, 1e-3, 1.0)?;
        check_range("map.jump_min_deg", m.jump_min_deg, 0.01, 45.0)?;
        check_range("map.horizontal_max_tilt_deg", m.horizontal_max_tilt_deg, 0.0, 90.0)?;
        check_range("map.vertical_min_tilt_deg", m.vertical_min_tilt_deg, 0.0, 90.0)?;
        check_range("map.max_vertices", m.max_vertices as f64, 8.0, 4096.0)?;
        check_range("map.foot_margin_m", m.foot_margin_m, 0.0, 1.0)?;
        check_range("map.clear_after_frames", m.clear_after_frames as f64, 1.0, 1000.0)?;
        check_range("map.clear_tolerance_m", m.clear_tolerance_m, 1e-3, 1.0)?;
        check_range("map.snapshot_period_s", m.snapshot_period_s, 0.1, 86_400.0)?;
        if m.horizontal_max_tilt_deg >= m.vertical_min_tilt_deg {
            return Err((
                "map.horizontal_max_tilt_deg".into(),
                format!(
                    "{} must be below vertical_min_tilt_deg = {}",
                    m.horizontal_max_tilt_deg, m.vertical_min_tilt_deg
                ),
            ));
        }
        Ok(())
    }
}
