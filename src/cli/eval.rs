//! `polymap eval`: a sequence's frames, its map, or per-pixel plane truth, scored.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use super::progress;
use crate::config::Config;
use crate::sequence::Sequence;
use crate::{eval, extract};

/// `polymap eval SEQ`: extracts every frame and scores its treads against the truth.
pub fn evaluate(s: &Sequence, config: &Config, json: bool, debug: Option<&Path>) -> Result<()> {
    let Some(truth) = &s.truth else { bail!("{} has no truth.json to evaluate against", s.dir.display()) };
    if !s.has_labels {
        bail!("{} has no labels/: single-frame IOU needs them", s.dir.display());
    }
    let rise = truth.stair.as_ref().map_or(f64::NAN, |st| st.rise);
    let mut extractor = extract::Extractor::new(&config.pipeline)?;
    let bar = progress(s.len() as u64, "eval");
    let (mut scores, mut level, mut held_back) = (Vec::new(), Vec::new(), Vec::new());
    for k in 0..s.len() {
        let extraction = extractor.extract(&s.depth(k)?, &s.intrinsics)?;
        let (result, pose) = (extraction.polygons, &s.poses[k].transform);
        let labels = s.labels(k)?;
        scores.extend(eval::score_frame(k, &result.polygons, pose, &labels, truth, &s.intrinsics));
        level.extend(eval::level_tilts(k, &result.polygons, pose));
        held_back.extend(eval::level_held_back(&extraction.stages.held_back, pose));
        if let Some(dir) = debug {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            let path = dir.join(format!("{k:06}.png"));
            eval::match_image(&result.polygons, &labels, truth, &s.intrinsics)
                .save(&path)
                .with_context(|| format!("writing {}", path.display()))?;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let summary = eval::summarise(&scores, rise);
    let level = eval::summarise_level(&level, &held_back);
    if json {
        let all = serde_json::json!({ "treads": scores, "summary": summary, "level": level });
        println!("{}", serde_json::to_string_pretty(&all)?);
        return Ok(());
    }
    println!(
        "{}: {} frames {}x{}, treads with >= {} visible pixels",
        s.dir.display(),
        s.len(),
        s.intrinsics.width,
        s.intrinsics.height,
        eval::min_visible_pixels(s.intrinsics.pixel_count())
    );
    println!(
        "{:>5} {:>7} {:>6} {:>10} {:>10} {:>9} {:>9}",
        "step", "frames", "found", "alpha deg", "IOU mean", "IOU min", "height m"
    );
    let max_step = scores.iter().map(|t| t.step).max().unwrap_or(0);
    for step in 0..=max_step {
        let of: Vec<_> = scores.iter().filter(|t| t.step == step).collect();
        if of.is_empty() {
            continue;
        }
        let alpha: Vec<f64> = of.iter().filter_map(|t| t.alpha_deg).collect();
        let ious: Vec<f64> = of.iter().map(|t| t.iou).collect();
        let heights: Vec<f64> = of.iter().filter_map(|t| t.height).collect();
        println!(
            "{:>5} {:>7} {:>6} {:>10.3} {:>10.3} {:>9.3} {:>9.4}",
            step,
            of.len(),
            of.iter().filter(|t| t.found).count(),
            eval::mean_std(&alpha).0,
            eval::mean_std(&ious).0,
            ious.iter().copied().fold(f64::NAN, f64::min),
            eval::mean_std(&heights).0
        );
    }
    let m = &summary;
    println!(
        "treads found {}/{}; alpha mean {:.3} deg, std {:.3} deg; IOU mean {:.3} (min {:.3}); step-height error mean {:.2} mm, std {:.2} mm over {} pairs",
        m.treads_found,
        m.treads_in_view,
        m.alpha_mean_deg,
        m.alpha_std_deg,
        m.iou_mean,
        m.iou_min,
        m.step_error_mean_mm,
        m.step_error_std_mm,
        m.step_pairs
    );
    let worst = |w: Option<eval::LevelTilt>| {
        w.map_or("-".into(), |w| {
            format!(
                "{:.3} deg (frame {}, polygon {}: {:.3} m2, {} px)",
                w.tilt_deg, w.frame, w.polygon, w.area_m2, w.pixels
            )
        })
    };
    for (which, t) in [("published", &level.all), ("steppable", &level.steppable)] {
        println!(
            "level polygons {which} (>= {} m2, within {} deg of level), every frame: {}; tilt mean {:.3} deg, p99 {:.3} deg, worst {}",
            eval::LEVEL_MIN_AREA_M2,
            eval::LEVEL_WITHIN_DEG,
            t.polygons,
            t.tilt_mean_deg,
            t.tilt_p99_deg,
            worst(t.worst.clone())
        );
    }
    let count = |c: eval::PolygonCount| format!("{} ({:.2} m2)", c.polygons, c.area_m2);
    println!(
        "level polygons marked not steppable: tilt not known to {} deg at 95 % {}, under {} px {}",
        extract::uncertainty::STEPPABLE_TILT_DEG,
        count(level.tilt_unknown),
        extract::uncertainty::MIN_STEPPABLE_PIXELS,
        count(level.few_pixels),
    );
    println!(
        "level polygons held back: not one plane {}, no plane {}",
        count(level.not_one_plane),
        count(level.no_plane)
    );
    let big = eval::MIN_STEPPABLE_TREAD_PIXELS_320 * s.intrinsics.pixel_count() / (320 * 240);
    let (deep, strips): (Vec<&eval::TreadScore>, Vec<&eval::TreadScore>) =
        scores.iter().filter(|t| t.visible_pixels >= big).partition(|t| t.visible_depth_m >= eval::FOOT_WIDTH_M);
    for (treads, which) in [(deep, "at least"), (strips, "under")] {
        println!(
            "treads with >= {big} visible pixels, seen {which} {} m deep: {}, found {}, found and steppable {}",
            eval::FOOT_WIDTH_M,
            treads.len(),
            treads.iter().filter(|t| t.found).count(),
            treads.iter().filter(|t| t.footing.is_some_and(|f| f.is_steppable())).count()
        );
    }
    Ok(())
}

/// `polymap eval SEQ --segmentation`: every frame's polygons against per-pixel plane truth,
/// scored with Hoover et al.'s metric; SEQ is one such sequence or a folder of them.
pub fn evaluate_segmentation(
    dir: &Path,
    config: &Config,
    tolerance: f64,
    json: bool,
    debug: Option<&Path>,
) -> Result<()> {
    use eval::segmentation::{FaceTruth, hoover, polygon_normals, polygon_regions};
    let dirs = if dir.join("camera.toml").exists() {
        vec![dir.to_path_buf()]
    } else {
        let mut dirs: Vec<PathBuf> = std::fs::read_dir(dir)
            .with_context(|| format!("reading {}", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.join("labels.png").exists())
            .collect();
        // Natural order, so abw.test.10 comes after abw.test.9.
        dirs.sort_by_key(|p| {
            let name = p.file_name().unwrap_or_default().to_string_lossy().to_string();
            let digits = name.len() - name.trim_end_matches(|c: char| c.is_ascii_digit()).len();
            (name[..name.len() - digits].to_string(), name[name.len() - digits..].parse::<u64>().unwrap_or(0))
        });
        dirs
    };
    if dirs.is_empty() {
        bail!("{}: no sequence with labels.png and planes.txt in it", dir.display());
    }
    let mut extractor = extract::Extractor::new(&config.pipeline)?;
    let mut rows = Vec::new();
    for d in &dirs {
        let s = Sequence::open(d)?;
        let truth = FaceTruth::open(d)?;
        if (truth.width, truth.height) != (s.intrinsics.width as usize, s.intrinsics.height as usize) {
            bail!(
                "{}: labels.png is {}x{}, the camera {}x{}",
                d.display(),
                truth.width,
                truth.height,
                s.intrinsics.width,
                s.intrinsics.height
            );
        }
        for k in 0..s.len() {
            let depth = s.depth(k)?;
            let result = extractor.extract(&depth, &s.intrinsics)?.polygons;
            let regions = polygon_regions(&result.polygons, &depth, &s.intrinsics);
            let score = hoover(&truth, &regions, &polygon_normals(&result.polygons), tolerance);
            let name = if s.len() == 1 { d.display().to_string() } else { format!("{} frame {k}", d.display()) };
            if let Some(out) = debug {
                std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
                let path = out.join(format!("{}_{k:06}.png", d.file_name().unwrap_or_default().to_string_lossy()));
                eval::segmentation::picture(&truth, &regions, &score)
                    .save(&path)
                    .with_context(|| format!("writing {}", path.display()))?;
            }
            rows.push((name, score));
        }
    }
    let scores: Vec<_> = rows.iter().map(|(_, s)| s.clone()).collect();
    let summary = eval::segmentation::summarise(&scores, tolerance);
    if json {
        let images: Vec<_> = rows.iter().map(|(name, s)| serde_json::json!({ "image": name, "score": s })).collect();
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({ "images": images, "summary": summary }))?);
        return Ok(());
    }
    println!("Hoover et al. 1996 at T = {tolerance}: per image, truth faces and how they came out");
    println!(
        "{:<40} {:>6} {:>7} {:>8} {:>5} {:>6} {:>7} {:>6} {:>10}",
        "image", "faces", "regions", "correct", "over", "under", "missed", "noise", "angle deg"
    );
    let row = |name: &str, s: [f64; 7], angle: f64| {
        println!(
            "{:<40} {:>6.1} {:>7.1} {:>8.1} {:>5.1} {:>6.1} {:>7.1} {:>6.1} {:>10.2}",
            name, s[0], s[1], s[2], s[3], s[4], s[5], s[6], angle
        )
    };
    for (name, s) in &rows {
        let c = |v: usize| v as f64;
        let short = name.rsplit('/').next().unwrap_or(name);
        row(
            short,
            [c(s.truth_faces), c(s.machine_regions), c(s.correct), c(s.over), c(s.under), c(s.missed), c(s.noise)],
            eval::mean_std(&s.angle_errors.iter().map(|a| a.error_deg).collect::<Vec<_>>()).0,
        );
    }
    let m = &summary;
    row(
        "mean",
        [m.truth_faces, m.machine_regions, m.correct, m.over, m.under, m.missed, m.noise],
        m.angle_error_mean_deg,
    );
    println!(
        "correct {:.1} of {:.1} faces per image ({:.0} %), fewest in one image {}; angle error mean {:.2} deg, max {:.2} over {} pairs",
        m.correct,
        m.truth_faces,
        100.0 * m.correct / m.truth_faces,
        m.correct_min,
        m.angle_error_mean_deg,
        m.angle_error_max_deg,
        m.angle_pairs
    );
    println!(
        "missed {:.1} faces per image: {:.1} of them half covered or more by regions inside them (under-grown or broken up), the rest by none",
        m.missed, m.missed_half_covered
    );
    Ok(())
}

/// `polymap eval SEQ --map FILE`: the final map against the truth.
pub fn evaluate_map(s: &Sequence, path: &Path, json: bool, debug: Option<&Path>) -> Result<()> {
    if s.truth.is_none() || !s.has_labels {
        bail!("{} needs truth.json and labels/ to score a map", s.dir.display());
    }
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let map: crate::map::MapSnapshot =
        serde_json::from_str(&text).with_context(|| format!("{} is not a polymap map", path.display()))?;
    let (scores, pictures) = eval::map::score_map(&map, s, debug.is_some())?;
    if let Some(dir) = debug {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        for (t, img) in scores.iter().zip(&pictures) {
            let path = dir.join(format!("step_{:02}.png", t.step));
            img.save(&path).with_context(|| format!("writing {}", path.display()))?;
        }
    }
    let summary = eval::map::summarise(&scores, &map, s);
    if json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({ "treads": scores, "summary": summary }))?);
        return Ok(());
    }
    println!("{} against {}: {} map polygons", path.display(), s.dir.display(), map.polygons.len());
    println!(
        "{:>5} {:>9} {:>8} {:>7} {:>9} {:>9} {:>10} {:>10} {:>13} {:>12}",
        "step", "seen m2", "polygon", "IOU", "over m2", "under m2", "alpha deg", "height m", "height err mm", "footing"
    );
    for t in &scores {
        println!(
            "{:>5} {:>9.4} {:>8} {:>7.3} {:>9.4} {:>9.4} {:>10.3} {:>10.4} {:>13.2} {:>12}",
            t.step,
            t.seen_area_m2,
            t.polygon.map_or("-".into(), |id| id.to_string()),
            t.iou,
            t.over_m2,
            t.under_m2,
            t.alpha_deg.unwrap_or(f64::NAN),
            t.height.unwrap_or(f64::NAN),
            t.height_error.map_or(f64::NAN, |e| e * 1e3),
            t.footing.map_or("-".into(), |f| format!("{f:?}"))
        );
    }
    let m = &summary;
    println!(
        "treads found {}/{}; IOU mean {:.3} (min {:.3}); alpha mean {:.3} deg, std {:.3} deg; step-height error mean {:.2} mm, std {:.2} mm; height error mean {:.2} mm, max {:.2} mm; drift estimate off by {:.2} mm (horizontally {:.2} mm, in yaw {:.3} deg)",
        m.treads_found,
        m.treads_seen,
        m.iou_mean,
        m.iou_min,
        m.alpha_mean_deg,
        m.alpha_std_deg,
        m.step_error_mean_mm,
        m.step_error_std_mm,
        m.height_error_mean_mm,
        m.height_error_max_mm,
        m.drift_error_mm,
        m.drift_error_xy_mm,
        m.drift_error_yaw_deg
    );
    println!(
        "steppable treads {}/{}, worst tilt {:.3} deg; level map polygons (>= {} m2, within {} deg of level) {}, steppable {}, worst steppable tilt {:.3} deg",
        m.treads_steppable,
        m.treads_found,
        m.steppable_tread_alpha_max_deg,
        eval::LEVEL_MIN_AREA_M2,
        eval::LEVEL_WITHIN_DEG,
        m.level_polygons,
        m.level_steppable,
        m.level_steppable_tilt_max_deg
    );
    Ok(())
}
