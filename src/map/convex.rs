//! Convex pieces of a non-convex polygon with holes, for planners that need convex
//! footholds: spade's constrained Delaunay triangulation (through geo), then Hertel-Mehlhorn:
//! remove diagonals while the two pieces they separate stay convex together. The result has
//! at most four times the fewest convex pieces possible, and usually close to it.

use std::collections::HashMap;

use geo::{Coord, Polygon as Shape, TriangulateDelaunay, triangulate_delaunay::DelaunayTriangulationConfig};

use super::geometry::signed_area;

/// A shape's constrained Delaunay triangles: the points, and each triangle's three indices
/// counter-clockwise (degenerate ones left out).
fn triangulate(shape: &Shape<f64>) -> (Vec<Coord<f64>>, Vec<Vec<usize>>) {
    let Ok(triangles) = shape.constrained_triangulation(DelaunayTriangulationConfig { snap_radius: 1e-7 }) else {
        return (Vec::new(), Vec::new());
    };
    // Shared vertices come out of one triangulation bit-identical: key them by their bits.
    let mut index: HashMap<(u64, u64), usize> = HashMap::new();
    let mut points: Vec<Coord<f64>> = Vec::new();
    let mut id = |c: Coord<f64>| {
        *index.entry((c.x.to_bits(), c.y.to_bits())).or_insert_with(|| {
            points.push(c);
            points.len() - 1
        })
    };
    let rings = triangles
        .iter()
        .map(|t| (t.v1(), t.v2(), t.v3()))
        .filter(|&(a, b, c)| cross(a, b, c) != 0.0)
        .map(|(a, b, c)| {
            let ccw = cross(a, b, c) > 0.0;
            let (a, b, c) = (id(a), id(b), id(c));
            if ccw { vec![a, b, c] } else { vec![a, c, b] }
        })
        .collect();
    (points, rings)
}

/// Directed edge -> the ring it bounds, for the rings still there.
fn edge_owners(rings: &[Option<Vec<usize>>]) -> HashMap<(usize, usize), usize> {
    let mut edges = HashMap::new();
    for (k, ring) in rings.iter().enumerate() {
        if let Some(ring) = ring {
            for i in 0..ring.len() {
                edges.insert((ring[i], ring[(i + 1) % ring.len()]), k);
            }
        }
    }
    edges
}

/// Convex pieces (counter-clockwise rings, no closing repeat) whose union is `shape`.
pub fn convex_pieces(shape: &Shape<f64>) -> Vec<Vec<Coord<f64>>> {
    let (points, triangles) = triangulate(shape);
    let mut pieces: Vec<Option<Vec<usize>>> = triangles.into_iter().map(Some).collect();
    loop {
        // A diagonal is an edge whose reverse bounds another piece.
        let edges = edge_owners(&pieces);
        let mut merged_any = false;
        for k in 0..pieces.len() {
            let Some(ring) = pieces[k].clone() else { continue };
            for i in 0..ring.len() {
                let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
                let Some(&q) = edges.get(&(b, a)) else { continue };
                if q == k || pieces[q].is_none() {
                    continue;
                }
                let joined = join(&ring, pieces[q].as_ref().unwrap(), a, b);
                if is_convex(&joined, &points) {
                    pieces[k] = Some(joined);
                    pieces[q] = None;
                    merged_any = true;
                    break;
                }
            }
            if merged_any {
                break;
            }
        }
        if !merged_any {
            break;
        }
    }
    pieces.into_iter().flatten().map(|ring| ring.into_iter().map(|i| points[i]).collect()).collect()
}

