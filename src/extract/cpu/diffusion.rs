//! Perona-Malik anisotropic diffusion of depth: the CPU twin of the GPU stage shaders/diffusion.wgsl (the WGSL half lands with the GPU backend).
//!
//! Each iteration moves every valid pixel by gamma * sum over its valid 4-neighbours
//! of c(d) * d, with d the neighbour's depth minus its own and c(d) = exp(-(d/kappa)^2).
//! Invalid pixels (0) neither receive nor give: no flux crosses into or out of them,
//! so holes never bleed into surfaces.

use rayon::prelude::*;

use crate::extract::Grid;

/// exp(-(d/kappa)^2) as 2^-t: the integer part of t by the exponent bits, the
/// fraction by a degree-4 minimax polynomial of 2^-f on [0, 1) (under 3e-6; with the
/// rounding of t, under 5e-6 of exp), branch-free. shaders/diffusion.wgsl has the same function, so both twins
/// compute the same conductance.
#[inline(always)]
pub fn conductance(d: f32, inv_kappa: f32) -> f32 {
    let s = d * inv_kappa;
    // Capped at 2^-100: smaller values would turn denormal and crawl.
    let t = (s * s * std::f32::consts::LOG2_E).min(100.0);
    // SAFETY: t is in [0, 100] (min() returns 100 for NaN), so the cast is exact; the
    // unchecked cast is what lets the loop vectorise.
    let n: i32 = unsafe { t.to_int_unchecked() };
    let f = t - n as f32;
    let p = EXP2_NEG[0] + f * (EXP2_NEG[1] + f * (EXP2_NEG[2] + f * (EXP2_NEG[3] + f * EXP2_NEG[4])));
    f32::from_bits(((127 - n) as u32) << 23) * p
}

/// 2^-f ~ Σ EXP2_NEG[k] f^k on [0, 1), minimax in relative error (Lawson's algorithm).
pub const EXP2_NEG: [f32; 5] = [0.9999974, -0.6930302, 0.23934102, -0.05307402, 0.0067670685];

/// Runs `iterations` diffusion steps on depth in metres (0 = invalid).
pub fn diffuse(depth: &Grid<f32>, iterations: u32, kappa: f32, gamma: f32) -> Grid<f32> {
    let (w, h) = (depth.width, depth.height);
    let inv_kappa = 1.0 / kappa;
    // A one-pixel border of invalid (0) pixels gives every pixel four neighbours, so
    // the inner loop has no edge cases and vectorises.
    let pw = w + 2;
    let mut cur = vec![0.0f32; pw * (h + 2)];
    for v in 0..h {
        cur[(v + 1) * pw + 1..(v + 1) * pw + 1 + w].copy_from_slice(&depth.data[v * w..(v + 1) * w]);
    }
    let mut next = cur.clone();
    // Bands of rows per task: one row is too little work to be worth a thread hop.
    let band = h.div_ceil(rayon::current_num_threads() * 4).max(8);
    for _ in 0..iterations {
        next[pw..(h + 1) * pw].par_chunks_mut(pw * band).enumerate().for_each(|(b, rows)| {
            diffuse_band(&cur, rows, b * band, pw, inv_kappa, gamma);
        });
        std::mem::swap(&mut cur, &mut next);
    }
    let mut data = Vec::with_capacity(w * h);
    for v in 0..h {
        data.extend_from_slice(&cur[(v + 1) * pw + 1..(v + 1) * pw + 1 + w]);
    }
    Grid { width: w, height: h, data }
}

super::widest_simd! {
    /// One step for image rows `first ..` (padded rows `first + 1 ..`) of `cur` into `out`.
    fn diffuse_band(cur: &[f32], out: &mut [f32], first: usize, pw: usize, inv_kappa: f32, gamma: f32) = diffuse_band_portable
}

/// Each flux is computed once per pixel pair and given to one side, taken from the
/// other (conductance is even in d): two conductances per pixel instead of four.
#[inline(always)]
fn diffuse_band_portable(cur: &[f32], out: &mut [f32], first: usize, pw: usize, inv_kappa: f32, gamma: f32) {
    let w = pw - 2;
    // The band starts with the fluxes between its first row and the row above it.
    let (mut from_below, mut into_row, mut across) = (vec![0.0f32; w], vec![0.0f32; w], vec![0.0f32; w + 1]);
    vertical_fluxes(cur, first, pw, inv_kappa, &mut from_below);
    for (k, o) in out.chunks_mut(pw).enumerate() {
        let p = first + k + 1;
        let row = &cur[p * pw..(p + 1) * pw];
        // across[i]: flux into padded pixel i from pixel i + 1.
        for i in 0..w + 1 {
            across[i] = pair_flux(row[i], row[i + 1], inv_kappa);
        }
        std::mem::swap(&mut into_row, &mut from_below);
        vertical_fluxes(cur, p, pw, inv_kappa, &mut from_below);
        let (o, c) = (&mut o[1..w + 1], &row[1..w + 1]);
        for i in 0..w {
            let sum = across[i + 1] - across[i] + from_below[i] - into_row[i];
            o[i] = c[i] + gamma * sum;
        }
    }
}

