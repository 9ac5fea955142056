//! Scans along the rows and down the columns for where one region meets another (or
//! itself across a gap): what the creases, the join candidates and the joins' bridges read.

use rayon::prelude::*;

use super::{MIN_BLOCK_ROWS, Segmentation};
use crate::extract::cloud::Cloud;
use crate::grid::for_each_set;

impl Segmentation {
    /// For each pair of regions (labels a < b, sorted), how many times a row or a column
    /// steps from one to the other across at most `max_gap` unlabelled pixels with no depth
    /// step (`ratio`, `no_depth_step`) on the way between the two pixels.
    ///
    /// Along a row, from each pixel where a region starts back to the nearest labelled one.
    /// Up the columns, from each labelled pixel to the last labelled one above it: each
    /// column's last label and its row are kept as the rows go down (`Columns`), so
    /// no column is walked up pixel by pixel (a cache line a pixel).
    pub(super) fn steps_between(&self, cloud: &Cloud, ratio: f32, max_gap: usize) -> Vec<((u32, u32), u32)> {
        let (w, h) = (self.labels.width, self.labels.height);
        let l = &self.labels.data;
        // From labelled pixel i to labelled pixel j, `px` pixels apart (a pixel apart, `stride`
        // in the image), nothing labelled between.
        let step = |steps: &mut Vec<((u32, u32), u32)>, i: usize, j: usize, px: usize, stride: usize| {
            let (a, b) = (l[i], l[j]);
            if a != b && no_depth_step(cloud, i, px, stride, ratio) {
                // Counted as they come where the pair repeats (along a border it mostly
                // does): far fewer entries to sort.
                let pair = (a.min(b), a.max(b));
                match steps.last_mut() {
                    Some((p, n)) if *p == pair => *n += 1,
                    _ => steps.push((pair, 1)),
                }
            }
        };
        // Rows in blocks side by side, each with its own list (the counts are summed below
        // whatever order they come in) and its own columns, which a block that starts below
        // the top first reads down from max_gap + 1 rows above its first row.
        let mut steps: Vec<((u32, u32), u32)> = (0..h)
            .into_par_iter()
            .with_min_len(MIN_BLOCK_ROWS)
            .fold(
                || (Vec::new(), Columns::new(w), None),
                |(mut steps, mut columns, next_row): (Vec<_>, Columns, Option<usize>), v| {
                    if next_row != Some(v) {
                        columns = Columns::new(w);
                        for above in v.saturating_sub(max_gap + 1)..v {
                            columns.down(&l[above * w..(above + 1) * w], above, max_gap + 1, Meeting::OtherLabel);
                        }
                    }
                    let row = &l[v * w..(v + 1) * w];
                    row_meetings(row, Meeting::OtherLabel, &mut columns.found);
                    for_each_set(&columns.found, |u| {
                        if let Some(t) = labelled_before(row, u, max_gap + 1) {
                            step(&mut steps, v * w + t, v * w + u, u - t, 1);
                        }
                    });
                    columns.down(row, v, max_gap + 1, Meeting::OtherLabel);
                    for_each_set(&columns.found, |u| {
                        let from = columns.from[u] as usize;
                        step(&mut steps, from * w + u, v * w + u, v - from, w);
                    });
                    (steps, columns, Some(v + 1))
                },
            )
            .map(|(steps, _, _)| steps)
            .reduce(Vec::new, |mut a, b| {
                a.extend(b);
                a
            });
        steps.sort_unstable();
        let mut counted: Vec<((u32, u32), u32)> = Vec::new();
        for (pair, k) in steps {
            match counted.last_mut() {
                Some((p, n)) if *p == pair => *n += k,
                _ => counted.push((pair, k)),
            }
        }
        counted
    }
}

/// Whether the line of pixels from `start` (`px` steps of `stride` to its end) holds no
/// depth step: each pixel with a depth within `ratio` of the depth of the last one before
/// it that has one, per pixel between them. Stepwise, not end to end: across a gap of
/// unlabelled pixels the ends' allowance would grow with the gap, and where the focal
/// length is long (ABW's 1,600-2,300 px) four pixels' worth passes an occluding face's
/// edge 4 cm in front of the face behind it as a crease.
fn no_depth_step(cloud: &Cloud, start: usize, px: usize, stride: usize, ratio: f32) -> bool {
    let (mut last, mut last_at) = (cloud.depth(start), 0);
    if last <= 0.0 {
        return false;
    }
    for k in 1..=px {
        let z = cloud.depth(start + k * stride);
        if z > 0.0 {
            if (z - last).abs() > ratio * (k - last_at) as f32 * z.min(last) {
                return false;
            }
            (last, last_at) = (z, k);
        }
    }
    last_at == px
}

