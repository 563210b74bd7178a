//! The simulated participant of the procedures (`[simulated_participant]`): the three-layer skin model
//! (`thermode_model::kron`) rests on the plate, driven by a prescribed plate temperature, and the participant detects
//! a change of its receptor (epidermis) temperature from where the trial started.
//!
//! Per trial the participant draws its criterion `threshold_c + noise_c · N(0, 1)` (at least 0) and, with
//! probability `lapse`, lapses: in a yes/no trial it then answers at random (yes or no, even odds); in a ramp of the
//! method of limits it misses the stimulus, so the ramp runs to the cut-off. Otherwise it detects at the first tick
//! its receptor has moved by the criterion in the ramp's direction and presses `reaction_time_s` later (limits), or
//! answers "yes" if that happened before the end of the trial's answer window (yes/no). Pain (CPT, HPT) is felt when
//! the receptor temperature itself crosses `cold_pain_c` or `heat_pain_c`.
//!
//! Between trials that return to the baseline the participant re-adapts (its skin settles to the steady state on
//! the plate at the next baseline: the inter-stimulus interval is taken as long enough); between the ramps of a
//! thermal sensory limen it does not.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use thermode_model::inverse::DEFAULT_DISPLAY_CONDUCTANCE_W_M2K;
use thermode_model::params::Rule;
use thermode_model::{KronEnvironment, KronModel, Skin};

use crate::plan::{Procedure, Response, TrialPlan};
use crate::skin_response::ANSWER_WINDOW_S;
use crate::ProcedureError;

/// The `[simulated_participant]` table of an experiment file.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ParticipantConfig {
    /// The change of the receptor (skin) temperature from the trial's start that the participant detects \[°C\],
    /// a magnitude, the same for cooling and warming. Default 0.5.
    pub threshold_c: f64,
    /// From detection to the press \[s\]. Default 0.4.
    pub reaction_time_s: f64,
    /// Standard deviation of the per-trial criterion around `threshold_c` \[°C\]. Default 0.05.
    pub noise_c: f64,
    /// Probability that a trial is a lapse (a random yes/no answer, or a missed ramp), 0–1. Default 0.
    pub lapse: f64,
    /// Receptor (epidermis) temperature felt as cold pain \[°C\]. Default 18 (a CPT near 12 °C at 1 °C/s).
    pub cold_pain_c: f64,
    /// Receptor (epidermis) temperature felt as heat pain \[°C\]. Default 41 (an HPT near 46 °C at 1 °C/s).
    pub heat_pain_c: f64,
    /// Finger–plate contact conductance [W/(m²·K)]. Default 800 (`thermode_model`'s display default).
    pub contact_conductance_w_m2k: f64,
}

impl Default for ParticipantConfig {
    fn default() -> Self {
        ParticipantConfig {
            threshold_c: 0.5,
            reaction_time_s: 0.4,
            noise_c: 0.05,
            lapse: 0.0,
            cold_pain_c: 18.0,
            heat_pain_c: 41.0,
            contact_conductance_w_m2k: DEFAULT_DISPLAY_CONDUCTANCE_W_M2K,
        }
    }
}

impl ParticipantConfig {
    /// Checks every value's range (key names as in the experiment file).
    pub fn validate(&self) -> Result<(), ProcedureError> {
        Rule::PositiveUpTo { max: 30.0 }.check("simulated_participant.threshold_c", self.threshold_c)?;
        Rule::Within { min: 0.0, max: 10.0 }.check("simulated_participant.reaction_time_s", self.reaction_time_s)?;
        Rule::Within { min: 0.0, max: 10.0 }.check("simulated_participant.noise_c", self.noise_c)?;
        Rule::Within { min: 0.0, max: 1.0 }.check("simulated_participant.lapse", self.lapse)?;
        Rule::Within { min: -10.0, max: 40.0 }.check("simulated_participant.cold_pain_c", self.cold_pain_c)?;
        Rule::Within { min: 30.0, max: 60.0 }.check("simulated_participant.heat_pain_c", self.heat_pain_c)?;
        Rule::PositiveUpTo { max: 1e6 }.check(
            "simulated_participant.contact_conductance_w_m2k",
            self.contact_conductance_w_m2k,
        )?;
        Ok(())
    }
}

