//! A segmentation scored against per-pixel plane truth with the metric of Hoover et al.,
//! "An Experimental Comparison of Range Image Segmentation Algorithms" (IEEE PAMI 18(7),
//! 1996, section 3), as the SegComp ABW images are scored.
//!
//! With P_n the pixels of truth face n, P_m those of machine region m and O_mn their
//! overlap, at a tolerance T (0.5 < T <= 1; 0.8 is the standard):
//! - correct detection: O_mn >= T P_m and O_mn >= T P_n;
//! - over-segmentation: a face n and machine regions m_1..m_x (x >= 2), each lying at T
//!   inside n (O >= T P_m), together covering it at T (sum O >= T P_n);
//! - under-segmentation: the mirror, one region covering faces m_1..m_x;
//! - missed: a face in none of these; noise: a region in none of these.
//!
//! A region takes part in one instance only, classified in that order (a correct detection
//! first), which is how the paper counts them: its table sums to the number of faces.
//! Angle error: for each pair of faces that touch in the truth and are both detected
//! correctly, the difference between the angle their truth planes make and the angle the
//! two machine planes make.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use anyhow::{Context, Result, bail};
use nalgebra::{Point3, Vector3};
use serde::Serialize;

use crate::extract::Polygon;
use crate::types::{DepthFrame, Intrinsics};

/// Truth pixels below this label are no face (SegComp: 0 no data, 1 and 2 small
/// unlabelled noise regions); each value from it up is one planar face.
pub const FIRST_FACE_LABEL: u16 = 10;

/// Faces whose pixels come within this many pixels of each other touch (the truth leaves
/// a thin unlabelled seam along some creases).
pub const TOUCH_PX: usize = 3;

/// A segmentation: one region id per pixel, 0 where none.
pub type Regions = Vec<u32>;

/// An image's plane truth: a face label per pixel and a plane per face.
pub struct FaceTruth {
    pub width: usize,
    pub height: usize,
    /// Face id per pixel (the truth's label), 0 where no face.
    pub faces: Regions,
    /// Unit normal of each face's plane, facing the camera.
    pub normals: BTreeMap<u32, [f64; 3]>,
}

impl FaceTruth {
    /// `labels.png` (8- or 16-bit) and `planes.txt` (`label pixels nx ny nz d rms_mm`) of `dir`.
    pub fn open(dir: &Path) -> Result<FaceTruth> {
        let path = dir.join("labels.png");
        let values: Vec<u16> = match image::open(&path).with_context(|| format!("reading {}", path.display()))? {
            image::DynamicImage::ImageLuma8(img) => img.into_raw().into_iter().map(u16::from).collect(),
            image::DynamicImage::ImageLuma16(img) => img.into_raw(),
            other => bail!("{}: labels must be 8- or 16-bit grey, not {:?}", path.display(), other.color()),
        };
        let (width, height) = image::image_dimensions(&path)?;
        let (width, height) = (width as usize, height as usize);
        let faces = values.into_iter().map(|v| if v >= FIRST_FACE_LABEL { v as u32 } else { 0 }).collect();
        let path = dir.join("planes.txt");
        let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
        let mut normals = BTreeMap::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let f: Vec<&str> = line.split_whitespace().collect();
            let parse = |k: usize| -> Result<f64> {
                f.get(k)
                    .and_then(|s| s.parse::<f64>().ok())
                    .with_context(|| format!("{} line {}: field {} is not a number", path.display(), i + 1, k + 1))
            };
            let label = parse(0)? as u32;
            let n = Vector3::new(parse(2)?, parse(3)?, parse(4)?);
            let d = parse(5)?;
            if (n.norm() - 1.0).abs() > 1e-3 {
                bail!("{} line {}: the normal of face {label} is not a unit vector", path.display(), i + 1);
            }
            // n.x + d = 0: the plane faces the camera (at the origin) when d > 0.
            let n = if d < 0.0 { -n } else { n };
            normals.insert(label, [n.x, n.y, n.z]);
        }
        Ok(FaceTruth { width, height, faces, normals })
    }
}

