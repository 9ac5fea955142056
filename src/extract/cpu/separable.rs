//! Separable 2-D filters for the CPU twins of the Sobel stages (normals, Canny): a row
//! pass, then a column pass, each a sum of shifted whole rows, so the loops run over
//! contiguous memory and vectorise. The GPU twins sum the same taps in one 2-D loop;
//! the results agree to float rounding.

use super::{ROWS_PER_TASK, widest_simd};
use crate::grid::par_rows;

/// Σ_j along_v[j] Σ_i along_u[i] ch(u + i - r, v + j - r) for every pixel at least r
/// from the border (r = half the kernel length); 0 within r of it.
pub fn filter(ch: &[f32], w: usize, h: usize, along_u: &[f32], along_v: &[f32]) -> Vec<f32> {
    assert_eq!(along_u.len(), along_v.len(), "kernels of one filter have one length");
    let r = along_u.len() / 2;
    if w <= 2 * r || h <= 2 * r {
        return vec![0.0; w * h];
    }
    let rows = par_rows(w, h, 0.0f32, ROWS_PER_TASK, |v, out| {
        row_pass(&ch[v * w..(v + 1) * w], &mut out[r..w - r], along_u);
    });
    par_rows(w, h, 0.0f32, ROWS_PER_TASK, |v, dst| {
        if v >= r && v + r < h {
            column_pass(&rows[(v - r) * w..(v + r + 1) * w], &mut dst[r..w - r], w, r, along_v);
        }
    })
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
    fn filter_equals_the_direct_2d_sum() {
        let (w, h) = (13, 9);
        let ch: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 11) as f32 - 3.0).collect();
        let (ku, kv) = ([1.0, 4.0, 6.0, 4.0, 1.0], [-1.0, -2.0, 0.0, 2.0, 1.0]);
        let out = filter(&ch, w, h, &ku, &kv);
        for v in 0..h {
            for u in 0..w {
                let mut want = 0.0;
                if (2..w - 2).contains(&u) && (2..h - 2).contains(&v) {
                    for j in 0..5 {
                        for i in 0..5 {
                            want += kv[j] * ku[i] * ch[(v + j - 2) * w + u + i - 2];
                        }
                    }
                }
                assert_eq!(out[v * w + u], want, "pixel ({u}, {v})");
            }
        }
    }
}
