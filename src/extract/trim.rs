//! Trimming each frame polygon at the planes of its neighbours.
//!
//! A polygon's outline is its region's pixel outline ray-cast onto its plane. Near an
//! edge between two planes that outline is off by a pixel or two (the edge band, the
//! growth back over it, half a pixel of outline), and on a tread seen at a grazing
//! angle one pixel spans centimetres. The edge itself is known far better: it is where
//! the two fitted planes meet. So a polygon that meets another along a crease (their
//! regions touch with no depth step, regions::Creases) and whose points all lie on one
//! side of that polygon's plane, give or take the inlier distance, is cut at that plane.
//! Where its points lie on both sides (a floor around a box standing on it), the other
//! plane does not bound it; where the two do not meet (faces of two blocks side by
//! side), the plane says nothing of where it ends: nothing is cut. The vertices made on
//! a cut say so ([`VertexKind::Cut`]): the map keeps them where they are.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::{Polygon, VertexKind};
use crate::ring::clip_tagged_ring;

/// Planes closer to parallel than this never bound each other (cos of 10 deg).
const PARALLEL_COS: f64 = 0.985;

/// A polygon's points beyond another plane, as a share of its points, up to which that
/// plane still bounds it (noise and the odd mixed pixel).
const STRAY_SHARE: f64 = 0.005;

/// Cuts every polygon at the planes of the others that meet it and bound it.
/// `points[k]` are a sample of the camera-frame points of polygon k's region (a
/// `PointSample`: a floor's hundred thousand at 640x480 would be counted again for every
/// plane that crosses it, and every k-th point's share is the share of them all);
/// `meet(a, b)` is whether polygons a and b meet along a crease; `dist` is the inlier
/// distance, m.
pub fn trim_at_neighbour_planes(
    polygons: &mut [Polygon],
    points: &[&[[f32; 3]]],
    meet: impl Fn(usize, usize) -> bool + Sync,
    dist: f64,
) {
    let planes: Vec<(Vector3<f64>, f64)> = polygons.iter().map(|p| (Vector3::from(p.normal), p.offset)).collect();
    polygons.par_iter_mut().enumerate().for_each(|(a, polygon)| {
        let own = planes[a].0;
        for (b, &(n, d)) in planes.iter().enumerate() {
            if b == a || own.dot(&n).abs() > PARALLEL_COS {
                continue;
            }
            // The side of the plane the polygon's points are on, and whether all are.
            let f = |p: &[f64; 3]| n.dot(&Vector3::from(*p)) + d;
            let side = if f(&polygon.centroid()) >= 0.0 { 1.0 } else { -1.0 };
            if polygon.boundary.iter().all(|v| side * f(v) >= 0.0) {
                continue;
            }
            if !meet(a, b) {
                tracing::debug!("polygon {a} crosses the plane of polygon {b}, which it does not meet: not cut");
                continue;
            }
            let pts = points[a];
            let strays = count_beyond(pts, n.into(), d, side, dist);
            if pts.is_empty() || strays as f64 > STRAY_SHARE * pts.len() as f64 {
                tracing::debug!(
                    "polygon {a} crosses the plane of polygon {b}: {strays} of {} points counted beyond it",
                    pts.len()
                );
                continue;
            }
            tracing::debug!("polygon {a} cut at the plane of polygon {b}");
            let keep = |p: &[f64; 3]| side * f(p);
            let cut = VertexKind::Cut { neighbour: Some(b as u32) };
            let (outer, outer_kinds) = clip_tagged_ring(&polygon.boundary, &polygon.boundary_kinds, keep, cut);
            if outer.len() < 3 {
                continue;
            }
            (polygon.boundary, polygon.boundary_kinds) = (outer, outer_kinds);
            (polygon.holes, polygon.hole_kinds) = polygon
                .holes
                .iter()
                .zip(&polygon.hole_kinds)
                .map(|(h, k)| clip_tagged_ring(h, k, keep, cut))
                .filter(|(h, _)| h.len() >= 3)
                .unzip();
        }
    });
}

crate::extract::cpu::widest_simd! {
    /// How many of `points` lie more than `dist` beyond the plane (n, d) from the `side`
    /// (1 or -1) a polygon is on: a cut's strays.
    fn count_beyond(points: &[[f32; 3]], n: [f64; 3], d: f64, side: f64, dist: f64) -> usize = count_beyond_portable
}

/// `side * (n . p + d) < -dist`, written out (as `f` in `trim_at_neighbour_planes` is) in
/// plain arithmetic, so the loop vectorises.
#[inline(always)]
fn count_beyond_portable(points: &[[f32; 3]], n: [f64; 3], d: f64, side: f64, dist: f64) -> usize {
    points
        .iter()
        .map(|p| usize::from(side * (n[0] * p[0] as f64 + n[1] * p[1] as f64 + n[2] * p[2] as f64 + d) < -dist))
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strays_are_the_points_beyond_the_plane_from_the_polygon_s_side() {
        // A 100 x 100 grid of points at z = 1, and the plane x = 0.3 facing -x: the points
        // with x > 0.3 + dist lie beyond it from side 1.
        let points: Vec<[f32; 3]> =
            (0..10_000).map(|i| [(i % 100) as f32 / 100.0, (i / 100) as f32 / 100.0, 1.0]).collect();
        let (n, d, dist) = ([-1.0, 0.0, 0.0], 0.3, 0.005);
        assert_eq!(count_beyond(&points, n, d, 1.0, dist), 69 * 100, "x = 0.31 ..= 0.99 beyond");
        assert_eq!(count_beyond(&points[..150], n, d, 1.0, dist), 69 + 19, "a vector's tail counted too");
        assert_eq!(count_beyond(&points, n, d, -1.0, dist), 30 * 100, "x = 0 ..= 0.29 beyond from the other side");
    }
}
