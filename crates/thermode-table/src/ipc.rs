//! The Arrow IPC file (Feather v2) writer: every column's bytes go from the table's own values to the sink, with no
//! Arrow array built and no copy of a batch in memory. A `Float64` column without nulls (every number a run
//! computes) is written straight from its slice; validity bits, text offsets, text and nullable values are gathered
//! in one small reused buffer and written from it. The messages around the bytes are Arrow's own: the schema
//! message and the footer's schema from arrow-ipc's encoder, the record batch headers from its flatbuffer types, so
//! any Arrow reader (arrow-rs, pyarrow, R's arrow, polars) reads the file.
//!
//! Layout (Arrow's IPC file format, metadata version 5, uncompressed, little-endian): the magic `ARROW1` padded to
//! 64 bytes, the schema message, one record batch message per table (or per [`ARROW_BATCH_ROWS`] rows of one), the
//! end-of-stream marker, the footer (schema and the batches' places) with its length, and the magic again. Every
//! message and every buffer starts on a 64-byte boundary; a column without nulls has no validity buffer (Arrow's
//! "null count 0" form).
//!
//! [`ArrowFileWriter`] writes a file a table at a time: the rows of each call reach the sink before it returns, so
//! a writer fed during a run holds no more than one table.

use std::io::Write;
use std::ops::Range;

use arrow_buffer::ToByteSlice;
use arrow_ipc::convert::IpcSchemaEncoder;
use arrow_ipc::writer::{write_message, DictionaryTracker, EncodedData, IpcDataGenerator, IpcWriteOptions};
use arrow_ipc::{Block, Buffer, FieldNode, MessageHeader, MetadataVersion};
use arrow_schema::SchemaRef;
use flatbuffers::FlatBufferBuilder;

use crate::table::{Table, Values};
use crate::TableError;

/// Alignment of every message and buffer [bytes]: Arrow's recommended 64, as arrow-rs and pyarrow write.
const ALIGNMENT: usize = 64;
/// Zero bytes to pad with.
const PADDING: [u8; ALIGNMENT] = [0; ALIGNMENT];
/// The magic at the start and the end of an Arrow IPC file.
const MAGIC: &[u8; 6] = b"ARROW1";
/// The end-of-stream marker before the footer: continuation, then a message of length 0.
const END_OF_STREAM: [u8; 8] = [0xFF, 0xFF, 0xFF, 0xFF, 0, 0, 0, 0];
/// Size at which gathered bytes are written [bytes]: small enough to stay in cache and be reused, large enough that
/// a write's overhead does not count.
const SCRATCH_BYTES: usize = 64 * 1024;
/// Rows per record batch at most: a table longer than this (more than 17 minutes of one channel at 1 kHz) is
/// written as several batches, so that a batch's text stays within Arrow's 32-bit offsets.
pub const ARROW_BATCH_ROWS: usize = 1 << 20;

/// The sink and the number of bytes written to it (the next byte's offset in the file).
struct Out<W: Write> {
    sink: W,
    position: usize,
}

impl<W: Write> Out<W> {
    fn put(&mut self, bytes: &[u8]) -> Result<(), TableError> {
        self.sink.write_all(bytes)?;
        self.position += bytes.len();
        Ok(())
    }

    /// Zero bytes up to the next multiple of [`ALIGNMENT`].
    fn pad(&mut self) -> Result<(), TableError> {
        let pad = (ALIGNMENT - self.position % ALIGNMENT) % ALIGNMENT;
        self.put(&PADDING[..pad])
    }

    /// Writes a message header (`message`, a flatbuffer) framed as arrow-ipc frames it; its length with the frame.
    fn message(&mut self, message: EncodedData) -> Result<usize, TableError> {
        let (meta, body) = write_message(&mut self.sink, message, &IpcWriteOptions::default())?;
        self.position += meta + body;
        Ok(meta)
    }
}

