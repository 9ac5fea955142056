//! Footprints on planes: a 3-D planar polygon becomes a 2-D `geo` shape in a frame fixed on
//! its plane, where union, intersection, simplification and buffering are plain 2-D work;
//! shapes go back to 3-D by moving each point along the frame's normal onto the current plane.

use geo::{Area, BooleanOps, BoundingRect, Coord, LineString, MultiPolygon, Polygon as Shape, Simplify};
use nalgebra::{Isometry3, Matrix3, SymmetricEigen, Vector3};

use serde::{Deserialize, Serialize};

use crate::ring::clip_ring;
use crate::ring::offset_vertices;
use crate::types::Intrinsics;

/// A plane n . p + d = 0 with unit n.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub normal: Vector3<f64>,
    pub offset: f64,
}

impl Plane {
    /// Where the line `q + t * dir` meets the plane, as t (None when parallel).
    pub fn along(&self, q: &Vector3<f64>, dir: &Vector3<f64>) -> Option<f64> {
        let nd = self.normal.dot(dir);
        (nd.abs() > 1e-9).then(|| -(self.normal.dot(q) + self.offset) / nd)
    }
}

/// 2-D coordinates on a plane: origin, two in-plane axes and the normal they were made for.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlaneFrame {
    pub origin: Vector3<f64>,
    pub e1: Vector3<f64>,
    pub e2: Vector3<f64>,
    pub normal: Vector3<f64>,
}

impl PlaneFrame {
    /// A frame at `origin` on a plane with `normal`; e1 follows world x where it can, so
    /// that the 2-D shapes of horizontal polygons are their top-down footprints.
    pub fn new(origin: Vector3<f64>, normal: Vector3<f64>) -> PlaneFrame {
        let n = normal.normalize();
        let seed = if n.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
        let e1 = (seed - n * n.dot(&seed)).normalize();
        PlaneFrame { origin, e1, e2: n.cross(&e1), normal: n }
    }

    pub fn to_2d(&self, p: &[f64; 3]) -> Coord<f64> {
        let d = Vector3::from(*p) - self.origin;
        Coord { x: d.dot(&self.e1), y: d.dot(&self.e2) }
    }

    /// The 3-D point at `c`, moved along the frame's normal onto `plane`.
    pub fn lift(&self, c: Coord<f64>, plane: &Plane) -> [f64; 3] {
        let q = self.origin + self.e1 * c.x + self.e2 * c.y;
        let p = q + self.normal * plane.along(&q, &self.normal).unwrap_or(0.0);
        [p.x, p.y, p.z]
    }

    /// A 3-D polygon (outline and holes, on or near this plane) as a 2-D shape, counter-clockwise
    /// outline and clockwise holes as `geo` expects.
    pub fn shape(&self, boundary: &[[f64; 3]], holes: &[Vec<[f64; 3]>]) -> Shape<f64> {
        let ring = |pts: &[[f64; 3]]| LineString::from(pts.iter().map(|p| self.to_2d(p)).collect::<Vec<_>>());
        let mut s = Shape::new(ring(boundary), holes.iter().map(|h| ring(h)).collect());
        use geo::orient::{Direction, Orient};
        s = s.orient(Direction::Default);
        s
    }

    /// A 2-D ring back in 3-D on `plane`, without the closing repeat of the first point.
    pub fn lift_ring(&self, ring: &LineString<f64>, plane: &Plane) -> Vec<[f64; 3]> {
        let n = ring.0.len().saturating_sub(usize::from(ring.is_closed()));
        ring.0[..n].iter().map(|c| self.lift(*c, plane)).collect()
    }
}

/// Area-weighted first and second moments of planar surface patches: the plane through
/// everything a map polygon has seen is the least-squares plane of these moments.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Moments {
    pub weight: f64,
    pub sum: Vector3<f64>,
    pub sum_sq: Matrix3<f64>,
}

impl Default for Moments {
    fn default() -> Self {
        Moments { weight: 0.0, sum: Vector3::zeros(), sum_sq: Matrix3::zeros() }
    }
}

