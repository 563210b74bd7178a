//! thermode-table: the tables thermode writes as CSV (`simulate`, `render`), also as columnar files that pandas,
//! polars, R and MATLAB read natively: Arrow IPC (Feather v2) when the output's name ends in `.arrow` or
//! `.feather`, Parquet when it ends in `.parquet` ([`Format::of`]). The columns and their order are the CSV's, and
//! every value is the one the CSV holds: floats as the exact `f64` (the CSV's exact default form reads back as
//! the same number), integers (`contact`, `fault`) as 64-bit integers, text as UTF-8; an empty CSV field is null.
//!
//! A file is written from one [`Table`] per run or per piece of a run (the rows a CSV writes for one material or
//! one render run, or the rows a run has just computed), its rows in order: in Arrow one record batch per table (per
//! [`ARROW_BATCH_ROWS`] rows of a longer one), every column's bytes
//! written from the run's own values without a copy ([`ArrowFileWriter`], which also writes a file a table at a
//! time); in Parquet through the Parquet writer, fed record batches of [`BATCH_ROWS`] rows. [`write()`] writes a
//! file's tables at once, [`TableWriter`] one table at a time (a long recording converted a block at a time).
//! [`read`] reads a file back into one table, [`read_fields`] into the CSV's header and fields (how the readers of
//! thermode's CSVs read these files).
//!
//! Arrow IPC is written uncompressed (the fastest to write and to read); Parquet uncompressed with dictionary
//! encoding (no compression codec is compiled in).

mod ipc;
mod table;

use std::fs::File;
use std::io::{Read, Seek, Write};
use std::path::Path;

use arrow_array::{RecordBatch, RecordBatchReader};
use arrow_schema::{ArrowError, SchemaRef};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::ArrowWriter;
use parquet::errors::ParquetError;

pub use ipc::{ArrowFileWriter, ARROW_BATCH_ROWS};
pub use table::{Table, Values, BATCH_ROWS};

/// What went wrong writing or reading a columnar file.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    /// The Arrow IPC writer or reader refused (a malformed file, a failed write).
    #[error("Arrow: {0}")]
    Arrow(#[from] ArrowError),
    /// The Parquet writer or reader refused.
    #[error("Parquet: {0}")]
    Parquet(#[from] ParquetError),
    /// The file could not be opened, read or written.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// The tables do not fit together (columns of different lengths, names or types), or a column has a type
    /// thermode does not write.
    #[error("{0}")]
    Shape(String),
}

/// The format of an output or input file, by its name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Comma-separated text (any other name, and `-`).
    Csv,
    /// Arrow IPC file (Feather v2): `.arrow`, `.feather`.
    Arrow,
    /// Parquet: `.parquet`.
    Parquet,
}

impl Format {
    /// The format a file name asks for: its extension, case-insensitive.
    pub fn of(path: &Path) -> Format {
        let extension = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        match extension.as_deref() {
            Some("arrow" | "feather") => Format::Arrow,
            Some("parquet") => Format::Parquet,
            _ => Format::Csv,
        }
    }

    /// Whether this is a columnar format (not CSV).
    pub fn is_columnar(self) -> bool {
        self != Format::Csv
    }
}

