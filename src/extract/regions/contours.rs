//! Outlines of regions: outer contour and holes, simplified to polygons in pixel
//! coordinates.
//!
//! Borders are followed as Suzuki & Abe do it ("Topological structural analysis of
//! digitized binary images by border following", CVGIP 30(1), 1985; the algorithm behind
//! OpenCV's findContours and imageproc's `find_contours`), with 8-connectivity, the
//! connectivity of the regions, so a contour and its region always agree. Here it runs on
//! the label image itself, visiting only a region's pixels and its border: no mask per
//! region, no scan of its bounding box. Douglas-Peucker, as imageproc's, simplifies.

use std::ops::Range;

use imageproc::point::Point;
use rayon::prelude::*;

use super::{PointSample, Segmentation};
use crate::grid::runs;
use crate::ring::offset_vertices;

/// A region traced: its component label, outline and holes (pixel centres, simplified).
#[derive(Clone, Debug, PartialEq)]
pub struct Outline {
    pub label: u32,
    pub outer: Vec<[f32; 2]>,
    pub holes: Vec<Vec<[f32; 2]>>,
    pub pixels: usize,
    /// A sample of the camera-frame points of its valid pixels, for regions that are
    /// outlined (none for the others).
    pub points: PointSample,
}

/// The outline and holes of every region r of `seg` with `wanted[r]` (the others are left
/// without: no polygon is made of them), simplified by Douglas-Peucker with
/// `simplify_px`, then moved half a pixel outwards (holes shrink) so that the polygon
/// covers its pixels' squares rather than joining their centres. A region in more than
/// one piece is outlined by its first piece in scan order.
pub fn trace(seg: &Segmentation, simplify_px: f64, wanted: &[bool]) -> Vec<Outline> {
    let (w, h) = (seg.labels.width, seg.labels.height);
    seg.pixels
        .par_iter()
        .enumerate()
        .map(|(r, pixels)| {
            let label = r as u32 + 1;
            let mut region = Outline {
                label,
                outer: Vec::new(),
                holes: Vec::new(),
                pixels: pixels.len(),
                points: PointSample::default(),
            };
            if pixels.is_empty() || !wanted[r] {
                return region;
            }
            let shape = LabelMask { labels: &seg.labels.data, width: w, height: h, label };
            SCRATCH.with_borrow_mut(|Scratch { marks, points, simple }| {
                marks.cover(w * h);
                points.clear();
                let borders = follow_borders(&shape, pixels, marks, points);
                // A region in pieces (joined across a stripe, or cut by its neighbours) is
                // outlined by its largest.
                let area = |b: &Border| {
                    let ring = &points[b.points.clone()];
                    let pairs = ring.iter().zip(ring.iter().cycle().skip(1));
                    pairs.map(|(p, q)| p.x as i64 * q.y as i64 - q.x as i64 * p.y as i64).sum::<i64>().abs()
                };
                let outers = borders.iter().enumerate().filter(|(_, b)| b.kind == BorderKind::Outer);
                let Some((oi, _)) = outers.max_by_key(|(_, b)| area(b)) else { return };
                region.outer = offset_ring(&simplify(&points[borders[oi].points.clone()], simplify_px, simple), 0.5);
                for b in &borders {
                    if b.kind == BorderKind::Hole && b.parent == Some(oi) {
                        let hole = simplify(&points[b.points.clone()], simplify_px, simple);
                        if hole.len() >= 3 {
                            region.holes.push(offset_ring(&hole, -0.5));
                        }
                    }
                }
            });
            region
        })
        .collect()
}

