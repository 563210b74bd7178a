//! Pure statistics of the paper's section 4: row probabilities of a confusion matrix, the probability ratio table
//! (eq. 8 / Table 2) and its means, the χ² test of a contingency table (Table 3), Pearson's r (the confusion
//! correlation), least-squares slopes (Figure 3) and shares within an interval (Figure 4).
//!
//! Matrices are indexed `[presented][identified]` throughout. A quantity that does not exist for the data (a
//! probability of a row without trials, a correlation without variance) is `None` or an [`Undefined`] with the reason,
//! never NaN.

use std::fmt;

use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Why a statistic does not exist for the given data (e.g. "zero variance in the real probabilities").
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Undefined(pub String);

impl fmt::Display for Undefined {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

fn undefined<T>(reason: impl Into<String>) -> Result<T, Undefined> {
    Err(Undefined(reason.into()))
}

/// Row probabilities P(identified | presented) of a count matrix; a row without trials gives `None` cells.
pub fn row_probabilities(counts: &[Vec<u64>]) -> Vec<Vec<Option<f64>>> {
    counts
        .iter()
        .map(|row| {
            let total: u64 = row.iter().sum();
            row.iter()
                .map(|&n| (total > 0).then(|| n as f64 / total as f64))
                .collect()
        })
        .collect()
}

/// The paper's eq. 8 per cell: P_sim(identified | presented) / P_real(identified | presented).
///
/// A cell is `None` (missing, `--` in the paper) where the real probability is zero or either probability is
/// undefined (no trials of that presented material in a condition). Both matrices must have the same shape.
pub fn ratio_matrix(p_simulated: &[Vec<Option<f64>>], p_real: &[Vec<Option<f64>>]) -> Vec<Vec<Option<f64>>> {
    p_simulated
        .iter()
        .zip(p_real)
        .map(|(sim_row, real_row)| {
            sim_row
                .iter()
                .zip(real_row)
                .map(|(&sim, &real)| match (sim, real) {
                    (Some(s), Some(r)) if r > 0.0 => Some(s / r),
                    _ => None,
                })
                .collect()
        })
        .collect()
}

/// Means of a ratio table over its non-missing correct (diagonal) and false (off-diagonal) cells.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeanRatios {
    /// Mean over the diagonal cells that are not missing; `None` if all are missing.
    pub correct: Option<f64>,
    /// Number of diagonal cells averaged.
    pub correct_cells: usize,
    /// Mean over the off-diagonal cells that are not missing; `None` if all are missing.
    pub false_: Option<f64>,
    /// Number of off-diagonal cells averaged.
    pub false_cells: usize,
}

/// Mean ratio over correct and over false cells (the paper: 0.78 and 1.78).
pub fn mean_ratios(ratios: &[Vec<Option<f64>>]) -> MeanRatios {
    let mut correct = Vec::new();
    let mut false_ = Vec::new();
    for (i, row) in ratios.iter().enumerate() {
        for (j, cell) in row.iter().enumerate() {
            if let Some(r) = cell {
                if i == j {
                    correct.push(*r);
                } else {
                    false_.push(*r);
                }
            }
        }
    }
    MeanRatios {
        correct: mean(&correct),
        correct_cells: correct.len(),
        false_: mean(&false_),
        false_cells: false_.len(),
    }
}

/// Arithmetic mean; `None` for an empty slice.
pub fn mean(values: &[f64]) -> Option<f64> {
    (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
}

/// Result of Pearson's χ² test of independence (homogeneity) of a contingency table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChiSquare {
    /// Σ (observed − expected)² / expected.
    pub statistic: f64,
    /// Degrees of freedom (rows − 1)(columns − 1).
    pub df: u64,
    /// The 95 % quantile of the central χ² distribution with `df` degrees of freedom.
    pub critical_95: f64,
    /// P(χ²(df) ≥ statistic) = 1 − cdf(statistic).
    pub p_value: f64,
    /// The smallest expected count (the usual rule of thumb wants ≥ 5).
    pub min_expected: f64,
}

impl ChiSquare {
    /// Whether the null hypothesis of independence is rejected at the 5 % level (statistic above the critical value).
    pub fn rejects_at_5_percent(&self) -> bool {
        self.statistic > self.critical_95
    }
}

