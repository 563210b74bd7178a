//! The tables of the paper's section 4 built from the confusion counts: identification rates, confusion matrices, the
//! eq. 8 ratio table (Table 2), the χ² homogeneity test (Table 3) and the confusion correlation.

use serde::Serialize;

use super::data::{MaterialInfo, Sessions};
use super::stats;
use crate::design::Condition;

/// One value per condition.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConditionPair<T> {
    /// Real contact.
    pub real: T,
    /// Simulated (rendered) contact.
    pub simulated: T,
}

impl<T> ConditionPair<T> {
    /// The value of `condition`.
    pub fn get(&self, condition: Condition) -> &T {
        match condition {
            Condition::Real => &self.real,
            Condition::Simulated => &self.simulated,
        }
    }

    /// Applies `f` to both values.
    pub fn map<U>(&self, mut f: impl FnMut(&T) -> U) -> ConditionPair<U> {
        ConditionPair {
            real: f(&self.real),
            simulated: f(&self.simulated),
        }
    }
}

/// Count matrices `[presented][identified]` per condition, in the order of `sessions.materials`.
pub fn confusion_counts(sessions: &Sessions) -> ConditionPair<Vec<Vec<u64>>> {
    let m = sessions.materials.len();
    let mut counts = ConditionPair {
        real: vec![vec![0u64; m]; m],
        simulated: vec![vec![0u64; m]; m],
    };
    for trial in &sessions.trials {
        // read_sessions guarantees both names are options.
        if let (Some(p), Some(i)) = (
            sessions.material_index(&trial.presented),
            sessions.material_index(&trial.identified),
        ) {
            let matrix = match trial.condition {
                Condition::Real => &mut counts.real,
                Condition::Simulated => &mut counts.simulated,
            };
            matrix[p][i] += 1;
        }
    }
    counts
}

/// Correct identifications of one presented material in one condition.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MaterialRate {
    /// The presented material.
    pub material: String,
    /// Trials in which it was presented.
    pub trials: u64,
    /// Trials in which it was identified correctly.
    pub correct: u64,
    /// correct / trials; `null` without trials.
    pub rate: Option<f64>,
}

/// Identification rates of one condition.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConditionRates {
    /// Trials of this condition.
    pub trials: u64,
    /// Correct identifications.
    pub correct: u64,
    /// correct / trials (the paper: 66 % real); `null` without trials.
    pub rate: Option<f64>,
    /// Per presented material, in the options' order.
    pub per_material: Vec<MaterialRate>,
}

impl ConditionRates {
    /// Rates from a `[presented][identified]` count matrix.
    pub fn from_counts(materials: &[MaterialInfo], counts: &[Vec<u64>]) -> ConditionRates {
        let per_material: Vec<MaterialRate> = materials
            .iter()
            .zip(counts)
            .enumerate()
            .map(|(p, (material, row))| {
                let trials: u64 = row.iter().sum();
                MaterialRate {
                    material: material.name.clone(),
                    trials,
                    correct: row[p],
                    rate: ratio(row[p], trials),
                }
            })
            .collect();
        let trials = per_material.iter().map(|r| r.trials).sum();
        let correct = per_material.iter().map(|r| r.correct).sum();
        ConditionRates {
            trials,
            correct,
            rate: ratio(correct, trials),
            per_material,
        }
    }
}

fn ratio(part: u64, total: u64) -> Option<f64> {
    (total > 0).then(|| part as f64 / total as f64)
}

/// A confusion matrix of one condition.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Confusion {
    /// What the rows are: `"presented"`.
    pub row_axis: &'static str,
    /// What the columns are: `"identified"`.
    pub column_axis: &'static str,
    /// Row and column labels.
    pub materials: Vec<String>,
    /// Trial counts `[presented][identified]`.
    pub counts: Vec<Vec<u64>>,
    /// P(identified | presented) `[presented][identified]`; a row without trials is `null`.
    pub probabilities: Vec<Vec<Option<f64>>>,
}

