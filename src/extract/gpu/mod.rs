//! The GPU half of the image stages and of the batched RANSAC, on wgpu (Vulkan; on a
//! machine without a GPU, Mesa's lavapipe). Each stage is a WGSL shader in shaders/
//! mirroring its CPU twin in `cpu/`; the tests hold the two to the same answers.
//!
//! One `Gpu` holds the device and the compiled pipelines. Buffers, uniforms and bind
//! groups are made for the first frame of a size and reused. A frame's per-pixel
//! stages, from the depth to the region labels, are one submit and one readback; GPU
//! timestamps around each stage's compute pass time them where the adapter has them.
//!
//! Here: the device, its pipelines and the types; [`frame`]: a frame size's resources and
//! dispatch lists; [`record`]: a frame's submit; [`ransac`]: the batched scoring;
//! [`alone`]: each stage alone, for the tests.

mod alone;
mod frame;
mod ransac;
mod record;

use wgpu::util::DeviceExt;

use super::cpu::ransac::{PointBatch, ScoringBatch};
use super::params::Access::{Read, ReadWrite, Uniform};
use super::params::*;
use super::regions::Segmentation;
use crate::config::PipelineConfig;
use crate::grid::Grid;
use crate::types::{DepthFrame, Intrinsics};

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
    #[error(
        "a {width}x{height} image is larger than the GPU's diffusion solves: lines of at most {DIFFUSION_MAX_LINE} pixels"
    )]
    TooLarge { width: u32, height: u32 },
    #[error("a {width}x{height} image of {len} pixels")]
    SizeMismatch { width: u32, height: u32, len: usize },
}

/// The longest row or column shaders/diffusion.wgsl solves (its MAX_LINE): a workgroup
/// holds a line's system in workgroup memory. The L515's largest depth image is 1024 x 768.
pub const DIFFUSION_MAX_LINE: u32 = 2047;

/// The workgroup memory that holds it: four arrays of 2048 f32.
const DIFFUSION_WORKGROUP_BYTES: u32 = 4 * 4 * (DIFFUSION_MAX_LINE + 1);

