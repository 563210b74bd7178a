//! The perceptual simulated participant (issue 28): sensory noise from discrimination data, a separate categorical
//! stage, response bias, per-person contact conductance, finger temperature varying between trials and a
//! non-thermal cue in real trials. docs/lab.md ("The simulated participant") gives each parameter's source.
//!
//! **Sensory stage.** The two thermal cues of [`CurveFeatures`] (initial cooling rate, end drop) are scaled by the
//! trial's physical factors — the finger's temperature, drawn per trial around rest (the heat extracted is
//! proportional to the finger–object difference), and the person's contact conductance, drawn once per person
//! (it limits the heat flux most for high-effusivity materials) — then perceived on the Weber-like
//! `asinh(x / x₀)` scale ([`CurveFeatures::perceived`]) with Gaussian noise `sensory_sd` on each cue.
//! `sensory_sd` follows from the 2AFC Weber fraction W of heat-extraction rate (Bergmann Tiest & Kappers 2009):
//! a change by the factor 1 + W shifts both perceived cues by ln(1 + W), and a 2AFC observer summing them is 75 %
//! correct when ln(1 + W) / σ = Φ⁻¹(0.75), so σ = ln(1 + W) / 0.6745 ([`sensory_sd_for`]).
//!
//! **Categorical stage.** Each person holds a prototype per response option: the perceived cues of real contact with
//! it (the references), plus memory noise drawn once per person (standard deviation `memory_noise_ratio ×
//! sensory_sd` per cue). The thermal answer maximises `−‖ψ − p_k‖² / (2 σ_c²) + b_k` with σ_c² the sum of the
//! sensory and memory variances and `b_k` the response bias of option k.
//!
//! **Non-thermal channel.** In real trials only, a separate categorical channel: with probability `π_k` (the
//! non-thermal recognition of the presented material k: texture, compliance, sound — any signature a real sample
//! has and a display's plate lacks) the person recognises the material by it and answers k; otherwise the thermal
//! stage answers. The channel carries no prior of its own into the thermal decision, so a material that is easy to
//! recognise by touch in real trials is not favoured in simulated ones (a bias fitted to the real rates would be).
//!
//! **Randomness.** Each person's draws come from ChaCha8 stream `(participant, 0)` and each trial's from
//! `(participant, trial)` of the seed ([`trial_rng`]), so a resumed session gives the same answers.

use rand::Rng;
use serde::Deserialize;
use std::collections::BTreeMap;
use thermode_model::materials::find;

use crate::design::Condition;
use crate::participant::{CurveFeatures, ParticipantError};
use crate::random::{standard_normal, trial_rng};

/// The fitted parameters shipped with thermode (written by the `fit_participant` example).
pub const FITTED_TOML: &str = include_str!("../data/participant_fit.toml");
/// Φ⁻¹(0.75): the 2AFC criterion of a threshold at 75 % correct.
pub const Z_75: f64 = 0.674_489_750_196_081_7;
/// Channel capacity of absolute identification along one perceptual continuum \[bits\]: about 2.5 bits ("the span
/// of absolute judgment", about seven categories) once the stimulus range is wide, for loudness, pitch, taste and
/// cutaneous intensity alike (Miller, Psychological Review 63:81, 1956).
pub const IDENTIFICATION_CAPACITY_BITS: f64 = 2.5;
/// Seed salt of the perceptual participant's streams.
const PERCEPTION_SALT: u64 = 0x7065_7263_6570_0028;
/// Window of the heat-flux cue used for the contact-conductance factor \[s\] (the initial cooling-rate window).
const CUE_WINDOW_S: f64 = 2.0;