/// The regions polygons claim in the image: each polygon's projection, on pixels that hold a
/// depth; where two projections overlap, the pixel goes to the polygon whose plane its point
/// lies nearer. Region k + 1 is `polygons[k]`.
pub fn polygon_regions(polygons: &[Polygon], frame: &DepthFrame, intr: &Intrinsics) -> Regions {
    let width = intr.width as usize;
    let mut regions = vec![0u32; intr.pixel_count()];
    let mut nearest = vec![f64::INFINITY; regions.len()];
    for (k, p) in polygons.iter().enumerate() {
        let n = Vector3::from(p.normal);
        for (i, inside) in p.image_mask(intr).into_iter().enumerate() {
            let Some(depth) = inside.then(|| frame.depth_m((i % width) as u32, (i / width) as u32)).flatten() else {
                continue;
            };
            let point: Point3<f64> = intr.back_project((i % width) as f64, (i / width) as f64, depth);
            let distance = (n.dot(&point.coords) + p.offset).abs();
            if distance < nearest[i] {
                nearest[i] = distance;
                regions[i] = k as u32 + 1;
            }
        }
    }
    regions
}

/// What became of one truth face.
#[derive(Clone, Copy, Debug, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    Correct,
    Over,
    Under,
    Missed,
}

/// The angle two touching faces make, in the truth and as segmented.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct AngleError {
    pub faces: (u32, u32),
    pub error_deg: f64,
}

/// How a segmentation came out against the truth at one tolerance.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct HooverScore {
    /// Each truth face's outcome.
    pub faces: BTreeMap<u32, Outcome>,
    /// Machine regions in no instance.
    pub noise_regions: BTreeSet<u32>,
    pub truth_faces: usize,
    pub machine_regions: usize,
    pub correct: usize,
    /// Instances (one face each) of over-segmentation.
    pub over: usize,
    /// Instances (one region each) of under-segmentation.
    pub under: usize,
    pub missed: usize,
    /// Each missed face: the share of it that regions lying at T inside it cover (0 when
    /// none does). Near T, the face was found but under-grown or broken up; near 0, no
    /// region stood for it.
    pub missed_cover: BTreeMap<u32, f64>,
    pub noise: usize,
    /// Per pair of touching faces both detected correctly: |truth angle - machine angle|.
    pub angle_errors: Vec<AngleError>,
}

