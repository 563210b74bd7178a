//! Just-noticeable differences the paper left open (beyond the paper): a cumulative-Gaussian fit to the
//! distribution of |Δk| and |Δc| over the mistakes of Figure 4, with bootstrap confidence intervals.
//!
//! **Model.** Over the mistakes of a group of trials (identified ≠ presented), the absolute difference |Δ| between
//! the identified and the presented material (|Δk| in cal/(cm·s·°C), |Δc| in cal/(g·°C)) is taken as drawn from a
//! normal distribution N(μ, σ²); its cumulative distribution Φ((x − μ)/σ) is the share of mistakes made between
//! materials at most x apart. μ (the 50 % point) is the difference below which half of the confusions happen, and
//! the 75 % point μ + 0.674 σ — reported as the just-noticeable difference, by the usual 75 % convention — the
//! difference below which three quarters of them happen: materials further apart than it are rarely confused.
//!
//! **Fit.** Maximum likelihood, which for the normal is closed-form: μ̂ the mean of the |Δ| values, σ̂ their standard
//! deviation with divisor n (every mistake counts once). Undefined (with the reason) below
//! [`MIN_MISTAKES`] mistakes or when every mistake has the same |Δ| (σ̂ = 0).
//!
//! **Confidence intervals.** Percentile bootstrap: [`BOOTSTRAP_RESAMPLES`] resamples of the mistakes with
//! replacement, drawn from ChaCha8 seeded with [`BOOTSTRAP_SEED`] (so the report is reproducible); the 2.5 % and
//! 97.5 % quantiles of each parameter over the resamples. Mistakes are resampled individually, not by participant:
//! the intervals leave out the variation between participants.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use super::figure4::{Discrimination, Figure4};

/// Resamples of the bootstrap: 2000.
pub const BOOTSTRAP_RESAMPLES: usize = 2000;
/// Seed of the bootstrap's ChaCha8 stream: 28.
pub const BOOTSTRAP_SEED: u64 = 28;
/// Fewest mistakes a fit needs: 5.
pub const MIN_MISTAKES: usize = 5;
/// Φ⁻¹(0.75): the 75 % point of a cumulative Gaussian lies 0.674 σ above μ.
pub const Z_75: f64 = 0.674_489_750_196_081_7;
/// Coverage of the confidence intervals: 95 %.
pub const CONFIDENCE: f64 = 0.95;

/// A parameter estimate with its bootstrap confidence interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Estimate {
    /// The maximum-likelihood estimate.
    pub value: f64,
    /// Lower end of the 95 % percentile-bootstrap interval.
    pub ci_low: f64,
    /// Upper end of the 95 % percentile-bootstrap interval.
    pub ci_high: f64,
}

/// The cumulative-Gaussian fit to the |Δ| of one quantity over the mistakes of one group.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GaussianFit {
    /// Number of mistakes fitted.
    pub mistakes: usize,
    /// μ: the 50 % point (mean |Δ|); `null` when undefined (see `note`).
    pub mu: Option<Estimate>,
    /// σ: the spread (standard deviation of |Δ|, divisor n).
    pub sigma: Option<Estimate>,
    /// The just-noticeable difference: the 75 % point μ + 0.674 σ.
    pub jnd_75: Option<Estimate>,
    /// Why the fit is undefined, if it is.
    pub note: Option<String>,
}

/// The fits of |Δk| and |Δc| for one group of trials.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GroupJnd {
    /// |Δk| of the mistakes [cal/(cm·s·°C)].
    pub k: GaussianFit,
    /// |Δc| of the mistakes [cal/(g·°C)].
    pub c: GaussianFit,
}

/// The just-noticeable differences of every group, with how they were computed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Jnd {
    /// The method, in words.
    pub method: &'static str,
    /// Unit of the k fits: `"cal/(cm·s·°C)"`.
    pub k_unit: &'static str,
    /// Unit of the c fits: `"cal/(g·°C)"`.
    pub c_unit: &'static str,
    /// Bootstrap resamples.
    pub bootstrap_resamples: usize,
    /// Seed of the bootstrap (ChaCha8).
    pub bootstrap_seed: u64,
    /// Coverage of the intervals (0.95).
    pub confidence: f64,
    /// Real trials.
    pub real: GroupJnd,
    /// Simulated trials.
    pub simulated: GroupJnd,
    /// Both conditions pooled.
    pub overall: GroupJnd,
}

