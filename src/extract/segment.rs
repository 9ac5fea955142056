//! Regions of one frame and their plane-driven clean-up, between the edge map and the
//! polygons (CPU, for both backends).
//!
//! Edges alone segment imperfectly: a Canny line broken by a sensor dropout lets two
//! surfaces leak into one region, and the edge lines, their closing and the squares of
//! normals spoiled by dropouts eat a band of pixels along every region's border, which
//! would shrink every polygon by a pixel or two. Once the planes are fitted both are
//! mended with the planes themselves:
//! - `split_leaks`: a region whose plane fits too few of its points keeps the largest
//!   connected patch of that plane's inliers; the rest becomes new regions, fitted again;
//! - `grow`: regions take back, wave by wave, the border pixels whose raw 3-D point lies
//!   within the inlier distance of their plane, the nearest plane winning where two meet.

use std::mem::MaybeUninit;
use std::ops::Range;

use nalgebra::Vector3;
use rayon::prelude::*;

use super::Grid;
use super::cloud::Cloud;
use super::cpu::ransac::{PlaneFit, PointBatch, for_each_strided, refit, sample_stride, support};
use crate::grid::{component_runs, first_other, flood, for_each_set, leading, par_rows, rows_around, runs};

/// Every `stride`-th of a region's valid points, in scan order, each standing for
/// `stride` of them: what the polygon checks read (a plane's covariance and its halves, a
/// cut's strays). A region's pixels lie on a regular grid, so every k-th point's sums are
/// those of all of them, times k, to well under a percent.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointSample {
    pub points: Vec<[f32; 3]>,
    pub stride: usize,
}

/// At most about this many of a region's points are sampled (`PointSample`): a floor at
/// 640x480 has a hundred thousand, and the checks cost the same for any size.
pub const MAX_SAMPLE_POINTS: usize = 2048;

impl PointSample {
    /// Every stride-th of `points`, the stride the smallest that keeps them to `max`.
    pub fn of(points: &[[f32; 3]], max: usize) -> PointSample {
        PointSample::of_parts(std::slice::from_ref(&points), max)
    }

    /// `of` the points of these parts, one after another.
    pub fn of_parts<P: AsRef<[[f32; 3]]>>(parts: &[P], max: usize) -> PointSample {
        let len = parts.iter().map(|part| part.as_ref().len()).sum();
        let stride = sample_stride(len, max);
        let mut sample = Vec::with_capacity(len.div_ceil(stride));
        // The index of each part's first point among all of them.
        let mut start = 0;
        for part in parts {
            let part = part.as_ref();
            // The part's first point taken: the first whose index is a multiple of the stride.
            let skip = (stride - start % stride) % stride;
            for_each_strided(part.get(skip..).unwrap_or_default(), stride, |p| sample.push(*p));
            start += part.len();
        }
        PointSample { points: sample, stride }
    }
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
    /// its mapped readback buffer, which a copy out took 0.17 ms of an H200's 640x480 frame.
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

    /// Camera-frame points (raw depth, valid pixels only) of the given regions, in that order.
    pub fn points(&self, regions: &[usize], cloud: &Cloud) -> PointBatch {
        self.sampled_points(regions, cloud, usize::MAX)
    }

    /// `points` of every stride-th pixel of a region of more than `max` pixels, the stride
    /// the smallest that keeps it to `max`: its pixels lie on a regular grid, so the plane
    /// through those points is the plane through all of them, to well under a percent of
    /// its noise.
    pub fn sampled_points(&self, regions: &[usize], cloud: &Cloud, max: usize) -> PointBatch {
        let stride = |r: usize| sample_stride(self.pixels[r].len(), max);
        let total = regions.iter().map(|&r| self.pixels[r].len().div_ceil(stride(r))).sum();
        let mut batch = PointBatch { points: Vec::with_capacity(total), ranges: Vec::with_capacity(regions.len()) };
        for &r in regions {
            let (start, stride) = (batch.points.len(), stride(r));
            if stride == 1 {
                self.extend_points(r, cloud, &mut batch.points);
            } else {
                for_each_strided(&self.pixels[r], stride, |&i| batch.points.extend(cloud.point(i as usize)));
            }
            batch.ranges.push(start..batch.points.len());
        }
        batch
    }

    /// `points_of` region r in parts, the points of `part_pixels` of its pixels each,
    /// gathered in parallel tasks.
    pub fn point_parts(&self, r: usize, cloud: &Cloud, part_pixels: usize) -> Vec<Vec<[f32; 3]>> {
        if self.pixels[r].len() <= part_pixels {
            vec![self.points_of(r, cloud)]
        } else {
            self.pixels[r].par_chunks(part_pixels).map(|pixels| points_of_pixels(pixels, cloud)).collect()
        }
    }

    /// Camera-frame points (raw depth, valid pixels only) of region r.
    pub fn points_of(&self, r: usize, cloud: &Cloud) -> Vec<[f32; 3]> {
        points_of_pixels(&self.pixels[r], cloud)
    }

    /// Appends the points of region r's valid pixels, run by run.
    fn extend_points(&self, r: usize, cloud: &Cloud, out: &mut Vec<[f32; 3]>) {
        extend_points_of(&self.pixels[r], cloud, out);
    }

    /// Splits every region whose fit has an inlier ratio under `min_ratio`: it keeps the
    /// largest 8-connected patch of its plane's inliers, refitted; the other connected
    /// pieces of at least `min_pixels` become new regions (their fits None).
    pub fn split_leaks(
        &mut self,
        fits: &mut Vec<Option<PlaneFit>>,
        cloud: &Cloud,
        dist: f32,
        min_ratio: f64,
        min_pixels: usize,
    ) -> Leaks {
        let (w, h) = (self.labels.width, self.labels.height);
        let mut leaks = Leaks::default();
        // Pixels flooded so far; a flood stays inside one region's pixels, which are
        // unmarked again after each use (a whole image cleared per region cost more).
        let mut seen = vec![false; w * h];
        for r in 0..self.pixels.len() {
            let Some(fit) = fits[r] else { continue };
            if fit.inlier_ratio() >= min_ratio {
                continue;
            }
            leaks.split.push(r);
            let label = r as u32 + 1;
            let inlier = |i: usize| {
                self.labels.data[i] == label && cloud.point(i).is_some_and(|p| fit.distance(&p) < dist as f64)
            };
            let mut best: Vec<u32> = Vec::new();
            for &i in &self.pixels[r] {
                if !seen[i as usize] && inlier(i as usize) {
                    let comp = flood(i as usize, w, h, &mut seen, inlier);
                    if comp.len() > best.len() {
                        best = comp;
                    }
                }
            }
            // Everything else in the region is released (marked so, for the floods of its
            // pieces), then its pieces regrouped.
            let old = std::mem::take(&mut self.pixels[r]);
            for &i in &old {
                self.labels.data[i as usize] = RELEASED;
            }
            for &i in &best {
                self.labels.data[i as usize] = label;
            }
            // In ascending order as the region's pixels were: no sort.
            self.pixels[r] = old.iter().copied().filter(|&i| self.labels.data[i as usize] == label).collect();
            fits[r] = refit(&self.points_of(r, cloud), fit.normal_f32(), fit.offset as f32, dist);
            old.iter().for_each(|&i| seen[i as usize] = false);
            for &i in &old {
                let i = i as usize;
                if self.labels.data[i] == RELEASED && !seen[i] {
                    let piece = flood(i, w, h, &mut seen, |j| self.labels.data[j] == RELEASED);
                    if piece.len() >= min_pixels {
                        leaks.pieces.push(self.push(piece));
                        fits.push(None);
                    }
                }
            }
            for &i in &old {
                seen[i as usize] = false;
                if self.labels.data[i as usize] == RELEASED {
                    self.labels.data[i as usize] = 0;
                }
            }
        }
        leaks
    }

    /// Grows every region with an accepted fit (`accepted[r]`) into unlabelled pixels,
    /// `waves` pixels deep. A pixel belongs to the plane nearest to its raw 3-D point
    /// among the accepted regions around it (if within `dist`), and joins that region
    /// once the region has reached it (a 4-neighbour). Nearest among the regions around,
    /// not just those already touching: at a tread's inner corner the riser's lowest
    /// centimetre lies within `dist` of the tread's plane, and the tread would take it
    /// before the riser got there. A pixel joins at wave k when, after wave k - 1, a
    /// 4-neighbour carries its plane's label; the result does not depend on scan order. A
    /// pixel's plane does not depend on the labels: it is found once for every unlabelled
    /// pixel (`plane_image`), and the waves are then byte masks of whole rows (`join_waves`).
    pub fn grow(&mut self, fits: &[Option<PlaneFit>], accepted: &[bool], cloud: &Cloud, dist: f32, waves: u32) {
        if waves > 0 {
            let nearby = NearbyRegions::new(self, accepted, (NEARBY_PER_WAVE * waves) as usize);
            let planes = plane_image(&self.labels, &nearby, fits, cloud, dist);
            join_waves(&mut self.labels, &planes, waves);
        }
        self.pixels_from_labels();
    }

