//! The GPU half of the image stages and of the batched RANSAC, on wgpu (Vulkan; on a
//! machine without a GPU, Mesa's lavapipe). Each stage is a WGSL shader in shaders/
//! mirroring its CPU twin in `cpu/`; the tests hold the two to the same answers.
//!
//! One `Gpu` holds the device and the compiled pipelines; image buffers are made for
//! the first frame of a size and reused. Each stage is submitted on its own and waited
//! for, so the stage times are real; the readbacks give the intermediate images the
//! CPU half of the pipeline (hysteresis, closing, regions) works on.

use wgpu::util::DeviceExt;

use super::Grid;
use super::cpu::normals::sobel_kernel;
use super::cpu::ransac::{MAX_SCORE_POINTS, PointBatch};
use crate::config::PipelineConfig;
use crate::types::Intrinsics;

/// Why the GPU backend could not start or run.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no Vulkan adapter: {0} (is a Vulkan driver installed? without a GPU, Mesa's lavapipe: mesa-vulkan-drivers)"
    )]
    NoAdapter(String),
    #[error("the Vulkan adapter {adapter} would not open a device: {reason}")]
    NoDevice { adapter: String, reason: String },
    #[error("a shader did not compile: {0}")]
    Shader(String),
    #[error("GPU dispatch failed: {0}")]
    Dispatch(String),
    #[error("GPU readback failed: {0}")]
    Readback(String),
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
    pub max_score_points: u32,
}

