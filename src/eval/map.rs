//! The final map against the truth: for every tread (and landing) the camera saw, the map
//! polygon that overlaps it best, its IOU, tilt, absolute height error, and the step-height
//! error between neighbouring treads.
//!
//! The truth a map can reach is the part of each tread some frame saw: the tread is
//! rasterised on a 2 mm grid and a cell counts as seen when it projects, with the frame's
//! true pose, onto a pixel that labels/ gives to that tread. IOU is measured on that grid.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use serde::Serialize;

use super::{mean_std, min_visible_pixels, treads, world_tilt_deg};
use crate::extract::Footing;
use crate::map::{MapPolygon, MapSnapshot};
use crate::ring::fill_rings;
use crate::sequence::{Sequence, SequenceError};

/// Grid cell for map IOU, m.
pub const CELL_M: f64 = 0.002;
/// Margin around a tread where a map polygon's overshoot still counts against it, m.
const MARGIN_M: f64 = 0.1;

/// How one tread came out in the map.
#[derive(Clone, Debug, Serialize)]
pub struct MapTreadScore {
    pub step: u32,
    /// Area of the tread some frame saw, m^2.
    pub seen_area_m2: f64,
    /// Whether a map polygon covers it with IOU at least `super::FOUND_IOU`.
    pub found: bool,
    pub iou: f64,
    /// Area of the best polygon outside the seen tread, and of the seen tread it misses, m^2.
    pub over_m2: f64,
    pub under_m2: f64,
    /// The map polygon that matched best.
    pub polygon: Option<u64>,
    /// Angle of the polygon's normal to +z, degrees.
    pub alpha_deg: Option<f64>,
    /// The polygon's plane height at the tread's centre, m.
    pub height: Option<f64>,
    /// |height - true height|, m.
    pub height_error: Option<f64>,
    /// Whether the map publishes that polygon as steppable.
    pub footing: Option<Footing>,
}

#[derive(Clone, Debug, Serialize)]
pub struct MapSummary {
    pub treads_seen: usize,
    pub treads_found: usize,
    pub iou_mean: f64,
    pub iou_min: f64,
    pub alpha_mean_deg: f64,
    pub alpha_std_deg: f64,
    pub step_error_mean_mm: f64,
    pub step_error_std_mm: f64,
    pub height_error_mean_mm: f64,
    pub height_error_max_mm: f64,
    /// The map's drift estimate minus the drift injected into the last frame's pose, mm.
    pub drift_error_mm: f64,
    /// Where the map's drift estimate puts the last frame's camera against where it was,
    /// seen from above, mm; and its yaw's error, degrees.
    pub drift_error_xy_mm: f64,
    pub drift_error_yaw_deg: f64,
    /// Treads found whose polygon is steppable, and the largest tilt of those, degrees.
    pub treads_steppable: usize,
    pub steppable_tread_alpha_max_deg: f64,
    /// Every map polygon within `LEVEL_WITHIN_DEG` of level and at least `LEVEL_MIN_AREA_M2`
    /// (every level surface of the scenes is exactly level): how many, how many steppable,
    /// and the worst tilt of a steppable one, degrees.
    pub level_polygons: usize,
    pub level_steppable: usize,
    pub level_steppable_tilt_max_deg: f64,
}

/// Scores `map` against `seq`'s truth and labels; with `pictures`, also one picture per tread
/// on the IOU grid (north up): green where map and seen tread agree, red where the map
/// overshoots, blue where it misses.
pub fn score_map(
    map: &MapSnapshot,
    seq: &Sequence,
    pictures: bool,
) -> Result<(Vec<MapTreadScore>, Vec<image::RgbImage>), SequenceError> {
    score_map_seen_in(map, seq, &(0..seq.len()).collect::<Vec<_>>(), pictures)
}

