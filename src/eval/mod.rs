//! Single-frame accuracy against a sequence's truth, with the metrics of
//! ../shared/REFERENCE.md: per tread in view, alpha (its fitted normal against world
//! +z), IOU of the polygon against the tread's pixels in labels/, and step-height error
//! between consecutive treads found in the same frame.
//!
//! IOU is measured in the image: the polygon (outline minus holes) is projected and
//! filled, then compared with the label mask of the tread, which is exactly the part of
//! the truth polygon the camera sees.

pub mod drift;
pub mod map;
pub mod segmentation;

use nalgebra::Isometry3;
use serde::Serialize;

use crate::extract::{Footing, HeldBack, HoldBack, Polygon};
use crate::sequence::Truth;
use crate::types::Intrinsics;

/// A tread in view with fewer visible pixels than this, at 640x480, is not scored
/// (the bar; scaled by image area for other sizes).
pub const MIN_VISIBLE_PIXELS_640: usize = 2000;

/// How one tread of one frame came out.
#[derive(Clone, Debug, Serialize)]
pub struct TreadScore {
    pub frame: usize,
    /// Step index of the tread (the landing counts as the top step).
    pub step: u32,
    pub visible_pixels: usize,
    /// How deep its visible part is across its narrowest direction, m (`visible_depth_m`).
    pub visible_depth_m: f64,
    /// Whether a polygon covers it with IOU at least `FOUND_IOU`.
    pub found: bool,
    pub iou: f64,
    /// Angle of the polygon's world normal to +z, degrees (when found).
    pub alpha_deg: Option<f64>,
    /// World z of the polygon's centroid, m (when found).
    pub height: Option<f64>,
    /// The standard deviation of the polygon's normal along its worst axis, as its
    /// plane uncertainty reports it, degrees (when found): what alpha is held against.
    pub tilt_sigma_deg: Option<f64>,
    /// Whether the polygon found is published as steppable (when found).
    pub footing: Option<Footing>,
}

/// A tread with this many visible pixels at 320x240 (scaled by image area for other sizes),
/// and a visible part at least `FOOT_WIDTH_M` deep, must be found and steppable: the
/// footing rule may not hide real treads.
pub const MIN_STEPPABLE_TREAD_PIXELS_320: usize = 1500;

/// About a humanoid's foot width. A strip of tread seen narrower than this (cut by the
/// image's edge) holds no foot across it, and its support is thin in one direction, which
/// the footing rule may mark; the map has the whole tread from other frames.
pub const FOOT_WIDTH_M: f64 = 0.10;

/// A polygon counts as the tread when it overlaps it at least this much.
pub const FOUND_IOU: f64 = 0.5;

/// Minimum visible pixels for a tread to be scored in an image of `pixel_count` pixels.
pub fn min_visible_pixels(pixel_count: usize) -> usize {
    MIN_VISIBLE_PIXELS_640 * pixel_count / (640 * 480)
}

/// Scores one frame: `polygons` in the camera frame, `t_world_camera` its pose, `labels`
/// its truth label image (1-based indices into `truth.polygons`).
pub fn score_frame(
    frame: usize,
    polygons: &[Polygon],
    t_world_camera: &Isometry3<f64>,
    labels: &[u16],
    truth: &Truth,
    intr: &Intrinsics,
) -> Vec<TreadScore> {
    let masks = polygon_masks(polygons, intr);
    let min_pixels = min_visible_pixels(intr.pixel_count());
    let mut scores = Vec::new();
    for (label, t) in treads(truth) {
        let Some(step) = t.step else { continue };
        let visible_pixels = labels.iter().filter(|&&l| l == label).count();
        if visible_pixels < min_pixels {
            continue;
        }
        let (k, iou) = best_match(&masks, labels, label);
        let found = iou >= FOUND_IOU;
        let visible_depth_m = visible_depth_m(labels, label, t.height, t_world_camera, intr);
        let world = found.then(|| polygons[k].transformed(t_world_camera));
        scores.push(TreadScore {
            frame,
            step,
            visible_pixels,
            visible_depth_m,
            found,
            iou,
            alpha_deg: world.as_ref().map(|p| p.normal[2].clamp(-1.0, 1.0).acos().to_degrees()),
            height: world.as_ref().map(|p| p.centroid()[2]),
            tilt_sigma_deg: found.then(|| polygons[k].uncertainty.tilt_sigma_rad().to_degrees()),
            footing: found.then(|| polygons[k].footing),
        });
    }
    scores
}

