//! Convex pieces of a non-convex polygon with holes, for planners that need convex
//! footholds: spade's constrained Delaunay triangulation (through geo), then Hertel-Mehlhorn:
//! remove diagonals while the two pieces they separate stay convex together. The result has
//! at most four times the fewest convex pieces possible, and usually close to it.

use std::collections::HashMap;

use geo::{Coord, Polygon as Shape, TriangulateDelaunay, triangulate_delaunay::DelaunayTriangulationConfig};

/// Convex pieces (counter-clockwise rings, no closing repeat) whose union is `shape`.
pub fn convex_pieces(shape: &Shape<f64>) -> Vec<Vec<Coord<f64>>> {
    let Ok(triangles) = shape.constrained_triangulation(DelaunayTriangulationConfig { snap_radius: 1e-7 }) else {
        return Vec::new();
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
    let mut pieces: Vec<Option<Vec<usize>>> = triangles
        .iter()
        .map(|t| (t.v1(), t.v2(), t.v3()))
        .filter(|&(a, b, c)| cross(a, b, c) != 0.0)
        .map(|(a, b, c)| {
            let ccw = cross(a, b, c) > 0.0;
            let (a, b, c) = (id(a), id(b), id(c));
            Some(if ccw { vec![a, b, c] } else { vec![a, c, b] })
        })
        .collect();

    loop {
        // Directed edge -> the piece it bounds; a diagonal is an edge whose reverse is bounded too.
        let mut edges: HashMap<(usize, usize), usize> = HashMap::new();
        for (k, p) in pieces.iter().enumerate() {
            if let Some(ring) = p {
                for i in 0..ring.len() {
                    edges.insert((ring[i], ring[(i + 1) % ring.len()]), k);
                }
            }
        }
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
