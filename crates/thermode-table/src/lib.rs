//! thermode-table: the tables thermode writes as CSV (`simulate`, `render`), also as columnar files that pandas,
//! polars, R and MATLAB read natively: Arrow IPC (Feather v2) when the output's name ends in `.arrow` or
//! `.feather`, Parquet when it ends in `.parquet` ([`Format::of`]). The columns and their order are the CSV's, and
//! every value is the one the CSV holds: floats as the exact `f64` (the CSV's exact default form reads back as
//! the same number), integers (`contact`, `fault`) as 64-bit integers, text as UTF-8; an empty CSV field is null.
//!
//! A file is written from one [`Table`] per run (the rows a CSV writes for one material or one render run); each
//! becomes one record batch (Arrow) or row group (Parquet), so the file's rows are the CSV's rows in order.
//! [`read`] reads a file back into one table (the readers of thermode's CSVs use it for these files).
//!
//! Arrow IPC is written uncompressed (the fastest to write and to read); Parquet uncompressed with dictionary
//! encoding (no compression codec is compiled in).

use std::borrow::Cow;
use std::fs::File;
use std::io::{Read, Seek, Write};
use std::ops::Range;
use std::path::Path;
use std::sync::Arc;

use arrow_array::{Array, ArrayRef, Float64Array, Int64Array, RecordBatch, RecordBatchReader, StringArray};
use arrow_schema::{ArrowError, DataType, Field, Schema, SchemaRef};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::ArrowWriter;
use parquet::errors::ParquetError;

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

/// Rows per record batch written: small enough that the buffers of a batch are reused from one batch to the next
/// (not fresh pages for a whole run), large enough that a batch's overhead does not count.
pub const BATCH_ROWS: usize = 16 * 1024;

/// One column's values (the numbers borrowed from the run that holds them, or owned).
#[derive(Debug, Clone, PartialEq)]
pub enum Values<'a> {
    /// Floating-point numbers (NaN kept as NaN, as the CSV writes `NaN`).
    F64(Cow<'a, [f64]>),
    /// Floating-point numbers of a column that may be empty (a recording's material properties outside a touch);
    /// `None` is an empty CSV field.
    F64Null(Vec<Option<f64>>),
    /// Integers; `None` is an empty CSV field.
    I64(Vec<Option<i64>>),
    /// Text; `None` is an empty CSV field.
    Text(Vec<Option<String>>),
    /// The same text in every one of `rows` rows (a run's material, controller, renderer): written as a text
    /// column, built without a string per row. [`read`] gives [`Values::Text`].
    Repeat {
        /// The text of every row.
        text: String,
        /// Number of rows.
        rows: usize,
    },
}

impl Values<'_> {
    /// Number of values.
    pub fn len(&self) -> usize {
        match self {
            Values::F64(v) => v.len(),
            Values::F64Null(v) => v.len(),
            Values::I64(v) => v.len(),
            Values::Text(v) => v.len(),
            Values::Repeat { rows, .. } => *rows,
        }
    }

    /// Whether there are no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The value of `row` as the CSV field that holds it: a float in its shortest exact form (`NaN`, `inf`,
    /// `-inf` as Rust writes them), an integer in decimal, text as it is, empty for null.
    pub fn field(&self, row: usize) -> String {
        match self {
            Values::F64(v) => v[row].to_string(),
            Values::F64Null(v) => v[row].map(|x| x.to_string()).unwrap_or_default(),
            Values::I64(v) => v[row].map(|x| x.to_string()).unwrap_or_default(),
            Values::Text(v) => v[row].clone().unwrap_or_default(),
            Values::Repeat { text, .. } => text.clone(),
        }
    }

    fn data_type(&self) -> DataType {
        match self {
            Values::F64(_) | Values::F64Null(_) => DataType::Float64,
            Values::I64(_) => DataType::Int64,
            Values::Text(_) | Values::Repeat { .. } => DataType::Utf8,
        }
    }

    /// The values of `rows` as an Arrow array.
    fn array(&self, rows: Range<usize>) -> ArrayRef {
        match self {
            Values::F64(v) => Arc::new(Float64Array::from(v[rows].to_vec())),
            Values::F64Null(v) => Arc::new(Float64Array::from(v[rows].to_vec())),
            Values::I64(v) => Arc::new(Int64Array::from(v[rows].to_vec())),
            Values::Text(v) => Arc::new(v[rows].iter().map(Option::as_deref).collect::<StringArray>()),
            Values::Repeat { text, .. } => Arc::new(StringArray::from_iter_values(std::iter::repeat_n(
                text.as_str(),
                rows.len(),
            ))),
        }
    }

    fn append(&mut self, array: &dyn Array, name: &str) -> Result<(), TableError> {
        let any = array.as_any();
        let wrong = || TableError::Shape(format!("column `{name}` changes its type between record batches"));
        match self {
            Values::F64(v) => {
                let a = any.downcast_ref::<Float64Array>().ok_or_else(wrong)?;
                v.to_mut()
                    .extend((0..a.len()).map(|i| if a.is_null(i) { f64::NAN } else { a.value(i) }));
            }
            Values::F64Null(v) => v.extend(any.downcast_ref::<Float64Array>().ok_or_else(wrong)?.iter()),
            Values::I64(v) => v.extend(any.downcast_ref::<Int64Array>().ok_or_else(wrong)?.iter()),
            Values::Text(v) => {
                let a = any.downcast_ref::<StringArray>().ok_or_else(wrong)?;
                v.extend(a.iter().map(|s| s.map(str::to_string)));
            }
            Values::Repeat { .. } => return Err(wrong()),
        }
        Ok(())
    }

    fn empty_like(field: &Field) -> Result<Values<'static>, TableError> {
        let name = field.name();
        match field.data_type() {
            DataType::Float64 if field.is_nullable() => Ok(Values::F64Null(Vec::new())),
            DataType::Float64 => Ok(Values::F64(Cow::Owned(Vec::new()))),
            DataType::Int64 => Ok(Values::I64(Vec::new())),
            DataType::Utf8 => Ok(Values::Text(Vec::new())),
            other => Err(TableError::Shape(format!(
                "column `{name}` is {other}; thermode's tables hold Float64, Int64 and Utf8 columns"
            ))),
        }
    }
}

