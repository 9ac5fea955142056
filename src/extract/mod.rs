//! Per-frame polygon extraction: depth frame + intrinsics -> planar polygons in the
//! camera frame.
//!
//! Stages: diffusion -> normals -> Canny on normals (+ depth steps, no-normal pixels)
//! -> close -> regions with holes (CPU) -> batched RANSAC + refit -> polygons ray cast
//! onto their planes. Each image stage has a CPU twin in `cpu/`.

pub mod contours;
pub mod cpu;
pub mod debug;
pub mod gpu;
pub mod segment;
pub mod trim;

use std::time::Instant;

use nalgebra::{Isometry3, Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::config::{Backend, PipelineConfig};
use crate::types::{DepthFrame, Intrinsics, StampNs};
use contours::Region;
use cpu::ransac::{PlaneFit, PointBatch};
use segment::Segmentation;

/// A row-major image of any pixel type.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid<T> {
    pub width: usize,
    pub height: usize,
    pub data: Vec<T>,
}

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

/// One planar polygon: plane n . p + d = 0 (n faces the camera), outline and holes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Polygon {
    pub id: u32,
    pub normal: [f64; 3],
    pub offset: f64,
    /// Area on the plane, holes excluded, m^2.
    pub area: f64,
    pub boundary: Vec<[f64; 3]>,
    pub holes: Vec<Vec<[f64; 3]>>,
    pub pixel_count: usize,
    pub inlier_ratio: f64,
    /// RMS point-to-plane distance of the inliers, m.
    pub rms: f64,
}

impl Polygon {
    /// The same polygon in another frame: `t` maps this polygon's frame into it.
    pub fn transformed(&self, t: &Isometry3<f64>) -> Polygon {
        let p = |v: &[f64; 3]| {
            let q = t * Point3::new(v[0], v[1], v[2]);
            [q.x, q.y, q.z]
        };
        let n = t.rotation * Vector3::from(self.normal);
        // A point on the plane moves with t; the offset follows from it.
        let on_plane = t * Point3::from(Vector3::from(self.normal) * -self.offset);
        Polygon {
            normal: [n.x, n.y, n.z],
            offset: -n.dot(&on_plane.coords),
            boundary: self.boundary.iter().map(p).collect(),
            holes: self.holes.iter().map(|h| h.iter().map(p).collect()).collect(),
            ..self.clone()
        }
    }

    /// Area-weighted centroid of the outer boundary (holes ignored), m.
    pub fn centroid(&self) -> [f64; 3] {
        let pts: Vec<Vector3<f64>> = self.boundary.iter().map(|v| Vector3::from(*v)).collect();
        let mut acc = Vector3::zeros();
        let mut total = 0.0;
        for i in 1..pts.len().saturating_sub(1) {
            let a = (pts[i] - pts[0]).cross(&(pts[i + 1] - pts[0])).dot(&Vector3::from(self.normal)) / 2.0;
            acc += (pts[0] + pts[i] + pts[i + 1]) / 3.0 * a;
            total += a;
        }
        let c =
            if total.abs() > 1e-12 { acc / total } else { pts.iter().sum::<Vector3<f64>>() / pts.len().max(1) as f64 };
        [c.x, c.y, c.z]
    }
}

/// A frame's polygons.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FramePolygons {
    pub stamp_ns: StampNs,
    pub polygons: Vec<Polygon>,
}

/// Milliseconds spent in each stage of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct StageTimes {
    pub upload: f64,
    pub diffusion: f64,
    pub normals: f64,
    pub edges: f64,
    pub contours: f64,
    pub ransac: f64,
    pub polygons: f64,
    pub total: f64,
}

/// Every intermediate image, for debug pictures and the twin comparisons.
#[derive(Clone, Debug)]
pub struct Stages {
    pub depth: Grid<f32>,
    pub smoothed: Grid<f32>,
    pub normals: Grid<[f32; 3]>,
    pub canny: Grid<u8>,
    /// Closed edge lines (Canny + depth steps) plus no-normal pixels: 1 = not inside any region.
    pub boundary: Grid<u8>,
    pub labels: Grid<u32>,
    pub regions: Vec<Region>,
    pub fits: Vec<Option<PlaneFit>>,
}

