//! Writing files the CLI produces through the one atomic writer (`thermode_platform::write_atomically`: temporary
//! file beside the target, synced, renamed, folder synced; a device or FIFO is written in place), so that an error
//! never leaves half a file behind, and printing to standard output without panicking on a closed pipe.
//!
//! One convention for every command: `-` as an output file means standard output; a device or FIFO is written in
//! place, never replaced (except an output written when the command stops, after the drives are off — `serve
//! --record FILE.arrow` — which must be a regular file, [`check_regular_output`]: a FIFO without a reader would hold
//! the stop for ever); and every output of a command is checked ([`check_outputs`]) before the command does its
//! work, so that a bad second path (an unwritable plot) cannot leave the first output (the CSV) behind.
//!
//! One path policy: **every output folder is created** (with its parents) when the command writes into it, never
//! before its checks pass — so a command that fails before its work leaves no folder behind — and a folder that
//! cannot be created (a file in the way, no permission) is refused by [`check_outputs`] before any work. The lab's
//! `--data-dir`, `lab analyze --out`, `lab export --bids` and `serve --record`/`--state-dir` follow the same rule.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::sync::mpsc::{sync_channel, SyncSender};
use std::thread::{Scope, ScopedJoinHandle};

use anyhow::{bail, Context, Result};
use thermode_platform::csv_text::Precision;
use thermode_platform::{WriteError, WritingAhead};
use thermode_table::{Format, Table, TableWriter};

/// Whether `path` names standard output (`-`).
pub fn is_stdout(path: &Path) -> bool {
    path.as_os_str() == "-"
}

/// Checks, before any work is done, that every output in `outputs` (option name, path) can be written: `-`
/// (standard output) always can; otherwise its folder must exist or be creatable (its nearest existing ancestor a
/// folder that takes a new file, probed by creating and removing one; nothing is created), a path that exists must
/// not be a folder, and a `--plot` must end in `.svg` or `.png`. Errors name the option and the path.
pub fn check_outputs(outputs: &[(&str, Option<&Path>)]) -> Result<()> {
    for (option, path) in outputs {
        let Some(path) = path.filter(|p| !is_stdout(p)) else {
            continue;
        };
        if path.is_dir() {
            bail!("{option} {}: is a folder, not a file", path.display());
        }
        if *option == "--plot" && !thermode_plot::is_figure_path(path) {
            bail!("--plot {}: plots are written as .svg or .png", path.display());
        }
        let folder = folder_of(path);
        let existing = folder.ancestors().find(|a| a.exists()).unwrap_or(Path::new("."));
        let probe = existing.join(format!(".thermode-probe-{}", std::process::id()));
        File::options()
            .write(true)
            .create_new(true)
            .open(&probe)
            .and_then(|_| std::fs::remove_file(&probe))
            .with_context(|| format!("{option} {}: cannot write in {}", path.display(), folder.display()))?;
    }
    Ok(())
}

/// Refuses the output `path` of `option` when it exists and is not a regular file (a FIFO, a device, a socket), for
/// an output written when the command stops (after the drives are off), where the in-place write of a special file
/// would wait for ever for a FIFO's reader, deaf to signals. Checked without opening it.
pub fn check_regular_output(option: &str, path: &Path) -> Result<()> {
    match thermode_platform::fs::special_file_kind(path) {
        Some(kind) => bail!(
            "{option} {}: it is {kind}, not a regular file: this output is written when the command stops, where \
             a FIFO without a reader would hold it for ever; name a regular file",
            path.display()
        ),
        None => Ok(()),
    }
}