/// How a labelled pixel meets the last labelled pixel before it along its row or up its
/// column, that a scan looks for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Meeting {
    /// A pixel of another label: where a row or a column steps from one region to another
    /// (the creases' and joins' scan).
    OtherLabel,
    /// A pixel of the same label, this one, across a gap (the joins' bridges).
    SameLabelAcrossGap(u32),
}

impl Meeting {
    /// As the row loops take it: 0 for `OtherLabel` (no region is labelled 0).
    pub(super) fn same_label(self) -> u32 {
        match self {
            Meeting::OtherLabel => 0,
            Meeting::SameLabelAcrossGap(label) => label,
        }
    }
}

/// 1 in `out` where a pixel of `row` is one `meeting` looks for whose left neighbour is of
/// another label or none (`OtherLabel`; 0 for a row's first pixel), or is none
/// (`SameLabelAcrossGap`): where the walk back along the row to the last labelled pixel
/// starts.
pub(super) fn row_meetings(row: &[u32], meeting: Meeting, out: &mut [u8]) {
    row_meetings_rows(row, meeting.same_label(), out);
}

crate::extract::cpu::widest_simd! {
    /// `row_meetings` on a plain label.
    pub(super) fn row_meetings_rows(row: &[u32], same: u32, out: &mut [u8]) = row_meetings_portable
}

/// Whole rows at a time, as `join_links_portable`.
#[inline(always)]
fn row_meetings_portable(row: &[u32], same: u32, out: &mut [u8]) {
    let out = &mut out[..row.len()];
    let Some(first) = out.first_mut() else { return };
    *first = 0;
    for ((o, &x), &left) in out[1..].iter_mut().zip(&row[1..]).zip(row) {
        *o = if same == 0 { u8::from((x != 0) & (x != left)) } else { u8::from((x == same) & (left == 0)) };
    }
}

/// The last labelled pixel of `row` before pixel k, at most `reach` pixels back.
pub(super) fn labelled_before(row: &[u32], k: usize, reach: usize) -> Option<usize> {
    (1..=k.min(reach)).map(|d| k - d).find(|&t| row[t] != 0)
}

/// What a scan down the rows keeps of the columns: each column's last label (0: none yet)
/// and the row it was in, and for the row just read, where its pixel meets the last
/// labelled pixel above it as the scan looks for (`found`) and that pixel's row (`from`).
pub(super) struct Columns {
    last_label: Vec<u32>,
    last_row: Vec<u32>,
    pub(super) from: Vec<u32>,
    pub(super) found: Vec<u8>,
}

impl Columns {
    pub(super) fn new(w: usize) -> Columns {
        Columns { last_label: vec![0; w], last_row: vec![0; w], from: vec![0; w], found: vec![0; w] }
    }

    /// Row v (`row`) down the columns: `found` where a labelled pixel meets the last
    /// labelled pixel above it, at most `reach` rows up, as `meeting` says (across a gap:
    /// two rows up or more); then the columns' last labels are the row's where it has one.
    pub(super) fn down(&mut self, row: &[u32], v: usize, reach: usize, meeting: Meeting) {
        column_meetings(row, v as u32, reach as u32, meeting.same_label(), self);
    }
}

crate::extract::cpu::widest_simd! {
    /// `Columns::down` on a plain label.
    pub(super) fn column_meetings(row: &[u32], v: u32, reach: u32, same: u32, columns: &mut Columns) = column_meetings_portable
}

/// Whole rows at a time, comparisons combined with `&`: the loop vectorises.
#[inline(always)]
fn column_meetings_portable(row: &[u32], v: u32, reach: u32, same: u32, columns: &mut Columns) {
    let Columns { last_label, last_row, from, found } = columns;
    let w = row.len();
    let (last_label, last_row, from, found) =
        (&mut last_label[..w], &mut last_row[..w], &mut from[..w], &mut found[..w]);
    for u in 0..w {
        let (x, above, at) = (row[u], last_label[u], last_row[u]);
        // `at` is a row above v wherever `above` is a label.
        let up = v.wrapping_sub(at);
        let near = (x != 0) & (above != 0) & (up <= reach);
        found[u] = if same == 0 {
            u8::from(near & (x != above))
        } else {
            u8::from(near & (x == same) & (above == same) & (up >= 2))
        };
        from[u] = at;
        last_label[u] = if x != 0 { x } else { above };
        last_row[u] = if x != 0 { v } else { at };
    }
}