/// An Arrow IPC file being written: [`ArrowFileWriter::try_new`] writes the header and schema,
/// [`ArrowFileWriter::write`] each table's rows, [`ArrowFileWriter::finish`] the footer.
pub struct ArrowFileWriter<W: Write> {
    out: Out<W>,
    schema: SchemaRef,
    /// Place and size of every record batch written, for the footer.
    blocks: Vec<Block>,
    /// Where computed bytes are gathered before they are written (reused).
    scratch: Vec<u8>,
}

impl<W: Write> ArrowFileWriter<W> {
    /// Starts a file with `schema` (the tables' columns, [`Table`]'s types) on `sink`: writes the magic and the
    /// schema message.
    pub fn try_new(sink: W, schema: SchemaRef) -> Result<Self, TableError> {
        let mut out = Out { sink, position: 0 };
        out.put(MAGIC)?;
        out.pad()?;
        let encoded = IpcDataGenerator::default().schema_to_bytes_with_dictionary_tracker(
            &schema,
            &mut DictionaryTracker::new(true),
            &IpcWriteOptions::default(),
        );
        out.message(encoded)?;
        Ok(ArrowFileWriter {
            out,
            schema,
            blocks: Vec::new(),
            scratch: Vec::with_capacity(SCRATCH_BYTES + ALIGNMENT),
        })
    }

    /// Writes the rows of `table` (the file's columns, names and types) as one record batch, or one per
    /// [`ARROW_BATCH_ROWS`] rows. A table of no rows writes nothing.
    pub fn write(&mut self, table: &Table<'_>) -> Result<(), TableError> {
        if table.schema() != self.schema {
            return Err(TableError::Shape(format!(
                "the table's columns differ from the file's: {:?} and {:?}",
                table.columns.iter().map(|(n, _)| n).collect::<Vec<_>>(),
                self.schema.fields().iter().map(|f| f.name()).collect::<Vec<_>>(),
            )));
        }
        table.check_shape()?;
        for start in (0..table.rows()).step_by(ARROW_BATCH_ROWS) {
            self.write_batch(table, start..(start + ARROW_BATCH_ROWS).min(table.rows()))?;
        }
        Ok(())
    }

    /// Writes the end-of-stream marker and the footer, flushes, and gives the sink back.
    pub fn finish(mut self) -> Result<W, TableError> {
        self.out.put(&END_OF_STREAM)?;
        let mut fbb = FlatBufferBuilder::new();
        let dictionaries = fbb.create_vector::<Block>(&[]);
        let record_batches = fbb.create_vector(&self.blocks);
        let schema = IpcSchemaEncoder::new().schema_to_fb_offset(&mut fbb, &self.schema);
        let mut footer = arrow_ipc::FooterBuilder::new(&mut fbb);
        footer.add_version(MetadataVersion::V5);
        footer.add_schema(schema);
        footer.add_dictionaries(dictionaries);
        footer.add_recordBatches(record_batches);
        let root = footer.finish();
        fbb.finish(root, None);
        let footer = fbb.finished_data();
        let length = i32::try_from(footer.len()).map_err(|_| TableError::Shape("footer over 2 GiB".into()))?;
        self.out.put(footer)?;
        self.out.put(&length.to_le_bytes())?;
        self.out.put(MAGIC)?;
        self.out.sink.flush()?;
        Ok(self.out.sink)
    }

    /// Writes `rows` of `table` as one record batch: its header, then every column's buffers.
    fn write_batch(&mut self, table: &Table<'_>, rows: Range<usize>) -> Result<(), TableError> {
        let mut nodes = Vec::with_capacity(table.columns.len());
        let mut buffers = Vec::new();
        let mut body = 0usize;
        for (name, values) in &table.columns {
            let nulls = null_count(values, rows.clone());
            nodes.push(FieldNode::new(rows.len() as i64, nulls as i64));
            for length in buffer_lengths(name, values, rows.clone(), nulls)? {
                buffers.push(Buffer::new(body as i64, length as i64));
                body += length.next_multiple_of(ALIGNMENT);
            }
        }
        let start = self.out.position;
        let ipc_message = batch_message(rows.len(), &nodes, &buffers, body);
        let meta = self.out.message(EncodedData {
            ipc_message,
            arrow_data: Vec::new(),
        })?;
        for ((_, values), node) in table.columns.iter().zip(&nodes) {
            self.write_column(values, rows.clone(), node.null_count() > 0)?;
        }
        let written = self.out.position - start - meta;
        if written != body {
            return Err(TableError::Shape(format!(
                "a record batch's body is {written} bytes, its header says {body}"
            )));
        }
        let meta = i32::try_from(meta).map_err(|_| TableError::Shape("a batch header over 2 GiB".into()))?;
        self.blocks.push(Block::new(start as i64, meta, body as i64));
        Ok(())
    }

