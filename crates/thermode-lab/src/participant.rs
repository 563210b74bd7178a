//! The nearest-reference simulated participant (beyond the paper): identifies a material from the skin temperature
//! curve of a trial, so that a lab can check its design and the effect sizes to expect before recruiting anyone.
//! `lab run --simulated-participant --participant-model calibrated` answers with this one; the default is the
//! perceptual participant of [`crate::perception`] (issue 28), which builds on this module's [`CurveFeatures`].
//!
//! **Features.** From a curve the simulated participant takes the two cues the paper's discussion of Figure 3 names: the
//! initial cooling rate, `(T(0) − T(2 s)) / 2 s` \[°C/s\], and the drop at the end of the presentation,
//! `T(0) − T(end)` \[°C\]. It perceives each through `asinh(x / x₀)` with x₀ = 0.1 °C/s and 0.1 °C, the smallest
//! detectable rate of change (`model.md` §6): linear near zero and logarithmic (Weber-like) above, so the same
//! noise means the same relative error for a fast and a slow material, and warming (negative values) is handled.
//!
//! **Decision.** Every response option has a reference: the features of real contact with it under the
//! finite-volume model ([`FvContact`]), computed once. The simulated adds Gaussian perceptual noise of standard
//! deviation `noise_sd` (in perceived units, on each feature independently) to the trial's features and answers
//! the option whose reference is nearest (Euclidean). The noise of each trial comes from its own ChaCha8 stream
//! (seed, participant, trial), so a resumed session gives the same answers.
//!
//! **Calibration.** [`SimulatedParticipant::calibrate`] searches the noise scale (bisection with common random numbers:
//! a fixed seeded sample of noise vectors, scaled) at which real contact is identified as often as in the paper,
//! 66 % over five options ([`PAPER_REAL_IDENTIFICATION_RATE`]). For the paper's five materials over 30 s the
//! calibrated value is 0.0981 ([`PAPER_CALIBRATED_NOISE_SD`]), i.e. a perceptual error of about 10 % on each cue;
//! on 10 000 fresh trials the simulated participant then identifies real contact 65.9 % of the time. Aluminium/steel and
//! wood/rubber are the pairs confused (stone is identified 93 % of the time): wood and rubber have almost the same
//! effusivity and their curves differ by a few hundredths of a degree, so no simulated tells them apart much better
//! than by chance.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use thermode_model::materials::find;
use thermode_model::params::{BadValue, Rule};
use thiserror::Error;

pub use crate::random::{standard_normal, trial_rng};
use crate::runner::stimulus::{FvContact, SkinCurve, StimulusError};

/// The paper's rate of correct identification of real materials (section 4.2 a: 66 %, five options).
pub const PAPER_REAL_IDENTIFICATION_RATE: f64 = 0.66;
/// The noise scale [`SimulatedParticipant::calibrate`] finds for the paper's five materials, 30 s presentations, the
/// default [`FvContact`], 4000 samples per option and seed 1 (documented; the tests recompute it).
pub const PAPER_CALIBRATED_NOISE_SD: f64 = 0.0981;
/// Window of the initial cooling rate \[s\].
pub const INITIAL_WINDOW_S: f64 = 2.0;
/// Perception scale of the cooling rate \[°C/s\] (the smallest detectable rate of change, `model.md` §6).
pub const RATE_SCALE_C_PER_S: f64 = 0.1;
/// Perception scale of the temperature drop \[°C\].
pub const DROP_SCALE_C: f64 = 0.1;
/// Seed salt of the simulated participant's per-trial noise streams.
const OBSERVER_SALT: u64 = 0x6f62_7365_7276_0001;