/// As [`score_map`], with "seen" meaning seen in `frames` only: the frames a live mapper
/// actually processed.
pub fn score_map_seen_in(
    map: &MapSnapshot,
    seq: &Sequence,
    frames: &[usize],
    pictures: bool,
) -> Result<(Vec<MapTreadScore>, Vec<image::RgbImage>), SequenceError> {
    let mut images = Vec::new();
    let Some(truth) = &seq.truth else { return Ok((Vec::new(), images)) };
    let intr = &seq.intrinsics;
    let labels: Vec<Vec<u16>> = frames.iter().map(|&k| seq.labels(k)).collect::<Result<_, _>>()?;
    let camera_world: Vec<Isometry3<f64>> =
        frames.iter().map(|&k| truth.true_pose(k, &seq.poses[k].transform).inverse()).collect();
    let min_pixels = min_visible_pixels(intr.pixel_count());
    let mut out = Vec::new();
    for (label, t) in treads(truth) {
        let Some(step) = t.step else { continue };
        if !labels.iter().any(|l| l.iter().filter(|&&v| v == label).count() >= min_pixels) {
            continue;
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in &t.boundary {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k] - MARGIN_M);
                hi[k] = hi[k].max(p[k] + MARGIN_M);
            }
        }
        let (nx, ny) = (((hi[0] - lo[0]) / CELL_M) as usize, ((hi[1] - lo[1]) / CELL_M) as usize);
        // Cell (i, j) has its centre at grid coordinates (i, j), as fill_rings samples them.
        let to_grid = |p: &[f64; 3]| [(p[0] - lo[0]) / CELL_M - 0.5, (p[1] - lo[1]) / CELL_M - 0.5];
        let centre = |i: usize| {
            [lo[0] + (i % nx) as f64 * CELL_M + CELL_M / 2.0, lo[1] + (i / nx) as f64 * CELL_M + CELL_M / 2.0]
        };
        let inside = fill_rings(&[t.boundary.iter().map(to_grid).collect()], nx, ny);
        let seen: Vec<bool> = inside
            .iter()
            .enumerate()
            .map(|(i, &inside)| {
                let [x, y] = centre(i);
                inside
                    && camera_world.iter().zip(&labels).any(|(cw, l)| {
                        let p = cw * Point3::new(x, y, t.height);
                        if p.z <= 0.0 {
                            return false;
                        }
                        let (u, v) = intr.project(&p);
                        let (u, v) = (u.round(), v.round());
                        u >= 0.0
                            && v >= 0.0
                            && u < intr.width as f64
                            && v < intr.height as f64
                            && l[v as usize * intr.width as usize + u as usize] == label
                    })
            })
            .collect();
        let seen_cells = seen.iter().filter(|&&s| s).count();
        let [tx, ty] = {
            let n = t.boundary.len() as f64;
            [t.boundary.iter().map(|p| p[0]).sum::<f64>() / n, t.boundary.iter().map(|p| p[1]).sum::<f64>() / n]
        };
        let best = map
            .polygons
            .iter()
            .filter(|p| p.label.is_horizontal() && p.normal[2].abs() > 0.5)
            .map(|p| {
                let rings: Vec<Vec<[f64; 2]>> =
                    std::iter::once(&p.boundary).chain(&p.holes).map(|r| r.iter().map(to_grid).collect()).collect();
                let mask = fill_rings(&rings, nx, ny);
                let (mut inter, mut union) = (0usize, 0usize);
                for (&m, &s) in mask.iter().zip(&seen) {
                    inter += (m && s) as usize;
                    union += (m || s) as usize;
                }
                let iou = if union == 0 { 0.0 } else { inter as f64 / union as f64 };
                let area = |cells: usize| cells as f64 * CELL_M * CELL_M;
                (p, iou, area(union - seen_cells), area(seen_cells - inter), mask)
            })
            .max_by(|a, b| a.1.total_cmp(&b.1));
        if pictures {
            let mut img = image::RgbImage::new(nx as u32, ny as u32);
            for (i, &s) in seen.iter().enumerate() {
                let m = best.as_ref().is_some_and(|b| b.4[i]);
                let colour = match (m, s) {
                    (true, true) => [40, 170, 60],
                    (true, false) => [220, 40, 40],
                    (false, true) => [40, 80, 230],
                    _ if inside[i] => [60, 60, 60],
                    _ => [0, 0, 0],
                };
                // Grid rows grow with y; pictures have north (+y) up.
                img.put_pixel((i % nx) as u32, (ny - 1 - i / nx) as u32, image::Rgb(colour));
            }
            images.push(img);
        }
        let (polygon, iou, over_m2, under_m2) = best
            .map_or((None, 0.0, 0.0, seen_cells as f64 * CELL_M * CELL_M), |(p, iou, o, u, _)| (Some(p), iou, o, u));
        let found = iou >= super::FOUND_IOU;
        let height = polygon.filter(|_| found).map(|p| -(p.normal[0] * tx + p.normal[1] * ty + p.offset) / p.normal[2]);
        out.push(MapTreadScore {
            step,
            seen_area_m2: seen_cells as f64 * CELL_M * CELL_M,
            found,
            iou,
            over_m2,
            under_m2,
            polygon: polygon.map(|p| p.id),
            alpha_deg: polygon.filter(|_| found).map(|p| world_tilt_deg(p.normal)),
            height,
            height_error: height.map(|z| (z - t.height).abs()),
            footing: polygon.filter(|_| found).map(|p| p.footing),
        });
    }
    Ok((out, images))
}