/// What tracing a region needs besides the region, kept by each thread from frame to
/// frame: a frame traces a hundred borders or more (every dropout inside a region is a
/// hole), and their few points each were as many allocations.
#[derive(Default)]
struct Scratch {
    /// `follow_borders`' marks, all 0 between calls.
    marks: Marks,
    /// The borders' pixels, one after the other.
    points: Vec<Point<i32>>,
    /// `simplify`'s corners and kept vertices.
    simple: [Vec<Point<i32>>; 2],
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// Border following's mark of each pixel (0: none yet), and a bit a pixel saying which are
/// marked: the last mark inside a run is then found 64 pixels a word. Read from the marks
/// themselves, that search touched every pixel of every region, and was most of the
/// border following's time.
#[derive(Default)]
pub struct Marks {
    values: Vec<i32>,
    marked: Vec<u64>,
}

impl Marks {
    pub const fn new() -> Marks {
        Marks { values: Vec::new(), marked: Vec::new() }
    }

    /// Room for `pixels` pixels (never less than before), new ones unmarked.
    pub fn cover(&mut self, pixels: usize) {
        if pixels > self.values.len() {
            self.values.resize(pixels, 0);
            self.marked.resize(pixels.div_ceil(64), 0);
        }
    }

    /// Whether no pixel is marked.
    pub fn all_clear(&self) -> bool {
        self.values.iter().all(|&m| m == 0) && self.marked.iter().all(|&b| b == 0)
    }

    #[inline]
    fn get(&self, i: usize) -> i32 {
        self.values[i]
    }

    /// Marks pixel i with m (not 0).
    #[inline]
    fn put(&mut self, i: usize, m: i32) {
        self.values[i] = m;
        self.marked[i / 64] |= 1 << (i % 64);
    }

    #[inline]
    fn clear(&mut self, i: usize) {
        self.values[i] = 0;
        self.marked[i / 64] &= !(1 << (i % 64));
    }

    /// The mark of the last marked pixel of `pixels`, if one is.
    fn last_in(&self, pixels: Range<usize>) -> Option<i32> {
        if pixels.is_empty() {
            return None;
        }
        let (first, last) = (pixels.start, pixels.end - 1);
        for word in (first / 64..=last / 64).rev() {
            let mut bits = self.marked[word];
            if word == last / 64 {
                bits &= u64::MAX >> (63 - last % 64);
            }
            if word == first / 64 {
                bits &= u64::MAX << (first % 64);
            }
            if bits != 0 {
                return Some(self.values[word * 64 + 63 - bits.leading_zeros() as usize]);
            }
        }
        None
    }
}

/// The pixels labelled `label` in an image of labels.
pub struct LabelMask<'a> {
    pub labels: &'a [u32],
    pub width: usize,
    pub height: usize,
    pub label: u32,
}

impl LabelMask<'_> {
    /// Whether pixel (x, y) is the shape's: false off the image.
    #[inline(always)]
    fn has(&self, x: i32, y: i32) -> bool {
        x >= 0
            && y >= 0
            && (x as usize) < self.width
            && (y as usize) < self.height
            && self.labels[y as usize * self.width + x as usize] == self.label
    }
}

/// Whether a border has the shape's inside or a hole's on its inner side.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BorderKind {
    Outer,
    Hole,
}

/// One border: where its pixels, in the order followed, lie in the list `follow_borders`
/// fills, and the index of the border around it.
#[derive(Clone, Debug, PartialEq)]
pub struct Border {
    pub points: Range<usize>,
    pub kind: BorderKind,
    pub parent: Option<usize>,
}

/// The 8 neighbours, clockwise on the image (y down) from the west.
const DIRECTIONS: [(i32, i32); 8] = [(-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0), (1, 1), (0, 1), (-1, 1)];
const EAST: usize = 4;
const WEST: usize = 0;