/// Smallest region worth a plane fit, pixels (the area test comes after the fit).
const MIN_REGION_PIXELS: usize = 30;

/// Depth units to metres (0 stays invalid), checking the frame against the intrinsics.
pub fn depth_metres(frame: &DepthFrame, intr: &Intrinsics) -> Result<Grid<f32>, ExtractError> {
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
    let s = frame.depth_scale as f32;
    Ok(Grid {
        width: intr.width as usize,
        height: intr.height as usize,
        data: frame.pixels.iter().map(|&d| d as f32 * s).collect(),
    })
}

/// Which twin runs the stages.
pub enum Engine {
    Cpu,
    Gpu(Box<gpu::Gpu>),
}

/// The extractor of a running pipeline: the backend chosen by config, and its state.
pub struct Extractor {
    pub engine: Engine,
    /// With `auto` on a software adapter: the first frame times both twins and keeps the faster.
    race_first_frame: bool,
    pub cfg: PipelineConfig,
}

impl Extractor {
    /// Opens the configured backend. `gpu` fails without a Vulkan adapter; `auto` falls
    /// back to the CPU twin then, and says so once in the log.
    pub fn new(cfg: &PipelineConfig) -> Result<Extractor, ExtractError> {
        let (engine, race_first_frame) = match cfg.backend {
            Backend::Cpu => (Engine::Cpu, false),
            Backend::Gpu => {
                let gpu = gpu::Gpu::new()?;
                tracing::info!("extraction on the GPU: {}", gpu.describe());
                (Engine::Gpu(Box::new(gpu)), false)
            }
            Backend::Auto => match gpu::Gpu::new() {
                Ok(gpu) if gpu.is_software() => (Engine::Gpu(Box::new(gpu)), true),
                Ok(gpu) => {
                    tracing::info!("extraction on the GPU: {}", gpu.describe());
                    (Engine::Gpu(Box::new(gpu)), false)
                }
                Err(e) => {
                    tracing::info!("extraction on the CPU twin: {e}");
                    (Engine::Cpu, false)
                }
            },
        };
        Ok(Extractor { engine, race_first_frame, cfg: cfg.clone() })
    }

    /// "gpu" or "cpu".
    pub fn backend(&self) -> &'static str {
        match self.engine {
            Engine::Cpu => "cpu",
            Engine::Gpu(_) => "gpu",
        }
    }

    pub fn extract(
        &mut self,
        frame: &DepthFrame,
        intr: &Intrinsics,
    ) -> Result<(FramePolygons, Stages, StageTimes), ExtractError> {
        // On a pool thread, whichever engine: every parallel loop of the frame (the CPU
        // twin's stages, and regions, fits and polygons after the GPU's) then starts where
        // it is called, instead of each one waking a worker and putting this thread to
        // sleep (dozens of hand-offs a frame, 40 % of a one-thread CPU frame).
        rayon::scope(|_| self.extract_on_pool(frame, intr))
    }

    fn extract_on_pool(
        &mut self,
        frame: &DepthFrame,
        intr: &Intrinsics,
    ) -> Result<(FramePolygons, Stages, StageTimes), ExtractError> {
        if std::mem::take(&mut self.race_first_frame)
            && let Engine::Gpu(gpu) = &mut self.engine
        {
            // The first GPU run compiles and allocates: time the second.
            extract_gpu(gpu, frame, intr, &self.cfg)?;
            let gpu_ms = extract_gpu(gpu, frame, intr, &self.cfg)?.2.total;
            let cpu = extract_cpu(frame, intr, &self.cfg)?;
            let name = gpu.describe();
            if cpu.2.total < gpu_ms {
                tracing::info!(
                    "extraction on the CPU twin: the only adapter, {name}, is software and slower ({gpu_ms:.1} ms vs {:.1} ms a frame)",
                    cpu.2.total
                );
                self.engine = Engine::Cpu;
                return Ok(cpu);
            }
            tracing::info!(
                "extraction on the GPU: {name} ({gpu_ms:.1} ms vs the CPU twin's {:.1} ms a frame)",
                cpu.2.total
            );
        }
        match &mut self.engine {
            Engine::Cpu => extract_cpu(frame, intr, &self.cfg),
            Engine::Gpu(gpu) => extract_gpu(gpu, frame, intr, &self.cfg),
        }
    }
}

