//! Joins and creases: regions of one plane that a row of dropouts cut apart are joined
//! (and the gaps between their pieces bridged), and which regions meet along a crease of
//! the surface is found for the polygons' trim.

use super::Segmentation;
use super::bounding_box;
use super::scan::{Columns, Meeting, labelled_before, row_meetings};
use crate::extract::cloud::Cloud;
use crate::extract::cpu::ransac::{PlaneFit, refit, support};
use crate::grid::for_each_set;

/// Two regions meet along a crease when at least this many rows and columns step from
/// one to the other: fewer is a corner touch or a stray pixel.
pub(super) const MIN_CREASE_STEPS: u32 = 3;
/// Unlabelled pixels a row or a column may cross from one region to a region it meets:
/// the band growth left between them (mixed pixels, a dropout).
pub(super) const MAX_CREASE_GAP_PX: usize = 4;

/// The pairs of regions `join_coplanar` considers: those that meet across at most
/// `JOIN_GAP_PX` unlabelled pixels with no depth step, with how many times a row or a
/// column steps between them (labels a < b, sorted). Found on the labels and the depth
/// alone (`Segmentation::join_candidates`), so before the fits and beside them; a leak
/// split after that changes the labels (`Leaks::split`), and they must be found again.
pub struct JoinCandidates {
    steps: Vec<((u32, u32), u32)>,
}

/// Which regions meet along a crease of the surface: where a row or a column steps from
/// one region to the other (across at most `MAX_CREASE_GAP_PX` unlabelled pixels) with no
/// depth step on the way between the two pixels. Regions side by side across a depth step
/// (a box's top before the floor behind it) or apart in the image do not meet.
pub struct Creases {
    /// (a, b) with a < b (labels), and the number of steps between them; sorted.
    steps: Vec<((u32, u32), u32)>,
}

impl Creases {
    /// Whether the regions labelled `a` and `b` meet.
    pub fn meet(&self, a: u32, b: u32) -> bool {
        let key = (a.min(b), a.max(b));
        self.steps.binary_search_by_key(&key, |&(k, _)| k).is_ok_and(|i| self.steps[i].1 >= MIN_CREASE_STEPS)
    }
}

impl Segmentation {
    /// The creases between regions; `ratio` is the depth step, relative to the depth, that
    /// parts two neighbouring pixels (as the boundary map's, per pixel of distance).
    pub fn creases(&self, cloud: &Cloud, ratio: f32) -> Creases {
        Creases { steps: self.steps_between(cloud, ratio, MAX_CREASE_GAP_PX) }
    }

    /// The pairs of regions that may join (`JoinCandidates`); `ratio` as for `creases`.
    pub fn join_candidates(&self, cloud: &Cloud, ratio: f32) -> JoinCandidates {
        JoinCandidates { steps: self.steps_between(cloud, ratio, JOIN_GAP_PX) }
    }

