//! The objective assessment (the paper's Figure 3): finger temperature curves for real and simulated contact, per
//! material, averaged over repetitions and compared.
//!
//! Curve CSV columns (header names trimmed, case-insensitive):
//! - `time_s` — time since contact \[s\], strictly increasing within a curve;
//! - a temperature \[°C\], the first present of [`TEMPERATURE_COLUMNS`]: `finger_c` (a `lab run` trial curve on a
//!   display: the finger measured on the plate), `skin_c`, `skin_surface_c`, `truth_skin_c`, `target_skin_c`;
//! - `material` — a library material name, or any name where the file also has `conductivity_w_mk` and
//!   `specific_heat_j_kgk` (SI) filled on the row (a custom material named by its properties); `condition` — `real`
//!   or `simulated`;
//! - optional `repetition` — rows with the same (file, condition, material, repetition) form one curve; without the
//!   column, one file holds one curve per (condition, material).
//!
//! An empty temperature cell is a sample that was not measured and is skipped (a `lab run` trial curve of a real
//! trial has no `finger_c`: the finger touched the sample, not the plate).
//!
//! The CSVs thermode writes are read as they are, without a `condition` column:
//! - a `render` CSV (`truth_skin_c` and `skin_c`, no `channel`): per (material, controller, renderer), the real
//!   curve is `truth_skin_c` (the simulated finger touching the real material) and the simulated curve `skin_c`
//!   (the same finger on the display), over the rows in contact (`contact` 1; time since the first of them); the
//!   controller and renderer name the repetition, so a `--controller both` file averages both controllers;
//! - a `serve --record` file (`channel`, `contact`, `target_skin_c` and `skin_c`): every touch of every channel
//!   (consecutive rows in contact with one material) is one repetition, its time counted from the touch; the real
//!   curve is `target_skin_c` (the renderer's finger on the real material), the simulated one `skin_c` (the finger
//!   model on the display); its property columns name each touched material, so a custom material reads back.
//!
//! Per material, all curves of both conditions are resampled by linear interpolation onto one uniform grid over the
//! time span they share (from the latest start to the earliest end), with a step no finer than the coarsest curve's
//! mean sampling interval; the mean curve of a condition is the mean of its repetitions on that grid. Reported: the
//! RMS difference of the mean curves (simulated − real) over the grid, the endpoint difference at the grid's end,
//! and per condition the initial slope [°C/s]: the least-squares line through the raw samples of all repetitions in
//! the first [`INITIAL_SLOPE_WINDOW_S`] seconds of the shared span.

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::Serialize;

use super::data::{CsvTable, MaterialInfo, MaterialResolver, PropertyColumns};
use super::stats;
use crate::design::Condition;
use crate::error::LabError;

/// Accepted temperature column names \[°C\], in order of preference.
pub const TEMPERATURE_COLUMNS: [&str; 5] = ["finger_c", "skin_c", "skin_surface_c", "truth_skin_c", "target_skin_c"];
/// Length of the window for the initial slope \[s\]: 2.
pub const INITIAL_SLOPE_WINDOW_S: f64 = 2.0;

/// The Figure 3 comparison of all curve files.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CurveAnalysis {
    /// The curve files, as given.
    pub files: Vec<String>,
    /// The temperature column used in each file (same order as `files`).
    pub temperature_columns: Vec<String>,
    /// Window of the initial slope \[s\].
    pub initial_slope_window_s: f64,
    /// Per material, by conductivity, highest first.
    pub materials: Vec<MaterialCurves>,
}

