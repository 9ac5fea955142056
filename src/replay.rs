//! Offline mapping of a recorded sequence: every frame extracted and merged with its pose
//! from poses.txt, the map snapshotted on the configured period and at the end.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};

use crate::config::Config;
use crate::extract::{Extraction, Extractor};
use crate::map::{MapUpdate, PolygonMap, persist};
use crate::sequence::Sequence;

/// Maps every frame of `seq` into `map`; `on_frame(k, update, map)` sees each frame's changes.
pub fn replay(
    seq: &Sequence,
    config: &Config,
    map: &mut PolygonMap,
    mut on_frame: impl FnMut(usize, &MapUpdate, &PolygonMap),
) -> Result<()> {
    let mut extractor = Extractor::new(&config.pipeline)?;
    let period = std::time::Duration::from_secs_f64(config.map.snapshot_period_s);
    let mut last_save = Instant::now();
    for k in 0..seq.len() {
        let depth = seq.depth(k)?;
        let Extraction { polygons, depth, .. } = extractor.extract(&depth, &seq.intrinsics)?;
        let update = map.update(&polygons.polygons, &seq.poses[k], &seq.intrinsics, Some(&depth));
        on_frame(k, &update, map);
        if last_save.elapsed() >= period {
            persist::save_configured(map, &config.map)?;
            last_save = Instant::now();
        }
    }
    persist::save_configured(map, &config.map)
}

/// Writes the map's JSON to `path`.
pub fn write_json(map: &mut PolygonMap, path: &Path) -> Result<()> {
    let json = serde_json::to_string_pretty(&map.snapshot())?;
    std::fs::write(path, json).with_context(|| format!("writing {}", path.display()))
}