    /// Joins regions of one plane that something cut apart: a row of sensor dropouts
    /// across a thin strip (a tread cut by the image's bottom edge leaves a strip a few
    /// pixels tall, and every dropout's spoiled square of normals cuts it through), into
    /// pieces each too small to keep. Two regions join when they touch across at most
    /// `JOIN_GAP_PX` with no depth step (`candidates`, found on the labels as they are
    /// now), their planes are within `JOIN_ANGLE_COS` or the smaller piece lies on the
    /// larger one's plane (as for the union below), and their union is still one plane:
    /// refitted, at least `min_ratio` of each one's points within `dist` of it. The region
    /// joined into keeps the lower index; the other is left empty, its fit None. Returns
    /// how many joins were made.
    pub fn join_coplanar(
        &mut self,
        candidates: JoinCandidates,
        fits: &mut [Option<PlaneFit>],
        cloud: &Cloud,
        dist: f32,
        min_ratio: f64,
    ) -> usize {
        // Enough of a piece's points on a plane to call the piece part of it.
        let enough = |points: usize| (min_ratio * points as f64).ceil() as usize;
        let mut joins = 0;
        let mut joined_into = vec![false; self.pixels.len()];
        // Where each region went: itself, or the region it was joined into (a chain).
        let mut now_in: Vec<usize> = (0..self.pixels.len()).collect();
        let find = |now_in: &[usize], mut r: usize| {
            while now_in[r] != r {
                r = now_in[r];
            }
            r
        };
        for ((a, b), n) in candidates.steps {
            // A pair met before one of its regions was joined away is a pair of what they
            // are now part of: a strip cut into pieces A B C joins A+B, then (A+B)+C.
            let (a, b) = (find(&now_in, a as usize - 1), find(&now_in, b as usize - 1));
            let (a, b) = (a.min(b), a.max(b));
            let (Some(fa), Some(fb)) = (fits[a], fits[b]) else { continue };
            if a == b || n < MIN_CREASE_STEPS {
                continue;
            }
            let on = |fit: &PlaneFit, pts: &[[f32; 3]]| support(pts, fit.normal.into(), fit.offset, dist as f64).0;
            let (start, smaller) = if fa.points >= fb.points { (fa, b) } else { (fb, a) };
            // Planes apart, unless the smaller piece lies on the larger one's plane: a strip
            // a few pixels wide (between the stripes of a structured-light scanner, say)
            // has a plane of its own that says little. A sample of it tells.
            if fa.normal.dot(&fb.normal) < JOIN_ANGLE_COS {
                let small = self.sampled_points(&[smaller], cloud, JOIN_SAMPLE_POINTS).points;
                if on(&start, &small) < enough(small.len()) {
                    continue;
                }
            }
            let both = self.points(&[a, b], cloud);
            let (na, pts) = (both.ranges[0].len(), both.points);
            let Some(joined) = refit(&pts, start.normal_f32(), start.offset as f32, dist) else { continue };
            // Each piece on the joined plane, not just their sum: a large region would
            // otherwise swallow a small piece of a neighbouring surface within its outliers.
            if on(&joined, &pts[..na]) < enough(na) || on(&joined, &pts[na..]) < enough(pts.len() - na) {
                continue;
            }
            let moved = std::mem::take(&mut self.pixels[b]);
            for &i in &moved {
                self.labels.data[i as usize] = a as u32 + 1;
            }
            let before = self.pixels[a].len();
            self.pixels[a].extend(moved);
            merge_tail(&mut self.pixels[a], before);
            (fits[a], fits[b]) = (Some(joined), None);
            now_in[b] = a;
            joined_into[a] = true;
            joins += 1;
        }
        if joins > 0 {
            self.bridge(&joined_into, fits, cloud, dist);
        }
        joins
    }