/// Real versus simulated curves of one material.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MaterialCurves {
    /// Library material name.
    pub material: String,
    /// Start of the shared time span \[s\].
    pub start_s: f64,
    /// End of the shared time span \[s\].
    pub end_s: f64,
    /// Step of the common grid \[s\].
    pub grid_step_s: f64,
    /// The real curves, if any.
    pub real: Option<ConditionCurve>,
    /// The simulated curves, if any.
    pub simulated: Option<ConditionCurve>,
    /// √(mean over the grid of (simulated − real)²) of the mean curves \[°C\]; `null` unless both conditions exist.
    pub rms_difference_c: Option<f64>,
    /// Simulated − real mean temperature at `end_s` \[°C\]; `null` unless both conditions exist.
    pub endpoint_difference_c: Option<f64>,
}

/// The curves of one (material, condition).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConditionCurve {
    /// Number of curves (repetitions) averaged.
    pub repetitions: usize,
    /// Mean temperature at `start_s` \[°C\].
    pub start_c: f64,
    /// Mean temperature at `end_s` \[°C\].
    pub endpoint_c: f64,
    /// Least-squares slope over the first [`INITIAL_SLOPE_WINDOW_S`] seconds [°C/s]; `null` with fewer than two
    /// sample times in the window.
    pub initial_slope_c_per_s: Option<f64>,
    /// Why the slope is undefined, if it is.
    pub initial_slope_note: Option<String>,
    /// The mean curve on the common grid: `[time_s, temperature_c]` pairs.
    pub mean_curve: Vec<[f64; 2]>,
}

/// One recorded curve.
#[derive(Debug, Clone)]
struct Curve {
    condition: Condition,
    samples: Vec<(f64, f64)>,
}

/// A curve within one file: (condition, material name, repetition).
type CurveKey = (Condition, String, String);

/// Curves grouped by material name.
type ByMaterial = BTreeMap<String, (MaterialInfo, Vec<Curve>)>;

/// Reads curve CSVs and compares real and simulated curves per material (see the module documentation).
pub fn analyze_curves(paths: &[PathBuf]) -> Result<CurveAnalysis, LabError> {
    if paths.is_empty() {
        return Err(LabError::NoData("no curve file given".to_string()));
    }
    let mut resolver = MaterialResolver::default();
    let mut by_material = ByMaterial::new();
    let mut temperature_columns = Vec::new();
    for path in paths {
        let table = CsvTable::read(path)?;
        temperature_columns.push(read_curve_file(&table, &mut resolver, &mut by_material)?);
    }
    let mut groups: Vec<(MaterialInfo, Vec<Curve>)> = by_material.into_values().collect();
    groups.sort_by(|a, b| b.0.conductivity_cal_cm_s_c.total_cmp(&a.0.conductivity_cal_cm_s_c));
    let materials = groups
        .iter()
        .map(|(m, curves)| compare(m, curves))
        .collect::<Result<_, _>>()?;
    Ok(CurveAnalysis {
        files: paths.iter().map(|p| p.display().to_string()).collect(),
        temperature_columns,
        initial_slope_window_s: INITIAL_SLOPE_WINDOW_S,
        materials,
    })
}

/// Column indexes of a curve file.
struct CurveColumns {
    time: usize,
    temperature: usize,
    material: usize,
    condition: usize,
    repetition: Option<usize>,
}

impl CurveColumns {
    fn of(table: &CsvTable) -> Result<CurveColumns, LabError> {
        let mut temperature = None;
        for name in TEMPERATURE_COLUMNS {
            if let Some(i) = table.optional_column(name)? {
                temperature = Some(i);
                break;
            }
        }
        let temperature = temperature.ok_or_else(|| LabError::MissingColumn {
            file: table.file.clone(),
            column: format!("a temperature column ({})", TEMPERATURE_COLUMNS.join(", ")),
        })?;
        Ok(CurveColumns {
            time: table.column("time_s")?,
            temperature,
            material: table.column("material")?,
            condition: table.column("condition")?,
            repetition: table.optional_column("repetition")?,
        })
    }
}

