//! Planar rings of 3-D vertices (outlines and holes, no closing repeat), for the
//! extractor's polygons and the map's shapes alike; rings drawn onto a pixel grid; 2-D rings
//! moved along their edges' normals (a polygon's half-pixel offset, the map's insets).

use nalgebra::Vector3;

/// Area of a planar ring, m^2 (Newell's method, magnitude).
pub fn ring_area(ring: &[[f64; 3]], normal: &Vector3<f64>) -> f64 {
    let mut acc = Vector3::zeros();
    for i in 0..ring.len() {
        let (a, b) = (Vector3::from(ring[i]), Vector3::from(ring[(i + 1) % ring.len()]));
        acc += a.cross(&b);
    }
    (acc.dot(normal) / 2.0).abs()
}

/// The part of a ring where `f` >= 0 (Sutherland-Hodgman against one plane; the ring
/// may be non-convex, a cut across it leaves a ring that runs along the cut).
pub fn clip_ring(ring: &[[f64; 3]], f: impl Fn(&[f64; 3]) -> f64) -> Vec<[f64; 3]> {
    clip_tagged_ring(ring, &vec![(); ring.len()], f, ()).0
}

/// [`clip_ring`] for a ring whose vertices carry a tag each (`tags[k]` is vertex k's):
/// kept vertices keep theirs, the vertices made on the cut get `cut`, and so does a kept
/// vertex that lies on the cut itself.
pub fn clip_tagged_ring<T: Copy + PartialEq>(
    ring: &[[f64; 3]],
    tags: &[T],
    f: impl Fn(&[f64; 3]) -> f64,
    cut: T,
) -> (Vec<[f64; 3]>, Vec<T>) {
    debug_assert_eq!(ring.len(), tags.len());
    let mut out: Vec<[f64; 3]> = Vec::with_capacity(ring.len() + 2);
    let mut out_tags = Vec::with_capacity(ring.len() + 2);
    let mut push = |p: [f64; 3], tag: T| {
        if out.last() == Some(&p) {
            // The same point twice: a vertex on the cut, met again as the cut's crossing.
            if tag == cut {
                *out_tags.last_mut().expect("one tag per point") = cut;
            }
        } else {
            out.push(p);
            out_tags.push(tag);
        }
    };
    for i in 0..ring.len() {
        let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
        let (fa, fb) = (f(&a), f(&b));
        if fa >= 0.0 {
            push(a, tags[i]);
        }
        if (fa >= 0.0) != (fb >= 0.0) {
            let t = fa / (fa - fb);
            push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])], cut);
        }
    }
    (out, out_tags)
}

/// Even-odd scanline fill of rings (outline and holes) at pixel centres.
pub fn fill_rings(rings: &[Vec<[f64; 2]>], width: usize, height: usize) -> Vec<bool> {
    let mut mask = vec![false; width * height];
    let mut xs = Vec::new();
    for v in 0..height {
        let y = v as f64;
        xs.clear();
        for ring in rings {
            for i in 0..ring.len() {
                let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
                // Half-open in y, so a vertex on the scanline is counted once.
                if (a[1] <= y) != (b[1] <= y) {
                    xs.push(a[0] + (y - a[1]) / (b[1] - a[1]) * (b[0] - a[0]));
                }
            }
        }
        xs.sort_by(f64::total_cmp);
        for pair in xs.chunks_exact(2) {
            let from = pair[0].ceil().max(0.0) as usize;
            let to = (pair[1].floor() as i64).min(width as i64 - 1);
            for u in from as i64..=to {
                mask[v * width + u as usize] = true;
            }
        }
    }
    mask
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