/// Scores `machine` against `truth.faces` at `tolerance`. `machine_normals[m]` is region m's
/// plane normal facing the camera, as the truth's, for the angle errors.
pub fn hoover(
    truth: &FaceTruth,
    machine: &[u32],
    machine_normals: &BTreeMap<u32, [f64; 3]>,
    tolerance: f64,
) -> HooverScore {
    assert!(tolerance > 0.5 && tolerance <= 1.0, "Hoover's tolerance lies in (0.5, 1]");
    assert_eq!(machine.len(), truth.faces.len(), "the segmentation and the truth differ in size");
    let mut face_size: BTreeMap<u32, usize> = BTreeMap::new();
    let mut region_size: BTreeMap<u32, usize> = BTreeMap::new();
    let mut overlap: BTreeMap<(u32, u32), usize> = BTreeMap::new();
    for (&n, &m) in truth.faces.iter().zip(machine) {
        if n != 0 {
            *face_size.entry(n).or_default() += 1;
        }
        if m != 0 {
            *region_size.entry(m).or_default() += 1;
        }
        if n != 0 && m != 0 {
            *overlap.entry((m, n)).or_default() += 1;
        }
    }
    let at = |o: usize, size: usize| o as f64 >= tolerance * size as f64;
    let mut used_faces = BTreeSet::new();
    let mut used_regions = BTreeSet::new();
    let mut score =
        HooverScore { truth_faces: face_size.len(), machine_regions: region_size.len(), ..Default::default() };

    let mut pairs = BTreeMap::new();
    for (&(m, n), &o) in &overlap {
        if at(o, region_size[&m]) && at(o, face_size[&n]) && !used_faces.contains(&n) && !used_regions.contains(&m) {
            used_faces.insert(n);
            used_regions.insert(m);
            pairs.insert(n, m);
            score.faces.insert(n, Outcome::Correct);
            score.correct += 1;
        }
    }
    // One region of one side split among two or more of the other's, each at T inside it and
    // together covering it at T: the parts, given (part, overlap, part's size).
    let split = |size: usize, parts: Vec<(u32, usize, usize)>| -> Option<Vec<u32>> {
        let inside: Vec<(u32, usize, usize)> = parts.into_iter().filter(|&(_, o, part)| at(o, part)).collect();
        (inside.len() >= 2 && at(inside.iter().map(|p| p.1).sum(), size)).then(|| inside.iter().map(|p| p.0).collect())
    };
    for (&n, &size) in &face_size {
        if used_faces.contains(&n) {
            continue;
        }
        let parts = overlap.iter().filter(|&(&(m, f), _)| f == n && !used_regions.contains(&m));
        if let Some(regions) = split(size, parts.map(|(&(m, _), &o)| (m, o, region_size[&m])).collect()) {
            used_faces.insert(n);
            used_regions.extend(regions);
            score.faces.insert(n, Outcome::Over);
            score.over += 1;
        }
    }
    for (&m, &size) in &region_size {
        if used_regions.contains(&m) {
            continue;
        }
        let parts = overlap.iter().filter(|&(&(r, n), _)| r == m && !used_faces.contains(&n));
        if let Some(faces) = split(size, parts.map(|(&(_, n), &o)| (n, o, face_size[&n])).collect()) {
            used_regions.insert(m);
            score.faces.extend(faces.iter().map(|&n| (n, Outcome::Under)));
            used_faces.extend(faces);
            score.under += 1;
        }
    }
    for (&n, &size) in &face_size {
        if *score.faces.entry(n).or_insert(Outcome::Missed) == Outcome::Missed {
            let inside = overlap.iter().filter(|&(&(m, f), &o)| f == n && at(o, region_size[&m]));
            score.missed_cover.insert(n, inside.map(|(_, &o)| o).sum::<usize>() as f64 / size as f64);
        }
    }
    score.noise_regions = region_size.keys().filter(|m| !used_regions.contains(m)).copied().collect();
    score.missed = face_size.len() - used_faces.len();
    score.noise = score.noise_regions.len();

    let angle = |a: &[f64; 3], b: &[f64; 3]| Vector3::from(*a).angle(&Vector3::from(*b)).to_degrees();
    for (a, b) in touching_faces(truth) {
        let (Some(ma), Some(mb)) = (pairs.get(&a), pairs.get(&b)) else { continue };
        let (Some(ta), Some(tb)) = (truth.normals.get(&a), truth.normals.get(&b)) else { continue };
        let (Some(na), Some(nb)) = (machine_normals.get(ma), machine_normals.get(mb)) else { continue };
        score.angle_errors.push(AngleError { faces: (a, b), error_deg: (angle(ta, tb) - angle(na, nb)).abs() });
    }
    score
}

/// Pairs of faces (a < b) whose pixels come within `TOUCH_PX` of each other.
fn touching_faces(truth: &FaceTruth) -> BTreeSet<(u32, u32)> {
    let (w, h) = (truth.width, truth.height);
    let mut pairs = BTreeSet::new();
    for y in 0..h {
        for x in 0..w {
            let a = truth.faces[y * w + x];
            if a == 0 {
                continue;
            }
            // Looking forward only (right, and rows below) finds every pair once either way.
            for yy in y..(y + TOUCH_PX + 1).min(h) {
                let from = if yy == y { x + 1 } else { x.saturating_sub(TOUCH_PX) };
                for xx in from..(x + TOUCH_PX + 1).min(w) {
                    let b = truth.faces[yy * w + xx];
                    if b != 0 && b != a {
                        pairs.insert((a.min(b), a.max(b)));
                    }
                }
            }
        }
    }
    pairs
}

