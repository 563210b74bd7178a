//! The one atomic file writer. Every file thermode produces (CSV, JSON, TOML, figures, session sidecars) is
//! written by [`write_atomically`]: into a temporary file beside the target (same extension, so encoders that
//! look at it see the right one), synced, renamed over the target, and the folder synced, so that a crash or an
//! error never leaves half a file and a written file survives a power cut. [`WritingAhead`] is the file a large
//! output is written through, so that the final sync finds most of it on the device already. A target that exists and is not a
//! regular file (a device such as `/dev/null`, a FIFO) is written in place instead: it is never replaced.
//!
//! And the bounded readers: an input file (settings, a plan, a CSV to analyse) is read through [`AtMost`], which
//! fails with `InvalidData` past a size limit ([`MAX_SETTINGS_BYTES`], [`MAX_DATA_BYTES`]), so a wrong path such as
//! `/dev/zero` is an error naming the file instead of a process that eats the machine's memory.

use std::fs::{File, OpenOptions};
use std::io::{self, Read, Write};
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
        let replaced = large_file(path);
        File::open(&tmp)
            .and_then(|file| file.sync_all())
            .and_then(|()| std::fs::rename(&tmp, path))
            .and_then(|()| sync_folder(path))
            .map_err(io_error)?;
        if let Some(file) = replaced {
            // Spawning can only fail by dropping the closure, which closes the file here instead.
            let _ = std::thread::Builder::new()
                .name("release".into())
                .spawn(move || drop(file));
        }
        Ok(())
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Size from which the file a write replaces is let go on a thread of its own \[bytes\]: 1 MiB.
const RELEASE_ON_THREAD_BYTES: u64 = 1 << 20;

/// `path` opened, when it is a regular file of at least [`RELEASE_ON_THREAD_BYTES`]: held open across the rename
/// over it, so that the rename does not free it. Freeing a large file (its cached pages and, on a disk mounted with
/// `discard`, its blocks, which waits for the device: 1.3–2 ms for 7 MB on the development machine) is then done by
/// a thread of its own while the command goes on; the kernel frees it at the latest when the process ends.
fn large_file(path: &Path) -> Option<File> {
    let file = File::open(path).ok()?;
    let metadata = file.metadata().ok()?;
    (metadata.is_file() && metadata.len() >= RELEASE_ON_THREAD_BYTES).then_some(file)
}

/// Writes `bytes` to `path` atomically (see [`write_atomically`]).
pub fn write_bytes_atomically(path: &Path, bytes: &[u8]) -> io::Result<()> {
    write_atomically(path, |tmp| WritingAhead::create(tmp)?.write_all(bytes)).map_err(|e| match e {
        WriteError::Fill(e) | WriteError::Io { source: e, .. } => e,
    })
}

/// Bytes written between two requests of [`WritingAhead`] to start putting them on the device: 1 MiB.
pub const WRITE_AHEAD_BYTES: u64 = 1 << 20;

/// A file written front to back whose bytes the kernel is asked to start putting on the device every
/// [`WRITE_AHEAD_BYTES`] as they are written, without waiting for it (Linux's `sync_file_range` with
/// `SYNC_FILE_RANGE_WRITE`; elsewhere nothing is asked). The sync of the finished file ([`write_atomically`]) then
/// finds most of it on the device already: a file written while its data is still being computed waits at the end
/// for little more than its last piece, instead of for all of it.
#[derive(Debug)]
pub struct WritingAhead {
    file: File,
    /// Bytes written so far.
    written: u64,
    /// Bytes the device has been asked to take so far.
    asked: u64,
}

impl WritingAhead {
    /// Creates (or truncates) `path` for writing.
    pub fn create(path: &Path) -> io::Result<Self> {
        let file = OpenOptions::new().write(true).create(true).truncate(true).open(path)?;
        Ok(WritingAhead {
            file,
            written: 0,
            asked: 0,
        })
    }
}