/// Pearson's χ² test of independence of the contingency table `observed[row][column]` (no continuity correction).
///
/// Undefined when the table has fewer than two rows or columns, or a row or column total is zero (an expected count
/// would be zero).
pub fn chi_square_independence(observed: &[Vec<u64>]) -> Result<ChiSquare, Undefined> {
    let rows = observed.len();
    let columns = observed.first().map_or(0, Vec::len);
    if rows < 2 || columns < 2 || observed.iter().any(|r| r.len() != columns) {
        return undefined(format!(
            "a χ² test needs a rectangular table of at least 2 × 2, got {rows} × {columns}"
        ));
    }
    let row_totals: Vec<f64> = observed.iter().map(|r| r.iter().sum::<u64>() as f64).collect();
    let column_totals: Vec<f64> = (0..columns)
        .map(|j| observed.iter().map(|r| r[j]).sum::<u64>() as f64)
        .collect();
    if row_totals.contains(&0.0) || column_totals.contains(&0.0) {
        return undefined("a row or column of the table has no observations, so an expected count is zero");
    }
    let total: f64 = row_totals.iter().sum();
    let mut statistic = 0.0;
    let mut min_expected = f64::INFINITY;
    for (row, row_total) in observed.iter().zip(&row_totals) {
        for (&count, column_total) in row.iter().zip(&column_totals) {
            let expected = row_total * column_total / total;
            min_expected = min_expected.min(expected);
            statistic += (count as f64 - expected).powi(2) / expected;
        }
    }
    let df = ((rows - 1) * (columns - 1)) as u64;
    let (critical_95, p_value) = chi_square_quantile_and_p(df, statistic)?;
    Ok(ChiSquare {
        statistic,
        df,
        critical_95,
        p_value,
        min_expected,
    })
}

/// The 95 % quantile of χ²(df) and the upper-tail probability of `statistic`.
pub fn chi_square_quantile_and_p(df: u64, statistic: f64) -> Result<(f64, f64), Undefined> {
    let distribution = ChiSquared::new(df as f64).map_err(|e| Undefined(format!("χ²({df}): {e}")))?;
    Ok((distribution.inverse_cdf(0.95), 1.0 - distribution.cdf(statistic)))
}

/// Pearson's correlation coefficient of paired values.
///
/// Undefined for fewer than two pairs or when either variable has zero variance. Rounding can push |r| past 1 by an
/// ulp; the result is clamped to [−1, 1] for that reason only.
pub fn pearson(x: &[f64], y: &[f64]) -> Result<f64, Undefined> {
    if x.len() != y.len() {
        return undefined(format!("{} x values but {} y values", x.len(), y.len()));
    }
    if x.len() < 2 {
        return undefined(format!("a correlation needs at least 2 pairs, got {}", x.len()));
    }
    let (mean_x, mean_y) = (mean(x).unwrap_or(0.0), mean(y).unwrap_or(0.0));
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        let (dx, dy) = (a - mean_x, b - mean_y);
        sxy += dx * dy;
        sxx += dx * dx;
        syy += dy * dy;
    }
    if sxx == 0.0 || syy == 0.0 {
        let which = if sxx == 0.0 { "first" } else { "second" };
        return undefined(format!("the {which} variable has zero variance"));
    }
    Ok((sxy / (sxx.sqrt() * syy.sqrt())).clamp(-1.0, 1.0))
}

/// Least-squares slope of y over x (ordinary least squares with intercept).
///
/// Undefined for fewer than two points or when all x are equal.
pub fn least_squares_slope(points: &[(f64, f64)]) -> Result<f64, Undefined> {
    if points.len() < 2 {
        return undefined(format!("a slope needs at least 2 samples, got {}", points.len()));
    }
    let n = points.len() as f64;
    let mean_x = points.iter().map(|p| p.0).sum::<f64>() / n;
    let mean_y = points.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = points.iter().map(|p| (p.0 - mean_x).powi(2)).sum();
    let sxy: f64 = points.iter().map(|p| (p.0 - mean_x) * (p.1 - mean_y)).sum();
    if sxx == 0.0 {
        return undefined("all samples are at the same time");
    }
    Ok(sxy / sxx)
}

/// Share of `values` with |value| ≤ `half_width` (inclusive; a relative slack of 1e-9 absorbs unit-conversion
/// rounding at the boundary); `None` for an empty slice.
pub fn share_within(values: &[f64], half_width: f64) -> Option<f64> {
    let inside = values.iter().filter(|&&v| is_within(v, half_width)).count();
    (!values.is_empty()).then(|| inside as f64 / values.len() as f64)
}