pub fn summarise(scores: &[MapTreadScore], map: &MapSnapshot, seq: &Sequence) -> MapSummary {
    let rise = seq.truth.as_ref().and_then(|t| t.stair.as_ref()).map_or(f64::NAN, |s| s.rise);
    let last = seq.len().saturating_sub(1);
    let injected = seq.truth.as_ref().map_or_else(Isometry3::identity, |t| t.drift_at(last));
    let estimated = Isometry3::from_parts(
        Translation3::new(map.drift_xy[0], map.drift_xy[1], map.drift_z),
        UnitQuaternion::from_euler_angles(0.0, 0.0, map.drift_yaw),
    );
    let camera = injected.inverse() * Point3::from(seq.poses[last].transform.translation.vector);
    let off = estimated.inverse() * (injected * camera) - camera;
    let yaw_off = (estimated.inverse() * injected).rotation.euler_angles().2;
    let ious: Vec<f64> = scores.iter().map(|s| s.iou).collect();
    let alphas: Vec<f64> = scores.iter().filter_map(|s| s.alpha_deg).collect();
    let heights: Vec<f64> = scores.iter().filter_map(|s| s.height_error).map(|e| e * 1e3).collect();
    let steps: Vec<f64> = scores
        .iter()
        .flat_map(|a| scores.iter().filter(move |b| b.step == a.step + 1).map(move |b| (a, b)))
        .filter_map(|(a, b)| Some(((b.height? - a.height?) - rise).abs() * 1e3))
        .collect();
    let (alpha_mean_deg, alpha_std_deg) = mean_std(&alphas);
    let (step_error_mean_mm, step_error_std_mm) = mean_std(&steps);
    let steppable: Vec<&MapTreadScore> =
        scores.iter().filter(|s| s.footing.is_some_and(Footing::is_steppable)).collect();
    let level: Vec<(&MapPolygon, f64)> = (map.polygons.iter())
        .map(|p| (p, world_tilt_deg(p.normal)))
        .filter(|(p, tilt)| p.area >= super::LEVEL_MIN_AREA_M2 && *tilt <= super::LEVEL_WITHIN_DEG)
        .collect();
    let steppable_level_tilts: Vec<f64> =
        level.iter().filter(|(p, _)| p.footing.is_steppable()).map(|(_, tilt)| *tilt).collect();
    MapSummary {
        treads_seen: scores.len(),
        treads_found: scores.iter().filter(|s| s.found).count(),
        iou_mean: mean_std(&ious).0,
        iou_min: ious.iter().copied().fold(f64::NAN, f64::min),
        alpha_mean_deg,
        alpha_std_deg,
        step_error_mean_mm,
        step_error_std_mm,
        height_error_mean_mm: mean_std(&heights).0,
        height_error_max_mm: heights.iter().copied().fold(f64::NAN, f64::max),
        drift_error_mm: (map.drift_z - injected.translation.z) * 1e3,
        drift_error_xy_mm: off.xy().norm() * 1e3,
        drift_error_yaw_deg: yaw_off.to_degrees(),
        treads_steppable: steppable.len(),
        steppable_tread_alpha_max_deg: steppable.iter().filter_map(|s| s.alpha_deg).fold(f64::NAN, f64::max),
        level_polygons: level.len(),
        level_steppable: steppable_level_tilts.len(),
        level_steppable_tilt_max_deg: steppable_level_tilts.iter().copied().fold(f64::NAN, f64::max),
    }
}