impl Confusion {
    /// The matrix of `counts` with its row probabilities.
    pub fn from_counts(materials: &[MaterialInfo], counts: Vec<Vec<u64>>) -> Confusion {
        Confusion {
            row_axis: "presented",
            column_axis: "identified",
            materials: materials.iter().map(|m| m.name.clone()).collect(),
            probabilities: stats::row_probabilities(&counts),
            counts,
        }
    }
}

/// The eq. 8 / Table 2 table: P_sim(identified | presented) / P_real(identified | presented) per cell.
///
/// Note the orientation: the paper prints identified as rows and presented as columns; here rows are presented and
/// columns identified, like the confusion matrices (the reports print the paper's orientation).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RatioTable {
    /// What the rows are: `"presented"`.
    pub row_axis: &'static str,
    /// What the columns are: `"identified"`.
    pub column_axis: &'static str,
    /// Row and column labels.
    pub materials: Vec<String>,
    /// Ratios `[presented][identified]`; `null` (missing) where the real probability is zero or a condition has no
    /// trial of the presented material.
    pub ratios: Vec<Vec<Option<f64>>>,
    /// Non-missing diagonal (correct) cells.
    pub correct_cells: usize,
    /// Non-missing off-diagonal (false) cells.
    pub false_cells: usize,
}

impl RatioTable {
    /// The table of two confusion matrices in the same material order.
    pub fn new(materials: &[MaterialInfo], simulated: &Confusion, real: &Confusion) -> RatioTable {
        let ratios = stats::ratio_matrix(&simulated.probabilities, &real.probabilities);
        let means = stats::mean_ratios(&ratios);
        RatioTable {
            row_axis: "presented",
            column_axis: "identified",
            materials: materials.iter().map(|m| m.name.clone()).collect(),
            ratios,
            correct_cells: means.correct_cells,
            false_cells: means.false_cells,
        }
    }
}

/// One row of Table 3: true and false classifications of one simulated material.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrueFalseRow {
    /// The presented material.
    pub material: String,
    /// Correct identifications.
    pub true_count: u64,
    /// Wrong identifications.
    pub false_count: u64,
    /// true / (true + false).
    pub true_share: f64,
    /// false / (true + false).
    pub false_share: f64,
}

/// The Table 3 χ² homogeneity test: H0 = the probability of a correct identification of a simulated material does
/// not depend on the material. A 2 × m table (true, false) × (materials with simulated trials), df = m − 1.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChiSquareReport {
    /// The condition tested: `"simulated"`.
    pub condition: &'static str,
    /// The observed counts (materials without simulated trials are left out).
    pub table: Vec<TrueFalseRow>,
    /// Pearson's χ² statistic (no continuity correction); `null` if undefined.
    pub statistic: Option<f64>,
    /// Degrees of freedom m − 1.
    pub df: Option<u64>,
    /// χ²(0.95; df), the 5 % critical value.
    pub critical_95: Option<f64>,
    /// 1 − cdf(statistic).
    pub p_value: Option<f64>,
    /// The smallest expected count.
    pub min_expected: Option<f64>,
    /// `"H0 maintained: …"`, `"H0 rejected: …"` or `"not computable: …"`.
    pub decision: String,
    /// Remarks: why the test is undefined, materials left out, expected counts below 5.
    pub notes: Vec<String>,
}

/// Decision text when the statistic does not exceed the critical value.
pub const H0_MAINTAINED: &str =
    "H0 maintained: no evidence that identification depends on material (χ² ≤ critical value, p ≥ 0.05)";
/// Decision text when the statistic exceeds the critical value.
pub const H0_REJECTED: &str = "H0 rejected: identification depends on material (χ² > critical value, p < 0.05)";