/// Why the simulated participant could not be built, calibrated or used.
#[derive(Debug, Error)]
pub enum ParticipantError {
    /// The reference curves could not be computed.
    #[error("simulated: {0}")]
    Stimulus(#[from] StimulusError),
    /// A response option is not a library material.
    #[error("simulated: {0}")]
    Material(#[from] thermode_model::ParamError),
    /// The trial has no skin curve to judge.
    #[error("simulated: the stimulus recorded no skin temperature curve; the simulated participant needs one")]
    NoCurve,
    /// A curve is too short for the features.
    #[error("simulated: the curve lasts {duration_s} s; the features need at least {INITIAL_WINDOW_S} s")]
    ShortCurve {
        /// Duration of the curve \[s\].
        duration_s: f64,
    },
    /// A setting is out of range (the one `BadValue` of `thermode_model::params`, naming the key).
    #[error("simulated: {0}")]
    BadSetting(#[from] BadValue),
    /// The target identification rate cannot be reached with these options.
    #[error(
        "simulated: a rate of {target} cannot be reached: with these options the rate stays between {lowest:.3} \
         (the most noise tried) and {highest:.3} (almost no noise); physically indistinguishable options limit it"
    )]
    Unreachable {
        /// The rate asked for.
        target: f64,
        /// Rate with almost no noise.
        highest: f64,
        /// Rate with the most noise tried.
        lowest: f64,
    },
}

/// The two cues of a skin temperature curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurveFeatures {
    /// Mean cooling rate over the first [`INITIAL_WINDOW_S`] seconds, `(T(0) − T(2 s)) / 2 s` \[°C/s\].
    pub initial_cooling_rate_c_per_s: f64,
    /// Temperature drop at the end of the curve, `T(0) − T(end)` \[°C\].
    pub end_drop_c: f64,
}

impl CurveFeatures {
    /// The features of `curve` (validated here).
    pub fn of(curve: &SkinCurve) -> Result<CurveFeatures, ParticipantError> {
        curve.validate()?;
        let end_s = curve.time_s[curve.time_s.len() - 1];
        if end_s < INITIAL_WINDOW_S {
            return Err(ParticipantError::ShortCurve { duration_s: end_s });
        }
        let t0 = curve.skin_c[0];
        Ok(CurveFeatures {
            initial_cooling_rate_c_per_s: (t0 - curve.at(INITIAL_WINDOW_S)) / INITIAL_WINDOW_S,
            end_drop_c: t0 - curve.skin_c[curve.skin_c.len() - 1],
        })
    }

    /// The features as perceived: `asinh(rate / 0.1 °C/s)`, `asinh(drop / 0.1 °C)`.
    pub fn perceived(&self) -> [f64; 2] {
        [
            (self.initial_cooling_rate_c_per_s / RATE_SCALE_C_PER_S).asinh(),
            (self.end_drop_c / DROP_SCALE_C).asinh(),
        ]
    }
}

/// The result of [`SimulatedParticipant::calibrate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseCalibration {
    /// The noise scale found (perceived units).
    pub noise_sd: f64,
    /// The identification rate of real contact at that scale, on the calibration sample.
    pub rate: f64,
    /// The rate with almost no noise (the ceiling set by indistinguishable options).
    pub highest_rate: f64,
}

/// The simulated participant (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct SimulatedParticipant {
    options: Vec<String>,
    references: Vec<CurveFeatures>,
    perceived: Vec<[f64; 2]>,
    noise_sd: f64,
    seed: u64,
}

impl SimulatedParticipant {
    /// An simulated whose references are the given features, one per option, without noise until
    /// [`calibrate`](Self::calibrate) or [`set_noise_sd`](Self::set_noise_sd); `seed` seeds the per-trial noise.
    pub fn new(options: Vec<String>, references: Vec<CurveFeatures>, seed: u64) -> SimulatedParticipant {
        let perceived = references.iter().map(CurveFeatures::perceived).collect();
        SimulatedParticipant {
            options,
            references,
            perceived,
            noise_sd: 0.0,
            seed,
        }
    }

    /// An simulated whose references are real contact with each option (library names) under `contact` for
    /// `presentation_s` seconds.
    pub fn from_model(
        options: &[String],
        contact: &FvContact,
        presentation_s: f64,
        seed: u64,
    ) -> Result<SimulatedParticipant, ParticipantError> {
        let mut references = Vec::with_capacity(options.len());
        for name in options {
            let material = find(name)?;
            let curve = contact
                .curve(&material, None, presentation_s)
                .map_err(StimulusError::from)?;
            references.push(CurveFeatures::of(&curve)?);
        }
        Ok(SimulatedParticipant::new(options.to_vec(), references, seed))
    }