/// Every border of `shape`, whose pixel indices are `pixels` (ascending), as Suzuki &
/// Abe's algorithm 1 finds them scanning the shape with a background margin around the
/// image, their pixels appended to `points`. `marks` (covering the image) must be all
/// clear, and is again on return.
pub fn follow_borders(
    shape: &LabelMask,
    pixels: &[u32],
    marks: &mut Marks,
    points: &mut Vec<Point<i32>>,
) -> Vec<Border> {
    // marks: 0 = a pixel no border has passed; n >= 2 = passed by border n - 2 (its
    // number in the paper); -n = passed by it with its east neighbour, background, seen.
    let w = shape.width;
    let mut borders: Vec<Border> = Vec::new();
    let mut parent_number = 1;
    // One pixel of the scan: a border may start there (its west or east neighbour is
    // background), and the last border passed is the parent of the next one on the row.
    let mut visit = |i: usize,
                     (x, y): (usize, usize),
                     west_in: bool,
                     east_in: bool,
                     marks: &mut Marks,
                     parent_number: &mut usize| {
        let mark = marks.get(i);
        let start = if mark == 0 && !west_in {
            Some((WEST, BorderKind::Outer))
        } else if mark >= 0 && !east_in {
            if mark > 1 {
                *parent_number = mark as usize;
            }
            Some((EAST, BorderKind::Hole))
        } else {
            None
        };
        if let Some((from, kind)) = start {
            let number = borders.len() as i32 + 2;
            let parent = (*parent_number > 1).then(|| {
                let p = *parent_number - 2;
                if (kind == BorderKind::Outer) ^ (borders[p].kind == BorderKind::Outer) {
                    Some(p)
                } else {
                    borders[p].parent
                }
            });
            let start = points.len();
            follow(shape, (x as i32, y as i32), from, number, marks, points);
            borders.push(Border { points: start..points.len(), kind, parent: parent.flatten() });
        }
        let mark = marks.get(i);
        if mark != 0 {
            *parent_number = mark.unsigned_abs() as usize;
        }
    };
    // Run by run along the rows: only a run's ends can start a border (inside it both
    // neighbours are the shape's), so its inside is only looked at for the last border
    // that passed it.
    let mut row = usize::MAX;
    for run in runs(pixels, w) {
        if run.v != row {
            row = run.v;
            parent_number = 1;
        }
        let (first, last) = (run.first, run.last);
        let (u_first, u_last) = run.columns();
        visit(first, (u_first, run.v), false, last > first, marks, &mut parent_number);
        if last > first {
            if let Some(m) = marks.last_in(first + 1..last) {
                parent_number = m.unsigned_abs() as usize;
            }
            visit(last, (u_last, run.v), true, false, marks, &mut parent_number);
        }
    }
    for b in &borders {
        for p in &points[b.points.clone()] {
            marks.clear(p.y as usize * w + p.x as usize);
        }
    }
    borders
}

/// Follows the border through `start`, whose neighbour towards `from` is background,
/// marking its pixels with `number` (step 3 of the paper's algorithm 1) and appending them
/// to `points`.
fn follow(
    shape: &LabelMask,
    start: (i32, i32),
    from: usize,
    number: i32,
    marks: &mut Marks,
    points: &mut Vec<Point<i32>>,
) {
    let width = shape.width;
    let step = |(x, y): (i32, i32), d: usize| (x + DIRECTIONS[d].0, y + DIRECTIONS[d].1);
    let at = |(x, y): (i32, i32)| y as usize * width + x as usize;
    // The first pixel of the shape clockwise from `from`: none, and `start` is alone.
    let Some(first) = (0..8).map(|k| (from + k) % 8).find(|&d| {
        let (x, y) = step(start, d);
        shape.has(x, y)
    }) else {
        marks.put(at(start), -number);
        points.push(Point::new(start.0, start.1));
        return;
    };
    let second = step(start, first);
    // `back`: the direction from the current pixel to the one before it; the second pixel
    // stands before the start. A step in direction d lands where d + 4 points back.
    let (mut current, mut back) = (start, first);
    loop {
        points.push(Point::new(current.0, current.1));
        // Counter-clockwise from just before the pixel we came from: the next border pixel
        // (the one we came from at worst), noting whether the east was seen empty on the way.
        let mut east_seen = false;
        let mut next = back;
        for k in 1..=8 {
            let d = (back + 8 - k) % 8;
            let (x, y) = step(current, d);
            if shape.has(x, y) {
                next = d;
                break;
            }
            east_seen |= d == EAST;
        }
        let following = step(current, next);
        let i = at(current);
        if east_seen {
            marks.put(i, -number);
        } else if marks.get(i) == 0 {
            marks.put(i, number);
        }
        if following == start && current == second {
            break;
        }
        (current, back) = (following, (next + 4) % 8);
    }
}

