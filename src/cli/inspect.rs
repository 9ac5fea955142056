//! `polymap inspect`: what a sequence or a log holds.

use std::path::Path;

use anyhow::{Context, Result};

use super::progress;
use crate::logs::{Log, LogTopics};
use crate::sequence::Sequence;
use crate::viz;

/// What a log holds, and what of it a replay with `topics` would map.
pub fn summarise_log(log: &Log, topics: &LogTopics) -> Result<()> {
    let scan = crate::logs::scan(log, &topics.odometry)?;
    let files = if log.files.len() > 1 { format!(" ({} files)", log.files.len()) } else { String::new() };
    println!("{}: {:?}{files}, {} topics", log.path.display(), log.kind, scan.topics.len());
    for (topic, t) in &scan.topics {
        let span_s = (t.last_ns - t.first_ns) as f64 * 1e-9;
        let rate = if span_s > 0.0 { format!(", {:.1} Hz", (t.count - 1) as f64 / span_s) } else { String::new() };
        let role = [(&topics.depth, "depth"), (&topics.camera_info, "camera_info"), (&topics.odometry, "odometry")]
            .iter()
            .find(|(name, _)| *name == topic)
            .map_or(String::new(), |(_, role)| format!("  <- {role}"));
        println!("  {topic} ({}): {} messages over {span_s:.1} s{rate}{role}", t.message_type, t.count);
    }
    let missing: Vec<&str> = [&topics.depth, &topics.camera_info, &topics.odometry]
        .into_iter()
        .filter(|t| scan.count(t) == 0)
        .map(String::as_str)
        .collect();
    match missing.is_empty() {
        true => println!(
            "  {} poses ({} refused); replay maps the depth images with a pose",
            scan.poses.len(),
            scan.poses_refused
        ),
        false => println!(
            "  missing for a replay: {} (see --depth-topic, --camera-info-topic, --odometry-topic)",
            missing.join(", ")
        ),
    }
    Ok(())
}

pub fn summarise(s: &Sequence) -> Result<()> {
    let i = &s.intrinsics;
    let first = s.poses.first().map_or(0, |p| p.stamp_ns);
    let last = s.poses.last().map_or(0, |p| p.stamp_ns);
    let mut valid = 0usize;
    for k in 0..s.len() {
        valid += s.depth(k)?.pixels.iter().filter(|&&d| d != 0).count();
    }
    println!(
        "{}: {} frames, {}x{}, fx {:.3} fy {:.3} cx {:.3} cy {:.3}, depth unit {} m",
        s.dir.display(),
        s.len(),
        i.width,
        i.height,
        i.fx,
        i.fy,
        i.cx,
        i.cy,
        i.depth_scale
    );
    println!(
        "  {:.3} s of stamps, {:.1} % of pixels valid",
        (last - first) as f64 * 1e-9,
        100.0 * valid as f64 / (s.len() * i.pixel_count()) as f64
    );
    match &s.truth {
        Some(t) => println!(
            "  truth: {} polygons{}, labels: {}",
            t.polygons.len(),
            t.stair
                .as_ref()
                .map(|st| format!(
                    " ({} stair, {} steps, rise {} m, going {:.3} m)",
                    st.kind, st.steps, st.rise, st.going
                ))
                .unwrap_or_default(),
            if s.has_labels { "yes" } else { "no" }
        ),
        None => println!("  no truth"),
    }
    Ok(())
}

/// One PNG per frame: depth in colour, and beside it the truth labels if the sequence has them.
pub fn write_previews(s: &Sequence, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let i = &s.intrinsics;
    let bar = progress(s.len() as u64, "preview");
    for k in 0..s.len() {
        let depth = s.depth(k)?;
        let mut panels = vec![viz::depth_units_image(i.width, i.height, &depth.pixels, i.depth_scale)];
        if s.has_labels {
            let labels = s.labels(k)?;
            panels.push(viz::label_image(i.width, i.height, &labels));
        }
        let refs: Vec<_> = panels.iter().collect();
        let path = dir.join(format!("{k:06}.png"));
        viz::side_by_side(&refs).save(&path).with_context(|| format!("writing {}", path.display()))?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    println!("previews in {}", dir.display());
    Ok(())
}