/// The model's parameters (the TOML file [`FITTED_TOML`]; docs/lab.md lists the sources).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PerceptionParams {
    /// When the fit was run (UTC date), or `unfitted`.
    pub fitted_on: String,
    /// The data the fit used.
    pub inputs: String,
    /// 2AFC Weber fraction of heat-extraction rate (Bergmann Tiest & Kappers 2009: 0.43).
    pub weber_fraction: f64,
    /// Memory noise of the prototypes relative to the sensory noise (dimensionless, per cue): the context-coding
    /// noise of a set spanning the references' perceived range at the channel capacity of absolute identification
    /// ([`memory_noise_sd_for`], [`IDENTIFICATION_CAPACITY_BITS`]) over `sensory_sd`, written by the fit (before:
    /// 1, assumed).
    pub memory_noise_ratio: f64,
    /// Probability π_k that the non-thermal channel recognises option k in a real trial, per option name (fitted;
    /// missing options: 0 = no non-thermal cue).
    pub non_thermal_recognition: BTreeMap<String, f64>,
    /// Finger–object temperature difference at rest \[°C\] (default 9: a 32 °C finger on 23 °C samples).
    pub finger_object_difference_c: f64,
    /// Standard deviation of the finger temperature between trials \[°C\] (assumed 0.5).
    pub finger_temperature_sd_c: f64,
    /// Median contact conductance of finger and object \[W/(m²·K)\] (assumed 3000).
    pub contact_conductance_w_m2k: f64,
    /// Standard deviation of ln(contact conductance) between persons (assumed 0.4).
    pub contact_conductance_log_sd: f64,
    /// Effusivity of the skin \[W·s^½/(m²·K)\] (k 0.37 W/(m·K), ρc 3.5 MJ/(m³·K): 1138).
    pub skin_effusivity: f64,
    /// Response bias per option name (added to the option's decision score; missing options: 0).
    pub bias: BTreeMap<String, f64>,
}

impl PerceptionParams {
    /// The shipped fitted parameters.
    pub fn fitted() -> PerceptionParams {
        toml::from_str(FITTED_TOML).expect("the shipped participant_fit.toml parses (a unit test checks it)")
    }

    /// Reads parameters from TOML text.
    pub fn from_toml(text: &str) -> Result<PerceptionParams, toml::de::Error> {
        toml::from_str(text)
    }

    /// The parameters as the TOML of `participant_fit.toml`.
    pub fn to_toml(&self) -> String {
        let table = |m: &BTreeMap<String, f64>| {
            m.iter()
                .map(|(k, v)| format!("{k} = {v:.4}"))
                .collect::<Vec<String>>()
                .join(", ")
        };
        format!(
            "# The perceptual simulated participant's parameters (crates/thermode-lab/src/perception.rs, docs/lab.md).\n\
             # Written by: cargo run --release -p thermode-lab --example fit_participant -- --write\n\
             fitted_on = \"{}\"\ninputs = \"{}\"\nweber_fraction = {}\nmemory_noise_ratio = {}\n\
             non_thermal_recognition = {{ {} }}\nfinger_object_difference_c = {}\nfinger_temperature_sd_c = {}\n\
             contact_conductance_w_m2k = {}\ncontact_conductance_log_sd = {}\nskin_effusivity = {}\n\
             bias = {{ {} }}\n",
            self.fitted_on,
            self.inputs,
            self.weber_fraction,
            self.memory_noise_ratio,
            table(&self.non_thermal_recognition),
            self.finger_object_difference_c,
            self.finger_temperature_sd_c,
            self.contact_conductance_w_m2k,
            self.contact_conductance_log_sd,
            self.skin_effusivity,
            table(&self.bias)
        )
    }

    /// The non-thermal recognition probabilities as `name π` pairs, e.g. `aluminium 0.12, wood 0.93`.
    pub fn recognition_summary(&self) -> String {
        self.non_thermal_recognition
            .iter()
            .map(|(name, p)| format!("{name} {p:.2}"))
            .collect::<Vec<String>>()
            .join(", ")
    }

    /// The sensory noise per perceived cue implied by the Weber fraction ([`sensory_sd_for`]).
    pub fn sensory_sd(&self) -> f64 {
        sensory_sd_for(self.weber_fraction)
    }
}

/// The sensory noise σ per perceived cue at which a 2AFC observer summing both cues is 75 % correct for a change of
/// heat-extraction rate by the factor `1 + weber_fraction`: ln(1 + W) / Φ⁻¹(0.75).
pub fn sensory_sd_for(weber_fraction: f64) -> f64 {
    (1.0 + weber_fraction).ln() / Z_75
}

/// The memory (context-coding) noise \[perceived units\] of a set of prototypes spanning `range` perceived units, for an
/// identification channel capacity of `capacity_bits`. Durlach & Braida's (1969) two-noise account of absolute
/// identification (as Nosofsky, J Exp Psychol Hum Percept Perform 9:299, 1983, states it): a response's variance is
/// sensory noise, which does not depend on the range, plus criterial (memory) noise, which grows with it; once the
/// range is wide the memory noise dominates and identification transmits the capacity C whatever the range, so the
/// memory noise is proportional to the range. A uniform input over `range` through Gaussian noise of standard
/// deviation σ transmits log₂(range / σ) − ½ log₂(2πe) bits when range ≫ σ (the output's entropy is the input's
/// plus nothing, the noise's is log₂(σ√(2πe))), so σ_m = range / (2^C √(2πe)): range / 23.4 at 2.5 bits (the
/// wide-range asymptote: at that σ the exact uniform-input channel transmits 2.61 bits, the edges of the range adding
/// 0.11; a σ 9 % larger transmits exactly 2.5).
pub fn memory_noise_sd_for(range: f64, capacity_bits: f64) -> f64 {
    range / (2f64.powf(capacity_bits) * (2.0 * std::f64::consts::PI * std::f64::consts::E).sqrt())
}

