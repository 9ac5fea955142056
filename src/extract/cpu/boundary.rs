//! Where a pixel cannot be inside a planar region: the CPU twin of shaders/boundary.wgsl
//! and shaders/morphology.wgsl. Canny edges and depth steps are closed into lines,
//! pixels without a normal sealed to them, and every line pixel grown into its
//! 4-neighbours. The fast loops work on whole rows; `boundary_oracle` runs the shaders'
//! passes pixel by pixel, one function per entry point.

use rayon::prelude::*;

use super::ROWS_PER_TASK;
use crate::extract::gpu::{BoundaryParams, MorphologyParams};
use crate::grid::Grid;

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
    lines.par_chunks_mut(w).enumerate().with_min_len(ROWS_PER_TASK).for_each(|(v, out)| {
        let row = |v: usize| &depth.data[v * w..(v + 1) * w];
        let (above, below) = ((v > 0).then(|| row(v - 1)), (v + 1 < h).then(|| row(v + 1)));
        depth_steps(row(v), above.unwrap_or(&[]), below.unwrap_or(&[]), out, ratio);
        out.iter_mut().zip(&canny.data[v * w..(v + 1) * w]).for_each(|(o, &c)| *o |= u8::from(c != 0));
    });
    let closed = close(&Grid { width: w, height: h, data: lines }, closing);
    let with_holes = Grid {
        width: w,
        height: h,
        data: closed.data.iter().zip(&normals.data).map(|(&l, n)| (l != 0 || *n == [0.0; 3]) as u8).collect(),
    };
    let sealed = close(&with_holes, seal);
    // Regions are 8-connected (as contour tracing sees them), so a thin diagonal line
    // would leak: growing each line pixel into its 4-neighbours (a plus-shaped dilation,
    // in whole rows) seals it.
    let mut out = vec![0u8; w * h];
    out.par_chunks_mut(w).enumerate().with_min_len(ROWS_PER_TASK).for_each(|(v, row)| {
        let line = |v: usize| &closed.data[v * w..(v + 1) * w];
        row.copy_from_slice(line(v));
        for (o, &left) in row[1..].iter_mut().zip(line(v)) {
            *o |= left;
        }
        for (o, &right) in row.iter_mut().zip(&line(v)[1..]) {
            *o |= right;
        }
        for j in [v.wrapping_sub(1), v + 1] {
            if j < h {
                row.iter_mut().zip(line(j)).for_each(|(o, &l)| *o |= l);
            }
        }
        row.iter_mut().zip(&sealed.data[v * w..(v + 1) * w]).for_each(|(o, &s)| *o |= s);
    });
    Grid { width: w, height: h, data: out }
}

