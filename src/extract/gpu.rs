//! The GPU half of the image stages and of the batched RANSAC, on wgpu (Vulkan; on a
//! machine without a GPU, Mesa's lavapipe). Each stage is a WGSL shader in shaders/
//! mirroring its CPU twin in `cpu/`; the tests hold the two to the same answers.
//!
//! One `Gpu` holds the device and the compiled pipelines. Buffers, uniforms and bind
//! groups are made for the first frame of a size and reused. A frame's per-pixel
//! stages, from the depth to the region labels, are one submit and one readback; GPU
//! timestamps around each stage's compute pass time them where the adapter has them.

use wgpu::util::DeviceExt;

use super::cpu::ransac::{PointBatch, ScoringBatch};
use super::params::Access::{Read, ReadWrite, Uniform};
use super::params::*;
use super::segment::Segmentation;
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

    /// Writes a raw depth frame (16-bit values, two a word, the first in the low half on
    /// the little-endian hosts wgpu runs on) and its scale for shaders/metres.wgsl. A
    /// write is whole words: an odd pixel count's last word is padded.
    fn upload_raw(&self, frame: &DepthFrame) {
        let f = self.frame.as_ref().expect("frame_for before");
        let bytes: &[u8] = bytemuck::cast_slice(&frame.pixels);
        let (whole, last) = bytes.split_at(bytes.len() / 4 * 4);
        self.queue.write_buffer(&f.raw, 0, whole);
        if !last.is_empty() {
            let mut word = [0u8; 4];
            word[..last.len()].copy_from_slice(last);
            self.queue.write_buffer(&f.raw, whole.len() as u64, &word);
        }
        let params = MetresParams { width: frame.width, height: frame.height, scale: frame.depth_scale as f32, pad: 0 };
        self.queue.write_buffer(&f.metres_params, 0, bytemuck::bytes_of(&params));
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

    /// The dispatches of shaders/components.wgsl over one bind group.
    fn components_dispatches<'a>(&'a self, group: &'a wgpu::BindGroup, size: [u32; 2]) -> [Dispatch<'a>; 3] {
        let c = &self.components;
        [(c.entry("init"), group, size), (c.entry("merge"), group, size), (c.entry("flatten"), group, size)]
    }

    fn frame_for(&mut self, width: u32, height: u32) {
        if self.frame.as_ref().is_some_and(|f| f.width == width && f.height == height) {
            return;
        }
        let n = width as u64 * height as u64;
        let image = |label: &str, bytes_per_pixel: u64| self.buffer(label, n * bytes_per_pixel, IMAGE);
        let depth = [image("depth a", 4), image("depth b", 4)];
        let raw = self.buffer("raw depth", n.div_ceil(2) * 4, IMAGE);
        let normals = image("normals", 12);
        let (magnitude, sector, class) = (image("magnitude", 4), image("sector", 4), image("class", 4));
        let (parent, edge_labels, strong, edges) =
            (image("parent", 4), image("edge labels", 4), image("strong", 4), image("edges", 4));
        let (lines, closed, holes, sealed, boundary) =
            (image("lines", 4), image("closed", 4), image("holes", 4), image("sealed", 4), image("boundary", 4));
        let scratch = [image("morphology a", 4), image("morphology b", 4)];
        let regions = image("regions", 4);
        // Regions, smoothed depth, normals (3), edges, boundary: 7 words a pixel at most.
        let readback = self.buffer(
            "readback",
            n * 4 * 7 + TIMESTAMP_BYTES,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        let zeros = |bytes: usize| self.uniform(&vec![0u8; bytes]);
        let metres_params = zeros(size_of::<MetresParams>());
        let diffusion_params = [zeros(size_of::<DiffusionParams>()), zeros(size_of::<DiffusionParams>())];
        let normals_params = zeros(size_of::<NormalsParams>());
        let canny_params = zeros(size_of::<CannyParams>());
        let morphology_params: Vec<wgpu::Buffer> = (0..8).map(|_| zeros(size_of::<MorphologyParams>())).collect();
        let boundary_params = zeros(size_of::<BoundaryParams>());
        let components_params = |inside_nonzero| {
            self.uniform(bytemuck::bytes_of(&ComponentsParams { width, height, inside_nonzero, pad: 0 }))
        };
        let (edge_params, region_params) = (components_params(1), components_params(0));
        let sobel = self.buffer("sobel", 14 * 4, wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST);
        // Closing: lines -> a -> b -> a -> closed; sealing: holes -> a -> b -> a -> sealed.
        let [a, b] = &scratch;
        let morphology_io = [(&lines, a), (a, b), (b, a), (a, &closed), (&holes, a), (a, b), (b, a), (a, &sealed)];
        let groups = FrameGroups {
            metres: self.bind(&self.metres, &[&metres_params, &raw, &depth[0]]),
            diffusion: [
                self.bind(&self.diffusion, &[&diffusion_params[0], &depth[0], &depth[1]]),
                self.bind(&self.diffusion, &[&diffusion_params[1], &depth[1], &depth[0]]),
            ],
            normals: self.bind(&self.normals, &[&normals_params, &depth[0], &sobel, &normals]),
            gradient: self.bind(&self.gradient, &[&canny_params, &normals, &magnitude, &sector]),
            classify: self.bind(&self.classify, &[&canny_params, &magnitude, &sector, &class]),
            edge_components: self.bind(&self.components, &[&edge_params, &class, &parent, &edge_labels]),
            hysteresis: self.bind(&self.hysteresis, &[&canny_params, &class, &edge_labels, &strong, &edges]),
            lines: self
                .bind(&self.boundary, &[&boundary_params, &depth[0], &normals, &edges, &closed, &sealed, &lines]),
            morphology: morphology_io
                .iter()
                .zip(&morphology_params)
                .map(|((src, dst), params)| self.bind(&self.morphology, &[params, src, dst]))
                .collect(),
            holes: self
                .bind(&self.boundary, &[&boundary_params, &depth[0], &normals, &edges, &closed, &sealed, &holes]),
            seal: self
                .bind(&self.boundary, &[&boundary_params, &depth[0], &normals, &edges, &closed, &sealed, &boundary]),
            regions: self.bind(&self.components, &[&region_params, &boundary, &parent, &regions]),
        };
        let timestamps = self.timestamps.then(|| {
            let set = self.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("stage timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 2 * TIMED_STAGES,
            });
            let resolved = self.buffer(
                "timestamps",
                TIMESTAMP_BYTES,
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            );
            (set, resolved)
        });
        self.frame = Some(Frame {
            width,
            height,
            raw,
            depth,
            normals,
            magnitude,
            sector,
            class,
            edges,
            lines,
            closed,
            boundary,
            regions,
            strong,
            readback,
            metres_params,
            diffusion_params,
            normals_params,
            canny_params,
            morphology_params,
            boundary_params,
            sobel,
            groups,
            timestamps,
        });
    }

    /// Writes every stage's uniform from the config and the image's size.
    fn write_uniforms(&self, w: u32, h: u32, intr: Option<&Intrinsics>, cfg: &PipelineConfig) {
        let f = self.frame.as_ref().expect("frame_for before");
        let q = &self.queue;
        let DiffusionSchedule { step, inv_kappa, .. } = DiffusionSchedule::of(cfg);
        let rows = DiffusionParams { len: w, lines: h, line_stride: w, elem_stride: 1, step, inv_kappa };
        let columns = DiffusionParams { len: h, lines: w, line_stride: 1, elem_stride: w, step, inv_kappa };
        q.write_buffer(&f.diffusion_params[0], 0, bytemuck::bytes_of(&rows));
        q.write_buffer(&f.diffusion_params[1], 0, bytemuck::bytes_of(&columns));
        let (smooth, deriv, norm) = sobel_kernel(cfg.normal_kernel);
        let mut weights = [0.0f32; 14];
        weights[..smooth.len()].copy_from_slice(smooth);
        weights[7..7 + deriv.len()].copy_from_slice(deriv);
        q.write_buffer(&f.sobel, 0, bytemuck::cast_slice(&weights));
        if let Some(intr) = intr {
            let normals = NormalsParams {
                width: w,
                height: h,
                radius: cfg.normal_kernel / 2,
                norm,
                fx: intr.fx as f32,
                fy: intr.fy as f32,
                cx: intr.cx as f32,
                cy: intr.cy as f32,
            };
            q.write_buffer(&f.normals_params, 0, bytemuck::bytes_of(&normals));
        }
        let canny = CannyParams { width: w, height: h, low: cfg.canny_low as f32, high: cfg.canny_high as f32 };
        q.write_buffer(&f.canny_params, 0, bytemuck::bytes_of(&canny));
        // The lines are closed with the closing square, the pixels without normals sealed with the normal kernel's.
        let closing = closing_passes(w, h, cfg.closing_kernel_px);
        let seal = closing_passes(w, h, cfg.normal_kernel);
        for (buffer, params) in f.morphology_params.iter().zip(closing.iter().chain(&seal)) {
            q.write_buffer(buffer, 0, bytemuck::bytes_of(params));
        }
        let boundary = BoundaryParams { width: w, height: h, depth_edge_ratio: cfg.depth_edge_ratio as f32, pad: 0 };
        q.write_buffer(&f.boundary_params, 0, bytemuck::bytes_of(&boundary));
    }

    /// Hysteresis from the classes: edge components, strong ones marked, their pixels kept.
    fn hysteresis_dispatches(&self, size: [u32; 2]) -> Vec<Dispatch<'_>> {
        let g = &self.frame.as_ref().expect("frame_for before").groups;
        let mut out = self.components_dispatches(&g.edge_components, size).to_vec();
        out.push((self.hysteresis.entry("mark_strong"), &g.hysteresis, size));
        out.push((self.hysteresis.entry("keep"), &g.hysteresis, size));
        out
    }

    /// The boundary from the edges, the smoothed depth and the normals: lines, closing,
    /// holes, sealing, the 4-neighbour growth.
    fn boundary_dispatches(&self, size: [u32; 2]) -> Vec<Dispatch<'_>> {
        let g = &self.frame.as_ref().expect("frame_for before").groups;
        let morph = self.morphology.entry("main");
        let mut out = vec![(self.boundary.entry("lines"), &g.lines, size)];
        out.extend(g.morphology[..4].iter().map(|group| (morph, group, size)));
        out.push((self.boundary.entry("holes"), &g.holes, size));
        out.extend(g.morphology[4..].iter().map(|group| (morph, group, size)));
        out.push((self.boundary.entry("seal"), &g.seal, size));
        out
    }

    /// Copies `outputs` one after another into the readback buffer (and, for a `timed`
    /// submit on an adapter with timestamps, the stages' timestamps after them), submits,
    /// runs `beside` on the CPU while the GPU works, and hands the words read back to `read`.
    fn submit_and_read<T, B>(
        &self,
        mut encoder: wgpu::CommandEncoder,
        scope: wgpu::ErrorScopeGuard,
        outputs: &[(&wgpu::Buffer, u64)],
        timed: bool,
        beside: impl FnOnce() -> B,
        read: impl FnOnce(&[u32], Option<&[u64]>) -> T,
    ) -> Result<(T, B), GpuError> {
        let f = self.frame.as_ref().expect("frame_for before");
        let mut at = 0;
        for (buffer, bytes) in outputs {
            encoder.copy_buffer_to_buffer(buffer, 0, &f.readback, at, *bytes);
            at += bytes;
        }
        let stamped = f.timestamps.as_ref().filter(|_| timed).map(|(set, resolved)| {
            encoder.resolve_query_set(set, 0..2 * TIMED_STAGES, resolved, 0);
            encoder.copy_buffer_to_buffer(resolved, 0, &f.readback, at, TIMESTAMP_BYTES);
        });
        self.submit(encoder, scope)?;
        let beside = beside();
        let bytes = at + if stamped.is_some() { TIMESTAMP_BYTES } else { 0 };
        let out = self.map(&f.readback, bytes, |data| {
            let (words, stamps) = data.split_at(at as usize);
            // The stamps sit at a multiple of 4 bytes: copy them out rather than cast in place.
            let stamps: Vec<u64> =
                stamps.chunks_exact(8).map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes"))).collect();
            read(bytemuck::cast_slice(words), stamped.map(|_| stamps.as_slice()))
        })?;
        Ok((out, beside))
    }

    /// The per-pixel stages of one depth image, in one submit: the raw depth to metres,
    /// diffusion, normals, Canny with hysteresis, the closed boundary, and the connected
    /// regions inside it. One readback: the region roots, numbered where they lie, and with
    /// `images` the intermediate images too. `beside` runs on the CPU while the GPU works
    /// (the frame's conversion to metres for the CPU's own stages), and its result comes back.
    pub fn image_stages<B>(
        &mut self,
        depth: DepthUpload,
        intr: &Intrinsics,
        cfg: &PipelineConfig,
        images: bool,
        beside: impl FnOnce() -> B,
    ) -> Result<(ImageStages, B), GpuError> {
        let (w, h) = depth.size()?;
        if w.max(h) > DIFFUSION_MAX_LINE {
            return Err(GpuError::TooLarge { width: w, height: h });
        }
        let n = w as u64 * h as u64;
        let mut lap = super::stopwatch();
        self.frame_for(w, h);
        let f = self.frame.as_ref().expect("made above");
        match depth {
            DepthUpload::Raw(frame) => self.upload_raw(frame),
            DepthUpload::Metres(depth) => self.queue.write_buffer(&f.depth[0], 0, bytemuck::cast_slice(&depth.data)),
        }
        self.write_uniforms(w, h, Some(intr), cfg);
        let upload = lap();

        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.clear_buffer(&f.strong, 0, None);
        let g = &f.groups;
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let set = f.timestamps.as_ref().map(|(set, _)| set);
        // A diffusion step: rows from depth a into b, then columns from b back into a, a
        // workgroup a line.
        let diffuse = self.diffusion.entry("main");
        let steps: Vec<Dispatch> = (0..DiffusionSchedule::of(cfg).steps)
            .flat_map(|_| [(diffuse, &g.diffusion[0], [h, 1]), (diffuse, &g.diffusion[1], [w, 1])])
            .collect();
        // Metres uploaded: an empty pass, so that every timestamp is written.
        let metres = [(self.metres.entry("main"), &g.metres, size)];
        Self::pass(&mut encoder, set, 0, if matches!(depth, DepthUpload::Raw(_)) { &metres } else { &[] });
        Self::pass(&mut encoder, set, 1, &steps);
        Self::pass(&mut encoder, set, 2, &[(self.normals.entry("main"), &g.normals, size)]);
        let mut edges =
            vec![(self.gradient.entry("main"), &g.gradient, size), (self.classify.entry("main"), &g.classify, size)];
        edges.extend(self.hysteresis_dispatches(size));
        edges.extend(self.boundary_dispatches(size));
        Self::pass(&mut encoder, set, 3, &edges);
        Self::pass(&mut encoder, set, 4, &self.components_dispatches(&g.regions, size));

        let mut outputs = vec![(&f.regions, n * 4)];
        if images {
            outputs.extend([(&f.depth[0], n * 4), (&f.normals, n * 12), (&f.edges, n * 4), (&f.boundary, n * 4)]);
        }
        let (w, h, n) = (w as usize, h as usize, n as usize);
        fn grid<T>(w: usize, h: usize, data: Vec<T>) -> Grid<T> {
            Grid { width: w, height: h, data }
        }
        let period_ms = self.queue.get_timestamp_period() as f64 * 1e-6;
        let mut times = GpuTimes { upload, ..Default::default() };
        let ((regions, images), beside) =
            self.submit_and_read(encoder, scope, &outputs, true, beside, |words, stamps| {
                if let Some(ticks) = stamps {
                    let ms = |k: usize| ticks[2 * k + 1].saturating_sub(ticks[2 * k]) as f64 * period_ms;
                    [times.metres, times.diffusion, times.normals, times.edges, times.regions] =
                        [ms(0), ms(1), ms(2), ms(3), ms(4)];
                    times.busy = ticks[2 * TIMED_STAGES as usize - 1].saturating_sub(ticks[0]) as f64 * period_ms;
                }
                let floats = |k: usize, per: usize| bytemuck::cast_slice::<u32, f32>(&words[k * n..(k + per) * n]);
                let bytes = |k: usize| words[k * n..(k + 1) * n].iter().map(|&b| b as u8).collect::<Vec<u8>>();
                let images = images.then(|| Images {
                    smoothed: grid(w, h, floats(1, 1).to_vec()),
                    normals: NormalPlanes::of(&grid(
                        w,
                        h,
                        floats(2, 3).chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
                    )),
                    canny: grid(w, h, bytes(5)),
                    boundary: grid(w, h, bytes(6)),
                });
                let mut lap = super::stopwatch();
                let regions = Segmentation::from_roots(&words[..n], w, MIN_REGION_PIXELS);
                times.numbering = lap();
                (regions, images)
            })?;
        Ok((ImageStages { regions, images, times }, beside))
    }

    /// Runs `dispatches` alone on inputs written into the frame's buffers, and reads
    /// `outputs` back, one after another.
    fn stage_alone(
        &self,
        inputs: &[(&wgpu::Buffer, &[u8])],
        dispatches: &[Dispatch],
        outputs: &[(&wgpu::Buffer, u64)],
    ) -> Result<Vec<u32>, GpuError> {
        let f = self.frame.as_ref().expect("frame_for before");
        for (buffer, data) in inputs {
            self.queue.write_buffer(buffer, 0, data);
        }
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.clear_buffer(&f.strong, 0, None);
        Self::pass(&mut encoder, None, 0, dispatches);
        let (words, ()) = self.submit_and_read(encoder, scope, outputs, false, || (), |words, _| words.to_vec())?;
        Ok(words)
    }

    /// The raw depth's conversion to metres alone on the GPU: the stage's GPU-vs-CPU test.
    pub fn metres_alone(&mut self, frame: &DepthFrame) -> Result<Grid<f32>, GpuError> {
        let (w, h) = DepthUpload::Raw(frame).size()?;
        self.frame_for(w, h);
        self.upload_raw(frame);
        let f = self.frame.as_ref().expect("made above");
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let words = self.stage_alone(
            &[],
            &[(self.metres.entry("main"), &f.groups.metres, size)],
            &[(&f.depth[0], frame.pixels.len() as u64 * 4)],
        )?;
        Ok(Grid { width: w as usize, height: h as usize, data: words.into_iter().map(f32::from_bits).collect() })
    }

    /// Hysteresis alone on the GPU, from classify's classes: the stage's GPU-vs-CPU test.
    pub fn hysteresis_alone(&mut self, class: &Grid<u8>, cfg: &PipelineConfig) -> Result<Grid<u8>, GpuError> {
        let (w, h) = (class.width as u32, class.height as u32);
        self.frame_for(w, h);
        self.write_uniforms(w, h, None, cfg);
        let f = self.frame.as_ref().expect("made above");
        let class32: Vec<u32> = class.data.iter().map(|&c| c as u32).collect();
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let words = self.stage_alone(
            &[(&f.class, bytemuck::cast_slice(&class32))],
            &self.hysteresis_dispatches(size),
            &[(&f.edges, class.data.len() as u64 * 4)],
        )?;
        Ok(Grid { width: class.width, height: class.height, data: words.into_iter().map(|e| e as u8).collect() })
    }

    /// The closed boundary alone on the GPU, from Canny's edges, the smoothed depth and the normals.
    pub fn boundary_alone(
        &mut self,
        canny: &Grid<u8>,
        smoothed: &Grid<f32>,
        normals: &Grid<[f32; 3]>,
        cfg: &PipelineConfig,
    ) -> Result<Grid<u8>, GpuError> {
        let (w, h) = (canny.width as u32, canny.height as u32);
        self.frame_for(w, h);
        self.write_uniforms(w, h, None, cfg);
        let f = self.frame.as_ref().expect("made above");
        let edges: Vec<u32> = canny.data.iter().map(|&c| c as u32).collect();
        let inputs: [(&wgpu::Buffer, &[u8]); 3] = [
            (&f.edges, bytemuck::cast_slice(&edges)),
            (&f.depth[0], bytemuck::cast_slice(&smoothed.data)),
            (&f.normals, bytemuck::cast_slice(&normals.data)),
        ];
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let words =
            self.stage_alone(&inputs, &self.boundary_dispatches(size), &[(&f.boundary, canny.data.len() as u64 * 4)])?;
        Ok(Grid { width: canny.width, height: canny.height, data: words.into_iter().map(|b| b as u8).collect() })
    }

    /// The regions' components alone on the GPU, from a boundary: root + 1 labels.
    pub fn regions_alone(&mut self, boundary: &Grid<u8>) -> Result<Grid<u32>, GpuError> {
        let (w, h) = (boundary.width as u32, boundary.height as u32);
        self.frame_for(w, h);
        let f = self.frame.as_ref().expect("made above");
        let mask: Vec<u32> = boundary.data.iter().map(|&b| b as u32).collect();
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let dispatches = self.components_dispatches(&f.groups.regions, size);
        let words = self.stage_alone(
            &[(&f.boundary, bytemuck::cast_slice(&mask))],
            &dispatches,
            &[(&f.regions, mask.len() as u64 * 4)],
        )?;
        Ok(Grid { width: boundary.width, height: boundary.height, data: words })
    }

    /// The diffusion's steps alone on the GPU, from depth in metres: the stage's GPU-vs-CPU test.
    pub fn diffusion_alone(&mut self, depth: &Grid<f32>, cfg: &PipelineConfig) -> Result<Grid<f32>, GpuError> {
        let (w, h) = (depth.width as u32, depth.height as u32);
        if w.max(h) > DIFFUSION_MAX_LINE {
            return Err(GpuError::TooLarge { width: w, height: h });
        }
        self.frame_for(w, h);
        self.write_uniforms(w, h, None, cfg);
        let f = self.frame.as_ref().expect("made above");
        let diffuse = self.diffusion.entry("main");
        let steps: Vec<Dispatch> = (0..DiffusionSchedule::of(cfg).steps)
            .flat_map(|_| [(diffuse, &f.groups.diffusion[0], [h, 1]), (diffuse, &f.groups.diffusion[1], [w, 1])])
            .collect();
        let words = self.stage_alone(
            &[(&f.depth[0], bytemuck::cast_slice(&depth.data))],
            &steps,
            &[(&f.depth[0], depth.data.len() as u64 * 4)],
        )?;
        Ok(Grid { width: depth.width, height: depth.height, data: words.into_iter().map(f32::from_bits).collect() })
    }

    /// The normal field's gradient alone on the GPU, from interleaved normals.
    pub fn gradient_alone(&mut self, normals: &Grid<[f32; 3]>, cfg: &PipelineConfig) -> Result<Gradient, GpuError> {
        let (w, h) = (normals.width as u32, normals.height as u32);
        self.frame_for(w, h);
        self.write_uniforms(w, h, None, cfg);
        let f = self.frame.as_ref().expect("made above");
        let n = normals.data.len();
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let words = self.stage_alone(
            &[(&f.normals, bytemuck::cast_slice(&normals.data))],
            &[(self.gradient.entry("main"), &f.groups.gradient, size)],
            &[(&f.magnitude, n as u64 * 4), (&f.sector, n as u64 * 4)],
        )?;
        let (magnitude, sector) = words.split_at(n);
        let grid = |data| Grid { width: normals.width, height: normals.height, data };
        Ok(Gradient {
            magnitude: grid(magnitude.iter().map(|&m| f32::from_bits(m)).collect()),
            sector: Grid {
                width: normals.width,
                height: normals.height,
                data: sector.iter().map(|&s| s as u8).collect(),
            },
        })
    }

    /// Non-maximum suppression and the double threshold alone on the GPU, from a gradient.
    pub fn classify_alone(&mut self, grad: &Gradient, cfg: &PipelineConfig) -> Result<Grid<u8>, GpuError> {
        let (w, h) = (grad.magnitude.width as u32, grad.magnitude.height as u32);
        self.frame_for(w, h);
        self.write_uniforms(w, h, None, cfg);
        let f = self.frame.as_ref().expect("made above");
        let sectors: Vec<u32> = grad.sector.data.iter().map(|&s| s as u32).collect();
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let words = self.stage_alone(
            &[(&f.magnitude, bytemuck::cast_slice(&grad.magnitude.data)), (&f.sector, bytemuck::cast_slice(&sectors))],
            &[(self.classify.entry("main"), &f.groups.classify, size)],
            &[(&f.class, sectors.len() as u64 * 4)],
        )?;
        Ok(Grid {
            width: grad.magnitude.width,
            height: grad.magnitude.height,
            data: words.into_iter().map(|c| c as u8).collect(),
        })
    }

    /// The morphology alone on the GPU: the boundary's closing of a mask (its first four
    /// passes, `closing_passes` of `closing_kernel_px`).
    pub fn closing_alone(&mut self, mask: &Grid<u8>, cfg: &PipelineConfig) -> Result<Grid<u8>, GpuError> {
        let (w, h) = (mask.width as u32, mask.height as u32);
        self.frame_for(w, h);
        self.write_uniforms(w, h, None, cfg);
        let f = self.frame.as_ref().expect("made above");
        let words32: Vec<u32> = mask.data.iter().map(|&m| m as u32).collect();
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let morph = self.morphology.entry("main");
        let passes: Vec<Dispatch> = f.groups.morphology[..4].iter().map(|group| (morph, group, size)).collect();
        let words = self.stage_alone(
            &[(&f.lines, bytemuck::cast_slice(&words32))],
            &passes,
            &[(&f.closed, words32.len() as u64 * 4)],
        )?;
        Ok(Grid { width: mask.width, height: mask.height, data: words.into_iter().map(|m| m as u8).collect() })
    }

    /// Inlier counts of every (region, hypothesis), row-major by region: one dispatch
    /// for the whole frame, the same numbers as `cpu::ransac::score_hypotheses`.
    pub fn score_hypotheses(
        &mut self,
        batch: &PointBatch,
        hypotheses: u32,
        inlier_distance: f32,
    ) -> Result<Vec<u32>, GpuError> {
        let regions = batch.ranges.len() as u32;
        let total = regions * hypotheses;
        if total == 0 {
            return Ok(Vec::new());
        }
        // The scoring subsets and the planes, not every point: a few hundred kB where the
        // regions' points are megabytes.
        let scoring = ScoringBatch::new(batch, hypotheses);
        let points = scoring.coords.len() as u64 / 3;
        let fits = |b: &RansacBuffers| b.points >= points && b.regions >= regions as u64 && b.hypotheses >= hypotheses;
        if !self.ransac_buffers.as_ref().is_some_and(fits) {
            let (points, regions) =
                (points.next_power_of_two().max(4096), (regions as u64).next_power_of_two().max(64));
            let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
            let params = self.uniform(bytemuck::bytes_of(&<RansacParams as bytemuck::Zeroable>::zeroed()));
            let coords = self.buffer("scoring points", points * 12, storage);
            let ranges = self.buffer("ranges", regions * 8, storage);
            let planes = self.buffer("planes", regions * hypotheses as u64 * 16, storage);
            let score_bytes = regions * hypotheses as u64 * 4;
            let scores = self.buffer("scores", score_bytes, IMAGE);
            let staging =
                self.buffer("scores read", score_bytes, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
            let group = self.bind(&self.ransac, &[&params, &coords, &ranges, &planes, &scores]);
            self.ransac_buffers = Some(RansacBuffers {
                points,
                regions,
                hypotheses,
                params,
                coords,
                ranges,
                planes,
                scores,
                staging,
                group,
            });
        }
        let b = self.ransac_buffers.as_ref().expect("made above");
        let params = RansacParams { hypotheses, regions, inlier_distance, points: points as u32 };
        self.queue.write_buffer(&b.params, 0, bytemuck::bytes_of(&params));
        if points > 0 {
            self.queue.write_buffer(&b.coords, 0, bytemuck::cast_slice(&scoring.coords));
        }
        self.queue.write_buffer(&b.ranges, 0, bytemuck::cast_slice(&scoring.ranges));
        self.queue.write_buffer(&b.planes, 0, bytemuck::cast_slice(&scoring.planes));
        let bytes = total as u64 * 4;
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        // At most 65535 workgroups per dimension: wrap into y.
        Self::pass(
            &mut encoder,
            None,
            0,
            &[(self.ransac.entry("main"), &b.group, [total.min(65535), total.div_ceil(65535)])],
        );
        encoder.copy_buffer_to_buffer(&b.scores, 0, &b.staging, 0, bytes);
        self.submit(encoder, scope)?;
        self.map(&b.staging, bytes, |data| bytemuck::cast_slice(data).to_vec())
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