/// Writes `tables` (one per run, all with the same columns) to `sink` in `format` (Arrow or Parquet), their rows in
/// order (in Arrow one record batch per table, in Parquet batches of [`BATCH_ROWS`] rows). CSV is not written here:
/// thermode's CSV writers stay as they are.
pub fn write(tables: &[Table<'_>], format: Format, sink: &mut dyn Write) -> Result<(), TableError> {
    let Some(first) = tables.first() else {
        return Err(TableError::Shape("nothing to write: no table".to_string()));
    };
    let schema = first.schema();
    if let Some(other) = tables.iter().find(|t| t.schema() != schema) {
        return Err(TableError::Shape(format!(
            "the tables' columns differ: {:?} and {:?}",
            schema.fields().iter().map(|f| f.name()).collect::<Vec<_>>(),
            other.columns.iter().map(|(n, _)| n).collect::<Vec<_>>()
        )));
    }
    let mut writer = TableWriter::try_new(format, first, sink)?;
    for table in tables {
        writer.write(table)?;
    }
    writer.finish()
}

/// An Arrow IPC or Parquet file written a table at a time (a long recording converted a block of rows at a time,
/// so that memory holds one block, not the session): [`TableWriter::try_new`] with the first table's columns,
/// [`TableWriter::write`] for each table in order, [`TableWriter::finish`] at the end.
pub struct TableWriter<'w> {
    inner: Inner<'w>,
}

/// The writer of each format.
enum Inner<'w> {
    /// Straight to the sink.
    Arrow(ArrowFileWriter<&'w mut dyn Write>),
    /// The Parquet writer wants a sink it can send between threads: the file is built in memory (row groups of at
    /// most the writer's default million rows are buffered; earlier ones are encoded) and copied at the end.
    Parquet {
        writer: Box<ArrowWriter<Vec<u8>>>,
        schema: SchemaRef,
        sink: &'w mut dyn Write,
    },
}

impl<'w> TableWriter<'w> {
    /// Starts a file in `format` on `sink` with the columns (names and types) of `columns_of`; nothing of its rows is
    /// written. CSV is refused (thermode's CSV writers write it).
    pub fn try_new(format: Format, columns_of: &Table<'_>, sink: &'w mut dyn Write) -> Result<Self, TableError> {
        let schema = columns_of.schema();
        let inner = match format {
            Format::Arrow => Inner::Arrow(ArrowFileWriter::try_new(sink, schema)?),
            Format::Parquet => Inner::Parquet {
                writer: Box::new(ArrowWriter::try_new(Vec::new(), schema.clone(), None)?),
                schema,
                sink,
            },
            Format::Csv => {
                return Err(TableError::Shape(
                    "CSV is written by thermode's CSV writers".to_string(),
                ))
            }
        };
        Ok(TableWriter { inner })
    }

    /// Writes the rows of `table`, which has the file's columns (else an error).
    pub fn write(&mut self, table: &Table<'_>) -> Result<(), TableError> {
        match &mut self.inner {
            Inner::Arrow(writer) => writer.write(table),
            Inner::Parquet { writer, schema, .. } => {
                if table.schema() != *schema {
                    return Err(TableError::Shape(format!(
                        "the table's columns differ from the file's: {:?}",
                        table.columns.iter().map(|(n, _)| n).collect::<Vec<_>>()
                    )));
                }
                for batch in table.batches(schema) {
                    writer.write(&batch?)?;
                }
                Ok(())
            }
        }
    }

    /// Ends the file (Arrow's footer, Parquet's metadata) and flushes it to the sink.
    pub fn finish(self) -> Result<(), TableError> {
        match self.inner {
            Inner::Arrow(writer) => {
                writer.finish()?;
            }
            Inner::Parquet { writer, sink, .. } => sink.write_all(&writer.into_inner()?)?,
        }
        Ok(())
    }
}

/// Reads an Arrow IPC or Parquet file (by its name, [`Format::of`]) into one table: every record batch or row group
/// in order. A file of another format, or a column of a type thermode does not write, is an error.
pub fn read(path: &Path) -> Result<Table<'static>, TableError> {
    let file = File::open(path)?;
    match Format::of(path) {
        Format::Arrow => read_arrow(file),
        Format::Parquet => {
            let reader = ParquetRecordBatchReaderBuilder::try_new(file)?.build()?;
            collect(reader.schema(), reader)
        }
        Format::Csv => Err(TableError::Shape(format!(
            "{}: not an Arrow (.arrow, .feather) or Parquet (.parquet) file",
            path.display()
        ))),
    }
}