/// What the participant watches for in one trial.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Criterion {
    /// A change of the receptor by the (noisy) threshold in the direction of `sign` (−1 cooling, +1 warming).
    Change {
        /// −1 for a cooling stimulus, +1 for a warming one.
        sign: f64,
    },
    /// The receptor below `cold_pain_c` (`sign` −1) or above `heat_pain_c` (`sign` +1).
    Pain {
        /// −1 for cold pain, +1 for heat pain.
        sign: f64,
    },
}

/// The simulated participant: its skin on the plate, its random stream and the current trial's state.
#[derive(Debug, Clone)]
pub struct SimulatedParticipant {
    config: ParticipantConfig,
    model: KronModel,
    rng: ChaCha8Rng,
    trial: TrialState,
}

#[derive(Debug, Clone, Copy, Default)]
struct TrialState {
    start_receptor_c: f64,
    criterion_c: f64,
    criterion: Option<Criterion>,
    lapsed: bool,
    elapsed_s: f64,
    detected_at_s: Option<f64>,
}

/// A standard normal draw (Box–Muller).
fn standard_normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = 1.0 - rng.gen::<f64>();
    let u2: f64 = rng.gen::<f64>();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

impl SimulatedParticipant {
    /// A participant with the default fingertip skin, seeded with `seed` (ChaCha8).
    pub fn new(config: ParticipantConfig, seed: u64) -> Result<Self, ProcedureError> {
        config.validate()?;
        let model = KronModel::new(&Skin::fingertip()).map_err(|e| ProcedureError::Skin(e.to_string()))?;
        Ok(SimulatedParticipant {
            config,
            model,
            rng: ChaCha8Rng::seed_from_u64(seed),
            trial: TrialState::default(),
        })
    }

    /// The participant's configuration.
    pub fn config(&self) -> &ParticipantConfig {
        &self.config
    }

    fn plate(&self, plate_c: f64) -> KronEnvironment {
        KronEnvironment::Plate {
            conductance_w_m2k: self.config.contact_conductance_w_m2k,
            temperature_c: plate_c,
        }
    }

    /// The skin settles to its steady state on the plate at `plate_c` \[°C\] (adaptation).
    pub fn adapt(&mut self, plate_c: f64) {
        let env = self.plate(plate_c);
        self.model.settle(&env);
    }

    /// The receptor (epidermis) temperature now \[°C\].
    pub fn receptor_c(&self) -> f64 {
        self.model.temperatures_c()[0]
    }

    /// Starts a trial watching for `criterion`: draws the criterion's noise and the lapse.
    pub fn begin_trial(&mut self, criterion: Criterion) {
        let noise = standard_normal(&mut self.rng);
        let lapsed = self.rng.gen::<f64>() < self.config.lapse;
        self.trial = TrialState {
            start_receptor_c: self.receptor_c(),
            criterion_c: (self.config.threshold_c + self.config.noise_c * noise).max(0.0),
            criterion: Some(criterion),
            lapsed,
            elapsed_s: 0.0,
            detected_at_s: None,
        };
    }

    /// Advances the skin by `dt_s` \[s\] with the plate at `plate_c` \[°C\] (the end of the step) and returns `true` on
    /// the tick the participant presses (reaction time after the detection; never in a lapsed trial).
    pub fn observe(&mut self, dt_s: f64, plate_c: f64) -> bool {
        let env = self.plate(plate_c);
        self.model.step(dt_s, &env);
        self.trial.elapsed_s += dt_s;
        if self.trial.detected_at_s.is_none() && self.felt() {
            self.trial.detected_at_s = Some(self.trial.elapsed_s);
        }
        match self.trial.detected_at_s {
            Some(at) if !self.trial.lapsed => self.trial.elapsed_s - at >= self.config.reaction_time_s - 1e-9,
            _ => false,
        }
    }

