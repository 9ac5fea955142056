//! Per-frame polygon extraction: depth frame + intrinsics -> planar polygons in the
//! camera frame.
//!
//! Stages: diffusion -> normals -> Canny on normals (+ depth steps, no-normal pixels)
//! -> close -> connected regions -> batched RANSAC + refit -> leaks split, coplanar
//! pieces joined, regions grown -> polygons ray cast onto their planes. Every stage up
//! to the regions is a WGSL shader in shaders/ with its CPU twin in `cpu/`; one
//! orchestration (`extract_with`) runs a frame on either twin.

pub mod cloud;
pub mod cpu;
pub mod debug;
pub mod gpu;
pub mod params;
pub mod polygon;
pub mod regions;
pub mod trim;
pub mod uncertainty;

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use crate::config::{Backend, PipelineConfig};
pub use crate::grid::Grid;
use crate::types::{DepthFrame, Intrinsics};
use cloud::Cloud;
use cpu::ransac::{PlaneFit, PointBatch};
pub use params::{Images, MIN_REGION_PIXELS, StageTimes};
pub use polygon::{FramePolygons, HeldBack, HoldBack, Polygon, VertexKind, build_polygons};
use regions::{Outline, Segmentation, segment_and_fit};
pub use uncertainty::Footing;

/// Why a frame could not be processed.
#[derive(Debug, thiserror::Error)]
pub enum ExtractError {
    #[error("depth frame is {got_w}x{got_h} with {len} pixels, the intrinsics say {want_w}x{want_h}")]
    SizeMismatch { got_w: u32, got_h: u32, len: usize, want_w: u32, want_h: u32 },
    #[error("depth frame's depth_scale {0} is not a positive number of metres per unit")]
    BadDepthScale(f64),
    #[error(transparent)]
    Gpu(#[from] gpu::GpuError),
}

/// What extraction makes of one frame.
#[derive(Clone, Debug)]
pub struct Extraction {
    pub polygons: FramePolygons,
    /// The frame in metres (0: invalid): what the map checks its polygons against.
    pub depth: Grid<f32>,
    pub stages: Stages,
    pub times: StageTimes,
}

/// What a frame went through, for debug pictures and the twin comparisons.
#[derive(Clone, Debug)]
pub struct Stages {
    /// The per-pixel stages' images: always from the CPU twin; from the GPU only when
    /// asked for (`Extractor::keep_images`), as they would be most of its readback.
    pub images: Option<Images>,
    pub labels: Grid<u32>,
    pub regions: Vec<Outline>,
    pub fits: Vec<Option<PlaneFit>>,
    /// The polygons outlined but not published, and why.
    pub held_back: Vec<HeldBack>,
}

/// Depth units to metres (0 stays invalid), checking the frame against the intrinsics.
pub fn depth_metres(frame: &DepthFrame, intr: &Intrinsics) -> Result<Grid<f32>, ExtractError> {
    check_frame(frame, intr)?;
    Ok(cpu::metres::metres(frame))
}

/// Whether a frame is one the stages can take: the intrinsics' size, as many pixels, and
/// a positive, finite depth scale.
fn check_frame(frame: &DepthFrame, intr: &Intrinsics) -> Result<(), ExtractError> {
    if frame.width != intr.width || frame.height != intr.height || frame.pixels.len() != intr.pixel_count() {
        return Err(ExtractError::SizeMismatch {
            got_w: frame.width,
            got_h: frame.height,
            len: frame.pixels.len(),
            want_w: intr.width,
            want_h: intr.height,
        });
    }
    if !(frame.depth_scale.is_finite() && frame.depth_scale > 0.0) {
        return Err(ExtractError::BadDepthScale(frame.depth_scale));
    }
    Ok(())
}

/// The extractor of a running pipeline: the backend chosen by config, and its state.
pub struct Extractor {
    /// The GPU twin's device and state; None: the CPU twin runs the stages.
    pub gpu: Option<Box<gpu::Gpu>>,
    /// With `auto` on a software adapter: the first frame times both twins and keeps the faster.
    race_first_frame: bool,
    pub cfg: PipelineConfig,
    /// Whether the GPU reads the intermediate images back (for debug pictures).
    pub keep_images: bool,
}

impl Extractor {
    /// Opens the configured backend. `gpu` fails without a Vulkan adapter; `auto` falls
    /// back to the CPU twin then, and says so once in the log.
    pub fn new(cfg: &PipelineConfig) -> Result<Extractor, ExtractError> {
        let (gpu, race_first_frame) = match cfg.backend {
            Backend::Cpu => (None, false),
            Backend::Gpu => {
                let gpu = gpu::Gpu::new()?;
                tracing::info!("extraction on the GPU: {}", gpu.describe());
                (Some(Box::new(gpu)), false)
            }
            Backend::Auto => match gpu::Gpu::new() {
                Ok(gpu) if gpu.is_software() => (Some(Box::new(gpu)), true),
                Ok(gpu) => {
                    tracing::info!("extraction on the GPU: {}", gpu.describe());
                    (Some(Box::new(gpu)), false)
                }
                Err(e) => {
                    tracing::info!("extraction on the CPU twin: {e}");
                    (None, false)
                }
            },
        };
        Ok(Extractor { gpu, race_first_frame, cfg: cfg.clone(), keep_images: false })
    }

