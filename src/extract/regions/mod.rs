//! Regions of one frame and their plane-driven clean-up, between the edge map and the
//! polygons (CPU, for both twins). `segment_and_fit` walks a frame's regions through the
//! jobs below in order, each in its own file:
//! - `runs`: regions numbered from the components (label runs to pixel lists);
//! - `fits`: the points a region's plane is fitted on, and the sample the polygon checks read;
//! - `leaks`: a region whose plane fits too few of its points is cut back to the plane's
//!   largest patch, the rest fitted again as new regions; one that fits enough gives up
//!   its large pieces of outliers (a second face) as new regions;
//! - `joins`: pieces of one plane cut apart by dropouts or stripes joined; creases between
//!   regions;
//! - `growth`: regions take back the border band the edges ate, onto their planes (then
//!   the joins once more, and growth again where they joined);
//! - `seeds`: the blobs of pixels no region took (a face the edges took whole) become
//!   regions, fitted, joined and grown like the rest;
//! - `borders`: where two regions meet, each pixel goes to the nearer of their planes;
//! - `scan`: the row and column scans the joins and creases read;
//! - `contours`: the outlines and holes of the regions that become polygons.

mod borders;
pub mod contours;
mod fits;
mod growth;
mod joins;
mod leaks;
mod runs;
mod scan;
mod seeds;
#[cfg(test)]
mod tests;

use std::ops::Range;

use super::cpu::ransac::{PlaneFit, PointBatch};
use super::{ExtractError, Grid, MIN_REGION_PIXELS, StageTimes};
use crate::config::PipelineConfig;
use crate::extract::cloud::Cloud;
use crate::grid::{component_runs, leading};
pub use contours::Outline;
use fits::{MAX_FIT_POINTS, refit_grown};
pub use fits::{MAX_SAMPLE_POINTS, PointSample};
pub use joins::{Creases, JoinCandidates};
pub use leaks::Leaks;
#[cfg(test)]
use runs::label_runs;
use runs::{par_label_runs, write_runs};

/// What segmentation hands on: the regions, their pixels, each one's plane if it has one,
/// and which of them meet along a crease.
pub type Segmented = (Segmentation, Vec<Outline>, Vec<Option<PlaneFit>>, Creases);

/// The regions' planes (`fit` is the batched RANSAC + refit of the twin), leaks split
/// and fitted again, coplanar pieces joined, regions grown back to their true borders
/// (joined and grown once more where growth brought pieces within reach), the pixels
/// where two meet given to the nearer plane, outlines
/// traced, creases found. Times the RANSAC calls as `ransac`, the rest as `contours`.
pub fn segment_and_fit(
    mut seg: Segmentation,
    cloud: &Cloud,
    cfg: &PipelineConfig,
    mut fit: impl FnMut(&PointBatch) -> Result<Vec<Option<PlaneFit>>, ExtractError> + Send,
    times: &mut StageTimes,
    lap: &mut (impl FnMut() -> f64 + Send),
) -> Result<Segmented, ExtractError> {
    let (dist, ratio) = (cfg.ransac_inlier_distance_m as f32, cfg.depth_edge_ratio as f32);
    let min_ratio = cfg.ransac_min_inlier_ratio;
    // The joins' scan reads the labels and the depth, and writes nothing the fits read: it
    // runs beside the fits' sample and the first fits (on another thread; one after the
    // other on one), which are serial in part. It runs again only in a frame where a split
    // (a leak, or a second face's outliers) has changed the labels.
    let (candidates, first_fits) = rayon::join(
        || seg.join_candidates(cloud, ratio),
        || {
            let all: Vec<usize> = (0..seg.pixels.len()).collect();
            let batch = seg.sampled_points(&all, cloud, MAX_FIT_POINTS);
            times.contours = lap();
            let fits = fit(&batch);
            times.ransac = lap();
            fits
        },
    );
    let mut fits = first_fits?;
    let leaks = seg.split_leaks(&mut fits, cloud, dist, min_ratio, MIN_REGION_PIXELS);
    fit_new(&seg, &leaks.pieces, cloud, &mut fits, &mut fit, times, lap)?;
    let candidates = if leaks.split.is_empty() { candidates } else { seg.join_candidates(cloud, ratio) };
    seg.join_coplanar(candidates, &mut fits, cloud, dist, min_ratio);
    let accepted_of = |fits: &[Option<PlaneFit>]| -> Vec<bool> {
        fits.iter().map(|f| f.is_some_and(|f| f.inlier_ratio() >= min_ratio)).collect()
    };
    let mut accepted = accepted_of(&fits);
    seg.grow(&fits, &accepted, cloud, dist, cfg.region_grow_px);
    // Growth narrows the bands between pieces of one plane to within a join's reach where
    // they were wider (a scanner's stripe of bad depth across a face): join once more, and
    // grow what joined.
    let candidates = seg.join_candidates(cloud, ratio);
    if seg.join_coplanar(candidates, &mut fits, cloud, dist, min_ratio) > 0 {
        accepted = accepted_of(&fits);
        seg.grow(&fits, &accepted, cloud, dist, cfg.region_grow_px);
    }
    // Faces the edges took whole lie in the blobs no region took: each blob a region,
    // fitted, joined to a neighbour whose plane it lies on, grown back to its border.
    let seeds = if cfg.seed_leftover_blobs { seg.seed_leftovers(cloud, MIN_REGION_PIXELS) } else { Vec::new() };
    if !seeds.is_empty() {
        fit_new(&seg, &seeds, cloud, &mut fits, &mut fit, times, lap)?;
        accepted = accepted_of(&fits);
        if seg.release_rejected(&seeds, &accepted, &mut fits) > 0 {
            let candidates = seg.join_candidates(cloud, ratio);
            seg.join_coplanar(candidates, &mut fits, cloud, dist, min_ratio);
            accepted = accepted_of(&fits);
            seg.grow(&fits, &accepted, cloud, dist, cfg.region_grow_px);
        }
    }
    // Where a crease's edge broke, one region ran past it as far as the other face stays
    // near its plane: the pixels go to the plane they lie nearer.
    seg.settle_borders(&fits, &accepted, cloud, dist);
    // Three jobs that only read the grown regions, side by side: each is a few tenths of a
    // millisecond that its own parallel loop, held up by the largest region, barely splits.
    let ((mut points, creases), mut regions) = rayon::join(
        || {
            rayon::join(
                || refit_grown(&seg, &mut fits, &accepted, cloud, dist, min_ratio),
                || seg.creases(cloud, ratio),
            )
        },
        // Outlines only for the planes that can become polygons: the refit keeps each
        // accepted region accepted and touches no other, so `accepted` still says which.
        || contours::trace(&seg, cfg.simplify_tolerance_px, &accepted),
    );
    for (region, points) in regions.iter_mut().zip(&mut points) {
        region.points = std::mem::take(points);
    }
    times.contours += lap();
    Ok((seg, regions, fits, creases))
}

