//! Offline mapping of a recorded sequence: every frame extracted and merged with its pose
//! from poses.txt, the map snapshotted on the configured period and at the end.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};

use crate::config::Config;
use crate::extract::Extractor;
use crate::map::{MapUpdate, PolygonMap, persist};
use crate::sequence::Sequence;

/// A map to start from: the configured snapshot when `map.load_at_start` is set and it
/// exists, else empty. A corrupt snapshot is moved aside, logged, and the map starts empty.
pub fn initial_map(config: &Config) -> PolygonMap {
    let m = &config.map;
    if !m.load_at_start || m.snapshot_path.as_os_str().is_empty() || !m.snapshot_path.exists() {
        return PolygonMap::new(m);
    }
    match persist::load(&m.snapshot_path, |s| PolygonMap::from_snapshot(m, s)) {
        Ok(map) => {
            tracing::info!("map loaded from {}: {} polygons", m.snapshot_path.display(), map.len());
            map
        }
        Err(e) => {
            tracing::error!("{e}; starting with an empty map");
            PolygonMap::new(m)
        }
    }
}

/// Saves the map where the config says, if it says.
pub fn save_snapshot(map: &mut PolygonMap, config: &Config) -> Result<()> {
    let path = &config.map.snapshot_path;
    if path.as_os_str().is_empty() {
        return Ok(());
    }
    write_snapshot(&map.snapshot(), path)
}

/// Writes a snapshot atomically, the error naming the file.
pub fn write_snapshot(snapshot: &crate::map::MapSnapshot, path: &Path) -> Result<()> {
    persist::save(snapshot, path).with_context(|| format!("saving the map to {}", path.display()))
}

/// Removes the temporary files a crashed writer left beside the configured snapshot.
pub fn remove_stale_snapshot_temps(config: &Config) {
    let path = &config.map.snapshot_path;
    if !path.as_os_str().is_empty() {
        for stale in persist::remove_stale_temps(path) {
            tracing::info!("removed {}, left by a write that never finished", stale.display());
        }
    }
}

/// Maps every frame of `seq` into `map`; `on_frame(k, update)` sees each frame's changes.
pub fn replay(
    seq: &Sequence,
    config: &Config,
    map: &mut PolygonMap,
    mut on_frame: impl FnMut(usize, &MapUpdate),
) -> Result<()> {
    let mut extractor = Extractor::new(&config.pipeline)?;
    let period = std::time::Duration::from_secs_f64(config.map.snapshot_period_s);
    let mut last_save = Instant::now();
    for k in 0..seq.len() {
        let depth = seq.depth(k)?;
        let (frame, stages, _) = extractor.extract(&depth, &seq.intrinsics)?;
        let update = map.update(&frame.polygons, &seq.poses[k].transform, &seq.intrinsics, Some(&stages.depth));
        on_frame(k, &update);
        if last_save.elapsed() >= period {
            save_snapshot(map, config)?;
            last_save = Instant::now();
        }
    }
    save_snapshot(map, config)
}

/// Writes the map's JSON to `path`.
pub fn write_json(map: &mut PolygonMap, path: &Path) -> Result<()> {
    let json = serde_json::to_string_pretty(&map.snapshot())?;
    std::fs::write(path, json).with_context(|| format!("writing {}", path.display()))
}
