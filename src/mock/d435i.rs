//! A D435i without hardware: IR images and IMU samples along a sequence's trajectory, for
//! feeding VINS (or its tests) exactly what the real camera would send.
//!
//! The sequence gives poses at 30 Hz; an IMU needs a trajectory with continuous
//! acceleration. So the poses become the control points of a uniform cumulative cubic
//! B-spline (positions in R³, rotations on SO(3), the form spline-based visual-inertial
//! calibration uses): C² everywhere, within millimetres of the sampled poses on a walking
//! path. Gyro and accel are its derivatives; the IR images are the synthetic scene rendered
//! from it with a texture, since passive IR (emitter off) sees surface texture only.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use crate::camera::{D435iSample, ImuSample};
use crate::synth::Scene;
use crate::types::{Intrinsics, StampNs};

/// Standard gravity, m/s²; the world's z axis points up.
pub const GRAVITY: f64 = 9.80665;
/// Distance from infra1 (left) to infra2 (right) along the image x axis, m.
pub const BASELINE_M: f64 = 0.050;
/// Step of the central differences that turn the spline into rates, s.
const DIFF_STEP_S: f64 = 1e-3;

/// A C² body trajectory through poses sampled at a fixed rate.
#[derive(Clone, Debug)]
pub struct Trajectory {
    start_ns: StampNs,
    step_s: f64,
    control: Vec<Isometry3<f64>>,
}

impl Trajectory {
    /// Needs at least 4 poses at evenly spaced stamps (within 1 %).
    pub fn new(stamps_ns: &[StampNs], poses: Vec<Isometry3<f64>>) -> Result<Trajectory, String> {
        if poses.len() < 4 || stamps_ns.len() != poses.len() {
            return Err(format!("a trajectory needs 4 or more poses with stamps, got {}", poses.len()));
        }
        let n = stamps_ns.len();
        let step_s = (stamps_ns[n - 1] - stamps_ns[0]) as f64 / (n - 1) as f64 * 1e-9;
        for (k, w) in stamps_ns.windows(2).enumerate() {
            let dt = w[1].saturating_sub(w[0]) as f64 * 1e-9;
            if (dt - step_s).abs() > 0.01 * step_s {
                return Err(format!("pose {} comes {dt} s after the one before; the mock needs a fixed rate", k + 1));
            }
        }
        Ok(Trajectory { start_ns: stamps_ns[0], step_s, control: poses })
    }

    /// The stamps the spline covers: from the second pose to the last but one.
    pub fn time_range_ns(&self) -> (StampNs, StampNs) {
        let n = self.control.len();
        let at = |k: usize| self.start_ns + (k as f64 * self.step_s * 1e9).round() as StampNs;
        (at(1), at(n - 2))
    }

    fn seconds(&self, t_ns: StampNs) -> f64 {
        (t_ns as f64 - self.start_ns as f64) * 1e-9
    }

    /// T_world_body at time `t` seconds after the first pose (clamped to the covered range).
    fn pose_s(&self, t: f64) -> Isometry3<f64> {
        let n = self.control.len();
        let s = (t / self.step_s).clamp(1.0, (n - 2) as f64);
        let i = (s.floor() as usize).min(n - 3);
        let u = s - i as f64;
        let b = [
            (5.0 + 3.0 * u - 3.0 * u * u + u * u * u) / 6.0,
            (1.0 + 3.0 * u + 3.0 * u * u - 2.0 * u * u * u) / 6.0,
            u * u * u / 6.0,
        ];
        let c = &self.control[i - 1..=i + 2];
        let mut position = c[0].translation.vector;
        let mut rotation = c[0].rotation;
        for j in 0..3 {
            position += b[j] * (c[j + 1].translation.vector - c[j].translation.vector);
            let delta = (c[j].rotation.inverse() * c[j + 1].rotation).scaled_axis();
            rotation *= UnitQuaternion::from_scaled_axis(delta * b[j]);
        }
        Isometry3::from_parts(Translation3::from(position), rotation)
    }