    /// The response options, in key order.
    pub fn options(&self) -> &[String] {
        &self.options
    }

    /// The reference features, one per option.
    pub fn references(&self) -> &[CurveFeatures] {
        &self.references
    }

    /// The noise scale in use (perceived units).
    pub fn noise_sd(&self) -> f64 {
        self.noise_sd
    }

    /// Sets the noise scale (finite, ≥ 0).
    pub fn set_noise_sd(&mut self, noise_sd: f64) -> Result<(), ParticipantError> {
        Rule::NonNegative.check("noise_sd", noise_sd)?;
        self.noise_sd = noise_sd;
        Ok(())
    }

    /// The option (0-based) whose reference is nearest to `features` after adding noise drawn from `rng`. Ties go to
    /// the first option.
    pub fn identify(&self, features: &CurveFeatures, rng: &mut impl Rng) -> usize {
        let p = features.perceived();
        let noisy = [
            p[0] + self.noise_sd * standard_normal(rng),
            p[1] + self.noise_sd * standard_normal(rng),
        ];
        self.nearest(noisy)
    }

    /// The answer to trial `trial` of participant `participant_index`, with the noise of that trial's own stream.
    pub fn identify_trial(
        &self,
        curve: &SkinCurve,
        participant_index: usize,
        trial: usize,
    ) -> Result<usize, ParticipantError> {
        let features = CurveFeatures::of(curve)?;
        let mut rng = trial_rng(self.seed ^ OBSERVER_SALT, participant_index, trial);
        Ok(self.identify(&features, &mut rng))
    }

    fn nearest(&self, point: [f64; 2]) -> usize {
        let distance = |r: &[f64; 2]| (r[0] - point[0]).powi(2) + (r[1] - point[1]).powi(2);
        let mut best = 0;
        for (i, r) in self.perceived.iter().enumerate() {
            if distance(r) < distance(&self.perceived[best]) {
                best = i;
            }
        }
        best
    }

    /// The rate at which the references themselves (real contact) are identified with noise `noise_sd`, over the
    /// fixed noise sample `draws` (one list of standard normal pairs per option).
    fn rate_with(&self, noise_sd: f64, draws: &[Vec<[f64; 2]>]) -> f64 {
        let mut correct = 0usize;
        let mut total = 0usize;
        for (i, (p, zs)) in self.perceived.iter().zip(draws).enumerate() {
            for z in zs {
                let point = [p[0] + noise_sd * z[0], p[1] + noise_sd * z[1]];
                correct += usize::from(self.nearest(point) == i);
                total += 1;
            }
        }
        correct as f64 / total.max(1) as f64
    }

