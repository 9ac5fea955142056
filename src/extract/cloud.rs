//! A frame's raw camera-frame points, one per pixel, computed once: the region steps
//! (fits, leak splits, joins, growth, polygons) each read points of many pixels, and a
//! lookup is cheaper than back-projecting a pixel index (a division) every time.

use std::ops::Range;

use super::Grid;
use crate::grid::par_rows;
use crate::types::Intrinsics;

pub struct Cloud {
    pub width: usize,
    /// Pixel i's point (x, y, z) in metres, z = 0 where the depth is invalid.
    points: Vec<[f32; 3]>,
}

impl Cloud {
    /// Back-projects every pixel of a depth image in metres (0 = invalid).
    pub fn new(depth: &Grid<f32>, intr: &Intrinsics) -> Cloud {
        let w = depth.width;
        let ray_x: Vec<f32> = (0..w).map(|u| ((u as f64 - intr.cx) / intr.fx) as f32).collect();
        let points = par_rows(w, depth.height, [0.0f32; 3], 1, |v, row| {
            let ray_y = ((v as f64 - intr.cy) / intr.fy) as f32;
            back_project_row(&depth.data[v * w..(v + 1) * w], &ray_x, ray_y, row);
        });
        Cloud { width: w, points }
    }

    /// Pixel i's point, None where its depth is invalid.
    #[inline]
    pub fn point(&self, i: usize) -> Option<[f32; 3]> {
        let p = self.points[i];
        has_depth(&p).then_some(p)
    }

    /// Appends the points of the valid pixels among `pixels` (consecutive indices), in
    /// order: a run with no dropout, the usual case, is copied whole.
    #[inline]
    pub fn extend_valid(&self, pixels: Range<usize>, out: &mut Vec<[f32; 3]>) {
        let points = &self.points[pixels];
        if points.iter().fold(true, |all, p| all & has_depth(p)) {
            out.extend_from_slice(points);
        } else {
            out.extend(points.iter().filter(|p| has_depth(p)));
        }
    }

    /// The points of consecutive pixels, invalid ones included (z = 0: `has_depth`).
    #[inline]
    pub fn points(&self, pixels: Range<usize>) -> &[[f32; 3]] {
        &self.points[pixels]
    }

    /// Pixel i's depth, m (0 = invalid).
    #[inline]
    pub fn depth(&self, i: usize) -> f32 {
        self.points[i][2]
    }
}

/// Whether a pixel's point is one: an invalid depth back-projects to z = 0.
#[inline(always)]
pub fn has_depth(p: &[f32; 3]) -> bool {
    p[2] != 0.0
}

crate::extract::cpu::widest_simd! {
    /// A row's points: depth z at a pixel whose ray is (x, y, 1) is (x z, y z, z).
    fn back_project_row(z: &[f32], ray_x: &[f32], ray_y: f32, out: &mut [[f32; 3]]) = back_project_row_portable
}

#[inline(always)]
fn back_project_row_portable(z: &[f32], ray_x: &[f32], ray_y: f32, out: &mut [[f32; 3]]) {
    for ((p, &z), &x) in out.iter_mut().zip(z).zip(ray_x) {
        *p = [x * z, ray_y * z, z];
    }
}
