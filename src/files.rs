//! Reading files that might be anything a user or a crash left: only a regular file, and
//! only up to a size that file could have, so `/dev/zero` or a runaway file is an error
//! naming it rather than memory running out.

use std::io::Read;
use std::path::Path;

/// The bytes of the regular file `path`, if it holds at most `max_bytes`.
pub fn read_capped(path: &Path, max_bytes: u64) -> std::io::Result<Vec<u8>> {
    let file = std::fs::File::open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(std::io::Error::other("not a regular file"));
    }
    let mut bytes = Vec::with_capacity(meta.len().min(max_bytes) as usize);
    // One byte past the cap tells a file that grew past it from one that fits exactly.
    file.take(max_bytes + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        return Err(std::io::Error::other(format!("larger than the {max_bytes} bytes such a file can be")));
    }
    Ok(bytes)
}

/// The same, as UTF-8 text.
pub fn read_text_capped(path: &Path, max_bytes: u64) -> std::io::Result<String> {
    String::from_utf8(read_capped(path, max_bytes)?).map_err(|e| std::io::Error::other(format!("not UTF-8 text: {e}")))
}

/// A write past the file size limit (`ulimit -f`, as a full disk stops one) is an error the
/// caller handles (the map's snapshot is tried again next period), not a signal that kills
/// the process, as SIGXFSZ does by default. Call once at start-up.
pub fn survive_file_size_limits() {
    #[cfg(unix)]
    // SAFETY: ignoring a signal changes no memory; done before any thread could write.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}