/// Adds the curves of one file to `by_material`; returns the temperature column used.
fn read_curve_file(
    table: &CsvTable,
    resolver: &mut MaterialResolver,
    by_material: &mut ByMaterial,
) -> Result<String, LabError> {
    if table.optional_column("condition")?.is_none() {
        if let Some(paired) = PairedColumns::of(table)? {
            return read_paired_file(table, &paired, resolver, by_material);
        }
    }
    let cols = CurveColumns::of(table)?;
    let properties = PropertyColumns::of(table)?;
    let temperature_name = table.header[cols.temperature].clone();
    let mut curves: BTreeMap<CurveKey, (MaterialInfo, Vec<(f64, f64)>)> = BTreeMap::new();
    for (line, fields) in &table.rows {
        let line = *line;
        let time_s = finite(table, line, "time_s", &fields[cols.time])?;
        if fields[cols.temperature].trim().is_empty() {
            // Not measured (a `lab run` real trial: the finger is on the sample, not on the plate).
            continue;
        }
        let temperature_c = finite(table, line, &temperature_name, &fields[cols.temperature])?;
        let condition = Condition::parse(&fields[cols.condition]).ok_or_else(|| LabError::BadCondition {
            file: table.file.clone(),
            line,
            value: fields[cols.condition].clone(),
        })?;
        let material = resolver.resolve_row(table, line, ("material", cols.material), fields, properties)?;
        let repetition = cols
            .repetition
            .map(|i| fields[i].trim().to_string())
            .unwrap_or_default();
        let key = (condition, material.name.clone(), repetition);
        let (_, samples) = curves.entry(key).or_insert_with(|| (material, Vec::new()));
        if samples.last().is_some_and(|&(t, _)| time_s <= t) {
            return Err(table.bad_value(line, "time_s", &fields[cols.time], "time must increase within a curve"));
        }
        samples.push((time_s, temperature_c));
    }
    for ((condition, name, repetition), (material, samples)) in curves {
        if samples.len() < 2 {
            return Err(LabError::NoData(format!(
                "{}: the {} curve of {name} (repetition `{repetition}`) has fewer than 2 samples",
                table.file.display(),
                condition.name()
            )));
        }
        let entry = by_material.entry(name).or_insert_with(|| (material, Vec::new()));
        entry.1.push(Curve { condition, samples });
    }
    Ok(temperature_name)
}

/// Columns of a thermode CSV that holds both conditions side by side (a `render` CSV or a `serve --record` file).
struct PairedColumns {
    time: usize,
    real: usize,
    simulated: usize,
    material: usize,
    contact: Option<usize>,
    /// `serve --record`: the channel column (curves are touches per channel).
    channel: Option<usize>,
    /// `render`: the columns naming a repetition (controller, renderer).
    repetition: Vec<usize>,
    /// `serve --record`: the touched material's properties.
    properties: Option<PropertyColumns>,
}

impl PairedColumns {
    fn of(table: &CsvTable) -> Result<Option<PairedColumns>, LabError> {
        let channel = table.optional_column("channel")?;
        let real_name = if channel.is_some() {
            "target_skin_c"
        } else {
            "truth_skin_c"
        };
        let (Some(real), Some(simulated)) = (table.optional_column(real_name)?, table.optional_column("skin_c")?)
        else {
            return Ok(None);
        };
        let mut repetition = Vec::new();
        for name in ["controller", "renderer"] {
            repetition.extend(table.optional_column(name)?);
        }
        Ok(Some(PairedColumns {
            time: table.column("time_s")?,
            real,
            simulated,
            material: table.column("material")?,
            contact: table.optional_column("contact")?,
            channel,
            repetition,
            properties: PropertyColumns::of(table)?,
        }))
    }
}

/// One curve being read from a paired file: its material and samples of both conditions.
struct PairedCurve {
    material: MaterialInfo,
    start_s: f64,
    real: Vec<(f64, f64)>,
    simulated: Vec<(f64, f64)>,
}

