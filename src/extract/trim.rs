//! Trimming each frame polygon at the planes of its neighbours.
//!
//! A polygon's outline is its region's pixel outline ray-cast onto its plane. Near an
//! edge between two planes that outline is off by a pixel or two (the edge band, the
//! growth back over it, half a pixel of outline), and on a tread seen at a grazing
//! angle one pixel spans centimetres. The edge itself is known far better: it is where
//! the two fitted planes meet. So a polygon whose points all lie on one side of another
//! polygon's plane, give or take the inlier distance, is cut at that plane; where its
//! points lie on both sides (a floor around a box standing on it), the other plane
//! does not bound it and nothing is cut.

use nalgebra::Vector3;

use super::Polygon;

/// Planes closer to parallel than this never bound each other (cos of 10 deg).
const PARALLEL_COS: f64 = 0.985;

/// A polygon's points beyond another plane, as a share of its points, up to which that
/// plane still bounds it (noise and the odd mixed pixel).
const STRAY_SHARE: f64 = 0.005;

/// Cuts every polygon at the planes of the others that bound it. `points[k]` are the
/// camera-frame points of polygon k's region; `dist` is the inlier distance, m.
pub fn trim_at_neighbour_planes(polygons: &mut [Polygon], points: &[Vec<[f32; 3]>], dist: f64) {
    let planes: Vec<(Vector3<f64>, f64)> = polygons.iter().map(|p| (Vector3::from(p.normal), p.offset)).collect();
    for (a, polygon) in polygons.iter_mut().enumerate() {
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
            let pts = &points[a];
            let strays = pts.iter().filter(|p| side * f(&p.map(f64::from)) < -dist).count();
            if pts.is_empty() || strays as f64 > STRAY_SHARE * pts.len() as f64 {
                tracing::debug!(
                    "polygon {a} crosses the plane of polygon {b}: {strays} of {} points beyond it",
                    pts.len()
                );
                continue;
            }
            tracing::debug!("polygon {a} cut at the plane of polygon {b}");
            let keep = |p: &[f64; 3]| side * f(p);
            let outer = clip_ring(&polygon.boundary, keep);
            if outer.len() < 3 {
                continue;
            }
            polygon.boundary = outer;
            polygon.holes = polygon.holes.iter().map(|h| clip_ring(h, keep)).filter(|h| h.len() >= 3).collect();
        }
    }
}

/// The part of a ring where `f` >= 0 (Sutherland-Hodgman against one plane; the ring
/// may be non-convex, a cut across it leaves a ring that runs along the cut).
pub fn clip_ring(ring: &[[f64; 3]], f: impl Fn(&[f64; 3]) -> f64) -> Vec<[f64; 3]> {
    let mut out = Vec::with_capacity(ring.len() + 2);
    for i in 0..ring.len() {
        let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
        let (fa, fb) = (f(&a), f(&b));
        if fa >= 0.0 {
            out.push(a);
        }
        if (fa >= 0.0) != (fb >= 0.0) {
            let t = fa / (fa - fb);
            out.push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])]);
        }
    }
    out.dedup();
    out
}
