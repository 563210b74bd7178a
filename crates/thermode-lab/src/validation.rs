//! Fitting and validating the perceptual simulated participant ([`crate::perception`]) against published human data:
//! the fit to the paper's real-condition identification rates ([`fit_real_rates`]), the paper's design simulated
//! over seeds ([`design_figures`], [`Spread`]) and the published numbers checked into the repository
//! (`data/validation.csv`, [`published`]). The `fit_participant` and `validate_participant` examples run them.

use serde::Deserialize;
use thermode_device::DeviceConfig;
use thermode_model::materials::find;
use thermode_model::units::{conductivity_to_cgs, specific_heat_to_cgs};
use thermode_pipeline::{gains_for_device, ControllerKind, PipelineConfig, PipelineError, RendererKind};
use thiserror::Error;

use crate::analysis::figure4::Discrimination;
use crate::analysis::stats::mean_ratios;
use crate::analysis::{ChiSquareReport, Confusion, MaterialInfo, RatioTable};
use crate::design::Condition;
use crate::participant::{CurveFeatures, ParticipantError};
use crate::perception::{PerceptionParams, PerceptualParticipant};
use crate::runner::stimulus::{DisplaySetup, DisplayStimulus, FvContact, StimulusError};

/// The paper's materials, in its order.
pub const PAPER_MATERIALS: [&str; 5] = ["aluminium", "steel", "stone", "wood", "rubber"];
/// The paper's real-condition correct-identification rates (Tables 2 and 3), in [`PAPER_MATERIALS`] order.
pub const PAPER_REAL_RATES: [f64; 5] = [0.53, 0.54, 0.80, 0.97, 0.56];
/// The published numbers with their sources (effect, source, published value, tolerance).
pub const VALIDATION_CSV: &str = include_str!("../data/validation.csv");

