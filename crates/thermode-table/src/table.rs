//! The table thermode writes: named columns of equal length in the CSV's order ([`Table`]), each a run of numbers
//! borrowed from the run that computed them or owned ([`Values`]); the Arrow arrays and record batches Parquet is
//! written from, and the columns a file reads back into.

use std::borrow::Cow;
use std::ops::Range;
use std::sync::Arc;

use arrow_array::{Array, ArrayRef, Float64Array, Int64Array, RecordBatch, StringArray};
use arrow_schema::{DataType, Field, Schema, SchemaRef};

use crate::TableError;

/// Rows per record batch given to the Parquet writer: small enough that the buffers of a batch are reused from one
/// batch to the next (not fresh pages for a whole run), large enough that a batch's overhead does not count.
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
    /// column, built without a string per row. [`crate::read`] gives [`Values::Text`].
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

    /// Whether the value of `row` is null (an empty CSV field).
    pub fn is_null(&self, row: usize) -> bool {
        match self {
            Values::F64(_) | Values::Repeat { .. } => false,
            Values::F64Null(v) => v[row].is_none(),
            Values::I64(v) => v[row].is_none(),
            Values::Text(v) => v[row].is_none(),
        }
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

    /// The Arrow type of the column.
    pub(crate) fn data_type(&self) -> DataType {
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

    /// Adds the values of `array` (a record batch's column `name`, of this column's type) at the end.
    pub(crate) fn append(&mut self, array: &dyn Array, name: &str) -> Result<(), TableError> {
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

    /// An empty column of the type of `field` (a file's column); types thermode does not write are refused.
    pub(crate) fn empty_like(field: &Field) -> Result<Values<'static>, TableError> {
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

    /// The Arrow schema of the columns: `F64` as a Float64 field without nulls, `F64Null` as a nullable Float64,
    /// `I64` as a nullable Int64, text as a nullable Utf8.
    pub(crate) fn schema(&self) -> SchemaRef {
        let fields: Vec<Field> = self
            .columns
            .iter()
            .map(|(name, values)| Field::new(name, values.data_type(), !matches!(values, Values::F64(_))))
            .collect();
        Arc::new(Schema::new(fields))
    }

    /// Every column has the table's rows; else which does not.
    pub(crate) fn check_shape(&self) -> Result<(), TableError> {
        match self.columns.iter().find(|(_, v)| v.len() != self.rows()) {
            Some((name, _)) => Err(TableError::Shape(format!(
                "column `{name}` has not the table's {} rows",
                self.rows()
            ))),
            None => Ok(()),
        }
    }

    /// The table as record batches of at most [`BATCH_ROWS`] rows, built one at a time.
    pub(crate) fn batches<'t>(
        &'t self,
        schema: &'t SchemaRef,
    ) -> impl Iterator<Item = Result<RecordBatch, TableError>> + 't {
        let shape = self.check_shape();
        let starts = (0..self.rows()).step_by(BATCH_ROWS);
        let batches = starts.map(move |start| {
            let rows = start..(start + BATCH_ROWS).min(self.rows());
            let arrays = self.columns.iter().map(|(_, v)| v.array(rows.clone())).collect();
            Ok(RecordBatch::try_new(schema.clone(), arrays)?)
        });
        shape.err().map(Err).into_iter().chain(batches)
    }
}
