//! Growth: regions take back, wave by wave, the border pixels whose raw 3-D point lies
//! within the inlier distance of their plane, the nearest plane winning where two meet.
//! Edge lines, their closing and the squares of normals spoiled by dropouts eat a band
//! along every region's border, which would shrink every polygon by a pixel or two.

use rayon::prelude::*;

use super::{MIN_BLOCK_ROWS, Segmentation};
use crate::extract::Grid;
use crate::extract::cloud::Cloud;
use crate::extract::cpu::ransac::PlaneFit;
use crate::grid::{par_rows, rows_around};

impl Segmentation {
    /// Grows every region with an accepted fit (`accepted[r]`) into unlabelled pixels,
    /// `waves` pixels deep. A pixel belongs to the plane nearest to its raw 3-D point
    /// among the accepted regions around it (if within `dist`; around: with a pixel within
    /// `waves` pixels, in whole cells, `NearbyRegions`), and joins that region once the
    /// region has reached it (a 4-neighbour). Nearest among the regions around,
    /// not just those already touching: at a tread's inner corner the riser's lowest
    /// centimetre lies within `dist` of the tread's plane, and the tread would take it
    /// before the riser got there. A pixel joins at wave k when, after wave k - 1, a
    /// 4-neighbour carries its plane's label; the result does not depend on scan order. A
    /// pixel's plane does not depend on the labels: it is found once for every unlabelled
    /// pixel (`plane_image`), and the waves are then byte masks of whole rows (`join_waves`).
    pub fn grow(&mut self, fits: &[Option<PlaneFit>], accepted: &[bool], cloud: &Cloud, dist: f32, waves: u32) {
        if waves > 0 {
            let nearby = NearbyRegions::new(self, accepted, waves as usize);
            let planes = plane_image(&self.labels, &nearby, fits, cloud, dist);
            join_waves(&mut self.labels, &planes, waves);
        }
        self.pixels_from_labels();
    }
}

