//! Edges of the normal image: the CPU twin of the GPU stage shaders/canny.wgsl (the WGSL half lands with the GPU backend).
//!
//! Canny on a vector image: the gradient of the unit-normal field (3x3 Sobel per
//! channel, in change of normal per pixel), its magnitude and Di Zenzo direction,
//! non-maximum suppression along that direction, and hysteresis between the two
//! thresholds. Depth discontinuities and pixels without a normal are edges too, and a
//! morphological close joins broken edges. Directions are chosen by comparisons, not
//! angles, so both twins pick the same neighbours.

use rayon::prelude::*;

use super::separable;
use crate::extract::{Grid, label_components};

const SOBEL_S: [f32; 3] = [1.0, 2.0, 1.0];
const SOBEL_D: [f32; 3] = [-1.0, 0.0, 1.0];

/// Gradient of the normal field: (magnitude, NMS sector 0..4) per pixel; sector 4 marks
/// a pixel whose 3x3 neighbourhood lacks a normal (magnitude 0 there).
pub fn normal_gradient(normals: &Grid<[f32; 3]>) -> Grid<(f32, u8)> {
    let (w, h) = (normals.width, normals.height);
    let channel = |c: usize| -> Vec<f32> { normals.data.iter().map(|n| n[c]).collect() };
    let channels = [channel(0), channel(1), channel(2)];
    let sobel =
        |c: &Vec<f32>| (separable::filter(c, w, h, &SOBEL_D, &SOBEL_S), separable::filter(c, w, h, &SOBEL_S, &SOBEL_D));
    let [(gx0, gy0), (gx1, gy1), (gx2, gy2)] = channels.each_ref().map(sobel);
    let valid: Vec<bool> = normals.data.iter().map(|n| *n != [0.0; 3]).collect();
    let all_valid = separable::window_all_valid(&valid, w, h, 1);
    let mut data = vec![(0.0f32, 4u8); w * h];
    data.par_chunks_mut(w).enumerate().for_each(|(v, out)| {
        for (u, g) in out.iter_mut().enumerate() {
            let i = v * w + u;
            if all_valid[i] {
                *g = gradient_sector([gx0[i], gx1[i], gx2[i]], [gy0[i], gy1[i], gy2[i]]);
            }
        }
    });
    Grid { width: w, height: h, data }
}

/// Magnitude and NMS sector (0: along u, 1: diagonal u+v, 2: along v, 3: diagonal u-v)
/// from the per-channel Sobel sums.
#[inline]
pub fn gradient_sector(gx: [f32; 3], gy: [f32; 3]) -> (f32, u8) {
    let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    // Sobel 3x3 responds 8 to a unit ramp: divide to get change per pixel.
    let (xx, yy, xy) = (dot(gx, gx) / 64.0, dot(gy, gy) / 64.0, dot(gx, gy) / 64.0);
    let magnitude = (xx + yy).sqrt();
    // Di Zenzo: the direction of largest change is at angle theta with
    // tan(2 theta) = 2 xy / (xx - yy); sectors of theta by comparing a and b.
    let (a, b) = (xx - yy, 2.0 * xy);
    let sector = if a >= b.abs() {
        0
    } else if b >= a.abs() {
        1
    } else if -a >= b.abs() {
        2
    } else {
        3
    };
    (magnitude, sector)
}

/// Offsets of the two neighbours compared in non-maximum suppression, by sector.
pub const SECTOR_STEP: [(isize, isize); 4] = [(1, 0), (1, 1), (0, 1), (-1, 1)];

/// Canny edges: 1 where the magnitude is a local maximum across the edge and joins a
/// pixel at or above `high` through pixels at or above `low` (8-connected).
pub fn canny(grad: &Grid<(f32, u8)>, low: f32, high: f32) -> Grid<u8> {
    hysteresis(&classify(grad, low, high))
}

/// Non-maximum suppression and the double threshold: 0 none, 1 weak, 2 strong per pixel.
pub fn classify(grad: &Grid<(f32, u8)>, low: f32, high: f32) -> Grid<u8> {
    let w = grad.width;
    let mut class = vec![0u8; w * grad.height];
    class.par_chunks_mut(w).enumerate().for_each(|(v, out)| {
        for u in 0..w {
            out[u] = suppressed_class(grad, u, v, low, high);
        }
    });
    Grid { width: w, height: grad.height, data: class }
}

/// Hysteresis: 1 for strong pixels and the weak ones 8-connected to them through weak pixels.
pub fn hysteresis(class: &Grid<u8>) -> Grid<u8> {
    let (w, h) = (class.width, class.height);
    let candidate: Vec<bool> = class.data.iter().map(|&c| c != 0).collect();
    let (labels, count) = label_components(&candidate, w, h);
    let mut strong = vec![false; count + 1];
    for (&l, &c) in labels.iter().zip(&class.data) {
        strong[l as usize] |= c == 2;
    }
    Grid { width: w, height: h, data: labels.iter().map(|&l| u8::from(l != 0 && strong[l as usize])).collect() }
}

