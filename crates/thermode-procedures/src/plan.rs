//! One trial as a small plan (baseline, target, rate, plateau, return, inter-stimulus interval), the response a
//! procedure records for it, and the program segments the plan becomes on a display's loop.

use serde::{Deserialize, Serialize};
use thermode_model::params::Rule;

/// What a ramp's rate in an experiment file must be \[°C/s\]: above 0, at most 300 (the display's own, lower limit
/// is checked when the file is planned or run on it).
pub const RAMP_RATE: Rule = Rule::PositiveUpTo { max: 300.0 };

/// Which way a stimulus changes the plate from its baseline.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Direction {
    /// The plate cools below the baseline.
    Cold,
    /// The plate warms above the baseline.
    Warm,
}

impl Direction {
    /// −1 for cold, +1 for warm: the sign of a change from the baseline.
    pub fn sign(self) -> f64 {
        match self {
            Direction::Cold => -1.0,
            Direction::Warm => 1.0,
        }
    }

    /// The other direction.
    pub fn opposite(self) -> Direction {
        match self {
            Direction::Cold => Direction::Warm,
            Direction::Warm => Direction::Cold,
        }
    }
}

/// One segment of a channel's program, as the loop's `program` request takes it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged, deny_unknown_fields)]
pub enum Segment {
    /// A ramp of the set-point to `to_c` \[°C\] at `rate_c_s` \[°C/s\]; with `until = "response"` a response ends it.
    Ramp {
        /// Target set-point \[°C\].
        to_c: f64,
        /// Rate \[°C/s\], positive.
        #[serde(rename = "rate_c_s")]
        rate_c_per_s: f64,
        /// `Some(Until::Response)`: a response on the channel ends the ramp early.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        until: Option<Until>,
    },
    /// A hold of the current set-point for `hold_s` \[s\]; with `until = "response"` a response ends it.
    Hold {
        /// Duration \[s\].
        hold_s: f64,
        /// `Some(Until::Response)`: a response on the channel ends the hold early.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        until: Option<Until>,
    },
    /// A step to `to_c` \[°C\] as fast as the safety envelope allows.
    Step {
        /// Target set-point \[°C\].
        to_c: f64,
    },
}

/// What ends a segment early.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Until {
    /// A response (button) on the segment's channel.
    Response,
}

/// One trial of a single-channel procedure: what to present, as the procedure asks for it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrialPlan {
    /// 0-based index of the trial in the session.
    pub index: usize,
    /// What the trial measures, e.g. `CDT`, `TSL`, `levels`, `staircase`, `questplus`.
    pub label: String,
    /// 1-based run (repetition) of `label`.
    pub run: usize,
    /// The plate temperature the stimulus starts from \[°C\].
    pub baseline_c: f64,
    /// The requested intensity: the change of the plate from the baseline \[°C\], signed (cold negative). For the
    /// method of limits it is the change to the cut-off, where the ramp ends if nobody responds.
    pub intensity_c: f64,
    /// The ramp's rate \[°C/s\].
    #[serde(rename = "rate_c_s")]
    pub rate_c_per_s: f64,
    /// A response ends the ramp (method of limits); otherwise the ramp runs to `baseline_c + intensity_c`.
    pub until_response: bool,
    /// The plateau held at the target \[s\] (0 for the method of limits).
    pub plateau_s: f64,
    /// Where the plate returns after the ramp (or plateau) \[°C\]; `None`: it stays (thermal sensory limen).
    pub return_c: Option<f64>,
    /// The return ramp's rate \[°C/s\].
    #[serde(rename = "return_rate_c_s")]
    pub return_rate_c_per_s: f64,
    /// The pause after the trial \[s\].
    pub isi_s: f64,
    /// The response asked for is pain (CPT, HPT), not the first sensation.
    pub pain: bool,
    /// The ramp starts where the previous trial's ramp stopped, without a return or a pause (the thermal sensory
    /// limen's alternating ramps).
    pub continues_previous: bool,
}

impl TrialPlan {
    /// The ramp's target (or cut-off) \[°C\]: `baseline_c + intensity_c`.
    pub fn target_c(&self) -> f64 {
        self.baseline_c + self.intensity_c
    }

    /// Clips the target to a display's range `[min_c, max_c]` \[°C\] (thermode's own display: 15–48 °C against the
    /// DFNS cut-offs 0 and 50 °C) and returns the display's cut-off when it applied, for the session to report.
    pub fn clip_to_range(&mut self, min_c: f64, max_c: f64) -> Option<f64> {
        let target = self.target_c();
        let clipped = target.clamp(min_c, max_c);
        if clipped == target {
            return None;
        }
        self.intensity_c = clipped - self.baseline_c;
        Some(clipped)
    }

    /// The plan as program segments: the ramp (ended by a response when `until_response`), the plateau, the return
    /// ramp, the inter-stimulus hold.
    pub fn segments(&self) -> Vec<Segment> {
        let until = self.until_response.then_some(Until::Response);
        let mut segments = vec![Segment::Ramp {
            to_c: self.target_c(),
            rate_c_per_s: self.rate_c_per_s,
            until,
        }];
        if self.plateau_s > 0.0 {
            segments.push(Segment::Hold {
                hold_s: self.plateau_s,
                until: None,
            });
        }
        if let Some(to_c) = self.return_c {
            segments.push(Segment::Ramp {
                to_c,
                rate_c_per_s: self.return_rate_c_per_s,
                until: None,
            });
        }
        if self.isi_s > 0.0 {
            segments.push(Segment::Hold {
                hold_s: self.isi_s,
                until: None,
            });
        }
        segments
    }
}

/// What the participant answered to one trial.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Response {
    /// Method of limits: the participant pressed before the cut-off. Yes/no procedures: the answer was "yes".
    pub detected: bool,
    /// The delivered intensity's plate temperature \[°C\]: the plate at the response tick (limits), where the ramp
    /// ended without a response (NaN: the plan's target), or the plate at the plateau (yes/no procedures).
    pub delivered_c: f64,
    /// Thermal sensory limen: a cold ramp felt as warm or hot (a paradoxical heat sensation).
    pub paradoxical_heat: bool,
}

impl Response {
    /// A yes/no answer at a plateau of `delivered_c` \[°C\].
    pub fn yes_no(detected: bool, delivered_c: f64) -> Self {
        Response {
            detected,
            delivered_c,
            paradoxical_heat: false,
        }
    }
}

/// The state machine every procedure is: ask for the next trial, record its response, ask again.
pub trait Procedure {
    /// The next trial to present, or `None` when the procedure has finished. Calling it again before recording a
    /// response returns the same pending trial.
    fn next_trial(&mut self) -> Option<TrialPlan>;

    /// Records the response to the pending trial.
    fn record(&mut self, response: Response) -> Result<(), crate::ProcedureError>;

    /// The procedure's threshold estimate so far \[°C of change from the baseline, as a magnitude\], if it has one.
    fn estimate_c(&self) -> Option<f64>;
}
