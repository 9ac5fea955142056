//! The stage layer under both twins: each stage's parameters as its shader's uniform
//! (`#[repr(C)]`, `Pod`; gpu/'s tests hold each to the struct its WGSL declares), the
//! shader table, and what the CPU twin (`cpu/`) and the GPU twin (`gpu/`) both need:
//! the Sobel kernels, the closing's passes, the diffusion's schedule and the normals'
//! planes. Both twins import from here; neither imports from the other.

use rayon::prelude::*;

use serde::Serialize;

use crate::config::PipelineConfig;
use crate::grid::Grid;

/// The per-pixel stages from the raw depth to the regions. Each twin runs them in its own
/// function (`cpu::image_stages` with `extract_with`, `Gpu::image_stages`), and says which
/// it runs as it runs it (`ran`); tests/gpu.rs holds both to `Stage::ORDER`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    Metres,
    Diffusion,
    Normals,
    Gradient,
    Classify,
    Hysteresis,
    /// Depth steps, closing and sealing: the regions' boundary.
    Boundary,
    /// Connected components inside the boundary.
    Regions,
}

impl Stage {
    /// The order of the stages, written once.
    pub const ORDER: [Stage; 8] = [
        Stage::Metres,
        Stage::Diffusion,
        Stage::Normals,
        Stage::Gradient,
        Stage::Classify,
        Stage::Hysteresis,
        Stage::Boundary,
        Stage::Regions,
    ];
}

thread_local! {
    /// The stages this thread ran, while `stages_run` listens.
    static RAN: std::cell::RefCell<Option<Vec<Stage>>> = const { std::cell::RefCell::new(None) };
}

/// Notes that this thread's twin runs (or records) `stage` now.
pub(crate) fn ran(stage: Stage) {
    RAN.with_borrow_mut(|ran| ran.as_mut().map(|ran| ran.push(stage)));
}

/// `f`'s result and the stages it ran on this thread, in order.
pub fn stages_run<R>(f: impl FnOnce() -> R) -> (R, Vec<Stage>) {
    RAN.set(Some(Vec::new()));
    let result = f();
    (result, RAN.take().unwrap_or_default())
}

/// Rows a rayon task takes in the CPU twin's row-parallel loops (and the planes' writing).
pub(crate) const ROWS_PER_TASK: usize = 8;

/// Milliseconds spent in each stage of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct StageTimes {
    /// On the CPU, depth units to metres; on the GPU, writing the raw depth into its
    /// buffer and its conversion there (the CPU's own conversion overlaps the GPU's work).
    pub upload: f64,
    pub diffusion: f64,
    pub normals: f64,
    /// Gradient, classes, hysteresis and the closed boundary.
    pub edges: f64,
    /// Connected components of the pixels inside the boundary, numbered (on the GPU
    /// twin: the components' GPU time and the CPU's numbering of the roots read back),
    /// and the rays of the frame's points (`Cloud`) on either twin.
    pub regions: f64,
    /// GPU only: from the upload to the numbered regions on the CPU, less the stages' GPU
    /// time and the numbering: the submit, waiting and mapping, the gaps between the
    /// passes, the images' copies when kept, and the CPU's own conversion to metres where
    /// it outlasts the GPU's work (all of it where the adapter has no timestamps, the
    /// stages then reading 0).
    pub readback: f64,
    /// Region clean-up (splits, joins, growth) and outlines.
    pub contours: f64,
    pub ransac: f64,
    pub polygons: f64,
    pub total: f64,
    /// GPU only, and where the adapter has timestamps: the GPU's time for the per-pixel
    /// stages, from the first one's start to the last one's end (0 otherwise).
    pub gpu_busy: f64,
}

/// The images of the per-pixel stages.
#[derive(Clone, Debug)]
pub struct Images {
    pub smoothed: Grid<f32>,
    /// The normals as planes (`NormalPlanes::interleaved` gives them back as the GPU writes them).
    pub normals: NormalPlanes,
    /// Canny edges after hysteresis.
    pub canny: Grid<u8>,
    /// Closed edge lines (Canny + depth steps) plus no-normal pixels: 1 = not inside any region.
    pub boundary: Grid<u8>,
}

/// The gradient of the normal field as shaders/gradient.wgsl writes it: a plane of
/// magnitudes and one of NMS sectors (0..4; 4 marks a pixel whose 3x3 neighbourhood lacks
/// a normal, or on the image's border, magnitude 0 there).
#[derive(Clone, Debug, PartialEq)]
pub struct Gradient {
    pub magnitude: Grid<f32>,
    pub sector: Grid<u8>,
}