/// Machine normals facing the camera, as the truth's, so angles compare: polygon k + 1.
pub fn polygon_normals(polygons: &[Polygon]) -> BTreeMap<u32, [f64; 3]> {
    polygons
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let n = if p.offset < 0.0 { -Vector3::from(p.normal) } else { Vector3::from(p.normal) };
            (k as u32 + 1, [n.x, n.y, n.z])
        })
        .collect()
}

/// Per-image scores averaged over images; the fewest correct in one image, and the angle
/// errors over every pair of every image.
#[derive(Clone, Debug, Serialize)]
pub struct HooverSummary {
    pub tolerance: f64,
    pub images: usize,
    pub truth_faces: f64,
    pub machine_regions: f64,
    pub correct: f64,
    pub over: f64,
    pub under: f64,
    pub missed: f64,
    /// Of the missed faces, those that regions lying inside them cover at least half of.
    pub missed_half_covered: f64,
    pub noise: f64,
    pub correct_min: usize,
    pub angle_error_mean_deg: f64,
    pub angle_error_max_deg: f64,
    pub angle_pairs: usize,
}

pub fn summarise(scores: &[HooverScore], tolerance: f64) -> HooverSummary {
    let mean = |f: fn(&HooverScore) -> usize| scores.iter().map(|s| f(s) as f64).sum::<f64>() / scores.len() as f64;
    let angles: Vec<f64> = scores.iter().flat_map(|s| s.angle_errors.iter().map(|a| a.error_deg)).collect();
    HooverSummary {
        tolerance,
        images: scores.len(),
        truth_faces: mean(|s| s.truth_faces),
        machine_regions: mean(|s| s.machine_regions),
        correct: mean(|s| s.correct),
        over: mean(|s| s.over),
        under: mean(|s| s.under),
        missed: mean(|s| s.missed),
        missed_half_covered: mean(|s| s.missed_cover.values().filter(|&&c| c >= 0.5).count()),
        noise: mean(|s| s.noise),
        correct_min: scores.iter().map(|s| s.correct).min().unwrap_or(0),
        angle_error_mean_deg: super::mean_std(&angles).0,
        angle_error_max_deg: angles.iter().copied().fold(f64::NAN, f64::max),
        angle_pairs: angles.len(),
    }
}