/// The folder of the output file `path` (`.` for a bare file name).
fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Creates the folder of the output file `path` (with its parents) if it is missing: the path policy (module
/// documentation), called when the command writes, after its checks and its work.
pub fn create_folder_of(path: &Path) -> Result<()> {
    let folder = folder_of(path);
    std::fs::create_dir_all(folder).with_context(|| format!("cannot create the folder {}", folder.display()))
}

/// Writes the bytes produced by `fill` to `path` atomically (to standard output for `-`), its folder created if
/// missing; errors name `path`.
pub fn write_atomically(path: &Path, fill: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    if is_stdout(path) {
        let mut bytes = Vec::new();
        fill(&mut bytes)?;
        return print_stdout(&String::from_utf8_lossy(&bytes));
    }
    create_folder_of(path)?;
    let fill_file = |tmp: &Path| -> Result<()> {
        let mut writer = BufWriter::new(WritingAhead::create(tmp)?);
        fill(&mut writer)?;
        writer.flush()?;
        Ok(())
    };
    thermode_platform::write_atomically(path, fill_file)
        .map_err(|e| match e {
            WriteError::Fill(e) => e,
            WriteError::Io { source, .. } => source.into(),
        })
        .with_context(|| format!("cannot write {}", path.display()))
}
/// Prints `text` to standard output; a closed pipe (e.g. `| head`) ends quietly instead of panicking.
pub fn print_stdout(text: &str) -> Result<()> {
    let mut stdout = std::io::stdout().lock();
    match stdout.write_all(text.as_bytes()).and_then(|()| stdout.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        Err(e) => Err(e).context("cannot write to standard output"),
    }
}

/// The CSV precision of a `--precision` option: exact without one.
pub fn csv_precision(decimals: Option<u8>) -> Precision {
    decimals.map_or(Precision::Exact, Precision::Decimals)
}

/// Refuses, before any work, `--precision` with an Arrow or Parquet output: those store every float exactly.
pub fn check_columnar_precision(out: Option<&Path>, precision: Option<u8>) -> Result<()> {
    match out {
        Some(path) if Format::of(path).is_columnar() && precision.is_some() => bail!(
            "--precision {}: --out {} is written as {}, which stores every number exactly; --precision rounds CSV \
             text only",
            precision.unwrap_or_default(),
            path.display(),
            if Format::of(path) == Format::Arrow {
                "Arrow IPC"
            } else {
                "Parquet"
            }
        ),
        _ => Ok(()),
    }
}

/// The columnar format the output `path` asks for by its name (Arrow IPC for `.arrow` and `.feather`, Parquet for
/// `.parquet`); `None` for any other name and for standard output (`-`), which are CSV.
pub fn columnar_format(path: &Path) -> Option<Format> {
    let format = Format::of(path);
    (!is_stdout(path) && format.is_columnar()).then_some(format)
}

/// Writes the tables of `tables` (one per run) to `path` as Arrow IPC or Parquet when its name asks for one
/// (`.arrow`, `.feather`, `.parquet`; atomically, like every output) and returns true; false (nothing written) for
/// any other name, which the caller writes as CSV. Standard output (`-`) is always CSV.
pub fn write_columnar<'a>(path: &Path, tables: impl FnOnce() -> Vec<Table<'a>>) -> Result<bool> {
    let Some(format) = columnar_format(path) else {
        return Ok(false);
    };
    let tables = tables();
    write_atomically(path, |sink| Ok(thermode_table::write(&tables, format, sink)?))?;
    Ok(true)
}

/// Pieces of rows a [`ColumnarStream`] holds at most while its thread writes (the run waits beyond that).
const STREAM_QUEUE_PIECES: usize = 16;

/// What a [`ColumnarStream`]'s thread receives.
enum Piece<'a> {
    /// The next rows of the file.
    Rows(Table<'a>),
    /// Everything has been sent: the file is finished and put in place.
    End,
}