    pub fn pose(&self, t_ns: StampNs) -> Isometry3<f64> {
        self.pose_s(self.seconds(t_ns))
    }

    /// What an ideal IMU at the body frame measures at `t_ns`: angular velocity and specific
    /// force (acceleration minus gravity), both in the body frame.
    pub fn imu(&self, t_ns: StampNs) -> ImuSample {
        let h = DIFF_STEP_S;
        let (lo, hi) = self.time_range_ns();
        let t = self.seconds(t_ns.clamp(lo, hi)).clamp(self.seconds(lo) + h, self.seconds(hi) - h);
        let (before, now, after) = (self.pose_s(t - h), self.pose_s(t), self.pose_s(t + h));
        let gyro = (before.rotation.inverse() * after.rotation).scaled_axis() / (2.0 * h);
        let accel_world =
            (after.translation.vector - 2.0 * now.translation.vector + before.translation.vector) / (h * h);
        let accel = now.rotation.inverse() * (accel_world + Vector3::new(0.0, 0.0, GRAVITY));
        ImuSample { stamp_ns: t_ns, gyro: gyro.into(), accel: accel.into() }
    }

    /// The IMU at wall time `t_ns` of a looped walk: backwards, the body turns the other
    /// way (the gyro changes sign; the acceleration, a second derivative, does not).
    pub fn imu_looped(&self, clock: &super::SequenceClock, t_ns: StampNs) -> ImuSample {
        let mut imu = self.imu(clock.sequence_time(t_ns));
        if clock.backwards(t_ns) {
            imu.gyro = imu.gyro.map(|w| -w);
        }
        imu.stamp_ns = t_ns;
        imu
    }
}

/// The D435i's IR intrinsics at `width` x `height` (about 87 deg across, as the real one).
pub fn ir_intrinsics(width: u32, height: u32) -> Intrinsics {
    let f = 385.0 * width as f64 / 640.0;
    Intrinsics {
        width,
        height,
        fx: f,
        fy: f,
        cx: (width as f64 - 1.0) / 2.0,
        cy: (height as f64 - 1.0) / 2.0,
        depth_scale: 0.001,
    }
}

/// The mock camera: a scene, the body's trajectory through it, and the IR profile.
pub struct MockD435i {
    pub scene: Scene,
    pub trajectory: Trajectory,
    pub intrinsics: Intrinsics,
}

impl MockD435i {
    /// T_world_infra of infra1 (index 1, at the body frame) or infra2 (index 2).
    pub fn infrared_pose(&self, t_ns: StampNs, index: u8) -> Isometry3<f64> {
        let offset = if index == 2 { BASELINE_M } else { 0.0 };
        self.trajectory.pose(t_ns) * Translation3::new(offset, 0.0, 0.0)
    }

    /// The IR image infra`index` sees at `t_ns`: the scene's texture, lit by ambient light.
    pub fn infrared(&self, t_ns: StampNs, index: u8) -> D435iSample {
        let pose = self.infrared_pose(t_ns, index);
        let render = crate::synth::render(&self.scene, &self.intrinsics, &pose);
        let w = self.intrinsics.width as usize;
        let pixels = render
            .depth_m
            .par_iter()
            .zip(&render.cos_incidence)
            .enumerate()
            .map(|(i, (&depth, &cos))| {
                if depth <= 0.0 {
                    return 12; // nothing within range: dark
                }
                let p = pose * Point3::from(self.intrinsics.ray((i % w) as f64, (i / w) as f64) * depth);
                let shade = 0.45 + 0.55 * cos as f64;
                (30.0 + 200.0 * texture(&p) * shade).round() as u8
            })
            .collect();
        D435iSample::Infrared { index, stamp_ns: t_ns, intrinsics: self.intrinsics, pixels }
    }
}