impl Moments {
    /// Moments of a ring's surface (fan triangles, signed so that the total area is positive).
    fn of_ring(ring: &[[f64; 3]], normal: &Vector3<f64>) -> Moments {
        let mut m = Moments::default();
        let Some(a) = ring.first().map(|p| Vector3::from(*p)) else { return m };
        for w in ring.windows(2).skip(1) {
            let (b, c) = (Vector3::from(w[0]), Vector3::from(w[1]));
            let area = (b - a).cross(&(c - a)).dot(normal) / 2.0;
            let s = a + b + c;
            m.weight += area;
            m.sum += s * (area / 3.0);
            // Exact second moment of a triangle: A/12 (a a' + b b' + c c' + s s').
            m.sum_sq += (a * a.transpose() + b * b.transpose() + c * c.transpose() + s * s.transpose()) * (area / 12.0);
        }
        if m.weight < 0.0 { m.scaled(-1.0) } else { m }
    }

    /// Moments of a polygon's surface: its outline minus its holes.
    pub fn of_polygon(boundary: &[[f64; 3]], holes: &[Vec<[f64; 3]>], normal: &Vector3<f64>) -> Moments {
        let mut m = Moments::of_ring(boundary, normal);
        for h in holes {
            m.add(&Moments::of_ring(h, normal).scaled(-1.0));
        }
        m
    }

    pub fn scaled(&self, k: f64) -> Moments {
        Moments { weight: self.weight * k, sum: self.sum * k, sum_sq: self.sum_sq * k }
    }

    pub fn add(&mut self, o: &Moments) {
        self.weight += o.weight;
        self.sum += o.sum;
        self.sum_sq += o.sum_sq;
    }

    /// The least-squares plane (normal along the smallest spread), normal on `hint`'s side.
    pub fn plane(&self, hint: &Vector3<f64>) -> Option<Plane> {
        if !(self.weight > 0.0) {
            return None;
        }
        let mean = self.sum / self.weight;
        let cov = self.sum_sq / self.weight - mean * mean.transpose();
        let eig = SymmetricEigen::new(cov);
        let k = eig.eigenvalues.imin();
        let mut n: Vector3<f64> = eig.eigenvectors.column(k).into_owned();
        if n.dot(hint) < 0.0 {
            n = -n;
        }
        n.iter().all(|v| v.is_finite()).then(|| Plane { normal: n, offset: -n.dot(&mean) })
    }
}

/// Vertices of a shape, outline and holes, closing repeats not counted.
pub fn vertex_count(s: &Shape<f64>) -> usize {
    std::iter::once(s.exterior()).chain(s.interiors()).map(|r| r.0.len().saturating_sub(1)).sum()
}

/// Holes smaller than this, or thinner than `SLIVER_HOLE_M`, are slivers that boolean
/// operations leave between nearly coincident outlines, not surface gaps (the extractor
/// keeps no hole under `min_polygon_area_m2`, 0.01 m^2 by default), m^2.
const SLIVER_HOLE_M2: f64 = 1e-3;
const SLIVER_HOLE_M: f64 = 0.005;

/// The largest part of a union or buffer, without sliver holes (parts and holes from
/// round-off are dropped).
pub fn largest(mp: MultiPolygon<f64>) -> Option<Shape<f64>> {
    mp.0.into_iter().max_by(|a, b| a.unsigned_area().total_cmp(&b.unsigned_area())).map(without_sliver_holes)
}

/// Pieces of an inset smaller than this are crumbs of the offset, not places for a foot, m^2.
const INSET_CRUMB_M2: f64 = 1e-4;

/// `shape` shrunk by `margin` (its holes grown by it): every piece that is left, each with
/// its holes; the shape itself for no margin.
pub fn inset(shape: &Shape<f64>, margin: f64) -> Vec<Shape<f64>> {
    if margin <= 0.0 {
        return vec![shape.clone()];
    }
    use geo::Buffer;
    shape
        .buffer(-margin)
        .0
        .into_iter()
        .filter(|piece| piece.unsigned_area() >= INSET_CRUMB_M2)
        .map(without_sliver_holes)
        .collect()
}

