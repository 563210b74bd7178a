//! `thermode lab analyze`: the paper's section 4 analysis of material-identification sessions (identification rates,
//! confusion matrices, the Table 2 ratio table, the Table 3 χ² test, the confusion correlation, Figure 4 and, with
//! `--curves`, Figure 3), written as JSON, figures and a Markdown or HTML report.
//!
//! All outputs go to `--out` (default `lab-report/`): `analysis.json`, `trials.csv`, `figure4.svg`/`.png`
//! (`figure3.*` with curves) and `report.md` or `report.html`. They are staged and moved into place only after the
//! whole analysis succeeded, so a bad input (malformed row, missing column, empty file, unknown condition or material)
//! leaves nothing behind; the error names the file and line, and `main` exits with code 2.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use thermode_lab::analysis::{self, ReportFormat as LabFormat};
use thermode_lab::procedure::analysis as procedure;
use thermode_procedures::analysis::parse_reference;

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
    /// Procedure sessions: the DFNS reference table (CSV: test, site, sex, age_band, mean, sd; mean and sd in the
    /// compared space, log10 for CDT, WDT and TSL) for z-scores. Needs --site, --sex and --age-band.
    #[arg(long, value_name = "FILE.csv", requires_all = ["site", "sex", "age_band"])]
    reference: Option<PathBuf>,
    /// The participants' body site in the reference table (e.g. hand).
    #[arg(long, requires = "reference")]
    site: Option<String>,
    /// The participants' sex in the reference table (e.g. female).
    #[arg(long, requires = "reference")]
    sex: Option<String>,
    /// The participants' age band in the reference table (e.g. 20-40).
    #[arg(long, requires = "reference")]
    age_band: Option<String>,
}

/// Where `md` and `html` reports go without `--out`: `lab-report` in the current folder.
pub const DEFAULT_REPORT_DIR: &str = "lab-report";

/// Runs `thermode lab analyze`.
pub fn run(args: &LabAnalyzeArgs) -> Result<()> {
    if args.files.iter().any(|f| procedure::is_procedure_csv(f)) {
        return run_procedures(args);
    }
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

/// Whether `file` is the events file (`<stem>_events.csv`) of a session `<stem>.csv` also among `files`: a glob over
/// a participant's sessions matches both, and the analysis reads the events with their session.
fn is_events_of_a_given_session(file: &Path, files: &[PathBuf]) -> bool {
    let Some(stem) = file
        .file_name()
        .and_then(|n| n.to_str())
        .and_then(|n| n.strip_suffix("_events.csv"))
    else {
        return false;
    };
    let session = file.with_file_name(format!("{stem}.csv"));
    files.contains(&session)
}

/// `lab analyze` of procedure sessions: thresholds, z-scores, estimates, ratings, a trace figure per trial.
fn run_procedures(args: &LabAnalyzeArgs) -> Result<()> {
    let files: Vec<PathBuf> = args
        .files
        .iter()
        .filter(|f| !is_events_of_a_given_session(f, &args.files))
        .cloned()
        .collect();
    if let Some(other) = files.iter().find(|f| !procedure::is_procedure_csv(f)) {
        anyhow::bail!(
            "{}: not a procedure session; analyse identification sessions and procedure sessions separately",
            other.display()
        );
    }
    let reference = match (&args.reference, &args.site, &args.sex, &args.age_band) {
        (Some(path), Some(site), Some(sex), Some(age_band)) => {
            let text = std::fs::read_to_string(path).with_context(|| path.display().to_string())?;
            Some(procedure::ReferenceChoice {
                rows: parse_reference(&text).with_context(|| path.display().to_string())?,
                site: site.clone(),
                sex: sex.clone(),
                age_band: age_band.clone(),
            })
        }
        _ => None,
    };
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from(DEFAULT_REPORT_DIR));
    let figures = (args.format != ReportFormat::Json || args.out.is_some()).then_some(out.as_path());
    if args.format == ReportFormat::Html {
        anyhow::bail!("--format html: a procedure session's report is Markdown (md) or JSON");
    }
    let sessions = procedure::analyze_sessions(&files, reference.as_ref(), figures)?;
    if figures.is_some() {
        std::fs::create_dir_all(&out).with_context(|| out.display().to_string())?;
    }
    let json = serde_json::to_string_pretty(&sessions)? + "\n";
    if figures.is_some() {
        std::fs::write(out.join("analysis.json"), &json)?;
    }
    match args.format {
        ReportFormat::Json => print_stdout(&json),
        ReportFormat::Md | ReportFormat::Html => {
            let report = out.join("report.md");
            std::fs::write(&report, procedure::markdown(&sessions))?;
            print_stdout(&format!("{}\n", report.display()))
        }
    }
}