/// |value| ≤ `half_width`, with the relative slack of [`share_within`].
pub fn is_within(value: f64, half_width: f64) -> bool {
    value.abs() <= half_width * (1.0 + 1e-9)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Independent χ² for a 2 × m table of true/false counts: Σ_j (k_j − n_j p̂)² / (n_j p̂ (1 − p̂)), p̂ = Σk / Σn.
    fn binomial_homogeneity(true_counts: &[u64], trials: &[u64]) -> f64 {
        let p = true_counts.iter().sum::<u64>() as f64 / trials.iter().sum::<u64>() as f64;
        true_counts
            .iter()
            .zip(trials)
            .map(|(&k, &n)| (k as f64 - n as f64 * p).powi(2) / (n as f64 * p * (1.0 - p)))
            .sum()
    }

    fn two_by_m(true_counts: &[u64], trials: &[u64]) -> Vec<Vec<u64>> {
        vec![
            true_counts.to_vec(),
            true_counts.iter().zip(trials).map(|(k, n)| n - k).collect(),
        ]
    }

    #[test]
    fn two_by_two_worked_by_hand() {
        // [[10, 5], [4, 11]]: totals rows 15, 15; columns 14, 16; N = 30. Expected 7, 8, 7, 8.
        // χ² = 9/7 + 9/8 + 9/7 + 9/8 = 4.8214285714…; df 1; χ²(0.95; 1) = 3.841458820694124.
        let test = chi_square_independence(&[vec![10, 5], vec![4, 11]]).expect("defined");
        let want = 9.0 / 7.0 + 9.0 / 8.0 + 9.0 / 7.0 + 9.0 / 8.0;
        assert!(
            (test.statistic - want).abs() < 1e-12,
            "χ² {} vs hand {want}",
            test.statistic
        );
        assert_eq!(test.df, 1);
        assert!(
            (test.critical_95 - 3.841458820694124).abs() < 1e-9,
            "critical {}",
            test.critical_95
        );
        // df = 1: p = erfc(√(χ²/2)).
        let p_want = statrs::function::erf::erfc((want / 2.0).sqrt());
        assert!(
            (test.p_value - p_want).abs() < 1e-9,
            "p {} vs erfc {p_want}",
            test.p_value
        );
        assert!(
            (test.min_expected - 7.0).abs() < 1e-12,
            "min expected {}",
            test.min_expected
        );
        assert!(test.rejects_at_5_percent());
    }

    #[test]
    fn two_by_three_worked_by_hand() {
        // true 6, 3, 9 of 10, 10, 10: p̂ = 0.6; χ² = (0 + 9 + 9) / (10 · 0.24) = 7.5; df 2; p = e^(−7.5/2).
        let test = chi_square_independence(&two_by_m(&[6, 3, 9], &[10, 10, 10])).expect("defined");
        assert!(
            (test.statistic - 7.5).abs() < 1e-12,
            "χ² {} vs hand 7.5",
            test.statistic
        );
        assert_eq!(test.df, 2);
        let p_want = (-7.5f64 / 2.0).exp();
        assert!(
            (test.p_value - p_want).abs() < 1e-12,
            "p {} vs e^(-x/2) {p_want}",
            test.p_value
        );
        // χ²(0.95; 2) = −2 ln 0.05.
        let crit_want = -2.0 * 0.05f64.ln();
        assert!(
            (test.critical_95 - crit_want).abs() < 1e-9,
            "critical {} vs {crit_want}",
            test.critical_95
        );
        assert!(test.rejects_at_5_percent(), "7.5 > 5.99 must reject");
    }

    #[test]
    fn matches_the_binomial_homogeneity_formula_on_unequal_groups() {
        let (k, n) = ([3u64, 8, 1, 12, 7], [9u64, 13, 6, 20, 10]);
        let test = chi_square_independence(&two_by_m(&k, &n)).expect("defined");
        let want = binomial_homogeneity(&k, &n);
        assert!(
            (test.statistic - want).abs() < 1e-12,
            "χ² {} vs binomial form {want}",
            test.statistic
        );
        // df = 4: 1 − cdf(x) = e^(−x/2)(1 + x/2).
        let p_want = (-want / 2.0).exp() * (1.0 + want / 2.0);
        assert!(
            (test.p_value - p_want).abs() < 1e-12,
            "p {} vs closed form {p_want}",
            test.p_value
        );
        assert!(
            (test.critical_95 - 9.487729036781154).abs() < 1e-9,
            "critical {}",
            test.critical_95
        );
    }

    #[test]
    fn chi_square_is_undefined_without_an_expected_count() {
        assert!(chi_square_independence(&[vec![5, 5], vec![0, 0]]).is_err(), "zero row");
        assert!(
            chi_square_independence(&[vec![5, 0], vec![3, 0]]).is_err(),
            "zero column"
        );
        assert!(chi_square_independence(&[vec![5, 1]]).is_err(), "single row");
    }

    #[test]
    fn paper_table_2_means() {
        // Table 2 (rows identified, columns presented) transposed into [presented][identified].
        let t2_identified_by_presented = [
            [Some(1.01), Some(1.25), Some(3.21), None, None],
            [Some(0.82), Some(0.67), None, None, None],
            [None, Some(2.14), Some(0.54), Some(4.61), Some(1.07)],
            [None, None, Some(2.14), Some(0.73), Some(1.07)],
            [None, None, Some(1.07), Some(0.38), Some(0.97)],
        ];
        let ratios: Vec<Vec<Option<f64>>> = (0..5)
            .map(|p| (0..5).map(|i| t2_identified_by_presented[i][p]).collect())
            .collect();
        let means = mean_ratios(&ratios);
        let correct = means.correct.expect("diagonal present");
        let false_ = means.false_.expect("off-diagonal present");
        assert!((correct - 3.92 / 5.0).abs() < 1e-12, "mean correct {correct} vs 0.784");
        assert!((false_ - 17.76 / 10.0).abs() < 1e-12, "mean false {false_} vs 1.776");
        assert_eq!(
            format!("{correct:.2}/{false_:.2}"),
            "0.78/1.78",
            "the paper's rounded means"
        );
        assert_eq!((means.correct_cells, means.false_cells), (5, 10));
    }

    #[test]
    fn ratio_matrix_marks_zero_real_probability_missing() {
        let real = vec![vec![Some(0.5), Some(0.0)], vec![None, None]];
        let sim = vec![vec![Some(0.25), Some(0.75)], vec![Some(0.5), Some(0.5)]];
        let ratios = ratio_matrix(&sim, &real);
        assert_eq!(ratios, vec![vec![Some(0.5), None], vec![None, None]]);
    }

    #[test]
    fn row_probabilities_divide_by_row_totals() {
        let p = row_probabilities(&[vec![3, 1], vec![0, 0]]);
        assert_eq!(p, vec![vec![Some(0.75), Some(0.25)], vec![None, None]]);
    }

    #[test]
    fn pearson_worked_by_hand() {
        // x = 1, 2, 3; y = 2, 4, 7: dx = −1, 0, 1; dy = −7/3, −1/3, 8/3; Sxy = 5, Sxx = 2, Syy = 114/9.
        // r = 5 / √(2 · 114/9) = 15 / √228 = 0.99339926779878…
        let r = pearson(&[1.0, 2.0, 3.0], &[2.0, 4.0, 7.0]).expect("defined");
        let want = 15.0 / 228f64.sqrt();
        assert!((r - want).abs() < 1e-12, "r {r} vs hand {want}");
        let r = pearson(&[1.0, 2.0, 3.0], &[3.0, 2.0, 1.0]).expect("defined");
        assert!((r + 1.0).abs() < 1e-12, "perfectly anti-correlated: {r}");
    }

    #[test]
    fn pearson_without_variance_is_undefined() {
        let err = pearson(&[1.0, 1.0, 1.0], &[1.0, 2.0, 3.0]).expect_err("zero variance");
        assert!(err.0.contains("zero variance"), "{err}");
        assert!(pearson(&[1.0], &[2.0]).is_err(), "one pair");
    }

    #[test]
    fn slope_of_a_line_is_exact() {
        let points: Vec<(f64, f64)> = (0..9)
            .map(|i| (i as f64 * 0.25, 32.0 - 1.5 * i as f64 * 0.25))
            .collect();
        let slope = least_squares_slope(&points).expect("defined");
        assert!((slope + 1.5).abs() < 1e-12, "slope {slope} vs -1.5");
        assert!(least_squares_slope(&[(1.0, 2.0), (1.0, 3.0)]).is_err());
    }

    #[test]
    fn share_within_counts_the_boundary() {
        assert_eq!(share_within(&[0.05, -0.05, 0.06, 0.0], 0.05), Some(0.75));
        assert_eq!(share_within(&[], 0.05), None);
    }
}