/// Fits the regions made since the first fits (a leak's pieces, the seeds), in one batch:
/// the sample timed as `contours`, the fits as `ransac`.
fn fit_new(
    seg: &Segmentation,
    regions: &[usize],
    cloud: &Cloud,
    fits: &mut Vec<Option<PlaneFit>>,
    fit: &mut impl FnMut(&PointBatch) -> Result<Vec<Option<PlaneFit>>, ExtractError>,
    times: &mut StageTimes,
    lap: &mut impl FnMut() -> f64,
) -> Result<(), ExtractError> {
    let batch = seg.sampled_points(regions, cloud, MAX_FIT_POINTS);
    times.contours += lap();
    fits.resize(seg.pixels.len(), None);
    if !regions.is_empty() {
        for (&r, f) in regions.iter().zip(fit(&batch)?) {
            fits[r] = f;
        }
    }
    times.ransac += lap();
    Ok(())
}

/// Pixel regions: region r is the pixels labelled r + 1 (0 = in no region).
#[derive(Clone, Debug)]
pub struct Segmentation {
    pub labels: Grid<u32>,
    /// Pixel indices of each region, ascending.
    pub pixels: Vec<Vec<u32>>,
}

impl Segmentation {
    /// 8-connected components of the pixels where `boundary` is 0, those with at least
    /// `min_pixels` pixels becoming regions in scan order.
    pub fn components(boundary: &Grid<u8>, min_pixels: usize) -> Segmentation {
        let free: Vec<bool> = boundary.data.iter().map(|&b| b == 0).collect();
        let (runs, count) = component_runs(&free, boundary.width, boundary.height);
        let runs = runs.iter().map(|r| (r.start..r.end, r.label)).collect();
        Segmentation::from_runs(boundary.width, boundary.height, runs, count, min_pixels)
    }

    /// Regions from component labels (1..=count, 0 outside any, numbered in scan order):
    /// those with at least `min_pixels` pixels, renumbered in the same order. The tests'
    /// way in from hand-made labels; frames come through `components` or `from_roots`.
    #[cfg(test)]
    pub fn from_labels(labels: Grid<u32>, count: usize, min_pixels: usize) -> Segmentation {
        Segmentation::from_runs(labels.width, labels.height, label_runs(&labels.data).collect(), count, min_pixels)
    }