/// Adds the curves of a `render` CSV or a `serve --record` file (see the module documentation).
fn read_paired_file(
    table: &CsvTable,
    cols: &PairedColumns,
    resolver: &mut MaterialResolver,
    by_material: &mut ByMaterial,
) -> Result<String, LabError> {
    let mut finished: Vec<PairedCurve> = Vec::new();
    // The curve being read per key: (channel or repetition names) -> curve.
    let mut open: BTreeMap<String, PairedCurve> = BTreeMap::new();
    for (line, fields) in &table.rows {
        let line = *line;
        let key = match cols.channel {
            Some(i) => fields[i].trim().to_string(),
            None => cols
                .repetition
                .iter()
                .map(|&i| fields[i].trim())
                .collect::<Vec<_>>()
                .join("/"),
        };
        let in_contact = cols.contact.is_none_or(|i| fields[i].trim() == "1");
        let material_name = fields[cols.material].trim();
        let continues = open.get(&key).is_some_and(|c| c.material.name == material_name);
        if !in_contact || material_name.is_empty() || !continues {
            // A release, or a new material on this key, ends the curve being read.
            finished.extend(open.remove(&key));
        }
        if !in_contact || material_name.is_empty() {
            continue;
        }
        let time_s = finite(table, line, "time_s", &fields[cols.time])?;
        let real_c = finite(table, line, &table.header[cols.real], &fields[cols.real])?;
        let simulated_c = finite(table, line, &table.header[cols.simulated], &fields[cols.simulated])?;
        if !open.contains_key(&key) {
            let material = resolver.resolve_row(table, line, ("material", cols.material), fields, cols.properties)?;
            open.insert(
                key.clone(),
                PairedCurve {
                    material,
                    start_s: time_s,
                    real: Vec::new(),
                    simulated: Vec::new(),
                },
            );
        }
        if let Some(curve) = open.get_mut(&key) {
            let t = time_s - curve.start_s;
            if curve.real.last().is_some_and(|&(last, _)| t <= last) {
                return Err(table.bad_value(line, "time_s", &fields[cols.time], "time must increase within a curve"));
            }
            curve.real.push((t, real_c));
            curve.simulated.push((t, simulated_c));
        }
    }
    finished.extend(open.into_values());
    let mut added = 0;
    for curve in finished.into_iter().filter(|c| c.real.len() >= 2) {
        let entry = by_material
            .entry(curve.material.name.clone())
            .or_insert_with(|| (curve.material.clone(), Vec::new()));
        entry.1.push(Curve {
            condition: Condition::Real,
            samples: curve.real,
        });
        entry.1.push(Curve {
            condition: Condition::Simulated,
            samples: curve.simulated,
        });
        added += 1;
    }
    if added == 0 {
        return Err(LabError::NoData(format!(
            "{}: no contact of at least 2 samples to compare",
            table.file.display()
        )));
    }
    Ok(format!("{} (real) / skin_c (simulated)", table.header[cols.real]))
}

fn finite(table: &CsvTable, line: u64, column: &str, text: &str) -> Result<f64, LabError> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(table.bad_value(line, column, text, "expected a finite number")),
    }
}