    /// Writes the buffers of one column's `rows`: validity (only with nulls), then values, or offsets and text.
    fn write_column(&mut self, values: &Values<'_>, rows: Range<usize>, nulls: bool) -> Result<(), TableError> {
        if nulls {
            let end = rows.end;
            let bytes = rows
                .clone()
                .step_by(8)
                .map(|first| validity_byte(values, first..(first + 8).min(end)));
            self.put_each(bytes, |byte, out| out.push(byte))?;
        }
        match values {
            Values::F64(v) if cfg!(target_endian = "little") => {
                self.out.put(v[rows].to_byte_slice())?;
                self.out.pad()
            }
            Values::F64(v) => self.put_each(v[rows].iter(), |x, out| out.extend_from_slice(&x.to_le_bytes())),
            Values::F64Null(v) => self.put_each(v[rows].iter(), |x, out| {
                out.extend_from_slice(&x.unwrap_or(0.0).to_le_bytes())
            }),
            Values::I64(v) => self.put_each(v[rows].iter(), |x, out| {
                out.extend_from_slice(&x.unwrap_or(0).to_le_bytes())
            }),
            Values::Text(v) => {
                let texts = || v[rows.clone()].iter().map(|s| s.as_deref().unwrap_or(""));
                self.put_text(texts)
            }
            Values::Repeat { text, .. } => self.put_text(|| std::iter::repeat_n(text.as_str(), rows.len())),
        }
    }

    /// Writes the offsets and then the bytes of `texts` (a text column's two buffers).
    fn put_text<'t, I: Iterator<Item = &'t str>>(&mut self, texts: impl Fn() -> I) -> Result<(), TableError> {
        let mut end = 0i32;
        let offsets = std::iter::once(0).chain(texts().map(|text| {
            end += text.len() as i32;
            end
        }));
        self.put_each(offsets, |offset, out| out.extend_from_slice(&offset.to_le_bytes()))?;
        self.put_each(texts(), |text, out| out.extend_from_slice(text.as_bytes()))
    }

    /// Writes the bytes `encode` gives for each of `items`, gathered [`SCRATCH_BYTES`] at a time, then pads.
    fn put_each<T>(
        &mut self,
        items: impl Iterator<Item = T>,
        mut encode: impl FnMut(T, &mut Vec<u8>),
    ) -> Result<(), TableError> {
        self.scratch.clear();
        for item in items {
            encode(item, &mut self.scratch);
            if self.scratch.len() >= SCRATCH_BYTES {
                self.out.put(&self.scratch)?;
                self.scratch.clear();
            }
        }
        self.out.put(&self.scratch)?;
        self.out.pad()
    }
}

/// The null values among `rows` of `values`.
fn null_count(values: &Values<'_>, rows: Range<usize>) -> usize {
    fn nones<T>(v: &[Option<T>]) -> usize {
        v.iter().filter(|x| x.is_none()).count()
    }
    match values {
        Values::F64(_) | Values::Repeat { .. } => 0,
        Values::F64Null(v) => nones(&v[rows]),
        Values::I64(v) => nones(&v[rows]),
        Values::Text(v) => nones(&v[rows]),
    }
}

