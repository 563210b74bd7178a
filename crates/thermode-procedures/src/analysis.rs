//! The analysis maths of the DFNS thermal tests: per-test thresholds from the method of limits' runs, the DFNS log
//! transform, and z-scores against a reference table the lab supplies.
//!
//! Following Rolke et al. (Eur J Pain 10 (2006) 77–88; the DFNS protocol):
//!
//! - A threshold is the arithmetic mean of its runs (a ramp that reached its cut-off counts at the cut-off, and the
//!   number of such runs is reported).
//! - CDT and WDT are differences from the baseline (CDT negative), TSL the mean difference between each run's warm
//!   and cold ramp (positive); these are log-normally distributed and are compared as `log10` of their magnitude.
//!   CPT and HPT are temperatures \[°C\], normally distributed, compared untransformed. PHS is a count (0–3).
//!   (Rolke et al. 2006, abstract: most QST parameters are normally distributed only after a logarithmic
//!   transformation, except the frequency of paradoxical heat sensations, the cold and heat pain thresholds and the
//!   vibration detection threshold.)
//! - `z = (x − mean) / sd` with x, mean and sd in the compared space; DFNS then signs z so that a positive z is a gain
//!   of function (more sensitive than the reference): CPT keeps its sign (a warmer cold-pain threshold is more
//!   sensitive), CDT, WDT, TSL and HPT are inverted (a larger threshold is less sensitive).

use serde::Serialize;

use crate::limits::{LimitsRun, LimitsTest};
use crate::plan::Direction;
use crate::ProcedureError;

/// One test's threshold.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TestThreshold {
    /// The test.
    pub test: LimitsTest,
    /// CDT, WDT: mean change from the baseline \[°C\] (signed); TSL: mean warm − cold limen \[°C\]; CPT, HPT: mean
    /// temperature \[°C\].
    pub value_c: f64,
    /// The value compared with the reference: `log10(|value_c|)` for CDT, WDT, TSL, `value_c` for CPT, HPT.
    pub compared: f64,
    /// Whether `compared` is log10-transformed.
    pub log_transformed: bool,
    /// Runs averaged.
    pub runs: usize,
    /// Runs that reached the cut-off without a response.
    pub cutoffs: usize,
    /// TSL only: the paradoxical heat sensations counted.
    pub phs: Option<usize>,
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// Per-test thresholds from the recorded runs of the method of limits, in the order the tests first appear.
pub fn thresholds(runs: &[LimitsRun]) -> Vec<TestThreshold> {
    let mut tests: Vec<LimitsTest> = Vec::new();
    for run in runs {
        if !tests.contains(&run.test) {
            tests.push(run.test);
        }
    }
    tests
        .into_iter()
        .filter_map(|test| {
            let of_test: Vec<&LimitsRun> = runs.iter().filter(|r| r.test == test).collect();
            threshold_of(test, &of_test)
        })
        .collect()
}

fn threshold_of(test: LimitsTest, runs: &[&LimitsRun]) -> Option<TestThreshold> {
    let cutoffs = runs.iter().filter(|r| r.cutoff_reached).count();
    let (values, phs): (Vec<f64>, Option<usize>) = match test {
        LimitsTest::Cdt | LimitsTest::Wdt => (runs.iter().map(|r| r.delivered_c - r.baseline_c).collect(), None),
        LimitsTest::Cpt | LimitsTest::Hpt => (runs.iter().map(|r| r.delivered_c).collect(), None),
        LimitsTest::Tsl => {
            let limens = runs
                .iter()
                .filter(|r| r.direction == Direction::Warm)
                .filter_map(|warm| {
                    let cold = runs
                        .iter()
                        .find(|r| r.run == warm.run && r.direction == Direction::Cold)?;
                    Some(warm.delivered_c - cold.delivered_c)
                })
                .collect();
            let phs = runs.iter().filter(|r| r.paradoxical_heat).count();
            (limens, Some(phs))
        }
    };
    if values.is_empty() {
        return None;
    }
    let value_c = mean(&values);
    let log_transformed = !test.is_pain();
    Some(TestThreshold {
        test,
        value_c,
        compared: if log_transformed {
            value_c.abs().log10()
        } else {
            value_c
        },
        log_transformed,
        runs: values.len(),
        cutoffs,
        phs,
    })
}