/// 0, 1 (weak) or 2 (strong) for pixel (u, v) after non-maximum suppression.
#[inline]
pub fn suppressed_class(grad: &Grid<(f32, u8)>, u: usize, v: usize, low: f32, high: f32) -> u8 {
    let (m, sector) = grad.data[v * grad.width + u];
    if sector == 4 || m < low {
        return 0;
    }
    let (du, dv) = SECTOR_STEP[sector as usize];
    let at = |s: isize| {
        let (nu, nv) = (u as isize + s * du, v as isize + s * dv);
        if nu < 0 || nv < 0 || nu >= grad.width as isize || nv >= grad.height as isize {
            0.0
        } else {
            grad.data[nv as usize * grad.width + nu as usize].0
        }
    };
    if m > at(-1) && m >= at(1) { if m >= high { 2 } else { 1 } } else { 0 }
}

/// 1 where the pixel cannot be inside a planar region: the closed edge lines (Canny,
/// and depth steps to a 4-neighbour larger than `ratio` times the depth), or no normal.
/// The lines are closed with the `closing` square. Pixels without a normal are closed
/// together with the lines only with the small `seal` square: a sensor dropout spoils
/// a kernel-sized square of normals and breaks the Canny line through it, leaving
/// narrow channels between the square and the line's ends that regions would leak
/// through; closing them with the big square would grow clusters of dropouts into
/// blobs that eat the surfaces around them.
pub fn boundary(
    canny: &Grid<u8>,
    depth: &Grid<f32>,
    ratio: f32,
    normals: &Grid<[f32; 3]>,
    closing: u32,
    seal: u32,
) -> Grid<u8> {
    let (w, h) = (depth.width, depth.height);
    let mut lines = vec![0u8; w * h];
    lines.par_chunks_mut(w).enumerate().for_each(|(v, out)| {
        for u in 0..w {
            let i = v * w + u;
            let z = depth.data[i];
            let step = any_4_neighbour(u, v, w, h, |j| {
                z != 0.0 && depth.data[j] != 0.0 && (depth.data[j] - z).abs() > ratio * z
            });
            out[u] = (canny.data[i] != 0 || step) as u8;
        }
    });
    let closed = close(&Grid { width: w, height: h, data: lines }, closing);
    let with_holes = Grid {
        width: w,
        height: h,
        data: closed.data.iter().zip(&normals.data).map(|(&l, n)| (l != 0 || *n == [0.0; 3]) as u8).collect(),
    };
    let sealed = close(&with_holes, seal);
    // Regions are 8-connected (as contour tracing sees them), so a thin diagonal line
    // would leak: growing each line pixel into its 4-neighbours seals it.
    let mut out = vec![0u8; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
        for u in 0..w {
            let i = v * w + u;
            let line = closed.data[i] != 0 || any_4_neighbour(u, v, w, h, |j| closed.data[j] != 0);
            row[u] = (line || sealed.data[i] != 0) as u8;
        }
    });
    Grid { width: w, height: h, data: out }
}

/// Whether `f` holds for the index of any 4-neighbour of (u, v) inside a w x h image.
#[inline]
fn any_4_neighbour(u: usize, v: usize, w: usize, h: usize, f: impl Fn(usize) -> bool) -> bool {
    let i = v * w + u;
    (u > 0 && f(i - 1)) || (u + 1 < w && f(i + 1)) || (v > 0 && f(i - w)) || (v + 1 < h && f(i + w))
}

/// Morphological close (dilate, then erode) with a `size` x `size` square; outside the
/// image counts as edge, so closing never eats into the border.
pub fn close(edges: &Grid<u8>, size: u32) -> Grid<u8> {
    let r = (size / 2) as usize;
    let dilated = dilate(edges, r, 1);
    let inverted =
        Grid { width: dilated.width, height: dilated.height, data: dilated.data.iter().map(|&e| 1 - e).collect() };
    let eroded_inv = dilate(&inverted, r, 0);
    Grid { width: edges.width, height: edges.height, data: eroded_inv.data.iter().map(|&e| 1 - e).collect() }
}

/// Binary dilation by a (2r+1)^2 square, separable: each row is the OR of its 2r + 1
/// shifted copies, then each row the OR of the 2r + 1 rows around it (whole rows at
/// a time, so both passes vectorise). `outside` is the value of pixels beyond the border.
pub fn dilate(mask: &Grid<u8>, r: usize, outside: u8) -> Grid<u8> {
    let (w, h) = (mask.width, mask.height);
    let mut rows = vec![0u8; w * h];
    rows.par_chunks_mut(w).zip(mask.data.par_chunks(w)).with_min_len(16).for_each(|(out, src)| {
        let mut padded = vec![outside; w + 2 * r];
        padded[r..r + w].copy_from_slice(src);
        for k in 0..=2 * r {
            out.iter_mut().zip(&padded[k..k + w]).for_each(|(o, &p)| *o |= p);
        }
    });
    let mut data = vec![0u8; w * h];
    data.par_chunks_mut(w).enumerate().with_min_len(16).for_each(|(v, out)| {
        if v < r || v + r >= h {
            out.fill(outside);
        }
        for j in v.saturating_sub(r)..(v + r + 1).min(h) {
            out.iter_mut().zip(&rows[j * w..(j + 1) * w]).for_each(|(o, &p)| *o |= p);
        }
    });
    Grid { width: w, height: h, data }
}
