//! The numbers behind the paper's Figure 4: for every classification the differences Δc = c_identified − c_presented
//! [cal/(g·°C)] and Δk = k_identified − k_presented [cal/(cm·s·°C)] (library values in the paper's cgs units), the
//! probability of a classification at each Δ (correct answers at Δ = 0), and the share of mistakes within
//! ±0.05 cal/(g·°C) and ±0.005 cal/(cm·s·°C) (the paper: 27 % and 44 %).

use serde::Serialize;

use super::data::MaterialInfo;
use super::stats::is_within;
use super::tables::ConditionPair;

/// Half width of the paper's Δc interval [cal/(g·°C)].
pub const C_HALF_WIDTH_CAL_G_C: f64 = 0.05;
/// Half width of the paper's Δk interval [cal/(cm·s·°C)].
pub const K_HALF_WIDTH_CAL_CM_S_C: f64 = 0.005;

/// Figure 4's numbers per condition and for both conditions pooled.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Figure4 {
    /// Unit of Δc: `"cal/(g·°C)"`.
    pub c_unit: &'static str,
    /// Unit of Δk: `"cal/(cm·s·°C)"`.
    pub k_unit: &'static str,
    /// Half width of the Δc interval [cal/(g·°C)]: 0.05.
    pub c_half_width: f64,
    /// Half width of the Δk interval [cal/(cm·s·°C)]: 0.005.
    pub k_half_width: f64,
    /// Real trials.
    pub real: Discrimination,
    /// Simulated trials.
    pub simulated: Discrimination,
    /// Real and simulated trials pooled.
    pub overall: Discrimination,
}

/// Classifications of one group of trials by their Δc and Δk.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Discrimination {
    /// Trials in the group.
    pub trials: u64,
    /// Trials with identified ≠ presented.
    pub mistakes: u64,
    /// Mistakes with |Δc| ≤ 0.05 cal/(g·°C).
    pub mistakes_within_c: u64,
    /// Mistakes with |Δk| ≤ 0.005 cal/(cm·s·°C).
    pub mistakes_within_k: u64,
    /// mistakes_within_c / mistakes; `null` without mistakes.
    pub share_mistakes_within_c: Option<f64>,
    /// mistakes_within_k / mistakes; `null` without mistakes.
    pub share_mistakes_within_k: Option<f64>,
    /// Every (presented, identified) pair that occurred, with its Δ values.
    pub pairs: Vec<PairDelta>,
    /// Probability of a classification at each distinct Δc (trials at Δc / all trials), ascending Δc.
    pub delta_c: Vec<DeltaBin>,
    /// Probability of a classification at each distinct Δk, ascending Δk.
    pub delta_k: Vec<DeltaBin>,
}

/// One (presented, identified) pair that occurred.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PairDelta {
    /// Presented material.
    pub presented: String,
    /// Identified material.
    pub identified: String,
    /// Number of trials.
    pub trials: u64,
    /// c_identified − c_presented [cal/(g·°C)].
    pub delta_c: f64,
    /// k_identified − k_presented [cal/(cm·s·°C)].
    pub delta_k: f64,
}

/// Classification probability at one Δ value.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DeltaBin {
    /// The Δ value (cgs unit of the quantity).
    pub delta: f64,
    /// Trials at this Δ.
    pub trials: u64,
    /// trials / all trials of the group.
    pub probability: f64,
}

impl Figure4 {
    /// Figure 4's numbers from the `[presented][identified]` count matrices.
    pub fn new(materials: &[MaterialInfo], counts: &ConditionPair<Vec<Vec<u64>>>) -> Figure4 {
        let pooled: Vec<Vec<u64>> = counts
            .real
            .iter()
            .zip(&counts.simulated)
            .map(|(a, b)| a.iter().zip(b).map(|(x, y)| x + y).collect())
            .collect();
        Figure4 {
            c_unit: "cal/(g·°C)",
            k_unit: "cal/(cm·s·°C)",
            c_half_width: C_HALF_WIDTH_CAL_G_C,
            k_half_width: K_HALF_WIDTH_CAL_CM_S_C,
            real: Discrimination::new(materials, &counts.real),
            simulated: Discrimination::new(materials, &counts.simulated),
            overall: Discrimination::new(materials, &pooled),
        }
    }
}

impl Discrimination {
    /// The Δ statistics of one `[presented][identified]` count matrix.
    pub fn new(materials: &[MaterialInfo], counts: &[Vec<u64>]) -> Discrimination {
        let mut pairs = Vec::new();
        for (p, row) in counts.iter().enumerate() {
            for (i, &n) in row.iter().enumerate().filter(|(_, &n)| n > 0) {
                let (shown, answer) = (&materials[p], &materials[i]);
                pairs.push(PairDelta {
                    presented: shown.name.clone(),
                    identified: answer.name.clone(),
                    trials: n,
                    // x − x = 0 exactly, so correct answers sit at Δ = 0.
                    delta_c: answer.specific_heat_cal_g_c - shown.specific_heat_cal_g_c,
                    delta_k: answer.conductivity_cal_cm_s_c - shown.conductivity_cal_cm_s_c,
                });
            }
        }
        let trials: u64 = pairs.iter().map(|d| d.trials).sum();
        let mistakes_of = |keep: &dyn Fn(&PairDelta) -> bool| -> u64 {
            pairs
                .iter()
                .filter(|d| d.presented != d.identified && keep(d))
                .map(|d| d.trials)
                .sum()
        };
        let mistakes = mistakes_of(&|_| true);
        let mistakes_within_c = mistakes_of(&|d| is_within(d.delta_c, C_HALF_WIDTH_CAL_G_C));
        let mistakes_within_k = mistakes_of(&|d| is_within(d.delta_k, K_HALF_WIDTH_CAL_CM_S_C));
        let share = |n: u64| (mistakes > 0).then(|| n as f64 / mistakes as f64);
        Discrimination {
            trials,
            mistakes,
            mistakes_within_c,
            mistakes_within_k,
            share_mistakes_within_c: share(mistakes_within_c),
            share_mistakes_within_k: share(mistakes_within_k),
            delta_c: histogram(pairs.iter().map(|d| (d.delta_c, d.trials)), trials),
            delta_k: histogram(pairs.iter().map(|d| (d.delta_k, d.trials)), trials),
            pairs,
        }
    }
}

/// Merges equal Δ values and divides by the group's trials; ascending Δ.
fn histogram(values: impl Iterator<Item = (f64, u64)>, total: u64) -> Vec<DeltaBin> {
    let mut values: Vec<(f64, u64)> = values.collect();
    values.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut bins: Vec<DeltaBin> = Vec::new();
    for (delta, n) in values {
        match bins.last_mut() {
            Some(last) if last.delta == delta => last.trials += n,
            _ => bins.push(DeltaBin {
                delta,
                trials: n,
                probability: 0.0,
            }),
        }
    }
    for bin in &mut bins {
        bin.probability = bin.trials as f64 / total as f64;
    }
    bins
}