    /// Rebuilds every region's pixel list from the labels, ascending by construction
    /// (cheaper than appending each wave of growth and sorting): the label runs found in
    /// bands of rows, the lists written from them, both in parallel. On one thread, one
    /// pass that writes each run as it finds it (`push_pixels`; two passes cost a third more).
    fn pixels_from_labels(&mut self) {
        if rayon::current_num_threads() == 1 {
            self.pixels.iter_mut().for_each(Vec::clear);
            push_pixels(&self.labels.data, &mut self.pixels);
            return;
        }
        write_runs(&par_label_runs(&self.labels.data, self.labels.width), &mut self.pixels, None);
    }
}

/// The points of the valid pixels among `pixels` (ascending), run by run.
fn points_of_pixels(pixels: &[u32], cloud: &Cloud) -> Vec<[f32; 3]> {
    let mut points = Vec::with_capacity(pixels.len());
    extend_points_of(pixels, cloud, &mut points);
    points
}

crate::extract::cpu::widest_simd! {
    /// Appends the points of the valid pixels among `pixels` (ascending), run by run.
    fn extend_points_of(pixels: &[u32], cloud: &Cloud, out: &mut Vec<[f32; 3]>) = extend_points_portable
}

/// `extend_points_of` at any vector width: a run's points are written whole (`Cloud::extend_valid`).
#[inline(always)]
fn extend_points_portable(pixels: &[u32], cloud: &Cloud, out: &mut Vec<[f32; 3]>) {
    for run in runs(pixels, cloud.width) {
        cloud.extend_valid(run.first..run.last + 1, out);
    }
}

/// Growth's plane of every pixel that no region holds: the label of the accepted region
/// around it whose plane is nearest its point, within `dist`, the lowest on a tie (as the
/// tests' per-pixel oracle `nearest_plane` says it); 0 for none and on every labelled pixel.
fn plane_image(
    labels: &Grid<u32>,
    nearby: &NearbyRegions,
    fits: &[Option<PlaneFit>],
    cloud: &Cloud,
    dist: f32,
) -> Grid<u32> {
    let w = labels.width;
    // Label l's plane (normal, offset) at l - 1; NaN for none, within no distance.
    let planes: Vec<[f64; 4]> =
        fits.iter().map(|f| f.map_or([f64::NAN; 4], |f| [f.normal.x, f.normal.y, f.normal.z, f.offset])).collect();
    let data = par_rows(w, labels.height, 0u32, 8, |v, out| {
        let (held, row) = (&labels.data[v * w..(v + 1) * w], cloud.row_part(v * w..(v + 1) * w));
        plane_row(nearby, &planes, row, held, v, dist as f64, out);
    });
    Grid { width: w, height: labels.height, data }
}

crate::extract::cpu::widest_simd! {
    /// `plane_image`'s row v: `held` its labels, `row` its points (`Cloud::row_part`).
    fn plane_row(
        nearby: &NearbyRegions,
        planes: &[[f64; 4]],
        row: (&[f32], &[f32], f32),
        held: &[u32],
        v: usize,
        dist: f64,
        out: &mut [u32],
    ) = plane_row_portable
}

/// A cell's run of pixels at a time, plane by plane across the run: the distance
/// computed as `PlaneFit::distance` computes it, so the same bits, and the lowest label
/// kept on a tie by taking only a strictly nearer plane (a cell's labels ascend).
#[inline(always)]
fn plane_row_portable(
    nearby: &NearbyRegions,
    planes: &[[f64; 4]],
    (depth, ray_x, ray_y): (&[f32], &[f32], f32),
    held: &[u32],
    v: usize,
    dist: f64,
    out: &mut [u32],
) {
    let cells = out.chunks_mut(CELL_PX).zip(held.chunks(CELL_PX)).zip(depth.chunks(CELL_PX).zip(ray_x.chunks(CELL_PX)));
    for (c, ((out, held), (depth, ray_x))) in cells.enumerate() {
        // Without an early exit, so the test is a vector compare: `all` went label by
        // label, and was a third of this loop's time at 640x480.
        if held.iter().fold(true, |all, &l| all & (l != 0)) {
            continue;
        }
        let mut nearest = [f64::INFINITY; CELL_PX];
        let mut label = [0u32; CELL_PX];
        for &l in nearby.around(c * CELL_PX, v) {
            let [nx, ny, nz, offset] = planes[l as usize - 1];
            for (((&z, &x), nearest), label) in depth.iter().zip(ray_x).zip(&mut nearest).zip(&mut label) {
                let p = [x * z, ray_y * z, z];
                let e = (nx * p[0] as f64 + ny * p[1] as f64 + nz * p[2] as f64 + offset).abs();
                let take = (e < dist) & (e < *nearest);
                *nearest = if take { e } else { *nearest };
                *label = if take { l } else { *label };
            }
        }
        for (((o, &h), &z), &l) in out.iter_mut().zip(held).zip(depth).zip(&label) {
            *o = if (h == 0) & (z != 0.0) { l } else { 0 };
        }
    }
}

/// Growth's waves. A pixel with a plane (`planes`, 0 for none) joins at wave 1 when a
/// 4-neighbour already holds its plane's label, and at wave k + 1 when a 4-neighbour of
/// the same plane joined by wave k. Which neighbours can bring a pixel in is found once
/// (`join_links`); the waves are then byte masks of whole rows (`wave_row`), 64 pixels an
/// instruction at AVX-512 where a sweep comparing labels took 16, and stop once a wave
/// takes nothing. The pixels that joined take their planes' labels at the end.
fn join_waves(labels: &mut Grid<u32>, planes: &Grid<u32>, waves: u32) {
    let (w, h) = (labels.width, labels.height);
    if waves == 0 || w == 0 || h == 0 {
        return;
    }
    let links = par_rows(w, h, 0u8, MIN_BLOCK_ROWS, |v, out| {
        join_links(rows_around(&labels.data, w, v), rows_around(&planes.data, w, v), [v > 0, v + 1 < h], out);
    });
    let mut joined: Vec<u8> = links.iter().map(|&k| k & HELD_BESIDE).collect();
    let mut next = vec![0u8; w * h];
    for _ in 1..waves {
        // Rows in parallel: a wave reads `joined` and writes `next` alone.
        let changed = (links.par_chunks_exact(w).zip(next.par_chunks_exact_mut(w)).enumerate())
            .with_min_len(MIN_BLOCK_ROWS)
            .map(|(v, (links, next))| wave_row(rows_around(&joined, w, v), links, next))
            .reduce(|| false, |a, b| a | b);
        std::mem::swap(&mut joined, &mut next);
        if !changed {
            break;
        }
    }
    let block = MIN_BLOCK_ROWS * w;
    let blocks = labels.data.par_chunks_mut(block).zip(joined.par_chunks(block).zip(planes.data.par_chunks(block)));
    blocks.for_each(|(labels, (joined, planes))| take_planes(joined, planes, labels));
}

crate::extract::cpu::widest_simd! {
    /// Where `joined`, the label becomes the plane's.
    fn take_planes(joined: &[u8], planes: &[u32], labels: &mut [u32]) = take_planes_portable
}

#[inline(always)]
fn take_planes_portable(joined: &[u8], planes: &[u32], labels: &mut [u32]) {
    let n = labels.len();
    let (joined, planes) = (&joined[..n], &planes[..n]);
    for i in 0..n {
        // By masks: as a select, the compiler chose between the two addresses to load from.
        let take = u32::from(joined[i] != 0).wrapping_neg();
        labels[i] = (planes[i] & take) | (labels[i] & !take);
    }
}

/// `join_links`' flags: a 4-neighbour holds the pixel's plane's label already.
const HELD_BESIDE: u8 = 1;
/// The neighbour to the left, right, above or below has the pixel's plane.
const SAME_LEFT: u8 = 2;
const SAME_RIGHT: u8 = 4;
const SAME_ABOVE: u8 = 8;
const SAME_BELOW: u8 = 16;

crate::extract::cpu::widest_simd! {
    /// For each pixel of a row with a plane, which 4-neighbours bring it into its plane's
    /// region (the flags above; 0 for a pixel without a plane), given the labels and the
    /// planes of the rows above, at and below it, and whether those rows are in the image.
    fn join_links(labels: [&[u32]; 3], planes: [&[u32]; 3], inside: [bool; 2], out: &mut [u8]) = join_links_portable
}

