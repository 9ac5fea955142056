//! Saving and loading the map. A save writes a temporary file beside the target, syncs it
//! and renames it over the target, so a crash at any moment leaves the last whole snapshot.
//! A file that does not load is moved aside (never overwritten) and reported.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use super::{MapSnapshot, PolygonMap};
use crate::config::MapConfig;

/// Where the config saves the map; None: nowhere (`map.snapshot_path = ""`).
pub fn snapshot_path(cfg: &MapConfig) -> Option<&Path> {
    Some(cfg.snapshot_path.as_path()).filter(|p| !p.as_os_str().is_empty())
}

/// The map to start from: the configured snapshot when `map.load_at_start` is set and it
/// exists, else empty. A corrupt snapshot is moved aside, logged, and the map starts empty.
pub fn initial_map(cfg: &MapConfig) -> PolygonMap {
    let Some(path) = snapshot_path(cfg).filter(|p| cfg.load_at_start && p.exists()) else {
        return PolygonMap::new(cfg);
    };
    match load(path, |s| PolygonMap::from_snapshot(cfg, s).map_err(|e| e.to_string())) {
        Ok(map) => {
            tracing::info!("map loaded from {}: {} polygons", path.display(), map.len());
            map
        }
        Err(e) => {
            tracing::error!("{e}; starting with an empty map");
            PolygonMap::new(cfg)
        }
    }
}

/// [`save`], the error naming the file.
pub fn save_to(snapshot: &MapSnapshot, path: &Path) -> anyhow::Result<()> {
    use anyhow::Context;
    save(snapshot, path).with_context(|| format!("saving the map to {}", path.display()))
}

/// Saves `map` where the config says (`map.snapshot_path`), if it says.
pub fn save_configured(map: &mut PolygonMap, cfg: &MapConfig) -> anyhow::Result<()> {
    match snapshot_path(cfg) {
        Some(path) => save_to(&map.snapshot(), path),
        None => Ok(()),
    }
}

/// Removes the temporary files a crashed writer left beside the configured snapshot.
pub fn remove_stale_configured(cfg: &MapConfig) {
    for stale in snapshot_path(cfg).map(remove_stale_temps).unwrap_or_default() {
        tracing::info!("removed {}, left by a write that never finished", stale.display());
    }
}

/// Writes `snapshot` to `path` atomically. A write that fails (a full disk, a read-only
/// directory) leaves no temporary file behind and the previous snapshot as it was.
pub fn save(snapshot: &MapSnapshot, path: &Path) -> std::io::Result<()> {
    let dir = directory_of(path);
    std::fs::create_dir_all(&dir)?;
    let tmp = dir.join(format!("{}{}", temp_prefix(path), std::process::id()));
    let written = (|| {
        let mut f = File::create(&tmp)?;
        f.write_all(&serde_json::to_vec(snapshot).map_err(std::io::Error::other)?)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written?;
    // The rename itself is durable once the directory is synced.
    File::open(&dir)?.sync_all()
}

fn directory_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    }
}

/// Temporary files of `path` are `.<name>.tmp.<pid>` beside it.
fn temp_prefix(path: &Path) -> String {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "map.json".into());
    format!(".{name}.tmp.")
}

/// Removes the temporary files of `path` that writers no longer running left behind (a
/// crash or kill -9 mid-write); returns what it removed.
pub fn remove_stale_temps(path: &Path) -> Vec<PathBuf> {
    let prefix = temp_prefix(path);
    let Ok(entries) = std::fs::read_dir(directory_of(path)) else { return Vec::new() };
    let mut removed = Vec::new();
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(pid) = name.strip_prefix(&prefix).and_then(|p| p.parse::<u32>().ok()) else { continue };
        let running = pid == std::process::id() || Path::new(&format!("/proc/{pid}")).exists();
        if !running && std::fs::remove_file(entry.path()).is_ok() {
            removed.push(entry.path());
        }
    }
    removed
}

/// The largest map file loaded: about 10 kB a polygon, so tens of thousands of polygons.
const MAX_SNAPSHOT_BYTES: u64 = 1 << 30;

/// Why a map file could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    #[error("cannot read map file {path}: {source}")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("map file {path} is corrupt ({why}); moved aside to {aside}")]
    Corrupt { path: PathBuf, why: String, aside: PathBuf },
}

/// Reads a snapshot and makes `build` of it (a map, or the snapshot itself); a file that
/// does not parse or that `build` refuses is renamed to `<name>.corrupt-<unix seconds>`.
pub fn load<T>(path: &Path, build: impl FnOnce(&MapSnapshot) -> Result<T, String>) -> Result<T, LoadError> {
    let bytes = crate::files::read_capped(path, MAX_SNAPSHOT_BYTES)
        .map_err(|source| LoadError::Read { path: path.to_owned(), source })?;
    let parsed = serde_json::from_slice::<MapSnapshot>(&bytes).map_err(|e| e.to_string());
    let why = match parsed {
        Ok(s) => match build(&s) {
            Ok(built) => return Ok(built),
            Err(why) => why,
        },
        Err(why) => why,
    };
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let mut aside = path.as_os_str().to_owned();
    aside.push(format!(".corrupt-{secs}"));
    let aside = PathBuf::from(aside);
    std::fs::rename(path, &aside).map_err(|source| LoadError::Read { path: path.to_owned(), source })?;
    Err(LoadError::Corrupt { path: path.to_owned(), why, aside })
}
