//! The one atomic file writer. Every file thermode produces (CSV, JSON, TOML, figures, session sidecars) is
//! written by [`write_atomically`]: into a temporary file beside the target (same extension, so encoders that
//! look at it see the right one), synced, renamed over the target, and the folder synced, so that a crash or an
//! error never leaves half a file and a written file survives a power cut. A target that exists and is not a
//! regular file (a device such as `/dev/null`, a FIFO) is written in place instead: it is never replaced.

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use thiserror::Error;

/// Why an atomic write failed: the caller's filling step, or the file system.
#[derive(Debug, Error)]
pub enum WriteError<E> {
    /// The step that fills the file failed (nothing was left behind).
    #[error(transparent)]
    Fill(E),
    /// Creating, syncing or renaming the file failed (nothing was left behind).
    #[error("{}: {source}", path.display())]
    Io {
        /// The target.
        path: PathBuf,
        /// The file system's error.
        source: io::Error,
    },
}

/// Writes `path` through `fill`, which writes the whole content to the path it is given (see the module
/// documentation). On any error the temporary file is removed and the target is untouched.
pub fn write_atomically<E>(path: &Path, fill: impl FnOnce(&Path) -> Result<(), E>) -> Result<(), WriteError<E>> {
    let io_error = |source| WriteError::Io {
        path: path.to_path_buf(),
        source,
    };
    if is_special_file(path) {
        return fill(path).map_err(WriteError::Fill);
    }
    let tmp = temporary_path(path);
    let result = fill(&tmp).map_err(WriteError::Fill).and_then(|()| {
        File::open(&tmp)
            .and_then(|file| file.sync_all())
            .and_then(|()| std::fs::rename(&tmp, path))
            .and_then(|()| sync_folder(path))
            .map_err(io_error)
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Writes `bytes` to `path` atomically (see [`write_atomically`]).
pub fn write_bytes_atomically(path: &Path, bytes: &[u8]) -> io::Result<()> {
    write_atomically(path, |tmp| {
        OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .open(tmp)?
            .write_all(bytes)
    })
    .map_err(|e| match e {
        WriteError::Fill(e) | WriteError::Io { source: e, .. } => e,
    })
}

/// Whether `path` exists and is not a regular file (following links).
fn is_special_file(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// `.NAME.PID.tmp.EXT` beside `path`.
fn temporary_path(path: &Path) -> PathBuf {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("output");
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    path.with_file_name(format!(".{name}.{}.tmp.{ext}", std::process::id()))
}

/// Syncs the folder holding `path` so that a rename survives a crash (a no-op where folders cannot be opened).
fn sync_folder(path: &Path) -> io::Result<()> {
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    match File::open(folder) {
        Ok(dir) => dir.sync_all().or(Ok(())),
        Err(_) => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_fill_leaves_neither_target_nor_temporary_file() {
        let dir = tempfile::tempdir().expect("temporary folder");
        let target = dir.path().join("out.csv");
        std::fs::write(&target, "old").expect("write");
        let result = write_atomically(&target, |tmp| {
            std::fs::write(tmp, "half")?;
            Err::<(), io::Error>(io::Error::other("disk full"))
        });
        assert!(matches!(result, Err(WriteError::Fill(_))));
        assert_eq!(std::fs::read_to_string(&target).expect("read"), "old");
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .expect("list")
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert_eq!(names.len(), 1, "left behind: {names:?}");
    }

    #[test]
    fn a_write_replaces_a_regular_file_and_keeps_the_extension_for_the_filler() {
        let dir = tempfile::tempdir().expect("temporary folder");
        let target = dir.path().join("figure.png");
        write_atomically(&target, |tmp| {
            assert_eq!(tmp.extension().and_then(|e| e.to_str()), Some("png"));
            std::fs::write(tmp, "new")
        })
        .expect("write");
        assert_eq!(std::fs::read_to_string(&target).expect("read"), "new");
    }

    #[test]
    fn a_special_file_is_written_in_place_not_replaced() {
        let null = Path::new("/dev/null");
        if !null.exists() {
            return;
        }
        write_bytes_atomically(null, b"discarded").expect("write to /dev/null");
        let meta = std::fs::metadata(null).expect("metadata");
        assert!(!meta.is_file(), "/dev/null was replaced by a regular file");
    }
}
