//! `serve --record FILE.arrow` (`.feather`, `.parquet`): the session is recorded as CSV as always (beside the file,
//! in its folder: crash-safe, whole rows, segments after a failure), and when `serve` stops, the session's CSV
//! files (every segment, in order) are written once more as the named Arrow IPC or Parquet file (a block of
//! [`BLOCK_ROWS`] rows at a time, so a long session is never held in memory whole), with the CSV's
//! columns and values (`channel`, `contact`, `fault` as Int64, `material`, `mode` as Utf8, every other column
//! Float64; an empty field null). The session's clock sidecar (`.clock.json`: the wall-clock time of the loop
//! clock's zero) is copied beside the file under its name, as `lab export --recording` looks for it.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use thermode_runtime::recorder::RecordStatus;
use thermode_table::{Format, Table, TableWriter, Values};

use crate::output::write_atomically;

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

/// Rows of a session CSV converted at a time: one block in memory (about 20 MB for a recording's columns), however
/// long the session.
const BLOCK_ROWS: usize = 64 * 1024;

/// Refuses `target` or its clock sidecar when either is not a regular file (a FIFO, a device, a socket): both are
/// written when `serve` stops, after the drives are off, where a FIFO without a reader would hold it for ever, deaf
/// to signals ([`crate::output::check_regular_output`]). Checked at start and again before the write.
pub fn check_targets(target: &Path) -> Result<()> {
    crate::output::check_regular_output("--record", target)?;
    crate::output::check_regular_output("--record", &target.with_extension("clock.json"))
}

/// Writes the session's CSV files (earlier segments first) to `target` as Arrow IPC or Parquet; returns the rows.
/// The session's clock sidecar is copied beside `target`. A target that has become a special file since the start is
/// refused ([`check_targets`]), never waited on.
pub fn write_session(target: &Path, recording: &RecordStatus) -> Result<usize> {
    check_targets(target)?;
    let mut files: Vec<PathBuf> = recording.earlier_files().into_iter().map(|(path, _)| path).collect();
    files.push(recording.path());
    let rows = write_files(target, &files, BLOCK_ROWS)?;
    let clock = files[0].with_extension("clock.json");
    if clock.is_file() {
        let copy = target.with_extension("clock.json");
        std::fs::copy(&clock, &copy)
            .with_context(|| format!("cannot copy {} to {}", clock.display(), copy.display()))?;
    }
    Ok(rows)
}

/// Writes the CSV `files` one after the other to `target` (atomically, in the format its name asks for), read and
/// written `block_rows` rows at a time; returns the rows.
fn write_files(target: &Path, files: &[PathBuf], block_rows: usize) -> Result<usize> {
    let format = Format::of(target);
    let mut rows = 0;
    write_atomically(target, |sink| {
        let mut sink = Some(sink);
        let mut writer: Option<TableWriter> = None;
        for file in files {
            let mut reader = csv::Reader::from_path(file).with_context(|| format!("cannot read {}", file.display()))?;
            let header: Vec<String> = reader.headers()?.iter().map(str::to_string).collect();
            let mut records = reader.records();
            loop {
                let block = read_block(&mut records, &header, file, block_rows)?;
                let writer = match &mut writer {
                    Some(writer) => writer,
                    None => {
                        let sink = sink.take().context("one file, started once")?;
                        writer.insert(TableWriter::try_new(format, &block, sink)?)
                    }
                };
                rows += block.rows();
                writer
                    .write(&block)
                    .with_context(|| format!("{}: not the columns of the session's first file", file.display()))?;
                if block.rows() < block_rows {
                    break;
                }
            }
        }
        match writer {
            Some(writer) => Ok(writer.finish()?),
            None => bail!("no session file to write"),
        }
    })?;
    Ok(rows)
}

/// The next at most `block_rows` rows of `records` (of the CSV `path` with `header`) as a table of its columns.
fn read_block(
    records: &mut csv::StringRecordsIter<'_, std::fs::File>,
    header: &[String],
    path: &Path,
    block_rows: usize,
) -> Result<Table<'static>> {
    let mut columns: Vec<Values<'static>> = header.iter().map(|name| empty_column(name)).collect();
    for record in records.take(block_rows) {
        let record = record.with_context(|| format!("cannot read {}", path.display()))?;
        for ((values, field), name) in columns.iter_mut().zip(record.iter()).zip(header) {
            push_field(values, field).with_context(|| format!("{}: column {name}: {field:?}", path.display()))?;
        }
    }
    let mut table = Table::new();
    for (name, values) in header.iter().zip(columns) {
        table.push(name.clone(), values);
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_converted_a_few_rows_at_a_time_read_back_as_their_csv_rows() {
        let dir = tempfile::tempdir().expect("temp dir");
        let header = "time_s,channel,mode,material,skin_c,fault\n";
        let rows = |first: usize, count: usize| -> String {
            (first..first + count)
                .map(|i| {
                    let material = if i % 3 == 0 { "" } else { "aluminium" };
                    let fault = if i % 5 == 0 { "104" } else { "" };
                    format!(
                        "{},{},touch,{material},{},{fault}\n",
                        i as f64 * 0.001,
                        i % 2,
                        30.0 + i as f64 / 7.0
                    )
                })
                .collect()
        };
        let files = [dir.path().join("s.csv"), dir.path().join("s_seg2.csv")];
        std::fs::write(&files[0], format!("{header}{}", rows(0, 17))).expect("write");
        std::fs::write(&files[1], format!("{header}{}", rows(17, 6))).expect("write");
        for name in ["s.arrow", "s.parquet"] {
            let target = dir.path().join(name);
            let written = write_files(&target, &files, 4).unwrap_or_else(|e| panic!("{name}: {e:#}"));
            assert_eq!(written, 23, "{name}");
            let (columns, fields) =
                thermode_table::read_fields(&target, 1 << 20).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(columns.join(",") + "\n", header, "{name}");
            let csv: Vec<Vec<String>> = rows(0, 23)
                .lines()
                .map(|l| l.split(',').map(str::to_string).collect())
                .collect();
            assert_eq!(fields, csv, "{name}: every row and field of both segments, in order");
        }
        std::fs::write(&files[1], "time_s,channel\n0.5,1\n").expect("write");
        let error = write_files(&dir.path().join("bad.arrow"), &files, 4).expect_err("other columns");
        assert!(format!("{error:#}").contains("not the columns"), "{error:#}");
        assert!(
            !dir.path().join("bad.arrow").exists(),
            "nothing left of a refused conversion"
        );
    }
}