/// Why a validation figure could not be computed.
#[derive(Debug, Error)]
pub enum ValidationError {
    /// The participant could not be built or a curve's features computed.
    #[error("validation: {0}")]
    Participant(#[from] ParticipantError),
    /// A curve could not be computed.
    #[error("validation: {0}")]
    Stimulus(#[from] StimulusError),
    /// The display's controller could not be set up.
    #[error("validation: {0}")]
    Pipeline(#[from] PipelineError),
}

/// Real and simulated features, one per paper material.
pub type ConditionFeatures = (Vec<CurveFeatures>, Vec<CurveFeatures>);

/// The paper-like display: the Kron renderer and the tuned PID on the default device (docs/lab.md).
pub fn paper_like_pipeline() -> Result<PipelineConfig, ValidationError> {
    let device = DeviceConfig::default();
    let gains = gains_for_device(&device)?.0;
    let mut pipeline = PipelineConfig::new(device, ControllerKind::Pid(gains));
    pipeline.renderer = RendererKind::Kron;
    Ok(pipeline)
}

/// thermode's own default display: the fv renderer and the model controller on the default device.
pub fn own_display_pipeline() -> PipelineConfig {
    PipelineConfig::new(DeviceConfig::default(), ControllerKind::Model)
}

/// The real and simulated features of the paper's materials (30 s) on the simulated display `pipeline`, finger
/// without drift, display seed 2008 (the paper design's seed).
pub fn display_features(pipeline: PipelineConfig) -> Result<ConditionFeatures, ValidationError> {
    let mut stimulus = DisplayStimulus::new(DisplaySetup::new(pipeline), 0.0, 2008)?;
    let (mut real, mut simulated) = (Vec::new(), Vec::new());
    for name in PAPER_MATERIALS {
        let curves = stimulus.curves(&find(name).map_err(ParticipantError::from)?, 30.0)?;
        real.push(CurveFeatures::of(&curves.real)?);
        simulated.push(CurveFeatures::of(&curves.simulated)?);
    }
    Ok((real, simulated))
}

/// The features of `name`'s contact curve under `contact` over 30 s.
fn contact_curve_features(contact: &FvContact, name: &str) -> Result<CurveFeatures, ValidationError> {
    let material = find(name).map_err(ParticipantError::from)?;
    Ok(CurveFeatures::of(
        &contact.curve(&material, None, 30.0).map_err(StimulusError::from)?,
    )?)
}

/// A two-option participant (seed 3) for `warmer` and `colder` with their room-temperature fv features.
fn pair_participant(
    params: &PerceptionParams,
    warmer: &str,
    colder: &str,
) -> Result<(PerceptualParticipant, [CurveFeatures; 2]), ValidationError> {
    let contact = FvContact::default();
    let features = [
        contact_curve_features(&contact, warmer)?,
        contact_curve_features(&contact, colder)?,
    ];
    let names = vec![warmer.to_string(), colder.to_string()];
    Ok((
        PerceptualParticipant::new(names, &features, params.clone(), 3)?,
        features,
    ))
}

/// Jones & Berris (2002)'s check: 2AFC proportion correct between copper and aluminium (Δk 164 W/(m·K)) under the
/// default fv model (30 s), `persons` × `trials`, participant seed 3.
pub fn metals_correct(params: &PerceptionParams, persons: usize, trials: usize) -> Result<f64, ValidationError> {
    let (p, f) = pair_participant(params, "aluminium", "copper")?;
    Ok(p.two_afc_correct((&f[0], 0), (&f[1], 1), persons, trials))
}

/// Yang, Kwon & Jones (2009)'s check: 2AFC proportion correct between aluminium and stone (stone the warmer, fv
/// model, 30 s) when aluminium touches `colder_sites` fingers and stone one, `persons` × `trials`, participant seed
/// 3; the summation rule is [`PerceptualParticipant::two_afc_correct_sites`]'s (averaging of independent channels).
pub fn fingers_correct(
    params: &PerceptionParams,
    colder_sites: usize,
    persons: usize,
    trials: usize,
) -> Result<f64, ValidationError> {
    let (p, f) = pair_participant(params, "stone", "aluminium")?;
    Ok(p.two_afc_correct_sites((&f[0], 0), (&f[1], 1), colder_sites, persons, trials))
}

/// A sample of `presented` whose contact curve (fv model, 30 s) matches that of `matched_to` at room temperature:
/// its temperature at the touch \[°C\], found by bisection in −30…60 °C so that the summed perceived cues (the 2AFC
/// decision variable) are equal, and the curve's features.
pub fn matched_sample(presented: &str, matched_to: &str) -> Result<(f64, CurveFeatures), ValidationError> {
    let room = FvContact::default();
    let features = contact_curve_features;
    let sum = |f: &CurveFeatures| f.perceived()[0] + f.perceived()[1];
    let target = sum(&features(&room, matched_to)?);
    let (mut cold_c, mut warm_c) = (-30.0, 60.0);
    for _ in 0..40 {
        let mid_c = 0.5 * (cold_c + warm_c);
        let contact = FvContact {
            object_c: mid_c,
            ..FvContact::default()
        };
        // A colder sample cools the finger more: a larger sum.
        if sum(&features(&contact, presented)?) > target {
            cold_c = mid_c;
        } else {
            warm_c = mid_c;
        }
    }
    let object_c = 0.5 * (cold_c + warm_c);
    let contact = FvContact {
        object_c,
        ..FvContact::default()
    };
    Ok((object_c, features(&contact, presented)?))
}

/// Bhattacharjee et al. (2020)'s check: how often `presented`, pre-heated or pre-cooled so that its contact curve
/// matches `matched_to`'s ([`matched_sample`]), is identified among the paper's five materials (prototypes at room
/// temperature) on its thermal cues alone (a display presentation: no non-thermal channel), `persons` ×
/// `repetitions`, participant seed 3; both are indices into [`PAPER_MATERIALS`] (panics outside it). Returns the sample's temperature and the proportion correct.
pub fn matched_identification(
    params: &PerceptionParams,
    (presented, matched_to): (usize, usize),
    persons: usize,
    repetitions: usize,
) -> Result<(f64, f64), ValidationError> {
    let (object_c, features) = matched_sample(PAPER_MATERIALS[presented], PAPER_MATERIALS[matched_to])?;
    let options: Vec<String> = PAPER_MATERIALS.iter().map(|s| s.to_string()).collect();
    let references = contact_features(&FvContact::default(), 30.0)?;
    let p = PerceptualParticipant::new(options, &references, params.clone(), 3)?;
    let mut correct = 0usize;
    for person in 0..persons {
        for trial in 1..=repetitions {
            correct += usize::from(p.respond(&features, presented, Condition::Simulated, person, trial) == presented);
        }
    }
    Ok((object_c, correct as f64 / (persons * repetitions).max(1) as f64))
}

/// The largest share of mistakes between wood and rubber (the only pair of the paper's materials within
/// k ± 0.005 cal/(cm·s·°C)) that any data matching the paper's correct rates can have: every mistake made on wood or
/// rubber in either condition taken as a wood–rubber confusion, over all mistakes, with equal trials per material and
/// condition (real rates [`PAPER_REAL_RATES`], simulated rates `simulated`).
pub fn wood_rubber_share_bound(simulated: &[f64; 5]) -> f64 {
    let mistakes = |rates: &[f64]| rates.iter().map(|r| 1.0 - r).collect::<Vec<f64>>();
    let (real, sim) = (mistakes(&PAPER_REAL_RATES), mistakes(simulated));
    let total: f64 = real.iter().chain(&sim).sum();
    (real[3] + real[4] + sim[3] + sim[4]) / total
}

/// P(X ≥ k) for X ~ Binomial(n, p).
pub fn binomial_upper_tail(n: u64, k: u64, p: f64) -> f64 {
    if p >= 1.0 {
        return if k <= n { 1.0 } else { 0.0 };
    }
    let mut pmf = (1.0 - p).powi(n as i32);
    let mut tail = if k == 0 { pmf } else { 0.0 };
    for i in 1..=n {
        pmf *= (n - i + 1) as f64 / i as f64 * p / (1.0 - p);
        if i >= k {
            tail += pmf;
        }
    }
    tail.min(1.0)
}

/// The largest probability, over every split p + q = 1, that one run of `n` trials each gives at least `wood` correct
/// wood answers (rate p) and at least `rubber` correct rubber answers (rate q): the bound for an observer to whom the
/// two materials feel alike (its answers depend on the percept only, so p + q ≤ 1; grid of 0.001).
pub fn alike_pair_joint_probability(n: u64, wood: u64, rubber: u64) -> f64 {
    (0..=1000)
        .map(|i| {
            let p = f64::from(i) / 1000.0;
            binomial_upper_tail(n, wood, p) * binomial_upper_tail(n, rubber, 1.0 - p)
        })
        .fold(0.0, f64::max)
}

/// One row of `data/validation.csv`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct Published {
    /// Short key used by the checks.
    pub key: String,
    /// What is compared.
    pub effect: String,
    /// Where the number is published.
    pub source: String,
    /// The published value.
    pub published: f64,
    /// The acceptance rule, in words.
    pub tolerance: String,
}

/// The rows of `data/validation.csv`.
pub fn published() -> Vec<Published> {
    csv::Reader::from_reader(VALIDATION_CSV.as_bytes())
        .deserialize()
        .collect::<Result<_, _>>()
        .expect("the shipped validation.csv parses (a unit test checks it)")
}

/// The real-contact features of the paper's materials under `contact` for `duration_s` (the participant's references).
pub fn contact_features(contact: &FvContact, duration_s: f64) -> Result<Vec<CurveFeatures>, ParticipantError> {
    PAPER_MATERIALS
        .iter()
        .map(|name| {
            let curve = contact
                .curve(&find(name)?, None, duration_s)
                .map_err(StimulusError::from)?;
            CurveFeatures::of(&curve)
        })
        .collect()
}

/// Fits the non-thermal recognition probabilities so that `base` identifies real contact at `targets` (one per
/// option): the thermal stage alone (π = 0) identifies option k at `t_k` on common random numbers (`persons` ×
/// `repetitions` trials per option); a recognised trial is always correct and the others are answered thermally,
/// so the real rate is `π_k + (1 − π_k) t_k` and `π_k = (r_k − t_k) / (1 − t_k)`, 0 where the thermal stage alone
/// already reaches the target. The biases stay as given. Returns the fitted parameters and the thermal-only rates.
pub fn fit_real_rates(
    base: &PerceptualParticipant,
    targets: &[f64],
    persons: usize,
    repetitions: usize,
) -> (PerceptionParams, Vec<f64>) {
    let mut params = base.params().clone();
    params.non_thermal_recognition.clear();
    let thermal = base.with_params(params.clone()).real_rates(persons, repetitions);
    for ((name, target), t) in base.options().iter().zip(targets).zip(&thermal) {
        let recognition = if *t < 1.0 {
            ((target - t) / (1.0 - t)).max(0.0)
        } else {
            0.0
        };
        params.non_thermal_recognition.insert(name.clone(), recognition);
    }
    (params, thermal)
}

/// The figures of one simulated run of the paper's design (as `lab analyze` computes them).
#[derive(Debug, Clone, PartialEq)]
pub struct DesignFigures {
    /// Table 3's χ²(4) over the simulated trials.
    pub chi_square: f64,
    /// Mean of the correct (diagonal) ratios simulated/real (Table 2).
    pub mean_ratio_correct: f64,
    /// Mean of the false (off-diagonal) ratios simulated/real.
    pub mean_ratio_false: f64,
    /// Share of all mistakes within c ± 0.05 cal/(g·°C) (Fig. 4, both conditions).
    pub share_within_c: f64,
    /// Share of all mistakes within k ± 0.005 cal/(cm·s·°C).
    pub share_within_k: f64,
    /// Simulated correct rate per material, [`PAPER_MATERIALS`] order.
    pub simulated_correct: Vec<f64>,
    /// Real correct rate per material.
    pub real_correct: Vec<f64>,
}

/// The paper's materials as the analysis describes them.
pub fn paper_material_info() -> Vec<MaterialInfo> {
    PAPER_MATERIALS
        .iter()
        .map(|name| {
            let m = find(name).expect("library material");
            MaterialInfo {
                name: m.name,
                conductivity_cal_cm_s_c: conductivity_to_cgs(m.conductivity_w_mk),
                specific_heat_cal_g_c: specific_heat_to_cgs(m.specific_heat_j_kgk),
            }
        })
        .collect()
}

/// The `[presented][identified]` counts of `participant` over the paper's design (`persons`, `repetitions` of each
/// material in each condition) when real trials have `real` features and simulated trials `simulated` ones.
pub fn design_counts(
    participant: &PerceptualParticipant,
    real: &[CurveFeatures],
    simulated: &[CurveFeatures],
    persons: usize,
    repetitions: usize,
) -> [Vec<Vec<u64>>; 2] {
    let n = real.len();
    let mut counts = [vec![vec![0u64; n]; n], vec![vec![0u64; n]; n]];
    for person in 0..persons {
        let mut trial = 0;
        for (c, (condition, features)) in [(Condition::Real, real), (Condition::Simulated, simulated)]
            .into_iter()
            .enumerate()
        {
            for _ in 0..repetitions {
                for k in 0..n {
                    trial += 1;
                    let answer = participant.respond(&features[k], k, condition, person, trial);
                    counts[c][k][answer] += 1;
                }
            }
        }
    }
    counts
}

/// The figures of one run from its counts (real, simulated).
pub fn design_figures(counts: &[Vec<Vec<u64>>; 2]) -> DesignFigures {
    let materials = paper_material_info();
    let [real, simulated] = counts;
    let chi = ChiSquareReport::new(&materials, simulated);
    let real_c = Confusion::from_counts(&materials, real.clone());
    let sim_c = Confusion::from_counts(&materials, simulated.clone());
    let ratios = RatioTable::new(&materials, &sim_c, &real_c);
    let means = mean_ratios(&ratios.ratios);
    let pooled: Vec<Vec<u64>> = real
        .iter()
        .zip(simulated)
        .map(|(a, b)| a.iter().zip(b).map(|(x, y)| x + y).collect())
        .collect();
    let overall = Discrimination::new(&materials, &pooled);
    let diagonal = |m: &Vec<Vec<u64>>| -> Vec<f64> {
        m.iter()
            .enumerate()
            .map(|(k, row)| row[k] as f64 / row.iter().sum::<u64>().max(1) as f64)
            .collect()
    };
    DesignFigures {
        chi_square: chi.statistic.unwrap_or(f64::NAN),
        mean_ratio_correct: means.correct.unwrap_or(f64::NAN),
        mean_ratio_false: means.false_.unwrap_or(f64::NAN),
        share_within_c: overall.share_mistakes_within_c.unwrap_or(f64::NAN),
        share_within_k: overall.share_mistakes_within_k.unwrap_or(f64::NAN),
        simulated_correct: diagonal(simulated),
        real_correct: diagonal(real),
    }
}

/// The paper's design (15 persons, 2 repetitions) run with participant seeds `seeds`.
pub fn design_over_seeds(
    params: &PerceptionParams,
    real: &[CurveFeatures],
    simulated: &[CurveFeatures],
    seeds: std::ops::Range<u64>,
) -> Result<Vec<DesignFigures>, ParticipantError> {
    let options: Vec<String> = PAPER_MATERIALS.iter().map(|s| s.to_string()).collect();
    seeds
        .map(|seed| {
            let p = PerceptualParticipant::new(options.clone(), real, params.clone(), seed)?;
            Ok(design_figures(&design_counts(&p, real, simulated, 15, 2)))
        })
        .collect()
}

/// The 5-95 % range (and median) of a figure across seeds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spread {
    /// 5th percentile.
    pub p5: f64,
    /// Median.
    pub median: f64,
    /// 95th percentile.
    pub p95: f64,
}

impl Spread {
    /// The spread of `values` (NaN left out; nearest-rank percentiles).
    pub fn of(values: impl IntoIterator<Item = f64>) -> Spread {
        let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        v.sort_by(f64::total_cmp);
        let at = |q: f64| {
            if v.is_empty() {
                return f64::NAN;
            }
            v[((q * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)]
        };
        Spread {
            p5: at(0.05),
            median: at(0.5),
            p95: at(0.95),
        }
    }

    /// Whether `value` lies in the 5-95 % range.
    pub fn contains(&self, value: f64) -> bool {
        (self.p5..=self.p95).contains(&value)
    }
}

/// The Weber fraction at which the sensory stage alone (no finger or contact variation) is 75 % correct in 2AFC
/// around `reference`: bisection on the factor 1 + W with common random numbers (`trials` draws, seed `seed`).
pub fn weber_fraction_at(params: &PerceptionParams, reference: &CurveFeatures, trials: usize, seed: u64) -> f64 {
    let sd = params.sensory_sd();
    let mut rng = crate::random::trial_rng(seed, 0, 0);
    let noise: Vec<f64> = (0..trials)
        .map(|_| (0..4).map(|_| crate::random::standard_normal(&mut rng)).sum::<f64>())
        .collect();
    let base = reference.perceived();
    let rate = |w: f64| {
        let scaled = CurveFeatures {
            initial_cooling_rate_c_per_s: reference.initial_cooling_rate_c_per_s * (1.0 + w),
            end_drop_c: reference.end_drop_c * (1.0 + w),
        }
        .perceived();
        let shift = scaled[0] + scaled[1] - base[0] - base[1];
        // The difference of the two intervals' summed cues: four independent noises of sd σ.
        noise.iter().filter(|z| shift + sd * **z > 0.0).count() as f64 / noise.len().max(1) as f64
    };
    let (mut low, mut high) = (0.0, 5.0);
    for _ in 0..50 {
        let mid = 0.5 * (low + high);
        if rate(mid) >= 0.75 {
            high = mid;
        } else {
            low = mid;
        }
    }
    high
}

/// The method of limits minus the method of levels for cold detection at `rate_c_s` \[°C\]: the limits estimate
/// `θ + r·(t_rt + lag)` against the trapezoid threshold (plateau `plateau_s`, return at the same rate) of the
/// procedures' skin response (`thermode_procedures::skin_response`) on the display's contact conductance.
pub fn limits_levels_gap_c(threshold_c: f64, rate_c_per_s: f64, reaction_time_s: f64, plateau_s: f64) -> Option<f64> {
    use thermode_procedures::skin_response::{SkinResponse, Trapezoid};
    let skin = thermode_model::skin::Skin::fingertip();
    let response = SkinResponse::new(&skin, thermode_model::inverse::DEFAULT_DISPLAY_CONDUCTANCE_W_M2K).ok()?;
    let limits = response.limits_estimate_c(threshold_c, rate_c_per_s, reaction_time_s)?;
    let timing = Trapezoid {
        rate_c_per_s,
        plateau_s,
        return_rate_c_per_s: rate_c_per_s,
    };
    let levels = response.trapezoid_threshold_c(threshold_c, timing)?;
    Some(limits - levels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_published_numbers_parse() {
        let rows = published();
        assert!(rows.iter().any(|r| r.key == "chi_square"), "{rows:?}");
        assert!(rows.iter().all(|r| !r.source.is_empty()));
    }

    #[test]
    fn binomial_tails_match_hand_computed_values() {
        // P(X ≥ 2), n 3, p 0.5: (3 + 1) / 8; P(X ≥ 0) = 1; P(X ≥ 3), p 0.1: 0.001.
        assert!((binomial_upper_tail(3, 2, 0.5) - 0.5).abs() < 1e-12);
        assert!((binomial_upper_tail(3, 0, 0.3) - 1.0).abs() < 1e-12);
        assert!((binomial_upper_tail(3, 3, 0.1) - 0.001).abs() < 1e-12);
    }

    #[test]
    fn spreads_use_nearest_ranks() {
        let s = Spread::of((0..=100).map(f64::from));
        assert_eq!((s.p5, s.median, s.p95), (5.0, 50.0, 95.0));
        assert!(s.contains(50.0) && !s.contains(96.0));
    }
}