/// How [`Jnd`] is computed, as reported.
pub const METHOD: &str = "maximum-likelihood normal fit (cumulative Gaussian) to |Δ| of the mistakes; 95 % \
                          percentile-bootstrap intervals over the mistakes (ChaCha8, seeded)";

impl Jnd {
    /// The fits of every group of Figure 4.
    pub fn new(figure4: &Figure4) -> Jnd {
        Jnd {
            method: METHOD,
            k_unit: figure4.k_unit,
            c_unit: figure4.c_unit,
            bootstrap_resamples: BOOTSTRAP_RESAMPLES,
            bootstrap_seed: BOOTSTRAP_SEED,
            confidence: CONFIDENCE,
            real: GroupJnd::new(&figure4.real),
            simulated: GroupJnd::new(&figure4.simulated),
            overall: GroupJnd::new(&figure4.overall),
        }
    }
}

impl GroupJnd {
    /// The fits of the mistakes of one group.
    pub fn new(group: &Discrimination) -> GroupJnd {
        let values = |delta: fn(&super::figure4::PairDelta) -> f64| -> Vec<f64> {
            group
                .pairs
                .iter()
                .filter(|p| p.presented != p.identified)
                .flat_map(|p| std::iter::repeat_n(delta(p).abs(), p.trials as usize))
                .collect()
        };
        GroupJnd {
            k: fit_cumulative_gaussian(&values(|p| p.delta_k), BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED),
            c: fit_cumulative_gaussian(&values(|p| p.delta_c), BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED),
        }
    }
}

/// The maximum-likelihood normal (μ, σ) of `values`: their mean and their standard deviation with divisor n.
pub fn normal_mle(values: &[f64]) -> (f64, f64) {
    let n = values.len().max(1) as f64;
    let mu = values.iter().sum::<f64>() / n;
    let variance = values.iter().map(|v| (v - mu).powi(2)).sum::<f64>() / n;
    (mu, variance.sqrt())
}

/// The cumulative-Gaussian fit of `values` (see the module documentation) with `resamples` bootstrap resamples
/// drawn from ChaCha8 seeded with `seed`.
pub fn fit_cumulative_gaussian(values: &[f64], resamples: usize, seed: u64) -> GaussianFit {
    let undefined = |note: String| GaussianFit {
        mistakes: values.len(),
        mu: None,
        sigma: None,
        jnd_75: None,
        note: Some(note),
    };
    if values.len() < MIN_MISTAKES {
        return undefined(format!(
            "undefined: {} mistake(s); a fit needs at least {MIN_MISTAKES}",
            values.len()
        ));
    }
    if values.iter().all(|&v| v == values[0]) {
        return undefined(format!(
            "undefined: every mistake has the same |Δ| ({}), so the spread is zero",
            values[0]
        ));
    }
    let (mu, sigma) = normal_mle(values);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut sample = vec![0.0; values.len()];
    let (mut mus, mut sigmas, mut jnds) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..resamples {
        for slot in sample.iter_mut() {
            *slot = values[rng.gen_range(0..values.len())];
        }
        let (m, s) = normal_mle(&sample);
        mus.push(m);
        sigmas.push(s);
        jnds.push(m + Z_75 * s);
    }
    let estimate = |value: f64, draws: &mut Vec<f64>| {
        let (ci_low, ci_high) = percentile_interval(draws, CONFIDENCE);
        Some(Estimate { value, ci_low, ci_high })
    };
    GaussianFit {
        mistakes: values.len(),
        mu: estimate(mu, &mut mus),
        sigma: estimate(sigma, &mut sigmas),
        jnd_75: estimate(mu + Z_75 * sigma, &mut jnds),
        note: None,
    }
}