/// Growth's plane of every pixel that no region holds: the label of the accepted region
/// around it whose plane is nearest its point, within `dist`, the lowest on a tie (as the
/// tests' per-pixel oracle `nearest_plane` says it); 0 for none and on every labelled pixel.
pub(super) fn plane_image(
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
    pub(super) fn plane_row(
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
        // Without an early exit, so the test is a vector compare (`all` goes label by label).
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
/// (`join_links`); the waves are then byte masks of whole rows (`wave_row`), four times
/// the pixels a vector of a sweep comparing labels, and stop once a wave takes nothing. The pixels that joined take their planes' labels at the end.
pub(super) fn join_waves(labels: &mut Grid<u32>, planes: &Grid<u32>, waves: u32) {
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
    pub(super) fn take_planes(joined: &[u8], planes: &[u32], labels: &mut [u32]) = take_planes_portable
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
pub(super) const HELD_BESIDE: u8 = 1;
/// The neighbour to the left, right, above or below has the pixel's plane.
pub(super) const SAME_LEFT: u8 = 2;
pub(super) const SAME_RIGHT: u8 = 4;
pub(super) const SAME_ABOVE: u8 = 8;
pub(super) const SAME_BELOW: u8 = 16;

crate::extract::cpu::widest_simd! {
    /// For each pixel of a row with a plane, which 4-neighbours bring it into its plane's
    /// region (the flags above; 0 for a pixel without a plane), given the labels and the
    /// planes of the rows above, at and below it, and whether those rows are in the image.
    pub(super) fn join_links(labels: [&[u32]; 3], planes: [&[u32]; 3], inside: [bool; 2], out: &mut [u8]) = join_links_portable
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
    pub(super) fn wave_row(joined: [&[u8]; 3], links: &[u8], out: &mut [u8]) -> bool = wave_row_portable
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

/// Side of the square cells of `NearbyRegions`, pixels.
pub(super) const CELL_PX: usize = 16;

/// For each CELL_PX square of the image, the accepted regions that hold a pixel within
/// a margin of it, rounded up to whole cells: the planes a pixel there may belong to.
/// Near the region's pixels, not its bounding box: the box of a large or bent region
/// (the floor around a box, an L-shaped face) covers faces it never reaches, and its
/// plane, nearest along the line where it cuts them, kept their own regions from growing
/// across that line. One list of labels, cell after cell (a list per cell was hundreds of
/// small allocations a frame).
pub(super) struct NearbyRegions {
    cells_w: usize,
    /// Cell c's labels are `labels[starts[c]..starts[c + 1]]`, ascending.
    starts: Vec<u32>,
    labels: Vec<u32>,
}

impl NearbyRegions {
    pub(super) fn new(seg: &Segmentation, accepted: &[bool], margin: usize) -> NearbyRegions {
        let (w, h) = (seg.labels.width, seg.labels.height);
        let (cells_w, cells_h) = (w.div_ceil(CELL_PX), h.div_ceil(CELL_PX));
        let reach = margin.div_ceil(CELL_PX);
        // (cell, label) for every cell within `reach` cells of a cell holding a pixel of an
        // accepted region; each pair once (`seen` holds the last label that marked a cell).
        let (mut held, mut seen) = (vec![0u32; cells_w * cells_h], vec![0u32; cells_w * cells_h]);
        let (mut pairs, mut own): (Vec<(u32, u32)>, Vec<usize>) = (Vec::new(), Vec::new());
        for (r, pixels) in seg.pixels.iter().enumerate().filter(|&(r, p)| accepted[r] && !p.is_empty()) {
            let label = r as u32 + 1;
            // The pixels ascend: row by row, and along a row a cell at a time where the
            // region runs unbroken to the cell's end (most of it), a pixel at a time where not.
            let (mut v, mut k) = (pixels[0] as usize / w, 0);
            while let Some(&i) = pixels.get(k) {
                let i = i as usize;
                while i >= (v + 1) * w {
                    v += 1;
                }
                let u = i - v * w;
                let c = (v / CELL_PX) * cells_w + u / CELL_PX;
                if held[c] != label {
                    held[c] = label;
                    own.push(c);
                }
                let to_cell_end = ((u / CELL_PX + 1) * CELL_PX).min(w) - u;
                let unbroken = pixels.get(k + to_cell_end - 1).is_some_and(|&j| j as usize == i + to_cell_end - 1);
                k += if unbroken { to_cell_end } else { 1 };
            }
            for c in own.drain(..) {
                let (cu, cv) = (c % cells_w, c / cells_w);
                for nv in cv.saturating_sub(reach)..=(cv + reach).min(cells_h - 1) {
                    for nu in cu.saturating_sub(reach)..=(cu + reach).min(cells_w - 1) {
                        let n = nv * cells_w + nu;
                        if seen[n] != label {
                            seen[n] = label;
                            pairs.push((n as u32, label));
                        }
                    }
                }
            }
        }
        // Cell by cell, each cell's labels in the order they came: ascending.
        let mut starts = vec![0u32; cells_w * cells_h + 1];
        for &(c, _) in &pairs {
            starts[c as usize + 1] += 1;
        }
        for c in 1..starts.len() {
            starts[c] += starts[c - 1];
        }
        let (mut next, mut labels) = (starts.clone(), vec![0u32; pairs.len()]);
        for (c, label) in pairs {
            labels[next[c as usize] as usize] = label;
            next[c as usize] += 1;
        }
        NearbyRegions { cells_w, starts, labels }
    }

    /// Labels of the regions around pixel (u, v).
    pub(super) fn around(&self, u: usize, v: usize) -> &[u32] {
        let c = (v / CELL_PX) * self.cells_w + u / CELL_PX;
        &self.labels[self.starts[c] as usize..self.starts[c + 1] as usize]
    }
}
