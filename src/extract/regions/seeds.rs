//! Seeds: regions for the blobs of pixels that no region took. A face whose normals are
//! noise (a dark or glossy patch) or that is only a few edge widths across is all Canny
//! lines: no component of it is large enough to become a region, and growth gives its
//! pixels to none (they lie off every plane around). What is left unlabelled after growth
//! holds such faces as compact blobs, and the bands between faces as long, thin ones.

use super::Segmentation;
use crate::extract::Grid;
use crate::extract::cloud::Cloud;
use crate::extract::cpu::morphology::dilate;
use crate::extract::cpu::ransac::PlaneFit;

/// A seed's blob must be at least this wide (the spread of its pixels across its minor
/// axis, one standard deviation, px): the bands growth leaves along a crease are thinner.
const MIN_SEED_SPREAD_PX: f64 = 2.0;

impl Segmentation {
    /// New regions (their indices) of the unlabelled pixels with a depth: opened by a 3x3
    /// square (bands up to two pixels wide vanish), each 8-connected blob of at least
    /// `min_pixels` pixels that is at least `MIN_SEED_SPREAD_PX` wide. Growth gives them
    /// back the ring the opening took.
    pub(super) fn seed_leftovers(&mut self, cloud: &Cloud, min_pixels: usize) -> Vec<usize> {
        let (w, h) = (self.labels.width, self.labels.height);
        let taken = Grid {
            width: w,
            height: h,
            data: (0..w * h).map(|i| u8::from(self.labels.data[i] != 0 || cloud.depth(i) <= 0.0)).collect(),
        };
        let blobs = Segmentation::components(&dilate(&taken, 1, 1), min_pixels).pixels;
        blobs
            .into_iter()
            .filter(|blob| minor_spread(blob, w) >= MIN_SEED_SPREAD_PX)
            .map(|blob| self.push(blob))
            .collect()
    }

    /// Gives the pixels of each seed whose fit is not `accepted` back to no region (its fit
    /// None): other regions may grow over them. Returns how many seeds are kept.
    pub(super) fn release_rejected(
        &mut self,
        seeds: &[usize],
        accepted: &[bool],
        fits: &mut [Option<PlaneFit>],
    ) -> usize {
        let mut kept = 0;
        for &r in seeds {
            if accepted[r] {
                kept += 1;
            } else {
                for &i in &std::mem::take(&mut self.pixels[r]) {
                    self.labels.data[i as usize] = 0;
                }
                fits[r] = None;
            }
        }
        kept
    }
}

/// The standard deviation of the pixels' positions along their minor axis, px (the square
/// root of the smaller eigenvalue of their 2x2 covariance).
fn minor_spread(pixels: &[u32], w: usize) -> f64 {
    let n = pixels.len() as f64;
    let (mut su, mut sv, mut suu, mut svv, mut suv) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &i in pixels {
        let (u, v) = ((i as usize % w) as f64, (i as usize / w) as f64);
        (su, sv, suu, svv, suv) = (su + u, sv + v, suu + u * u, svv + v * v, suv + u * v);
    }
    let (mu, mv) = (su / n, sv / n);
    let (a, b, c) = (suu / n - mu * mu, suv / n - mu * mv, svv / n - mv * mv);
    let minor = (a + c) / 2.0 - ((a - c) * (a - c) / 4.0 + b * b).sqrt();
    minor.max(0.0).sqrt()
}
