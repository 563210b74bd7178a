//! `lab analyze` of procedure sessions: per-test thresholds of the method of limits (mean of runs, the DFNS log
//! transform, runs ended at a cut-off counted), z-scores against a reference table the lab supplies, the adaptive
//! procedures' final estimates, multi-zone ratings, and a figure of every trial's trace with its response marked.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Serialize;
use thermode_platform::fs::{read_text_at_most, MAX_DATA_BYTES, MAX_SETTINGS_BYTES};
use thermode_plot::{Figure, Marker, Panel, Series, SeriesStyle};
use thermode_procedures::analysis::{thresholds, z_scores, ReferenceRow, TestThreshold, ZScore};
use thermode_procedures::limits::{LimitsRun, LimitsTest};
use thermode_procedures::{Direction, ProcedureFile};

use super::session::{read_rows, ProcedureRow, ProcedureSidecar, PROCEDURE_SIDECAR_FORMAT};
use crate::error::LabError;

/// Whose z-scores: the reference rows of this site, sex and age band.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceChoice {
    /// The reference table.
    pub rows: Vec<ReferenceRow>,
    /// Body site (e.g. `hand`).
    pub site: String,
    /// Sex (e.g. `female`).
    pub sex: String,
    /// Age band (e.g. `20-40`).
    pub age_band: String,
}

/// One multi-zone stimulus' ratings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StimulusRatings {
    /// The stimulus.
    pub name: String,
    /// Mean rating (0–100; `null` without ratings).
    pub mean_rating: Option<f64>,
    /// Presentations rated.
    pub rated: usize,
    /// Presentations.
    pub presentations: usize,
}

/// The analysis of one procedure session.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProcedureSessionAnalysis {
    /// The session CSV.
    pub file: String,
    /// Participant.
    pub participant: String,
    /// Experiment.
    pub experiment: String,
    /// Procedure.
    pub procedure: String,
    /// Trials.
    pub trials: usize,
    /// Trials whose target the display clipped (its cut-off).
    pub display_cutoffs: usize,
    /// Method of limits: per-test thresholds.
    pub thresholds: Vec<TestThreshold>,
    /// Method of limits: z-scores against the reference (empty without one).
    pub z_scores: Vec<ZScore>,
    /// Levels, staircase, QUEST+: the final estimate \[°C, magnitude of the change from the baseline\].
    pub estimate_c: Option<f64>,
    /// Multi-zone programs: ratings per stimulus.
    pub ratings: Vec<StimulusRatings>,
    /// Trace figures written, relative to the output folder.
    pub figures: Vec<String>,
}

/// Whether a session CSV's header is a procedure session's.
pub fn is_procedure_csv(path: &Path) -> bool {
    read_text_at_most(path, MAX_DATA_BYTES).is_ok_and(|text| {
        let header = text.lines().next().unwrap_or("");
        header.split(',').any(|c| c == "intensity_c") && header.split(',').any(|c| c == "delivered_c")
    })
}

fn bad(path: &Path, message: impl Into<String>) -> LabError {
    LabError::Procedure {
        file: path.to_path_buf(),
        message: message.into(),
    }
}

/// The sidecar beside a procedure session CSV.
fn sidecar_of(csv: &Path) -> Result<ProcedureSidecar, LabError> {
    let path = csv.with_extension("json");
    let text = read_text_at_most(&path, MAX_SETTINGS_BYTES)
        .map_err(|e| bad(&path, format!("the session's sidecar cannot be read: {e}")))?;
    let sidecar: ProcedureSidecar =
        serde_json::from_str(&text).map_err(|e| bad(&path, format!("not a procedure session sidecar: {e}")))?;
    if sidecar.format != PROCEDURE_SIDECAR_FORMAT {
        return Err(bad(
            &path,
            format!("format `{}` is not a procedure session's", sidecar.format),
        ));
    }
    Ok(sidecar)
}