impl Write for WritingAhead {
    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        let count = self.file.write(bytes)?;
        self.written += count as u64;
        if self.written - self.asked >= WRITE_AHEAD_BYTES {
            start_writeback(&self.file, self.asked, self.written - self.asked);
            self.asked = self.written;
        }
        Ok(count)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

/// Asks the kernel to start writing `length` bytes of `file` from `offset` to its device, without waiting. Only a
/// hint: a failure changes nothing (the file's final sync writes what is left and reports errors).
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
fn start_writeback(file: &File, offset: u64, length: u64) {
    use std::os::fd::AsRawFd;
    let (Ok(offset), Ok(length)) = (i64::try_from(offset), i64::try_from(length)) else {
        return;
    };
    // SAFETY: sync_file_range reads no memory of ours; the descriptor is open for as long as `file` is borrowed.
    unsafe {
        libc::sync_file_range(file.as_raw_fd(), offset, length, libc::SYNC_FILE_RANGE_WRITE);
    }
}

#[cfg(not(target_os = "linux"))]
fn start_writeback(_file: &File, _offset: u64, _length: u64) {}

/// The most thermode reads of a settings or plan file (device, material, skin, gains, experiment, answers, session
/// sidecar): 16 MiB, some thousand times a real one (a device file is about 5 KiB).
pub const MAX_SETTINGS_BYTES: u64 = 16 << 20;

/// The most thermode reads of a data file (a CSV to analyse or export): 1 GiB (an hour of `render` at 1 kHz is
/// about half of that).
pub const MAX_DATA_BYTES: u64 = 1 << 30;

/// A reader that yields at most `limit` bytes of `inner` and then fails with `InvalidData` if there is more, where
/// `Read::take` would end quietly and hand on a cut file.
#[derive(Debug)]
pub struct AtMost<R> {
    inner: R,
    /// Bytes that may still be read.
    left: u64,
    /// The limit, for the error message \[bytes\].
    limit: u64,
}

impl<R: Read> AtMost<R> {
    /// `inner`, read to at most `limit` bytes.
    pub fn new(inner: R, limit: u64) -> Self {
        Self {
            inner,
            left: limit,
            limit,
        }
    }
}

impl<R: Read> Read for AtMost<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if buf.is_empty() {
            return Ok(0);
        }
        if self.left == 0 {
            let mut probe = [0u8; 1];
            return match self.inner.read(&mut probe)? {
                0 => Ok(0),
                _ => Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    format!(
                        "larger than {}, the most thermode reads of such a file",
                        byte_size(self.limit)
                    ),
                )),
            };
        }
        let wanted = buf.len().min(usize::try_from(self.left).unwrap_or(usize::MAX));
        let got = self.inner.read(&mut buf[..wanted])?;
        self.left -= got as u64;
        Ok(got)
    }
}

/// `path` opened to read at most `limit` bytes.
pub fn open_at_most(path: &Path, limit: u64) -> io::Result<AtMost<File>> {
    Ok(AtMost::new(File::open(path)?, limit))
}

/// The text of `path`, at most `limit` bytes: more is `InvalidData`, and so is text that is not UTF-8.
pub fn read_text_at_most(path: &Path, limit: u64) -> io::Result<String> {
    let mut text = String::new();
    open_at_most(path, limit)?.read_to_string(&mut text)?;
    Ok(text)
}

/// `bytes` for a person: in MiB when a whole number of them, else in bytes.
fn byte_size(bytes: u64) -> String {
    if bytes >= 1 << 20 && bytes.is_multiple_of(1 << 20) {
        format!("{} MiB", bytes >> 20)
    } else {
        format!("{bytes} bytes")
    }
}

