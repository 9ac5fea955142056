//! Where a pixel cannot be inside a planar region: the CPU twin of shaders/boundary.wgsl.
//! Canny edges and depth steps are closed into lines (`morphology::close`), pixels
//! without a normal sealed to them, and every line pixel grown into its 4-neighbours. The fast loops work on whole rows; `boundary_oracle` runs the shaders'
//! passes pixel by pixel, one function per entry point.

use super::ROWS_PER_TASK;
use super::morphology::{close, morphology_at};
use crate::extract::params::{BoundaryParams, NormalPlanes, closing_passes};
use crate::grid::{Grid, par_rows, rows_around};

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
    normals: &NormalPlanes,
    closing: u32,
    seal: u32,
) -> Grid<u8> {
    let (w, h) = (depth.width, depth.height);
    let lines = par_rows(w, h, 0u8, ROWS_PER_TASK, |v, out| {
        let [above, row, below] = rows_around(&depth.data, w, v);
        edges_and_depth_steps(&canny.data[v * w..(v + 1) * w], row, above, below, out, ratio);
    });
    let closed = close(&Grid { width: w, height: h, data: lines }, closing);
    // The normals' validity plane, a row at a time: 0 where the pixel has no normal.
    let with_holes = par_rows(w, h, 0u8, ROWS_PER_TASK, |v, out| {
        let valid = &normals.data[(4 * v + 3) * w..(4 * v + 4) * w];
        lines_or_holes(&closed.data[v * w..(v + 1) * w], valid, out);
    });
    let with_holes = Grid { width: w, height: h, data: with_holes };
    let sealed = close(&with_holes, seal);
    // Regions are 8-connected (as contour tracing sees them), so a thin diagonal line
    // would leak: growing each line pixel into its 4-neighbours (a plus-shaped dilation,
    // in whole rows) seals it.
    let out = par_rows(w, h, 0u8, ROWS_PER_TASK, |v, row| {
        let [above, line, below] = rows_around(&closed.data, w, v);
        plus_or_sealed(line, above, below, &sealed.data[v * w..(v + 1) * w], row);
    });
    Grid { width: w, height: h, data: out }
}

super::widest_simd! {
    /// One row of the boundary: the lines grown into their 4-neighbours (`line` the row's,
    /// `above` and `below` the neighbouring rows', as `rows_around` gives them), or `sealed`.
    /// A kernel, as `lines_or_holes` is: as a closure it ran at SSE2 whatever the CPU.
    fn plus_or_sealed(line: &[u8], above: &[u8], below: &[u8], sealed: &[u8], out: &mut [u8]) = plus_or_sealed_portable
}

#[inline(always)]
fn plus_or_sealed_portable(line: &[u8], above: &[u8], below: &[u8], sealed: &[u8], out: &mut [u8]) {
    let n = out.len();
    let (line, sealed) = (&line[..n], &sealed[..n]);
    for i in 0..n {
        out[i] = line[i] | sealed[i];
    }
    for (o, &left) in out[1..].iter_mut().zip(line) {
        *o |= left;
    }
    for (o, &right) in out.iter_mut().zip(&line[1..]) {
        *o |= right;
    }
    for other in [above, below] {
        out.iter_mut().zip(other).for_each(|(o, &l)| *o |= l);
    }
}

super::widest_simd! {
    /// 1 in `out` where a line (`lines`) or no normal (`valid` 0): one row. Compiled at
    /// each width, as the closure around it was not.
    fn lines_or_holes(lines: &[u8], valid: &[f32], out: &mut [u8]) = lines_or_holes_portable
}

#[inline(always)]
fn lines_or_holes_portable(lines: &[u8], valid: &[f32], out: &mut [u8]) {
    let n = out.len();
    let (lines, valid) = (&lines[..n], &valid[..n]);
    for i in 0..n {
        out[i] = u8::from((lines[i] != 0) | (valid[i] == 0.0));
    }
}

super::widest_simd! {
    /// 1 in `out` where a Canny edge (`edges`) is, or where the depth steps to a 4-neighbour
    /// by more than `ratio` (> 0) times the depth (both valid); `above` and `below` are the
    /// neighbouring rows, as `rows_around` gives them (the row itself steps nowhere).
    fn edges_and_depth_steps(edges: &[u8], row: &[f32], above: &[f32], below: &[f32], out: &mut [u8], ratio: f32) = edges_and_depth_steps_portable
}

