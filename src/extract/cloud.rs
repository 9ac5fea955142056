//! A frame's raw camera-frame points, one per pixel: the region steps (fits, leak splits,
//! joins, growth, polygons) each read points of many pixels.
//!
//! The points are not stored: pixel (u, v) of depth z is (x_u z, y_v z, z), the rays' x_u
//! and y_v computed once per column and row, so a point costs two products where it is
//! read. A stored cloud was three times the depth's size (12 bytes a pixel), written once
//! and read whole twice or more a frame (the fits' points, growth, the grown regions'
//! points), too large for any cache at 640x480. The products are the ones the stored
//! cloud held, so every reader sees the same bits.

use std::ops::Range;

use super::Grid;
use crate::types::Intrinsics;

pub struct Cloud<'a> {
    pub width: usize,
    /// Depth, m (0 = invalid).
    depth: &'a [f32],
    /// x / z of column u's ray.
    ray_x: Vec<f32>,
    /// y / z of row v's ray.
    ray_y: Vec<f32>,
}

impl<'a> Cloud<'a> {
    /// The points of a depth image in metres (0 = invalid).
    pub fn new(depth: &'a Grid<f32>, intr: &Intrinsics) -> Cloud<'a> {
        let ray_x = (0..depth.width).map(|u| ((u as f64 - intr.cx) / intr.fx) as f32).collect();
        let ray_y = (0..depth.height).map(|v| ((v as f64 - intr.cy) / intr.fy) as f32).collect();
        Cloud { width: depth.width, depth: &depth.data, ray_x, ray_y }
    }

    /// Pixel i's point, None where its depth is invalid.
    #[inline]
    pub fn point(&self, i: usize) -> Option<[f32; 3]> {
        let z = self.depth[i];
        (z != 0.0).then(|| [self.ray_x[i % self.width] * z, self.ray_y[i / self.width] * z, z])
    }

    /// Appends the points of the valid pixels among `pixels` (consecutive indices within
    /// one row), in order: a run with no dropout, the usual case, is back-projected whole.
    #[inline(always)]
    pub fn extend_valid(&self, pixels: Range<usize>, out: &mut Vec<[f32; 3]>) {
        let (z, ray_x, ray_y) = self.row_part(pixels);
        if z.iter().fold(true, |all, &z| all & (z != 0.0)) {
            out.extend(z.iter().zip(ray_x).map(|(&z, &x)| [x * z, ray_y * z, z]));
        } else {
            out.extend(z.iter().zip(ray_x).filter(|(z, _)| **z != 0.0).map(|(&z, &x)| [x * z, ray_y * z, z]));
        }
    }

    /// The depths of consecutive pixels within one row, their columns' ray x / z, and the
    /// row's ray y / z: their points, invalid ones included, are (x z, y z, z).
    #[inline(always)]
    pub fn row_part(&self, pixels: Range<usize>) -> (&[f32], &[f32], f32) {
        let (v, u) = (pixels.start / self.width, pixels.start % self.width);
        let len = pixels.len();
        (&self.depth[pixels], &self.ray_x[u..u + len], self.ray_y[v])
    }

    /// Pixel i's depth, m (0 = invalid).
    #[inline]
    pub fn depth(&self, i: usize) -> f32 {
        self.depth[i]
    }
}