/// Douglas-Peucker on a traced border (closed), as imageproc's `approximate_polygon_dp`
/// gives it. It runs on the border's corners only: the first and last pixels and each
/// pixel where the step to the next one turns. A pixel inside a straight stretch is never
/// the one picked: its distance to a chord is exact (integer coordinates, the same
/// divisor), affine along the stretch, so the stretch's largest is at an end and an inner
/// pixel only ties with the first end, which comes before it and wins. The same polygon
/// from a fifth to a tenth of the points. `scratch` holds the corners and the kept ones.
fn simplify(pts: &[Point<i32>], tolerance: f64, scratch: &mut [Vec<Point<i32>>; 2]) -> Vec<[f32; 2]> {
    let [corners, kept] = scratch;
    let simple: &[Point<i32>] = if pts.len() > 3 {
        corners_of(pts, corners);
        kept.clear();
        kept.push(corners[0]);
        douglas_peucker(corners, tolerance, kept);
        // A closed curve: its last corner is not repeated (it is the first's neighbour).
        kept.pop();
        kept
    } else {
        pts
    };
    simple.iter().map(|p| [p.x as f32, p.y as f32]).collect()
}

/// Douglas-Peucker's recursion as imageproc's `approximate_polygon_dp` runs it, appending
/// the curve's vertices after the first to `out`, without its allocation a step (several
/// per vertex kept, a hundred borders a frame). The farthest vertex from the chord is the
/// first with the largest |a x + b y + c| (integers: the same order as imageproc's
/// distances, which divide them all by one norm), split at when its distance exceeds
/// `tolerance`. The simplify test holds the result to imageproc's.
fn douglas_peucker(curve: &[Point<i32>], tolerance: f64, out: &mut Vec<Point<i32>>) {
    let (p, q) = (curve[0], curve[curve.len() - 1]);
    let (a, b) = (i64::from(p.y - q.y), i64::from(q.x - p.x));
    let c = i64::from(p.x) * i64::from(q.y) - i64::from(q.x) * i64::from(p.y);
    let (mut farthest, mut index) = (0, 0);
    for (i, v) in curve.iter().enumerate().skip(1) {
        let d = (a * i64::from(v.x) + b * i64::from(v.y) + c).abs();
        if d > farthest {
            (farthest, index) = (d, i);
        }
    }
    // As imageproc divides (a chord of one point: 0 / 0, never above the tolerance).
    if farthest as f64 / ((a * a + b * b) as f64).sqrt() > tolerance {
        douglas_peucker(&curve[..=index], tolerance, out);
        douglas_peucker(&curve[index..], tolerance, out);
    } else {
        out.push(q);
    }
}

/// The first and last points of a chain and every point where its step turns, into `out`.
fn corners_of(pts: &[Point<i32>], out: &mut Vec<Point<i32>>) {
    let step = |a: Point<i32>, b: Point<i32>| (b.x - a.x, b.y - a.y);
    out.clear();
    out.extend(pts.first());
    out.extend(pts.windows(3).filter(|t| step(t[0], t[1]) != step(t[1], t[2])).map(|t| t[1]));
    if pts.len() > 1 {
        out.extend(pts.last());
    }
}

