//! Planar regions from the boundary map: connected components, their outer contour
//! and holes, simplified to polygons in pixel coordinates.
//!
//! imageproc does the tracing (Suzuki-Abe border following, the algorithm behind
//! OpenCV's findContours) and the labelling, both with 8-connectivity so a contour
//! and its component always agree; Douglas-Peucker simplifies.

use image::{GrayImage, Luma};
use imageproc::contours::{BorderType, find_contours};
use imageproc::geometry::approximate_polygon_dp;
use imageproc::point::Point;
use imageproc::region_labelling::{Connectivity, connected_components};

use crate::extract::Grid;

/// One region: its component label, outline and holes (pixel centres, simplified).
#[derive(Clone, Debug, PartialEq)]
pub struct Region {
    pub label: u32,
    pub outer: Vec<[f32; 2]>,
    pub holes: Vec<Vec<[f32; 2]>>,
    pub pixels: usize,
}

/// Regions of the pixels where `boundary` is 0, with at least `min_pixels` pixels, and
/// the component label of every pixel (0 = boundary).
pub fn regions(boundary: &Grid<u8>, simplify_px: f64, min_pixels: usize) -> (Grid<u32>, Vec<Region>) {
    let (w, h) = (boundary.width as u32, boundary.height as u32);
    let inside =
        GrayImage::from_fn(w, h, |u, v| Luma([if boundary.data[(v * w + u) as usize] == 0 { 255 } else { 0 }]));
    let labels = connected_components(&inside, Connectivity::Eight, Luma([0u8]));
    let mut pixels = vec![0usize; 1];
    for l in labels.pixels() {
        let l = l.0[0] as usize;
        if l >= pixels.len() {
            pixels.resize(l + 1, 0);
        }
        pixels[l] += 1;
    }
    let simplify = |pts: &[Point<i32>]| -> Vec<[f32; 2]> {
        let simple = if pts.len() > 3 { approximate_polygon_dp(pts, simplify_px, true) } else { pts.to_vec() };
        simple.iter().map(|p| [p.x as f32, p.y as f32]).collect()
    };
    let contours = find_contours::<i32>(&inside);
    let mut out: Vec<Region> = Vec::new();
    let mut region_of_contour = vec![None; contours.len()];
    for (ci, c) in contours.iter().enumerate() {
        if c.border_type != BorderType::Outer || c.points.is_empty() {
            continue;
        }
        let p = c.points[0];
        let label = labels.get_pixel(p.x as u32, p.y as u32).0[0];
        if pixels[label as usize] < min_pixels || c.points.len() < 3 {
            continue;
        }
        region_of_contour[ci] = Some(out.len());
        out.push(Region { label, outer: simplify(&c.points), holes: Vec::new(), pixels: pixels[label as usize] });
    }
    for c in &contours {
        if c.border_type == BorderType::Hole
            && c.points.len() >= 3
            && let Some(r) = c.parent.and_then(|p| region_of_contour[p])
        {
            let hole = simplify(&c.points);
            if hole.len() >= 3 {
                out[r].holes.push(hole);
            }
        }
    }
    out.sort_by_key(|r| r.label);
    (Grid { width: w as usize, height: h as usize, data: labels.into_raw() }, out)
}