/// How deep the part of a level tread at world height `height` that pixels labelled
/// `label` see is, across its narrowest direction, m: the rectangle with the same spread,
/// sqrt(12 x the smaller variance of where the pixels' rays meet the tread).
fn visible_depth_m(labels: &[u16], label: u16, height: f64, t_world_camera: &Isometry3<f64>, intr: &Intrinsics) -> f64 {
    let origin = t_world_camera.translation.vector;
    let (mut n, mut sum, mut products) = (0.0, nalgebra::Vector2::zeros(), nalgebra::Matrix2::zeros());
    for (i, _) in labels.iter().enumerate().filter(|&(_, &l)| l == label) {
        let (u, v) = ((i % intr.width as usize) as f64, (i / intr.width as usize) as f64);
        let ray = t_world_camera.rotation * intr.ray(u, v);
        let along = (height - origin.z) / ray.z;
        if !(along > 0.0 && along.is_finite()) {
            continue;
        }
        let p = nalgebra::Vector2::new(origin.x + along * ray.x, origin.y + along * ray.y);
        n += 1.0;
        sum += p;
        products += p * p.transpose();
    }
    if n < 2.0 {
        return 0.0;
    }
    let mean = sum / n;
    let spread = products / n - mean * mean.transpose();
    (12.0 * spread.symmetric_eigenvalues().min().max(0.0)).sqrt()
}

/// A picture of how the treads were matched: green where polygon and tread agree, red
/// where a matched polygon covers what is not its tread, blue where the tread is missed.
pub fn match_image(polygons: &[Polygon], labels: &[u16], truth: &Truth, intr: &Intrinsics) -> image::RgbImage {
    let (w, h) = (intr.width, intr.height);
    let mut img = image::RgbImage::new(w, h);
    let masks = polygon_masks(polygons, intr);
    for (label, _) in treads(truth) {
        let (k, score) = best_match(&masks, labels, label);
        let mask = (score > 0.0).then(|| &masks[k]);
        for (i, &l) in labels.iter().enumerate() {
            let m = mask.is_some_and(|m| m[i]);
            let colour = match (m, l == label) {
                (true, true) => [40, 170, 60],
                (true, false) => [220, 40, 40],
                (false, true) => [40, 80, 230],
                _ => continue,
            };
            img.put_pixel(i as u32 % w, i as u32 / w, image::Rgb(colour));
        }
    }
    img
}

/// The stepping surfaces of the truth (treads and the landing) with their label values.
pub(crate) fn treads(truth: &Truth) -> impl Iterator<Item = (u16, &crate::sequence::TruthPolygon)> {
    truth
        .polygons
        .iter()
        .enumerate()
        .filter(|(_, t)| t.label == "tread" || t.label == "landing")
        .map(|(index, t)| (index as u16 + 1, t))
}

fn polygon_masks(polygons: &[Polygon], intr: &Intrinsics) -> Vec<Vec<bool>> {
    polygons.iter().map(|p| p.image_mask(intr)).collect()
}

/// The polygon that overlaps the pixels of `label` best, and its IOU ((0, 0.0) for none).
fn best_match(masks: &[Vec<bool>], labels: &[u16], label: u16) -> (usize, f64) {
    masks
        .iter()
        .enumerate()
        .map(|(k, m)| (k, iou(m, labels, label)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, 0.0))
}

fn iou(mask: &[bool], labels: &[u16], label: u16) -> f64 {
    let (mut inter, mut union) = (0usize, 0usize);
    for (&m, &l) in mask.iter().zip(labels) {
        let t = l == label;
        inter += (m && t) as usize;
        union += (m || t) as usize;
    }
    if union == 0 { 0.0 } else { inter as f64 / union as f64 }
}

/// Step-height errors |(z_k - z_{k-1}) - rise| between consecutive treads found in the same frame, m.
pub fn step_errors(scores: &[TreadScore], rise: f64) -> Vec<f64> {
    let mut out = Vec::new();
    for a in scores {
        for b in scores {
            if a.frame == b.frame
                && b.step == a.step + 1
                && let (Some(za), Some(zb)) = (a.height, b.height)
            {
                out.push(((zb - za) - rise).abs());
            }
        }
    }
    out
}

/// Published polygons within this of level, and at least `LEVEL_MIN_AREA_M2` large, are
/// ground a planner may put a foot on: the steppable ones' tilt is held to 1 deg.
pub const LEVEL_WITHIN_DEG: f64 = 25.0;
pub const LEVEL_MIN_AREA_M2: f64 = 0.02;

/// A published polygon near level, and how far it tilts from level: every level surface
/// of the synthetic scenes is exactly level, so its tilt is its error.
#[derive(Clone, Debug, Serialize)]
pub struct LevelTilt {
    pub frame: usize,
    pub polygon: u32,
    pub tilt_deg: f64,
    pub area_m2: f64,
    pub pixels: usize,
    pub footing: Footing,
}

/// The angle of a world-frame unit normal from the vertical, either way up, degrees.
pub(crate) fn world_tilt_deg(normal: [f64; 3]) -> f64 {
    normal[2].abs().min(1.0).acos().to_degrees()
}

/// The angle of a camera-frame normal from the world's vertical, either way up, degrees.
fn tilt_from_level_deg(normal: [f64; 3], t_world_camera: &Isometry3<f64>) -> f64 {
    world_tilt_deg((t_world_camera.rotation * nalgebra::Vector3::from(normal)).into())
}