    fn felt(&self) -> bool {
        let receptor = self.receptor_c();
        match self.trial.criterion {
            Some(Criterion::Change { sign }) => {
                sign * (receptor - self.trial.start_receptor_c) >= self.trial.criterion_c
            }
            Some(Criterion::Pain { sign }) if sign < 0.0 => receptor <= self.config.cold_pain_c,
            Some(Criterion::Pain { .. }) => receptor >= self.config.heat_pain_c,
            None => false,
        }
    }

    /// The yes/no answer at the end of a trial: whether the criterion was met, or a coin flip in a lapsed trial.
    pub fn answer(&mut self) -> bool {
        if self.trial.lapsed {
            self.rng.gen::<bool>()
        } else {
            self.trial.detected_at_s.is_some()
        }
    }

    /// Runs `plan` with the plate following its set-points exactly (a prescribed plate temperature), stepping the
    /// skin every `dt_s` \[s\], and gives the response the procedure records. A ramp `until_response` stops at the
    /// press (the delivered temperature is the plate on that tick) or at its target (the cut-off, not detected); a
    /// trapezoid is answered yes/no after [`ANSWER_WINDOW_S`] past its return, delivered at its plateau.
    ///
    /// The participant watches for pain when `plan.pain`, else for a change in the ramp's direction; it re-adapts to
    /// the baseline first unless `plan.continues_previous`.
    pub fn run_trial(&mut self, plan: &TrialPlan, dt_s: f64) -> Response {
        let sign = plan.intensity_c.signum();
        let criterion = if plan.pain {
            Criterion::Pain { sign }
        } else {
            Criterion::Change { sign }
        };
        if !plan.continues_previous {
            self.adapt(plan.baseline_c);
        }
        if plan.until_response {
            self.run_ramp(plan, criterion, dt_s)
        } else {
            self.run_trapezoid(plan, criterion, dt_s)
        }
    }

    fn run_ramp(&mut self, plan: &TrialPlan, criterion: Criterion, dt_s: f64) -> Response {
        self.begin_trial(criterion);
        let sign = plan.intensity_c.signum();
        let steps = (plan.intensity_c.abs() / plan.rate_c_per_s / dt_s).ceil() as u64;
        for k in 1..=steps {
            let change = (plan.rate_c_per_s * k as f64 * dt_s).min(plan.intensity_c.abs());
            let plate_c = plan.baseline_c + sign * change;
            if self.observe(dt_s, plate_c) {
                return Response::yes_no(true, plate_c);
            }
        }
        Response::yes_no(false, plan.target_c())
    }

    fn run_trapezoid(&mut self, plan: &TrialPlan, criterion: Criterion, dt_s: f64) -> Response {
        self.begin_trial(criterion);
        let amplitude = plan.intensity_c.abs();
        let sign = plan.intensity_c.signum();
        let t1 = amplitude / plan.rate_c_per_s;
        let t2 = t1 + plan.plateau_s;
        let t3 = t2 + amplitude / plan.return_rate_c_per_s;
        let steps = ((t3 + ANSWER_WINDOW_S) / dt_s).ceil() as u64;
        for k in 1..=steps {
            let t = k as f64 * dt_s;
            let change = if t < t1 {
                plan.rate_c_per_s * t
            } else if t < t2 {
                amplitude
            } else {
                (amplitude - plan.return_rate_c_per_s * (t - t2)).max(0.0)
            };
            self.observe(dt_s, plan.baseline_c + sign * change);
        }
        let yes = self.answer();
        Response::yes_no(yes, plan.target_c())
    }
}

/// One trial of a simulated session: what was asked and what was answered.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrialRecord {
    /// The trial's plan.
    pub plan: TrialPlan,
    /// The participant's response.
    pub response: Response,
}

/// Runs `procedure` to its end with `participant` answering every trial ([`SimulatedParticipant::run_trial`], its
/// skin stepped every `dt_s` \[s\]) and returns the trials in order.
pub fn run_simulated(
    procedure: &mut dyn Procedure,
    participant: &mut SimulatedParticipant,
    dt_s: f64,
) -> Result<Vec<TrialRecord>, ProcedureError> {
    let mut records = Vec::new();
    while let Some(plan) = procedure.next_trial() {
        let response = participant.run_trial(&plan, dt_s);
        procedure.record(response)?;
        records.push(TrialRecord { plan, response });
    }
    Ok(records)
}