/// Whole-row comparisons, so the loops vectorise.
#[inline(always)]
fn edges_and_depth_steps_portable(edges: &[u8], row: &[f32], above: &[f32], below: &[f32], out: &mut [u8], ratio: f32) {
    // `&`, not `&&`: no branches, so the loops vectorise.
    let jump = |z: f32, q: f32| u8::from((z != 0.0) & (q != 0.0) & ((q - z).abs() > ratio * z));
    out.iter_mut().zip(edges).for_each(|(o, &e)| *o = u8::from(e != 0));
    // Right neighbours (zip stops at the row's end), then left ones; rows are never empty.
    for (o, (&z, &q)) in out.iter_mut().zip(row.iter().zip(&row[1..])) {
        *o |= jump(z, q);
    }
    for (o, (&z, &q)) in out[1..].iter_mut().zip(row[1..].iter().zip(row)) {
        *o |= jump(z, q);
    }
    for other in [above, below] {
        for (o, (&z, &q)) in out.iter_mut().zip(row.iter().zip(other)) {
            *o |= jump(z, q);
        }
    }
}

/// boundary.wgsl's `lines` at pixel i: a Canny edge, or a depth step to a 4-neighbour.
pub fn line_at(p: &BoundaryParams, depth: &[f32], edges: &[u8], i: usize) -> u8 {
    let (w, x, y) = (p.width as usize, i % p.width as usize, i / p.width as usize);
    let z = depth[i];
    let jump = |j: usize| {
        let q = depth[j];
        u8::from(z != 0.0 && q != 0.0 && (q - z).abs() > p.depth_edge_ratio * z)
    };
    let mut line = u8::from(edges[i] != 0);
    if x + 1 < w {
        line |= jump(i + 1);
    }
    if x > 0 {
        line |= jump(i - 1);
    }
    if y > 0 {
        line |= jump(i - w);
    }
    if y + 1 < p.height as usize {
        line |= jump(i + w);
    }
    line
}

/// boundary.wgsl's `holes` at pixel i: a closed line, or no normal.
pub fn holes_at(closed: &[u8], normals: &[[f32; 3]], i: usize) -> u8 {
    u8::from(closed[i] != 0 || normals[i] == [0.0; 3])
}

/// boundary.wgsl's `seal` at pixel i: a closed line pixel or its 4-neighbour, or sealed.
pub fn seal_at(p: &BoundaryParams, closed: &[u8], sealed: &[u8], i: usize) -> u8 {
    let (w, x, y) = (p.width as usize, i % p.width as usize, i / p.width as usize);
    let mut out = closed[i] | sealed[i];
    if x > 0 {
        out |= closed[i - 1];
    }
    if x + 1 < w {
        out |= closed[i + 1];
    }
    if y > 0 {
        out |= closed[i - w];
    }
    if y + 1 < p.height as usize {
        out |= closed[i + w];
    }
    u8::from(out != 0)
}

/// `boundary` as the GPU computes it: every pass of shaders/boundary.wgsl and
/// shaders/morphology.wgsl in turn, pixel by pixel.
pub fn boundary_oracle(
    canny: &Grid<u8>,
    depth: &Grid<f32>,
    ratio: f32,
    normals: &Grid<[f32; 3]>,
    closing: u32,
    seal: u32,
) -> Grid<u8> {
    let (w, h) = (depth.width as u32, depth.height as u32);
    let p = BoundaryParams { width: w, height: h, depth_edge_ratio: ratio, pad: 0 };
    let n = depth.data.len();
    let each = |f: &dyn Fn(usize) -> u8| (0..n).map(f).collect::<Vec<u8>>();
    let close = |mut img: Vec<u8>, size| {
        for pass in closing_passes(w, h, size) {
            img = each(&|i| morphology_at(&pass, &img, i));
        }
        img
    };
    let lines = each(&|i| line_at(&p, &depth.data, &canny.data, i));
    let closed = close(lines, closing);
    let with_holes = each(&|i| holes_at(&closed, &normals.data, i));
    let sealed = close(with_holes, seal);
    Grid { width: depth.width, height: depth.height, data: each(&|i| seal_at(&p, &closed, &sealed, i)) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extract::cpu::gradient::normal_gradient;
    use crate::extract::cpu::hysteresis::canny;
    use crate::extract::cpu::test_frames::stair_normals;

    #[test]
    fn fast_boundary_is_the_oracle() {
        let n = stair_normals();
        let (w, h) = (n.width, n.height);
        // Depth with steps and holes, Canny lines from the gradient of these normals.
        let depth = Grid {
            width: w,
            height: h,
            data: (0..w * h)
                .map(|i| if n.data[i] == [0.0; 3] && i % 3 == 0 { 0.0 } else { 1.0 + 0.3 * ((i % w) / 40) as f32 })
                .collect(),
        };
        let canny = canny(&normal_gradient(&n), 0.05, 0.1);
        let fast = boundary(&canny, &depth, 0.03, &NormalPlanes::of(&n), 7, 5);
        let want = boundary_oracle(&canny, &depth, 0.03, &n, 7, 5);
        assert_eq!(fast, want);
        let ones = want.data.iter().filter(|&&b| b != 0).count();
        assert!(ones > w * h / 20 && ones < w * h * 9 / 10, "a boundary worth comparing: {ones} of {} px", w * h);
    }
}
