//! Outlines of regions: outer contour and holes, simplified to polygons in pixel
//! coordinates.
//!
//! imageproc does the tracing (Suzuki-Abe border following, the algorithm behind
//! OpenCV's findContours) with 8-connectivity, the connectivity of the regions, so a
//! contour and its region always agree; Douglas-Peucker simplifies.

use image::{GrayImage, Luma};
use imageproc::contours::{BorderType, find_contours};
use imageproc::geometry::approximate_polygon_dp;
use imageproc::point::Point;
use rayon::prelude::*;

use super::segment::{Segmentation, bounding_box};

/// One region: its component label, outline and holes (pixel centres, simplified).
#[derive(Clone, Debug, PartialEq)]
pub struct Region {
    pub label: u32,
    pub outer: Vec<[f32; 2]>,
    pub holes: Vec<Vec<[f32; 2]>>,
    pub pixels: usize,
}

/// The outline and holes of every region r of `seg` with `wanted[r]` (the others are left
/// without: no polygon is made of them), simplified by Douglas-Peucker with
/// `simplify_px`, then moved half a pixel outwards (holes shrink) so that the polygon
/// covers its pixels' squares rather than joining their centres.
pub fn trace(seg: &Segmentation, simplify_px: f64, wanted: &[bool]) -> Vec<Region> {
    let w = seg.labels.width;
    seg.pixels
        .par_iter()
        .enumerate()
        .map(|(r, pixels)| {
            let label = r as u32 + 1;
            if pixels.is_empty() || !wanted[r] {
                return Region { label, outer: Vec::new(), holes: Vec::new(), pixels: pixels.len() };
            }
            // The region's bounding box with a one-pixel margin, so its border is traced whole.
            let [u0, v0, u1, v1] = bounding_box(pixels, w);
            let mut mask = GrayImage::new((u1 - u0 + 3) as u32, (v1 - v0 + 3) as u32);
            for &i in pixels {
                let (u, v) = (i as usize % w, i as usize / w);
                mask.put_pixel((u - u0 + 1) as u32, (v - v0 + 1) as u32, Luma([255]));
            }
            let to_image = |ring: Vec<[f32; 2]>, outwards: f32| -> Vec<[f32; 2]> {
                offset_ring(&ring, outwards).iter().map(|p| [p[0] + u0 as f32 - 1.0, p[1] + v0 as f32 - 1.0]).collect()
            };
            let contours = find_contours::<i32>(&mask);
            let outer_index = contours.iter().position(|c| c.border_type == BorderType::Outer);
            let mut region = Region { label, outer: Vec::new(), holes: Vec::new(), pixels: pixels.len() };
            let Some(oi) = outer_index else { return region };
            region.outer = to_image(simplify(&contours[oi].points, simplify_px), 0.5);
            for c in &contours {
                if c.border_type == BorderType::Hole && c.parent == Some(oi) {
                    let hole = simplify(&c.points, simplify_px);
                    if hole.len() >= 3 {
                        region.holes.push(to_image(hole, -0.5));
                    }
                }
            }
            region
        })
        .collect()
}

fn simplify(pts: &[Point<i32>], tolerance: f64) -> Vec<[f32; 2]> {
    let simple = if pts.len() > 3 { approximate_polygon_dp(pts, tolerance, true) } else { pts.to_vec() };
    simple.iter().map(|p| [p.x as f32, p.y as f32]).collect()
}

/// The ring with every edge moved `d` pixels away from the ring's inside (d < 0: towards
/// it). Vertices move along the bisector, the shift capped at 2|d| on sharp corners.
pub fn offset_ring(ring: &[[f32; 2]], d: f32) -> Vec<[f32; 2]> {
    if d == 0.0 {
        return ring.to_vec();
    }
    let pts: Vec<[f64; 2]> = ring.iter().map(|p| [p[0] as f64, p[1] as f64]).collect();
    offset_vertices(&pts, &vec![d as f64; pts.len()]).iter().map(|p| [p[0] as f32, p[1] as f32]).collect()
}

/// The ring with vertex i moved so that both its edges move `d[i]` away from the ring's
/// inside (d < 0: towards it), whichever way the ring winds: along the bisector of the
/// edges' normals, the shift capped at 2|d[i]| on sharp corners.
pub fn offset_vertices(ring: &[[f64; 2]], d: &[f64]) -> Vec<[f64; 2]> {
    let n = ring.len();
    if n < 3 {
        return ring.to_vec();
    }
    // Twice the signed area: its sign says which side of each edge is inside.
    let area2: f64 = (0..n).map(|i| ring[i][0] * ring[(i + 1) % n][1] - ring[(i + 1) % n][0] * ring[i][1]).sum();
    let side = if area2 > 0.0 { 1.0 } else { -1.0 };
    // Outward unit normal of edge i (from vertex i to i + 1).
    let normal = |i: usize| {
        let (a, b) = (ring[i], ring[(i + 1) % n]);
        let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
        let len = ex.hypot(ey).max(1e-12);
        [side * ey / len, -side * ex / len]
    };
    (0..n)
        .map(|i| {
            let (a, b) = (normal((i + n - 1) % n), normal(i));
            let (sx, sy) = (a[0] + b[0], a[1] + b[1]);
            let dot = (sx * a[0] + sy * a[1]).max(1e-6);
            // Along the bisector, far enough that both edges move by d.
            let scale = (d[i] / dot).clamp(-2.0 * d[i].abs(), 2.0 * d[i].abs());
            [ring[i][0] + sx * scale, ring[i][1] + sy * scale]
        })
        .collect()
}
