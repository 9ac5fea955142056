//! `polymap extract`: one frame of a sequence through the extraction, its polygons as JSON
//! (camera or world frame) and, if asked, a picture of every stage.

use std::path::Path;

use anyhow::{Context, Result, bail};

use crate::config::Config;
use crate::extract::{self, Extractor};
use crate::sequence::Sequence;

/// Extracts frame `frame` of the sequence at `seq`, writing the polygons' JSON to `out`
/// (stdout without), in the world frame with `world`, the stage pictures into `debug`.
pub fn extract_frame(
    seq: &Path,
    frame: usize,
    config: &Config,
    world: bool,
    debug: Option<&Path>,
    out: Option<&Path>,
) -> Result<()> {
    let s = Sequence::open(seq)?;
    if frame >= s.len() {
        bail!("--frame {frame}: {} has frames 0..{}", seq.display(), s.len());
    }
    let depth = s.depth(frame)?;
    let mut extractor = Extractor::new(&config.pipeline)?;
    extractor.keep_images = debug.is_some();
    let extraction = extractor.extract(&depth, &s.intrinsics)?;
    let count = extraction.polygons.polygons.len();
    tracing::info!("frame {frame}: {count} polygons in {:.1} ms", extraction.times.total);
    if let Some(dir) = debug {
        extract::debug::write_stage_images(dir, &extraction, &s.intrinsics)?;
        // Not on stdout: without --out, stdout carries the JSON alone.
        tracing::info!("stage pictures in {}", dir.display());
    }
    let result = extraction.polygons;
    let polygons: Vec<_> = if world {
        result.polygons.iter().map(|p| p.transformed(&s.poses[frame].transform)).collect()
    } else {
        result.polygons
    };
    let json = serde_json::to_string_pretty(&serde_json::json!({
        "frame": if world { "world" } else { "camera" },
        "stamp_ns": result.stamp_ns,
        "polygons": polygons,
    }))?;
    match out {
        Some(path) => std::fs::write(path, json).with_context(|| format!("writing {}", path.display()))?,
        None => println!("{json}"),
    }
    Ok(())
}