/// A compiled shader file: its group 0 layout and a pipeline per entry point used.
struct Shader {
    layout: wgpu::BindGroupLayout,
    entries: Vec<(&'static str, wgpu::ComputePipeline)>,
}

impl Shader {
    fn entry(&self, name: &str) -> &wgpu::ComputePipeline {
        &self.entries.iter().find(|(n, _)| *n == name).expect("an entry point compiled in Gpu::new").1
    }
}

/// What the image stages start from.
#[derive(Clone, Copy)]
pub enum DepthUpload<'a> {
    /// The sensor's frame as it comes, 16 bits a pixel (checked against the intrinsics by
    /// the caller), converted to metres on the GPU (shaders/metres.wgsl): half the bytes
    /// of metres to upload, and the CPU converts its own copy while the GPU works.
    Raw(&'a DepthFrame),
    /// Depth in metres: how a test hands the stages its CPU twin's input.
    Metres(&'a Grid<f32>),
}

impl DepthUpload<'_> {
    /// Width and height, once the pixels are checked to be as many: a short image would
    /// leave the last frame's pixels in the buffer, a long one overrun it.
    fn size(&self) -> Result<(u32, u32), GpuError> {
        let (width, height, len) = match self {
            DepthUpload::Raw(frame) => (frame.width, frame.height, frame.pixels.len()),
            DepthUpload::Metres(depth) => (depth.width as u32, depth.height as u32, depth.data.len()),
        };
        if len as u64 != width as u64 * height as u64 {
            return Err(GpuError::SizeMismatch { width, height, len });
        }
        Ok((width, height))
    }
}

/// The image stages' outputs, read back.
pub struct ImageStages {
    /// The 8-connected components of non-boundary pixels, numbered on the CPU from the
    /// roots shaders/components.wgsl leaves (`Segmentation::from_roots`) where they were
    /// read back, in the mapped buffer: no copy of them is made.
    pub regions: Segmentation,
    /// The intermediate images, when asked for.
    pub images: Option<Images>,
    pub times: GpuTimes,
}

/// Milliseconds of one frame on the GPU. The stages are read from GPU timestamps where
/// the adapter has them, else they are 0 (`extract_with` counts the rest of the wall
/// time as the readback); `upload` and `numbering` are the CPU's wall-clock time.
#[derive(Clone, Copy, Debug, Default)]
pub struct GpuTimes {
    /// Writing the depth into the GPU's buffer (and the uniforms).
    pub upload: f64,
    /// The raw depth converted to metres on the GPU (about 0, an empty pass, for metres
    /// uploaded).
    pub metres: f64,
    pub diffusion: f64,
    pub normals: f64,
    /// Gradient, classes, hysteresis and the closed boundary.
    pub edges: f64,
    /// Connected components of the non-boundary pixels.
    pub regions: f64,
    /// The CPU numbering the components' roots in the mapped readback buffer.
    pub numbering: f64,
    /// From the first stage's start to the last one's end: the GPU's time for the
    /// per-pixel stages, the gaps between them included.
    pub busy: f64,
}

/// The timed stages of the one submit, in order: metres, diffusion, normals, edges, regions.
const TIMED_STAGES: u32 = 5;
const TIMESTAMP_BYTES: u64 = 2 * TIMED_STAGES as u64 * 8;

/// Buffers, uniforms and bind groups for one image size, made once.
struct Frame {
    width: u32,
    height: u32,
    /// The raw depth, two 16-bit pixels a word.
    raw: wgpu::Buffer,
    /// Depth in, and after the diffusion's last column pass the smoothed depth, in [0].
    depth: [wgpu::Buffer; 2],
    normals: wgpu::Buffer,
    /// gradient.wgsl's magnitude (f32) and sector (u32) planes.
    magnitude: wgpu::Buffer,
    sector: wgpu::Buffer,
    /// classify.wgsl's 0 / 1 weak / 2 strong.
    class: wgpu::Buffer,
    edges: wgpu::Buffer,
    /// The boundary's depth-step lines, and their closing (the morphology's first four passes).
    lines: wgpu::Buffer,
    closed: wgpu::Buffer,
    boundary: wgpu::Buffer,
    regions: wgpu::Buffer,
    strong: wgpu::Buffer,
    /// Everything read back, one copy after another, then the timestamps.
    readback: wgpu::Buffer,
    /// Uniforms rewritten each frame from the config: rows, columns of the diffusion,
    /// normals, Canny, the 8 morphology passes, boundary; the raw depth's scale.
    metres_params: wgpu::Buffer,
    diffusion_params: [wgpu::Buffer; 2],
    normals_params: wgpu::Buffer,
    canny_params: wgpu::Buffer,
    morphology_params: Vec<wgpu::Buffer>,
    boundary_params: wgpu::Buffer,
    sobel: wgpu::Buffer,
    groups: FrameGroups,
    timestamps: Option<(wgpu::QuerySet, wgpu::Buffer)>,
}

struct FrameGroups {
    metres: wgpu::BindGroup,
    diffusion: [wgpu::BindGroup; 2],
    normals: wgpu::BindGroup,
    gradient: wgpu::BindGroup,
    classify: wgpu::BindGroup,
    edge_components: wgpu::BindGroup,
    hysteresis: wgpu::BindGroup,
    lines: wgpu::BindGroup,
    morphology: Vec<wgpu::BindGroup>,
    holes: wgpu::BindGroup,
    seal: wgpu::BindGroup,
    regions: wgpu::BindGroup,
}

pub struct Gpu {
    device: wgpu::Device,
    queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    metres: Shader,
    diffusion: Shader,
    normals: Shader,
    gradient: Shader,
    classify: Shader,
    components: Shader,
    hysteresis: Shader,
    morphology: Shader,
    boundary: Shader,
    ransac: Shader,
    timestamps: bool,
    frame: Option<Frame>,
    ransac_buffers: Option<RansacBuffers>,
}

/// The RANSAC batch's buffers, sized for the largest batch so far (to the next power of
/// two) and made again only when a batch outgrows them: a frame's batches are rewritten
/// in place.
struct RansacBuffers {
    /// Scoring points and regions they hold room for; hypotheses x regions planes and scores.
    points: u64,
    regions: u64,
    hypotheses: u32,
    params: wgpu::Buffer,
    coords: wgpu::Buffer,
    ranges: wgpu::Buffer,
    planes: wgpu::Buffer,
    scores: wgpu::Buffer,
    staging: wgpu::Buffer,
    group: wgpu::BindGroup,
}

/// Usages of every image buffer: bound as storage, filled and read back by copies.
const IMAGE: wgpu::BufferUsages =
    wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_SRC).union(wgpu::BufferUsages::COPY_DST);

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
        if adapter.limits().max_compute_workgroup_storage_size < DIFFUSION_WORKGROUP_BYTES {
            return Err(GpuError::NoDevice {
                adapter: info.name,
                reason: format!(
                    "{} bytes of workgroup memory, and the diffusion's line solves take {DIFFUSION_WORKGROUP_BYTES}",
                    adapter.limits().max_compute_workgroup_storage_size
                ),
            });
        }
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("polymap"),
            required_limits: adapter.limits(),
            required_features: if timestamps { wgpu::Features::TIMESTAMP_QUERY } else { wgpu::Features::empty() },
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoDevice { adapter: info.name.clone(), reason: e.to_string() })?;
        let compile = |file: &ShaderFile, entries: &[&'static str]| {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(file.name),
                source: wgpu::ShaderSource::Wgsl(file.source.into()),
            });
            let layout_entries: Vec<wgpu::BindGroupLayoutEntry> = file
                .bindings
                .iter()
                .enumerate()
                .map(|(binding, access)| wgpu::BindGroupLayoutEntry {
                    binding: binding as u32,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: match access {
                            Uniform => wgpu::BufferBindingType::Uniform,
                            Read => wgpu::BufferBindingType::Storage { read_only: true },
                            ReadWrite => wgpu::BufferBindingType::Storage { read_only: false },
                        },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                })
                .collect();
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(file.name),
                entries: &layout_entries,
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(file.name),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let entries = entries
                .iter()
                .map(|&entry| {
                    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                        label: Some(entry),
                        layout: Some(&pipeline_layout),
                        module: &module,
                        entry_point: Some(entry),
                        compilation_options: Default::default(),
                        cache: None,
                    });
                    (entry, pipeline)
                })
                .collect();
            Shader { layout, entries }
        };
        // A shader the driver rejects is an error to report, not wgpu's default panic.
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let gpu = Gpu {
            metres: compile(&METRES, &["main"]),
            diffusion: compile(&DIFFUSION, &["main"]),
            normals: compile(&NORMALS, &["main"]),
            gradient: compile(&GRADIENT, &["main"]),
            classify: compile(&CLASSIFY, &["main"]),
            components: compile(&COMPONENTS, &["init", "merge", "flatten"]),
            hysteresis: compile(&HYSTERESIS, &["mark_strong", "keep"]),
            morphology: compile(&MORPHOLOGY, &["main"]),
            boundary: compile(&BOUNDARY, &["lines", "holes", "seal"]),
            ransac: compile(&RANSAC, &["main"]),
            device: device.clone(),
            queue,
            info,
            timestamps,
            frame: None,
            ransac_buffers: None,
        };
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Shader(e.to_string()));
        }
        Ok(gpu)
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

    /// Whether the stage times come from GPU timestamps.
    pub fn has_timestamps(&self) -> bool {
        self.timestamps
    }

    fn buffer(&self, label: &str, bytes: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(4),
            usage,
            mapped_at_creation: false,
        })
    }

    fn uniform(&self, bytes: &[u8]) -> wgpu::Buffer {
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("params"),
            contents: bytes,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        })
    }

    /// A bind group of a shader file's layout: buffer k at binding k.
    fn bind(&self, shader: &Shader, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &shader.layout,
            entries: &entries,
        })
    }

    /// Submits `encoder` and reports a validation error as `Dispatch`. Does not wait for
    /// the GPU: `map` does, so the CPU can work in between.
    fn submit(&self, encoder: wgpu::CommandEncoder, scope: wgpu::ErrorScopeGuard) -> Result<(), GpuError> {
        self.queue.submit([encoder.finish()]);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Dispatch(e.to_string()));
        }
        Ok(())
    }

    /// Maps `staging` (filled by the submit just done), hands its first `bytes` to `read`,
    /// unmaps. This is where the CPU waits for the GPU: `submit` does not.
    fn map<T>(&self, staging: &wgpu::Buffer, bytes: u64, read: impl FnOnce(&[u8]) -> T) -> Result<T, GpuError> {
        let slice = staging.slice(..bytes.max(4));
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Readback(e.to_string()))?;
        rx.recv().map_err(|e| GpuError::Readback(e.to_string()))?.map_err(|e| GpuError::Readback(e.to_string()))?;
        let out = read(&slice.get_mapped_range().map_err(|e| GpuError::Readback(e.to_string()))?);
        staging.unmap();
        Ok(out)
    }

    /// Records one compute pass of `(pipeline, bind group, workgroups)` dispatches, with
    /// timestamps `2k` and `2k + 1` around it when the frame has a query set.
    fn pass(encoder: &mut wgpu::CommandEncoder, timestamps: Option<&wgpu::QuerySet>, k: u32, dispatches: &[Dispatch]) {
        let timestamp_writes = timestamps.map(|query_set| wgpu::ComputePassTimestampWrites {
            query_set,
            beginning_of_pass_write_index: Some(2 * k),
            end_of_pass_write_index: Some(2 * k + 1),
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes });
        for (pipeline, group, [x, y]) in dispatches {
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, *group, &[]);
            pass.dispatch_workgroups(*x, *y, 1);
        }
    }
}

