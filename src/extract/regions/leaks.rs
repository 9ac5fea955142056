//! Leak splits: a region whose plane fits too few of its points (a Canny line broken by a
//! dropout let two surfaces leak into one) keeps the largest connected patch of that
//! plane's inliers; the rest becomes new regions, fitted again. A region whose plane fits
//! enough of its points still gives up each large connected piece of its outliers: a
//! second face it took in across a crease whose edge broke, too small a share of it to
//! fail the ratio (a 35 deg side face, half of it within the inlier distance of the top's
//! plane).

use super::Segmentation;
use crate::extract::cloud::Cloud;
use crate::extract::cpu::ransac::{PlaneFit, refit};
use crate::grid::flood;

/// The label of a leaking region's pixels between its split and their regrouping.
pub(super) const RELEASED: u32 = u32::MAX;

/// What `split_leaks` did: the regions it cut (their labels changed), and the new regions
/// made of what it cut off that is large enough (ascending).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Leaks {
    pub split: Vec<usize>,
    pub pieces: Vec<usize>,
}

impl Segmentation {
    /// Splits every region whose fit has an inlier ratio under `min_ratio`: it keeps the
    /// largest 8-connected patch of its plane's inliers, refitted; the other connected
    /// pieces of at least `min_pixels` become new regions (their fits None). Every other
    /// region with a fit gives up the 8-connected pieces of its outliers of at least
    /// `min_pixels` as new regions (`cut_outliers`).
    pub fn split_leaks(
        &mut self,
        fits: &mut Vec<Option<PlaneFit>>,
        cloud: &Cloud,
        dist: f32,
        min_ratio: f64,
        min_pixels: usize,
    ) -> Leaks {
        let (w, h) = (self.labels.width, self.labels.height);
        let mut leaks = Leaks::default();
        // Pixels flooded so far; a flood stays inside one region's pixels, which are
        // unmarked again after each use (a whole image cleared per region cost more).
        let mut seen = vec![false; w * h];
        for r in 0..self.pixels.len() {
            let Some(fit) = fits[r] else { continue };
            if fit.inlier_ratio() >= min_ratio {
                // Too few outliers, by the fit's count, to make a piece worth a region.
                if (1.0 - fit.inlier_ratio()) * (self.pixels[r].len() as f64) < min_pixels as f64 {
                    continue;
                }
                let cut = self.cut_outliers(r, &fit, cloud, dist, min_pixels, &mut seen);
                if !cut.is_empty() {
                    leaks.split.push(r);
                    leaks.pieces.extend(cut);
                    fits.resize(self.pixels.len(), None);
                }
                continue;
            }
            leaks.split.push(r);
            let label = r as u32 + 1;
            let inlier = |i: usize| {
                self.labels.data[i] == label && cloud.point(i).is_some_and(|p| fit.distance(&p) < dist as f64)
            };
            let mut best: Vec<u32> = Vec::new();
            for &i in &self.pixels[r] {
                if !seen[i as usize] && inlier(i as usize) {
                    let comp = flood(i as usize, w, h, &mut seen, inlier);
                    if comp.len() > best.len() {
                        best = comp;
                    }
                }
            }
            // Everything else in the region is released (marked so, for the floods of its
            // pieces), then its pieces regrouped.
            let old = std::mem::take(&mut self.pixels[r]);
            for &i in &old {
                self.labels.data[i as usize] = RELEASED;
            }
            for &i in &best {
                self.labels.data[i as usize] = label;
            }
            // In ascending order as the region's pixels were: no sort.
            self.pixels[r] = old.iter().copied().filter(|&i| self.labels.data[i as usize] == label).collect();
            fits[r] = refit(&self.points_of(r, cloud), fit.normal_f32(), fit.offset as f32, dist);
            old.iter().for_each(|&i| seen[i as usize] = false);
            for &i in &old {
                let i = i as usize;
                if self.labels.data[i] == RELEASED && !seen[i] {
                    let piece = flood(i, w, h, &mut seen, |j| self.labels.data[j] == RELEASED);
                    if piece.len() >= min_pixels {
                        leaks.pieces.push(self.push(piece));
                        fits.push(None);
                    }
                }
            }
            for &i in &old {
                seen[i as usize] = false;
                if self.labels.data[i as usize] == RELEASED {
                    self.labels.data[i as usize] = 0;
                }
            }
        }
        leaks
    }

    /// Region r's outliers of `fit` (pixels with a point beyond `dist` of its plane) in
    /// 8-connected pieces of at least `min_pixels` that leave the plane
    /// (`leaves_the_plane`), each made a new region; r keeps the
    /// rest, smaller pieces included (a plane's noise, filled in its polygon). Returns the
    /// new regions. `seen` is all false on entry and exit.
    fn cut_outliers(
        &mut self,
        r: usize,
        fit: &PlaneFit,
        cloud: &Cloud,
        dist: f32,
        min_pixels: usize,
        seen: &mut [bool],
    ) -> Vec<usize> {
        let (w, h, label) = (self.labels.width, self.labels.height, r as u32 + 1);
        let outlier =
            |i: usize| self.labels.data[i] == label && cloud.point(i).is_some_and(|p| fit.distance(&p) >= dist as f64);
        let mut cut = Vec::new();
        for &i in &self.pixels[r] {
            if !seen[i as usize] && outlier(i as usize) {
                let piece = flood(i as usize, w, h, seen, outlier);
                if piece.len() >= min_pixels && leaves_the_plane(&piece, fit, cloud, dist) {
                    cut.push(piece);
                }
            }
        }
        self.pixels[r].iter().for_each(|&i| seen[i as usize] = false);
        let pieces: Vec<usize> = cut.into_iter().map(|piece| self.push(piece)).collect();
        if !pieces.is_empty() {
            // In ascending order as they were: no sort.
            self.pixels[r].retain(|&i| self.labels.data[i as usize] == label);
        }
        pieces
    }
}

/// Half of a second face's points lie at least this many inlier distances off the plane:
/// a face that turns away from it leaves it steadily, while the tail of a plane's noise
/// beyond the band crowds the band's edge (a far patch of floor on a drift walk, 100
/// pixels at 22 deg to the floor: a median of 1.4-1.6).
const SECOND_FACE_MEDIAN_BANDS: f64 = 1.6;

/// Whether a piece of a plane's outliers is a second face (`SECOND_FACE_MEDIAN_BANDS`).
fn leaves_the_plane(piece: &[u32], fit: &PlaneFit, cloud: &Cloud, dist: f32) -> bool {
    let mut off: Vec<f64> = piece.iter().filter_map(|&i| cloud.point(i as usize)).map(|p| fit.distance(&p)).collect();
    let k = off.len() / 2;
    !off.is_empty() && *off.select_nth_unstable_by(k, f64::total_cmp).1 >= SECOND_FACE_MEDIAN_BANDS * dist as f64
}
