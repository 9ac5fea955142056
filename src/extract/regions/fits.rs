//! The points of regions for the plane fits (all, or every k-th), and the sample of them
//! the polygon checks read.

use rayon::prelude::*;

use super::Segmentation;
use crate::extract::cloud::Cloud;
use crate::extract::cpu;
use crate::extract::cpu::ransac::PlaneFit;
use crate::extract::cpu::ransac::{PointBatch, for_each_strided, sample_stride};
use crate::grid::runs;

/// Every `stride`-th of a region's valid points, in scan order, each standing for
/// `stride` of them: what the polygon checks read (a plane's covariance and its halves, a
/// cut's strays). A region's pixels lie on a regular grid, so every k-th point's sums are
/// those of all of them, times k, to well under a percent.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointSample {
    pub points: Vec<[f32; 3]>,
    pub stride: usize,
}

/// At most about this many of a region's points are sampled (`PointSample`): a floor at
/// 640x480 has a hundred thousand, and the checks cost the same for any size.
pub const MAX_SAMPLE_POINTS: usize = 2048;

impl PointSample {
    /// Every stride-th of `points`, the stride the smallest that keeps them to `max`.
    pub fn of(points: &[[f32; 3]], max: usize) -> PointSample {
        PointSample::of_parts(std::slice::from_ref(&points), max)
    }

    /// `of` the points of these parts, one after another.
    pub fn of_parts<P: AsRef<[[f32; 3]]>>(parts: &[P], max: usize) -> PointSample {
        let len = parts.iter().map(|part| part.as_ref().len()).sum();
        let stride = sample_stride(len, max);
        let mut sample = Vec::with_capacity(len.div_ceil(stride));
        // The index of each part's first point among all of them.
        let mut start = 0;
        for part in parts {
            let part = part.as_ref();
            // The part's first point taken: the first whose index is a multiple of the stride.
            let skip = (stride - start % stride) % stride;
            for_each_strided(part.get(skip..).unwrap_or_default(), stride, |p| sample.push(*p));
            start += part.len();
        }
        PointSample { points: sample, stride }
    }
}

impl Segmentation {
    /// Camera-frame points (raw depth, valid pixels only) of the given regions, in that order.
    pub fn points(&self, regions: &[usize], cloud: &Cloud) -> PointBatch {
        self.sampled_points(regions, cloud, usize::MAX)
    }

    /// `points` of every stride-th pixel of a region of more than `max` pixels, the stride
    /// the smallest that keeps it to `max`: its pixels lie on a regular grid, so the plane
    /// through those points is the plane through all of them, to well under a percent of
    /// its noise.
    pub fn sampled_points(&self, regions: &[usize], cloud: &Cloud, max: usize) -> PointBatch {
        let stride = |r: usize| sample_stride(self.pixels[r].len(), max);
        let total = regions.iter().map(|&r| self.pixels[r].len().div_ceil(stride(r))).sum();
        let mut batch = PointBatch { points: Vec::with_capacity(total), ranges: Vec::with_capacity(regions.len()) };
        for &r in regions {
            let (start, stride) = (batch.points.len(), stride(r));
            if stride == 1 {
                self.extend_points(r, cloud, &mut batch.points);
            } else {
                for_each_strided(&self.pixels[r], stride, |&i| batch.points.extend(cloud.point(i as usize)));
            }
            batch.ranges.push(start..batch.points.len());
        }
        batch
    }

    /// `points_of` region r in parts, the points of `part_pixels` of its pixels each,
    /// gathered in parallel tasks.
    pub fn point_parts(&self, r: usize, cloud: &Cloud, part_pixels: usize) -> Vec<Vec<[f32; 3]>> {
        if self.pixels[r].len() <= part_pixels {
            vec![self.points_of(r, cloud)]
        } else {
            self.pixels[r].par_chunks(part_pixels).map(|pixels| points_of_pixels(pixels, cloud)).collect()
        }
    }

    /// Camera-frame points (raw depth, valid pixels only) of region r.
    pub fn points_of(&self, r: usize, cloud: &Cloud) -> Vec<[f32; 3]> {
        points_of_pixels(&self.pixels[r], cloud)
    }