/// A compute pipeline and the layout of its group 0.
struct Stage {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

/// Buffers for one image size.
struct ImageBuffers {
    width: u32,
    height: u32,
    depth: [wgpu::Buffer; 2],
    /// The diffusion's elimination factors.
    factor: wgpu::Buffer,
    normals: wgpu::Buffer,
    magnitude: wgpu::Buffer,
    sector: wgpu::Buffer,
    class: wgpu::Buffer,
}

/// The image stages' outputs, read back.
pub struct ImageStages {
    pub smoothed: Grid<f32>,
    pub normals: Grid<[f32; 3]>,
    /// Non-maximum-suppressed double-threshold classes: 0 none, 1 weak, 2 strong.
    pub class: Grid<u8>,
    /// Milliseconds: upload, diffusion, normals, edges (gradient + classes + readback).
    pub times: [f64; 4],
}

pub struct Gpu {
    device: wgpu::Device,
    queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    diffusion: Stage,
    normals: Stage,
    gradient: Stage,
    classify: Stage,
    ransac: Stage,
    images: Option<ImageBuffers>,
}

impl Gpu {
    /// Opens the first Vulkan adapter (a real GPU preferred over a software one).
    pub fn new() -> Result<Gpu, GpuError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends: wgpu::Backends::VULKAN,
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        });
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("polymap"),
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoDevice { adapter: info.name.clone(), reason: e.to_string() })?;
        let stage = |source: &str, entry: &str| {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(entry),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
            let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            });
            let layout = pipeline.get_bind_group_layout(0);
            Stage { pipeline, layout }
        };
        // A shader the driver rejects is an error to report, not wgpu's default panic.
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let (diffusion, normals, gradient, classify, ransac) = (
            stage(include_str!("../../shaders/diffusion.wgsl"), "main"),
            stage(include_str!("../../shaders/normals.wgsl"), "main"),
            stage(include_str!("../../shaders/gradient.wgsl"), "main"),
            stage(include_str!("../../shaders/classify.wgsl"), "main"),
            stage(include_str!("../../shaders/ransac.wgsl"), "main"),
        );
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Shader(e.to_string()));
        }
        Ok(Gpu { diffusion, normals, gradient, classify, ransac, device, queue, info, images: None })
    }

    /// Whether the adapter is a software rasteriser (lavapipe, SwiftShader).
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// A one-line description of the adapter, for logs.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?}, driver {})",
            self.info.name, self.info.device_type, self.info.backend, self.info.driver
        )
    }

    fn storage(&self, label: &str, bytes: u64) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(4),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    fn uniform(&self, bytes: &[u8]) -> wgpu::Buffer {
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("params"),
            contents: bytes,
            usage: wgpu::BufferUsages::UNIFORM,
        })
    }

    /// A bind group of (binding, buffer) pairs: only the bindings the entry point uses,
    /// as its derived layout holds no others.
    fn bind(&self, stage: &Stage, buffers: &[(u32, &wgpu::Buffer)]) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .map(|(i, b)| wgpu::BindGroupEntry { binding: *i, resource: b.as_entire_binding() })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &stage.layout,
            entries: &entries,
        })
    }

    /// Records `dispatches` of one stage each with its bind group, submits, and waits.
    fn run(&self, stage: &Stage, dispatches: &[(&wgpu::BindGroup, [u32; 2])]) -> Result<(), GpuError> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&stage.pipeline);
            for (group, [x, y]) in dispatches {
                pass.set_bind_group(0, *group, &[]);
                pass.dispatch_workgroups(*x, *y, 1);
            }
        }
        self.queue.submit([encoder.finish()]);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Dispatch(e.to_string()));
        }
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Dispatch(e.to_string()))?;
        Ok(())
    }

    /// Copies `buffer`'s first `bytes` bytes back to the CPU.
    fn read(&self, buffer: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>, GpuError> {
        let bytes = bytes.max(4);
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, bytes);
        self.queue.submit([encoder.finish()]);
        let slice = staging.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Readback(e.to_string()))?;
        rx.recv().map_err(|e| GpuError::Readback(e.to_string()))?.map_err(|e| GpuError::Readback(e.to_string()))?;
        let data = slice.get_mapped_range().map_err(|e| GpuError::Readback(e.to_string()))?.to_vec();
        Ok(data)
    }

    fn images_for(&mut self, width: u32, height: u32) -> &ImageBuffers {
        if self.images.as_ref().is_none_or(|b| b.width != width || b.height != height) {
            let n = width as u64 * height as u64;
            self.images = Some(ImageBuffers {
                width,
                height,
                depth: [self.storage("depth a", n * 4), self.storage("depth b", n * 4)],
                factor: self.storage("diffusion factors", n * 4),
                normals: self.storage("normals", n * 12),
                magnitude: self.storage("magnitude", n * 4),
                sector: self.storage("sector", n * 4),
                class: self.storage("class", n * 4),
            });
        }
        self.images.as_ref().expect("just made")
    }

    /// Diffusion, normals, and the per-pixel half of Canny for one depth image (m).
    pub fn image_stages(
        &mut self,
        depth: &Grid<f32>,
        intr: &Intrinsics,
        cfg: &PipelineConfig,
    ) -> Result<ImageStages, GpuError> {
        let kernel = cfg.normal_kernel;
        let (low, high) = (cfg.canny_low as f32, cfg.canny_high as f32);
        let (w, h) = (depth.width as u32, depth.height as u32);
        let n = w as u64 * h as u64;
        let groups = [w.div_ceil(16), h.div_ceil(16)];
        let mut lap = super::stopwatch();
        self.images_for(w, h);
        let b = self.images.as_ref().expect("made above");
        self.queue.write_buffer(&b.depth[0], 0, bytemuck::cast_slice(&depth.data));
        let upload = lap();

        // A step: rows from depth a into b, then columns from b back into a.
        let steps = if cfg.diffusion_time > 0.0 { cfg.diffusion_steps } else { 0 };
        let step = cfg.diffusion_time as f32 / steps.max(1) as f32;
        let inv_kappa = 1.0 / cfg.diffusion_kappa_m as f32;
        let rows = DiffusionParams { len: w, lines: h, line_stride: w, elem_stride: 1, step, inv_kappa };
        let columns = DiffusionParams { len: h, lines: w, line_stride: 1, elem_stride: w, step, inv_kappa };
        let (rows_params, columns_params) =
            (self.uniform(bytemuck::bytes_of(&rows)), self.uniform(bytemuck::bytes_of(&columns)));
        let along_rows =
            self.bind(&self.diffusion, &[(0, &rows_params), (1, &b.depth[0]), (2, &b.depth[1]), (3, &b.factor)]);
        let along_columns =
            self.bind(&self.diffusion, &[(0, &columns_params), (1, &b.depth[1]), (2, &b.depth[0]), (3, &b.factor)]);
        let passes: Vec<_> = (0..steps)
            .flat_map(|_| [(&along_rows, [h.div_ceil(64), 1]), (&along_columns, [w.div_ceil(64), 1])])
            .collect();
        self.run(&self.diffusion, &passes)?;
        let smoothed_buf = &b.depth[0];
        let diffusion = lap();

        let (smooth, deriv, norm) = sobel_kernel(kernel);
        let mut weights = [0.0f32; 14];
        weights[..smooth.len()].copy_from_slice(smooth);
        weights[7..7 + deriv.len()].copy_from_slice(deriv);
        let weights = self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("sobel"),
            contents: bytemuck::cast_slice(&weights),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let params = self.uniform(bytemuck::bytes_of(&NormalsParams {
            width: w,
            height: h,
            radius: kernel / 2,
            norm,
            fx: intr.fx as f32,
            fy: intr.fy as f32,
            cx: intr.cx as f32,
            cy: intr.cy as f32,
        }));
        let group = self.bind(&self.normals, &[(0, &params), (1, smoothed_buf), (2, &weights), (3, &b.normals)]);
        self.run(&self.normals, &[(&group, groups)])?;
        let normals_ms = lap();

        let params = self.uniform(bytemuck::bytes_of(&CannyParams { width: w, height: h, low, high }));
        let group = self.bind(&self.gradient, &[(0, &params), (1, &b.normals), (2, &b.magnitude), (3, &b.sector)]);
        self.run(&self.gradient, &[(&group, groups)])?;
        let group = self.bind(&self.classify, &[(0, &params), (2, &b.magnitude), (3, &b.sector), (4, &b.class)]);
        self.run(&self.classify, &[(&group, groups)])?;
        let edges = lap();

        let grid = |data| Grid { width: w as usize, height: h as usize, data };
        let smoothed: Vec<f32> = bytemuck::cast_slice(&self.read(smoothed_buf, n * 4)?).to_vec();
        let normals: Vec<[f32; 3]> = bytemuck::cast_slice::<u8, f32>(&self.read(&b.normals, n * 12)?)
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        // The gradient's magnitude and sector stay on the GPU: only classify reads them.
        let class: Vec<u32> = bytemuck::cast_slice(&self.read(&b.class, n * 4)?).to_vec();
        // Readbacks count to the edges stage, the last one.
        let readback = lap();
        Ok(ImageStages {
            smoothed: grid(smoothed),
            normals: Grid { width: w as usize, height: h as usize, data: normals },
            class: Grid { width: w as usize, height: h as usize, data: class.into_iter().map(|c| c as u8).collect() },
            times: [upload, diffusion, normals_ms, edges + readback],
        })
    }

    /// Inlier counts of every (region, hypothesis), row-major by region: one dispatch
    /// for the whole frame, the same numbers as `cpu::ransac::score_hypotheses`.
    pub fn score_hypotheses(
        &self,
        batch: &PointBatch,
        hypotheses: u32,
        inlier_distance: f32,
    ) -> Result<Vec<u32>, GpuError> {
        let regions = batch.ranges.len() as u32;
        let total = regions * hypotheses;
        if total == 0 {
            return Ok(Vec::new());
        }
        let init = |label: &str, contents: &[u8]| {
            self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: if contents.is_empty() { &[0; 4] } else { contents },
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let points = init("points", bytemuck::cast_slice(&batch.points));
        let ranges: Vec<[u32; 2]> = batch.ranges.iter().map(|r| [r.start as u32, (r.end - r.start) as u32]).collect();
        let ranges = init("ranges", bytemuck::cast_slice(&ranges));
        let scores = self.storage("scores", total as u64 * 4);
        let params = self.uniform(bytemuck::bytes_of(&RansacParams {
            hypotheses,
            regions,
            inlier_distance,
            max_score_points: MAX_SCORE_POINTS as u32,
        }));
        let group = self.bind(&self.ransac, &[(0, &params), (1, &points), (2, &ranges), (3, &scores)]);
        // At most 65535 workgroups per dimension: wrap into y.
        self.run(&self.ransac, &[(&group, [total.min(65535), total.div_ceil(65535)])])?;
        Ok(bytemuck::cast_slice(&self.read(&scores, total as u64 * 4)?).to_vec())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (name, offset, type) of each field of a #[repr(C)] struct, in declaration order; the
    /// types are checked against the struct's by the compiler.
    macro_rules! fields {
        ($t:ty { $($f:ident: $ty:ident),* }) => {{
            $(let _: fn(&$t) -> $ty = |s| s.$f;)*
            vec![$((stringify!($f), std::mem::offset_of!($t, $f), stringify!($ty))),*]
        }};
    }

    /// The WGSL struct `name` has exactly these fields, in this order, at these offsets, and `size` bytes.
    fn assert_declared_as(source: &str, name: &str, fields: Vec<(&str, usize, &str)>, size: usize) {
        let module = naga::front::wgsl::parse_str(source).unwrap_or_else(|e| panic!("{name}: {e}"));
        let (_, ty) = module.types.iter().find(|(_, t)| t.name.as_deref() == Some(name)).expect(name);
        let naga::TypeInner::Struct { members, span } = &ty.inner else { panic!("{name} is not a struct") };
        let declared: Vec<(&str, usize, &str)> = members
            .iter()
            .map(|m| {
                let scalar = match module.types[m.ty].inner {
                    naga::TypeInner::Scalar(naga::Scalar { kind: naga::ScalarKind::Uint, width: 4 }) => "u32",
                    naga::TypeInner::Scalar(naga::Scalar { kind: naga::ScalarKind::Float, width: 4 }) => "f32",
                    ref other => panic!("{name}: a member of type {other:?}"),
                };
                (m.name.as_deref().unwrap_or(""), m.offset as usize, scalar)
            })
            .collect();
        assert_eq!(declared, fields, "{name}: the shader's fields against the Rust type's");
        assert_eq!(*span as usize, size, "{name}: size");
    }

    #[test]
    fn every_stage_s_uniform_is_the_struct_its_shader_declares() {
        assert_declared_as(
            include_str!("../../shaders/diffusion.wgsl"),
            "DiffusionParams",
            fields!(DiffusionParams {
                len: u32,
                lines: u32,
                line_stride: u32,
                elem_stride: u32,
                step: f32,
                inv_kappa: f32
            }),
            size_of::<DiffusionParams>(),
        );
        assert_declared_as(
            include_str!("../../shaders/normals.wgsl"),
            "NormalsParams",
            fields!(NormalsParams {
                width: u32,
                height: u32,
                radius: u32,
                norm: f32,
                fx: f32,
                fy: f32,
                cx: f32,
                cy: f32
            }),
            size_of::<NormalsParams>(),
        );
        for source in [include_str!("../../shaders/gradient.wgsl"), include_str!("../../shaders/classify.wgsl")] {
            assert_declared_as(
                source,
                "CannyParams",
                fields!(CannyParams { width: u32, height: u32, low: f32, high: f32 }),
                size_of::<CannyParams>(),
            );
        }
        assert_declared_as(
            include_str!("../../shaders/ransac.wgsl"),
            "RansacParams",
            fields!(RansacParams { hypotheses: u32, regions: u32, inlier_distance: f32, max_score_points: u32 }),
            size_of::<RansacParams>(),
        );
    }
}