/// Analyses the procedure session `csv`; with `figures_dir`, writes each trial's trace figure there.
pub fn analyze_session(
    csv: &Path,
    reference: Option<&ReferenceChoice>,
    figures_dir: Option<&Path>,
) -> Result<ProcedureSessionAnalysis, LabError> {
    let sidecar = sidecar_of(csv)?;
    let rows = read_rows(csv).map_err(|e| bad(csv, e.to_string()))?;
    let file = ProcedureFile::from_toml_str(&sidecar.experiment_toml).map_err(|e| bad(csv, e.to_string()))?;
    let mut analysis = ProcedureSessionAnalysis {
        file: csv.display().to_string(),
        participant: sidecar.participant.clone(),
        experiment: sidecar.experiment.clone(),
        procedure: sidecar.procedure.clone(),
        trials: rows.len(),
        display_cutoffs: rows.iter().filter(|r| r.cutoff_c.is_finite()).count(),
        thresholds: Vec::new(),
        z_scores: Vec::new(),
        estimate_c: None,
        ratings: Vec::new(),
        figures: Vec::new(),
    };
    match &file.limits {
        Some(limits) if sidecar.procedure == "limits" => {
            let runs = limits_runs(csv, &rows, limits.baseline_c)?;
            analysis.thresholds = thresholds(&runs);
            if let Some(r) = reference {
                analysis.z_scores = z_scores(&analysis.thresholds, &r.rows, &r.site, &r.sex, &r.age_band);
            }
        }
        _ if sidecar.procedure == "program" => analysis.ratings = ratings(&rows),
        _ => analysis.estimate_c = rows.last().map(|r| r.estimate_c).filter(|v| v.is_finite()),
    }
    if let Some(dir) = figures_dir {
        for row in &rows {
            analysis.figures.push(trace_figure(csv, &sidecar, row, dir)?);
        }
    }
    Ok(analysis)
}

/// The method of limits' runs of a session's rows.
fn limits_runs(csv: &Path, rows: &[ProcedureRow], baseline_c: f64) -> Result<Vec<LimitsRun>, LabError> {
    rows.iter()
        .map(|row| {
            let test = LimitsTest::from_name(&row.label)
                .ok_or_else(|| bad(csv, format!("trial {}: `{}` is not a DFNS test", row.trial, row.label)))?;
            Ok(LimitsRun {
                test,
                run: row.run,
                direction: if row.intensity_c < 0.0 {
                    Direction::Cold
                } else {
                    Direction::Warm
                },
                start_c: row.baseline_c,
                baseline_c,
                delivered_c: row.delivered_c,
                cutoff_reached: row.response == "none",
                paradoxical_heat: row.paradoxical_heat,
            })
        })
        .collect()
}

fn ratings(rows: &[ProcedureRow]) -> Vec<StimulusRatings> {
    let mut by_name: BTreeMap<&str, (f64, usize, usize, usize)> = BTreeMap::new();
    for (order, row) in rows.iter().enumerate() {
        let entry = by_name.entry(&row.label).or_insert((0.0, 0, 0, order));
        entry.2 += 1;
        if row.rating.is_finite() {
            entry.0 += row.rating;
            entry.1 += 1;
        }
    }
    let mut list: Vec<_> = by_name.into_iter().collect();
    list.sort_by_key(|(_, (.., order))| *order);
    list.into_iter()
        .map(|(name, (sum, rated, presentations, _))| StimulusRatings {
            name: name.to_string(),
            mean_rating: (rated > 0).then(|| sum / rated as f64),
            rated,
            presentations,
        })
        .collect()
}

