//! Footholds: a convex region of the map where a foot fits around a point, as a footstep
//! planner asks for it. Only insets of steppable polygons count (the polygons shrunk by the
//! foot margin, holes grown by it), so a foot placed anywhere in the answer stays on a
//! surface whose plane is known.

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
/// steppable horizontal surface within [`MAX_HEIGHT_DIFFERENCE_M`] of its height; failing
/// that, around the nearest point of the nearest such inset.
pub fn foothold(s: &MapSnapshot, p: [f64; 3]) -> Foothold<'_> {
    let at = Coord { x: p[0], y: p[1] };
    let mut best: Option<(f64, f64, &MapPolygon, Shape<f64>)> = None;
    let footholds = s.polygons.iter().filter(|q| q.footing.is_steppable() && q.label.is_horizontal());
    for poly in footholds.filter(|q| q.normal[2].abs() > 1e-3) {
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
