//! The Sobel derivatives of the normals stage on the CPU: a derivative pass along one
//! axis, then a smoothing pass along the other, each over whole rows so that the loops run
//! over contiguous memory and vectorise.
//!
//! The derivative is taken as differences of the pixels either side of the centre,
//! Σ_k c_k (z[+k] - z[-k]), not as Σ_i d_i z[i]: on a smooth surface the neighbours'
//! depths are within a factor of two of each other, so each difference is exact, and so
//! are the small integer multiples and their sums. The derivatives are then the same bits
//! whatever order or fused multiply-adds a GPU uses (the weighted sum of raw depths lost
//! the millimetres in the metres and differed in the fifth decimal of the normal on an
//! NVIDIA GPU), and the normals lose nothing to cancellation.

use super::{ROWS_PER_TASK, widest_simd};
use crate::grid::par_rows;

/// The derivative kernel's weights right of its centre, c_1..c_r (the left ones are their
/// negatives, the centre 0).
pub fn half_derivative(deriv: &[f32]) -> &[f32] {
    let r = deriv.len() / 2;
    debug_assert!(deriv[r] == 0.0 && (1..=r).all(|k| deriv[r - k] == -deriv[r + k]), "antisymmetric");
    &deriv[r + 1..]
}

/// Σ_j smooth[j] Σ_k c_k (z(u + k, v + j - r) - z(u - k, v + j - r)), the derivative along u
/// smoothed along v, for every pixel at least r from the border; 0 within r of it.
pub fn derivative_u(z: &[f32], w: usize, h: usize, deriv: &[f32], smooth: &[f32]) -> Vec<f32> {
    let r = smooth.len() / 2;
    if w <= 2 * r || h <= 2 * r {
        return vec![0.0; w * h];
    }
    let c = half_derivative(deriv);
    let rows = par_rows(w, h, 0.0f32, ROWS_PER_TASK, |v, out| {
        differences(&z[v * w..(v + 1) * w], 1, r, &mut out[r..w - r], c);
    });
    par_rows(w, h, 0.0f32, ROWS_PER_TASK, |v, dst| {
        if v >= r && v + r < h {
            column_pass(&rows[(v - r) * w..(v + r + 1) * w], &mut dst[r..w - r], w, r, smooth);
        }
    })
}

/// Σ_t smooth[t] Σ_k c_k (z(u + t - r, v + k) - z(u + t - r, v - k)), the derivative along v
/// smoothed along u; 0 within r of the border.
pub fn derivative_v(z: &[f32], w: usize, h: usize, deriv: &[f32], smooth: &[f32]) -> Vec<f32> {
    let r = smooth.len() / 2;
    if w <= 2 * r || h <= 2 * r {
        return vec![0.0; w * h];
    }
    let c = half_derivative(deriv);
    let columns = par_rows(w, h, 0.0f32, ROWS_PER_TASK, |v, out| {
        if v >= r && v + r < h {
            differences(&z[(v - r) * w..(v + r + 1) * w], w, r * w, out, c);
        }
    });
    par_rows(w, h, 0.0f32, ROWS_PER_TASK, |v, dst| {
        if v >= r && v + r < h {
            row_pass(&columns[v * w..(v + 1) * w], &mut dst[r..w - r], smooth);
        }
    })
}

widest_simd! {
    /// out[i] = Σ_k c[k - 1] (src[centre + i + k step] - src[centre + i - k step]), k = 1..=c.len().
    fn differences(src: &[f32], step: usize, centre: usize, out: &mut [f32], c: &[f32]) = differences_portable
}

#[inline(always)]
fn differences_portable(src: &[f32], step: usize, centre: usize, out: &mut [f32], c: &[f32]) {
    let n = out.len();
    for (k, &ck) in (1..).zip(c) {
        let (ahead, behind) = (&src[centre + k * step..][..n], &src[centre - k * step..][..n]);
        for ((o, &a), &b) in out.iter_mut().zip(ahead).zip(behind) {
            *o += ck * (a - b);
        }
    }
}