/// The central `confidence` interval of `draws` (sorted here): the empirical quantiles at (1 − confidence)/2 and
/// (1 + confidence)/2, by linear interpolation between order statistics. `draws` must not be empty.
pub fn percentile_interval(draws: &mut [f64], confidence: f64) -> (f64, f64) {
    draws.sort_by(f64::total_cmp);
    let quantile = |q: f64| {
        let position = q * (draws.len() - 1) as f64;
        let (low, high) = (position.floor() as usize, position.ceil() as usize);
        draws[low] + (position - low as f64) * (draws[high] - draws[low])
    };
    let tail = (1.0 - confidence) / 2.0;
    (quantile(tail), quantile(1.0 - tail))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::random::standard_normal;

    #[test]
    fn the_fit_recovers_a_known_cumulative_gaussian() {
        // 1500 draws of N(0.05, 0.02²): standard errors σ/√n = 0.00052 for μ and σ/√(2n) = 0.00037 for σ.
        let (mu, sigma, n) = (0.05, 0.02, 1500);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let values: Vec<f64> = (0..n).map(|_| mu + sigma * standard_normal(&mut rng)).collect();
        let fit = fit_cumulative_gaussian(&values, 1000, 3);
        let (m, s, j) = (fit.mu.expect("fit"), fit.sigma.expect("fit"), fit.jnd_75.expect("fit"));
        // Tolerance: 4 standard errors.
        assert!((m.value - mu).abs() < 4.0 * 0.000_52, "μ {} vs {mu}", m.value);
        assert!((s.value - sigma).abs() < 4.0 * 0.000_37, "σ {} vs {sigma}", s.value);
        let jnd = mu + 0.674_489_75 * sigma;
        assert!((j.value - jnd).abs() < 0.002, "75 % point {} vs {jnd}", j.value);
        // The intervals hold the truth and have the normal theory's width 2 · 1.96 · SE (within 20 %).
        assert!(
            m.ci_low < mu && mu < m.ci_high,
            "μ {mu} outside [{}, {}]",
            m.ci_low,
            m.ci_high
        );
        assert!(
            s.ci_low < sigma && sigma < s.ci_high,
            "σ {sigma} outside [{}, {}]",
            s.ci_low,
            s.ci_high
        );
        let width_mu = m.ci_high - m.ci_low;
        let want_mu = 2.0 * 1.959_964 * sigma / (n as f64).sqrt();
        assert!(
            (width_mu / want_mu - 1.0).abs() < 0.2,
            "μ CI width {width_mu} vs {want_mu}"
        );
        let width_sigma = s.ci_high - s.ci_low;
        let want_sigma = 2.0 * 1.959_964 * sigma / (2.0 * n as f64).sqrt();
        assert!(
            (width_sigma / want_sigma - 1.0).abs() < 0.2,
            "σ CI width {width_sigma} vs {want_sigma}"
        );
    }

    #[test]
    fn the_maximum_likelihood_normal_of_a_small_sample_is_worked_by_hand() {
        // 1, 2, 3, 6: mean 3; squared deviations 4, 1, 0, 9 → variance 14/4 = 3.5.
        let (mu, sigma) = normal_mle(&[1.0, 2.0, 3.0, 6.0]);
        assert!((mu - 3.0).abs() < 1e-12, "μ {mu} vs 3");
        assert!((sigma - 3.5f64.sqrt()).abs() < 1e-12, "σ {sigma} vs √3.5");
    }

    #[test]
    fn percentiles_interpolate_between_order_statistics() {
        // 0..=100: the 2.5 % quantile at position 2.5 → 2.5, the 97.5 % at 97.5.
        let mut draws: Vec<f64> = (0..=100).rev().map(f64::from).collect();
        let (low, high) = percentile_interval(&mut draws, 0.95);
        assert!(
            (low - 2.5).abs() < 1e-12 && (high - 97.5).abs() < 1e-12,
            "[{low}, {high}]"
        );
    }

    #[test]
    fn too_few_or_identical_mistakes_are_undefined() {
        let few = fit_cumulative_gaussian(&[0.1, 0.2], 10, 1);
        assert!(
            few.mu.is_none() && few.note.as_deref().is_some_and(|n| n.contains("at least")),
            "{few:?}"
        );
        let same = fit_cumulative_gaussian(&[0.1; 8], 10, 1);
        assert!(
            same.mu.is_none() && same.note.as_deref().is_some_and(|n| n.contains("zero")),
            "{same:?}"
        );
    }
}