/// The header and rows of an Arrow IPC or Parquet file as the CSV of the same table holds them: every value as its
/// CSV field ([`Values::field`]: a float in its shortest exact form, an integer in decimal, null as an empty field).
/// The readers of thermode's CSVs read these files through it. A file larger than `max_bytes` (bytes) or not a
/// regular file (a device, a FIFO) is refused before it is read.
pub fn read_fields(path: &Path, max_bytes: u64) -> Result<(Vec<String>, Vec<Vec<String>>), TableError> {
    let metadata = std::fs::metadata(path)?;
    if !metadata.is_file() || metadata.len() > max_bytes {
        return Err(TableError::Io(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "{}: not a regular file of at most {max_bytes} bytes ({} bytes)",
                path.display(),
                metadata.len()
            ),
        )));
    }
    let table = read(path)?;
    let header = table.columns.iter().map(|(name, _)| name.clone()).collect();
    let rows = (0..table.rows())
        .map(|row| table.columns.iter().map(|(_, values)| values.field(row)).collect())
        .collect();
    Ok((header, rows))
}

fn read_arrow(file: impl Read + Seek) -> Result<Table<'static>, TableError> {
    let reader = arrow_ipc::reader::FileReader::try_new(file, None)?;
    let schema = reader.schema();
    collect(schema, reader)
}

