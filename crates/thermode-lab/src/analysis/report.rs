//! Writing the analysis: `analysis.json`, `trials.csv`, the figures (SVG and PNG) and the Markdown/HTML reports.
//!
//! Everything is first written into a staging folder beside the output folder and moved into place only when every
//! file has been written, so an error never leaves half of the outputs behind. The reports are built once as a list
//! of [`Block`]s (headings, paragraphs, tables, figures) and rendered to Markdown and to a self-contained HTML page.

use std::path::{Path, PathBuf};

use super::figures;
use super::Analysis;
use crate::error::LabError;

mod blocks;
mod render;

pub use blocks::{report_blocks, Block, Cell, Emphasis, Table};
pub use render::{html, markdown};

/// Which report to write besides `analysis.json`, `trials.csv` and the figures (which are always written).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ReportFormat {
    /// Only the JSON document (and the figures).
    Json,
    /// `report.md`.
    Markdown,
    /// `report.html`.
    Html,
}

/// File name of the JSON document.
pub const JSON_FILE: &str = "analysis.json";
/// File name of the Markdown report.
pub const MARKDOWN_FILE: &str = "report.md";
/// File name of the HTML report.
pub const HTML_FILE: &str = "report.html";
/// File name of the echoed trials.
pub const TRIALS_FILE: &str = "trials.csv";

/// Writes the outputs of `analysis` into `out_dir` (created if missing) and returns their paths: the requested
/// reports first, then `analysis.json`, `trials.csv` and the figures. Nothing is moved into `out_dir` unless every
/// file was written.
pub fn write_outputs(analysis: &Analysis, out_dir: &Path, formats: &[ReportFormat]) -> Result<Vec<PathBuf>, LabError> {
    if out_dir.exists() && !out_dir.is_dir() {
        let source = std::io::Error::new(std::io::ErrorKind::AlreadyExists, "exists and is not a folder");
        return Err(LabError::io(out_dir, source));
    }
    let staging = staging_dir(out_dir)?;
    let names = match write_all(analysis, &staging, formats) {
        Ok(names) => names,
        Err(e) => {
            let _ = std::fs::remove_dir_all(&staging);
            return Err(e);
        }
    };
    publish(&staging, out_dir, &names)?;
    Ok(names.iter().map(|n| out_dir.join(n)).collect())
}

/// A fresh, empty folder beside `out_dir`.
fn staging_dir(out_dir: &Path) -> Result<PathBuf, LabError> {
    let parent = match out_dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).map_err(|e| LabError::io(&parent, e))?;
    let name = out_dir
        .file_name()
        .map_or("lab-report".into(), |n| n.to_string_lossy().into_owned());
    let staging = parent.join(format!(".{name}.staging-{}", std::process::id()));
    if staging.exists() {
        std::fs::remove_dir_all(&staging).map_err(|e| LabError::io(&staging, e))?;
    }
    std::fs::create_dir(&staging).map_err(|e| LabError::io(&staging, e))?;
    Ok(staging)
}

/// Writes every output into `dir`; returns the file names in report order.
fn write_all(analysis: &Analysis, dir: &Path, formats: &[ReportFormat]) -> Result<Vec<String>, LabError> {
    let mut names = Vec::new();
    let blocks = report_blocks(analysis);
    if formats.contains(&ReportFormat::Markdown) {
        write_text(dir, MARKDOWN_FILE, &markdown(&blocks), &mut names)?;
    }
    if formats.contains(&ReportFormat::Html) {
        write_text(dir, HTML_FILE, &html(&blocks), &mut names)?;
    }
    write_text(
        dir,
        JSON_FILE,
        &(serde_json::to_string_pretty(analysis)? + "\n"),
        &mut names,
    )?;
    write_text(dir, TRIALS_FILE, &trials_csv(analysis)?, &mut names)?;
    let mut plots = vec![("figure4", figures::figure4(&analysis.figure4))];
    if let Some(curves) = &analysis.curves {
        plots.push(("figure3", figures::figure3(curves)));
    }
    for (stem, figure) in plots {
        for extension in ["svg", "png"] {
            let name = format!("{stem}.{extension}");
            thermode_plot::write_figure(&figure, &dir.join(&name))?;
            names.push(name);
        }
    }
    Ok(names)
}

fn write_text(dir: &Path, name: &str, text: &str, names: &mut Vec<String>) -> Result<(), LabError> {
    let path = dir.join(name);
    std::fs::write(&path, text).map_err(|e| LabError::io(&path, e))?;
    names.push(name.to_string());
    Ok(())
}

/// The included trials with all their columns, plus `source_file` and `source_line`.
fn trials_csv(analysis: &Analysis) -> Result<String, LabError> {
    let sessions = &analysis.sessions;
    let csv_error = |e: csv::Error| LabError::Csv {
        file: PathBuf::from(TRIALS_FILE),
        line: None,
        message: e.to_string(),
    };
    let mut writer = csv::Writer::from_writer(Vec::new());
    let header = ["source_file", "source_line"]
        .into_iter()
        .chain(sessions.columns.iter().map(String::as_str));
    writer.write_record(header).map_err(csv_error)?;
    for trial in &sessions.trials {
        let mut record = vec![trial.file.display().to_string(), trial.line.to_string()];
        for column in &sessions.columns {
            let value = trial
                .fields
                .iter()
                .find(|(name, _)| name == column)
                .map(|(_, v)| v.clone());
            record.push(value.unwrap_or_default());
        }
        writer.write_record(&record).map_err(csv_error)?;
    }
    let bytes = writer.into_inner().map_err(|e| LabError::Csv {
        file: PathBuf::from(TRIALS_FILE),
        line: None,
        message: e.to_string(),
    })?;
    String::from_utf8(bytes).map_err(|e| LabError::Csv {
        file: PathBuf::from(TRIALS_FILE),
        line: None,
        message: e.to_string(),
    })
}

/// Moves the staged files into `out_dir`: a rename of the whole folder if `out_dir` does not exist yet, otherwise
/// file by file (replacing older outputs of the same names).
fn publish(staging: &Path, out_dir: &Path, names: &[String]) -> Result<(), LabError> {
    if !out_dir.exists() {
        return std::fs::rename(staging, out_dir).map_err(|e| LabError::io(out_dir, e));
    }
    for name in names {
        let target = out_dir.join(name);
        if let Err(e) = std::fs::rename(staging.join(name), &target) {
            let _ = std::fs::remove_dir_all(staging);
            return Err(LabError::io(target, e));
        }
    }
    std::fs::remove_dir(staging).map_err(|e| LabError::io(staging, e))
}