/// A large convex region of `shape` around `at` (counter-clockwise, no closing repeat), or
/// around the nearest part of `shape` when `at` is outside it. Two ways, the larger wins:
///
/// - cutting: start from the shape's convex hull and, while an edge of the shape (outline
///   or hole) reaches into the region, cut the region at that edge's point nearest `at`,
///   across the line from `at`, nearest edge first (the 2-D form of IRIS, Deits and Tedrake
///   2014): each cut clears one edge whole, so it ends within one cut per edge;
/// - growing: the triangle under `at`, grown one neighbouring triangle at a time (the one
///   adding the most area first) while the region stays convex.
///
/// None for a shape with no area.
pub fn convex_region_around(shape: &Shape<f64>, at: Coord<f64>) -> Option<Vec<Coord<f64>>> {
    let (points, triangles) = triangulate(shape);
    let distance = |t: &[usize]| {
        let ring: Vec<[f64; 3]> = t.iter().map(|&i| [points[i].x, points[i].y, 0.0]).collect();
        crate::ring::distance_xy(&ring, [at.x, at.y])
    };
    let start = (0..triangles.len()).min_by(|&a, &b| distance(&triangles[a]).total_cmp(&distance(&triangles[b])))?;
    // Cutting needs a point inside: `at`, or the middle of the triangle nearest it.
    let seed = if distance(&triangles[start]) == 0.0 {
        at
    } else {
        let t = &triangles[start];
        Coord {
            x: t.iter().map(|&i| points[i].x).sum::<f64>() / 3.0,
            y: t.iter().map(|&i| points[i].y).sum::<f64>() / 3.0,
        }
    };
    let cut = cut_around(shape, seed);
    let grown = grow_from(&points, triangles, start);
    [cut, grown].into_iter().filter(|r| r.len() >= 3).max_by(|a, b| signed_area(a).total_cmp(&signed_area(b)))
}

/// The region `shape`'s convex hull leaves once cut clear of every edge of `shape`, around `q`.
fn cut_around(shape: &Shape<f64>, q: Coord<f64>) -> Vec<Coord<f64>> {
    use geo::ConvexHull;
    let hull = shape.convex_hull();
    let mut region = tidy(hull.exterior().0.to_vec());
    if signed_area(&region) < 0.0 {
        region.reverse();
    }
    let edges: Vec<(Coord<f64>, Coord<f64>)> = std::iter::once(shape.exterior())
        .chain(shape.interiors())
        .flat_map(|r| r.lines().map(|l| (l.start, l.end)))
        .collect();
    let mut left: Vec<bool> = vec![true; edges.len()];
    loop {
        // The nearest edge still reaching into the region.
        let nearest = (0..edges.len())
            .filter(|&k| left[k] && reaches_into(&region, edges[k]))
            .map(|k| (k, nearest_on(edges[k], q)))
            .min_by(|a, b| dist(a.1, q).total_cmp(&dist(b.1, q)));
        let Some((k, p)) = nearest else { break };
        left[k] = false;
        let normal = Coord { x: p.x - q.x, y: p.y - q.y };
        if normal.x == 0.0 && normal.y == 0.0 {
            return Vec::new();
        }
        // Keep the side of the line through p, across q -> p, that holds q.
        region = tidy(clip(&region, p, normal));
        if region.len() < 3 {
            return Vec::new();
        }
    }
    region
}

/// A ring without repeated points (within [`ON_BORDER_M`]): a side of no length has no
/// direction to tell inside from outside.
fn tidy(mut ring: Vec<Coord<f64>>) -> Vec<Coord<f64>> {
    ring.dedup_by(|b, a| dist(*a, *b) <= ON_BORDER_M);
    while ring.len() > 1 && dist(ring[0], ring[ring.len() - 1]) <= ON_BORDER_M {
        ring.pop();
    }
    ring
}

fn dist(a: Coord<f64>, b: Coord<f64>) -> f64 {
    (a.x - b.x).hypot(a.y - b.y)
}

/// The point of segment `e` nearest `q`.
fn nearest_on(e: (Coord<f64>, Coord<f64>), q: Coord<f64>) -> Coord<f64> {
    let (a, b) = e;
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    let t = (((q.x - a.x) * dx + (q.y - a.y) * dy) / (dx * dx + dy * dy).max(1e-300)).clamp(0.0, 1.0);
    Coord { x: a.x + t * dx, y: a.y + t * dy }
}

/// Points of the region this close to its border are on it, not inside, m.
const ON_BORDER_M: f64 = 1e-9;

