//! Non-maximum suppression and the double threshold: the CPU twin of
//! shaders/classify.wgsl, the second part of Canny on the normal image (hysteresis, the
//! third, is `hysteresis`, with Canny whole).

use super::ROWS_PER_TASK;
use super::widest_simd;
use crate::extract::params::Gradient;
use crate::grid::{Grid, par_rows};

/// Offsets of the two neighbours compared in non-maximum suppression, by sector.
pub const SECTOR_STEP: [(isize, isize); 4] = [(1, 0), (1, 1), (0, 1), (-1, 1)];

/// Non-maximum suppression and the double threshold: 0 none, 1 weak, 2 strong per pixel.
pub fn classify(grad: &Gradient, low: f32, high: f32) -> Grid<u8> {
    let (w, h) = (grad.magnitude.width, grad.magnitude.height);
    let class = par_rows(w, h, 0u8, ROWS_PER_TASK, |v, out| {
        if w >= 3 && v >= 1 && v + 1 < h {
            let m = &grad.magnitude.data[(v - 1) * w..(v + 2) * w];
            suppress_row(m, &grad.sector.data[v * w..(v + 1) * w], low, high, out);
        }
        // The image's border, whose neighbours lie off it (0 to the oracle): by the oracle.
        // The gradient leaves sector 4 there, so these are 0.
        let border = if v == 0 || v + 1 == h { 0..w } else { 0..0 };
        for u in border.chain([0, w.saturating_sub(1)]) {
            out[u] = suppressed_class(grad, u, v, low, high);
        }
    });
    Grid { width: w, height: h, data: class }
}

widest_simd! {
    /// One row of `classify`'s interior (columns 1 ..= w - 2): `magnitudes` holds the rows
    /// above, at and below it (w each), `sectors` its sectors, `out` the whole row.
    fn suppress_row(magnitudes: &[f32], sectors: &[u8], low: f32, high: f32, out: &mut [u8]) = suppress_row_portable
}

/// `suppressed_class` for a row's inside, over equal-length slices (the rows shifted by a
/// pixel each way) so that the loop vectorises. A search for the pixels at or over `low`
/// and the oracle on those alone took four to six times as long: on a noisy frame they
/// are most of it.
#[inline(always)]
fn suppress_row_portable(magnitudes: &[f32], sectors: &[u8], low: f32, high: f32, out: &mut [u8]) {
    let w = sectors.len();
    let n = w - 2;
    // Columns 0.., 1.. and 2.. of a row: left of, at and right of the pixels 1 ..= w - 2.
    let shifts = |j: usize| {
        let r = &magnitudes[j * w..(j + 1) * w];
        (&r[..n], &r[1..n + 1], &r[2..n + 2])
    };
    let ((up_left, up, up_right), (left, centre, right), (down_left, down, down_right)) =
        (shifts(0), shifts(1), shifts(2));
    let (sectors, out) = (&sectors[1..n + 1], &mut out[1..n + 1]);
    for i in 0..n {
        let (m, s) = (centre[i], sectors[i]);
        // SECTOR_STEP's neighbours at -1 and +1, picked by masks of their bits (picked by
        // value, the compiler made them gathers).
        let mask = |k: u8| 0u32.wrapping_sub(u32::from(s == k));
        let pick = |c: [f32; 4]| {
            let bits = (c[0].to_bits() & mask(0)) | (c[1].to_bits() & mask(1));
            f32::from_bits(bits | (c[2].to_bits() & mask(2)) | (c[3].to_bits() & mask(3)))
        };
        let before = pick([left[i], up_left[i], up[i], up_right[i]]);
        let after = pick([right[i], down_right[i], down[i], down_left[i]]);
        let kept = (s < 4) & (m >= low) & (m > before) & (m >= after);
        out[i] = u8::from(kept) * (1 + u8::from(m >= high));
    }
}

/// classify.wgsl at pixel (u, v), the oracle: 0, 1 (weak) or 2 (strong) after non-maximum suppression.
#[inline]
pub fn suppressed_class(grad: &Gradient, u: usize, v: usize, low: f32, high: f32) -> u8 {
    let (w, h) = (grad.magnitude.width, grad.magnitude.height);
    let (m, sector) = (grad.magnitude.data[v * w + u], grad.sector.data[v * w + u]);
    if sector == 4 || m < low {
        return 0;
    }
    let (du, dv) = SECTOR_STEP[sector as usize];
    let at = |s: isize| {
        let (nu, nv) = (u as isize + s * du, v as isize + s * dv);
        if nu < 0 || nv < 0 || nu >= w as isize || nv >= h as isize {
            0.0
        } else {
            grad.magnitude.data[nv as usize * w + nu as usize]
        }
    };
    if m > at(-1) && m >= at(1) { if m >= high { 2 } else { 1 } } else { 0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extract::cpu::gradient::normal_gradient;
    use crate::extract::cpu::test_frames::stair_normals;

    #[test]
    fn fast_classes_are_the_oracle_s() {
        let grad = normal_gradient(&stair_normals());
        let (w, h) = (grad.magnitude.width, grad.magnitude.height);
        let fast = classify(&grad, 0.05, 0.1);
        for v in 0..h {
            for u in 0..w {
                assert_eq!(fast.data[v * w + u], suppressed_class(&grad, u, v, 0.05, 0.1), "pixel ({u}, {v})");
            }
        }
        let count = |c: u8| fast.data.iter().filter(|&&x| x == c).count();
        assert!(count(1) > 100 && count(2) > 100, "weak ({}) and strong ({}) pixels to compare", count(1), count(2));
    }
}