/// The shared span and grid of a material's curves, then the per-condition means and their differences.
fn compare(material: &MaterialInfo, curves: &[Curve]) -> Result<MaterialCurves, LabError> {
    let start_s = curves.iter().map(|c| c.samples[0].0).fold(f64::NEG_INFINITY, f64::max);
    let end_s = curves
        .iter()
        .map(|c| c.samples[c.samples.len() - 1].0)
        .fold(f64::INFINITY, f64::min);
    if end_s <= start_s {
        return Err(LabError::NoData(format!(
            "the curves of {} do not share a time span (latest start {start_s} s, earliest end {end_s} s)",
            material.name
        )));
    }
    let coarsest_step_s = curves.iter().map(mean_step_s).fold(0.0, f64::max);
    let intervals = ((end_s - start_s) / coarsest_step_s).ceil().max(1.0) as usize;
    let grid: Vec<f64> = (0..=intervals)
        .map(|i| {
            if i == intervals {
                end_s
            } else {
                start_s + (end_s - start_s) * i as f64 / intervals as f64
            }
        })
        .collect();
    let of = |condition| condition_curve(curves, condition, &grid, start_s);
    let (real, simulated) = (of(Condition::Real), of(Condition::Simulated));
    let (rms_difference_c, endpoint_difference_c) = match (&real, &simulated) {
        (Some(r), Some(s)) => (
            Some(rms_difference(&r.mean_curve, &s.mean_curve)),
            Some(s.endpoint_c - r.endpoint_c),
        ),
        _ => (None, None),
    };
    Ok(MaterialCurves {
        material: material.name.clone(),
        start_s,
        end_s,
        grid_step_s: (end_s - start_s) / intervals as f64,
        real,
        simulated,
        rms_difference_c,
        endpoint_difference_c,
    })
}

fn mean_step_s(curve: &Curve) -> f64 {
    let n = curve.samples.len();
    (curve.samples[n - 1].0 - curve.samples[0].0) / (n - 1) as f64
}

/// The mean curve of one condition on `grid`, and its initial slope; `None` without curves of that condition.
fn condition_curve(curves: &[Curve], condition: Condition, grid: &[f64], start_s: f64) -> Option<ConditionCurve> {
    let chosen: Vec<&Curve> = curves.iter().filter(|c| c.condition == condition).collect();
    if chosen.is_empty() {
        return None;
    }
    let mean_curve: Vec<[f64; 2]> = grid
        .iter()
        .map(|&t| {
            [
                t,
                chosen.iter().map(|c| interpolate(&c.samples, t)).sum::<f64>() / chosen.len() as f64,
            ]
        })
        .collect();
    let window_end_s = start_s + INITIAL_SLOPE_WINDOW_S * (1.0 + 1e-12);
    let early: Vec<(f64, f64)> = chosen
        .iter()
        .flat_map(|c| {
            c.samples
                .iter()
                .copied()
                .filter(|&(t, _)| t >= start_s && t <= window_end_s)
        })
        .collect();
    let (slope, note) = match stats::least_squares_slope(&early) {
        Ok(s) => (Some(s), None),
        Err(why) => (None, Some(format!("undefined: {why}"))),
    };
    Some(ConditionCurve {
        repetitions: chosen.len(),
        start_c: mean_curve[0][1],
        endpoint_c: mean_curve[mean_curve.len() - 1][1],
        initial_slope_c_per_s: slope,
        initial_slope_note: note,
        mean_curve,
    })
}

/// Linear interpolation of increasing `samples` at `t` (held at the ends outside their span).
fn interpolate(samples: &[(f64, f64)], t: f64) -> f64 {
    let after = samples.partition_point(|&(time, _)| time < t);
    if after == 0 {
        return samples[0].1;
    }
    if after == samples.len() {
        return samples[samples.len() - 1].1;
    }
    let ((t0, y0), (t1, y1)) = (samples[after - 1], samples[after]);
    y0 + (y1 - y0) * (t - t0) / (t1 - t0)
}

fn rms_difference(real: &[[f64; 2]], simulated: &[[f64; 2]]) -> f64 {
    let sum: f64 = real.iter().zip(simulated).map(|(r, s)| (s[1] - r[1]).powi(2)).sum();
    (sum / real.len() as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_is_exact_on_a_line() {
        let samples = [(0.0, 30.0), (1.0, 28.0), (3.0, 24.0)];
        assert_eq!(interpolate(&samples, 2.0), 26.0);
        assert_eq!(interpolate(&samples, 0.5), 29.0);
        assert_eq!(interpolate(&samples, 3.0), 24.0);
        assert_eq!(interpolate(&samples, 0.0), 30.0);
    }
}
