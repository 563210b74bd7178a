//! The paper's section 4 analysis of material-identification sessions, with figures and reports.
//!
//! [`analyze`] reads session CSVs ([`data`] describes the format) and computes:
//! - identification rates per condition and per (condition, material), and the chance level 1 / options;
//! - confusion matrices (presented × identified) per condition, counts and row probabilities;
//! - the probability ratio table of eq. 8 / Table 2, P_sim(identified | presented) / P_real(identified | presented),
//!   missing where the real probability is zero, with the mean ratio over correct and over false cells;
//! - the χ² homogeneity test of Table 3 over the simulated true/false counts per material;
//! - Pearson's r between the real and simulated row-probability matrices over the off-diagonal cells (the kind of
//!   mistakes; the paper's r = 0.90), and over all cells;
//! - Figure 4: the distribution of Δc and Δk (identified − presented) and the share of mistakes within
//!   ±0.05 cal/(g·°C) and ±0.005 cal/(cm·s·°C);
//! - beyond the paper, the just-noticeable differences it left open ([`jnd`]: a cumulative-Gaussian fit to |Δk| and
//!   |Δc| of the mistakes, with bootstrap intervals) and an honest comparison of the real and simulated confusions
//!   ([`comparison`]: r over the off-diagonal cells not zero in both conditions, with a permutation p-value).
//!
//! [`analyze_curves`] compares recorded or rendered temperature curves (Figure 3). [`write_outputs`] writes the JSON,
//! the figures and the Markdown/HTML reports without ever leaving half of them behind.

pub mod comparison;
pub mod curves;
pub mod data;
pub mod figure4;
pub mod figures;
pub mod jnd;
pub mod report;
pub mod stats;
pub mod tables;

use std::path::PathBuf;

use serde::Serialize;

pub use comparison::ConfusionComparison;
pub use curves::{analyze_curves, CurveAnalysis};
pub use data::{read_sessions, MaterialInfo, Sessions, Trial};
pub use figure4::Figure4;
pub use jnd::Jnd;
pub use report::{write_outputs, ReportFormat};
pub use tables::{ChiSquareReport, ConditionPair, ConditionRates, Confusion, Correlation, RatioTable};

use crate::error::LabError;

/// Everything the paper's section 4 reports, for one data set. Serialises to the `analysis.json` document.
#[derive(Debug, Clone, Serialize)]
pub struct Analysis {
    /// The session files analysed, as given.
    pub input_files: Vec<String>,
    /// Number of distinct participants among the included trials.
    pub participants: usize,
    /// Number of included trials.
    pub trials: usize,
    /// Number of trials marked excluded (left out of every statistic).
    pub excluded_trials: usize,
    /// The response options (all presented materials) with k and c in cgs, by conductivity, highest first. Every
    /// matrix below uses this order.
    pub materials: Vec<MaterialInfo>,
    /// Chance level of a correct identification: 1 / number of options.
    pub chance: f64,
    /// Identification rates per condition, overall and per presented material.
    pub rates: ConditionPair<ConditionRates>,
    /// Confusion matrices per condition, rows presented, columns identified.
    pub confusion: ConditionPair<Confusion>,
    /// The eq. 8 / Table 2 ratio table, rows presented, columns identified.
    pub ratio_table: RatioTable,
    /// Mean of the non-missing diagonal (correct) ratios; the paper: 0.78.
    pub mean_ratio_correct: Option<f64>,
    /// Mean of the non-missing off-diagonal (false) ratios; the paper: 1.78.
    pub mean_ratio_false: Option<f64>,
    /// The Table 3 χ² homogeneity test over the simulated trials.
    pub chi_square: ChiSquareReport,
    /// Pearson's r between the real and simulated row probabilities over the cells named by
    /// `confusion_correlation_cells`; `null` when undefined (see `confusion_correlation_note`). The paper: 0.90.
    pub confusion_correlation: Option<f64>,
    /// Which cells `confusion_correlation` uses: always `"off-diagonal"`.
    pub confusion_correlation_cells: &'static str,
    /// Number of (real, simulated) probability pairs in `confusion_correlation`.
    pub confusion_correlation_pairs: usize,
    /// Why `confusion_correlation` is undefined, if it is.
    pub confusion_correlation_note: Option<String>,
    /// The same correlation over all cells (diagonal included).
    pub confusion_correlation_all_cells: Correlation,
    /// Beyond the paper: the real and simulated confusions compared over the off-diagonal cells that are not zero in
    /// both conditions (the paper's r counts those as agreement), with a permutation p-value ([`comparison`]).
    pub confusion_comparison: ConfusionComparison,
    /// Figure 4: Δc and Δk of the classifications and the share of mistakes within the paper's intervals.
    pub figure4: Figure4,
    /// Beyond the paper: the just-noticeable differences of k and c, cumulative-Gaussian fits to |Δk| and |Δc| of
    /// the mistakes of Figure 4 with bootstrap intervals ([`jnd`]).
    pub jnd: Jnd,
    /// Figure 3: the objective curve comparison, when curve files were analysed (see [`analyze_curves`]).
    pub curves: Option<CurveAnalysis>,
    /// The included trials with all their columns, written as `trials.csv`; not part of the JSON.
    #[serde(skip)]
    pub sessions: Sessions,
}

/// Reads the session CSVs at `paths` and computes every number of the paper's section 4 analysis.
///
/// Errors: unreadable files, malformed rows, missing columns, empty files, bad conditions, unknown materials,
/// identified materials that were never presented, or no included trial at all.
pub fn analyze(paths: &[PathBuf]) -> Result<Analysis, LabError> {
    let sessions = read_sessions(paths)?;
    Ok(analyze_sessions(sessions))
}

/// The analysis of sessions already read (cannot fail: undefined statistics are `None` with a reason).
pub fn analyze_sessions(sessions: Sessions) -> Analysis {
    let counts = tables::confusion_counts(&sessions);
    let confusion = counts.map(|c| Confusion::from_counts(&sessions.materials, c.clone()));
    let ratio_table = RatioTable::new(&sessions.materials, &confusion.simulated, &confusion.real);
    let means = stats::mean_ratios(&ratio_table.ratios);
    let off_diagonal = tables::confusion_correlation(&confusion, false);
    let figure4 = Figure4::new(&sessions.materials, &counts);
    let mut participants: Vec<&str> = sessions.trials.iter().map(|t| t.participant.as_str()).collect();
    participants.sort_unstable();
    participants.dedup();
    Analysis {
        input_files: sessions.files.iter().map(|p| p.display().to_string()).collect(),
        participants: participants.len(),
        trials: sessions.trials.len(),
        excluded_trials: sessions.excluded_trials,
        chance: 1.0 / sessions.materials.len() as f64,
        rates: counts.map(|c| ConditionRates::from_counts(&sessions.materials, c)),
        chi_square: ChiSquareReport::new(&sessions.materials, &counts.simulated),
        confusion_correlation: off_diagonal.r,
        confusion_correlation_cells: "off-diagonal",
        confusion_correlation_pairs: off_diagonal.pairs,
        confusion_correlation_note: off_diagonal.note,
        confusion_correlation_all_cells: tables::confusion_correlation(&confusion, true),
        confusion_comparison: ConfusionComparison::new(&confusion),
        jnd: Jnd::new(&figure4),
        figure4,
        mean_ratio_correct: means.correct,
        mean_ratio_false: means.false_,
        confusion,
        ratio_table,
        materials: sessions.materials.clone(),
        curves: None,
        sessions,
    }
}