/// Named columns of equal length, in the CSV's order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Table<'a> {
    /// (name, values) of every column.
    pub columns: Vec<(String, Values<'a>)>,
}

impl<'a> Table<'a> {
    /// An empty table, to which [`Table::push`] adds columns.
    pub fn new() -> Self {
        Table::default()
    }

    /// Adds the column `name` with `values`.
    pub fn push(&mut self, name: impl Into<String>, values: Values<'a>) {
        self.columns.push((name.into(), values));
    }

    /// Number of rows (of the first column; 0 without columns).
    pub fn rows(&self) -> usize {
        self.columns.first().map_or(0, |(_, v)| v.len())
    }

    /// The values of the column `name`, if there is one.
    pub fn column(&self, name: &str) -> Option<&Values<'a>> {
        self.columns.iter().find(|(n, _)| n == name).map(|(_, v)| v)
    }

    fn schema(&self) -> SchemaRef {
        let fields: Vec<Field> = self
            .columns
            .iter()
            .map(|(name, values)| Field::new(name, values.data_type(), !matches!(values, Values::F64(_))))
            .collect();
        Arc::new(Schema::new(fields))
    }

    /// The table as record batches of at most [`BATCH_ROWS`] rows, built one at a time.
    fn batches<'t>(&'t self, schema: &'t SchemaRef) -> impl Iterator<Item = Result<RecordBatch, TableError>> + 't {
        let shape = match self.columns.iter().find(|(_, v)| v.len() != self.rows()) {
            Some((name, _)) => Err(TableError::Shape(format!(
                "column `{name}` has not the table's {} rows",
                self.rows()
            ))),
            None => Ok(()),
        };
        let starts = (0..self.rows()).step_by(BATCH_ROWS);
        let batches = starts.map(move |start| {
            let rows = start..(start + BATCH_ROWS).min(self.rows());
            let arrays = self.columns.iter().map(|(_, v)| v.array(rows.clone())).collect();
            Ok(RecordBatch::try_new(schema.clone(), arrays)?)
        });
        shape.err().map(Err).into_iter().chain(batches)
    }
}

/// Writes `tables` (one per run, all with the same columns) to `sink` in `format` (Arrow or Parquet), their rows in
/// order (record batches of at most [`BATCH_ROWS`] rows). CSV is not written here: thermode's CSV writers stay as
/// they are.
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
    match format {
        Format::Arrow => {
            let mut writer = arrow_ipc::writer::FileWriter::try_new(sink, &schema)?;
            for table in tables {
                for batch in table.batches(&schema) {
                    writer.write(&batch?)?;
                }
            }
            writer.finish()?;
        }
        Format::Parquet => {
            // The Parquet writer wants a sink it can send between threads: the file is built in memory.
            let mut writer = ArrowWriter::try_new(Vec::new(), schema.clone(), None)?;
            for table in tables {
                for batch in table.batches(&schema) {
                    writer.write(&batch?)?;
                }
            }
            sink.write_all(&writer.into_inner()?)?;
        }
        Format::Csv => {
            return Err(TableError::Shape(
                "CSV is written by thermode's CSV writers".to_string(),
            ))
        }
    }
    Ok(())
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
}