/// Whether `path` exists and is not a regular file (following links).
fn is_special_file(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// What `path` is when it exists and is not a regular file (following links), in words ("a FIFO", "a device", "a
/// socket", "a directory"); None for a regular file or nothing there. For outputs written after the drives are off
/// or inputs read at start, where a FIFO without its other end would block for ever.
pub fn special_file_kind(path: &Path) -> Option<&'static str> {
    std::fs::metadata(path)
        .ok()
        .filter(|m| !m.is_file())
        .map(|m| file_kind(&m.file_type()))
}

/// What a file that is not a regular file is, in words.
pub fn file_kind(kind: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if kind.is_fifo() {
            return "a FIFO";
        }
        if kind.is_char_device() || kind.is_block_device() {
            return "a device";
        }
        if kind.is_socket() {
            return "a socket";
        }
    }
    if kind.is_dir() {
        "a directory"
    } else {
        "not a regular file"
    }
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

    /// Fails unless `folder` holds exactly one file (the target: no temporary file left behind).
    fn assert_only_file_in(folder: &Path) {
        let names: Vec<_> = std::fs::read_dir(folder)
            .expect("list")
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert_eq!(names.len(), 1, "left behind: {names:?}");
    }

    #[test]
    fn a_file_written_ahead_holds_every_byte_in_order() {
        let dir = tempfile::tempdir().expect("temporary folder");
        let target = dir.path().join("big.bin");
        let bytes: Vec<u8> = (0..3 * WRITE_AHEAD_BYTES + 12_345).map(|i| (i % 251) as u8).collect();
        let mut file = WritingAhead::create(&target).expect("create");
        for piece in bytes.chunks(100_003) {
            file.write_all(piece).expect("write");
        }
        file.flush().expect("flush");
        assert_eq!(file.written, bytes.len() as u64);
        assert!(
            file.asked > 0 && file.written - file.asked < WRITE_AHEAD_BYTES,
            "the device was asked for {} of {} bytes",
            file.asked,
            file.written
        );
        drop(file);
        assert!(
            std::fs::read(&target).expect("read") == bytes,
            "the file differs from what was written"
        );
    }

    #[test]
    fn a_large_file_replaced_is_let_go_and_only_the_new_one_remains() {
        let dir = tempfile::tempdir().expect("temporary folder");
        let target = dir.path().join("big.arrow");
        std::fs::write(&target, vec![1u8; RELEASE_ON_THREAD_BYTES as usize]).expect("write the old file");
        assert!(
            large_file(&target).is_some(),
            "a file of 1 MiB is let go on its own thread"
        );
        write_bytes_atomically(&target, b"new").expect("replace");
        assert_eq!(std::fs::read(&target).expect("read"), b"new");
        assert_only_file_in(dir.path());
        assert!(large_file(&target).is_none(), "a small file is closed where it is");
    }

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
        assert_only_file_in(dir.path());
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

    #[test]
    fn a_file_up_to_the_limit_is_read_and_one_byte_more_is_an_error() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("settings.toml");
        std::fs::write(&path, "x = 1\n").expect("write");
        assert_eq!(read_text_at_most(&path, 6).expect("six bytes"), "x = 1\n");
        let error = read_text_at_most(&path, 5).expect_err("seven bytes");
        assert_eq!(error.kind(), io::ErrorKind::InvalidData);
        assert_eq!(
            error.to_string(),
            "larger than 5 bytes, the most thermode reads of such a file"
        );
        std::fs::write(&path, [0xff, 0xfe]).expect("write");
        let not_text = read_text_at_most(&path, 6).expect_err("not UTF-8");
        assert_eq!(not_text.kind(), io::ErrorKind::InvalidData);
    }

    #[test]
    fn an_endless_device_is_an_error_not_a_full_memory() {
        let path = Path::new("/dev/zero");
        if !path.exists() {
            return;
        }
        let error = read_text_at_most(path, MAX_SETTINGS_BYTES).expect_err("endless");
        assert_eq!(
            error.to_string(),
            "larger than 16 MiB, the most thermode reads of such a file"
        );
    }
}
