//! Leak splits: a region whose plane fits too few of its points (a Canny line broken by a
//! dropout let two surfaces leak into one) keeps the largest connected patch of that
//! plane's inliers; the rest becomes new regions, fitted again.

use super::Segmentation;
use crate::extract::cloud::Cloud;
use crate::extract::cpu::ransac::{PlaneFit, refit};
use crate::grid::flood;

/// The label of a leaking region's pixels between its split and their regrouping.
pub(super) const RELEASED: u32 = u32::MAX;

/// What `split_leaks` did: the regions it cut back to their plane's largest patch (their
/// labels changed), and the new regions made of the pieces of the rest that are large
/// enough (ascending).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Leaks {
    pub split: Vec<usize>,
    pub pieces: Vec<usize>,
}

impl Segmentation {
    /// Splits every region whose fit has an inlier ratio under `min_ratio`: it keeps the
    /// largest 8-connected patch of its plane's inliers, refitted; the other connected
    /// pieces of at least `min_pixels` become new regions (their fits None).
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
}