    /// Regions from component roots, as the GPU's components.wgsl leaves them: each pixel
    /// its component's root index + 1 (a component's root is its first pixel in scan
    /// order), 0 outside any. The components are numbered in scan order, as
    /// `dense_from_roots` numbers them, but run by run (the runs found in bands of rows in
    /// parallel): a per-pixel renumbering pass was most of the GPU twin's regions stage.
    /// `roots` is a `width`-wide image borrowed where it lies: the GPU twin numbers them in
    /// its mapped readback buffer, which is not copied out first.
    pub fn from_roots(roots: &[u32], width: usize, min_pixels: usize) -> Segmentation {
        thread_local! {
            /// Each root's number, written at the root's own run (the first of its
            /// component in the scan) and cleared after: kept between frames.
            static NUMBER_OF_ROOT: std::cell::RefCell<Vec<u32>> = const { std::cell::RefCell::new(Vec::new()) };
        }
        let mut count = 0u32;
        // Each run's root becomes its component's number, in place.
        let mut runs = par_label_runs(roots, width);
        NUMBER_OF_ROOT.with_borrow_mut(|number| {
            number.resize(number.len().max(roots.len()), 0);
            for (range, root) in &mut runs {
                let r = *root as usize - 1;
                if r == range.start {
                    count += 1;
                    number[r] = count;
                }
                // A root with no run of its own (not what the shader leaves) numbers nothing.
                *root = number.get(r).copied().unwrap_or(0);
            }
            for (range, _) in &runs {
                number[range.start] = 0;
            }
        });
        // Whole rows: the lists are written up to width x height, and a run past that would
        // not fit them.
        assert!(
            if width == 0 { roots.is_empty() } else { roots.len().is_multiple_of(width) },
            "roots of whole {width}-pixel rows"
        );
        let height = roots.len().checked_div(width).unwrap_or(0);
        Segmentation::from_runs(width, height, runs, count as usize, min_pixels)
    }

    /// Regions from the runs of components 1..=count (pixel index ranges in scan order,
    /// each with its component): sizes and numbers taken run by run, never pixel by pixel
    /// (a count per pixel waits on the previous pixel's store to its count), then the
    /// labels and pixel lists written from the runs in parallel (`write_runs`).
    fn from_runs(
        w: usize,
        h: usize,
        mut runs: Vec<(Range<usize>, u32)>,
        count: usize,
        min_pixels: usize,
    ) -> Segmentation {
        let mut sizes = vec![0usize; count + 1];
        for (range, l) in &runs {
            sizes[*l as usize] += range.len();
        }
        let mut region_of = vec![0u32; count + 1];
        let mut regions = 0;
        for l in 1..=count {
            if sizes[l] >= min_pixels {
                regions += 1;
                region_of[l] = regions;
            }
        }
        // Each run's component becomes its region, in place (0: too small, in none).
        for (_, l) in &mut runs {
            *l = region_of[*l as usize];
        }
        let mut pixels = vec![Vec::new(); regions as usize];
        let mut labels = Vec::with_capacity(w * h);
        write_runs(&runs, &mut pixels, Some(&mut labels.spare_capacity_mut()[..w * h]));
        // SAFETY: `write_runs` wrote every pixel of the image's labels.
        unsafe { labels.set_len(w * h) };
        Segmentation { labels: Grid { width: w, height: h, data: labels }, pixels }
    }

    /// Adds a region of these pixels (sorted here), returning its index.
    fn push(&mut self, mut pixels: Vec<u32>) -> usize {
        pixels.sort_unstable();
        let label = self.pixels.len() as u32 + 1;
        for &i in &pixels {
            self.labels.data[i as usize] = label;
        }
        self.pixels.push(pixels);
        self.pixels.len() - 1
    }
}

/// The fewest rows in a task of the row scans split over threads (`join_waves`' links,
/// waves and planes taken, `steps_between`): fewer is too little work to hand to another
/// thread.
pub(super) const MIN_BLOCK_ROWS: usize = 16;

/// [u_min, v_min, u_max, v_max] of a non-empty, ascending list of pixel indices in an
/// image `w` wide: only each row's first and last pixel, the last found by `leading`.
pub fn bounding_box(pixels: &[u32], w: usize) -> [usize; 4] {
    let (mut u0, mut u1) = (usize::MAX, 0);
    let mut k = 0;
    while let Some(&first) = pixels.get(k) {
        let row_start = first as usize / w * w;
        k += leading(|j| pixels.get(k + j).is_some_and(|&p| (p as usize) < row_start + w));
        (u0, u1) = (u0.min(first as usize - row_start), u1.max(pixels[k - 1] as usize - row_start));
    }
    [u0, pixels[0] as usize / w, u1, pixels[pixels.len() - 1] as usize / w]
}