/// Writes the trace figure of `row` into `dir`; returns its file name.
fn trace_figure(csv: &Path, sidecar: &ProcedureSidecar, row: &ProcedureRow, dir: &Path) -> Result<String, LabError> {
    let trace_path = csv.parent().unwrap_or(Path::new(".")).join(&row.curve_file);
    let text = read_text_at_most(&trace_path, MAX_DATA_BYTES)
        .map_err(|e| bad(&trace_path, format!("the trial's trace cannot be read: {e}")))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let columns: Vec<Vec<f64>> = {
        let mut columns = vec![Vec::new(); header.len()];
        for line in lines {
            for (i, field) in line.split(',').enumerate().take(header.len()) {
                columns[i].push(field.parse::<f64>().unwrap_or(f64::NAN));
            }
        }
        columns
    };
    let time = columns.first().ok_or_else(|| bad(&trace_path, "an empty trace"))?;
    let t0 = row.start_time_s;
    let mut series = Vec::new();
    for (index, name) in header.iter().enumerate().skip(1) {
        let (style, shown) = match name.rsplit('_').nth(1) {
            Some("setpoint") => (SeriesStyle::Dashed, "set-point"),
            Some("plate") => (SeriesStyle::Line, "plate"),
            _ => continue,
        };
        let channel = name.strip_prefix("ch").and_then(|n| n.split('_').next());
        let label = channel.map_or(shown.to_string(), |c| format!("channel {c} {shown}"));
        let points = time.iter().zip(&columns[index]).map(|(&t, &v)| (t - t0, v)).collect();
        let color = channel.and_then(|c| c.parse::<usize>().ok()).unwrap_or(0);
        series.push(Series::new(label, points, style, color));
    }
    if let Some(tick_time_s) = row.response_time_s.is_finite().then_some(row.response_time_s) {
        let value = if row.delivered_c.is_finite() {
            row.delivered_c
        } else {
            row.baseline_c
        };
        series.push(
            Series::new("response", vec![(tick_time_s - t0, value)], SeriesStyle::Points, 3)
                .with_marker(Marker::nth(3)),
        );
    }
    let figure = Figure::single(Panel {
        title: format!("{} run {}: {}", row.label, row.run, row.response),
        x_label: "time since the trial's start [s]".into(),
        y_label: "temperature [°C]".into(),
        series,
        x_range: None,
        y_range: None,
    })
    .with_title(format!(
        "{} {} trial {}",
        sidecar.participant, sidecar.experiment, row.trial
    ));
    // Named by the session's file (participant, experiment, day), so several sessions of one participant analysed
    // together keep every figure.
    let stem = csv
        .file_stem()
        .map_or_else(|| sidecar.participant.clone(), |s| s.to_string_lossy().into_owned());
    let name = format!("{stem}_trial-{:03}.svg", row.trial);
    std::fs::create_dir_all(dir).map_err(|e| bad(dir, e.to_string()))?;
    thermode_plot::write_figure(&figure, &dir.join(&name)).map_err(|e| bad(dir, e.to_string()))?;
    Ok(name)
}

/// Analyses several procedure sessions, the trace figures into `out/figures`.
pub fn analyze_sessions(
    files: &[PathBuf],
    reference: Option<&ReferenceChoice>,
    out: Option<&Path>,
) -> Result<Vec<ProcedureSessionAnalysis>, LabError> {
    let figures = out.map(|o| o.join("figures"));
    files
        .iter()
        .map(|f| analyze_session(f, reference, figures.as_deref()))
        .collect()
}

/// A Markdown report of the sessions.
pub fn markdown(sessions: &[ProcedureSessionAnalysis]) -> String {
    let mut text = String::from("# Procedure sessions\n");
    for s in sessions {
        text.push_str(&format!(
            "\n## {} — {} ({})\n\n{} trial(s); {} with the display's cut-off.\n",
            s.participant, s.experiment, s.procedure, s.trials, s.display_cutoffs
        ));
        if !s.thresholds.is_empty() {
            text.push_str(
                "\n| test | threshold | compared | runs | at cut-off | PHS | z |\n|---|---|---|---|---|---|---|\n",
            );
            for t in &s.thresholds {
                let z = s
                    .z_scores
                    .iter()
                    .find(|z| z.test == t.test)
                    .map_or("".into(), |z| format!("{:.2}", z.z));
                let unit = if matches!(t.test, LimitsTest::Cpt | LimitsTest::Hpt) {
                    "°C"
                } else {
                    "°C change"
                };
                text.push_str(&format!(
                    "| {} | {:.2} {unit} | {:.3}{} | {} | {} | {} | {z} |\n",
                    t.test.name(),
                    t.value_c,
                    t.compared,
                    if t.log_transformed { " (log10)" } else { "" },
                    t.runs,
                    t.cutoffs,
                    t.phs.map_or(String::new(), |p| p.to_string()),
                ));
            }
        }
        if let Some(estimate) = s.estimate_c {
            text.push_str(&format!(
                "\nFinal threshold estimate: {estimate:.3} °C of change from the baseline.\n"
            ));
        }
        for r in &s.ratings {
            let mean = r
                .mean_rating
                .map_or("not rated".into(), |m| format!("mean rating {m:.1}"));
            text.push_str(&format!(
                "\n- {}: {mean} ({} of {} rated)",
                r.name, r.rated, r.presentations
            ));
        }
        if !s.figures.is_empty() {
            text.push_str(&format!("\n\nTrace figures: {} in `figures/`.\n", s.figures.len()));
        }
    }
    text
}