    /// Fills the gaps (at most `JOIN_GAP_PX`, along rows and columns) between two pixels
    /// of one region marked in `regions`, where every pixel of the gap is a dropout or lies
    /// on the region's plane: the pieces a join united become one connected region (an
    /// outline is traced around one connected region).
    pub(super) fn bridge(&mut self, regions: &[bool], fits: &[Option<PlaneFit>], cloud: &Cloud, dist: f32) {
        let w = self.labels.width;
        let labels = &self.labels.data;
        // Each united region is scanned once, inside its bounding box only (a gap between two
        // of its pixels lies there), row by row; columns keep their last labelled pixel
        // each, so they too are read along the rows.
        let united: Vec<(u32, &PlaneFit, [usize; 4])> = (0..regions.len())
            .filter(|&r| regions[r] && !self.pixels[r].is_empty())
            .filter_map(|r| Some((r as u32 + 1, fits[r].as_ref()?, bounding_box(&self.pixels[r], w))))
            .collect();
        // The pixels strictly between the labelled t0 and t of a line (pixel `at(t)`),
        // both of `label` with nothing labelled between: filled if a short gap on the plane.
        let gap =
            |fills: &mut Vec<(u32, u32)>, t0: usize, t: usize, at: &dyn Fn(usize) -> usize, label, fit: &PlaneFit| {
                if t - t0 > 1 && t - t0 <= JOIN_GAP_PX + 1 {
                    let on_plane = |t: usize| cloud.point(at(t)).is_none_or(|p| fit.distance(&p) < dist as f64);
                    if (t0 + 1..t).all(on_plane) {
                        fills.extend((t0 + 1..t).map(|t| (at(t) as u32, label)));
                    }
                }
            };
        let (mut row_fills, mut column_fills) = (Vec::new(), Vec::new());
        for &(label, fit, [u0, v0, u1, v1]) in &united {
            let meeting = Meeting::SameLabelAcrossGap(label);
            let mut columns = Columns::new(u1 - u0 + 1);
            for v in v0..=v1 {
                let row = &labels[v * w + u0..=v * w + u1];
                // Back along the row from a pixel of the region after a gap, to the last
                // labelled pixel in the box.
                row_meetings(row, meeting, &mut columns.found);
                for_each_set(&columns.found, |k| {
                    if let Some(t0) = labelled_before(row, k, JOIN_GAP_PX + 1).filter(|&t0| row[t0] == label) {
                        gap(&mut row_fills, u0 + t0, u0 + k, &|t| v * w + t, label, fit);
                    }
                });
                columns.down(row, v, JOIN_GAP_PX + 1, meeting);
                for_each_set(&columns.found, |k| {
                    gap(&mut column_fills, columns.from[k] as usize, v, &|t| t * w + u0 + k, label, fit);
                });
            }
        }
        // Rows' fills first: where a gap is both, the row's fill is the one kept.
        let before: Vec<usize> = self.pixels.iter().map(Vec::len).collect();
        for (i, l) in row_fills.into_iter().chain(column_fills) {
            if self.labels.data[i as usize] == 0 {
                self.labels.data[i as usize] = l;
                self.pixels[l as usize - 1].push(i);
            }
        }
        for (p, before) in self.pixels.iter_mut().zip(before) {
            merge_tail(p, before);
        }
    }
}

/// Sorts a list whose first `sorted` entries ascend and whose tail (appended after them,
/// in any order, none equal to an entry before) is short or ascends too: the tail is
/// sorted, then merged in from the back, in place. A full sort found the two runs and
/// merged them too, through a buffer of half the list.
pub(super) fn merge_tail(list: &mut Vec<u32>, sorted: usize) {
    let mut tail = list.split_off(sorted);
    if tail.is_empty() {
        return;
    }
    tail.sort_unstable();
    let (mut a, mut b) = (list.len(), tail.len());
    list.resize(a + b, 0);
    while b > 0 {
        if a > 0 && list[a - 1] > tail[b - 1] {
            list[a + b - 1] = list[a - 1];
            a -= 1;
        } else {
            list[a + b - 1] = tail[b - 1];
            b -= 1;
        }
    }
}

/// Regions of one plane cut apart by at most this many pixels are joined (a dropout's
/// spoiled square of normals, sealed by the closing: up to the normal kernel plus the
/// closing's side, 5 + 7 px at the defaults).
pub(super) const JOIN_GAP_PX: usize = 12;
/// Planes of regions that may join are within this (cos of 10 deg). Loose on purpose: the
/// pieces of a strip ten rows tall are fitted on a few rows each, and tilt by up to 7 deg
/// (the nearest tread of mock_frames/straight_320 frame 26); the refit of their union,
/// which each piece must lie on, is what decides.
pub(super) const JOIN_ANGLE_COS: f64 = 0.985;
/// Where two pieces' planes are further apart than `JOIN_ANGLE_COS`, this many of the
/// smaller piece's points (every k-th pixel's) are checked on the larger one's plane
/// before their union is fitted: a riser's piece fails there, cheaply.
const JOIN_SAMPLE_POINTS: usize = 256;