/// The byte lengths of the buffers of `rows` of the column `name` with `nulls` null values (unpadded): validity
/// (empty without nulls), then values (8 bytes a row), or offsets (4 bytes a row and one) and text. Text over 2 GiB
/// in one batch is refused.
fn buffer_lengths(name: &str, values: &Values<'_>, rows: Range<usize>, nulls: usize) -> Result<Vec<usize>, TableError> {
    let validity = if nulls == 0 { 0 } else { rows.len().div_ceil(8) };
    let text = match values {
        Values::F64(_) | Values::F64Null(_) | Values::I64(_) => return Ok(vec![validity, rows.len() * 8]),
        Values::Text(v) => v[rows.clone()].iter().map(|s| s.as_ref().map_or(0, String::len)).sum(),
        Values::Repeat { text, .. } => text.len().saturating_mul(rows.len()),
    };
    if i32::try_from(text).is_err() {
        return Err(TableError::Shape(format!(
            "column `{name}`: {text} bytes of text in {} rows, over Arrow's 2 GiB a batch",
            rows.len()
        )));
    }
    Ok(vec![validity, (rows.len() + 1) * 4, text])
}

/// The validity bits of `rows` (at most 8), least significant first: 1 for a value, 0 for null.
fn validity_byte(values: &Values<'_>, rows: Range<usize>) -> u8 {
    let first = rows.start;
    rows.filter(|&row| !values.is_null(row))
        .fold(0u8, |byte, row| byte | 1 << (row - first))
}

