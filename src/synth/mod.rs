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

use crate::sequence::{SequenceWriter, Truth};
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
    /// Image width; height is 3/4 of it, intrinsics the L515's scaled.
    pub width: u32,
    pub frames: usize,
    /// Range noise at 1 m, mm (0 = noise-free, only quantised).
    pub noise_mm: f64,
    /// Vertical drift added to the written poses, mm per frame (the truth stays true).
    pub drift_mm_per_frame: f64,
    pub seed: u64,
    /// Frame rate of the stamps, Hz.
    pub fps: f64,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            scene: SceneKind::Straight,
            width: 320,
            frames: 30,
            noise_mm: 2.0,
            drift_mm_per_frame: 0.0,
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
        if !(self.fps >= 0.1 && self.fps <= 1000.0) {
            return Some(format!("--fps {} must be within 0.1..=1000", self.fps));
        }
        None
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
    for (k, t_world_camera) in path::trajectory(&scene, opts.frames).into_iter().enumerate() {
        let r = render(&scene, &intrinsics, &t_world_camera);
        let depth = noisy_depth(&r, &model, opts.seed, k);
        let mut written = t_world_camera;
        written.translation.vector.z += opts.drift_mm_per_frame * k as f64 / 1000.0;
        writer.push(&depth, Pose { stamp_ns: stamp_ns(k, opts.fps), transform: written }, Some(&r.labels))?;
        on_frame(k, &r);
    }
    let truth = Truth { pose_drift_per_frame: opts.drift_mm_per_frame / 1000.0, ..scene.truth() };
    writer.finish(Some(&truth))
}