/// Smallest region worth a plane fit, pixels (the area test comes after the fit).
pub const MIN_REGION_PIXELS: usize = 30;

/// The diffusion's schedule: how many semi-implicit steps, each's time and 1 / kappa.
/// No steps when the time is zero.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiffusionSchedule {
    pub steps: u32,
    pub step: f32,
    pub inv_kappa: f32,
}

impl DiffusionSchedule {
    pub fn new(time: f32, steps: u32, kappa: f32) -> DiffusionSchedule {
        let steps = if time > 0.0 { steps } else { 0 };
        DiffusionSchedule { steps, step: time / steps.max(1) as f32, inv_kappa: 1.0 / kappa }
    }

    pub fn of(cfg: &PipelineConfig) -> DiffusionSchedule {
        DiffusionSchedule::new(cfg.diffusion_time as f32, cfg.diffusion_steps, cfg.diffusion_kappa_m as f32)
    }
}

/// The uniform of shaders/diffusion.wgsl, field by field its `DiffusionParams`: one
/// pass of implicit solves along every row or every column of the image.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct DiffusionParams {
    /// Pixels along a line.
    pub len: u32,
    pub lines: u32,
    /// Index of line k's first pixel: k * line_stride.
    pub line_stride: u32,
    /// From one pixel of a line to the next.
    pub elem_stride: u32,
    /// The step's time.
    pub step: f32,
    pub inv_kappa: f32,
}

/// The uniform of shaders/metres.wgsl, field by field its `MetresParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct MetresParams {
    pub width: u32,
    pub height: u32,
    /// Metres per depth unit (the frame's `depth_scale`).
    pub scale: f32,
    pub pad: u32,
}

/// The uniform of shaders/normals.wgsl, field by field its `NormalsParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct NormalsParams {
    pub width: u32,
    pub height: u32,
    /// Half the Sobel kernel's side.
    pub radius: u32,
    /// The kernel's derivative normalisation (`sobel_kernel`'s third value).
    pub norm: f32,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
}

/// The uniform of shaders/gradient.wgsl and shaders/classify.wgsl, field by field their `CannyParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct CannyParams {
    pub width: u32,
    pub height: u32,
    /// The double threshold on the gradient's magnitude.
    pub low: f32,
    pub high: f32,
}

/// The uniform of shaders/ransac.wgsl, field by field its `RansacParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RansacParams {
    pub hypotheses: u32,
    pub regions: u32,
    pub inlier_distance: f32,
    /// Scoring points in all (the length of each coordinate's plane).
    pub points: u32,
}

/// The uniform of shaders/morphology.wgsl, field by field its `MorphologyParams`: one
/// axis of a square dilation or erosion.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct MorphologyParams {
    pub width: u32,
    pub height: u32,
    pub radius: u32,
    /// 0 along rows, 1 along columns.
    pub axis: u32,
    /// 0 any pixel of the window (dilation), 1 all of them (erosion).
    pub all: u32,
    /// The value of pixels beyond the border.
    pub outside: u32,
}

/// The uniform of shaders/boundary.wgsl, field by field its `BoundaryParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BoundaryParams {
    pub width: u32,
    pub height: u32,
    pub depth_edge_ratio: f32,
    pub pad: u32,
}

/// The uniform of shaders/components.wgsl, field by field its `ComponentsParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ComponentsParams {
    pub width: u32,
    pub height: u32,
    /// 1: the components of the nonzero mask pixels; 0: of the zero ones.
    pub inside_nonzero: u32,
    pub pad: u32,
}

/// How a shader declares one binding of its group 0.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    Uniform,
    Read,
    ReadWrite,
}

/// One WGSL file: its source and its group 0, binding by binding. Every entry point of
/// the file shares that one layout (the unit test holds the list to the shader).
pub struct ShaderFile {
    pub name: &'static str,
    pub source: &'static str,
    pub bindings: &'static [Access],
}

use Access::{Read, ReadWrite, Uniform};

/// A shader file of shaders/ by its name (the file is the name's), its bindings in order.
macro_rules! shader_file {
    ($name:literal, [$($access:ident),*]) => {
        ShaderFile { name: $name, source: include_str!(concat!("../../shaders/", $name, ".wgsl")), bindings: &[$($access),*] }
    };
}