/// Fluxes into padded row p from row p + 1. A function, not a closure, so that it
/// inlines into the AVX2 copy of the band loop (closures are compiled for the baseline).
#[inline(always)]
fn vertical_fluxes(cur: &[f32], p: usize, pw: usize, inv_kappa: f32, out: &mut [f32]) {
    let w = out.len();
    let (row, down) = (&cur[p * pw + 1..p * pw + 1 + w], &cur[(p + 1) * pw + 1..(p + 1) * pw + 1 + w]);
    for i in 0..w {
        out[i] = pair_flux(row[i], down[i], inv_kappa);
    }
}

/// Flux into z from its neighbour q: none unless both are valid.
#[inline(always)]
pub fn pair_flux(z: f32, q: f32, inv_kappa: f32) -> f32 {
    let d = q - z;
    conductance(d, inv_kappa) * d * (((z != 0.0) & (q != 0.0)) as u32 as f32)
}

/// The oracle of one `diffuse` step: pixel (u, v) of `src` alone, line for line as
/// shaders/diffusion.wgsl computes it (four fluxes, right, left, below, above).
pub fn diffuse_at(src: &Grid<f32>, u: usize, v: usize, inv_kappa: f32, gamma: f32) -> f32 {
    let (w, h) = (src.width as isize, src.height as isize);
    let z = src.data[v * src.width + u];
    if z == 0.0 {
        return 0.0;
    }
    let depth_at = |u: isize, v: isize| {
        if u < 0 || v < 0 || u >= w || v >= h { 0.0 } else { src.data[(v * w + u) as usize] }
    };
    let flux = |q: f32| {
        if q == 0.0 {
            return 0.0;
        }
        let d = q - z;
        conductance(d, inv_kappa) * d
    };
    let (u, v) = (u as isize, v as isize);
    let sum = flux(depth_at(u + 1, v)) + flux(depth_at(u - 1, v)) + flux(depth_at(u, v + 1)) + flux(depth_at(u, v - 1));
    z + gamma * sum
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_diffusion_is_the_oracle_bit_for_bit() {
        // A noisy slanted plane with a step, holes and a hole touching the border.
        let (w, h) = (97, 61);
        let mut data: Vec<f32> = (0..w * h)
            .map(|i| {
                let (u, v) = ((i % w) as f32, (i / w) as f32);
                let step = if u > 50.0 { 0.15 } else { 0.0 };
                1.0 + 0.004 * v + step + 0.002 * ((i * 7919 % 101) as f32 / 101.0 - 0.5)
            })
            .collect();
        for (i, z) in data.iter_mut().enumerate() {
            if i % 131 == 0 || (i % w < 3 && i / w < 4) {
                *z = 0.0;
            }
        }
        let depth = Grid { width: w, height: h, data };
        let (kappa, gamma) = (0.0335f32, 0.2f32);
        let mut oracle = depth.clone();
        for iterations in 1..=3 {
            oracle = Grid {
                width: w,
                height: h,
                data: (0..w * h).map(|i| diffuse_at(&oracle, i % w, i / w, 1.0 / kappa, gamma)).collect(),
            };
            let fast = diffuse(&depth, iterations, kappa, gamma);
            for i in 0..w * h {
                assert_eq!(fast.data[i].to_bits(), oracle.data[i].to_bits(), "{iterations} steps, pixel {i}");
            }
        }
        assert_ne!(oracle.data, depth.data, "the steps moved the depth");
    }

    #[test]
    fn conductance_matches_exp() {
        for i in 0..2000 {
            let d = (i as f32 - 1000.0) * 1e-4;
            let exact = (-(d / 0.0335f32).powi(2)).exp();
            let approx = conductance(d, 1.0 / 0.0335);
            assert!((approx - exact).abs() <= 5e-6 * exact + 1e-30, "d {d}: {approx} vs {exact}");
        }
        assert!(conductance(10.0, 1.0 / 0.0335) < 1e-30);
    }
}