/// One row of the reference table: `test, site, sex, age_band, mean, sd` (mean and sd in the compared space:
/// log10 for CDT, WDT, TSL).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReferenceRow {
    /// The test (`CDT`, `WDT`, `TSL`, `CPT`, `HPT`).
    pub test: LimitsTest,
    /// The body site, e.g. `hand`, `foot`, `face`.
    pub site: String,
    /// The sex, e.g. `female`, `male`.
    pub sex: String,
    /// The age band, e.g. `20-40`.
    pub age_band: String,
    /// The reference mean.
    pub mean: f64,
    /// The reference standard deviation, positive.
    pub sd: f64,
}

/// Parses a reference table: a CSV with the header `test,site,sex,age_band,mean,sd` (any column order; further
/// columns are ignored).
pub fn parse_reference(text: &str) -> Result<Vec<ReferenceRow>, ProcedureError> {
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let header = reader
        .headers()
        .map_err(|e| ProcedureError::Reference {
            line: 1,
            message: e.to_string(),
        })?
        .clone();
    let column = |name: &str| {
        header
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| ProcedureError::Reference {
                line: 1,
                message: format!("missing column `{name}` (needs test, site, sex, age_band, mean, sd)"),
            })
    };
    let cols = [
        column("test")?,
        column("site")?,
        column("sex")?,
        column("age_band")?,
        column("mean")?,
        column("sd")?,
    ];
    let mut rows = Vec::new();
    for (i, record) in reader.records().enumerate() {
        let line = i as u64 + 2;
        let record = record.map_err(|e| ProcedureError::Reference {
            line,
            message: e.to_string(),
        })?;
        let field = |k: usize| record.get(cols[k]).unwrap_or("");
        let bad = |message: String| ProcedureError::Reference { line, message };
        let test = LimitsTest::from_name(field(0))
            .ok_or_else(|| bad(format!("unknown test `{}` (CDT, WDT, TSL, CPT, HPT)", field(0))))?;
        let number = |k: usize, name: &str| {
            field(k)
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| bad(format!("{name} `{}` is not a number", field(k))))
        };
        let (mean, sd) = (number(4, "mean")?, number(5, "sd")?);
        if sd <= 0.0 {
            return Err(bad(format!("sd {sd} is not positive")));
        }
        rows.push(ReferenceRow {
            test,
            site: field(1).to_string(),
            sex: field(2).to_string(),
            age_band: field(3).to_string(),
            mean,
            sd,
        });
    }
    Ok(rows)
}

/// A threshold's z-score against its reference row.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ZScore {
    /// The test.
    pub test: LimitsTest,
    /// `(compared − mean) / sd`, signed so that positive is a gain of function (DFNS).
    pub z: f64,
    /// The reference row used.
    pub reference: ReferenceRow,
}

/// The z-scores of `thresholds` against the rows of `reference` for `site`, `sex` and `age_band` (compared
/// case-insensitively); a test without a matching row is left out.
pub fn z_scores(
    thresholds: &[TestThreshold],
    reference: &[ReferenceRow],
    site: &str,
    sex: &str,
    age_band: &str,
) -> Vec<ZScore> {
    thresholds
        .iter()
        .filter_map(|t| {
            let row = reference.iter().find(|r| {
                r.test == t.test
                    && r.site.eq_ignore_ascii_case(site)
                    && r.sex.eq_ignore_ascii_case(sex)
                    && r.age_band.eq_ignore_ascii_case(age_band)
            })?;
            let raw = (t.compared - row.mean) / row.sd;
            let z = if t.test == LimitsTest::Cpt { raw } else { -raw };
            Some(ZScore {
                test: t.test,
                z,
                reference: row.clone(),
            })
        })
        .collect()
}