/// 1 in `out` where the depth steps to a 4-neighbour by more than `ratio` times the depth
/// (both valid); `above` and `below` are the neighbouring rows, empty beyond the image.
/// Whole-row comparisons, so the loops vectorise.
fn depth_steps(row: &[f32], above: &[f32], below: &[f32], out: &mut [u8], ratio: f32) {
    let jump = |z: f32, q: f32| u8::from(z != 0.0 && q != 0.0 && (q - z).abs() > ratio * z);
    out.fill(0);
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

/// Morphological close (dilate, then erode) with a `size` x `size` square; outside the
/// image counts as edge, so closing never eats into the border.
pub fn close(edges: &Grid<u8>, size: u32) -> Grid<u8> {
    let r = (size / 2) as usize;
    square::<true>(&square::<false>(edges, r, 1), r, 1)
}

/// Binary dilation (any pixel of the square set) or, with `ALL`, erosion (every pixel of
/// it set) of a 0/1 mask by a (2r+1)^2 square, separable: each row is the OR (AND) of its
/// 2r + 1 shifted copies, then each row that of the 2r + 1 rows around it (whole rows at a
/// time, so both passes vectorise). `outside` is the value of pixels beyond the border.
fn square<const ALL: bool>(mask: &Grid<u8>, r: usize, outside: u8) -> Grid<u8> {
    let (w, h) = (mask.width, mask.height);
    let combine = |o: &mut u8, p: u8| if ALL { *o &= p } else { *o |= p };
    let identity = u8::from(ALL);
    let mut rows = vec![identity; w * h];
    rows.par_chunks_mut(w).zip(mask.data.par_chunks(w)).with_min_len(16).for_each_init(
        || vec![outside; w + 2 * r],
        |padded, (out, src)| {
            padded[r..r + w].copy_from_slice(src);
            for k in 0..=2 * r {
                out.iter_mut().zip(&padded[k..k + w]).for_each(|(o, &p)| combine(o, p));
            }
        },
    );
    let mut data = vec![identity; w * h];
    data.par_chunks_mut(w).enumerate().with_min_len(16).for_each(|(v, out)| {
        if v < r || v + r >= h {
            out.iter_mut().for_each(|o| combine(o, outside));
        }
        for j in v.saturating_sub(r)..(v + r + 1).min(h) {
            out.iter_mut().zip(&rows[j * w..(j + 1) * w]).for_each(|(o, &p)| combine(o, p));
        }
    });
    Grid { width: w, height: h, data }
}

/// shaders/morphology.wgsl at pixel i: one axis of a square dilation (any) or erosion (all).
pub fn morphology_at(p: &MorphologyParams, src: &[u8], i: usize) -> u8 {
    let (x, y) = (i % p.width as usize, i / p.width as usize);
    let r = p.radius as isize;
    let (at, len, stride) =
        if p.axis == 1 { (y as isize, p.height as isize, p.width as isize) } else { (x as isize, p.width as isize, 1) };
    let (mut any, mut all) = (0u8, 1u8);
    for k in -r..=r {
        let j = at + k;
        let x =
            if j >= 0 && j < len { u8::from(src[(i as isize + k * stride) as usize] != 0) } else { p.outside as u8 };
        any |= x;
        all &= x;
    }
    if p.all == 1 { all } else { any }
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

/// The square passes of a morphological close: dilation then erosion, each rows then
/// columns; outside the image counts as set, so closing never eats into the border.
pub fn closing_passes(width: u32, height: u32, size: u32) -> [MorphologyParams; 4] {
    let pass = |axis, all| MorphologyParams { width, height, radius: size / 2, axis, all, outside: 1 };
    [pass(0, 0), pass(1, 0), pass(0, 1), pass(1, 1)]
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
    use crate::extract::cpu::canny::canny;
    use crate::extract::cpu::canny::normal_gradient;
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
        let fast = boundary(&canny, &depth, 0.03, &n, 7, 5);
        let want = boundary_oracle(&canny, &depth, 0.03, &n, 7, 5);
        assert_eq!(fast, want);
        let ones = want.data.iter().filter(|&&b| b != 0).count();
        assert!(ones > w * h / 20 && ones < w * h * 9 / 10, "a boundary worth comparing: {ones} of {} px", w * h);
    }

    #[test]
    fn fast_dilation_and_erosion_are_the_oracle_s_passes() {
        let (w, h) = (37usize, 29usize);
        let mask = Grid {
            width: w,
            height: h,
            data: (0..w * h)
                .map(|i| u8::from(crate::extract::cpu::ransac::hash(i as u32).is_multiple_of(13)))
                .collect(),
        };
        for size in [3, 5, 7] {
            // A dilation with the outside set, and a whole close.
            let [rows, columns, ..] = closing_passes(w as u32, h as u32, size);
            let each = |f: &dyn Fn(usize) -> u8| (0..w * h).map(f).collect::<Vec<u8>>();
            let by_rows = each(&|i| morphology_at(&rows, &mask.data, i));
            assert_eq!(
                square::<false>(&mask, size as usize / 2, 1).data,
                each(&|i| morphology_at(&columns, &by_rows, i))
            );
            let mut closed = mask.data.clone();
            for pass in closing_passes(w as u32, h as u32, size) {
                closed = each(&|i| morphology_at(&pass, &closed, i));
            }
            let fast = close(&mask, size);
            assert_eq!(fast.data, closed, "close {size}");
            assert_ne!(fast, mask, "close {size} changes the mask");
        }
    }
}