fn without_sliver_holes(s: Shape<f64>) -> Shape<f64> {
    let (outline, holes) = s.into_inner();
    let is_gap = |h: &LineString<f64>| {
        let area = ring_area(h);
        let perimeter: f64 = h.lines().map(|l| (l.end.x - l.start.x).hypot(l.end.y - l.start.y)).sum();
        // A thin hole's width is about twice its area over its perimeter.
        area >= SLIVER_HOLE_M2 && 2.0 * area >= SLIVER_HOLE_M * perimeter
    };
    Shape::new(outline, holes.into_iter().filter(is_gap).collect())
}

/// A ring of 3-D points on or near `frame`'s plane in 2-D, each vertex moved `d[i]` into
/// the material: inwards for an outline, out of the hole for a hole (at most twice d, on
/// sharp corners).
pub fn inset_ring(frame: &PlaneFrame, ring: &[[f64; 3]], d: &[f64], outline: bool) -> LineString<f64> {
    let pts: Vec<[f64; 2]> = ring.iter().map(|p| frame.to_2d(p)).map(|c| [c.x, c.y]).collect();
    // An outline's material is its inside; a hole's is outside it.
    let away: Vec<f64> = d.iter().map(|&d| if outline { -d } else { d }).collect();
    LineString::from(offset_vertices(&pts, &away).into_iter().map(|[x, y]| Coord { x, y }).collect::<Vec<_>>())
}

/// A polygon with holes (world frame) seen from above: its x and y as a 2-D shape.
pub fn top_down(boundary: &[[f64; 3]], holes: &[Vec<[f64; 3]>]) -> Shape<f64> {
    let ring = |pts: &[[f64; 3]]| LineString::from(pts.iter().map(|p| Coord { x: p[0], y: p[1] }).collect::<Vec<_>>());
    Shape::new(ring(boundary), holes.iter().map(|h| ring(h)).collect())
}

/// Signed area of a 2-D ring (positive counter-clockwise), m^2 (shoelace).
pub fn signed_area(ring: &[Coord<f64>]) -> f64 {
    let n = ring.len();
    (0..n).map(|i| ring[i].x * ring[(i + 1) % n].y - ring[(i + 1) % n].x * ring[i].y).sum::<f64>() / 2.0
}

/// Area enclosed by a ring, m^2 (shoelace).
fn ring_area(r: &LineString<f64>) -> f64 {
    r.lines().map(|l| l.start.x * l.end.y - l.end.x * l.start.y).sum::<f64>().abs() / 2.0
}

/// The space a camera looked into: the pyramid through its image's corners, pulled in
/// by a margin (world frame).
#[derive(Clone, Copy, Debug)]
pub struct ViewPyramid {
    apex: Vector3<f64>,
    /// Inward normals of the four side planes (all through the apex) and the optical axis.
    inward: [Vector3<f64>; 5],
}

/// The farthest a view pyramid reaches on a plane, m (the L515 ranges to 9 m).
const VIEW_REACH_M: f64 = 10.0;
/// A point nearer the camera than this, along its axis, is not in view, m.
const VIEW_NEAR_M: f64 = 0.05;

impl ViewPyramid {
    pub fn new(t_world_camera: &Isometry3<f64>, intr: &Intrinsics, margin_px: f64) -> ViewPyramid {
        let (u0, v0) = (margin_px, margin_px);
        let (u1, v1) = (intr.width as f64 - 1.0 - margin_px, intr.height as f64 - 1.0 - margin_px);
        let corners = [intr.ray(u0, v0), intr.ray(u1, v0), intr.ray(u1, v1), intr.ray(u0, v1)];
        let axis = Vector3::z();
        let side = |a: &Vector3<f64>, b: &Vector3<f64>| {
            let n = a.cross(b);
            if n.dot(&axis) < 0.0 { -n } else { n }
        };
        let r = t_world_camera.rotation;
        let inward = [
            r * side(&corners[0], &corners[1]),
            r * side(&corners[1], &corners[2]),
            r * side(&corners[2], &corners[3]),
            r * side(&corners[3], &corners[0]),
            r * axis,
        ];
        ViewPyramid { apex: t_world_camera.translation.vector, inward }
    }