impl ChiSquareReport {
    /// The test over the simulated count matrix `[presented][identified]`.
    pub fn new(materials: &[MaterialInfo], simulated: &[Vec<u64>]) -> ChiSquareReport {
        let mut notes = Vec::new();
        let mut table = Vec::new();
        for (p, (material, row)) in materials.iter().zip(simulated).enumerate() {
            let trials: u64 = row.iter().sum();
            if trials == 0 {
                notes.push(format!("{} left out: no simulated trials", material.name));
                continue;
            }
            table.push(TrueFalseRow {
                material: material.name.clone(),
                true_count: row[p],
                false_count: trials - row[p],
                true_share: row[p] as f64 / trials as f64,
                false_share: (trials - row[p]) as f64 / trials as f64,
            });
        }
        let observed = vec![
            table.iter().map(|r| r.true_count).collect(),
            table.iter().map(|r| r.false_count).collect(),
        ];
        let mut report = ChiSquareReport {
            condition: "simulated",
            table,
            statistic: None,
            df: None,
            critical_95: None,
            p_value: None,
            min_expected: None,
            decision: String::new(),
            notes,
        };
        match stats::chi_square_independence(&observed) {
            Ok(test) => report.set_test(&test),
            Err(why) => {
                report.decision = format!("not computable: {why}");
                report.notes.push(why.0);
            }
        }
        report
    }

    fn set_test(&mut self, test: &stats::ChiSquare) {
        self.statistic = Some(test.statistic);
        self.df = Some(test.df);
        self.critical_95 = Some(test.critical_95);
        self.p_value = Some(test.p_value);
        self.min_expected = Some(test.min_expected);
        self.decision = if test.rejects_at_5_percent() {
            H0_REJECTED
        } else {
            H0_MAINTAINED
        }
        .to_string();
        if test.min_expected < 5.0 {
            self.notes.push(format!(
                "the smallest expected count is {:.2} (< 5): the χ² approximation is rough",
                test.min_expected
            ));
        }
    }
}

/// A Pearson correlation with its number of pairs, or the reason it is undefined.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Correlation {
    /// Which cells: `"off-diagonal"` or `"all"`.
    pub cells: &'static str,
    /// Pearson's r; `null` if undefined.
    pub r: Option<f64>,
    /// Number of (real, simulated) pairs used.
    pub pairs: usize,
    /// Why `r` is undefined, if it is.
    pub note: Option<String>,
}

/// Pearson's r between the real and simulated row probabilities, over the off-diagonal cells or over all cells.
/// Cells of a presented material without trials in either condition are skipped.
pub fn confusion_correlation(confusion: &ConditionPair<Confusion>, include_diagonal: bool) -> Correlation {
    let (mut real, mut simulated) = (Vec::new(), Vec::new());
    for cell in probability_cells(confusion).filter(|c| include_diagonal || !c.is_diagonal()) {
        real.push(cell.real);
        simulated.push(cell.simulated);
    }
    let (r, note) = match stats::pearson(&real, &simulated) {
        Ok(r) => (Some(r), None),
        Err(why) => (
            None,
            Some(format!("undefined: {why} (first = real, second = simulated)")),
        ),
    };
    Correlation {
        cells: if include_diagonal { "all" } else { "off-diagonal" },
        r,
        pairs: real.len(),
        note,
    }
}

/// One cell of the confusion matrices with a probability in both conditions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbabilityCell {
    /// Index of the presented material.
    pub presented: usize,
    /// Index of the identified material.
    pub identified: usize,
    /// P_real(identified | presented).
    pub real: f64,
    /// P_sim(identified | presented).
    pub simulated: f64,
}

impl ProbabilityCell {
    /// Whether the cell is a correct identification.
    pub fn is_diagonal(&self) -> bool {
        self.presented == self.identified
    }
}

/// The cells whose presented material has trials in both conditions, row by row.
pub fn probability_cells(confusion: &ConditionPair<Confusion>) -> impl Iterator<Item = ProbabilityCell> + '_ {
    let rows = confusion
        .real
        .probabilities
        .iter()
        .zip(&confusion.simulated.probabilities);
    rows.enumerate().flat_map(|(presented, (real_row, sim_row))| {
        real_row
            .iter()
            .zip(sim_row)
            .enumerate()
            .filter_map(move |(identified, pair)| match pair {
                (Some(real), Some(simulated)) => Some(ProbabilityCell {
                    presented,
                    identified,
                    real: *real,
                    simulated: *simulated,
                }),
                _ => None,
            })
    })
}
