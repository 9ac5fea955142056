//! Registration: a frame's planes, matched to the map's, say how far the drift estimate is
//! off; a step of the odometry is taken into the drift instead of into the map.
//!
//! Every match gives a point-to-plane row at the overlap's centroid (a tread or the floor
//! pins the height, a riser or a wall the horizontal along its normal and, through its lever
//! arm, the yaw); a vertical plane's normal against the map's gives the yaw directly. Rows
//! that disagree with the rest or with what the filter already knows are dropped before the
//! solution is fused.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3, Vector4};

use super::drift::{self, Row};
use super::*;
use crate::types::Pose;

/// A row further than this many standard deviations from the solution, or from what the
/// filter predicts, is a wrong match.
const OUTLIER_SIGMAS: f64 = 4.0;

/// What a frame's registration found, for the update and the logs.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Registration {
    /// The drift estimate's error the frame measured: x, y, z (m), yaw (rad).
    pub error: [f64; 4],
    /// Directions measured (bits of `map::drift`: X, Y, Z, YAW).
    pub observed: u8,
    pub rows: usize,
    /// Rows dropped as wrong matches.
    pub outliers: usize,
}

/// The last frames' corrected poses, for telling a step of the odometry from motion.
#[derive(Clone, Debug, Default)]
pub(super) struct Track {
    last: Vec<(u64, Isometry3<f64>)>,
}

/// Two frames further apart than this leave nothing to predict the next from, s.
const MAX_PREDICT_GAP_S: f64 = 0.25;

impl Track {
    pub(super) fn push(&mut self, stamp_ns: u64, corrected: Isometry3<f64>) {
        if self.last.last().is_some_and(|(s, _)| *s >= stamp_ns) {
            self.last.clear();
        }
        self.last.push((stamp_ns, corrected));
        if self.last.len() > 2 {
            self.last.remove(0);
        }
    }

    /// Where the camera would be at `stamp_ns` moving on as it did between the last two
    /// frames: position and yaw (None without two recent frames).
    fn predict(&self, stamp_ns: u64) -> Option<(Vector3<f64>, f64)> {
        let [(s0, a), (s1, b)] = self.last.as_slice() else { return None };
        let (dt01, dt) = ((s1 - s0) as f64 * 1e-9, stamp_ns.checked_sub(*s1)? as f64 * 1e-9);
        if !(dt01 > 0.0 && dt01 <= MAX_PREDICT_GAP_S && dt > 0.0 && dt <= MAX_PREDICT_GAP_S) {
            return None;
        }
        let ratio = dt / dt01;
        let (pa, pb) = (a.translation.vector, b.translation.vector);
        let turn = wrap(heading(b) - heading(a));
        Some((pb + (pb - pa) * ratio, heading(b) + turn * ratio))
    }
}

/// The camera's heading about z: where its optical axis points, seen from above.
fn heading(t: &Isometry3<f64>) -> f64 {
    let axis = t.rotation * Vector3::z();
    axis.y.atan2(axis.x)
}