/// The batches of `batches` (with `schema`) as one table.
fn collect(
    schema: SchemaRef,
    batches: impl Iterator<Item = Result<RecordBatch, ArrowError>>,
) -> Result<Table<'static>, TableError> {
    let mut table = Table::new();
    for field in schema.fields() {
        table.push(field.name().clone(), Values::empty_like(field)?);
    }
    for batch in batches {
        let batch = batch?;
        for (index, (name, values)) in table.columns.iter_mut().enumerate() {
            values.append(batch.column(index).as_ref(), name)?;
        }
    }
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_runs() -> Vec<Table<'static>> {
        let run = |material: &str, start: f64| {
            let mut t = Table::new();
            t.push("time_s", Values::F64(vec![start, start + 0.1, start + 0.2].into()));
            t.push("skin_c", Values::F64(vec![32.1, f64::NAN, 1.0 / 3.0].into()));
            t.push("fault", Values::I64(vec![None, Some(104), None]));
            t.push("thickness_m", Values::F64Null(vec![None, Some(0.01), None]));
            t.push(
                "material",
                Values::Repeat {
                    text: material.to_string(),
                    rows: 3,
                },
            );
            t
        };
        vec![run("aluminium", -0.1), run("wood", 0.0)]
    }

    /// The values of `table`, NaN compared by its bits.
    fn bits(table: &Table) -> Vec<(String, Vec<String>)> {
        let show = |v: &Values| match v {
            Values::F64(v) => v.iter().map(|x| format!("{:016x}", x.to_bits())).collect(),
            other => (0..other.len()).map(|i| other.field(i)).collect(),
        };
        table.columns.iter().map(|(n, v)| (n.clone(), show(v))).collect()
    }

    #[test]
    fn arrow_and_parquet_files_read_back_as_the_tables_written_bit_for_bit() {
        let runs = two_runs();
        let mut whole = runs[0].clone();
        for ((_, all), (_, more)) in whole.columns.iter_mut().zip(&runs[1].columns) {
            match (all, more) {
                (Values::F64(a), Values::F64(b)) => a.to_mut().extend(b.iter()),
                (Values::I64(a), Values::I64(b)) => a.extend(b),
                (Values::F64Null(a), Values::F64Null(b)) => a.extend(b),
                (Values::Text(a), Values::Text(b)) => a.extend(b.iter().cloned()),
                (a @ Values::Repeat { .. }, b @ Values::Repeat { .. }) => {
                    let texts = |v: &Values| (0..v.len()).map(|i| Some(v.field(i))).collect::<Vec<_>>();
                    *a = Values::Text([texts(a), texts(b)].concat());
                }
                _ => unreachable!("same columns"),
            }
        }
        let dir = tempfile::tempdir().expect("temp dir");
        for name in ["t.arrow", "t.feather", "t.parquet"] {
            let path = dir.path().join(name);
            let mut bytes = Vec::new();
            write(&runs, Format::of(&path), &mut bytes).expect("write");
            std::fs::write(&path, bytes).expect("save");
            let back = read(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(bits(&back), bits(&whole), "{name}");
        }
    }

    #[test]
    fn a_run_longer_than_a_batch_reads_back_whole_and_in_order() {
        let rows = 2 * BATCH_ROWS + 5;
        let mut table = Table::new();
        table.push(
            "time_s",
            Values::F64((0..rows).map(|i| i as f64 * 1e-3).collect::<Vec<_>>().into()),
        );
        table.push(
            "fault",
            Values::I64((0..rows).map(|i| (i % 7 == 0).then_some(i as i64)).collect()),
        );
        table.push(
            "material",
            Values::Repeat {
                text: "cork".into(),
                rows,
            },
        );
        let dir = tempfile::tempdir().expect("temp dir");
        for name in ["long.arrow", "long.parquet"] {
            let path = dir.path().join(name);
            let mut bytes = Vec::new();
            write(std::slice::from_ref(&table), Format::of(&path), &mut bytes).expect("write");
            std::fs::write(&path, bytes).expect("save");
            let back = read(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(back.rows(), rows, "{name}");
            assert_eq!(back.column("time_s"), table.column("time_s"), "{name}");
            assert_eq!(back.column("fault"), table.column("fault"), "{name}");
            assert_eq!(
                back.column("material"),
                Some(&Values::Text(vec![Some("cork".into()); rows])),
                "{name}"
            );
        }
    }

    #[test]
    fn the_format_follows_the_name_and_mismatched_tables_are_refused() {
        let format = |name: &str| Format::of(Path::new(name));
        assert_eq!(
            [
                format("a.arrow"),
                format("a.FEATHER"),
                format("a.parquet"),
                format("a.csv"),
                format("-")
            ],
            [Format::Arrow, Format::Arrow, Format::Parquet, Format::Csv, Format::Csv]
        );
        let mut runs = two_runs();
        runs[1].columns.pop();
        let error = write(&runs, Format::Arrow, &mut Vec::new()).expect_err("mismatched");
        assert!(error.to_string().contains("differ"), "{error}");
        assert_eq!(Values::F64(vec![0.1 + 0.2].into()).field(0), "0.30000000000000004");
        assert_eq!(Values::I64(vec![None]).field(0), "");
    }

    #[test]
    fn a_files_fields_are_the_csvs_and_a_file_over_the_limit_is_refused() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("runs.parquet");
        let mut bytes = Vec::new();
        write(&two_runs(), Format::Parquet, &mut bytes).expect("write");
        std::fs::write(&path, &bytes).expect("save");
        let (header, rows) = read_fields(&path, 1 << 20).expect("read");
        assert_eq!(header, ["time_s", "skin_c", "fault", "thickness_m", "material"]);
        assert_eq!(rows.len(), 6);
        assert_eq!(
            rows[1],
            ["0", "NaN", "104", "0.01", "aluminium"],
            "the CSV's fields of the second row"
        );
        assert_eq!(rows[3][0], "0", "the second run's first time");
        assert_eq!(rows[5][1], "0.3333333333333333");
        assert_eq!(rows[0][2], "", "null as an empty field");
        let error = read_fields(&path, bytes.len() as u64 - 1).expect_err("over the limit");
        assert!(error.to_string().contains("at most"), "{error}");
        let error = read_fields(dir.path(), 1 << 20).expect_err("a folder");
        assert!(error.to_string().contains("not a regular file"), "{error}");
    }
}
