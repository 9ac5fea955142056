//! Binary dilation, erosion and closing by a square: the CPU twin of
//! shaders/morphology.wgsl (`morphology_at` is its oracle, pixel by pixel). The boundary
//! closes its lines with them; the normals find the pixels whose window is all valid.

use rayon::prelude::*;

use crate::extract::params::MorphologyParams;
use crate::grid::{Grid, par_rows};

/// Morphological close (dilate, then erode) with a `size` x `size` square; outside the
/// image counts as edge, so closing never eats into the border.
pub fn close(edges: &Grid<u8>, size: u32) -> Grid<u8> {
    let r = (size / 2) as usize;
    square::<true>(&square::<false>(edges, r, 1), r, 1)
}

/// Binary dilation of a 0/1 mask by a (2r+1)^2 square: 1 where any pixel of the square
/// around is; `outside` is the value of pixels beyond the border.
pub fn dilate(mask: &Grid<u8>, r: usize, outside: u8) -> Grid<u8> {
    square::<false>(mask, r, outside)
}

/// Binary dilation (any pixel of the square set) or, with `ALL`, erosion (every pixel of
/// it set) of a 0/1 mask by a (2r+1)^2 square, separable: each row is the OR (AND) of its
/// 2r + 1 shifted copies, then each row that of the 2r + 1 rows around it (whole rows at a
/// time, so both passes vectorise). `outside` is the value of pixels beyond the border.
fn square<const ALL: bool>(mask: &Grid<u8>, r: usize, outside: u8) -> Grid<u8> {
    let (w, h) = (mask.width, mask.height);
    let identity = u8::from(ALL);
    let mut rows = vec![identity; w * h];
    rows.par_chunks_mut(w).zip(mask.data.par_chunks(w)).with_min_len(16).for_each_init(
        || vec![outside; w + 2 * r],
        |padded, (out, src)| {
            padded[r..r + w].copy_from_slice(src);
            combine_shifted(out, padded, 2 * r + 1, ALL);
        },
    );
    let data = par_rows(w, h, identity, 16, |v, out| {
        if v < r || v + r >= h {
            out.iter_mut().for_each(|o| *o = if ALL { *o & outside } else { *o | outside });
        }
        let (first, end) = (v.saturating_sub(r), (v + r + 1).min(h));
        combine_rows(out, &rows[first * w..end * w], ALL);
    });
    Grid { width: w, height: h, data }
}

super::widest_simd! {
    /// `out` (w long) combined with `shifts` copies of `padded` shifted by 0, 1, ...: with
    /// `all` an AND (erosion), else an OR (dilation). The square's inner loops, compiled
    /// at each vector width: the baseline's is a quarter of AVX-512's.
    fn combine_shifted(out: &mut [u8], padded: &[u8], shifts: usize, all: bool) = combine_shifted_portable
}

super::widest_simd! {
    /// `out` combined with each of the rows of `rows` (whole rows of out's length), as
    /// `combine_shifted` combines.
    fn combine_rows(out: &mut [u8], rows: &[u8], all: bool) = combine_rows_portable
}

#[inline(always)]
fn combine_shifted_portable(out: &mut [u8], padded: &[u8], shifts: usize, all: bool) {
    let w = out.len();
    for k in 0..shifts {
        combine_into(out, &padded[k..k + w], all);
    }
}

#[inline(always)]
fn combine_rows_portable(out: &mut [u8], rows: &[u8], all: bool) {
    for row in rows.chunks_exact(out.len()) {
        combine_into(out, row, all);
    }
}

/// `out[i] &= src[i]` (`all`) or `|=`, over equal-length slices: the loop vectorises.
#[inline(always)]
fn combine_into(out: &mut [u8], src: &[u8], all: bool) {
    let src = &src[..out.len()];
    if all {
        out.iter_mut().zip(src).for_each(|(o, &p)| *o &= p);
    } else {
        out.iter_mut().zip(src).for_each(|(o, &p)| *o |= p);
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extract::params::closing_passes;

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
            assert_eq!(dilate(&mask, size as usize / 2, 1).data, each(&|i| morphology_at(&columns, &by_rows, i)));
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