/// The 8-connected set of pixels reachable from `start` through pixels where `inside`
/// holds, marking them in `seen`.
pub fn flood(start: usize, w: usize, h: usize, seen: &mut [bool], inside: impl Fn(usize) -> bool) -> Vec<u32> {
    let mut out = Vec::new();
    let mut stack = vec![start];
    seen[start] = true;
    while let Some(i) = stack.pop() {
        out.push(i as u32);
        let (u, v) = ((i % w) as isize, (i / w) as isize);
        for dv in -1..=1 {
            for du in -1..=1 {
                let (nu, nv) = (u + du, v + dv);
                if nu < 0 || nv < 0 || nu >= w as isize || nv >= h as isize {
                    continue;
                }
                let j = nv as usize * w + nu as usize;
                if !seen[j] && inside(j) {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
    }
    out
}

/// 8-connected components of the pixels where `inside` holds: a label per pixel (0
/// outside; components numbered from 1 in the scan order of their first pixel) and
/// the number of components. Runs of pixels along rows are joined by union-find with
/// the runs they touch in the row above, so the work grows with the runs, not pixels.
pub fn label_components(inside: &[bool], w: usize, h: usize) -> (Vec<u32>, usize) {
    // Runs [start, end) of row v, in scan order, and their union-find parents.
    let mut runs: Vec<(usize, usize, usize)> = Vec::new();
    let mut parent: Vec<u32> = Vec::new();
    fn root(parent: &mut [u32], mut r: u32) -> u32 {
        while parent[r as usize] != r {
            parent[r as usize] = parent[parent[r as usize] as usize];
            r = parent[r as usize];
        }
        r
    }
    let mut above = 0..0;
    for v in 0..h {
        let row = &inside[v * w..(v + 1) * w];
        let first = runs.len();
        let mut u = 0;
        while u < w {
            if !row[u] {
                u += 1;
                continue;
            }
            let start = u;
            while u < w && row[u] {
                u += 1;
            }
            let me = runs.len() as u32;
            runs.push((v, start, u));
            parent.push(me);
            // Runs above touching columns start - 1 ..= u (diagonals included); both rows'
            // runs are in column order, so the first candidate only moves right.
            while above.start < above.end && runs[above.start].2 < start {
                above.start += 1;
            }
            for k in above.clone() {
                if runs[k].1 > u {
                    break;
                }
                let (a, b) = (root(&mut parent, k as u32), root(&mut parent, me));
                // The older root stays root, so a component's root is its first run.
                parent[a.max(b) as usize] = a.min(b);
            }
        }
        above = first..runs.len();
    }
    let mut labels = vec![0u32; w * h];
    let mut label_of_root = vec![0u32; runs.len()];
    let mut count = 0;
    for (k, &(v, s, e)) in runs.iter().enumerate() {
        let r = root(&mut parent, k as u32) as usize;
        if label_of_root[r] == 0 {
            count += 1;
            label_of_root[r] = count as u32;
        }
        labels[v * w + s..v * w + e].fill(label_of_root[r]);
    }
    (labels, count)
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

/// Extracts a frame's polygons on the CPU, keeping every stage's image.
pub fn extract_cpu(
    frame: &DepthFrame,
    intr: &Intrinsics,
    cfg: &PipelineConfig,
) -> Result<(FramePolygons, Stages, StageTimes), ExtractError> {
    let mut times = StageTimes::default();
    let t0 = Instant::now();
    let mut lap = stopwatch();
    let depth = depth_metres(frame, intr)?;
    times.upload = lap();
    let smoothed = cpu::diffusion::diffuse(
        &depth,
        cfg.diffusion_iterations,
        cfg.diffusion_kappa_m as f32,
        cfg.diffusion_gamma as f32,
    );
    times.diffusion = lap();
    let normals = cpu::normals::normals(&smoothed, intr, cfg.normal_kernel);
    times.normals = lap();
    let grad = cpu::canny::normal_gradient(&normals);
    let class = cpu::canny::classify(&grad, cfg.canny_low as f32, cfg.canny_high as f32);
    let fit = |batch: &PointBatch| {
        Ok(cpu::ransac::fit_planes(batch, cfg.ransac_hypotheses, cfg.ransac_inlier_distance_m as f32))
    };
    let (polygons, stages) = finish(depth, smoothed, normals, &class, intr, cfg, fit, &mut times, &mut lap)?;
    times.total = t0.elapsed().as_secs_f64() * 1e3;
    Ok((FramePolygons { stamp_ns: frame.stamp_ns, polygons }, stages, times))
}

/// Extracts a frame's polygons with the image stages and the RANSAC scoring on the GPU.
pub fn extract_gpu(
    gpu: &mut gpu::Gpu,
    frame: &DepthFrame,
    intr: &Intrinsics,
    cfg: &PipelineConfig,
) -> Result<(FramePolygons, Stages, StageTimes), ExtractError> {
    let mut times = StageTimes::default();
    let t0 = Instant::now();
    let depth = depth_metres(frame, intr)?;
    let out = gpu.image_stages(
        &depth,
        intr,
        cfg.diffusion_iterations,
        cfg.diffusion_kappa_m as f32,
        cfg.diffusion_gamma as f32,
        cfg.normal_kernel,
        cfg.canny_low as f32,
        cfg.canny_high as f32,
    )?;
    [times.upload, times.diffusion, times.normals, times.edges] = out.times;
    times.upload += t0.elapsed().as_secs_f64() * 1e3 - out.times.iter().sum::<f64>();
    let mut lap = stopwatch();
    let (hyp, dist) = (cfg.ransac_hypotheses, cfg.ransac_inlier_distance_m as f32);
    let gpu = &*gpu;
    let fit = |batch: &PointBatch| {
        let scores = gpu.score_hypotheses(batch, hyp, dist)?;
        Ok(cpu::ransac::fits_from_scores(batch, &scores, hyp, dist))
    };
    let (polygons, stages) =
        finish(depth, out.smoothed, out.normals, &out.class, intr, cfg, fit, &mut times, &mut lap)?;
    times.total = t0.elapsed().as_secs_f64() * 1e3;
    Ok((FramePolygons { stamp_ns: frame.stamp_ns, polygons }, stages, times))
}

/// The stages after the per-pixel ones, shared by both backends: hysteresis, depth
/// steps and closing, regions, plane fits (`fit` is the backend's), polygons.
#[allow(clippy::too_many_arguments)]
fn finish(
    depth: Grid<f32>,
    smoothed: Grid<f32>,
    normals: Grid<[f32; 3]>,
    class: &Grid<u8>,
    intr: &Intrinsics,
    cfg: &PipelineConfig,
    fit: impl FnMut(&PointBatch) -> Result<Vec<Option<PlaneFit>>, ExtractError>,
    times: &mut StageTimes,
    lap: &mut impl FnMut() -> f64,
) -> Result<(Vec<Polygon>, Stages), ExtractError> {
    let canny = cpu::canny::hysteresis(class);
    let boundary = cpu::canny::boundary(
        &canny,
        &smoothed,
        cfg.depth_edge_ratio as f32,
        &normals,
        cfg.closing_kernel_px,
        cfg.normal_kernel,
    );
    times.edges += lap();
    let (seg, regions, fits) = segment_and_fit(&depth, &boundary, intr, cfg, fit, times, lap)?;
    let polygons = build_polygons(&regions, &fits, &seg, &depth, intr, cfg);
    times.polygons = lap();
    Ok((polygons, Stages { depth, smoothed, normals, canny, boundary, labels: seg.labels, regions, fits }))
}

/// What segmentation hands on: the regions, their pixels, and each one's plane if it has one.
pub type Segmented = (Segmentation, Vec<Region>, Vec<Option<PlaneFit>>);

/// Regions from the boundary map, their planes (`fit` is the batched RANSAC + refit of
/// the backend), leaks split and fitted again, regions grown back to their true
/// borders, outlines traced. Times the RANSAC calls as `ransac`, the rest as `contours`.
pub fn segment_and_fit(
    depth: &Grid<f32>,
    boundary: &Grid<u8>,
    intr: &Intrinsics,
    cfg: &PipelineConfig,
    mut fit: impl FnMut(&PointBatch) -> Result<Vec<Option<PlaneFit>>, ExtractError>,
    times: &mut StageTimes,
    lap: &mut impl FnMut() -> f64,
) -> Result<Segmented, ExtractError> {
    let dist = cfg.ransac_inlier_distance_m as f32;
    let min_ratio = cfg.ransac_min_inlier_ratio;
    let mut seg = Segmentation::components(boundary, MIN_REGION_PIXELS);
    let all: Vec<usize> = (0..seg.pixels.len()).collect();
    let batch = seg.points(&all, depth, intr);
    times.contours = lap();
    let mut fits = fit(&batch)?;
    times.ransac = lap();
    let pieces = seg.split_leaks(&mut fits, depth, intr, dist, min_ratio, MIN_REGION_PIXELS);
    let batch = seg.points(&pieces, depth, intr);
    times.contours += lap();
    if !pieces.is_empty() {
        for (r, f) in pieces.iter().zip(fit(&batch)?) {
            fits[*r] = f;
        }
    }
    times.ransac += lap();
    let accepted: Vec<bool> = fits.iter().map(|f| f.is_some_and(|f| f.inlier_ratio() >= min_ratio)).collect();
    seg.grow(&fits, &accepted, depth, intr, dist, cfg.region_grow_px);
    let regions = contours::trace(&seg, cfg.simplify_tolerance_px);
    times.contours += lap();
    Ok((seg, regions, fits))
}

/// Polygons from regions and their plane fits: keep well-supported fits, ray cast the
/// pixel outlines onto the planes, cut them where the planes of their neighbours bound
/// them, drop what is smaller than the minimum area.
pub fn build_polygons(
    regions: &[Region],
    fits: &[Option<PlaneFit>],
    seg: &Segmentation,
    depth: &Grid<f32>,
    intr: &Intrinsics,
    cfg: &PipelineConfig,
) -> Vec<Polygon> {
    let mut out = Vec::new();
    let mut points = Vec::new();
    for (region, fit) in regions.iter().zip(fits) {
        let Some(fit) = fit else {
            tracing::debug!("region {} ({} px): no plane fit", region.label, region.pixels);
            continue;
        };
        if fit.inlier_ratio() < cfg.ransac_min_inlier_ratio {
            tracing::debug!(
                "region {} ({} px): inlier ratio {:.3} below {}",
                region.label,
                region.pixels,
                fit.inlier_ratio(),
                cfg.ransac_min_inlier_ratio
            );
            continue;
        }
        let onto_plane = |ring: &[[f32; 2]]| -> Option<Vec<[f64; 3]>> {
            ring.iter().map(|&[u, v]| ray_cast(&intr.ray(u as f64, v as f64), fit).map(|p| [p.x, p.y, p.z])).collect()
        };
        let Some(mut boundary) = onto_plane(&region.outer) else { continue };
        drop_border_vertices_onto_plane(&mut boundary, &region.outer, region.label, seg, depth, intr, fit);
        let n = fit.normal;
        out.push(Polygon {
            id: 0,
            normal: [n.x, n.y, n.z],
            offset: fit.offset,
            area: 0.0,
            boundary,
            holes: region.holes.iter().filter_map(|h| onto_plane(h)).collect(),
            pixel_count: region.pixels,
            inlier_ratio: fit.inlier_ratio(),
            rms: fit.rms,
        });
        points.push(seg.points(&[region.label as usize - 1], depth, intr).points);
    }
    trim::trim_at_neighbour_planes(&mut out, &points, cfg.ransac_inlier_distance_m);
    out.retain_mut(|p| {
        let n = Vector3::from(p.normal);
        // Holes smaller than a region worth keeping are sensor dropouts, not surface gaps.
        p.holes.retain(|h| ring_area(h, &n) >= cfg.min_polygon_area_m2);
        p.area = ring_area(&p.boundary, &n) - p.holes.iter().map(|h| ring_area(h, &n)).sum::<f64>();
        p.area >= cfg.min_polygon_area_m2
    });
    for (id, p) in out.iter_mut().enumerate() {
        p.id = id as u32;
    }
    out
}

/// Outline vertices within this many pixels of the image's edge are on its border.
const BORDER_PX: i64 = 3;

/// Where a region meets the image's border there are no normals to stop its growth, and
/// its pixels there can be the next surface's first (a riser above a far tread, within the
/// inlier distance of the tread's plane). Ray-cast onto the plane at a grazing angle they
/// land centimetres beyond the edge; their measured points, dropped straight onto the
/// plane, land where they are. So a border vertex moves by what dropping its pixel's point
/// instead of ray-casting it changes, when that pulls it towards the polygon's inside (a
/// pixel of the plane itself moves by its depth noise either way: only shrinking is safe).
fn drop_border_vertices_onto_plane(
    boundary: &mut [[f64; 3]],
    outline_px: &[[f32; 2]],
    label: u32,
    seg: &Segmentation,
    depth: &Grid<f32>,
    intr: &Intrinsics,
    fit: &PlaneFit,
) {
    let (w, h) = (depth.width as i64, depth.height as i64);
    let n = boundary.len().max(1) as f64;
    let centre = boundary.iter().fold(Vector3::zeros(), |acc, v| acc + Vector3::from(*v)) / n;
    for (vertex, &[u, v]) in boundary.iter_mut().zip(outline_px) {
        let (pu, pv) = ((u.round() as i64).clamp(0, w - 1), (v.round() as i64).clamp(0, h - 1));
        if pu >= BORDER_PX && pv >= BORDER_PX && pu < w - BORDER_PX && pv < h - BORDER_PX {
            continue;
        }
        // The region's pixel at the vertex (it lies half a pixel outside its pixels).
        let Some((x, y)) = (-1..=1)
            .flat_map(|dv| (-1..=1).map(move |du| (pu + du, pv + dv)))
            .filter(|&(x, y)| x >= 0 && y >= 0 && x < w && y < h)
            .find(|&(x, y)| {
                let i = (y * w + x) as usize;
                seg.labels.data[i] == label && depth.data[i] > 0.0
            })
        else {
            continue;
        };
        let ray = intr.ray(x as f64, y as f64);
        let measured = ray * depth.data[(y * w + x) as usize] as f64;
        let dropped = measured - fit.normal * (fit.normal.dot(&measured) + fit.offset);
        let Some(cast) = ray_cast(&ray, fit) else { continue };
        let shift = dropped - cast;
        let v3 = Vector3::from(*vertex);
        if shift.dot(&(centre - v3)) > 0.0 {
            let moved = v3 + shift;
            *vertex = [moved.x, moved.y, moved.z];
        }
    }
}

/// Where a camera ray meets a fitted plane in front of the camera.
fn ray_cast(ray: &Vector3<f64>, fit: &PlaneFit) -> Option<Vector3<f64>> {
    let t = -fit.offset / fit.normal.dot(ray);
    (t.is_finite() && t > 0.0).then(|| ray * t)
}

/// Area of a planar ring, m^2 (Newell's method, magnitude).
pub fn ring_area(ring: &[[f64; 3]], normal: &Vector3<f64>) -> f64 {
    let mut acc = Vector3::zeros();
    for i in 0..ring.len() {
        let (a, b) = (Vector3::from(ring[i]), Vector3::from(ring[(i + 1) % ring.len()]));
        acc += a.cross(&b);
    }
    (acc.dot(normal) / 2.0).abs()
}
