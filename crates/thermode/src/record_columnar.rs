//! `serve --record FILE.arrow` (`.feather`, `.parquet`): the session is recorded as CSV as always (beside the file,
//! in its folder: crash-safe, whole rows, segments after a failure), and when `serve` stops, the session's CSV
//! files (every segment, in order) are written once more as the named Arrow IPC or Parquet file, with the CSV's
//! columns and values (`channel`, `contact`, `fault` as Int64, `material`, `mode` as Utf8, every other column
//! Float64; an empty field null). The session's clock sidecar (`.clock.json`: the wall-clock time of the loop
//! clock's zero) is copied beside the file under its name, as `lab export --recording` looks for it.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use thermode_runtime::recorder::RecordStatus;
use thermode_table::{Format, Table, Values};

use crate::output::write_columnar;

/// Whether `--record` names a columnar file rather than a folder.
pub fn is_columnar(record: &Path) -> bool {
    Format::of(record).is_columnar()
}

/// The folder the session CSVs go to: `--record` itself, or the folder of a columnar file name.
pub fn record_folder(record: &Path) -> PathBuf {
    if !is_columnar(record) {
        return record.to_path_buf();
    }
    match record.parent() {
        Some(folder) if !folder.as_os_str().is_empty() => folder.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Writes the session's CSV files (earlier segments first) to `target` as Arrow IPC or Parquet; returns the rows.
pub fn write_session(target: &Path, recording: &RecordStatus) -> Result<usize> {
    let mut files: Vec<PathBuf> = recording.earlier_files().into_iter().map(|(path, _)| path).collect();
    files.push(recording.path());
    let tables = files.iter().map(|f| session_table(f)).collect::<Result<Vec<_>>>()?;
    let rows = tables.iter().map(Table::rows).sum();
    write_columnar(target, || tables)?;
    let clock = files[0].with_extension("clock.json");
    if clock.is_file() {
        let copy = target.with_extension("clock.json");
        std::fs::copy(&clock, &copy)
            .with_context(|| format!("cannot copy {} to {}", clock.display(), copy.display()))?;
    }
    Ok(rows)
}

/// One session CSV as a table of its columns.
fn session_table(path: &Path) -> Result<Table<'static>> {
    let mut reader = csv::Reader::from_path(path).with_context(|| format!("cannot read {}", path.display()))?;
    let header: Vec<String> = reader.headers()?.iter().map(str::to_string).collect();
    let mut columns: Vec<Values<'static>> = header.iter().map(|name| empty_column(name)).collect();
    for record in reader.records() {
        let record = record.with_context(|| format!("cannot read {}", path.display()))?;
        for ((values, field), name) in columns.iter_mut().zip(record.iter()).zip(&header) {
            push_field(values, field).with_context(|| format!("{}: column {name}: {field:?}", path.display()))?;
        }
    }
    let mut table = Table::new();
    for (name, values) in header.into_iter().zip(columns) {
        table.push(name, values);
    }
    Ok(table)
}

/// The column type of a recording's column `name`.
fn empty_column(name: &str) -> Values<'static> {
    match name {
        "channel" | "contact" | "fault" => Values::I64(Vec::new()),
        "material" | "mode" => Values::Text(Vec::new()),
        _ => Values::F64Null(Vec::new()),
    }
}

/// Adds the CSV field `field` to `values` (empty: null).
fn push_field(values: &mut Values<'static>, field: &str) -> Result<()> {
    let empty = field.is_empty();
    match values {
        Values::I64(v) => v.push(if empty { None } else { Some(field.parse()?) }),
        Values::Text(v) => v.push((!empty).then(|| field.to_string())),
        Values::F64Null(v) => v.push(if empty { None } else { Some(field.parse()?) }),
        Values::F64(_) | Values::Repeat { .. } => unreachable!("a recording's columns are built by empty_column"),
    }
    Ok(())
}
