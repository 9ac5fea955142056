//! The CPU twin of every GPU stage, in plain Rust (rayon over rows): one file per shader,
//! named after it (metres, diffusion, normals, gradient, classify, components,
//! hysteresis, morphology, boundary, ransac), and two helpers (`separable` convolutions,
//! `simd`'s widest-vector dispatch).

pub mod boundary;
pub mod classify;
pub mod components;
pub mod diffusion;
pub mod gradient;
pub mod hysteresis;
pub mod metres;
pub mod morphology;
pub mod normals;
pub mod ransac;
pub mod separable;
pub mod simd;

use super::params::{Images, Stage, StageTimes, ran};
use crate::config::PipelineConfig;
use crate::grid::Grid;
use crate::types::Intrinsics;

/// The per-pixel stages of one depth image (m) on the CPU, timing each into `times`.
pub fn image_stages(
    depth: &Grid<f32>,
    intr: &Intrinsics,
    cfg: &PipelineConfig,
    times: &mut StageTimes,
    lap: &mut impl FnMut() -> f64,
) -> Images {
    ran(Stage::Diffusion);
    let smoothed =
        diffusion::diffuse(depth, cfg.diffusion_time as f32, cfg.diffusion_steps, cfg.diffusion_kappa_m as f32);
    times.diffusion = lap();
    ran(Stage::Normals);
    let normals = normals::normal_planes(&smoothed, intr, cfg.normal_kernel);
    times.normals = lap();
    ran(Stage::Gradient);
    let gradient = gradient::gradient_of_planes(&normals);
    ran(Stage::Classify);
    let class = classify::classify(&gradient, cfg.canny_low as f32, cfg.canny_high as f32);
    ran(Stage::Hysteresis);
    let canny = hysteresis::hysteresis(&class);
    ran(Stage::Boundary);
    let boundary = boundary::boundary(
        &canny,
        &smoothed,
        cfg.depth_edge_ratio as f32,
        &normals,
        cfg.closing_kernel_px,
        cfg.normal_kernel,
    );
    times.edges = lap();
    Images { smoothed, normals, canny, boundary }
}

pub(crate) use super::params::ROWS_PER_TASK;

pub(crate) use simd::widest_simd;

/// Frames the stage tests share.
#[cfg(test)]
pub(crate) mod test_frames {
    use super::{Grid, diffusion, normals};
    use crate::synth::{NoiseModel, Scene, SceneKind, noisy_depth, path::trajectory, render};
    use crate::types::Intrinsics;

    /// Normals of a noisy stair frame with sensor dropouts, as the pipeline makes them.
    pub fn stair_normals() -> Grid<[f32; 3]> {
        let scene = Scene::build(SceneKind::Straight);
        let pose = trajectory(&scene, 30)[12];
        let intr = Intrinsics::L515_320X240;
        let pixels = noisy_depth(&render(&scene, &intr, &pose), &NoiseModel::l515(2.0), 7, 0);
        let (w, h) = (intr.width as usize, intr.height as usize);
        let mut depth = Grid { width: w, height: h, data: pixels.iter().map(|&d| d as f32 * 0.00025).collect() };
        // Dropouts of every size the gradient's validity test must see.
        for (k, z) in depth.data.iter_mut().enumerate() {
            if k % 997 == 0 || (k / w) % 61 == 3 && (k % w) % 43 < 5 {
                *z = 0.0;
            }
        }
        let smoothed = diffusion::diffuse(&depth, 4.0, 1, 0.0335);
        normals::normals(&smoothed, &intr, 5)
    }
}
