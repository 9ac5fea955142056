//! The synthetic world: stair scenes, a walking camera, ray-cast depth with an
//! L515-like noise model, and the exact truth. `polymap synth` writes it as a
//! sequence; the mock camera and the tests use it directly.

pub mod noise;
pub mod path;
pub mod scene;

use std::path::Path;

use nalgebra::Isometry3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

pub use noise::NoiseModel;
pub use scene::{Scene, SceneKind};

use crate::sequence::{HorizontalDrift, PoseJump, SequenceWriter, Truth};
use crate::types::{Intrinsics, Pose};

/// A noise-free render of a scene from one camera pose.
#[derive(Clone, Debug)]
pub struct Render {
    pub width: u32,
    pub height: u32,
    pub intrinsics: Intrinsics,
    /// Depth (camera z) of the nearest hit, m; 0 where the ray hits nothing.
    pub depth_m: Vec<f64>,
    /// 1-based index of the surface hit (= truth.json polygon), 0 = nothing.
    pub labels: Vec<u16>,
    /// |cos| of the angle between the ray and the surface normal.
    pub cos_incidence: Vec<f32>,
}

impl Render {
    /// Length of pixel (u, v)'s ray per metre of depth.
    pub fn ray_length(&self, u: f64, v: f64) -> f64 {
        self.intrinsics.ray(u, v).norm()
    }
}

/// Ray casts every pixel of `intrinsics` from `t_world_camera`.
pub fn render(scene: &Scene, intrinsics: &Intrinsics, t_world_camera: &Isometry3<f64>) -> Render {
    let (w, h) = (intrinsics.width as usize, intrinsics.height as usize);
    let origin = t_world_camera.translation.vector.into();
    let rows: Vec<Vec<(f64, u16, f32)>> = (0..h)
        .into_par_iter()
        .map(|v| {
            (0..w)
                .map(|u| {
                    // Ray with camera z = 1: its parameter at the hit is the depth.
                    let dir = t_world_camera.rotation * intrinsics.ray(u as f64, v as f64);
                    match scene.cast(&origin, &dir) {
                        Some((t, i)) => {
                            let cos = (scene.surfaces[i].normal.dot(&dir) / dir.norm()).abs();
                            (t, (i + 1) as u16, cos as f32)
                        }
                        None => (0.0, 0, 0.0),
                    }
                })
                .collect()
        })
        .collect();
    let mut r = Render {
        width: intrinsics.width,
        height: intrinsics.height,
        intrinsics: *intrinsics,
        depth_m: Vec::with_capacity(w * h),
        labels: Vec::with_capacity(w * h),
        cos_incidence: Vec::with_capacity(w * h),
    };
    for (d, l, c) in rows.into_iter().flatten() {
        r.depth_m.push(d);
        r.labels.push(l);
        r.cos_incidence.push(c);
    }
    r
}

/// What `polymap synth` makes.
#[derive(Clone, Debug)]
pub struct SynthOptions {
    pub scene: SceneKind,
    /// Up the flight of steps or down it.
    pub walk: path::Direction,
    /// Image width; height is 3/4 of it, intrinsics the L515's scaled.
    pub width: u32,
    pub frames: usize,
    /// Range noise at 1 m, mm (0 = noise-free, only quantised).
    pub noise_mm: f64,
    /// Vertical drift added to the written poses, mm per frame (the truth stays true).
    pub drift_mm_per_frame: f64,
    /// Horizontal drift, mm per frame, and yaw drift about the walk's start, degrees per frame.
    pub drift_xy_mm_per_frame: [f64; 2],
    pub drift_yaw_deg_per_frame: f64,
    /// A step of the odometry from a frame on (VINS-Fusion's loop closure): frame, x, y, z
    /// (mm) and yaw (degrees).
    pub jump: Option<JumpOptions>,
    pub seed: u64,
    /// Frame rate of the stamps, Hz.
    pub fps: f64,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            scene: SceneKind::Straight,
            walk: path::Direction::Up,
            width: 320,
            frames: 30,
            noise_mm: 2.0,
            drift_mm_per_frame: 0.0,
            drift_xy_mm_per_frame: [0.0; 2],
            drift_yaw_deg_per_frame: 0.0,
            jump: None,
            seed: 1,
            fps: 30.0,
        }
    }
}

impl SynthOptions {
    pub fn intrinsics(&self) -> Intrinsics {
        Intrinsics::L515_320X240.scaled_to(self.width, self.width * 3 / 4)
    }