    /// Appends the points of region r's valid pixels, run by run.
    pub(super) fn extend_points(&self, r: usize, cloud: &Cloud, out: &mut Vec<[f32; 3]>) {
        extend_points_of(&self.pixels[r], cloud, out);
    }
}

/// The points of the valid pixels among `pixels` (ascending), run by run.
pub(super) fn points_of_pixels(pixels: &[u32], cloud: &Cloud) -> Vec<[f32; 3]> {
    let mut points = Vec::with_capacity(pixels.len());
    extend_points_of(pixels, cloud, &mut points);
    points
}

crate::extract::cpu::widest_simd! {
    /// Appends the points of the valid pixels among `pixels` (ascending), run by run.
    pub(super) fn extend_points_of(pixels: &[u32], cloud: &Cloud, out: &mut Vec<[f32; 3]>) = extend_points_portable
}

/// `extend_points_of` at any vector width: a run's points are written whole (`Cloud::extend_valid`).
#[inline(always)]
fn extend_points_portable(pixels: &[u32], cloud: &Cloud, out: &mut Vec<[f32; 3]>) {
    for run in runs(pixels, cloud.width) {
        cloud.extend_valid(run.first..run.last + 1, out);
    }
}

/// At most about this many of a region's points (every k-th pixel's) are fitted before
/// growth: those fits only steer the leak splits, the joins and the growth, and each plane
/// kept is fitted again on every pixel of its grown region (`refit_grown`); RANSAC scores
/// on 2048 of them (`MAX_SCORE_POINTS`). A floor at 640x480 has a hundred thousand pixels,
/// gathered and read twice by the refit for nothing.
pub(super) const MAX_FIT_POINTS: usize = 8192;

/// The refit after growth takes the points within this many of the first fit's RMS of its
/// plane (at most the inlier distance, at least `MIN_REFIT_BAND_SHARE` of it). Growth
/// hands a region every border pixel within the inlier distance of its plane, and those
/// include the first centimetre of the walls and risers it meets, all on one side of the
/// plane: fitted with them, a whole tread tilted by a third of a degree.
const REFIT_BAND_RMS: f32 = 3.0;
const MIN_REFIT_BAND_SHARE: f32 = 0.1;

/// A grown region of more pixels than this is refitted in parts of this many, a task
/// each (`refit_parts`): the floor of a 640x480 frame, a hundred thousand pixels, is
/// seven.
pub(super) const REFIT_PART_PIXELS: usize = 16384;

/// Fits each accepted region's plane again on its grown pixels, and hands back a sample
/// of those pixels' points for the polygon checks (none for the other regions). Growth
/// gives a region back the band along its border that edges and closing ate; for a thin
/// strip (a tread cut by the image's edge, ten rows tall) that band doubles its support
/// across, and the plane fitted without it can be tilted by a degree.
pub(super) fn refit_grown(
    seg: &Segmentation,
    fits: &mut [Option<PlaneFit>],
    accepted: &[bool],
    cloud: &Cloud,
    dist: f32,
    min_ratio: f64,
) -> Vec<PointSample> {
    use rayon::prelude::*;
    let refits: Vec<(Option<PlaneFit>, PointSample)> = (0..fits.len())
        .into_par_iter()
        .map(|r| {
            let Some(f) = fits[r].filter(|_| accepted[r]) else { return (None, PointSample::default()) };
            let parts = seg.point_parts(r, cloud, REFIT_PART_PIXELS);
            let band = (REFIT_BAND_RMS * f.rms as f32).clamp(dist * MIN_REFIT_BAND_SHARE, dist);
            let refit = cpu::ransac::refit_parts(&parts, f.normal_f32(), f.offset as f32, band);
            (refit, PointSample::of_parts(&parts, MAX_SAMPLE_POINTS))
        })
        .collect();
    refits
        .into_iter()
        .zip(fits.iter_mut())
        .map(|((new, points), fit)| {
            if let Some(new) = new.filter(|f| f.inlier_ratio() >= min_ratio) {
                *fit = Some(new);
            }
            points
        })
        .collect()
}
