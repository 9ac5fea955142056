//! The gradient of the normal image: the CPU twin of shaders/gradient.wgsl, the first half
//! of Canny on a vector image. The gradient of the unit-normal field (3x3 Sobel per channel,
//! in change of normal per pixel), its magnitude and Di Zenzo direction as one of four
//! sectors. Directions are chosen by comparisons, not angles, so both twins pick the same
//! neighbours (`classify` suppresses along them).

use rayon::prelude::*;

use super::{ROWS_PER_TASK, widest_simd};
pub use crate::extract::params::Gradient;
use crate::extract::params::NormalPlanes;
use crate::grid::Grid;

/// Gradient of the normal field (`Gradient`). The fast loop reads the normals as planes
/// of x, y, z and validity (`NormalPlanes`, which the normals stage writes beside the
/// interleaved normals), so that each row is one pass of plain slice arithmetic over the three rows around it, and
/// vectorises. Sums in the order of `gradient_at` (and of shaders/gradient.wgsl): the
/// results are the same bits.
pub fn normal_gradient(normals: &Grid<[f32; 3]>) -> Gradient {
    gradient_of_planes(&NormalPlanes::of(normals))
}

/// `normal_gradient` of normals already split into planes (as the normals stage hands them on).
pub fn gradient_of_planes(planes: &NormalPlanes) -> Gradient {
    let (w, h) = (planes.width, planes.height);
    let (mut magnitude, mut sector) = (vec![0.0f32; w * h], vec![4u8; w * h]);
    if w >= 3 && h >= 3 {
        let planes = &planes.data;
        (magnitude.par_chunks_mut(w).zip(sector.par_chunks_mut(w)).enumerate().with_min_len(ROWS_PER_TASK))
            .for_each_init(
                || vec![0.0f32; 7 * w],
                |scratch, (v, (m, s))| {
                    if v >= 1 && v + 1 < h {
                        let rows = &planes[(v - 1) * 4 * w..(v + 2) * 4 * w];
                        gradient_row(rows, &mut m[1..w - 1], &mut s[1..w - 1], w, scratch);
                    }
                },
            );
    }
    Gradient {
        magnitude: Grid { width: w, height: h, data: magnitude },
        sector: Grid { width: w, height: h, data: sector },
    }
}

widest_simd! {
    /// One row of `normal_gradient`: `planes` holds the planes of the rows above, at and
    /// below it; `magnitudes` and `sectors` are the row's interior (columns 1 ..= w - 2);
    /// scratch of 7w floats.
    fn gradient_row(planes: &[f32], magnitudes: &mut [f32], sectors: &mut [u8], w: usize, scratch: &mut [f32]) = gradient_row_portable
}

/// Loops over equal-length slices only, so that they carry no bounds checks and vectorise.
#[inline(always)]
fn gradient_row_portable(planes: &[f32], magnitudes: &mut [f32], sectors: &mut [u8], w: usize, scratch: &mut [f32]) {
    let n = magnitudes.len();
    // Taps left, centre and right of plane c of row j (0 above, 1 at, 2 below).
    let taps = |j: usize, c: usize| {
        let p = &planes[(4 * j + c) * w..][..n + 2];
        (&p[..n], &p[1..n + 1], &p[2..n + 2])
    };
    let (sums, ok) = scratch.split_at_mut(6 * n);
    let ok = &mut ok[..n];
    let sectors = &mut sectors[..n];
    for (c, g) in sums.chunks_exact_mut(2 * n).enumerate() {
        let (gx, gy) = g.split_at_mut(n);
        let ((l0, m0, r0), (l1, _, r1), (l2, m2, r2)) = (taps(0, c), taps(1, c), taps(2, c));
        for i in 0..n {
            // Row sums, then the column (d = -1 0 1 along, s = 1 2 1 across).
            gx[i] = (r0[i] - l0[i]) + 2.0 * (r1[i] - l1[i]) + (r2[i] - l2[i]);
            gy[i] = (l2[i] + 2.0 * m2[i] + r2[i]) - (l0[i] + 2.0 * m0[i] + r0[i]);
        }
    }
    ok.fill(1.0);
    for j in 0..3 {
        let (l, m, r) = taps(j, 3);
        for i in 0..n {
            ok[i] = ok[i].min(l[i]).min(m[i]).min(r[i]);
        }
    }
    let (g0, rest) = sums.split_at(2 * n);
    let (g1, g2) = rest.split_at(2 * n);
    let ((gx0, gy0), (gx1, gy1), (gx2, gy2)) = (g0.split_at(n), g1.split_at(n), g2.split_at(n));
    for i in 0..n {
        let (m, sector) = gradient_sector([gx0[i], gx1[i], gx2[i]], [gy0[i], gy1[i], gy2[i]]);
        let valid = ok[i] == 1.0;
        magnitudes[i] = if valid { m } else { 0.0 };
        sectors[i] = if valid { sector } else { 4 };
    }
}

/// The oracle of `normal_gradient`: pixel (u, v) alone, line for line as shaders/gradient.wgsl
/// computes it.
pub fn gradient_at(normals: &Grid<[f32; 3]>, u: usize, v: usize) -> (f32, u8) {
    let (w, h) = (normals.width, normals.height);
    if u == 0 || v == 0 || u + 1 >= w || v + 1 >= h {
        return (0.0, 4);
    }
    let (s, d) = ([1.0f32, 2.0, 1.0], [-1.0f32, 0.0, 1.0]);
    let (mut gx, mut gy) = ([0.0f32; 3], [0.0f32; 3]);
    // Row sums first, then the column.
    for j in 0..3 {
        let (mut row_x, mut row_y) = ([0.0f32; 3], [0.0f32; 3]);
        for t in 0..3 {
            let n = normals.data[(v + j - 1) * w + u + t - 1];
            if n == [0.0; 3] {
                return (0.0, 4);
            }
            for c in 0..3 {
                row_x[c] += d[t] * n[c];
                row_y[c] += s[t] * n[c];
            }
        }
        for c in 0..3 {
            gx[c] += s[j] * row_x[c];
            gy[c] += d[j] * row_y[c];
        }
    }
    gradient_sector(gx, gy)
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
    // The first of: a >= |b| (0), b >= |a| (1), -a >= |b| (2), else 3; by arithmetic on
    // the comparisons, not branches, so the row loop vectorises.
    let (not0, not1, not2) = (u8::from(!(a >= b.abs())), u8::from(!(b >= a.abs())), u8::from(!(-a >= b.abs())));
    (magnitude, not0 * (1 + not1 * (1 + not2)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extract::cpu::test_frames::stair_normals;

    #[test]
    fn fast_gradient_is_the_oracle_bit_for_bit() {
        let n = stair_normals();
        let fast = normal_gradient(&n);
        let mut edges = 0;
        for v in 0..n.height {
            for u in 0..n.width {
                let (m, s) = (fast.magnitude.data[v * n.width + u], fast.sector.data[v * n.width + u]);
                let (want_m, want_s) = gradient_at(&n, u, v);
                assert_eq!((m.to_bits(), s), (want_m.to_bits(), want_s), "pixel ({u}, {v})");
                edges += usize::from(s != 4 && m > 0.05);
            }
        }
        let holes = fast.sector.data.iter().filter(|&&s| s == 4).count();
        assert!(edges > 500 && holes > 1000, "the frame has edges ({edges}) and holes ({holes}) to compare");
    }
}