/// The extent of a set of references on the perceived scale \[perceived units\]: the largest Euclidean distance
/// between two references' perceived cue pairs (the two cues rise together with effusivity, so the set lies near one
/// line and this is its length).
pub fn perceived_range(references: &[CurveFeatures]) -> f64 {
    let points: Vec<[f64; 2]> = references.iter().map(CurveFeatures::perceived).collect();
    let mut range = 0.0f64;
    for (i, a) in points.iter().enumerate() {
        for b in &points[i + 1..] {
            range = range.max((a[0] - b[0]).hypot(a[1] - b[1]));
        }
    }
    range
}

/// The fraction of the perfect-contact heat flux that passes a contact of conductance `h_w_m2k` between skin and a
/// material, over the cue window: the bodies' resistance `2√(t/π)(1/e_skin + 1/e_material)` (constant flux into
/// two semi-infinite bodies) in series with `1/h`.
pub fn contact_factor(h_w_m2k: f64, skin_effusivity: f64, material_effusivity: f64) -> f64 {
    let bodies =
        2.0 * (CUE_WINDOW_S / std::f64::consts::PI).sqrt() * (1.0 / skin_effusivity + 1.0 / material_effusivity);
    bodies / (bodies + 1.0 / h_w_m2k)
}

/// One person's draws: prototypes (perceived, with memory noise) and contact conductance.
#[derive(Debug, Clone)]
struct Person {
    prototypes: Vec<[f64; 2]>,
    conductance_w_m2k: f64,
}

/// The perceptual simulated participant (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct PerceptualParticipant {
    options: Vec<String>,
    perceived: Vec<[f64; 2]>,
    effusivity: Vec<f64>,
    bias: Vec<f64>,
    recognition: Vec<f64>,
    params: PerceptionParams,
    seed: u64,
}

impl PerceptualParticipant {
    /// A participant for `options` (library names) whose prototypes are `references` (real contact with each
    /// option), with `params`; `seed` seeds every person's and trial's draws.
    pub fn new(
        options: Vec<String>,
        references: &[CurveFeatures],
        params: PerceptionParams,
        seed: u64,
    ) -> Result<PerceptualParticipant, ParticipantError> {
        let effusivity = options
            .iter()
            .map(|name| Ok(find(name)?.effusivity()))
            .collect::<Result<Vec<f64>, ParticipantError>>()?;
        Ok(PerceptualParticipant {
            perceived: references.iter().map(CurveFeatures::perceived).collect(),
            bias: per_option(&options, &params.bias),
            recognition: per_option(&options, &params.non_thermal_recognition),
            options,
            effusivity,
            params,
            seed,
        })
    }

    /// The response options.
    pub fn options(&self) -> &[String] {
        &self.options
    }

    /// The parameters in use.
    pub fn params(&self) -> &PerceptionParams {
        &self.params
    }

    fn person(&self, participant_index: usize) -> Person {
        let mut rng = trial_rng(self.seed ^ PERCEPTION_SALT, participant_index, 0);
        let p = &self.params;
        let conductance_w_m2k =
            p.contact_conductance_w_m2k * (p.contact_conductance_log_sd * standard_normal(&mut rng)).exp();
        let memory_sd = p.memory_noise_ratio * p.sensory_sd();
        let prototypes = self
            .perceived
            .iter()
            .map(|r| {
                [
                    r[0] + memory_sd * standard_normal(&mut rng),
                    r[1] + memory_sd * standard_normal(&mut rng),
                ]
            })
            .collect();
        Person {
            prototypes,
            conductance_w_m2k,
        }
    }

