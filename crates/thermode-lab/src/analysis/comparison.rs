//! An honest comparison of the real and simulated confusions (beyond the paper): Pearson's r over the off-diagonal
//! cells that are not zero in both conditions, with a permutation p-value.
//!
//! The paper's r = 0.90 (and [`super::tables::confusion_correlation`], kept for comparison with it) correlates every
//! off-diagonal cell; cells where neither condition ever confused the pair (0 and 0) agree trivially and inflate r —
//! with a simulated participant, most off-diagonal cells are such pairs. Here those cells are left out: r is
//! computed over the cells with a non-zero probability in at least one condition (and trials of the presented
//! material in both).
//!
//! **Permutation test.** Null hypothesis: which simulated probability goes with which real one is arbitrary. The
//! statistic is r itself, one-sided (the question is whether the mistakes resemble each other, a positive
//! association): p = P(r_perm ≥ r_obs) over the pairings of the simulated values with the real ones. With at most
//! [`EXACT_MAX_CELLS`] cells every permutation is enumerated (the exact p-value); with more, [`PERMUTATIONS`] random
//! permutations from ChaCha8 seeded with [`PERMUTATION_SEED`] give p = (1 + #{r_perm ≥ r_obs}) / (1 + N) (never 0).
//! A relative slack of 1e-12 counts permutations whose r equals the observed one up to rounding.

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use super::stats::pearson;
use super::tables::{probability_cells, ConditionPair, Confusion};

/// Random permutations of the Monte Carlo test: 9999.
pub const PERMUTATIONS: usize = 9999;
/// Seed of the Monte Carlo permutations (ChaCha8): 28.
pub const PERMUTATION_SEED: u64 = 28;
/// Up to this many cells every permutation is enumerated (7! = 5040).
pub const EXACT_MAX_CELLS: usize = 7;

/// Which cells [`ConfusionComparison`] uses, in words.
pub const CELLS: &str = "off-diagonal cells not zero in both conditions";

/// The comparison of the real and simulated confusions.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConfusionComparison {
    /// Which cells: [`CELLS`].
    pub cells: &'static str,
    /// Pearson's r between the real and simulated row probabilities over those cells; `null` when undefined.
    pub r: Option<f64>,
    /// Number of cells used.
    pub pairs: usize,
    /// Off-diagonal cells left out because both conditions have probability 0 there.
    pub zero_in_both: usize,
    /// One-sided permutation p-value P(r_perm ≥ r); `null` when r is undefined.
    pub p_value: Option<f64>,
    /// `"exact"` (every permutation enumerated) or `"monte carlo"`.
    pub p_method: &'static str,
    /// Permutations evaluated (n! when exact).
    pub permutations: usize,
    /// Seed of the Monte Carlo permutations (ChaCha8).
    pub seed: u64,
    /// Why r is undefined, if it is.
    pub note: Option<String>,
}

impl ConfusionComparison {
    /// The comparison of the two conditions' row probabilities.
    pub fn new(confusion: &ConditionPair<Confusion>) -> ConfusionComparison {
        let (mut real, mut simulated, mut zero_in_both) = (Vec::new(), Vec::new(), 0);
        for cell in probability_cells(confusion).filter(|c| !c.is_diagonal()) {
            if cell.real == 0.0 && cell.simulated == 0.0 {
                zero_in_both += 1;
            } else {
                real.push(cell.real);
                simulated.push(cell.simulated);
            }
        }
        let mut comparison = compare(&real, &simulated, PERMUTATIONS, PERMUTATION_SEED);
        comparison.zero_in_both = zero_in_both;
        comparison
    }
}

/// Pearson's r of the pairs (`x`, `y`) with its one-sided permutation p-value (see the module documentation);
/// `permutations` and `seed` apply when there are more than [`EXACT_MAX_CELLS`] pairs.
pub fn compare(x: &[f64], y: &[f64], permutations: usize, seed: u64) -> ConfusionComparison {
    let mut comparison = ConfusionComparison {
        cells: CELLS,
        r: None,
        pairs: x.len(),
        zero_in_both: 0,
        p_value: None,
        p_method: "exact",
        permutations: 0,
        seed,
        note: None,
    };
    let observed = match pearson(x, y) {
        Ok(r) => r,
        Err(why) => {
            comparison.note = Some(format!("undefined: {why} (first = real, second = simulated)"));
            return comparison;
        }
    };
    comparison.r = Some(observed);
    let threshold = observed - 1e-12 * observed.abs().max(1.0);
    let at_least = |permuted: &[f64]| pearson(x, permuted).is_ok_and(|r| r >= threshold);
    if x.len() <= EXACT_MAX_CELLS {
        let (hits, total) = exact_count(y, &at_least);
        comparison.p_value = Some(hits as f64 / total as f64);
        comparison.permutations = total;
    } else {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut permuted = y.to_vec();
        let mut hits = 0usize;
        for _ in 0..permutations {
            permuted.shuffle(&mut rng);
            hits += usize::from(at_least(&permuted));
        }
        comparison.p_value = Some((1 + hits) as f64 / (1 + permutations) as f64);
        comparison.p_method = "monte carlo";
        comparison.permutations = permutations;
    }
    comparison
}