    /// Why these options cannot make a sequence, if they cannot.
    pub fn problem(&self) -> Option<String> {
        if self.width < 32 || self.width > 4096 || !self.width.is_multiple_of(4) {
            return Some(format!("--width {} must be a multiple of 4 within 32..=4096", self.width));
        }
        if self.frames == 0 || self.frames > 100_000 {
            return Some(format!("--frames {} must be within 1..=100000", self.frames));
        }
        if !(self.noise_mm >= 0.0 && self.noise_mm <= 100.0) {
            return Some(format!("--noise {} must be within 0..=100 mm", self.noise_mm));
        }
        if !(self.drift_mm_per_frame.is_finite() && self.drift_mm_per_frame.abs() <= 100.0) {
            return Some(format!("--drift {} must be within -100..=100 mm per frame", self.drift_mm_per_frame));
        }
        for (name, v, max) in [
            ("--drift-xy", self.drift_xy_mm_per_frame[0], 100.0),
            ("--drift-xy", self.drift_xy_mm_per_frame[1], 100.0),
            ("--drift-yaw", self.drift_yaw_deg_per_frame, 10.0),
        ] {
            if !(v.is_finite() && v.abs() <= max) {
                return Some(format!("{name} {v} must be within -{max}..={max} per frame"));
            }
        }
        if let Some(j) = self.jump {
            let ok = j.xyz_mm.iter().all(|v| v.is_finite() && v.abs() <= 1000.0)
                && j.yaw_deg.is_finite()
                && j.yaw_deg.abs() <= 45.0;
            // Two frames before it set the datum and the motion it is told from.
            if !ok || j.frame < 2 || j.frame >= self.frames {
                return Some(format!(
                    "--jump {} {:?} {}: the frame must be one of the walk's from its third, the step within 1000 mm and 45 degrees",
                    j.frame, j.xyz_mm, j.yaw_deg
                ));
            }
        }
        if !(self.fps >= 0.1 && self.fps <= 1000.0) {
            return Some(format!("--fps {} must be within 0.1..=1000", self.fps));
        }
        None
    }
}

/// A step of the written poses from `frame` on.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JumpOptions {
    pub frame: usize,
    pub xyz_mm: [f64; 3],
    pub yaw_deg: f64,
}

impl SynthOptions {
    /// The horizontal drift the options inject (None: none).
    fn horizontal_drift(&self, start: &Isometry3<f64>) -> Option<HorizontalDrift> {
        let none = self.drift_xy_mm_per_frame == [0.0; 2] && self.drift_yaw_deg_per_frame == 0.0 && self.jump.is_none();
        (!none).then(|| HorizontalDrift {
            xy_per_frame: self.drift_xy_mm_per_frame.map(|v| v / 1000.0),
            yaw_deg_per_frame: self.drift_yaw_deg_per_frame,
            pivot: [start.translation.x, start.translation.y],
            jump: self.jump.map(|j| PoseJump { frame: j.frame, xyz: j.xyz_mm.map(|v| v / 1000.0), yaw_deg: j.yaw_deg }),
        })
    }
}

/// Frame k's stamp at `fps`, starting at 0.
pub fn stamp_ns(k: usize, fps: f64) -> u64 {
    (k as f64 * 1e9 / fps).round() as u64
}

/// Noisy depth units of frame k: a separate random stream per (seed, frame), so
/// any frame can be made alone and the result never depends on thread count.
pub fn noisy_depth(render: &Render, model: &NoiseModel, seed: u64, k: usize) -> Vec<u16> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(k as u64);
    model.apply(render, render.intrinsics.depth_scale, &mut rng)
}

/// Writes a synthetic sequence to `out`; `on_frame` is called after each frame (progress).
pub fn generate(opts: &SynthOptions, out: &Path, mut on_frame: impl FnMut(usize, &Render)) -> std::io::Result<()> {
    if let Some(p) = opts.problem() {
        return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, p));
    }
    let scene = Scene::build(opts.scene);
    let intrinsics = opts.intrinsics();
    let model = NoiseModel::l515(opts.noise_mm);
    let mut writer = SequenceWriter::create(out, intrinsics, true)?;
    let poses = path::walk(&scene, opts.frames, opts.walk);
    let truth = Truth {
        pose_drift_per_frame: opts.drift_mm_per_frame / 1000.0,
        pose_drift: opts.horizontal_drift(&poses[0]),
        ..scene.truth()
    };
    for (k, t_world_camera) in poses.into_iter().enumerate() {
        let r = render(&scene, &intrinsics, &t_world_camera);
        let depth = noisy_depth(&r, &model, opts.seed, k);
        let written = truth.drift_at(k) * t_world_camera;
        writer.push(&depth, Pose { stamp_ns: stamp_ns(k, opts.fps), transform: written }, Some(&r.labels))?;
        on_frame(k, &r);
    }
    writer.finish(Some(&truth))
}
