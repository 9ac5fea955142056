//! Surface normals from smoothed depth: the CPU twin of shaders/normals.wgsl.
//!
//! Sobel derivatives Z_u, Z_v (normalised to depth change per pixel) give the exact
//! tangents of the back-projected surface P(u, v) = Z(u, v) * ray(u, v):
//!   dP/du = Z_u * ray + Z * (1/fx, 0, 0),   dP/dv = Z_v * ray + Z * (0, 1/fy, 0),
//! and n = normalise(dP/du x dP/dv), turned to face the camera. The reference
//! implementation dropped the Z terms' coupling to the ray; this does not.
//! A pixel with any invalid tap gets the zero normal.

use super::{ROWS_PER_TASK, morphology, separable};
use crate::extract::Grid;
use crate::extract::params::{NormalPlanes, sobel_kernel};
use crate::grid::par_rows;
use crate::types::Intrinsics;

/// Unit normals in the camera frame, [0, 0, 0] where not every tap is valid, interleaved
/// (as shaders/normals.wgsl writes them).
pub fn normals(depth: &Grid<f32>, intr: &Intrinsics, kernel: u32) -> Grid<[f32; 3]> {
    normal_planes(depth, intr, kernel).interleaved()
}

/// The normals stage: `normals` as planes, the only form the frame reads (the gradient,
/// the boundary's validity), so no interleaved copy is written.
pub fn normal_planes(depth: &Grid<f32>, intr: &Intrinsics, kernel: u32) -> NormalPlanes {
    let (w, h) = (depth.width, depth.height);
    let (smooth, deriv, norm) = sobel_kernel(kernel);
    let r = smooth.len() / 2;
    let (fx, fy, cx, cy) = (intr.fx as f32, intr.fy as f32, intr.cx as f32, intr.cy as f32);
    let z = &depth.data;
    let (zu, zv) = (separable::derivative_u(z, w, h, deriv, smooth), separable::derivative_v(z, w, h, deriv, smooth));
    // Every tap is valid where no invalid pixel, nor the border, is within r: the
    // invalid pixels dilated by the kernel's square, the outside counting as invalid.
    let invalid = Grid { width: w, height: h, data: z.iter().map(|&z| u8::from(z == 0.0)).collect() };
    let spoiled = morphology::dilate(&invalid, r, 1);
    // The rays' x / z and y / z, once a column and once a row rather than a division a pixel
    // each (the row loop was bound by its divisions): the same operations, so the same bits.
    let ray_x: Vec<f32> = (0..w).map(|u| (u as f32 - cx) / fx).collect();
    // The Sobel norm is a power of two, so multiplying by its reciprocal is dividing by it.
    debug_assert!(norm.log2().fract() == 0.0);
    let planes = par_rows(4 * w, h, 0.0f32, ROWS_PER_TASK, |v, planes| {
        let row = v * w..(v + 1) * w;
        let camera = [fx, fy, (v as f32 - cy) / fy, 1.0 / norm];
        normals_row(&z[row.clone()], &zu[row.clone()], &zv[row.clone()], &spoiled.data[row], &ray_x, planes, camera);
    });
    NormalPlanes { width: w, height: h, data: planes }
}

super::widest_simd! {
    /// One row of normals as four planes into `planes` (4w); `ray_x` is each column's ray
    /// x / z, `camera` [fx, fy, the row's ray y / z, 1 / the Sobel norm].
    fn normals_row(z: &[f32], zu: &[f32], zv: &[f32], spoiled: &[u8], ray_x: &[f32], planes: &mut [f32], camera: [f32; 4]) = normals_row_portable
}

/// Equal-length slices and a branch-free `surface_normal`: the loop vectorises.
#[inline(always)]
fn normals_row_portable(
    z: &[f32],
    zu: &[f32],
    zv: &[f32],
    spoiled: &[u8],
    ray_x: &[f32],
    planes: &mut [f32],
    camera: [f32; 4],
) {
    let [fx, fy, ray_y, inv_norm] = camera;
    let n = z.len();
    let (z, zu, zv, spoiled, ray_x) = (&z[..n], &zu[..n], &zv[..n], &spoiled[..n], &ray_x[..n]);
    let (x, rest) = planes[..4 * n].split_at_mut(n);
    let (y, rest) = rest.split_at_mut(n);
    let (zn, valid) = rest.split_at_mut(n);
    let (x, y, zn, valid) = (&mut x[..n], &mut y[..n], &mut zn[..n], &mut valid[..n]);
    for u in 0..n {
        let normal = normal_on_ray(z[u], zu[u] * inv_norm, zv[u] * inv_norm, ray_x[u], ray_y, fx, fy);
        let normal = if spoiled[u] == 0 { normal } else { [0.0; 3] };
        (x[u], y[u], zn[u]) = (normal[0], normal[1], normal[2]);
        // `|`, not `!=` on the arrays (which stops at the first difference): no branches.
        valid[u] = f32::from(u8::from((normal[0] != 0.0) | (normal[1] != 0.0) | (normal[2] != 0.0)));
    }
}