/// One dispatch: a pipeline, its bind group, and the workgroups along x and y.
type Dispatch<'a> = (&'a wgpu::ComputePipeline, &'a wgpu::BindGroup, [u32; 2]);

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
            DIFFUSION.source,
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
            NORMALS.source,
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
        for file in [&GRADIENT, &CLASSIFY, &HYSTERESIS] {
            assert_declared_as(
                file.source,
                "CannyParams",
                fields!(CannyParams { width: u32, height: u32, low: f32, high: f32 }),
                size_of::<CannyParams>(),
            );
        }
        assert_declared_as(
            MORPHOLOGY.source,
            "MorphologyParams",
            fields!(MorphologyParams { width: u32, height: u32, radius: u32, axis: u32, all: u32, outside: u32 }),
            size_of::<MorphologyParams>(),
        );
        assert_declared_as(
            METRES.source,
            "MetresParams",
            fields!(MetresParams { width: u32, height: u32, scale: f32, pad: u32 }),
            size_of::<MetresParams>(),
        );
        assert_declared_as(
            BOUNDARY.source,
            "BoundaryParams",
            fields!(BoundaryParams { width: u32, height: u32, depth_edge_ratio: f32, pad: u32 }),
            size_of::<BoundaryParams>(),
        );
        assert_declared_as(
            COMPONENTS.source,
            "ComponentsParams",
            fields!(ComponentsParams { width: u32, height: u32, inside_nonzero: u32, pad: u32 }),
            size_of::<ComponentsParams>(),
        );
        assert_declared_as(
            RANSAC.source,
            "RansacParams",
            fields!(RansacParams { hypotheses: u32, regions: u32, inlier_distance: f32, points: u32 }),
            size_of::<RansacParams>(),
        );
    }

    #[test]
    fn the_diffusion_shader_solves_the_lines_the_rust_side_lets_through() {
        let module = naga::front::wgsl::parse_str(DIFFUSION.source).unwrap();
        let (_, max_line) =
            module.constants.iter().find(|(_, c)| c.name.as_deref() == Some("MAX_LINE")).expect("MAX_LINE");
        let naga::Expression::Literal(naga::Literal::U32(declared)) = module.global_expressions[max_line.init] else {
            panic!("MAX_LINE is not a u32 literal")
        };
        assert_eq!(declared, DIFFUSION_MAX_LINE);
    }

    #[test]
    fn every_shader_is_valid_and_binds_the_layout_the_rust_side_makes() {
        for file in SHADERS {
            let module = naga::front::wgsl::parse_str(file.source).unwrap_or_else(|e| panic!("{}: {e}", file.name));
            // What the device checks when it compiles: caught here without a GPU.
            naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
                .validate(&module)
                .unwrap_or_else(|e| panic!("{}: {e:?}", file.name));
            let mut declared: Vec<(u32, Access)> = module
                .global_variables
                .iter()
                .filter_map(|(_, var)| {
                    let binding = var.binding.as_ref()?;
                    assert_eq!(binding.group, 0, "{}: {:?} outside group 0", file.name, var.name);
                    let access = match var.space {
                        naga::AddressSpace::Uniform => Access::Uniform,
                        naga::AddressSpace::Storage { access } if access.contains(naga::StorageAccess::STORE) => {
                            Access::ReadWrite
                        }
                        naga::AddressSpace::Storage { .. } => Access::Read,
                        other => panic!("{}: {:?} in {other:?}", file.name, var.name),
                    };
                    Some((binding.binding, access))
                })
                .collect();
            declared.sort_by_key(|(b, _)| *b);
            let made: Vec<(u32, Access)> = file.bindings.iter().enumerate().map(|(b, a)| (b as u32, *a)).collect();
            assert_eq!(declared, made, "{}: the shader's bindings against ShaderFile::bindings", file.name);
        }
    }
}
