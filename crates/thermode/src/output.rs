//! Writing files the CLI produces through the one atomic writer (`thermode_platform::write_atomically`: temporary
//! file beside the target, synced, renamed, folder synced; a device or FIFO is written in place), so that an error
//! never leaves half a file behind, and printing to standard output without panicking on a closed pipe.
//!
//! One convention for every command: `-` as an output file means standard output; a device or FIFO is written in
//! place, never replaced; and every output of a command is checked ([`check_outputs`]) before the command does its
//! work, so that a bad second path (an unwritable plot) cannot leave the first output (the CSV) behind.
//!
//! One path policy: **every output folder is created** (with its parents) when the command writes into it, never
//! before its checks pass — so a command that fails before its work leaves no folder behind — and a folder that
//! cannot be created (a file in the way, no permission) is refused by [`check_outputs`] before any work. The lab's
//! `--data-dir`, `lab analyze --out`, `lab export --bids` and `serve --record`/`--state-dir` follow the same rule.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::{bail, Context, Result};
use thermode_platform::csv_text::Precision;
use thermode_platform::WriteError;
use thermode_table::{Format, Table};

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
        let file = File::options().write(true).create(true).truncate(true).open(tmp)?;
        let mut writer = BufWriter::new(file);
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

/// Writes the tables of `tables` (one per run) to `path` as Arrow IPC or Parquet when its name asks for one
/// (`.arrow`, `.feather`, `.parquet`; atomically, like every output) and returns true; false (nothing written) for
/// any other name, which the caller writes as CSV. Standard output (`-`) is always CSV.
pub fn write_columnar<'a>(path: &Path, tables: impl FnOnce() -> Vec<Table<'a>>) -> Result<bool> {
    let format = Format::of(path);
    if is_stdout(path) || !format.is_columnar() {
        return Ok(false);
    }
    let tables = tables();
    write_atomically(path, |sink| Ok(thermode_table::write(&tables, format, sink)?))?;
    Ok(true)
}