    /// The answer (0-based option) of participant `participant_index` to trial `trial` (≥ 1) presenting option
    /// `presented` whose skin curve has `features`, in `condition`.
    pub fn respond(
        &self,
        features: &CurveFeatures,
        presented: usize,
        condition: Condition,
        participant_index: usize,
        trial: usize,
    ) -> usize {
        let person = self.person(participant_index);
        let mut rng = trial_rng(self.seed ^ PERCEPTION_SALT, participant_index, trial.max(1));
        let percept = self.percept(
            features,
            self.surface_effusivity(presented, condition),
            &person,
            &mut rng,
        );
        let recognised = rng.gen::<f64>() < self.recognition.get(presented).copied().unwrap_or(0.0);
        if condition == Condition::Real && recognised {
            return presented;
        }
        self.thermal_answer(percept, &person)
    }

    /// The categorical stage on thermal evidence: the option maximising `−‖ψ − p_k‖² / (2 σ_c²) + b_k`.
    fn thermal_answer(&self, percept: [f64; 2], person: &Person) -> usize {
        let p = &self.params;
        let sensory = p.sensory_sd();
        let categorical_var = sensory * sensory * (1.0 + p.memory_noise_ratio * p.memory_noise_ratio);
        let mut best = (0, f64::NEG_INFINITY);
        for (k, proto) in person.prototypes.iter().enumerate() {
            let distance = (percept[0] - proto[0]).powi(2) + (percept[1] - proto[1]).powi(2);
            let score = -distance / (2.0 * categorical_var) + self.bias[k];
            if score > best.1 {
                best = (k, score);
            }
        }
        best.0
    }

    /// The effusivity of what the finger touches \[W·s^½/(m²·K)\]: the presented material in a real trial; in a
    /// simulated trial the display's temperature-controlled plate, which acts as a body of infinite effusivity (the
    /// person's contact conductance limits its flux as it limits a metal's, whatever material is rendered).
    fn surface_effusivity(&self, presented: usize, condition: Condition) -> f64 {
        match condition {
            Condition::Real => self.effusivity.get(presented).copied().unwrap_or(f64::INFINITY),
            Condition::Simulated => f64::INFINITY,
        }
    }

    /// The noisy perceived cues of one trial (`e` the effusivity of the touched surface).
    fn percept(&self, features: &CurveFeatures, e: f64, person: &Person, rng: &mut impl Rng) -> [f64; 2] {
        let p = &self.params;
        let finger = 1.0 + p.finger_temperature_sd_c * standard_normal(rng) / p.finger_object_difference_c;
        let contact = contact_factor(person.conductance_w_m2k, p.skin_effusivity, e)
            / contact_factor(p.contact_conductance_w_m2k, p.skin_effusivity, e);
        let scale = finger * contact;
        let scaled = CurveFeatures {
            initial_cooling_rate_c_per_s: features.initial_cooling_rate_c_per_s * scale,
            end_drop_c: features.end_drop_c * scale,
        };
        let q = scaled.perceived();
        let sd = p.sensory_sd();
        [q[0] + sd * standard_normal(rng), q[1] + sd * standard_normal(rng)]
    }

    /// Identification rates of real contact per option: `persons` persons, `repetitions` trials of each option each,
    /// the references as the presented curves (the fit's and the checks' common random numbers: the same seed gives
    /// the same draws).
    pub fn real_rates(&self, persons: usize, repetitions: usize) -> Vec<f64> {
        let references: Vec<CurveFeatures> = self.perceived.iter().map(|q| unperceive(*q)).collect();
        let n = self.options.len();
        let mut correct = vec![0usize; n];
        for person in 0..persons {
            for k in 0..n {
                for r in 0..repetitions {
                    let trial = 1 + r * n + k;
                    correct[k] += usize::from(self.respond(&references[k], k, Condition::Real, person, trial) == k);
                }
            }
        }
        correct
            .iter()
            .map(|&c| c as f64 / (persons * repetitions).max(1) as f64)
            .collect()
    }

    /// Proportion correct of a 2AFC "which is colder" between `a` and `b` (options `ia`, `ib`, `b` the colder)
    /// over `trials` trials of `persons` persons: each interval perceived with the sensory stage (finger temperature,
    /// the person's contact conductance, sensory noise), the answer the interval whose summed perceived cues are larger.
    pub fn two_afc_correct(
        &self,
        a: (&CurveFeatures, usize),
        b: (&CurveFeatures, usize),
        persons: usize,
        trials: usize,
    ) -> f64 {
        self.two_afc_correct_sites(a, b, 1, persons, trials)
    }