/// Whole rows at a time, comparisons combined with `&` and `|`: the loops vectorise. Beyond
/// the image's top and bottom the row itself stands in: its label at a pixel with a plane
/// is 0, never the plane's, and its planes are ignored by `inside`.
#[inline(always)]
fn join_links_portable(
    [above, row, below]: [&[u32]; 3],
    [p_above, plane, p_below]: [&[u32]; 3],
    [up, down]: [bool; 2],
    out: &mut [u8],
) {
    let w = row.len();
    let (above, below, p_above, plane, p_below, out) =
        (&above[..w], &below[..w], &p_above[..w], &plane[..w], &p_below[..w], &mut out[..w]);
    let flag = |set: bool, flag: u8| if set { flag } else { 0 };
    for u in 0..w {
        let p = plane[u];
        let held = flag((above[u] == p) | (below[u] == p), HELD_BESIDE);
        let same = flag((p_above[u] == p) & up, SAME_ABOVE) | flag((p_below[u] == p) & down, SAME_BELOW);
        out[u] = flag(p != 0, held | same);
    }
    for u in 1..w {
        let p = plane[u];
        out[u] |= flag(p != 0, flag(row[u - 1] == p, HELD_BESIDE) | flag(plane[u - 1] == p, SAME_LEFT));
    }
    for u in 0..w.saturating_sub(1) {
        let p = plane[u];
        out[u] |= flag(p != 0, flag(row[u + 1] == p, HELD_BESIDE) | flag(plane[u + 1] == p, SAME_RIGHT));
    }
}

crate::extract::cpu::widest_simd! {
    /// One wave on a row: `joined` (1 or 0) of the rows above, at and below it before the
    /// wave, `links` the row's `join_links`; the row after the wave into `out`. Whether it
    /// took a pixel.
    fn wave_row(joined: [&[u8]; 3], links: &[u8], out: &mut [u8]) -> bool = wave_row_portable
}

#[inline(always)]
fn wave_row_portable([above, row, below]: [&[u8]; 3], links: &[u8], out: &mut [u8]) -> bool {
    let w = row.len();
    let (above, below, links, out) = (&above[..w], &below[..w], &links[..w], &mut out[..w]);
    // 1 where a neighbour of the same plane on that side has joined.
    let from = |link: u8, side: u8, joined: u8| u8::from(link & side != 0) & joined;
    for u in 0..w {
        out[u] = row[u] | from(links[u], SAME_ABOVE, above[u]) | from(links[u], SAME_BELOW, below[u]);
    }
    for u in 1..w {
        out[u] |= from(links[u], SAME_LEFT, row[u - 1]);
    }
    for u in 0..w.saturating_sub(1) {
        out[u] |= from(links[u], SAME_RIGHT, row[u + 1]);
    }
    out.iter().zip(row).fold(false, |any, (&o, &x)| any | (o != x))
}

/// The fewest rows in a task of the row scans split over threads (`join_waves`' links,
/// waves and planes taken, `steps_between`): fewer is too little work to hand to another
/// thread.
const MIN_BLOCK_ROWS: usize = 16;

/// How a labelled pixel meets the last labelled pixel before it along its row or up its
/// column, that a scan looks for.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Meeting {
    /// A pixel of another label: where a row or a column steps from one region to another
    /// (the creases' and joins' scan).
    OtherLabel,
    /// A pixel of the same label, this one, across a gap (the joins' bridges).
    SameLabelAcrossGap(u32),
}

impl Meeting {
    /// As the row loops take it: 0 for `OtherLabel` (no region is labelled 0).
    fn same_label(self) -> u32 {
        match self {
            Meeting::OtherLabel => 0,
            Meeting::SameLabelAcrossGap(label) => label,
        }
    }
}

/// 1 in `out` where a pixel of `row` is one `meeting` looks for whose left neighbour is of
/// another label or none (`OtherLabel`; 0 for a row's first pixel), or is none
/// (`SameLabelAcrossGap`): where the walk back along the row to the last labelled pixel
/// starts.
fn row_meetings(row: &[u32], meeting: Meeting, out: &mut [u8]) {
    row_meetings_rows(row, meeting.same_label(), out);
}

crate::extract::cpu::widest_simd! {
    /// `row_meetings` on a plain label.
    fn row_meetings_rows(row: &[u32], same: u32, out: &mut [u8]) = row_meetings_portable
}

/// Whole rows at a time, as `join_links_portable`.
#[inline(always)]
fn row_meetings_portable(row: &[u32], same: u32, out: &mut [u8]) {
    let out = &mut out[..row.len()];
    let Some(first) = out.first_mut() else { return };
    *first = 0;
    for ((o, &x), &left) in out[1..].iter_mut().zip(&row[1..]).zip(row) {
        *o = if same == 0 { u8::from((x != 0) & (x != left)) } else { u8::from((x == same) & (left == 0)) };
    }
}

/// The last labelled pixel of `row` before pixel k, at most `reach` pixels back.
fn labelled_before(row: &[u32], k: usize, reach: usize) -> Option<usize> {
    (1..=k.min(reach)).map(|d| k - d).find(|&t| row[t] != 0)
}

/// What a scan down the rows keeps of the columns: each column's last label (0: none yet)
/// and the row it was in, and for the row just read, where its pixel meets the last
/// labelled pixel above it as the scan looks for (`found`) and that pixel's row (`from`).
struct Columns {
    last_label: Vec<u32>,
    last_row: Vec<u32>,
    from: Vec<u32>,
    found: Vec<u8>,
}

impl Columns {
    fn new(w: usize) -> Columns {
        Columns { last_label: vec![0; w], last_row: vec![0; w], from: vec![0; w], found: vec![0; w] }
    }

    /// Row v (`row`) down the columns: `found` where a labelled pixel meets the last
    /// labelled pixel above it, at most `reach` rows up, as `meeting` says (across a gap:
    /// two rows up or more); then the columns' last labels are the row's where it has one.
    fn down(&mut self, row: &[u32], v: usize, reach: usize, meeting: Meeting) {
        column_meetings(row, v as u32, reach as u32, meeting.same_label(), self);
    }
}

crate::extract::cpu::widest_simd! {
    /// `Columns::down` on a plain label.
    fn column_meetings(row: &[u32], v: u32, reach: u32, same: u32, columns: &mut Columns) = column_meetings_portable
}

/// Whole rows at a time, comparisons combined with `&`: the loop vectorises.
#[inline(always)]
fn column_meetings_portable(row: &[u32], v: u32, reach: u32, same: u32, columns: &mut Columns) {
    let Columns { last_label, last_row, from, found } = columns;
    let w = row.len();
    let (last_label, last_row, from, found) =
        (&mut last_label[..w], &mut last_row[..w], &mut from[..w], &mut found[..w]);
    for u in 0..w {
        let (x, above, at) = (row[u], last_label[u], last_row[u]);
        // `at` is a row above v wherever `above` is a label.
        let up = v.wrapping_sub(at);
        let near = (x != 0) & (above != 0) & (up <= reach);
        found[u] = if same == 0 {
            u8::from(near & (x != above))
        } else {
            u8::from(near & (x == same) & (above == same) & (up >= 2))
        };
        from[u] = at;
        last_label[u] = if x != 0 { x } else { above };
        last_row[u] = if x != 0 { v } else { at };
    }
}

/// Appends every labelled pixel's index to its region's list (label l: region l - 1),
/// ascending, a run of one label at a time: labels come in long runs along the rows, and
/// a run is one contiguous extend where pixel by pixel each push reloaded its list.
fn push_pixels(labels: &[u32], pixels: &mut [Vec<u32>]) {
    for (range, l) in label_runs(labels) {
        pixels[l as usize - 1].extend(range.start as u32..range.end as u32);
    }
}

/// `label_runs` of a `width`-wide image, found in bands of rows in parallel (a run across
/// a band's edge comes as two, each band's runs in order).
fn par_label_runs(labels: &[u32], width: usize) -> Vec<(Range<usize>, u32)> {
    let band = RUN_BAND_ROWS * width.max(1);
    (labels.par_chunks(band).enumerate())
        .flat_map_iter(|(b, labels)| label_runs(labels).map(move |(r, l)| (b * band + r.start..b * band + r.end, l)))
        .collect()
}

/// Rows of a band in which `par_label_runs` finds label runs as one task.
const RUN_BAND_ROWS: usize = 32;
/// The fewest pixels of the image a task of `write_runs` covers.
const MIN_WRITE_PIXELS: usize = 16 * 1024;

