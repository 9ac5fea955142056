//! Label runs to pixel lists and label images, written in parallel: how regions are
//! numbered from components and how their lists are rebuilt after growth.

use std::mem::MaybeUninit;
use std::ops::Range;

use rayon::prelude::*;

use super::Segmentation;
use crate::grid::first_other;

impl Segmentation {
    /// Rebuilds every region's pixel list from the labels, ascending by construction
    /// (cheaper than appending each wave of growth and sorting): the label runs found in
    /// bands of rows, the lists written from them, both in parallel. On one thread, one
    /// pass that writes each run as it finds it (`push_pixels`: two passes cost more there).
    pub(super) fn pixels_from_labels(&mut self) {
        if rayon::current_num_threads() == 1 {
            self.pixels.iter_mut().for_each(Vec::clear);
            push_pixels(&self.labels.data, &mut self.pixels);
            return;
        }
        write_runs(&par_label_runs(&self.labels.data, self.labels.width), &mut self.pixels, None);
    }
}

/// Appends every labelled pixel's index to its region's list (label l: region l - 1),
/// ascending, a run of one label at a time: labels come in long runs along the rows, and
/// a run is one contiguous extend where pixel by pixel each push reloaded its list.
pub(super) fn push_pixels(labels: &[u32], pixels: &mut [Vec<u32>]) {
    for (range, l) in label_runs(labels) {
        pixels[l as usize - 1].extend(range.start as u32..range.end as u32);
    }
}

/// `label_runs` of a `width`-wide image, found in bands of rows in parallel (a run across
/// a band's edge comes as two, each band's runs in order).
pub(super) fn par_label_runs(labels: &[u32], width: usize) -> Vec<(Range<usize>, u32)> {
    let band = RUN_BAND_ROWS * width.max(1);
    (labels.par_chunks(band).enumerate())
        .flat_map_iter(|(b, labels)| label_runs(labels).map(move |(r, l)| (b * band + r.start..b * band + r.end, l)))
        .collect()
}

/// Rows of a band in which `par_label_runs` finds label runs as one task.
pub(super) const RUN_BAND_ROWS: usize = 32;
/// The fewest pixels of the image a task of `write_runs` covers.
pub(super) const MIN_WRITE_PIXELS: usize = 16 * 1024;

/// Writes each region's pixel list (region l - 1: the pixels of the runs of value l; runs
/// of value 0 are in none), ascending, and with `labels` the label image (each run's
/// value, 0 between runs), from `runs`: ascending, disjoint pixel ranges. In parallel:
/// the runs are cut into tasks of about equal stretches of the image, which count each
/// region's pixels in their runs, and then each writes its own stretch of each list (the
/// stretches in task order) and of the labels. Written by one thread, after the parallel
/// stages before them, the lists and labels were the largest serial step of a frame on
/// many cores (their scan read labels from other cores' caches).
pub(super) fn write_runs(
    runs: &[(Range<usize>, u32)],
    pixels: &mut [Vec<u32>],
    labels: Option<&mut [MaybeUninit<u32>]>,
) {
    let n = labels.as_ref().map_or_else(|| runs.last().map_or(0, |(r, _)| r.end), |l| l.len());
    let tasks = n.div_ceil(MIN_WRITE_PIXELS).clamp(1, 4 * rayon::current_num_threads());
    // Task k takes the runs starting in its k-th of the image, and the labels from its
    // first run's start (the image's for the first task) to the next task's.
    let firsts: Vec<usize> = (0..=tasks).map(|k| runs.partition_point(|(r, _)| r.start < k * n / tasks)).collect();
    let mut bounds: Vec<usize> = firsts.iter().map(|&f| runs.get(f).map_or(n, |(r, _)| r.start)).collect();
    bounds[0] = 0;
    let task_runs: Vec<&[(Range<usize>, u32)]> = firsts.windows(2).map(|f| &runs[f[0]..f[1]]).collect();
    let counts: Vec<Vec<usize>> = (task_runs.par_iter())
        .map(|runs| {
            let mut counts = vec![0; pixels.len()];
            for (range, l) in runs.iter().filter(|(_, l)| *l != 0) {
                counts[*l as usize - 1] += range.len();
            }
            counts
        })
        .collect();
    let lengths: Vec<usize> = (0..pixels.len()).map(|r| counts.iter().map(|c| c[r]).sum()).collect();
    for (list, &len) in pixels.iter_mut().zip(&lengths) {
        list.clear();
        list.reserve(len);
    }
    // Each task's stretch of each list, cut off the lists' fronts in task order, and of the labels.
    let mut rests: Vec<&mut [MaybeUninit<u32>]> = pixels.iter_mut().map(Vec::spare_capacity_mut).collect();
    let stretches: Vec<Vec<&mut [MaybeUninit<u32>]>> = (counts.iter())
        .map(|counts| rests.iter_mut().zip(counts).map(|(rest, &len)| cut_front(rest, len)).collect())
        .collect();
    let mut labels_left = labels;
    let label_stretches: Vec<Option<&mut [MaybeUninit<u32>]>> =
        (bounds.windows(2)).map(|b| labels_left.as_mut().map(|rest| cut_front(rest, b[1] - b[0]))).collect();
    let work = task_runs.into_par_iter().zip(stretches).zip(label_stretches).zip(bounds.par_windows(2));
    work.for_each(|(((runs, mut lists), labels), bounds)| {
        let mut filled = vec![0; lists.len()];
        for (range, l) in runs.iter().filter(|(_, l)| *l != 0) {
            let (r, start) = (*l as usize - 1, range.start as u32);
            let out = &mut lists[r][filled[r]..filled[r] + range.len()];
            out.iter_mut().enumerate().for_each(|(k, o)| *o = MaybeUninit::new(start + k as u32));
            filled[r] += range.len();
        }
        if let Some(labels) = labels {
            // Offsets into this task's stretch of the labels, which starts at bounds[0].
            let (mut at, base) = (0, bounds[0]);
            for (range, l) in runs {
                labels[at..range.start - base].fill(MaybeUninit::new(0));
                labels[range.start - base..range.end - base].fill(MaybeUninit::new(*l));
                at = range.end - base;
            }
            labels[at..].fill(MaybeUninit::new(0));
        }
    });
    for (list, len) in pixels.iter_mut().zip(lengths) {
        // SAFETY: the tasks' stretches, each filled by its task's runs, cover the first len.
        unsafe { list.set_len(len) };
    }
}

/// The first `len` values of `rest`, which keeps the others.
pub(super) fn cut_front<'a, T>(rest: &mut &'a mut [T], len: usize) -> &'a mut [T] {
    let (front, back) = std::mem::take(rest).split_at_mut(len);
    *rest = back;
    front
}

/// The stretches of one non-zero label in a label image, in order, with their label.
pub(super) fn label_runs(labels: &[u32]) -> impl Iterator<Item = (Range<usize>, u32)> + '_ {
    let mut i = 0;
    std::iter::from_fn(move || {
        i += first_other(labels.get(i..)?, 0)?;
        let l = labels[i];
        let end = i + first_other(&labels[i..], l).unwrap_or(labels.len() - i);
        let range = i..end;
        i = end;
        Some((range, l))
    })
}