/// How many of the n! orderings of `values` satisfy `keep`, and n! (Heap's algorithm).
fn exact_count(values: &[f64], keep: &dyn Fn(&[f64]) -> bool) -> (usize, usize) {
    let mut a = values.to_vec();
    let n = a.len();
    let mut c = vec![0usize; n];
    let (mut hits, mut total) = (usize::from(keep(&a)), 1usize);
    let mut i = 0;
    while i < n {
        if c[i] < i {
            if i % 2 == 0 {
                a.swap(0, i);
            } else {
                a.swap(c[i], i);
            }
            hits += usize::from(keep(&a));
            total += 1;
            c[i] += 1;
            i = 0;
        } else {
            c[i] = 0;
            i += 1;
        }
    }
    (hits, total)
}

#[cfg(test)]
mod tests {
    use rand::Rng;

    use super::*;

    #[test]
    fn the_exact_p_value_of_a_perfect_ranking_is_one_over_n_factorial() {
        // Four distinct values in the same order: only the identity pairing reaches r = 1 → p = 1/24.
        let x = [0.1, 0.2, 0.4, 0.8];
        let c = compare(&x, &[1.0, 2.0, 3.0, 5.0], 0, 1);
        assert_eq!(c.p_method, "exact");
        assert_eq!(c.permutations, 24);
        let p = c.p_value.expect("defined");
        assert!((p - 1.0 / 24.0).abs() < 1e-12, "p {p} vs 1/24");
        // x = 1, 2, 3 against y = 1, 3, 2: r = 0.5; the six pairings give r = 1, 0.5, 0.5, −0.5, −0.5, −1, so
        // P(r ≥ 0.5) = 3/6.
        let c = compare(&[1.0, 2.0, 3.0], &[1.0, 3.0, 2.0], 0, 1);
        let (r, p) = (c.r.expect("r"), c.p_value.expect("p"));
        assert!((r - 0.5).abs() < 1e-12, "r {r} vs 0.5");
        assert!((p - 0.5).abs() < 1e-12, "p {p} vs 3/6");
    }

    #[test]
    fn perfectly_correlated_tables_give_a_small_monte_carlo_p_value() {
        // Twelve distinct cells, y = 2x: r = 1, exact p = 1/12! ≈ 2e-9; the Monte Carlo p is its floor 1/(N + 1).
        let x: Vec<f64> = (0..12).map(|i| 0.01 * f64::from(i * i + 1)).collect();
        let y: Vec<f64> = x.iter().map(|v| 2.0 * v).collect();
        let c = compare(&x, &y, 999, 5);
        assert_eq!(c.p_method, "monte carlo");
        let p = c.p_value.expect("defined");
        assert!((p - 1.0 / 1000.0).abs() < 1e-12, "p {p} vs 1/1000");
    }

    #[test]
    fn independent_tables_give_roughly_uniform_p_values() {
        // 300 pairs of independent uniform tables of 10 cells: under the null the p-values are uniform, so about
        // 5 % fall below 0.05 (binomial sd 1.3 %: bounds 4 sd) and their mean is about 0.5 (sd 0.29/√300 = 0.017).
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let ps: Vec<f64> = (0..300)
            .map(|k| {
                let x: Vec<f64> = (0..10).map(|_| rng.gen::<f64>()).collect();
                let y: Vec<f64> = (0..10).map(|_| rng.gen::<f64>()).collect();
                compare(&x, &y, 199, k).p_value.expect("defined")
            })
            .collect();
        let below = ps.iter().filter(|&&p| p <= 0.05).count() as f64 / ps.len() as f64;
        let mean = ps.iter().sum::<f64>() / ps.len() as f64;
        assert!((below - 0.05).abs() < 0.052, "share of p ≤ 0.05: {below} vs 0.05");
        assert!((mean - 0.5).abs() < 0.07, "mean p {mean} vs 0.5");
    }

    #[test]
    fn cells_zero_in_both_conditions_are_left_out() {
        use crate::analysis::MaterialInfo;
        let materials: Vec<MaterialInfo> = ["a", "b", "c"]
            .map(|name| MaterialInfo {
                name: name.to_string(),
                conductivity_cal_cm_s_c: 0.1,
                specific_heat_cal_g_c: 0.2,
            })
            .to_vec();
        let pair = ConditionPair {
            real: Confusion::from_counts(&materials, vec![vec![8, 2, 0], vec![1, 9, 0], vec![0, 0, 10]]),
            simulated: Confusion::from_counts(&materials, vec![vec![6, 4, 0], vec![3, 7, 0], vec![0, 1, 9]]),
        };
        // Off-diagonal (real, simulated): (0.2, 0.4), (0, 0), (0.1, 0.3), (0, 0), (0, 0), (0, 0.1): three cells kept.
        // Hand: dx = 0.1, 0, −0.1; dy = 2/15, 1/30, −1/6; Sxy = 0.03, Sxx = 0.02, Syy = 42/900 → r = 0.98198.
        let c = ConfusionComparison::new(&pair);
        assert_eq!((c.pairs, c.zero_in_both), (3, 3), "{c:?}");
        let want = 0.03 / (0.02f64 * 7.0 / 150.0).sqrt();
        let r = c.r.expect("defined");
        assert!((r - want).abs() < 1e-9, "r {r} vs hand {want}");
        // Of the 3! pairings only the observed one reaches r ≥ 0.98 (the next best gives 0.65): p = 1/6.
        let p = c.p_value.expect("defined");
        assert!((p - 1.0 / 6.0).abs() < 1e-12, "p {p} vs 1/6");
    }

    #[test]
    fn without_variance_the_comparison_is_undefined() {
        let c = compare(&[0.0, 0.0, 0.0], &[0.1, 0.2, 0.3], 10, 1);
        assert!(c.r.is_none() && c.p_value.is_none(), "{c:?}");
        assert!(c.note.as_deref().is_some_and(|n| n.contains("zero variance")), "{c:?}");
    }
}