    /// [`Self::two_afc_correct`] with the colder material `b` touching `colder_sites` fingers (≥ 1) and `a` one.
    /// Summation rule: each finger is an independent channel (its own finger-temperature and sensory-noise draws, the
    /// person's contact conductance shared) and the interval's percept is the mean of its fingers' perceived cues —
    /// averaging of independent noisy channels, the ideal combination of equal channels, so the colder interval's
    /// noise variance falls by the number of fingers and its mean stays (no intensity summation is claimed).
    pub fn two_afc_correct_sites(
        &self,
        (a, ia): (&CurveFeatures, usize),
        (b, ib): (&CurveFeatures, usize),
        colder_sites: usize,
        persons: usize,
        trials: usize,
    ) -> f64 {
        let mut correct = 0usize;
        for person_index in 0..persons {
            let person = self.person(person_index);
            for trial in 1..=trials {
                let mut rng = trial_rng(self.seed ^ PERCEPTION_SALT, person_index, trial);
                let (ea, eb) = (self.effusivity[ia], self.effusivity[ib]);
                let pa = self.percept(a, ea, &person, &mut rng);
                let pb = self.percept(b, eb, &person, &mut rng);
                let mut colder = pb[0] + pb[1];
                for _ in 1..colder_sites {
                    let more = self.percept(b, eb, &person, &mut rng);
                    colder += more[0] + more[1];
                }
                correct += usize::from(colder / colder_sites.max(1) as f64 > pa[0] + pa[1]);
            }
        }
        correct as f64 / (persons * trials).max(1) as f64
    }

    /// A copy with other parameters (same options, references and seed).
    pub fn with_params(&self, params: PerceptionParams) -> PerceptualParticipant {
        PerceptualParticipant {
            bias: per_option(&self.options, &params.bias),
            recognition: per_option(&self.options, &params.non_thermal_recognition),
            params,
            ..self.clone()
        }
    }
}

/// The values of `table` for `options` in order (missing: 0).
fn per_option(options: &[String], table: &BTreeMap<String, f64>) -> Vec<f64> {
    options.iter().map(|o| table.get(o).copied().unwrap_or(0.0)).collect()
}