/// Writes each region's pixel list (region l - 1: the pixels of the runs of value l; runs
/// of value 0 are in none), ascending, and with `labels` the label image (each run's
/// value, 0 between runs), from `runs`: ascending, disjoint pixel ranges. In parallel:
/// the runs are cut into tasks of about equal stretches of the image, which count each
/// region's pixels in their runs, and then each writes its own stretch of each list (the
/// stretches in task order) and of the labels. Written by one thread, after the parallel
/// stages before them, the lists and labels were the largest serial step of a frame on
/// many cores (their scan read labels from other cores' caches).
fn write_runs(runs: &[(Range<usize>, u32)], pixels: &mut [Vec<u32>], labels: Option<&mut [MaybeUninit<u32>]>) {
    let n = labels.as_ref().map_or_else(|| runs.last().map_or(0, |(r, _)| r.end), |l| l.len());
    let tasks = n.div_ceil(MIN_WRITE_PIXELS).clamp(1, 4 * rayon::current_num_threads());
    // Task k takes the runs starting in its k-th of the image, and the labels from its
    // first run's start (the image's for the first task) to the next task's.
    let firsts: Vec<usize> = (0..=tasks).map(|k| runs.partition_point(|(r, _)| r.start < k * n / tasks)).collect();
    let mut bounds: Vec<usize> = firsts.iter().map(|&f| runs.get(f).map_or(n, |(r, _)| r.start)).collect();
    bounds[0] = 0;
    let task_runs: Vec<&[(Range<usize>, u32)]> = firsts.windows(2).map(|f| &runs[f[0]..f[1]]).collect();
    let counts: Vec<Vec<usize>> = (task_runs.par_iter())
        .map(|runs| {
            let mut counts = vec![0; pixels.len()];
            for (range, l) in runs.iter().filter(|(_, l)| *l != 0) {
                counts[*l as usize - 1] += range.len();
            }
            counts
        })
        .collect();
    let lengths: Vec<usize> = (0..pixels.len()).map(|r| counts.iter().map(|c| c[r]).sum()).collect();
    for (list, &len) in pixels.iter_mut().zip(&lengths) {
        list.clear();
        list.reserve(len);
    }
    // Each task's stretch of each list, cut off the lists' fronts in task order, and of the labels.
    let mut rests: Vec<&mut [MaybeUninit<u32>]> = pixels.iter_mut().map(Vec::spare_capacity_mut).collect();
    let stretches: Vec<Vec<&mut [MaybeUninit<u32>]>> = (counts.iter())
        .map(|counts| rests.iter_mut().zip(counts).map(|(rest, &len)| cut_front(rest, len)).collect())
        .collect();
    let mut labels_left = labels;
    let label_stretches: Vec<Option<&mut [MaybeUninit<u32>]>> =
        (bounds.windows(2)).map(|b| labels_left.as_mut().map(|rest| cut_front(rest, b[1] - b[0]))).collect();
    let work = task_runs.into_par_iter().zip(stretches).zip(label_stretches).zip(bounds.par_windows(2));
    work.for_each(|(((runs, mut lists), labels), bounds)| {
        let mut filled = vec![0; lists.len()];
        for (range, l) in runs.iter().filter(|(_, l)| *l != 0) {
            let (r, start) = (*l as usize - 1, range.start as u32);
            let out = &mut lists[r][filled[r]..filled[r] + range.len()];
            out.iter_mut().enumerate().for_each(|(k, o)| *o = MaybeUninit::new(start + k as u32));
            filled[r] += range.len();
        }
        if let Some(labels) = labels {
            // Offsets into this task's stretch of the labels, which starts at bounds[0].
            let (mut at, base) = (0, bounds[0]);
            for (range, l) in runs {
                labels[at..range.start - base].fill(MaybeUninit::new(0));
                labels[range.start - base..range.end - base].fill(MaybeUninit::new(*l));
                at = range.end - base;
            }
            labels[at..].fill(MaybeUninit::new(0));
        }
    });
    for (list, len) in pixels.iter_mut().zip(lengths) {
        // SAFETY: the tasks' stretches, each filled by its task's runs, cover the first len.
        unsafe { list.set_len(len) };
    }
}

/// The first `len` values of `rest`, which keeps the others.
fn cut_front<'a, T>(rest: &mut &'a mut [T], len: usize) -> &'a mut [T] {
    let (front, back) = std::mem::take(rest).split_at_mut(len);
    *rest = back;
    front
}

/// The stretches of one non-zero label in a label image, in order, with their label.
fn label_runs(labels: &[u32]) -> impl Iterator<Item = (Range<usize>, u32)> + '_ {
    let mut i = 0;
    std::iter::from_fn(move || {
        i += first_other(labels.get(i..)?, 0)?;
        let l = labels[i];
        let end = i + first_other(&labels[i..], l).unwrap_or(labels.len() - i);
        let range = i..end;
        i = end;
        Some((range, l))
    })
}

/// The label of a leaking region's pixels between its split and their regrouping.
const RELEASED: u32 = u32::MAX;

/// Two regions meet along a crease when at least this many rows and columns step from
/// one to the other: fewer is a corner touch or a stray pixel.
const MIN_CREASE_STEPS: u32 = 3;
/// Unlabelled pixels a row or a column may cross from one region to a region it meets:
/// the band growth left between them (mixed pixels, a dropout).
const MAX_CREASE_GAP_PX: usize = 4;

/// What `split_leaks` did: the regions it cut back to their plane's largest patch (their
/// labels changed), and the new regions made of the pieces of the rest that are large
/// enough (ascending).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Leaks {
    pub split: Vec<usize>,
    pub pieces: Vec<usize>,
}

/// The pairs of regions `join_coplanar` considers: those that meet across at most
/// `JOIN_GAP_PX` unlabelled pixels with no depth step, with how many times a row or a
/// column steps between them (labels a < b, sorted). Found on the labels and the depth
/// alone (`Segmentation::join_candidates`), so before the fits and beside them; a leak
/// split after that changes the labels (`Leaks::split`), and they must be found again.
pub struct JoinCandidates {
    steps: Vec<((u32, u32), u32)>,
}

/// Which regions meet along a crease of the surface: where a row or a column steps from
/// one region to the other (across at most `MAX_CREASE_GAP_PX` unlabelled pixels) with no
/// depth step between the two pixels. Regions side by side across a depth step (a box's
/// top before the floor behind it) or apart in the image do not meet.
pub struct Creases {
    /// (a, b) with a < b (labels), and the number of steps between them; sorted.
    steps: Vec<((u32, u32), u32)>,
}

impl Creases {
    /// Whether the regions labelled `a` and `b` meet.
    pub fn meet(&self, a: u32, b: u32) -> bool {
        let key = (a.min(b), a.max(b));
        self.steps.binary_search_by_key(&key, |&(k, _)| k).is_ok_and(|i| self.steps[i].1 >= MIN_CREASE_STEPS)
    }
}

impl Segmentation {
    /// The creases between regions; `ratio` is the depth step, relative to the depth, that
    /// parts two neighbouring pixels (as the boundary map's, per pixel of distance).
    pub fn creases(&self, cloud: &Cloud, ratio: f32) -> Creases {
        Creases { steps: self.steps_between(cloud, ratio, MAX_CREASE_GAP_PX) }
    }

    /// The pairs of regions that may join (`JoinCandidates`); `ratio` as for `creases`.
    pub fn join_candidates(&self, cloud: &Cloud, ratio: f32) -> JoinCandidates {
        JoinCandidates { steps: self.steps_between(cloud, ratio, JOIN_GAP_PX) }
    }