/// A blotchy surface texture in [0.2, 1]: 3 cm cells of hashed brightness, so feature
/// trackers find corners everywhere, the same from every view.
fn texture(p: &Point3<f64>) -> f64 {
    // The lattice is shifted off round numbers: a tread at z = 0.15 m would otherwise lie on
    // a cell boundary and flicker between two cells pixel by pixel.
    let cell = |v: f64| ((v + 0.0137) / 0.03).floor() as i64;
    let mut h = (cell(p.x) as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (cell(p.y) as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (cell(p.z) as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
    h ^= h >> 29;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 32;
    0.2 + 0.8 * (h % 1024) as f64 / 1023.0
}

impl MockD435i {
    /// The mock along a sequence's trajectory: body = the depth camera moved by the inverse of
    /// `t_body_camera`, scene from the sequence's truth.json.
    pub fn from_sequence(
        seq: &crate::sequence::Sequence,
        t_body_camera: &Isometry3<f64>,
        cfg: &crate::config::D435iConfig,
    ) -> Result<MockD435i, String> {
        let truth =
            seq.truth.as_ref().ok_or_else(|| format!("{}: the mock D435i needs truth.json", seq.dir.display()))?;
        let stamps: Vec<StampNs> = seq.poses.iter().map(|p| p.stamp_ns).collect();
        let body =
            seq.poses.iter().enumerate().map(|(k, p)| truth.true_pose(k, &p.transform) * t_body_camera.inverse());
        Ok(MockD435i {
            scene: Scene::from_truth(truth),
            trajectory: Trajectory::new(&stamps, body.collect())?,
            intrinsics: ir_intrinsics(cfg.ir_width, cfg.ir_height),
        })
    }

    /// Sends IMU at `gyro_hz` and IR pairs at `ir_fps`, stamped on the wall clock, with the
    /// trajectory looped on `clock` like the mock camera and the mock VINS. Stamps sit on
    /// each stream's exact grid, as a camera's do, however late the runtime wakes; the IR
    /// renders run beside the IMU so they never hold it up. Stops when the receiver goes away.
    pub async fn run(
        self,
        clock: super::SequenceClock,
        cfg: &crate::config::D435iConfig,
        tx: tokio::sync::mpsc::Sender<D435iSample>,
    ) {
        let mock = std::sync::Arc::new(self);
        let clock = std::sync::Arc::new(clock);
        let start = (tokio::time::Instant::now(), crate::clock::now_ns());
        let imu = {
            let (mock, clock, tx) = (mock.clone(), clock.clone(), tx.clone());
            every(start, cfg.gyro_hz as f64, move |t| {
                let (mock, clock, tx) = (mock.clone(), clock.clone(), tx.clone());
                async move {
                    let imu = mock.trajectory.imu_looped(&clock, t);
                    tx.send(D435iSample::Imu(imu)).await.is_ok()
                }
            })
        };
        let ir = every(start, cfg.ir_fps as f64, move |t| {
            let (mock, clock, tx) = (mock.clone(), clock.clone(), tx.clone());
            async move {
                let tau = clock.sequence_time(t);
                let Ok(pair) = tokio::task::spawn_blocking(move || [1u8, 2].map(|i| mock.infrared(tau, i))).await
                else {
                    return false;
                };
                for mut image in pair {
                    if let D435iSample::Infrared { stamp_ns, .. } = &mut image {
                        *stamp_ns = t;
                    }
                    if tx.send(image).await.is_err() {
                        return false;
                    }
                }
                true
            }
        });
        tokio::join!(imu, ir);
    }
}

/// Calls `tick(stamp)` at `hz` from `start` (a runtime instant and its wall-clock stamp) on an
/// exact grid of stamps, until it returns false. A late wake-up catches up, keeping the grid.
async fn every<F: std::future::Future<Output = bool>>(
    start: (tokio::time::Instant, StampNs),
    hz: f64,
    mut tick: impl FnMut(StampNs) -> F,
) {
    let period = std::time::Duration::from_secs_f64(1.0 / hz);
    for k in 0u32.. {
        let offset = period * k;
        tokio::time::sleep_until(start.0 + offset).await;
        if !tick(start.1 + offset.as_nanos() as StampNs).await {
            return;
        }
    }
}
