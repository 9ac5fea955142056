//! An L515-like depth noise model, applied to a noise-free render.
//!
//! What a LiDAR-ToF camera like the L515 does to depth, in the order applied:
//! 1. mixed pixels: where the true depth jumps between neighbouring pixels of
//!    different surfaces, a pixel may return a depth between the two;
//! 2. range noise: Gaussian along the ray, sigma(r) = noise * (0.5 + 0.5 r / 1 m),
//!    grown by 1/sqrt(cos(incidence)) because less light returns at grazing angles;
//! 3. dropouts: no return at grazing incidence or outside 0.25..9 m, isolated
//!    random pixels, and a few clustered blobs (dark or specular patches);
//! 4. quantisation to the depth unit (0.25 mm), 0 = invalid.

use rand::{Rng, RngExt};
use rand_distr::{Distribution, Normal};

use super::Render;

#[derive(Clone, Debug, PartialEq)]
pub struct NoiseModel {
    /// Range noise standard deviation at 1 m and normal incidence, m.
    pub sigma_at_1m: f64,
    /// Probability that a pixel at a depth jump returns a mixed depth.
    pub mixed_pixel_probability: f64,
    /// Depth jump between neighbours (of different surfaces) that can mix, m.
    pub mixed_pixel_jump: f64,
    /// Probability of an isolated dropout per pixel.
    pub dropout_probability: f64,
    /// Most clustered dropout blobs per frame (uniform 0..=max).
    pub max_dropout_clusters: u32,
    /// Below this cosine of the incidence angle nothing returns.
    pub min_cos_incidence: f64,
    pub min_range: f64,
    pub max_range: f64,
}

impl NoiseModel {
    /// The L515-like model with `noise_mm` of range noise at 1 m; 0 turns every effect off
    /// (only the range limits and quantisation remain).
    pub fn l515(noise_mm: f64) -> NoiseModel {
        let on = noise_mm > 0.0;
        NoiseModel {
            sigma_at_1m: noise_mm / 1000.0,
            mixed_pixel_probability: if on { 0.5 } else { 0.0 },
            mixed_pixel_jump: 0.02,
            dropout_probability: if on { 0.002 } else { 0.0 },
            max_dropout_clusters: if on { 3 } else { 0 },
            min_cos_incidence: if on { 0.08 } else { 0.0 },
            min_range: 0.25,
            max_range: 9.0,
        }
    }

    /// Depth units (u16, 0 = invalid) of a noisy measurement of `render`.
    pub fn apply(&self, render: &Render, depth_scale: f64, rng: &mut impl Rng) -> Vec<u16> {
        let (w, h) = (render.width as usize, render.height as usize);
        let truth = &render.depth_m;
        let mut depth = truth.clone();

        if self.mixed_pixel_probability > 0.0 {
            for v in 0..h {
                for u in 0..w {
                    let i = v * w + u;
                    if truth[i] == 0.0 {
                        continue;
                    }
                    // The neighbour across the largest jump to another surface.
                    let mut far: Option<f64> = None;
                    for (du, dv) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                        let (nu, nv) = (u as i64 + du, v as i64 + dv);
                        if nu < 0 || nv < 0 || nu >= w as i64 || nv >= h as i64 {
                            continue;
                        }
                        let j = nv as usize * w + nu as usize;
                        let jump = (truth[j] - truth[i]).abs();
                        if truth[j] > 0.0
                            && render.labels[j] != render.labels[i]
                            && jump > self.mixed_pixel_jump
                            && far.is_none_or(|f| jump > (f - truth[i]).abs())
                        {
                            far = Some(truth[j]);
                        }
                    }
                    if let Some(f) = far
                        && rng.random_bool(self.mixed_pixel_probability)
                    {
                        let t: f64 = rng.random();
                        depth[i] = truth[i] + t * (f - truth[i]);
                    }
                }
            }
        }

        let unit = Normal::new(0.0, 1.0).expect("unit normal distribution");
        for i in 0..w * h {
            let z = depth[i];
            if z == 0.0 {
                continue;
            }
            let (u, v) = ((i % w) as f64, (i / w) as f64);
            let ray_len = render.ray_length(u, v);
            let range = z * ray_len;
            let cos = render.cos_incidence[i] as f64;
            if range < self.min_range || range > self.max_range || cos < self.min_cos_incidence {
                depth[i] = 0.0;
                continue;
            }
            if self.sigma_at_1m > 0.0 {
                let sigma = self.sigma_at_1m * (0.5 + 0.5 * range) / cos.max(0.05).sqrt();
                depth[i] = (range + sigma * unit.sample(rng)) / ray_len;
            }
            if self.dropout_probability > 0.0 && rng.random_bool(self.dropout_probability) {
                depth[i] = 0.0;
            }
        }

        if self.max_dropout_clusters > 0 {
            let clusters = rng.random_range(0..=self.max_dropout_clusters);
            for _ in 0..clusters {
                let (cu, cv) = (rng.random_range(0.0..w as f64), rng.random_range(0.0..h as f64));
                let ru = rng.random_range(0.01..0.04) * w as f64;
                let rv = ru * rng.random_range(0.5..1.5);
                let (v0, v1) = ((cv - rv).max(0.0) as usize, ((cv + rv) as usize).min(h - 1));
                let (u0, u1) = ((cu - ru).max(0.0) as usize, ((cu + ru) as usize).min(w - 1));
                for v in v0..=v1 {
                    for u in u0..=u1 {
                        if ((u as f64 - cu) / ru).powi(2) + ((v as f64 - cv) / rv).powi(2) <= 1.0 {
                            depth[v * w + u] = 0.0;
                        }
                    }
                }
            }
        }

        depth.iter().map(|&z| quantize(z, depth_scale)).collect()
    }
}

/// Metres to depth units: rounded, 0 stays invalid, beyond the u16 range is invalid.
pub fn quantize(depth_m: f64, depth_scale: f64) -> u16 {
    if !(depth_m > 0.0) {
        return 0;
    }
    let units = (depth_m / depth_scale).round();
    if units >= 1.0 && units <= u16::MAX as f64 { units as u16 } else { 0 }
}