/// An Arrow IPC or Parquet output written on a thread of its own while the runs that fill it compute, so that the
/// writing (and the device taking the bytes, [`WritingAhead`]) overlaps the computing instead of following it. The
/// thread belongs to the caller's scope (`std::thread::scope`), so the pieces it writes are the runs' own numbers,
/// borrowed, not copies: [`ColumnarStream::start`], [`ColumnarStream::send`] for each piece of rows in order (all
/// with the same columns), [`ColumnarStream::finish`]. The file is written atomically like every output: a stream
/// dropped without `finish` (a run failed) leaves nothing behind and the target untouched.
pub struct ColumnarStream<'scope, 'a> {
    path: &'a Path,
    pieces: SyncSender<Piece<'a>>,
    writer: ScopedJoinHandle<'scope, Result<()>>,
}

impl<'scope, 'a: 'scope> ColumnarStream<'scope, 'a> {
    /// Starts writing `path` on a thread of `scope` when its name asks for Arrow or Parquet (`.arrow`, `.feather`,
    /// `.parquet`); `None` for any other name or standard output, which the caller writes as CSV.
    pub fn start(scope: &'scope Scope<'scope, '_>, path: &'a Path) -> Option<Self> {
        let format = columnar_format(path)?;
        let (pieces, received) = sync_channel(STREAM_QUEUE_PIECES);
        let writer = scope.spawn(move || {
            write_atomically(path, |sink| {
                let first = match received.recv() {
                    Ok(Piece::Rows(table)) => table,
                    Ok(Piece::End) => bail!("nothing to write: no rows"),
                    Err(_) => bail!("the run stopped before its output was complete"),
                };
                let mut writer = TableWriter::try_new(format, &first, sink)?;
                writer.write(&first)?;
                for piece in received {
                    match piece {
                        Piece::Rows(table) => writer.write(&table)?,
                        Piece::End => return Ok(writer.finish()?),
                    }
                }
                bail!("the run stopped before its output was complete")
            })
        });
        Some(ColumnarStream { path, pieces, writer })
    }

    /// Queues the next rows (waiting while the queue is full). Rows sent after the writer failed are dropped: its
    /// error is reported by [`ColumnarStream::finish`].
    pub fn send(&self, rows: Table<'a>) {
        let _ = self.pieces.send(Piece::Rows(rows));
    }

    /// Ends the file, waits until it is written and in place, and reports the writer's error if it failed.
    pub fn finish(self) -> Result<()> {
        let _ = self.pieces.send(Piece::End);
        match self.writer.join() {
            Ok(result) => result,
            Err(_) => bail!("cannot write {}: the writer thread panicked", self.path.display()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use thermode_table::Values;

    fn piece(first: f64) -> Table<'static> {
        let mut table = Table::new();
        table.push("time_s", Values::F64(vec![first, first + 1.0].into()));
        table
    }

    #[test]
    fn a_finished_stream_is_the_file_of_its_pieces_and_an_abandoned_one_leaves_the_target_as_it_was() {
        let dir = tempfile::tempdir().expect("temporary folder");
        let target = dir.path().join("out.arrow");
        std::thread::scope(|scope| {
            let stream = ColumnarStream::start(scope, &target).expect("a columnar name");
            stream.send(piece(0.0));
            stream.send(piece(2.0));
            stream.finish().expect("written");
        });
        let table = thermode_table::read(&target).expect("read back");
        assert_eq!(
            table.column("time_s"),
            Some(&Values::F64(vec![0.0, 1.0, 2.0, 3.0].into()))
        );
        let before = std::fs::read(&target).expect("read");
        std::thread::scope(|scope| {
            let stream = ColumnarStream::start(scope, &target).expect("a columnar name");
            stream.send(piece(10.0));
            drop(stream);
        });
        assert!(
            std::fs::read(&target).expect("read") == before,
            "the abandoned stream changed the target"
        );
        let entries = std::fs::read_dir(dir.path()).expect("list").count();
        assert_eq!(entries, 1, "the abandoned stream left its temporary file behind");
        let csv = dir.path().join("out.csv");
        std::thread::scope(|scope| assert!(ColumnarStream::start(scope, &csv).is_none(), "CSV is not streamed"));
    }
}
