//! Saving and loading the map. A save writes a temporary file beside the target, syncs it
//! and renames it over the target, so a crash at any moment leaves the last whole snapshot.
//! A file that does not load is moved aside (never overwritten) and reported.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use super::MapSnapshot;

/// Writes `snapshot` to `path` atomically.
pub fn save(snapshot: &MapSnapshot, path: &Path) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir)?;
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "map.json".into());
    let tmp = dir.join(format!(".{name}.tmp.{}", std::process::id()));
    {
        let mut f = File::create(&tmp)?;
        f.write_all(&serde_json::to_vec(snapshot).map_err(std::io::Error::other)?)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)?;
    // The rename itself is durable once the directory is synced.
    File::open(&dir)?.sync_all()
}

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
    let bytes = std::fs::read(path).map_err(|source| LoadError::Read { path: path.to_owned(), source })?;
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