/// The ring with every edge moved `d` pixels away from the ring's inside (d < 0: towards
/// it). Vertices move along the bisector, the shift capped at 2|d| on sharp corners.
pub fn offset_ring(ring: &[[f32; 2]], d: f32) -> Vec<[f32; 2]> {
    if d == 0.0 {
        return ring.to_vec();
    }
    let pts: Vec<[f64; 2]> = ring.iter().map(|p| [p[0] as f64, p[1] as f64]).collect();
    offset_vertices(&pts, &vec![d as f64; pts.len()]).iter().map(|p| [p[0] as f32, p[1] as f32]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{GrayImage, Luma};
    use imageproc::contours::{BorderType, find_contours};
    use imageproc::geometry::approximate_polygon_dp;
    use rand::{RngExt, SeedableRng};

    /// A border with its own pixels: what imageproc hands back.
    #[derive(Debug, PartialEq)]
    struct Traced {
        points: Vec<Point<i32>>,
        kind: BorderKind,
        parent: Option<usize>,
    }

    /// imageproc's Suzuki & Abe, on the shape with the background margin drawn in.
    fn imageproc_borders(shape: &[bool], w: usize, h: usize) -> Vec<Traced> {
        let mut mask = GrayImage::new(w as u32 + 2, h as u32 + 2);
        for (i, _) in shape.iter().enumerate().filter(|(_, s)| **s) {
            mask.put_pixel((i % w) as u32 + 1, (i / w) as u32 + 1, Luma([255]));
        }
        find_contours::<i32>(&mask)
            .into_iter()
            .map(|c| Traced {
                points: c.points.iter().map(|p| Point::new(p.x - 1, p.y - 1)).collect(),
                kind: if c.border_type == BorderType::Outer { BorderKind::Outer } else { BorderKind::Hole },
                parent: c.parent,
            })
            .collect()
    }

    #[test]
    fn the_last_mark_in_a_stretch_is_the_last_non_zero_one() {
        // Stretches of every length over three words, marks (of either sign) at every
        // place, alone and after an earlier one, the stretch and the words unaligned.
        let mut marks = Marks::new();
        marks.cover(200);
        for start in [0, 1, 63, 64, 70] {
            for len in 0..130 {
                let pixels = start..start + len;
                assert_eq!(marks.last_in(pixels.clone()), None);
                for at in pixels.clone() {
                    let (early, m) = ((start + at) / 2, if at % 2 == 0 { 5 } else { -7 });
                    marks.put(at, m);
                    assert_eq!(marks.last_in(pixels.clone()), Some(m), "{pixels:?}, mark at {at}");
                    marks.put(early, 9);
                    let want = if early == at { 9 } else { m };
                    assert_eq!(marks.last_in(pixels.clone()), Some(want), "{pixels:?}, marks at {early} and {at}");
                    // Marks outside the stretch are not its.
                    for out in [start.wrapping_sub(1), start + len] {
                        if out < 200 {
                            marks.put(out, 3);
                            assert_eq!(marks.last_in(pixels.clone()), Some(want), "{pixels:?}, a mark at {out}");
                            marks.clear(out);
                        }
                    }
                    marks.clear(at);
                    marks.clear(early);
                    assert!(marks.all_clear());
                }
            }
        }
    }

    #[test]
    fn borders_followed_on_the_shape_are_imageproc_s_on_a_mask() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut counts = [0usize; 2];
        // Noise of every density (islands, holes in holes, one-pixel shapes and lines),
        // touching the image's edges, on odd sizes.
        for case in 0..300 {
            let (w, h) = (rng.random_range(1..40), rng.random_range(1..30));
            let density = [0.1, 0.3, 0.5, 0.7, 0.9][case % 5];
            let shape: Vec<bool> = (0..w * h).map(|_| rng.random_bool(density)).collect();
            let labels: Vec<u32> = shape.iter().map(|&s| s as u32 * 3).collect();
            let pixels: Vec<u32> = (0..w * h).filter(|&i| shape[i]).map(|i| i as u32).collect();
            let mut marks = Marks::new();
            marks.cover(w * h);
            // Not empty: a border's range says where its pixels lie, whatever came before.
            let mut points = vec![Point::new(-1, -1)];
            let shape_3 = LabelMask { labels: &labels, width: w, height: h, label: 3 };
            let ours: Vec<Traced> = follow_borders(&shape_3, &pixels, &mut marks, &mut points)
                .into_iter()
                .map(|b| Traced { points: points[b.points].to_vec(), kind: b.kind, parent: b.parent })
                .collect();
            assert_eq!(ours, imageproc_borders(&shape, w, h), "case {case}: {w}x{h} at density {density}");
            assert!(marks.all_clear(), "case {case}: marks left behind");
            for b in &ours {
                counts[(b.kind == BorderKind::Hole) as usize] += 1;
            }
        }
        assert!(counts[0] > 1000 && counts[1] > 1000, "outer and hole borders both compared: {counts:?}");
    }

    #[test]
    fn simplifying_the_corners_is_simplifying_every_pixel() {
        // Borders of noise (many short stretches) and of polygons with long slanted edges
        // (long stretches, parallel to chords), at tolerances from under a pixel to many.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let (mut compared, mut fewer) = (0, 0);
        // Carried from border to border, as tracing carries it.
        let mut scratch = [Vec::new(), Vec::new()];
        for case in 0..400 {
            let (w, h) = (rng.random_range(3..60), rng.random_range(3..50));
            let shape: Vec<bool> = if case % 2 == 0 {
                (0..w * h).map(|_| rng.random_bool(0.6)).collect()
            } else {
                // Inside three random half-planes: a triangle-like blob with straight edges.
                let cuts: Vec<[f64; 3]> = (0..3)
                    .map(|_| {
                        let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                        [a.cos(), a.sin(), rng.random_range(0.0..0.4 * w.min(h) as f64)]
                    })
                    .collect();
                let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0);
                (0..w * h)
                    .map(|i| cuts.iter().all(|c| c[0] * ((i % w) as f64 - cx) + c[1] * ((i / w) as f64 - cy) < c[2]))
                    .collect()
            };
            for border in imageproc_borders(&shape, w, h) {
                for tolerance in [0.5, 1.0, 1.5, 3.0, 8.0] {
                    let every: Vec<[f32; 2]> = if border.points.len() > 3 {
                        approximate_polygon_dp(&border.points, tolerance, true)
                            .iter()
                            .map(|p| [p.x as f32, p.y as f32])
                            .collect()
                    } else {
                        border.points.iter().map(|p| [p.x as f32, p.y as f32]).collect()
                    };
                    assert_eq!(
                        simplify(&border.points, tolerance, &mut scratch),
                        every,
                        "case {case}, tolerance {tolerance}"
                    );
                    compared += 1;
                    corners_of(&border.points, &mut scratch[0]);
                    fewer += usize::from(scratch[0].len() * 2 < border.points.len());
                }
            }
        }
        assert!(
            compared > 2000 && fewer > 500,
            "{compared} borders compared, {fewer} with under half the points as corners"
        );
    }

    /// A region in two pieces (a speck cut off it first in scan order, a large part
    /// below) is outlined by the large part.
    #[test]
    fn a_region_in_pieces_is_outlined_by_its_largest() {
        let (w, h) = (30usize, 30usize);
        let inside = |u: usize, v: usize| {
            (2..4).contains(&u) && (1..3).contains(&v) || (5..25).contains(&u) && (8..28).contains(&v)
        };
        let labels: Vec<u32> = (0..w * h).map(|i| u32::from(inside(i % w, i / w))).collect();
        let pixels = vec![(0..w * h).filter(|&i| labels[i] == 1).map(|i| i as u32).collect()];
        let seg = Segmentation { labels: crate::extract::Grid { width: w, height: h, data: labels }, pixels };
        let outline = trace(&seg, 0.5, &[true]).remove(0);
        let (us, vs): (Vec<f32>, Vec<f32>) = outline.outer.iter().map(|&[u, v]| (u, v)).unzip();
        let extent =
            |c: &[f32]| (c.iter().copied().fold(f32::MAX, f32::min), c.iter().copied().fold(f32::MIN, f32::max));
        assert_eq!((extent(&us), extent(&vs)), ((4.5, 24.5), (7.5, 27.5)), "{:?}", outline.outer);
    }
}