    /// For each pair of regions (labels a < b, sorted), how many times a row or a column
    /// steps from one to the other across at most `max_gap` unlabelled pixels with no depth
    /// step (`ratio` per pixel of distance) between the two pixels.
    ///
    /// Along a row, from each pixel where a region starts back to the nearest labelled one.
    /// Up the columns, from each labelled pixel to the last labelled one above it: each
    /// column's last label and its row are kept as the rows go down (`Columns`), so
    /// no column is walked up pixel by pixel (a cache line a pixel).
    fn steps_between(&self, cloud: &Cloud, ratio: f32, max_gap: usize) -> Vec<((u32, u32), u32)> {
        let (w, h) = (self.labels.width, self.labels.height);
        let l = &self.labels.data;
        // From labelled pixel i to labelled pixel j, `px` pixels apart, nothing labelled between.
        let step = |steps: &mut Vec<((u32, u32), u32)>, i: usize, j: usize, px: usize| {
            let (a, b, zi, zj) = (l[i], l[j], cloud.depth(i), cloud.depth(j));
            if a != b && zi > 0.0 && zj > 0.0 && (zi - zj).abs() <= ratio * px as f32 * zi.min(zj) {
                // Counted as they come where the pair repeats (along a border it mostly
                // does): far fewer entries to sort.
                let pair = (a.min(b), a.max(b));
                match steps.last_mut() {
                    Some((p, n)) if *p == pair => *n += 1,
                    _ => steps.push((pair, 1)),
                }
            }
        };
        // Rows in blocks side by side, each with its own list (the counts are summed below
        // whatever order they come in) and its own columns, which a block that starts below
        // the top first reads down from max_gap + 1 rows above its first row.
        let mut steps: Vec<((u32, u32), u32)> = (0..h)
            .into_par_iter()
            .with_min_len(MIN_BLOCK_ROWS)
            .fold(
                || (Vec::new(), Columns::new(w), None),
                |(mut steps, mut columns, next_row): (Vec<_>, Columns, Option<usize>), v| {
                    if next_row != Some(v) {
                        columns = Columns::new(w);
                        for above in v.saturating_sub(max_gap + 1)..v {
                            columns.down(&l[above * w..(above + 1) * w], above, max_gap + 1, Meeting::OtherLabel);
                        }
                    }
                    let row = &l[v * w..(v + 1) * w];
                    row_meetings(row, Meeting::OtherLabel, &mut columns.found);
                    for_each_set(&columns.found, |u| {
                        if let Some(t) = labelled_before(row, u, max_gap + 1) {
                            step(&mut steps, v * w + t, v * w + u, u - t);
                        }
                    });
                    columns.down(row, v, max_gap + 1, Meeting::OtherLabel);
                    for_each_set(&columns.found, |u| {
                        let from = columns.from[u] as usize;
                        step(&mut steps, from * w + u, v * w + u, v - from);
                    });
                    (steps, columns, Some(v + 1))
                },
            )
            .map(|(steps, _, _)| steps)
            .reduce(Vec::new, |mut a, b| {
                a.extend(b);
                a
            });
        steps.sort_unstable();
        let mut counted: Vec<((u32, u32), u32)> = Vec::new();
        for (pair, k) in steps {
            match counted.last_mut() {
                Some((p, n)) if *p == pair => *n += k,
                _ => counted.push((pair, k)),
            }
        }
        counted
    }

    /// Joins regions of one plane that something cut apart: a row of sensor dropouts
    /// across a thin strip (a tread cut by the image's bottom edge leaves a strip a few
    /// pixels tall, and every dropout's spoiled square of normals cuts it through), into
    /// pieces each too small to keep. Two regions join when they touch across at most
    /// `JOIN_GAP_PX` with no depth step (`candidates`, found on the labels as they are
    /// now), their planes are within `JOIN_ANGLE_COS`, and their union is still one plane:
    /// refitted, at least `min_ratio` of each one's points within `dist` of it. The region
    /// joined into keeps the lower index; the other is left empty, its fit None. Returns
    /// how many joins were made.
    pub fn join_coplanar(
        &mut self,
        candidates: JoinCandidates,
        fits: &mut [Option<PlaneFit>],
        cloud: &Cloud,
        dist: f32,
        min_ratio: f64,
    ) -> usize {
        let mut joins = 0;
        let mut joined_into = vec![false; self.pixels.len()];
        // Where each region went: itself, or the region it was joined into (a chain).
        let mut now_in: Vec<usize> = (0..self.pixels.len()).collect();
        let find = |now_in: &[usize], mut r: usize| {
            while now_in[r] != r {
                r = now_in[r];
            }
            r
        };
        for ((a, b), n) in candidates.steps {
            // A pair met before one of its regions was joined away is a pair of what they
            // are now part of: a strip cut into pieces A B C joins A+B, then (A+B)+C.
            let (a, b) = (find(&now_in, a as usize - 1), find(&now_in, b as usize - 1));
            let (a, b) = (a.min(b), a.max(b));
            let (Some(fa), Some(fb)) = (fits[a], fits[b]) else { continue };
            if a == b || n < MIN_CREASE_STEPS || fa.normal.dot(&fb.normal) < JOIN_ANGLE_COS {
                continue;
            }
            let both = self.points(&[a, b], cloud);
            let (na, pts) = (both.ranges[0].len(), both.points);
            let start = if fa.points >= fb.points { fa } else { fb };
            let Some(joined) = refit(&pts, start.normal_f32(), start.offset as f32, dist) else { continue };
            // Each piece on the joined plane, not just their sum: a large region would
            // otherwise swallow a small piece of a neighbouring surface within its outliers.
            let nb = pts.len() - na;
            let on_plane = |pts: &[[f32; 3]]| support(pts, joined.normal.into(), joined.offset, dist as f64).0;
            if on_plane(&pts[..na]) < (min_ratio * na as f64).ceil() as usize
                || on_plane(&pts[na..]) < (min_ratio * nb as f64).ceil() as usize
            {
                continue;
            }
            let moved = std::mem::take(&mut self.pixels[b]);
            for &i in &moved {
                self.labels.data[i as usize] = a as u32 + 1;
            }
            let before = self.pixels[a].len();
            self.pixels[a].extend(moved);
            merge_tail(&mut self.pixels[a], before);
            (fits[a], fits[b]) = (Some(joined), None);
            now_in[b] = a;
            joined_into[a] = true;
            joins += 1;
        }
        if joins > 0 {
            self.bridge(&joined_into, fits, cloud, dist);
        }
        joins
    }

    /// Fills the gaps (at most `JOIN_GAP_PX`, along rows and columns) between two pixels
    /// of one region marked in `regions`, where every pixel of the gap is a dropout or lies
    /// on the region's plane: the pieces a join united become one connected region (an
    /// outline is traced around one connected region).
    fn bridge(&mut self, regions: &[bool], fits: &[Option<PlaneFit>], cloud: &Cloud, dist: f32) {
        let w = self.labels.width;
        let labels = &self.labels.data;
        // Each united region is scanned once, inside its bounding box only (a gap between two
        // of its pixels lies there), row by row; columns keep their last labelled pixel
        // each, so they too are read along the rows.
        let united: Vec<(u32, &PlaneFit, [usize; 4])> = (0..regions.len())
            .filter(|&r| regions[r] && !self.pixels[r].is_empty())
            .filter_map(|r| Some((r as u32 + 1, fits[r].as_ref()?, bounding_box(&self.pixels[r], w))))
            .collect();
        // The pixels strictly between the labelled t0 and t of a line (pixel `at(t)`),
        // both of `label` with nothing labelled between: filled if a short gap on the plane.
        let gap =
            |fills: &mut Vec<(u32, u32)>, t0: usize, t: usize, at: &dyn Fn(usize) -> usize, label, fit: &PlaneFit| {
                if t - t0 > 1 && t - t0 <= JOIN_GAP_PX + 1 {
                    let on_plane = |t: usize| cloud.point(at(t)).is_none_or(|p| fit.distance(&p) < dist as f64);
                    if (t0 + 1..t).all(on_plane) {
                        fills.extend((t0 + 1..t).map(|t| (at(t) as u32, label)));
                    }
                }
            };
        let (mut row_fills, mut column_fills) = (Vec::new(), Vec::new());
        for &(label, fit, [u0, v0, u1, v1]) in &united {
            let meeting = Meeting::SameLabelAcrossGap(label);
            let mut columns = Columns::new(u1 - u0 + 1);
            for v in v0..=v1 {
                let row = &labels[v * w + u0..=v * w + u1];
                // Back along the row from a pixel of the region after a gap, to the last
                // labelled pixel in the box.
                row_meetings(row, meeting, &mut columns.found);
                for_each_set(&columns.found, |k| {
                    if let Some(t0) = labelled_before(row, k, JOIN_GAP_PX + 1).filter(|&t0| row[t0] == label) {
                        gap(&mut row_fills, u0 + t0, u0 + k, &|t| v * w + t, label, fit);
                    }
                });
                columns.down(row, v, JOIN_GAP_PX + 1, meeting);
                for_each_set(&columns.found, |k| {
                    gap(&mut column_fills, columns.from[k] as usize, v, &|t| t * w + u0 + k, label, fit);
                });
            }
        }
        // Rows' fills first: where a gap is both, the row's fill is the one kept.
        let before: Vec<usize> = self.pixels.iter().map(Vec::len).collect();
        for (i, l) in row_fills.into_iter().chain(column_fills) {
            if self.labels.data[i as usize] == 0 {
                self.labels.data[i as usize] = l;
                self.pixels[l as usize - 1].push(i);
            }
        }
        for (p, before) in self.pixels.iter_mut().zip(before) {
            merge_tail(p, before);
        }
    }
}

