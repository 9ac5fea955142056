//! Footholds: the convex piece of the map under a point, as a footstep planner asks for it.

use super::{MapPolygon, MapSnapshot};

/// A convex piece found for a point.
#[derive(Clone, Copy, Debug)]
pub struct Found<'a> {
    pub polygon: &'a MapPolygon,
    pub piece: &'a [[f64; 3]],
    /// Horizontal distance from the point to the piece, m (0 when it contains it).
    pub distance: f64,
}

/// What a foothold query finds: a piece, or nothing within reach.
pub type Foothold<'a> = Option<Found<'a>>;

/// Surfaces further than this above or below the point are not its footholds, m.
pub const MAX_HEIGHT_DIFFERENCE_M: f64 = 0.3;

/// The convex piece under `p` (seen from above, on a horizontal surface within
/// [`MAX_HEIGHT_DIFFERENCE_M`] of its height), or failing that the nearest such piece.
pub fn foothold(s: &MapSnapshot, p: [f64; 3]) -> Foothold<'_> {
    let mut best: Option<(f64, f64, Found)> = None;
    for poly in s.polygons.iter().filter(|q| q.label.is_horizontal() && q.normal[2].abs() > 1e-3) {
        let z = -(poly.normal[0] * p[0] + poly.normal[1] * p[1] + poly.offset) / poly.normal[2];
        let dz = (z - p[2]).abs();
        if dz > MAX_HEIGHT_DIFFERENCE_M {
            continue;
        }
        for piece in &poly.convex_pieces {
            let d = distance_xy(piece, [p[0], p[1]]);
            let better =
                best.as_ref().is_none_or(|&(bd, bdz, _)| (d, dz) < (bd, bdz) && (d < bd || (d == 0.0 && dz < bdz)));
            if better {
                best = Some((d, dz, Found { polygon: poly, piece, distance: d }));
            }
        }
    }
    best.map(|(_, _, f)| f)
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