fn wrap(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

impl PolygonMap {
    /// A step of the odometry (the corrected pose off what the last frames predict by over
    /// `jump_min_m` or `jump_min_deg`) is taken into the drift when the frame's planes match
    /// the map better with it taken out. Returns whether it was.
    pub(super) fn take_odometry_step(&mut self, valid: &[&Polygon], pose: &Pose, intrinsics: &Intrinsics) -> bool {
        let Some((position, yaw)) = self.track.predict(pose.stamp_ns) else { return false };
        let now = self.corrected(&pose.transform);
        let (shift, turn) = (position - now.translation.vector, wrap(yaw - heading(&now)));
        if shift.norm() <= self.cfg.jump_min_m && turn.abs() <= self.cfg.jump_min_deg.to_radians() {
            return false;
        }
        // The map frame moved so that the camera lands where it was predicted: turned about it.
        let c = now.translation.vector;
        let step =
            Translation3::from(c + shift) * UnitQuaternion::from_euler_angles(0.0, 0.0, turn) * Translation3::from(-c);
        let before = self.drift;
        let matched_before = self.matched_area(valid, &pose.transform, intrinsics);
        self.drift.set_transform(&(self.drift.transform() * step.inverse()));
        if self.matched_area(valid, &pose.transform, intrinsics) <= matched_before {
            self.drift = before;
            return false;
        }
        // The prediction is only as good as the motion is smooth: the doubt of a minimal step.
        let (m, yaw_m) = (self.cfg.jump_min_m, self.cfg.jump_min_deg.to_radians() * drift::YAW_LEVER_M);
        self.drift.widen(Vector4::new(m * m, m * m, m * m, yaw_m * yaw_m));
        self.counters.odometry_steps += 1;
        tracing::info!(
            "map: odometry stepped {:.1} mm, {:.2} deg: taken into the drift",
            shift.norm() * 1e3,
            turn.to_degrees()
        );
        true
    }

    /// The overlap area of every match of the frame's polygons under the current drift.
    fn matched_area(&self, valid: &[&Polygon], t_world_camera: &Isometry3<f64>, intrinsics: &Intrinsics) -> f64 {
        let obs = self.observations(valid, t_world_camera, intrinsics);
        obs.iter().flat_map(|o| self.matches(o)).map(|m| m.area).sum()
    }

    /// The drift predicted, measured on the frame's planes matched to the map's, corrected.
    pub(super) fn register(
        &mut self,
        valid: &[&Polygon],
        t_world_camera: &Isometry3<f64>,
        intrinsics: &Intrinsics,
    ) -> Option<Registration> {
        self.drift.predict(&self.corrected(t_world_camera).translation.vector);
        let obs = self.observations(valid, t_world_camera, intrinsics);
        let mut rows = self.rows(&obs);
        let total = rows.len();
        if total == 0 {
            self.drift.observed = 0;
            return None;
        }
        // Rows far off what the filter predicts, then off what the rest say, are wrong matches.
        let prior = Matrix4::from(self.drift.cov);
        let floor = self.cfg.drift_sigma_m;
        // A step of the odometry too small to be taken in as one is still within 4 sigma.
        let step = (self.cfg.jump_min_m / OUTLIER_SIGMAS).powi(2);
        rows.retain(|r| r.y * r.y <= OUTLIER_SIGMAS.powi(2) * (r.h.dot(&(prior * r.h)) + r.var + floor).max(step));
        let mut solution = drift::solve(&rows);
        for _ in 0..2 {
            let before = rows.len();
            rows.retain(|r| r.residual(&solution.error).powi(2) <= OUTLIER_SIGMAS.powi(2) * (r.var + floor));
            if rows.len() == before {
                break;
            }
            solution = drift::solve(&rows);
        }
        self.drift.correct(&solution);
        let e = solution.error;
        let r = Registration {
            error: [e.x, e.y, e.z, e.w / drift::YAW_LEVER_M],
            observed: self.drift.observed,
            rows: rows.len(),
            outliers: total - rows.len(),
        };
        self.counters.registration_outliers += r.outliers as u64;
        tracing::debug!("map: registration {r:?} -> drift {:?}", self.drift);
        Some(r)
    }

    /// The registration rows of every match of `obs` (only heights when the horizontal drift
    /// is not estimated).
    fn rows(&self, obs: &[Observation]) -> Vec<Row> {
        let sin_vertical = (90.0 - self.cfg.vertical_min_tilt_deg).to_radians().sin();
        let mut rows = Vec::new();
        for o in obs {
            for m in self.matches(o) {
                let e = &self.entries[&m.id];
                let n = e.frame.normal;
                let var = self.offset_variance(&o.uncertainty, &m.at) + self.offset_variance(&e.uncertainty, &m.at);
                if !self.drift.noise.horizontal {
                    if self.label_table.labelled(m.id).0.is_horizontal() {
                        rows.push(Row { h: Vector4::new(0.0, 0.0, n.z, 0.0), y: -m.dz, var });
                    }
                    continue;
                }
                rows.push(Row::point_to_plane(&m.at, &n, m.dz, var));
                if n.z.abs() <= sin_vertical {
                    let mut seen = o.plane.normal;
                    if seen.dot(&e.plane.normal) < 0.0 {
                        seen = -seen;
                    }
                    let (a, b) = (seen.xy(), e.plane.normal.xy());
                    let angle = a.perp(&b).atan2(a.dot(&b));
                    let var = tilt_variance(&o.uncertainty, self.cfg.drift_sigma_m)
                        + tilt_variance(&e.uncertainty, self.cfg.drift_sigma_m);
                    rows.push(Row::heading(angle, var));
                }
            }
        }
        rows
    }

    /// The variance of a plane's position along its normal at `at`, m^2 (unknown: the least
    /// variance a frame's measurement is given).
    fn offset_variance(&self, u: &PlaneUncertainty, at: &Vector3<f64>) -> f64 {
        if !u.is_known() {
            return self.cfg.drift_sigma_m;
        }
        let v = u.expressed_at((*at).into(), u.axes).cov[2][2];
        if v.is_finite() { v.max(MIN_ROW_VARIANCE_M2) } else { self.cfg.drift_sigma_m }
    }
}

/// No row is trusted to better than 0.1 mm.
const MIN_ROW_VARIANCE_M2: f64 = 1e-8;

/// The variance of a plane's normal direction, rad^2 (unknown: as a shift's least variance
/// would be at a metre).
fn tilt_variance(u: &PlaneUncertainty, unknown: f64) -> f64 {
    if u.is_known() { u.tilt_sigma_rad().powi(2).max(MIN_ROW_VARIANCE_M2) } else { unknown }
}