/// The level polygons of one frame (`polygons` in the camera frame, `t_world_camera` its pose).
pub fn level_tilts(frame: usize, polygons: &[Polygon], t_world_camera: &Isometry3<f64>) -> Vec<LevelTilt> {
    polygons
        .iter()
        .filter(|p| p.area >= LEVEL_MIN_AREA_M2)
        .map(|p| {
            let tilt_deg = tilt_from_level_deg(p.normal, t_world_camera);
            LevelTilt { frame, polygon: p.id, tilt_deg, area_m2: p.area, pixels: p.pixel_count, footing: p.footing }
        })
        .filter(|t| t.tilt_deg <= LEVEL_WITHIN_DEG)
        .collect()
}

/// The level polygons of one frame that the extractor held back (`held` in the camera
/// frame), as level and as large as the published ones `level_tilts` takes.
pub fn level_held_back(held: &[HeldBack], t_world_camera: &Isometry3<f64>) -> Vec<HeldBack> {
    (held.iter())
        .filter(|h| h.area >= LEVEL_MIN_AREA_M2 && tilt_from_level_deg(h.normal, t_world_camera) <= LEVEL_WITHIN_DEG)
        .cloned()
        .collect()
}

/// How many level polygons a rule marked or held back, and their area, m^2.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct PolygonCount {
    pub polygons: usize,
    pub area_m2: f64,
}

impl PolygonCount {
    fn of<'a>(areas: impl Iterator<Item = &'a f64>) -> PolygonCount {
        areas.fold(PolygonCount::default(), |c, a| PolygonCount { polygons: c.polygons + 1, area_m2: c.area_m2 + a })
    }
}

/// The level polygons' tilts over a whole sequence: of all published, and of the
/// steppable ones (mean, 99th percentile, the worst); what the footing rule marked not
/// steppable, and what the extractor held back, each by reason.
#[derive(Clone, Debug, Serialize)]
pub struct LevelSummary {
    pub all: TiltSummary,
    pub steppable: TiltSummary,
    pub tilt_unknown: PolygonCount,
    pub few_pixels: PolygonCount,
    pub not_one_plane: PolygonCount,
    pub no_plane: PolygonCount,
}

/// Tilts of a set of level polygons, degrees: mean, 99th percentile (nearest rank), worst.
#[derive(Clone, Debug, Serialize)]
pub struct TiltSummary {
    pub polygons: usize,
    pub tilt_mean_deg: f64,
    pub tilt_p99_deg: f64,
    pub worst: Option<LevelTilt>,
}

impl TiltSummary {
    fn of<'a>(tilts: impl Iterator<Item = &'a LevelTilt>) -> TiltSummary {
        let tilts: Vec<&LevelTilt> = tilts.collect();
        let values: Vec<f64> = tilts.iter().map(|t| t.tilt_deg).collect();
        TiltSummary {
            polygons: tilts.len(),
            tilt_mean_deg: mean_std(&values).0,
            tilt_p99_deg: crate::stats::percentile(&values, 0.99),
            worst: tilts.iter().max_by(|a, b| a.tilt_deg.total_cmp(&b.tilt_deg)).map(|&t| t.clone()),
        }
    }
}

pub fn summarise_level(tilts: &[LevelTilt], held_back: &[HeldBack]) -> LevelSummary {
    let marked = |f: Footing| PolygonCount::of(tilts.iter().filter(|t| t.footing == f).map(|t| &t.area_m2));
    let held = |why: HoldBack| PolygonCount::of(held_back.iter().filter(|h| h.why == why).map(|h| &h.area));
    LevelSummary {
        all: TiltSummary::of(tilts.iter()),
        steppable: TiltSummary::of(tilts.iter().filter(|t| t.footing.is_steppable())),
        tilt_unknown: marked(Footing::TiltUnknown),
        few_pixels: marked(Footing::FewPixels),
        not_one_plane: held(HoldBack::NotOnePlane),
        no_plane: held(HoldBack::NoPlane),
    }
}

/// Mean and (population) standard deviation; (NaN, NaN) for no values.
pub fn mean_std(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

/// The summary row of an evaluation.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub treads_in_view: usize,
    pub treads_found: usize,
    pub alpha_mean_deg: f64,
    pub alpha_std_deg: f64,
    /// Mean IOU over treads in view (a missed tread counts as its best overlap).
    pub iou_mean: f64,
    pub iou_min: f64,
    pub step_error_mean_mm: f64,
    pub step_error_std_mm: f64,
    pub step_pairs: usize,
}

pub fn summarise(scores: &[TreadScore], rise: f64) -> Summary {
    let alphas: Vec<f64> = scores.iter().filter_map(|s| s.alpha_deg).collect();
    let ious: Vec<f64> = scores.iter().map(|s| s.iou).collect();
    let steps: Vec<f64> = step_errors(scores, rise).iter().map(|e| e * 1e3).collect();
    let (alpha_mean_deg, alpha_std_deg) = mean_std(&alphas);
    let (step_error_mean_mm, step_error_std_mm) = mean_std(&steps);
    Summary {
        treads_in_view: scores.len(),
        treads_found: scores.iter().filter(|s| s.found).count(),
        alpha_mean_deg,
        alpha_std_deg,
        iou_mean: mean_std(&ious).0,
        iou_min: ious.iter().copied().fold(f64::NAN, f64::min),
        step_error_mean_mm,
        step_error_std_mm,
        step_pairs: steps.len(),
    }
}