widest_simd! {
    /// out[u] = Σ_i k[i] src[u + i] (out is src's interior).
    fn row_pass(src: &[f32], out: &mut [f32], k: &[f32]) = row_pass_portable
}

#[inline(always)]
fn row_pass_portable(src: &[f32], out: &mut [f32], k: &[f32]) {
    let n = out.len();
    for (i, &ki) in k.iter().enumerate() {
        for (o, &s) in out.iter_mut().zip(&src[i..i + n]) {
            *o += ki * s;
        }
    }
}

widest_simd! {
    /// out[u] = Σ_j k[j] rows[j * w + r + u] over the 2r + 1 rows given.
    fn column_pass(rows: &[f32], out: &mut [f32], w: usize, r: usize, k: &[f32]) = column_pass_portable
}

#[inline(always)]
fn column_pass_portable(rows: &[f32], out: &mut [f32], w: usize, r: usize, k: &[f32]) {
    let n = out.len();
    for (j, &kj) in k.iter().enumerate() {
        for (o, &s) in out.iter_mut().zip(&rows[j * w + r..j * w + r + n]) {
            *o += kj * s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derivatives_equal_the_direct_2d_sums() {
        // Small integers: every sum is exact, so any order gives the same answer.
        let (w, h) = (13, 9);
        let ch: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 11) as f32 - 3.0).collect();
        let (smooth, deriv) = ([1.0, 4.0, 6.0, 4.0, 1.0], [-1.0, -2.0, 0.0, 2.0, 1.0]);
        let (du, dv) = (derivative_u(&ch, w, h, &deriv, &smooth), derivative_v(&ch, w, h, &deriv, &smooth));
        for v in 0..h {
            for u in 0..w {
                let (mut want_u, mut want_v) = (0.0, 0.0);
                if (2..w - 2).contains(&u) && (2..h - 2).contains(&v) {
                    for j in 0..5 {
                        for i in 0..5 {
                            let z = ch[(v + j - 2) * w + u + i - 2];
                            want_u += smooth[j] * deriv[i] * z;
                            want_v += deriv[j] * smooth[i] * z;
                        }
                    }
                }
                assert_eq!(du[v * w + u], want_u, "d/du at ({u}, {v})");
                assert_eq!(dv[v * w + u], want_v, "d/dv at ({u}, {v})");
            }
        }
    }

    #[test]
    fn derivatives_of_a_smooth_surface_keep_their_precision() {
        // Depths of a tilted plane near 1.5 m. Differences of neighbours are exact, so the
        // derivative is off the exact sum of the same f32 depths by a rounding of its own
        // size (here under 1e-6 of it), not of the depths' (the weighted sum of raw depths
        // misses by ~1e-5 of it at 5 x 5 and 7 x 7).
        let (w, h) = (40, 30);
        let z: Vec<f32> = (0..w * h).map(|i| 1.5 + 0.0123 * (i % w) as f32 + 0.0071 * (i / w) as f32).collect();
        for size in [3, 5, 7] {
            let (smooth, deriv, _) = crate::extract::params::sobel_kernel(size);
            let r = smooth.len() / 2;
            let (du, dv) = (derivative_u(&z, w, h, deriv, smooth), derivative_v(&z, w, h, deriv, smooth));
            for v in r..h - r {
                for u in r..w - r {
                    let (mut want_u, mut want_v) = (0.0f64, 0.0f64);
                    for j in 0..smooth.len() {
                        for i in 0..smooth.len() {
                            let z = z[(v + j - r) * w + u + i - r] as f64;
                            want_u += (smooth[j] * deriv[i]) as f64 * z;
                            want_v += (deriv[j] * smooth[i]) as f64 * z;
                        }
                    }
                    for (got, want, axis) in [(du[v * w + u], want_u, "u"), (dv[v * w + u], want_v, "v")] {
                        let error = (got as f64 - want).abs() / want.abs();
                        assert!(error < 1e-6, "size {size}: d/d{axis} at ({u}, {v}) off by {error:e} of itself");
                    }
                }
            }
        }
    }
}
