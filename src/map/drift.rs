//! The odometry's drift in x, y, z and yaw, as a Kalman filter over what each frame's planes
//! say of it once matched to the map's.
//!
//! The drift D says where the odometry puts a point of the map: p_odometry = D p_map, D a
//! turn about z by `yaw` then a shift by (x, y, z). Roll and pitch stay with the odometry,
//! which sees gravity. Each frame's polygons are taken to the map by D⁻¹ before they are
//! merged. With only heights measured (`horizontal` off, or a frame that sees no wall) it is
//! the paper's scalar filter on z.
//!
//! The filter keeps the covariance of the map frame's error: a small turn and shift of the
//! map's coordinates, (dx, dy, dz, dyaw · YAW_LEVER_M), every component in metres, so one
//! eigen-decomposition tells which directions a frame measured.

use nalgebra::{Isometry3, Matrix4, SymmetricEigen, Translation3, UnitQuaternion, Vector3, Vector4};
use serde::{Deserialize, Serialize};

/// Yaw is carried as the arc it turns at this radius, m, so its variance is in m^2 like the
/// others' (about the reach of the L515's view).
pub const YAW_LEVER_M: f64 = 1.0;

/// A direction the frame pinned to better than this is observed, m.
const OBSERVED_SIGMA_M: f64 = 0.01;

/// The four directions of the drift, as bits of `Observed`.
pub const X: u8 = 1;
pub const Y: u8 = 2;
pub const Z: u8 = 4;
pub const YAW: u8 = 8;

/// How uncertain the drift becomes each frame and each frame's measurement is at best.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DriftNoise {
    /// Process noise per frame: vertical, horizontal (each of x and y), m^2; yaw, rad^2.
    pub p_z: f64,
    pub p_xy: f64,
    pub p_yaw: f64,
    /// Least variance of one frame's measurement: of a shift, m^2; of the yaw, rad^2.
    pub m: f64,
    pub m_yaw: f64,
    /// Estimate x, y and yaw as well as z.
    pub horizontal: bool,
}