pub const METRES: ShaderFile = shader_file!("metres", [Uniform, Read, ReadWrite]);
pub const DIFFUSION: ShaderFile = shader_file!("diffusion", [Uniform, Read, ReadWrite]);
pub const NORMALS: ShaderFile = shader_file!("normals", [Uniform, Read, Read, ReadWrite]);
pub const GRADIENT: ShaderFile = shader_file!("gradient", [Uniform, Read, ReadWrite, ReadWrite]);
pub const CLASSIFY: ShaderFile = shader_file!("classify", [Uniform, Read, Read, ReadWrite]);
pub const COMPONENTS: ShaderFile = shader_file!("components", [Uniform, Read, ReadWrite, ReadWrite]);
pub const HYSTERESIS: ShaderFile = shader_file!("hysteresis", [Uniform, Read, Read, ReadWrite, ReadWrite]);
pub const MORPHOLOGY: ShaderFile = shader_file!("morphology", [Uniform, Read, ReadWrite]);
pub const BOUNDARY: ShaderFile = shader_file!("boundary", [Uniform, Read, Read, Read, Read, Read, ReadWrite]);
pub const RANSAC: ShaderFile = shader_file!("ransac", [Uniform, Read, Read, Read, ReadWrite]);

/// Every shader file, for the tests that parse and validate them all.
pub const SHADERS: [&ShaderFile; 10] =
    [&METRES, &DIFFUSION, &NORMALS, &GRADIENT, &CLASSIFY, &COMPONENTS, &HYSTERESIS, &MORPHOLOGY, &BOUNDARY, &RANSAC];

/// Separable Sobel weights (smoothing, derivative) and the derivative's response to a
/// unit ramp times the smoothing sum, by kernel size.
pub fn sobel_kernel(size: u32) -> (&'static [f32], &'static [f32], f32) {
    match size {
        3 => (&[1.0, 2.0, 1.0], &[-1.0, 0.0, 1.0], 8.0),
        5 => (&[1.0, 4.0, 6.0, 4.0, 1.0], &[-1.0, -2.0, 0.0, 2.0, 1.0], 128.0),
        7 => (&[1.0, 6.0, 15.0, 20.0, 15.0, 6.0, 1.0], &[-1.0, -4.0, -5.0, 0.0, 5.0, 4.0, 1.0], 2048.0),
        _ => panic!("Sobel kernel size {size} is not 3, 5 or 7 (the config validates this)"),
    }
}

/// The square passes of a morphological close: dilation then erosion, each rows then
/// columns; outside the image counts as set, so closing never eats into the border.
pub fn closing_passes(width: u32, height: u32, size: u32) -> [MorphologyParams; 4] {
    let pass = |axis, all| MorphologyParams { width, height, radius: size / 2, axis, all, outside: 1 };
    [pass(0, 0), pass(1, 0), pass(0, 1), pass(1, 1)]
}

/// Normals as planes, for the gradient: row v is [x; w] [y; w] [z; w] [1 where a normal,
/// else 0; w], so each of the gradient's row loops runs over plain slices and vectorises.
#[derive(Clone, Debug, PartialEq)]
pub struct NormalPlanes {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl NormalPlanes {
    /// The planes of interleaved normals (the normals stage writes both at once).
    pub fn of(normals: &Grid<[f32; 3]>) -> NormalPlanes {
        let w = normals.width;
        let mut data = vec![0.0f32; 4 * w * normals.height];
        data.par_chunks_mut(4 * w).zip(normals.data.par_chunks(w)).with_min_len(ROWS_PER_TASK).for_each(
            |(planes, row)| {
                for (u, n) in row.iter().enumerate() {
                    planes[u] = n[0];
                    planes[w + u] = n[1];
                    planes[2 * w + u] = n[2];
                    planes[3 * w + u] = f32::from(u8::from(*n != [0.0; 3]));
                }
            },
        );
        NormalPlanes { width: w, height: normals.height, data }
    }

    /// The normals interleaved again, as the GPU stage writes them (for pictures and the
    /// GPU twin's inputs; the frame itself reads only the planes).
    pub fn interleaved(&self) -> Grid<[f32; 3]> {
        let w = self.width;
        let data = (self.data.chunks(4 * w))
            .flat_map(|row| (0..w).map(move |u| [row[u], row[w + u], row[2 * w + u]]))
            .collect();
        Grid { width: w, height: self.height, data }
    }
}