/// Left, the truth faces by outcome (green correct, blue over-, magenta under-segmented, red
/// missed), outlined; right, the machine regions, each its own colour, noise in dark red.
pub fn picture(truth: &FaceTruth, machine: &[u32], score: &HooverScore) -> image::RgbImage {
    let (w, h) = (truth.width as u32, truth.height as u32);
    let mut img = image::RgbImage::new(2 * w + 8, h);
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let face = match score.faces.get(&truth.faces[i]) {
                _ if truth.faces[i] == 0 => [0, 0, 0],
                Some(Outcome::Correct) => [40, 180, 60],
                Some(Outcome::Over) => [50, 90, 230],
                Some(Outcome::Under) => [210, 60, 210],
                Some(Outcome::Missed) | None => [220, 40, 30],
            };
            // Where the face changes to the right or below, a dark line, so faces of one
            // outcome stay apart.
            let edge = (x + 1 < w && truth.faces[i + 1] != truth.faces[i])
                || (y + 1 < h && truth.faces[i + w as usize] != truth.faces[i]);
            img.put_pixel(x, y, image::Rgb(if edge { face.map(|c| c / 3) } else { face }));
            let m = machine[i];
            let region = if m == 0 {
                [0, 0, 0]
            } else if score.noise_regions.contains(&m) {
                [120, 20, 20]
            } else {
                // A spread of hues that neighbours rarely share.
                let k = m.wrapping_mul(2654435761);
                [90 + (k >> 24) as u8 % 160, 90 + (k >> 16) as u8 % 160, 90 + (k >> 8) as u8 % 160]
            };
            img.put_pixel(w + 8 + x, y, image::Rgb(region));
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 10x4 truth of two faces side by side (ids 10 and 11) at a right angle.
    fn two_faces() -> FaceTruth {
        let faces = (0..40).map(|i| if i % 10 < 5 { 10 } else { 11 }).collect();
        let normals = BTreeMap::from([(10, [0.0, 0.0, -1.0]), (11, [1.0, 0.0, 0.0])]);
        FaceTruth { width: 10, height: 4, faces, normals }
    }

    fn normals(n: &[(u32, [f64; 3])]) -> BTreeMap<u32, [f64; 3]> {
        n.iter().copied().collect()
    }

    #[test]
    fn the_truth_scored_against_itself_is_all_correct_with_no_angle_error() {
        let t = two_faces();
        let s = hoover(&t, &t.faces, &t.normals, 0.8);
        assert_eq!((s.correct, s.over, s.under, s.missed, s.noise), (2, 0, 0, 0, 0));
        assert_eq!(s.angle_errors, vec![AngleError { faces: (10, 11), error_deg: 0.0 }]);
    }

    #[test]
    fn a_face_cut_in_two_is_over_segmented_and_one_region_over_both_is_under_segmented() {
        let t = two_faces();
        // Face 10 split into rows 0-1 and rows 2-3; face 11 whole.
        let split: Vec<u32> = (0..40)
            .map(|i| {
                if i % 10 >= 5 {
                    3
                } else if i < 20 {
                    1
                } else {
                    2
                }
            })
            .collect();
        let s = hoover(&t, &split, &normals(&[]), 0.8);
        assert_eq!((s.correct, s.over, s.under, s.missed, s.noise), (1, 1, 0, 0, 0));
        let merged = vec![7u32; 40];
        let s = hoover(&t, &merged, &normals(&[]), 0.8);
        assert_eq!((s.correct, s.over, s.under, s.missed, s.noise), (0, 0, 1, 0, 0));
    }

    #[test]
    fn the_tolerance_decides_and_what_is_left_is_missed_or_noise() {
        let t = two_faces();
        // Region 1 is face 10 less one column (16 of its 20 pixels: 80 %); region 2 covers
        // one column of face 11 only (4 of 20 pixels).
        let m: Vec<u32> = (0..40)
            .map(|i| match i % 10 {
                0..=3 => 1,
                5 => 2,
                _ => 0,
            })
            .collect();
        let s = hoover(&t, &m, &normals(&[]), 0.8);
        assert_eq!((s.correct, s.missed, s.noise), (1, 1, 1));
        // Face 11's missing: region 2 lies inside it, covering a fifth.
        assert_eq!(s.missed_cover, BTreeMap::from([(11, 0.2)]));
        let s = hoover(&t, &m, &normals(&[]), 0.81);
        assert_eq!((s.correct, s.missed, s.noise), (0, 2, 2));
        assert_eq!(s.missed_cover, BTreeMap::from([(10, 0.8), (11, 0.2)]));
    }

    #[test]
    fn the_angle_error_is_the_difference_of_the_angles_between_touching_faces() {
        let t = two_faces();
        // The machine sees the two faces at 80 deg instead of 90.
        let a = 80f64.to_radians();
        let n = normals(&[(10, [0.0, 0.0, -1.0]), (11, [a.sin(), 0.0, -a.cos()])]);
        let s = hoover(&t, &t.faces, &n, 0.8);
        assert_eq!(s.angle_errors.len(), 1);
        assert!((s.angle_errors[0].error_deg - 10.0).abs() < 1e-9, "{:?}", s.angle_errors);
    }
}
