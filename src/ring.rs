//! Planar rings of 3-D vertices (outlines and holes, no closing repeat), for the
//! extractor's polygons and the map's shapes alike.

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