    /// Finds and sets the noise scale at which real contact (the references) is identified at `target_rate`, on
    /// `samples_per_option` seeded noise draws per option: bisection between a scale whose rate is at least the
    /// target and one whose rate is below it, 60 halvings. Deterministic for a given seed.
    pub fn calibrate(
        &mut self,
        target_rate: f64,
        samples_per_option: usize,
        seed: u64,
    ) -> Result<NoiseCalibration, ParticipantError> {
        Rule::Between { min: 0.0, max: 1.0 }.check("target_rate", target_rate)?;
        Rule::AtLeast { min: 1.0 }.check("samples_per_option", samples_per_option as f64)?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let draws: Vec<Vec<[f64; 2]>> = (0..self.options.len())
            .map(|_| {
                (0..samples_per_option)
                    .map(|_| [standard_normal(&mut rng), standard_normal(&mut rng)])
                    .collect()
            })
            .collect();
        let (mut lo, mut hi) = (1e-9, 1e-2);
        let highest_rate = self.rate_with(lo, &draws);
        let unreachable = |lowest: f64| ParticipantError::Unreachable {
            target: target_rate,
            highest: highest_rate,
            lowest,
        };
        if highest_rate < target_rate {
            return Err(unreachable(highest_rate));
        }
        while self.rate_with(hi, &draws) >= target_rate {
            if hi > 1e3 {
                return Err(unreachable(self.rate_with(hi, &draws)));
            }
            lo = hi;
            hi *= 2.0;
        }
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if self.rate_with(mid, &draws) >= target_rate {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        self.noise_sd = lo;
        Ok(NoiseCalibration {
            noise_sd: lo,
            rate: self.rate_with(lo, &draws),
            highest_rate,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn linear_curve(rate_c_per_s: f64, duration_s: f64) -> SkinCurve {
        let time_s: Vec<f64> = (0..=(duration_s * 10.0) as usize).map(|i| i as f64 * 0.1).collect();
        let skin_c = time_s.iter().map(|t| 32.0 - rate_c_per_s * t).collect();
        SkinCurve { time_s, skin_c }
    }

    #[test]
    fn features_of_a_linear_curve_are_its_slope_and_total_drop() {
        let f = CurveFeatures::of(&linear_curve(0.25, 30.0)).expect("valid curve");
        assert!(
            (f.initial_cooling_rate_c_per_s - 0.25).abs() < 1e-12,
            "rate {}",
            f.initial_cooling_rate_c_per_s
        );
        assert!((f.end_drop_c - 7.5).abs() < 1e-9, "drop {}", f.end_drop_c);
        let p = f.perceived();
        assert!(
            (p[0] - 2.5f64.asinh()).abs() < 1e-12 && (p[1] - 75f64.asinh()).abs() < 1e-9,
            "{p:?}"
        );
    }

    #[test]
    fn short_curves_are_refused() {
        assert!(matches!(
            CurveFeatures::of(&linear_curve(0.25, 1.0)),
            Err(ParticipantError::ShortCurve { .. })
        ));
    }

    #[test]
    fn standard_normals_have_unit_moments() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let n = 200_000;
        let xs: Vec<f64> = (0..n).map(|_| standard_normal(&mut rng)).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        // Standard errors: 1/√n ≈ 0.0022 for the mean, √(2/n) ≈ 0.0032 for the variance; 5 σ bounds.
        assert!(mean.abs() < 0.011, "mean {mean} vs 0");
        assert!((var - 1.0).abs() < 0.016, "variance {var} vs 1");
        let within_one = xs.iter().filter(|x| x.abs() < 1.0).count() as f64 / n as f64;
        assert!(
            (within_one - 0.682_689).abs() < 0.006,
            "P(|z|<1) {within_one} vs 0.6827"
        );
    }

    #[test]
    fn trial_streams_differ_and_repeat() {
        let a: f64 = trial_rng(1, 0, 1).gen();
        let b: f64 = trial_rng(1, 0, 2).gen();
        let c: f64 = trial_rng(1, 1, 1).gen();
        assert_ne!(a, b);
        assert_ne!(a, c);
        assert_eq!(a, trial_rng(1, 0, 1).gen::<f64>());
    }

    #[test]
    fn two_well_separated_options_follow_the_normal_law() {
        // Two references 2d apart on the first perceived axis: with noise σ the correct rate is Φ(d/σ).
        let f = |rate: f64| CurveFeatures {
            initial_cooling_rate_c_per_s: RATE_SCALE_C_PER_S * rate.sinh(),
            end_drop_c: DROP_SCALE_C * 3f64.sinh(),
        };
        let mut simulated = SimulatedParticipant::new(vec!["a".into(), "b".into()], vec![f(2.0), f(2.4)], 9);
        simulated.set_noise_sd(0.2).expect("valid");
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let n = 40_000;
        let correct = (0..n).filter(|_| simulated.identify(&f(2.0), &mut rng) == 0).count();
        let rate = correct as f64 / n as f64;
        // Φ(0.2 / 0.2) = Φ(1) = 0.841345; standard error 0.0018.
        assert!((rate - 0.841_345).abs() < 0.01, "rate {rate} vs Φ(1) = 0.8413");
        let calibration = simulated.calibrate(0.841_345, 20_000, 5).expect("reachable");
        assert!(
            (calibration.noise_sd - 0.2).abs() < 0.01,
            "σ {} vs 0.2",
            calibration.noise_sd
        );
        assert!(matches!(
            simulated.calibrate(0.4, 100, 5),
            Err(ParticipantError::Unreachable { .. })
        ));
        assert!(simulated.calibrate(1.5, 100, 5).is_err());
        assert!(simulated.set_noise_sd(f64::NAN).is_err());
    }
}