/// Sorts a list whose first `sorted` entries ascend and whose tail (appended after them,
/// in any order, none equal to an entry before) is short or ascends too: the tail is
/// sorted, then merged in from the back, in place. A full sort found the two runs and
/// merged them too, through a buffer of half the list.
fn merge_tail(list: &mut Vec<u32>, sorted: usize) {
    let mut tail = list.split_off(sorted);
    if tail.is_empty() {
        return;
    }
    tail.sort_unstable();
    let (mut a, mut b) = (list.len(), tail.len());
    list.resize(a + b, 0);
    while b > 0 {
        if a > 0 && list[a - 1] > tail[b - 1] {
            list[a + b - 1] = list[a - 1];
            a -= 1;
        } else {
            list[a + b - 1] = tail[b - 1];
            b -= 1;
        }
    }
}

/// Regions of one plane cut apart by at most this many pixels are joined (a dropout's
/// spoiled square of normals, sealed by the closing: up to the normal kernel plus the
/// closing's side, 5 + 7 px at the defaults).
const JOIN_GAP_PX: usize = 12;
/// Planes of regions that may join are within this (cos of 10 deg). Loose on purpose: the
/// pieces of a strip ten rows tall are fitted on a few rows each, and tilt by up to 7 deg
/// (the nearest tread of mock_frames/straight_320 frame 26); the refit of their union,
/// which each piece must lie on, is what decides.
const JOIN_ANGLE_COS: f64 = 0.985;

/// How far around a region, per wave of growth, its plane competes for pixels: far
/// enough to cover the edge band between two regions even where neither can grow
/// across all of it.
const NEARBY_PER_WAVE: u32 = 4;

/// Side of the square cells of `NearbyRegions`, pixels.
const CELL_PX: usize = 16;

/// For each CELL_PX square of the image, the accepted regions whose bounding box,
/// widened by a margin, overlaps it: the planes a pixel there may belong to. One list of
/// labels, cell after cell (a list per cell was hundreds of small allocations a frame).
struct NearbyRegions {
    cells_w: usize,
    /// Cell c's labels are `labels[starts[c]..starts[c + 1]]`, ascending.
    starts: Vec<u32>,
    labels: Vec<u32>,
}

impl NearbyRegions {
    fn new(seg: &Segmentation, accepted: &[bool], margin: usize) -> NearbyRegions {
        let (w, h) = (seg.labels.width, seg.labels.height);
        let (cells_w, cells_h) = (w.div_ceil(CELL_PX), h.div_ceil(CELL_PX));
        // Each accepted region's label and the cells its widened box covers.
        let boxes: Vec<(u32, [usize; 4])> = (seg.pixels.iter().enumerate())
            .filter(|&(r, pixels)| accepted[r] && !pixels.is_empty())
            .map(|(r, pixels)| {
                let [u0, v0, u1, v1] = bounding_box(pixels, w);
                let (u0, v0) = (u0.saturating_sub(margin) / CELL_PX, v0.saturating_sub(margin) / CELL_PX);
                let (u1, v1) = ((u1 + margin).min(w - 1) / CELL_PX, (v1 + margin).min(h - 1) / CELL_PX);
                (r as u32 + 1, [u0, v0, u1, v1])
            })
            .collect();
        let cells =
            |[u0, v0, u1, v1]: [usize; 4]| (v0..=v1).flat_map(move |cv| (cv * cells_w + u0)..=(cv * cells_w + u1));
        let mut starts = vec![0u32; cells_w * cells_h + 1];
        for &(_, cell_box) in &boxes {
            for c in cells(cell_box) {
                starts[c + 1] += 1;
            }
        }
        for c in 1..starts.len() {
            starts[c] += starts[c - 1];
        }
        let mut next = starts.clone();
        let mut labels = vec![0u32; starts[starts.len() - 1] as usize];
        for &(label, cell_box) in &boxes {
            for c in cells(cell_box) {
                labels[next[c] as usize] = label;
                next[c] += 1;
            }
        }
        NearbyRegions { cells_w, starts, labels }
    }

    /// Labels of the regions around pixel (u, v).
    fn around(&self, u: usize, v: usize) -> &[u32] {
        let c = (v / CELL_PX) * self.cells_w + u / CELL_PX;
        &self.labels[self.starts[c] as usize..self.starts[c + 1] as usize]
    }
}

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

