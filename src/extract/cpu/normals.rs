//! Surface normals from smoothed depth: the CPU twin of the GPU stage shaders/normals.wgsl (the WGSL half lands with the GPU backend).
//!
//! Sobel derivatives Z_u, Z_v (normalised to depth change per pixel) give the exact
//! tangents of the back-projected surface P(u, v) = Z(u, v) * ray(u, v):
//!   dP/du = Z_u * ray + Z * (1/fx, 0, 0),   dP/dv = Z_v * ray + Z * (0, 1/fy, 0),
//! and n = normalise(dP/du x dP/dv), turned to face the camera. The reference
//! implementation dropped the Z terms' coupling to the ray; this does not.
//! A pixel with any invalid tap gets the zero normal.

use rayon::prelude::*;

use super::separable;
use crate::extract::Grid;
use crate::types::Intrinsics;

/// Separable Sobel weights (smoothing, derivative) and the derivative's response to a
/// unit ramp times the smoothing sum, by kernel size.
pub fn sobel_kernel(size: u32) -> (&'static [f32], &'static [f32], f32) {
    match size {
        3 => (&[1.0, 2.0, 1.0], &[-1.0, 0.0, 1.0], 8.0),
        5 => (&[1.0, 4.0, 6.0, 4.0, 1.0], &[-1.0, -2.0, 0.0, 2.0, 1.0], 128.0),
        7 => (&[1.0, 6.0, 15.0, 20.0, 15.0, 6.0, 1.0], &[-1.0, -4.0, -5.0, 0.0, 5.0, 4.0, 1.0], 2048.0),
        _ => panic!("Sobel kernel size {size} is not 3, 5 or 7 (the config validates this)"),
    }
}

/// Unit normals in the camera frame, [0, 0, 0] where not every tap is valid.
pub fn normals(depth: &Grid<f32>, intr: &Intrinsics, kernel: u32) -> Grid<[f32; 3]> {
    let (w, h) = (depth.width, depth.height);
    let (smooth, deriv, norm) = sobel_kernel(kernel);
    let r = smooth.len() / 2;
    let (fx, fy, cx, cy) = (intr.fx as f32, intr.fy as f32, intr.cx as f32, intr.cy as f32);
    let z = &depth.data;
    let (zu, zv) = (separable::filter(z, w, h, deriv, smooth), separable::filter(z, w, h, smooth, deriv));
    let valid: Vec<bool> = z.iter().map(|&z| z != 0.0).collect();
    let all_valid = separable::window_all_valid(&valid, w, h, r);
    let mut data = vec![[0.0f32; 3]; w * h];
    data.par_chunks_mut(w).enumerate().for_each(|(v, out)| {
        for (u, n) in out.iter_mut().enumerate() {
            let i = v * w + u;
            if all_valid[i] {
                *n = surface_normal(z[i], zu[i] / norm, zv[i] / norm, u as f32, v as f32, fx, fy, cx, cy);
            }
        }
    });
    Grid { width: w, height: h, data }
}

/// The exact normal of the back-projected surface at pixel (u, v) of depth z, from
/// its depth derivatives per pixel; faces the camera.
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn surface_normal(z: f32, zu: f32, zv: f32, u: f32, v: f32, fx: f32, fy: f32, cx: f32, cy: f32) -> [f32; 3] {
    let (x, y) = ((u - cx) / fx, (v - cy) / fy);
    let a = [zu * x + z / fx, zu * y, zu];
    let b = [zv * x, zv * y + z / fy, zv];
    let mut n = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if !(len > 0.0) {
        return [0.0; 3];
    }
    // Face the camera: n . ray < 0.
    let s = if n[0] * x + n[1] * y + n[2] > 0.0 { -1.0 / len } else { 1.0 / len };
    n.iter_mut().for_each(|c| *c *= s);
    n
}