/// Whether some of segment `e` lies inside the convex counter-clockwise `region` (more than
/// [`ON_BORDER_M`] from its border): Cyrus-Beck clipping against each side.
fn reaches_into(region: &[Coord<f64>], e: (Coord<f64>, Coord<f64>)) -> bool {
    let (a, b) = e;
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for i in 0..region.len() {
        let (c, d) = (region[i], region[(i + 1) % region.len()]);
        let len = dist(c, d).max(1e-300);
        // Signed distance inside this side, at a and its change along a -> b.
        let at_a = cross(c, d, a) / len - ON_BORDER_M;
        let along = (cross(c, d, b) - cross(c, d, a)) / len;
        if along == 0.0 {
            if at_a <= 0.0 {
                return false;
            }
        } else {
            let t = -at_a / along;
            if along > 0.0 { t0 = t0.max(t) } else { t1 = t1.min(t) }
        }
        if t0 >= t1 {
            return false;
        }
    }
    true
}

/// The part of the convex `region` on the side of the line through `p` with normal `n`
/// away from which `n` points (x with (x - p) . n <= 0).
fn clip(region: &[Coord<f64>], p: Coord<f64>, n: Coord<f64>) -> Vec<Coord<f64>> {
    let side = |x: Coord<f64>| (x.x - p.x) * n.x + (x.y - p.y) * n.y;
    let mut out = Vec::with_capacity(region.len() + 1);
    for i in 0..region.len() {
        let (a, b) = (region[i], region[(i + 1) % region.len()]);
        let (sa, sb) = (side(a), side(b));
        if sa <= 0.0 {
            out.push(a);
        }
        if (sa < 0.0 && sb > 0.0) || (sa > 0.0 && sb < 0.0) {
            let t = sa / (sa - sb);
            out.push(Coord { x: a.x + t * (b.x - a.x), y: a.y + t * (b.y - a.y) });
        }
    }
    out
}

/// The triangle `start` grown by its neighbours while it stays convex, largest first.
fn grow_from(points: &[Coord<f64>], triangles: Vec<Vec<usize>>, start: usize) -> Vec<Coord<f64>> {
    let mut rings: Vec<Option<Vec<usize>>> = triangles.into_iter().map(Some).collect();
    loop {
        let edges = edge_owners(&rings);
        let region = rings[start].as_ref().expect("the region is never merged away");
        let mut best: Option<(f64, usize, Vec<usize>)> = None;
        for i in 0..region.len() {
            let (a, b) = (region[i], region[(i + 1) % region.len()]);
            let Some(&q) = edges.get(&(b, a)) else { continue };
            if q == start {
                continue;
            }
            let neighbour = rings[q].as_ref().expect("edges are of rings still there");
            let joined = join(region, neighbour, a, b);
            if is_convex(&joined, points) {
                let gain = ring_area(neighbour, points);
                if best.as_ref().is_none_or(|(g, _, _)| gain > *g) {
                    best = Some((gain, q, joined));
                }
            }
        }
        let Some((_, q, joined)) = best else { break };
        rings[start] = Some(joined);
        rings[q] = None;
    }
    rings[start].take().map_or(Vec::new(), |ring| ring.into_iter().map(|i| points[i]).collect())
}

fn ring_area(ring: &[usize], pts: &[Coord<f64>]) -> f64 {
    signed_area(&ring.iter().map(|&i| pts[i]).collect::<Vec<_>>())
}

fn cross(a: Coord<f64>, b: Coord<f64>, c: Coord<f64>) -> f64 {
    (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)
}

/// Two counter-clockwise rings sharing edge a->b (in `p`; b->a in `q`) as one ring.
fn join(p: &[usize], q: &[usize], a: usize, b: usize) -> Vec<usize> {
    let start_p = p.iter().position(|&v| v == b).unwrap();
    let start_q = q.iter().position(|&v| v == a).unwrap();
    // p from b round to a, then q from a round to b, each shared vertex once.
    let mut out: Vec<usize> = (0..p.len()).map(|i| p[(start_p + i) % p.len()]).collect();
    out.extend((1..q.len() - 1).map(|i| q[(start_q + i) % q.len()]));
    out
}

/// Every turn is left (or straight, within round-off).
fn is_convex(ring: &[usize], pts: &[Coord<f64>]) -> bool {
    let n = ring.len();
    (0..n).all(|i| {
        let (a, b, c) = (pts[ring[i]], pts[ring[(i + 1) % n]], pts[ring[(i + 2) % n]]);
        let scale = ((b.x - a.x).hypot(b.y - a.y) * (c.x - b.x).hypot(c.y - b.y)).max(1e-300);
        cross(a, b, c) / scale >= -1e-9
    })
}
