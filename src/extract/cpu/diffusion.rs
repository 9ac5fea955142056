//! Perona-Malik anisotropic diffusion of depth: the CPU twin of the GPU stage shaders/diffusion.wgsl (the WGSL half lands with the GPU backend).
//!
//! Each iteration moves every valid pixel by gamma * sum over its valid 4-neighbours
//! of c(d) * d, with d the neighbour's depth minus its own and c(d) = exp(-(d/kappa)^2).
//! Invalid pixels (0) neither receive nor give: no flux crosses into or out of them,
//! so holes never bleed into surfaces.

use rayon::prelude::*;

use crate::extract::Grid;

/// exp(-(d/kappa)^2) as 2^-t with a degree-7 polynomial for 2^-frac(t): relative
/// error under 5e-6, branch-free. The WGSL twin is to use the same
/// function, so both compute the same conductance.
#[inline(always)]
pub fn conductance(d: f32, inv_kappa: f32) -> f32 {
    let s = d * inv_kappa;
    // Capped at 2^-100: smaller values would turn denormal and crawl.
    let t = (s * s * std::f32::consts::LOG2_E).min(100.0);
    // SAFETY: t is in [0, 100] (min() returns 100 for NaN), so the cast is exact; the
    // unchecked cast is what lets the loop vectorise.
    let n: i32 = unsafe { t.to_int_unchecked() };
    let y = (t - n as f32) * std::f32::consts::LN_2;
    // e^-y for y in [0, ln 2): Taylor to y^7 (remainder under 2.6e-6 relative).
    let p = 1.0
        - y * (1.0
            - y * (0.5
                - y * (1.0 / 6.0 - y * (1.0 / 24.0 - y * (1.0 / 120.0 - y * (1.0 / 720.0 - y * (1.0 / 5040.0)))))));
    f32::from_bits(((127 - n) as u32) << 23) * p
}

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
    for _ in 0..iterations {
        // Bands of rows per task: one row is too little work to be worth a thread hop.
        let band = h.div_ceil(rayon::current_num_threads() * 4).max(8);
        next[pw..(h + 1) * pw].par_chunks_mut(pw * band).enumerate().for_each(|(b, rows)| {
            for (i, out) in rows.chunks_mut(pw).enumerate() {
                let v = b * band + i;
                let (up, row, down) =
                    (&cur[v * pw..(v + 1) * pw], &cur[(v + 1) * pw..(v + 2) * pw], &cur[(v + 2) * pw..(v + 3) * pw]);
                let (o, c) = (&mut out[1..w + 1], &row[1..w + 1]);
                let (l, r, a, b) = (&row[..w], &row[2..w + 2], &up[1..w + 1], &down[1..w + 1]);
                for i in 0..w {
                    let z = c[i];
                    let sum = flux(z, l[i], inv_kappa)
                        + flux(z, r[i], inv_kappa)
                        + flux(z, a[i], inv_kappa)
                        + flux(z, b[i], inv_kappa);
                    // Masks, not branches, so the loop vectorises.
                    o[i] = (z + gamma * sum) * ((z != 0.0) as u32 as f32);
                }
            }
        });
        std::mem::swap(&mut cur, &mut next);
    }
    let mut data = Vec::with_capacity(w * h);
    for v in 0..h {
        data.extend_from_slice(&cur[(v + 1) * pw + 1..(v + 1) * pw + 1 + w]);
    }
    Grid { width: w, height: h, data }
}

/// Flux from neighbour q into z: none across an invalid pixel.
#[inline(always)]
pub fn flux(z: f32, q: f32, inv_kappa: f32) -> f32 {
    let d = q - z;
    conductance(d, inv_kappa) * d * ((q != 0.0) as u32 as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

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