impl From<&crate::config::MapConfig> for DriftNoise {
    fn from(c: &crate::config::MapConfig) -> DriftNoise {
        DriftNoise {
            p_z: c.drift_sigma_p,
            p_xy: c.drift_sigma_p_xy,
            p_yaw: c.drift_sigma_p_yaw,
            m: c.drift_sigma_m,
            m_yaw: c.drift_sigma_m_yaw,
            horizontal: c.drift_horizontal,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DriftFilter {
    /// The drift's shift, m, and turn about z, rad (see the module's header).
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub yaw: f64,
    /// Covariance of the map frame's error (dx, dy, dz, dyaw · YAW_LEVER_M), m^2.
    pub cov: [[f64; 4]; 4],
    pub noise: DriftNoise,
    /// The directions the last measurement observed (bits X, Y, Z, YAW).
    pub observed: u8,
}

/// One row of a frame's registration: the map frame's error e moves it by h·e, and it is
/// measured to be `y`, with variance `var` (m^2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Row {
    pub h: Vector4<f64>,
    pub y: f64,
    pub var: f64,
}

impl Row {
    /// A point `q` of the map (m) on a matched plane of normal `n`, the frame's plane lying
    /// `dz` beyond the map's there along `n`: the error must take it back by `dz`.
    pub fn point_to_plane(q: &Vector3<f64>, n: &Vector3<f64>, dz: f64, var: f64) -> Row {
        // A turn dyaw about z moves q by dyaw (ẑ × q) = dyaw (-q_y, q_x, 0).
        let turn = (n.y * q.x - n.x * q.y) / YAW_LEVER_M;
        Row { h: Vector4::new(n.x, n.y, n.z, turn), y: -dz, var }
    }

    /// A vertical plane whose normal the frame turns `angle` rad (about z, counter-clockwise)
    /// short of the map's, with variance `var` rad^2.
    pub fn heading(angle: f64, var: f64) -> Row {
        Row { h: Vector4::new(0.0, 0.0, 0.0, 1.0), y: angle * YAW_LEVER_M, var: var * YAW_LEVER_M.powi(2) }
    }

    /// What is left of the measurement once the error `e` is taken out.
    pub fn residual(&self, e: &Vector4<f64>) -> f64 {
        self.y - self.h.dot(e)
    }
}

/// The least-squares error of the map frame the rows say, in the directions they observe.
#[derive(Clone, Debug, PartialEq)]
pub struct Solution {
    pub error: Vector4<f64>,
    /// Observed directions (unit vectors), the information along each (1/m^2), and the
    /// error's component along each.
    pub directions: Vec<(Vector4<f64>, f64, f64)>,
}

/// Least squares over `rows`, each weighted by its variance; directions pinned to worse than
/// OBSERVED_SIGMA_M are left out.
pub fn solve(rows: &[Row]) -> Solution {
    let mut info = Matrix4::zeros();
    let mut rhs = Vector4::zeros();
    for r in rows {
        info += r.h * r.h.transpose() / r.var;
        rhs += r.h * (r.y / r.var);
    }
    let eig = SymmetricEigen::new(info);
    let mut error = Vector4::zeros();
    let mut directions = Vec::new();
    for i in 0..4 {
        let lambda = eig.eigenvalues[i];
        if lambda.is_finite() && lambda * OBSERVED_SIGMA_M.powi(2) >= 1.0 {
            let u: Vector4<f64> = eig.eigenvectors.column(i).into();
            let along = u.dot(&rhs) / lambda;
            error += u * along;
            directions.push((u, lambda, along));
        }
    }
    Solution { error, directions }
}

impl DriftFilter {
    pub fn new(noise: DriftNoise) -> DriftFilter {
        // The map's first frame defines the datum: no drift, no doubt about it.
        DriftFilter { x: 0.0, y: 0.0, z: 0.0, yaw: 0.0, cov: [[0.0; 4]; 4], noise, observed: 0 }
    }

    /// Variance of the vertical drift, m^2.
    pub fn var(&self) -> f64 {
        self.cov[2][2]
    }

    /// The drift as a transform: odometry coordinates of a map point.
    pub fn transform(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(self.x, self.y, self.z),
            UnitQuaternion::from_euler_angles(0.0, 0.0, self.yaw),
        )
    }

    /// Sets the drift to `t` (a turn about z and a shift; any roll or pitch is dropped).
    pub fn set_transform(&mut self, t: &Isometry3<f64>) {
        let v = t.translation.vector;
        (self.x, self.y, self.z) = (v.x, v.y, v.z);
        self.yaw = t.rotation.euler_angles().2;
    }

    /// Moves the map frame by `error` (its components as `cov`'s): D becomes D · error⁻¹.
    pub fn shift_map(&mut self, error: &Vector4<f64>) {
        let step = Isometry3::from_parts(
            Translation3::new(error.x, error.y, error.z),
            UnitQuaternion::from_euler_angles(0.0, 0.0, error.w / YAW_LEVER_M),
        );
        self.set_transform(&(self.transform() * step.inverse()));
    }

    /// Prediction: the drift is a random walk, so only the doubt grows; a turn of the
    /// odometry's yaw is about the camera (at `camera`, map coordinates), not the origin.
    pub fn predict(&mut self, camera: &Vector3<f64>) {
        let n = &self.noise;
        let mut cov = Matrix4::from(self.cov);
        if n.horizontal {
            // A turn about c is the same turn about the origin and a shift of -dyaw (ẑ × c).
            let mut j = Matrix4::identity();
            j[(0, 3)] = camera.y / YAW_LEVER_M;
            j[(1, 3)] = -camera.x / YAW_LEVER_M;
            let q = Matrix4::from_diagonal(&Vector4::new(n.p_xy, n.p_xy, n.p_z, n.p_yaw * YAW_LEVER_M.powi(2)));
            cov += j * q * j.transpose();
        } else {
            cov[(2, 2)] += n.p_z;
        }
        self.cov = cov.into();
    }

    /// Correction with one frame's solution: a Kalman update along each observed direction,
    /// its measurement variance the solution's plus the least a frame is allowed.
    pub fn correct(&mut self, s: &Solution) {
        if s.directions.is_empty() {
            self.observed = 0;
            return;
        }
        let p = Matrix4::from(self.cov);
        let k_rows = s.directions.len();
        let mut h = nalgebra::DMatrix::<f64>::zeros(k_rows, 4);
        let mut z = nalgebra::DVector::<f64>::zeros(k_rows);
        let mut r = nalgebra::DMatrix::<f64>::zeros(k_rows, k_rows);
        let floor = Vector4::new(self.noise.m, self.noise.m, self.noise.m, self.noise.m_yaw * YAW_LEVER_M.powi(2));
        let mut observed = 0;
        for (i, (u, lambda, along)) in s.directions.iter().enumerate() {
            h.row_mut(i).copy_from(&u.transpose());
            z[i] = *along;
            r[(i, i)] = 1.0 / lambda + u.component_mul(u).dot(&floor);
            for (bit, k) in [(X, 0), (Y, 1), (Z, 2), (YAW, 3)] {
                if u[k] * u[k] >= 0.5 {
                    observed |= bit;
                }
            }
        }
        let pd = nalgebra::DMatrix::from_iterator(4, 4, p.iter().copied());
        let innovation = &h * &pd * h.transpose() + r;
        let Some(inv) = innovation.try_inverse() else {
            self.observed = 0;
            return;
        };
        let gain = &pd * h.transpose() * inv;
        let error = &gain * z;
        let post = (nalgebra::DMatrix::<f64>::identity(4, 4) - &gain * &h) * &pd;
        let post = (&post + post.transpose()) / 2.0;
        self.shift_map(&Vector4::new(error[0], error[1], error[2], error[3]));
        self.cov = Matrix4::from_iterator(post.iter().copied()).into();
        self.observed = observed;
    }

    /// Widens the doubt by `var` in every direction (a step of the odometry taken in).
    pub fn widen(&mut self, var: Vector4<f64>) {
        self.cov = (Matrix4::from(self.cov) + Matrix4::from_diagonal(&var)).into();
    }

    /// Standard deviations of x, y, z (m) and yaw (rad).
    pub fn sigmas(&self) -> [f64; 4] {
        let c = self.cov;
        [c[0][0].sqrt(), c[1][1].sqrt(), c[2][2].sqrt(), c[3][3].sqrt() / YAW_LEVER_M]
    }
}
