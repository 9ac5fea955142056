//! Footholds: a convex region of the map where a foot fits around a point, as a footstep
//! planner asks for it. Only insets count (the polygons shrunk by the foot margin, holes
//! grown by it), so a foot placed anywhere in the answer stays on the surface.

use geo::{Coord, Distance, Euclidean, Point, Polygon as Shape};

use super::geometry::top_down;
use super::{MapPolygon, MapSnapshot};

/// A foothold found for a point.
#[derive(Clone, Debug)]
pub struct Found<'a> {
    pub polygon: &'a MapPolygon,
    /// The convex region, on the polygon's plane (counter-clockwise from above).
    pub piece: Vec<[f64; 3]>,
    /// Horizontal distance from the point to the inset it was grown in, m (0 inside).
    pub distance: f64,
}

/// What a foothold query finds: a region, or nothing within reach.
pub type Foothold<'a> = Option<Found<'a>>;

/// Surfaces further than this above or below the point are not its footholds, m.
pub const MAX_HEIGHT_DIFFERENCE_M: f64 = 0.3;

/// The largest convex region around `p` (seen from above) inside the inset under it, on a
/// horizontal surface within [`MAX_HEIGHT_DIFFERENCE_M`] of its height; failing that, around
/// the nearest point of the nearest such inset.
pub fn foothold(s: &MapSnapshot, p: [f64; 3]) -> Foothold<'_> {
    let at = Coord { x: p[0], y: p[1] };
    let mut best: Option<(f64, f64, &MapPolygon, Shape<f64>)> = None;
    for poly in s.polygons.iter().filter(|q| q.label.is_horizontal() && q.normal[2].abs() > 1e-3) {
        let dz = (poly.height_at(at.x, at.y) - p[2]).abs();
        if dz > MAX_HEIGHT_DIFFERENCE_M {
            continue;
        }
        for inset in &poly.insets {
            let shape = top_down(&inset.boundary, &inset.holes);
            let d = Euclidean.distance(&Point(at), &shape);
            if best.as_ref().is_none_or(|&(bd, bdz, _, _)| d < bd || (d == bd && dz < bdz)) {
                best = Some((d, dz, poly, shape));
            }
        }
    }
    let (distance, _, polygon, shape) = best?;
    let region = super::convex::convex_region_around(&shape, at)?;
    let piece = region.into_iter().map(|c| [c.x, c.y, polygon.height_at(c.x, c.y)]).collect();
    Some(Found { polygon, piece, distance })
}

/// Horizontal distance from `q` to a convex ring (0 inside).
pub fn distance_xy(ring: &[[f64; 3]], q: [f64; 2]) -> f64 {
    let n = ring.len();
    let mut inside = n >= 3;
    let mut nearest = f64::INFINITY;
    let area: f64 = (0..n).map(|i| ring[i][0] * ring[(i + 1) % n][1] - ring[(i + 1) % n][0] * ring[i][1]).sum();
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + 1) % n]);
        let cross = (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]);
        if cross * area.signum() < 0.0 {
            inside = false;
        }
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len2 = (dx * dx + dy * dy).max(1e-300);
        let t = (((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / len2).clamp(0.0, 1.0);
        nearest = nearest.min((a[0] + t * dx - q[0]).hypot(a[1] + t * dy - q[1]));
    }
    if inside { 0.0 } else { nearest }
}
