//! The CPU twin of every GPU stage, one file per shader, in plain Rust (rayon over rows).

pub mod boundary;
pub mod canny;
pub mod components;
pub mod diffusion;
pub mod morphology;
pub mod normals;
pub mod ransac;
pub mod separable;

use super::{Images, StageTimes};
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
    let smoothed =
        diffusion::diffuse(depth, cfg.diffusion_time as f32, cfg.diffusion_steps, cfg.diffusion_kappa_m as f32);
    times.diffusion = lap();
    let normals = normals::normals(&smoothed, intr, cfg.normal_kernel);
    times.normals = lap();
    let class = canny::classify(&canny::normal_gradient(&normals), cfg.canny_low as f32, cfg.canny_high as f32);
    let canny = components::hysteresis(&class);
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

/// Rows per rayon task in the per-row loops: one row is too little work to be worth a thread hop.
pub(crate) const ROWS_PER_TASK: usize = 8;

/// The four f64 lanes of an AVX vector added up, in lane order (pairs first): how the
/// AVX2 passes that keep a sum per lane (refits, plane covariances) hand back their sums.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
pub(crate) fn lane_sum(v: std::arch::x86_64::__m256d) -> f64 {
    let mut l = [0.0f64; 4];
    // SAFETY: stores 4 f64 into a local array of 4.
    unsafe { std::arch::x86_64::_mm256_storeu_pd(l.as_mut_ptr(), v) };
    (l[0] + l[1]) + (l[2] + l[3])
}

/// Defines `$name` to run `$portable` (an `#[inline(always)]` fn) compiled for AVX2
/// when the CPU has it, else as compiled for the baseline target. The loops are plain
/// Rust either way; only the width of the vectors the compiler may use differs, which
/// doubles their throughput on x86-64 without tying the binary to one CPU.
macro_rules! widest_simd {
    ($(#[$meta:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? = $portable:ident) => {
        $(#[$meta])*
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2")]
                fn avx2($($arg: $ty),*) $(-> $ret)? {
                    $portable($($arg),*)
                }
                if std::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU has AVX2, checked just above.
                    return unsafe { avx2($($arg),*) };
                }
            }
            $portable($($arg),*)
        }
    };
}
pub(crate) use widest_simd;

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