/// The header of a record batch of `rows` rows: its field nodes, buffers and body length, as a flatbuffer message.
fn batch_message(rows: usize, nodes: &[FieldNode], buffers: &[Buffer], body: usize) -> Vec<u8> {
    let mut fbb = FlatBufferBuilder::new();
    let buffers = fbb.create_vector(buffers);
    let nodes = fbb.create_vector(nodes);
    let mut batch = arrow_ipc::RecordBatchBuilder::new(&mut fbb);
    batch.add_length(rows as i64);
    batch.add_nodes(nodes);
    batch.add_buffers(buffers);
    let batch = batch.finish().as_union_value();
    let mut message = arrow_ipc::MessageBuilder::new(&mut fbb);
    message.add_version(MetadataVersion::V5);
    message.add_header_type(MessageHeader::RecordBatch);
    message.add_bodyLength(body as i64);
    message.add_header(batch);
    let root = message.finish();
    fbb.finish(root, None);
    fbb.finished_data().to_vec()
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    /// A table of `rows` rows with every kind of column and nulls that do not fall on byte boundaries.
    fn mixed(rows: usize, material: &str) -> Table<'static> {
        let mut t = Table::new();
        let specials = [
            0.1 + 0.2,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            -0.0,
            f64::MIN_POSITIVE,
            1e300,
        ];
        t.push(
            "x",
            Values::F64(
                (0..rows)
                    .map(|i| specials[i % specials.len()] * (i + 1) as f64)
                    .collect::<Vec<_>>()
                    .into(),
            ),
        );
        t.push(
            "maybe",
            Values::F64Null((0..rows).map(|i| (i % 3 != 0).then_some(i as f64 / 7.0)).collect()),
        );
        t.push(
            "code",
            Values::I64((0..rows).map(|i| (i % 5 == 2).then_some(-(i as i64) << 40)).collect()),
        );
        let text = |i: usize| match i % 4 {
            0 => None,
            1 => Some(String::new()),
            2 => Some("Zürich €".to_string()),
            _ => Some(format!("row {i}")),
        };
        t.push("note", Values::Text((0..rows).map(text).collect()));
        t.push("never", Values::Text(vec![None; rows]));
        t.push(
            "material",
            Values::Repeat {
                text: material.into(),
                rows,
            },
        );
        t
    }

    /// Every value of `table` as text, floats by their bits.
    fn bits(table: &Table) -> Vec<(String, Vec<String>)> {
        let float = |x: f64| format!("{:016x}", x.to_bits());
        let show = |v: &Values| match v {
            Values::F64(v) => v.iter().map(|&x| float(x)).collect(),
            Values::F64Null(v) => v
                .iter()
                .map(|x| x.map(float).unwrap_or_else(|| "null".into()))
                .collect(),
            other => (0..other.len())
                .map(|i| {
                    if other.is_null(i) {
                        "null".into()
                    } else {
                        other.field(i)
                    }
                })
                .collect(),
        };
        table.columns.iter().map(|(n, v)| (n.clone(), show(v))).collect()
    }

    /// `tables` one after the other, as [`crate::read`] gives them (a repeat as text).
    fn concatenated(tables: &[Table]) -> Vec<(String, Vec<String>)> {
        let mut all = bits(&tables[0]);
        for table in &tables[1..] {
            for ((_, column), (_, more)) in all.iter_mut().zip(bits(table)) {
                column.extend(more);
            }
        }
        all
    }

    fn ours(tables: &[Table], path: &Path) {
        let mut writer = ArrowFileWriter::try_new(Vec::new(), tables[0].schema()).expect("start");
        for table in tables {
            writer.write(table).expect("write");
        }
        std::fs::write(path, writer.finish().expect("finish")).expect("save");
    }

    /// The same tables through arrow-rs's own IPC writer (record batches built as Arrow arrays): the reference.
    fn arrow_rs(tables: &[Table], path: &Path) {
        let schema = tables[0].schema();
        let mut writer = arrow_ipc::writer::FileWriter::try_new(Vec::new(), &schema).expect("start");
        for table in tables {
            for batch in table.batches(&schema) {
                writer.write(&batch.expect("batch")).expect("write");
            }
        }
        std::fs::write(path, writer.into_inner().expect("finish")).expect("save");
    }

    #[test]
    fn every_kind_of_column_reads_back_as_written_and_as_arrow_rs_writes_it() {
        let tables = [
            mixed(21, "aluminium"),
            mixed(0, "aluminium"),
            mixed(1, "wood"),
            mixed(64, ""),
        ];
        let dir = tempfile::tempdir().expect("temp dir");
        let (mine, reference) = (dir.path().join("ours.arrow"), dir.path().join("arrow-rs.arrow"));
        ours(&tables, &mine);
        arrow_rs(&tables, &reference);
        let expected = concatenated(&tables);
        let back = crate::read(&mine).unwrap_or_else(|e| panic!("our file: {e}"));
        let by_arrow_rs = crate::read(&reference).unwrap_or_else(|e| panic!("arrow-rs's file: {e}"));
        assert_eq!(bits(&by_arrow_rs), expected, "the reference writer and reader");
        assert_eq!(bits(&back), expected, "our writer, read by arrow-rs's reader");
        let batches = arrow_ipc::reader::FileReader::try_new(std::fs::File::open(&mine).expect("open"), None)
            .expect("reader")
            .map(|b| b.expect("batch").num_rows())
            .collect::<Vec<_>>();
        assert_eq!(batches, [21, 1, 64], "one record batch per table with rows");
    }

    #[test]
    fn a_table_longer_than_a_batch_is_split_and_mismatched_tables_are_refused() {
        let rows = ARROW_BATCH_ROWS + 3;
        let mut table = Table::new();
        table.push("t", Values::F64((0..rows).map(|i| i as f64).collect::<Vec<_>>().into()));
        table.push(
            "material",
            Values::Repeat {
                text: "cork".into(),
                rows,
            },
        );
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("long.arrow");
        ours(std::slice::from_ref(&table), &path);
        let reader =
            arrow_ipc::reader::FileReader::try_new(std::fs::File::open(&path).expect("open"), None).expect("reader");
        let batches: Vec<usize> = reader.map(|b| b.expect("batch").num_rows()).collect();
        assert_eq!(batches, [ARROW_BATCH_ROWS, 3]);
        let back = crate::read(&path).expect("read");
        assert_eq!(back.column("t"), table.column("t"));
        assert_eq!(
            back.column("material").map(|m| m.field(rows - 1)),
            Some("cork".to_string())
        );

        let mut writer = ArrowFileWriter::try_new(Vec::new(), table.schema()).expect("start");
        let other = mixed(3, "wood");
        let error = writer.write(&other).expect_err("other columns");
        assert!(error.to_string().contains("differ"), "{error}");
        let mut short = table.clone();
        short.columns[1].1 = Values::Repeat {
            text: "cork".into(),
            rows: 2,
        };
        let error = writer.write(&short).expect_err("a short column");
        assert!(error.to_string().contains("`material` has not the table's"), "{error}");
    }
}