    /// The twin that runs the frames: `Backend::Gpu` or `Backend::Cpu`, never `Auto`.
    pub fn backend(&self) -> Backend {
        if self.gpu.is_some() { Backend::Gpu } else { Backend::Cpu }
    }

    pub fn extract(&mut self, frame: &DepthFrame, intr: &Intrinsics) -> Result<Extraction, ExtractError> {
        // On a pool thread, whichever twin: every parallel loop of the frame (the CPU
        // twin's stages, and regions, fits and polygons after the GPU's) then starts where
        // it is called, instead of each one waking a worker and putting this thread to
        // sleep (dozens of hand-offs a frame; docs/speed-history.md has their cost).
        let frame_over = AtomicBool::new(false);
        rayon::scope(|s| {
            let home = rayon::current_thread_index();
            for _ in 1..rayon::current_num_threads() {
                let over = &frame_over;
                s.spawn(move |_| take_work_until(over, home));
            }
            let _over = SetOnDrop(&frame_over);
            self.extract_on_pool(frame, intr)
        })
    }

    fn extract_on_pool(&mut self, frame: &DepthFrame, intr: &Intrinsics) -> Result<Extraction, ExtractError> {
        let keep = self.keep_images;
        if std::mem::take(&mut self.race_first_frame)
            && let Some(gpu) = &mut self.gpu
        {
            // The first GPU run compiles and allocates: time the second.
            extract_with(Some(gpu), frame, intr, &self.cfg, keep)?;
            let gpu_ms = extract_with(Some(gpu), frame, intr, &self.cfg, keep)?.times.total;
            let cpu = extract_cpu(frame, intr, &self.cfg)?;
            let name = gpu.describe();
            if cpu.times.total < gpu_ms {
                tracing::info!(
                    "extraction on the CPU twin: the only adapter, {name}, is software and slower ({gpu_ms:.1} ms vs {:.1} ms a frame)",
                    cpu.times.total
                );
                self.gpu = None;
                return Ok(cpu);
            }
            tracing::info!(
                "extraction on the GPU: {name} ({gpu_ms:.1} ms vs the CPU twin's {:.1} ms a frame)",
                cpu.times.total
            );
        }
        extract_with(self.gpu.as_deref_mut(), frame, intr, &self.cfg, keep)
    }
}

/// Runs the pool's pending work until `over` is set, on a worker other than `home` (the
/// frame's own, which returns at once: it would wait for itself), yielding the core to
/// other threads whenever none is pending. The other workers so stay awake for the whole
/// frame: between two parallel loops they fell asleep, and waking one took longer than
/// most of the frame's loops.
fn take_work_until(over: &AtomicBool, home: Option<usize>) {
    if rayon::current_thread_index() == home {
        return;
    }
    while !over.load(Ordering::Acquire) {
        if rayon::yield_now() != Some(rayon::Yield::Executed) {
            std::thread::yield_now();
        }
    }
}

/// Sets its flag when dropped, however the scope it guards ends.
struct SetOnDrop<'a>(&'a AtomicBool);