/// The oracle of `normals`: pixel (u, v) alone, line for line as shaders/normals.wgsl
/// computes it: each row's derivative along u and each column's along v as differences
/// either side of the centre (`separable`'s order of sums), then their smoothing; any
/// invalid tap or the border gives zero.
pub fn normal_at(depth: &Grid<f32>, intr: &Intrinsics, kernel: u32, u: usize, v: usize) -> [f32; 3] {
    let (w, h) = (depth.width, depth.height);
    let (smooth, deriv, norm) = sobel_kernel(kernel);
    let r = smooth.len() / 2;
    if v < r || v + r >= h || u < r || u + r >= w {
        return [0.0; 3];
    }
    let c = separable::half_derivative(deriv);
    let z = |u: usize, v: usize| depth.data[v * w + u];
    // Row j's differences read every tap off column u, column j's every tap off row v.
    if z(u, v) == 0.0 {
        return [0.0; 3];
    }
    let (mut gu, mut gv) = (0.0f32, 0.0f32);
    for j in 0..smooth.len() {
        let (row, column) = (v + j - r, u + j - r);
        let (mut along_u, mut along_v) = (0.0f32, 0.0f32);
        for (k, &ck) in (1..).zip(c) {
            let (right, left, below, above) = (z(u + k, row), z(u - k, row), z(column, v + k), z(column, v - k));
            if right == 0.0 || left == 0.0 || below == 0.0 || above == 0.0 {
                return [0.0; 3];
            }
            along_u += ck * (right - left);
            along_v += ck * (below - above);
        }
        gu += smooth[j] * along_u;
        gv += smooth[j] * along_v;
    }
    let (fx, fy, cx, cy) = (intr.fx as f32, intr.fy as f32, intr.cx as f32, intr.cy as f32);
    surface_normal(z(u, v), gu / norm, gv / norm, u as f32, v as f32, fx, fy, cx, cy)
}

/// The exact normal of the back-projected surface at pixel (u, v) of depth z, from
/// its depth derivatives per pixel; faces the camera.
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn surface_normal(z: f32, zu: f32, zv: f32, u: f32, v: f32, fx: f32, fy: f32, cx: f32, cy: f32) -> [f32; 3] {
    normal_on_ray(z, zu, zv, (u - cx) / fx, (v - cy) / fy, fx, fy)
}

/// `surface_normal` of the pixel whose ray is (x, y, 1).
#[inline(always)]
fn normal_on_ray(z: f32, zu: f32, zv: f32, x: f32, y: f32, fx: f32, fy: f32) -> [f32; 3] {
    let a = [zu * x + z / fx, zu * y, zu];
    let b = [zv * x, zv * y + z / fy, zv];
    let mut n = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    // Face the camera: n . ray < 0. Selects, not early returns, so that loops over
    // pixels vectorise (a zero length gives NaNs here, replaced by the zero normal).
    let s = if n[0] * x + n[1] * y + n[2] > 0.0 { -1.0 / len } else { 1.0 / len };
    n.iter_mut().for_each(|c| *c *= s);
    if len > 0.0 { n } else { [0.0; 3] }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{NoiseModel, Scene, SceneKind, noisy_depth, path::trajectory, render};

    #[test]
    fn fast_normals_are_the_oracle_bit_for_bit() {
        let scene = Scene::build(SceneKind::Spiral);
        let pose = trajectory(&scene, 30)[9];
        let intr = Intrinsics::L515_320X240;
        let pixels = noisy_depth(&render(&scene, &intr, &pose), &NoiseModel::l515(2.0), 3, 0);
        let w = intr.width as usize;
        // Dropouts: single pixels and short runs.
        let data = pixels
            .iter()
            .enumerate()
            .map(
                |(k, &d)| if k % 1009 == 0 || (k / w) % 53 == 7 && (k % w) % 37 < 4 { 0.0 } else { d as f32 * 0.00025 },
            )
            .collect();
        let depth = Grid { width: w, height: intr.height as usize, data };
        for kernel in [3, 5, 7] {
            let planes = normal_planes(&depth, &intr, kernel);
            let fast = planes.interleaved();
            assert_eq!(planes, NormalPlanes::of(&fast), "kernel {kernel}: the validity plane is the normals'");
            for v in 0..depth.height {
                for u in 0..w {
                    let want = normal_at(&depth, &intr, kernel, u, v);
                    assert_eq!(
                        fast.data[v * w + u].map(f32::to_bits),
                        want.map(f32::to_bits),
                        "kernel {kernel}, ({u}, {v})"
                    );
                }
            }
            let zero = fast.data.iter().filter(|n| **n == [0.0; 3]).count();
            assert!(zero > 1000 && zero < depth.data.len() / 2, "kernel {kernel}: {zero} pixels without a normal");
        }
    }
}
