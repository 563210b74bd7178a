//! `thermode lab analyze`: the paper's section 4 analysis of material-identification sessions (identification rates,
//! confusion matrices, the Table 2 ratio table, the Table 3 χ² test, the confusion correlation, Figure 4 and, with
//! `--curves`, Figure 3), written as JSON, figures and a Markdown or HTML report.
//!
//! All outputs go to `--out` (default `lab-report/`): `analysis.json`, `trials.csv`, `figure4.svg`/`.png`
//! (`figure3.*` with curves) and `report.md` or `report.html`. They are staged and moved into place only after the
//! whole analysis succeeded, so a bad input (malformed row, missing column, empty file, unknown condition or material)
//! leaves nothing behind; the error names the file and line, and `main` exits with code 2.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use thermode_lab::analysis::{self, ReportFormat as LabFormat};

use crate::output::print_stdout;

/// Output format of `thermode lab analyze`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ReportFormat {
    /// Print the analysis JSON to standard output (also written to `<out>/analysis.json` if `--out` is given).
    Json,
    /// Write `<out>/report.md` and print its path.
    Md,
    /// Write `<out>/report.html` (a self-contained page) and print its path.
    Html,
}

/// Arguments of `thermode lab analyze`.
#[derive(Args, Debug)]
pub struct LabAnalyzeArgs {
    /// Session CSV files: one row per trial with the columns participant, condition (real|simulated), presented,
    /// identified, and optionally excluded (true/false/1/0); other columns are kept.
    #[arg(required = true, num_args = 1..)]
    files: Vec<PathBuf>,
    /// Output folder (created if missing; files of the same names are replaced). Default for `md` and `html`:
    /// `lab-report` in the current folder; `json` writes no file unless it is given.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Report format.
    #[arg(long, value_enum, default_value = "md")]
    format: ReportFormat,
    /// Curve CSV file for Figure 3: a `render` CSV (truth_skin_c real, skin_c simulated), a `serve --record` file
    /// (each touch: target_skin_c real, skin_c simulated), a `lab run` trial curve on a display (finger_c), or a
    /// table with time_s, finger_c | skin_c | skin_surface_c | truth_skin_c | target_skin_c, material, condition
    /// and an optional repetition; repeat for several files.
    #[arg(long)]
    curves: Vec<PathBuf>,
}

/// Where `md` and `html` reports go without `--out`: `lab-report` in the current folder.
pub const DEFAULT_REPORT_DIR: &str = "lab-report";

/// Runs `thermode lab analyze`.
pub fn run(args: &LabAnalyzeArgs) -> Result<()> {
    let mut result = analysis::analyze(&args.files)?;
    if !args.curves.is_empty() {
        result.curves = Some(analysis::analyze_curves(&args.curves)?);
    }
    let formats = match args.format {
        ReportFormat::Json => [LabFormat::Json],
        ReportFormat::Md => [LabFormat::Markdown],
        ReportFormat::Html => [LabFormat::Html],
    };
    match (args.format, &args.out) {
        (ReportFormat::Json, out) => {
            if let Some(out) = out {
                analysis::write_outputs(&result, out, &formats)?;
            }
            print_stdout(&(serde_json::to_string_pretty(&result)? + "\n"))
        }
        (ReportFormat::Md | ReportFormat::Html, out) => {
            let out = out.clone().unwrap_or_else(|| PathBuf::from(DEFAULT_REPORT_DIR));
            let written = analysis::write_outputs(&result, &out, &formats)?;
            let report = written.first().context("no report was written")?;
            print_stdout(&format!("{}\n", report.display()))
        }
    }
}