impl Drop for SetOnDrop<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Release);
    }
}

/// Milliseconds since the last call, for stage times.
pub(crate) fn stopwatch() -> impl FnMut() -> f64 {
    let mut last = Instant::now();
    move || {
        let now = Instant::now();
        let ms = (now - last).as_secs_f64() * 1e3;
        last = now;
        ms
    }
}

/// Extracts a frame's polygons on the CPU twin, keeping every stage's image.
pub fn extract_cpu(frame: &DepthFrame, intr: &Intrinsics, cfg: &PipelineConfig) -> Result<Extraction, ExtractError> {
    extract_with(None, frame, intr, cfg, true)
}

/// Extracts a frame's polygons with the per-pixel stages and the RANSAC scoring on the
/// GPU; `keep_images` reads the intermediate images back too.
pub fn extract_gpu(
    gpu: &mut gpu::Gpu,
    frame: &DepthFrame,
    intr: &Intrinsics,
    cfg: &PipelineConfig,
    keep_images: bool,
) -> Result<Extraction, ExtractError> {
    extract_with(Some(gpu), frame, intr, cfg, keep_images)
}

/// One frame, every stage, on the GPU twin where `gpu` is given, else the CPU twin: the
/// per-pixel stages up to the region labels (one submit on the GPU), then the plane fits
/// (RANSAC scored by the twin), the region clean-up, outlines and polygons.
pub fn extract_with(
    gpu: Option<&mut gpu::Gpu>,
    frame: &DepthFrame,
    intr: &Intrinsics,
    cfg: &PipelineConfig,
    keep_images: bool,
) -> Result<Extraction, ExtractError> {
    let mut times = StageTimes::default();
    let t0 = Instant::now();
    let mut lap = stopwatch();
    let (images, seg, depth, mut gpu) = match gpu {
        None => {
            params::ran(params::Stage::Metres);
            let depth = depth_metres(frame, intr)?;
            times.upload = lap();
            let images = cpu::image_stages(&depth, intr, cfg, &mut times, &mut lap);
            params::ran(params::Stage::Regions);
            let seg = Segmentation::components(&images.boundary, MIN_REGION_PIXELS);
            (Some(images), seg, depth, None)
        }
        Some(gpu) => {
            // Checked before anything is uploaded; the GPU converts the raw frame to metres,
            // and the CPU its own copy while the GPU works.
            check_frame(frame, intr)?;
            let (out, depth) =
                gpu.image_stages(gpu::DepthUpload::Raw(frame), intr, cfg, keep_images, || cpu::metres::metres(frame))?;
            // The upload, the submit, the readback and the numbering.
            let ms = lap();
            let t = out.times;
            [times.diffusion, times.normals, times.edges] = [t.diffusion, t.normals, t.edges];
            times.upload = t.upload + t.metres;
            times.regions = t.regions + t.numbering;
            times.gpu_busy = t.busy;
            times.readback = (ms - times.upload - t.diffusion - t.normals - t.edges - times.regions).max(0.0);
            (out.images, out.regions, depth, Some(gpu))
        }
    };
    let cloud = Cloud::new(&depth, intr);
    times.regions += lap();
    let (hyp, dist) = (cfg.ransac_hypotheses, cfg.ransac_inlier_distance_m as f32);
    let fit = |batch: &PointBatch| match gpu.as_deref_mut() {
        None => Ok(cpu::ransac::fit_planes(batch, hyp, dist)),
        Some(gpu) => Ok(cpu::ransac::fits_from_scores(batch, &gpu.score_hypotheses(batch, hyp, dist)?, hyp, dist)),
    };
    let (seg, regions, fits, creases) = segment_and_fit(seg, &cloud, cfg, fit, &mut times, &mut lap)?;
    let (polygons, held_back) = build_polygons(&regions, &fits, &seg, &creases, &depth, intr, cfg);
    times.polygons = lap();
    times.total = t0.elapsed().as_secs_f64() * 1e3;
    let stages = Stages { images, labels: seg.labels, regions, fits, held_back };
    Ok(Extraction { polygons: FramePolygons { stamp_ns: frame.stamp_ns, polygons }, depth, stages, times })
}