/// The features whose perceived values are `q` (the inverse of [`CurveFeatures::perceived`]).
fn unperceive(q: [f64; 2]) -> CurveFeatures {
    CurveFeatures {
        initial_cooling_rate_c_per_s: crate::participant::RATE_SCALE_C_PER_S * q[0].sinh(),
        end_drop_c: crate::participant::DROP_SCALE_C * q[1].sinh(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_parameters_parse_and_round_trip() {
        let p = PerceptionParams::fitted();
        assert_eq!(
            PerceptionParams::from_toml(&p.to_toml())
                .expect("round trip")
                .bias
                .len(),
            p.bias.len()
        );
    }

    /// The information a uniform input over `range` transmits through Gaussian noise `sigma` \[bits\], integrated
    /// numerically: I = h(Y) − log₂(σ√(2πe)) with Y's density (Φ(y/σ) − Φ((y − R)/σ)) / R.
    fn transmitted_bits(range: f64, sigma: f64) -> f64 {
        let phi = |x: f64| 0.5 * statrs::function::erf::erfc(-x / std::f64::consts::SQRT_2);
        let (lo, hi, n) = (-8.0 * sigma, range + 8.0 * sigma, 200_000);
        let dy = (hi - lo) / n as f64;
        let mut entropy_bits = 0.0;
        for i in 0..n {
            let y = lo + (i as f64 + 0.5) * dy;
            let p = (phi(y / sigma) - phi((y - range) / sigma)) / range;
            if p > 0.0 {
                entropy_bits -= p * p.log2() * dy;
            }
        }
        entropy_bits - (sigma * (2.0 * std::f64::consts::PI * std::f64::consts::E).sqrt()).log2()
    }

    /// The memory noise's closed form is the wide-range asymptote of the uniform-input Gaussian channel: at 8 bits the
    /// integrated information equals the capacity to 0.01 bit; at 2.5 bits the asymptote leaves out the edges of the
    /// range, which carry 0.11 bit more (2.61 bits: the exact channel would need a σ 9 % larger), and R/σ_m is
    /// 2^2.5 √(2πe) = 23.4.
    #[test]
    fn the_memory_noise_is_the_wide_range_asymptote_of_the_capacity() {
        let range = 2.0;
        let wide = memory_noise_sd_for(range, 8.0);
        let at_wide = transmitted_bits(range, wide);
        assert!(
            (at_wide - 8.0).abs() < 0.01,
            "σ_m = {wide:.6} transmits {at_wide:.4} bits, capacity 8"
        );
        let sigma = memory_noise_sd_for(range, IDENTIFICATION_CAPACITY_BITS);
        let edge_bits = transmitted_bits(range, sigma) - IDENTIFICATION_CAPACITY_BITS;
        assert!(
            (0.05..0.15).contains(&edge_bits),
            "σ_m = {sigma:.4} over {range}: the edges carry {edge_bits:.4} bits beyond the asymptote's capacity"
        );
        assert!(
            (range / sigma - 23.4).abs() < 0.1,
            "range / σ_m = {:.3}, expected 2^2.5 √(2πe) = 23.4",
            range / sigma
        );
    }

    /// The extent of three collinear references is the distance between the outer two.
    #[test]
    fn the_perceived_range_is_the_largest_distance() {
        let at = |q0: f64, q1: f64| CurveFeatures {
            initial_cooling_rate_c_per_s: crate::participant::RATE_SCALE_C_PER_S * q0.sinh(),
            end_drop_c: crate::participant::DROP_SCALE_C * q1.sinh(),
        };
        let range = perceived_range(&[at(1.0, 2.0), at(4.0, 6.0), at(2.5, 4.0)]);
        assert!(
            (range - 5.0).abs() < 1e-9,
            "range {range}, expected 5 (a 3-4-5 triangle)"
        );
    }

    /// A participant recognising every material by its non-thermal cue: real trials are always right, simulated
    /// trials answer exactly as a participant without the channel (the channel carries no prior into them).
    #[test]
    fn the_non_thermal_channel_acts_in_real_trials_only() {
        let options: Vec<String> = ["aluminium", "wood"].iter().map(|s| s.to_string()).collect();
        let features = [
            CurveFeatures {
                initial_cooling_rate_c_per_s: 4.0,
                end_drop_c: 7.0,
            },
            CurveFeatures {
                initial_cooling_rate_c_per_s: 1.4,
                end_drop_c: 2.5,
            },
        ];
        let mut without = PerceptionParams::fitted();
        without.non_thermal_recognition.clear();
        let mut with = without.clone();
        with.non_thermal_recognition = options.iter().map(|o| (o.clone(), 1.0)).collect();
        let p0 = PerceptualParticipant::new(options.clone(), &features, without, 4).expect("participant");
        let p1 = p0.with_params(with);
        // The stimulus halfway between the prototypes: the thermal stage errs often.
        let middle = CurveFeatures {
            initial_cooling_rate_c_per_s: 2.4,
            end_drop_c: 4.2,
        };
        let (mut real_wrong, mut differ) = (0, 0);
        for trial in 1..=400 {
            real_wrong += usize::from(p1.respond(&middle, 0, Condition::Real, trial % 7, trial) != 0);
            let a = p0.respond(&middle, 0, Condition::Simulated, trial % 7, trial);
            differ += usize::from(a != p1.respond(&middle, 0, Condition::Simulated, trial % 7, trial));
        }
        let thermal_wrong = (1..=400)
            .filter(|&t| p0.respond(&middle, 0, Condition::Real, t % 7, t) != 0)
            .count();
        assert_eq!(real_wrong, 0, "recognised real trials are all right");
        assert_eq!(differ, 0, "simulated trials unchanged by the channel");
        assert!(
            thermal_wrong > 40,
            "the thermal stage alone errs: {thermal_wrong} of 400"
        );
    }

    #[test]
    fn the_sensory_noise_of_a_43_percent_weber_fraction() {
        // ln(1.43) / 0.674490 = 0.357674 / 0.674490 = 0.530289.
        assert!(
            (sensory_sd_for(0.43) - 0.530_289).abs() < 1e-5,
            "{}",
            sensory_sd_for(0.43)
        );
    }

    #[test]
    fn contact_conductance_limits_metals_more_than_wood() {
        // Aluminium e ≈ 2.4e4, wood e ≈ 4e2 W·s^½/(m²·K): halving h loses more of the metal's flux.
        let metal = contact_factor(1500.0, 1138.0, 2.4e4) / contact_factor(3000.0, 1138.0, 2.4e4);
        let wood = contact_factor(1500.0, 1138.0, 4e2) / contact_factor(3000.0, 1138.0, 4e2);
        assert!(metal < wood && metal < 0.9 && wood > 0.9, "metal {metal} wood {wood}");
        assert!((contact_factor(1e12, 1138.0, 4e2) - 1.0).abs() < 1e-6);
    }
}