impl PlaneFit {
    /// Distance of a point to the plane, m.
    #[inline]
    pub fn distance(&self, p: &[f32; 3]) -> f64 {
        (self.normal.dot(&Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)) + self.offset).abs()
    }

    pub fn normal_f32(&self) -> [f32; 3] {
        [self.normal.x as f32, self.normal.y as f32, self.normal.z as f32]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extract::cpu::components::{components_oracle, dense_from_roots};
    use crate::extract::cpu::ransac::hash;

    #[test]
    fn regions_from_roots_are_the_densely_numbered_components() {
        // Masks of random specks and blobs, the roots as the shader leaves them; twice
        // each, so the kept numbers of the first pass must not leak into the second.
        let (w, h) = (61, 37);
        for seed in 0..8u32 {
            let mask: Vec<bool> = (0..w * h)
                .map(|i| hash((i as u32 / 3) ^ seed.wrapping_mul(0x9e37_79b9)) % 100 < 25 + seed * 3)
                .collect();
            let roots = Grid { width: w, height: h, data: components_oracle(w, h, |i| mask[i]) };
            let mut dense = roots.data.clone();
            let count = dense_from_roots(&mut dense);
            assert!(count > 5, "seed {seed}: {count} components");
            for min_pixels in [1, 4] {
                let want =
                    Segmentation::from_labels(Grid { width: w, height: h, data: dense.clone() }, count, min_pixels);
                for pass in 0..2 {
                    let got = Segmentation::from_roots(&roots.data, roots.width, min_pixels);
                    assert_eq!(got.labels, want.labels, "seed {seed}, min {min_pixels}, pass {pass}: labels");
                    assert_eq!(got.pixels, want.pixels, "seed {seed}, min {min_pixels}, pass {pass}: pixels");
                }
            }
        }
    }

    /// Growth's plane of one pixel, the oracle of `plane_row`: the label of the accepted region
    /// around pixel i = (u, v) whose plane is nearest to the pixel's point, within `dist` (the
    /// lowest label on a tie); None for none or an invalid pixel.
    fn nearest_plane(
        nearby: &NearbyRegions,
        fits: &[Option<PlaneFit>],
        cloud: &Cloud,
        dist: f32,
        i: usize,
        u: usize,
        v: usize,
    ) -> Option<u32> {
        let p = cloud.point(i)?;
        let mut best: Option<(f64, u32)> = None;
        for &l in nearby.around(u, v) {
            let Some(fit) = &fits[l as usize - 1] else { continue };
            let e = fit.distance(&p);
            if e < dist as f64 && best.is_none_or(|(b, bl)| e < b || (e == b && l < bl)) {
                best = Some((e, l));
            }
        }
        best.map(|(_, l)| l)
    }

    /// Growth as its definition says it, the oracle: each wave a sweep of the whole image
    /// that labels an unlabelled pixel when a 4-neighbour had its plane's label after the
    /// wave before.
    fn grow_by_sweeps(seg: &Segmentation, fits: &[Option<PlaneFit>], cloud: &Cloud, dist: f32, waves: u32) -> Vec<u32> {
        let (w, h) = (seg.labels.width, seg.labels.height);
        let accepted = vec![true; fits.len()];
        let nearby = NearbyRegions::new(seg, &accepted, (NEARBY_PER_WAVE * waves) as usize);
        let mut labels = seg.labels.data.clone();
        for _ in 0..waves {
            let before = labels.clone();
            for (i, label) in labels.iter_mut().enumerate() {
                let (u, v) = (i % w, i / w);
                let touching =
                    [(u > 0, i.wrapping_sub(1)), (u + 1 < w, i + 1), (v > 0, i.wrapping_sub(w)), (v + 1 < h, i + w)];
                if before[i] == 0
                    && let Some(l) = nearest_plane(&nearby, fits, cloud, dist, i, u, v)
                    && touching.iter().any(|&(inside, j)| inside && before[j] == l)
                {
                    *label = l;
                }
            }
        }
        labels
    }

    /// A w x h camera of focal length f pixels, centred, depth in millimetres.
    fn centred_camera(w: usize, h: usize, f: f64) -> crate::types::Intrinsics {
        let (width, height) = (w as u32, h as u32);
        crate::types::Intrinsics {
            width,
            height,
            fx: f,
            fy: f,
            cx: w as f64 / 2.0,
            cy: h as f64 / 2.0,
            depth_scale: 0.001,
        }
    }

    /// Labels and pixel lists written from runs in parallel (`write_runs`, through
    /// `from_labels`) and lists rebuilt from the labels (`pixels_from_labels`) are the
    /// pixel-by-pixel ones, on 1, 2 and 16 threads, on an image of several tasks and bands.
    #[test]
    fn lists_and_labels_written_in_parallel_are_the_pixel_by_pixel_ones() {
        let (w, h, regions) = (300usize, 220usize, 7u32);
        let mut data = vec![0u32; w * h];
        let (mut i, mut k) = (0, 0u32);
        while i < data.len() {
            let end = (i + 1 + (hash(k) % 150) as usize).min(data.len());
            data[i..end].fill(hash(k ^ 0x77) % (regions + 1));
            (i, k) = (end, k + 1);
        }
        // Numbered in scan order, as `from_labels` wants them.
        let mut number = vec![0u32; regions as usize + 1];
        let mut count = 0;
        for l in data.iter_mut().filter(|l| **l != 0) {
            if number[*l as usize] == 0 {
                count += 1;
                number[*l as usize] = count;
            }
            *l = number[*l as usize];
        }
        let mut want = vec![Vec::new(); count as usize];
        for (i, &l) in data.iter().enumerate().filter(|(_, l)| **l != 0) {
            want[l as usize - 1].push(i as u32);
        }
        assert!(data.len() > 3 * MIN_WRITE_PIXELS && h > 3 * RUN_BAND_ROWS && count == regions);
        for threads in [1, 2, 16] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let labels = Grid { width: w, height: h, data: data.clone() };
                let mut seg = Segmentation::from_labels(labels, count as usize, 1);
                assert_eq!(seg.labels.data, data, "{threads} threads");
                assert_eq!(seg.pixels, want, "{threads} threads");
                seg.pixels.iter_mut().for_each(|list| list.extend([7, 8, 9]));
                seg.pixels_from_labels();
                assert_eq!(seg.pixels, want, "{threads} threads, lists from the labels");
            });
        }
    }

    #[test]
    fn growth_is_the_wave_by_wave_sweep() {
        // Three planes (1/depth linear in the pixel), noisy, with dropouts; regions are the
        // planes' pixels less a band along their borders and specks of no region. Growth
        // from them, 0 to 6 waves deep, with inlier distances that take most of the band
        // or little of it.
        let (w, h) = (90usize, 70usize);
        let intr = centred_camera(w, h, 60.0);
        let piece = |u: usize, v: usize| {
            if v > 40 + u / 6 {
                0
            } else if u < 50 {
                1
            } else {
                2
            }
        };
        let inverse_depth = [[0.45, 0.0, 0.004], [0.9, -0.002, 0.0], [0.2, 0.003, 0.001]];
        // An image of f(pixel index, u, v).
        fn image<T>(w: usize, h: usize, f: impl Fn(usize, usize, usize) -> T) -> Grid<T> {
            Grid { width: w, height: h, data: (0..w * h).map(|i| f(i, i % w, i / w)).collect() }
        }
        let depth = image(w, h, |i, u, v| {
            let [a, b, c] = inverse_depth[piece(u, v)];
            let noise = (hash(i as u32) % 1000) as f32 * 4e-6 - 2e-3;
            if hash(i as u32 ^ 0x55).is_multiple_of(53) { 0.0 } else { 1.0 / (a + b * u as f32 + c * v as f32) + noise }
        });
        let cloud = Cloud::new(&depth, &intr);
        // A pixel's region: its piece's, unless within 4 pixels of another piece or a speck.
        let labels = image(w, h, |i, u, v| {
            let near_other = (u.saturating_sub(4)..(u + 5).min(w))
                .any(|x| (v.saturating_sub(4)..(v + 5).min(h)).any(|y| piece(x, y) != piece(u, v)));
            if near_other || hash(i as u32 ^ 0xaa).is_multiple_of(40) { 0 } else { piece(u, v) as u32 + 1 }
        });
        for dist in [0.003f32, 0.02] {
            for waves in 0..=6 {
                let mut seg = Segmentation::from_labels(labels.clone(), 3, 1);
                assert_eq!(seg.pixels.len(), 3);
                let fits = super::super::cpu::ransac::fit_planes(&seg.points(&[0, 1, 2], &cloud), 32, 0.004);
                let want = grow_by_sweeps(&seg, &fits, &cloud, dist, waves);
                // On 2 and 16 threads, the links and the waves found by tasks of rows side by side.
                for threads in [2, 16] {
                    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                    let mut on_blocks = Segmentation::from_labels(labels.clone(), 3, 1);
                    pool.install(|| on_blocks.grow(&fits, &[true; 3], &cloud, dist, waves));
                    assert_eq!(on_blocks.labels.data, want, "{dist}, {waves} waves, {threads} threads");
                }
                rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| {
                    seg.grow(&fits, &[true; 3], &cloud, dist, waves);
                });
                assert_eq!(seg.labels.data, want, "inlier distance {dist}, {waves} waves");
                let grown = want.iter().zip(&labels.data).filter(|(a, b)| a != b).count();
                let left = want.iter().zip(&depth.data).filter(|&(&l, &z)| l == 0 && z != 0.0).count();
                // Some growth, and while the bands are not yet crossed, pixels left to grow into.
                assert!(waves == 0 || grown > 100, "{dist}, {waves} waves: grew {grown}");
                assert!(waves > 2 || left > 100, "{dist}, {waves} waves: left {left}");
                let listed: usize = seg.pixels.iter().map(Vec::len).sum();
                assert_eq!(listed, want.iter().filter(|&&l| l != 0).count(), "pixel lists follow the labels");
            }
        }
    }

    #[test]
    fn merge_tail_sorts_as_a_full_sort_does() {
        // Ascending heads of every length to 40, tails of 0 to 9 values not in the head, in
        // hashed order (the fills) or ascending (a joined region's pixels).
        for n in 0..40u32 {
            for k in 0..10u32 {
                let all: Vec<u32> = (0..n + k).map(|i| i * 3 + hash(i * 7 + n) % 3).collect();
                let check = |ascending: bool| {
                    let (mut head, mut tail) = (Vec::new(), Vec::new());
                    for (i, &x) in all.iter().enumerate() {
                        if hash(i as u32 + 101 * n + 7 * k) % (n + k) < k { tail.push(x) } else { head.push(x) }
                    }
                    if !ascending {
                        tail.sort_by_key(|&x| hash(x));
                    }
                    let sorted = head.len();
                    head.extend(tail);
                    let mut want = head.clone();
                    want.sort();
                    merge_tail(&mut head, sorted);
                    assert_eq!(head, want, "{n} + {k}, ascending tail {ascending}");
                };
                check(true);
                check(false);
            }
        }
    }

    #[test]
    fn sampled_points_are_every_stride_th_pixel_s() {
        // Two regions side by side, one of 1200 pixels with dropouts, one of 40.
        let (w, h) = (50usize, 30usize);
        let intr = centred_camera(w, h, 40.0);
        let labels: Vec<u32> = (0..w * h)
            .map(|i| {
                if i % w < 40 {
                    1
                } else if i / w < 4 {
                    2
                } else {
                    0
                }
            })
            .collect();
        let seg = Segmentation::from_labels(Grid { width: w, height: h, data: labels }, 2, 1);
        let depth = Grid {
            width: w,
            height: h,
            data: (0..w * h)
                .map(|i| if hash(i as u32).is_multiple_of(9) { 0.0 } else { 1.0 + i as f32 * 1e-4 })
                .collect(),
        };
        let cloud = Cloud::new(&depth, &intr);
        let (all, sampled) = (seg.points(&[0, 1], &cloud), seg.sampled_points(&[0, 1], &cloud, 100));
        let every = |r: usize, k: usize| -> Vec<[f32; 3]> {
            seg.pixels[r].iter().step_by(k).filter_map(|&i| cloud.point(i as usize)).collect()
        };
        assert_eq!(seg.pixels[0].len(), 1200);
        assert_eq!(all.points[all.ranges[0].clone()], every(0, 1)[..], "all of the large region");
        // 1200 pixels to at most 100: every 12th.
        assert_eq!(sampled.points[sampled.ranges[0].clone()], every(0, 12)[..]);
        assert!(sampled.ranges[0].len() < 100 && sampled.ranges[0].len() > 80, "dropouts left out");
        // The small region whole, after the large one's sample.
        assert_eq!(sampled.points[sampled.ranges[1].clone()], every(1, 1)[..]);
        assert_eq!(sampled.ranges[1].start, sampled.ranges[0].end);
        // In parts of 100 pixels (cut inside rows and runs) on two threads, or in one.
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let parts = pool.install(|| seg.point_parts(0, &cloud, 100));
        assert_eq!(parts.len(), 12);
        assert_eq!(parts.concat(), every(0, 1), "the points in order, dropouts left out");
        assert_eq!(seg.point_parts(1, &cloud, 100), vec![every(1, 1)], "a small region one part");
    }

    #[test]
    fn bounding_box_is_the_pixels_extent() {
        // Pixels of every density, rows with one pixel, many runs or whole, on widths with
        // rows long and short.
        for (w, h) in [(1, 4), (5, 3), (37, 29), (300, 7)] {
            for keep in [1, 2, 5, 40] {
                let pixels: Vec<u32> = (0..(w * h) as u32).filter(|&i| hash(i).is_multiple_of(keep)).collect();
                if pixels.is_empty() {
                    continue;
                }
                let (us, vs) = (|| pixels.iter().map(|&i| i as usize % w), || pixels.iter().map(|&i| i as usize / w));
                let want = [us().min().unwrap(), vs().min().unwrap(), us().max().unwrap(), vs().max().unwrap()];
                assert_eq!(bounding_box(&pixels, w), want, "{w}x{h}, one pixel in {keep}");
            }
        }
    }

    #[test]
    fn steps_between_regions_are_the_walks_back_along_rows_and_up_columns() {
        // Blobs of labels with gaps of 0 to 6 pixels between them, dropouts, and depth
        // steps; more rows than one block, so that blocks start below the top on 4 threads.
        let (w, h) = (53usize, 90usize);
        let data: Vec<u32> = (0..w * h)
            .map(|i| {
                let (u, v) = ((i % w) as u32, (i / w) as u32);
                if hash(u / 6 + 101 * (v / 3)).is_multiple_of(4) { 0 } else { 1 + hash(u / 11 + 7 * (v / 2)) % 5 }
            })
            .collect();
        let seg = Segmentation::from_labels(Grid { width: w, height: h, data: data.clone() }, 5, 1);
        let depth = Grid {
            width: w,
            height: h,
            data: (0..w * h)
                .map(|i| match hash(i as u32 ^ 0x5bd1) % 23 {
                    0 => 0.0,
                    1 => 2.0,
                    _ => 1.0 + (i % w) as f32 * 1e-3,
                })
                .collect(),
        };
        let cloud = Cloud::new(&depth, &centred_camera(w, h, 40.0));
        let (ratio, max_gap) = (0.03f32, 4usize);
        // The oracle: from every labelled pixel, back along its row and up its column to the
        // nearest labelled pixel at most max_gap + 1 away; a pair where the two differ in
        // label and not by a depth step.
        let l = &seg.labels.data;
        let mut want = std::collections::BTreeMap::<(u32, u32), u32>::new();
        for j in (0..w * h).filter(|&j| l[j] != 0) {
            let (u, v) = (j % w, j / w);
            for (stride, room) in [(1, u), (w, v)] {
                let Some((i, px)) = (1..=room.min(max_gap + 1)).map(|k| (j - k * stride, k)).find(|&(i, _)| l[i] != 0)
                else {
                    continue;
                };
                let (zi, zj) = (depth.data[i], depth.data[j]);
                if l[i] != l[j] && zi > 0.0 && zj > 0.0 && (zi - zj).abs() <= ratio * px as f32 * zi.min(zj) {
                    *want.entry((l[i].min(l[j]), l[i].max(l[j]))).or_default() += 1;
                }
            }
        }
        let want: Vec<((u32, u32), u32)> = want.into_iter().collect();
        assert!(want.len() >= 5 && want.iter().any(|(_, n)| *n > 20), "pairs to find: {want:?}");
        for threads in [1, 4] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a pool");
            assert_eq!(pool.install(|| seg.steps_between(&cloud, ratio, max_gap)), want, "{threads} threads");
        }
    }

    #[test]
    fn row_scans_are_the_pixel_by_pixel_ones() {
        // Growth's links and wave on a row, and where rows enter a region.
        // Labels in blobs and specks, 0 between, on widths that leave every remainder of
        // the eight-byte words and of the vectors.
        for (w, h) in [(1, 1), (1, 5), (7, 3), (37, 29), (70, 11)] {
            let labels = Grid {
                width: w,
                height: h,
                data: (0..w * h)
                    .map(|i| {
                        let (u, v) = ((i % w) as u32, (i / w) as u32);
                        if hash(u / 5 + 97 * (v / 4)).is_multiple_of(3) || hash(i as u32).is_multiple_of(11) {
                            1 + u / 9
                        } else {
                            0
                        }
                    })
                    .collect(),
            };
            let at = |u: isize, v: isize| {
                if u < 0 || v < 0 || u >= w as isize || v >= h as isize {
                    0
                } else {
                    labels.data[v as usize * w + u as usize]
                }
            };
            // Each unlabelled pixel's plane: a label near the pixel's own blob, or none (0,
            // as on every labelled pixel: `plane_image`).
            let plane = |u: isize, v: isize| {
                let k = hash((u * 31 + v * 7) as u32);
                let outside = u < 0 || v < 0 || u >= w as isize || v >= h as isize;
                if outside || at(u, v) != 0 || k.is_multiple_of(4) { 0 } else { 1 + (u as u32 + k % 3) / 9 }
            };
            let planes = Grid {
                width: w,
                height: h,
                data: (0..w * h).map(|i| plane((i % w) as isize, (i / w) as isize)).collect(),
            };
            // Growth's links by their definition: a pixel with a plane joins at the first
            // wave when a 4-neighbour holds it, and then when a 4-neighbour of the same
            // plane has joined.
            let sides = [(-1, 0, SAME_LEFT), (1, 0, SAME_RIGHT), (0, -1, SAME_ABOVE), (0, 1, SAME_BELOW)];
            let mut want_links = Vec::new();
            for v in 0..h as isize {
                for u in 0..w as isize {
                    let p = plane(u, v);
                    let mut flags = 0;
                    for &(du, dv, same) in &sides {
                        if p != 0 && at(u + du, v + dv) == p {
                            flags |= HELD_BESIDE;
                        }
                        if p != 0 && plane(u + du, v + dv) == p {
                            flags |= same;
                        }
                    }
                    want_links.push(flags);
                }
            }
            // A wave from some pixels joined, by its definition.
            let joined: Vec<u8> = (0..w * h).map(|i| u8::from(hash(i as u32 ^ 0x3c).is_multiple_of(3))).collect();
            let joined_at = |u: isize, v: isize| {
                let inside = u >= 0 && v >= 0 && u < w as isize && v < h as isize;
                inside && joined[v as usize * w + u as usize] == 1
            };
            let mut want_wave = Vec::new();
            for v in 0..h as isize {
                for u in 0..w as isize {
                    let k = want_links[v as usize * w + u as usize];
                    let brought = sides.iter().any(|&(du, dv, same)| k & same != 0 && joined_at(u + du, v + dv));
                    want_wave.push(u8::from(joined_at(u, v) || brought));
                }
            }
            // Where a row enters a region (the creases' and joins' scan).
            let mut entries = Vec::new();
            for v in 0..h as isize {
                for u in 0..w as isize {
                    let x = at(u, v);
                    if x != 0 && u > 0 && at(u - 1, v) != x {
                        entries.push((u as usize, v as usize));
                    }
                }
            }
            let (mut links, mut wave, mut got_entries) = (vec![0u8; w * h], vec![0u8; w * h], Vec::new());
            let mut mask = vec![0u8; w];
            for v in 0..h {
                let row = v * w..(v + 1) * w;
                let (labels_around, planes_around) = (rows_around(&labels.data, w, v), rows_around(&planes.data, w, v));
                join_links(labels_around, planes_around, [v > 0, v + 1 < h], &mut links[row.clone()]);
                let took = wave_row(rows_around(&joined, w, v), &want_links[row.clone()], &mut wave[row.clone()]);
                assert_eq!(took, want_wave[row.clone()] != joined[row], "{w} x {h}, row {v}");
                row_meetings(labels_around[1], Meeting::OtherLabel, &mut mask);
                for_each_set(&mask, |u| got_entries.push((u, v)));
            }
            assert_eq!(links, want_links, "{w} x {h}");
            assert_eq!(wave, want_wave, "{w} x {h}");
            assert_eq!(got_entries, entries, "{w} x {h}");
            // Every kind of link, pixels a wave brings in, and borders.
            let count = |flag: u8| want_links.iter().filter(|&&k| k & flag != 0).count();
            let brought = want_wave.iter().zip(&joined).filter(|(a, b)| a != b).count();
            let kinds = [HELD_BESIDE, SAME_LEFT, SAME_RIGHT, SAME_ABOVE, SAME_BELOW].map(count);
            assert!(
                w * h < 100 || (kinds.iter().all(|&n| n > 10) && brought > 10 && entries.len() > 20),
                "{w} x {h}: {kinds:?}, {brought}"
            );
        }
        // Any non-zero byte counts, in a word and in the tail.
        let mut set = Vec::new();
        for_each_set(&[0, 3, 0, 0, 0, 0, 0, 255, 9, 0, 128], |i| set.push(i));
        assert_eq!(set, [1, 7, 8, 10]);
    }
}