    /// Where the pyramid meets `frame`'s plane (within `VIEW_REACH_M` of the apex's foot),
    /// in the frame's 2-D coordinates; None where it misses.
    pub fn on_plane(&self, frame: &PlaneFrame) -> Option<Shape<f64>> {
        let foot = frame.to_2d(&[self.apex.x, self.apex.y, self.apex.z]);
        let r = VIEW_REACH_M;
        let mut ring: Vec<[f64; 3]> =
            [(-r, -r), (r, -r), (r, r), (-r, r)].iter().map(|&(x, y)| [foot.x + x, foot.y + y, 0.0]).collect();
        // Each half-space n . (X - apex) >= near, with X = origin + e1 x + e2 y on the plane.
        for (i, n) in self.inward.iter().enumerate() {
            let near = if i == 4 { VIEW_NEAR_M } else { 0.0 };
            let (a, b, c) = (n.dot(&frame.e1), n.dot(&frame.e2), n.dot(&(frame.origin - self.apex)) - near);
            ring = clip_ring(&ring, |p| a * p[0] + b * p[1] + c);
            if ring.len() < 3 {
                return None;
            }
        }
        Some(Shape::new(LineString::from(ring.iter().map(|p| Coord { x: p[0], y: p[1] }).collect::<Vec<_>>()), vec![]))
    }
}

/// `a` without `b`, keeping the largest part.
pub fn difference(a: &Shape<f64>, b: &MultiPolygon<f64>) -> Option<Shape<f64>> {
    largest(a.difference(b)).filter(|s| s.unsigned_area() > 0.0)
}

/// Union of two shapes, keeping the largest connected part.
pub fn union(a: &Shape<f64>, b: &Shape<f64>) -> Option<Shape<f64>> {
    largest(a.union(b))
}

/// Intersection of two shapes, keeping the largest part.
pub fn intersection(a: &Shape<f64>, b: &Shape<f64>) -> Option<Shape<f64>> {
    largest(a.intersection(b)).filter(|s| s.unsigned_area() > 0.0)
}

/// Area of the overlap of two shapes, and the overlap's centroid.
pub fn overlap(a: &Shape<f64>, b: &Shape<f64>) -> (f64, Option<Coord<f64>>) {
    let (ra, rb) = (a.bounding_rect(), b.bounding_rect());
    let (Some(ra), Some(rb)) = (ra, rb) else { return (0.0, None) };
    if ra.max().x < rb.min().x || rb.max().x < ra.min().x || ra.max().y < rb.min().y || rb.max().y < ra.min().y {
        return (0.0, None);
    }
    let i = a.intersection(b);
    use geo::Centroid;
    (i.unsigned_area(), i.centroid().map(|p| p.0))
}

/// The shape simplified (Douglas-Peucker, growing tolerance from 5 mm) until it has at most
/// `max_vertices`; holes that vanish are dropped.
pub fn simplify_to(s: &Shape<f64>, max_vertices: usize) -> Shape<f64> {
    let mut eps = 0.005;
    let mut out = s.clone();
    while vertex_count(&out) > max_vertices && eps < 10.0 {
        out = s.simplify(eps);
        let interiors: Vec<LineString<f64>> = out.interiors().iter().filter(|r| r.0.len() >= 4).cloned().collect();
        out = Shape::new(out.exterior().clone(), interiors);
        eps *= 1.5;
    }
    // Holes simplify to no fewer than three vertices each: the smallest go until it fits.
    if vertex_count(&out) > max_vertices {
        let (outline, mut holes) = out.into_inner();
        holes.sort_by(|a, b| ring_area(b).total_cmp(&ring_area(a)));
        let mut room = max_vertices.saturating_sub(outline.0.len().saturating_sub(1));
        holes.retain(|h| {
            let n = h.0.len().saturating_sub(1);
            let fits = n <= room;
            room = room.saturating_sub(n);
            fits
        });
        out = Shape::new(outline, holes);
    }
    out
}
