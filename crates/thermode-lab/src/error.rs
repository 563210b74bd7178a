//! The lab's typed error: every variant names the file (and the line, where there is one) so that the message can be
//! shown to an experimenter as it is. The CLI turns any of them into exit code 2.

use std::path::PathBuf;

use thiserror::Error;

/// Why lab data could not be read, analysed or written.
#[derive(Debug, Error)]
pub enum LabError {
    /// A file could not be read or written.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file or folder concerned.
        path: PathBuf,
        /// The operating-system error (in the message, not repeated as a source).
        error: std::io::Error,
    },
    /// The CSV reader failed (e.g. invalid UTF-8); `line` is 1-based where the reader knows it.
    #[error("{}{}: {message}", file.display(), at_line(*line))]
    Csv {
        /// The CSV file.
        file: PathBuf,
        /// 1-based line of the problem, when known.
        line: Option<u64>,
        /// The reader's message.
        message: String,
    },
    /// A data row does not have as many fields as the header.
    #[error("{}:{line}: malformed row: {found} fields, the header has {expected}", file.display())]
    MalformedRow {
        /// The CSV file.
        file: PathBuf,
        /// 1-based line of the row.
        line: u64,
        /// Number of header fields.
        expected: usize,
        /// Number of fields in the row.
        found: usize,
    },
    /// A required column is absent from the header.
    #[error("{}: missing column `{column}`", file.display())]
    MissingColumn {
        /// The CSV file.
        file: PathBuf,
        /// The required column name.
        column: String,
    },
    /// A column that the analysis reads appears twice in the header.
    #[error("{}: column `{column}` appears more than once", file.display())]
    DuplicateColumn {
        /// The CSV file.
        file: PathBuf,
        /// The repeated column name.
        column: String,
    },
    /// The file has no data rows (it is empty or holds only a header).
    #[error("{}: empty file (no data rows)", file.display())]
    EmptyFile {
        /// The CSV file.
        file: PathBuf,
    },
    /// The `condition` field is neither `real` nor `simulated`.
    #[error("{}:{line}: condition `{value}` is neither `real` nor `simulated`", file.display())]
    BadCondition {
        /// The CSV file.
        file: PathBuf,
        /// 1-based line of the row.
        line: u64,
        /// The value found.
        value: String,
    },
    /// A material name that is not in the model's material library (`thermode materials` lists it).
    #[error("{}:{line}: unknown material `{value}` in column `{column}`{}", file.display(), suggest(close))]
    UnknownMaterial {
        /// The CSV file.
        file: PathBuf,
        /// 1-based line of the row.
        line: u64,
        /// `presented`, `identified` or `material`.
        column: String,
        /// The value found.
        value: String,
        /// Library names close to `value` (may be empty).
        close: Vec<String>,
    },
    /// An identified material that was never presented (the response options are the presented materials).
    #[error(
        "{}:{line}: identified material `{value}` is not a response option (the presented materials: {})",
        file.display(),
        options.join(", ")
    )]
    NotAnOption {
        /// The CSV file.
        file: PathBuf,
        /// 1-based line of the row.
        line: u64,
        /// The identified material.
        value: String,
        /// The response options (all presented materials).
        options: Vec<String>,
    },
    /// A field that cannot be parsed or is out of range (e.g. `excluded = maybe`, a non-finite temperature).
    #[error("{}:{line}: column `{column}` = `{value}`: {expected}", file.display())]
    BadField {
        /// The CSV file.
        file: PathBuf,
        /// 1-based line of the row.
        line: u64,
        /// The column.
        column: String,
        /// The value found.
        value: String,
        /// What was expected instead.
        expected: String,
    },
    /// The data as a whole cannot be analysed (no input files, every trial excluded, a curve without samples, …).
    #[error("{0}")]
    NoData(String),
    /// A procedure session's file is unusable (its sidecar, rows or trace).
    #[error("{}: {message}", file.display())]
    Procedure {
        /// The file.
        file: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A figure could not be drawn or written.
    #[error("figure: {0}")]
    Plot(#[from] thermode_plot::PlotError),
    /// The analysis could not be serialised to JSON.
    #[error("JSON: {0}")]
    Json(#[from] serde_json::Error),
}

fn suggest(close: &[String]) -> String {
    if close.is_empty() {
        String::new()
    } else {
        format!("; did you mean {}?", close.join(", "))
    }
}

fn at_line(line: Option<u64>) -> String {
    line.map(|l| format!(":{l}")).unwrap_or_default()
}

impl LabError {
    /// Wraps an I/O error with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        LabError::Io {
            path: path.into(),
            error,
        }
    }
}
