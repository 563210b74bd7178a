//! Multi-zone programs (`procedure = "program"`): stimuli that give several channels a list of segments each, all
//! starting on the same tick — the thermal grill, temporal summation, thermal icons. Each stimulus is presented
//! `repetitions` times, in the file's order, with a pause of `isi_s` after each; with `rating` the participant rates
//! each presentation (0–100).

use std::collections::BTreeMap;
use thermode_model::params::Rule;

use serde::{Deserialize, Serialize};

use crate::plan::{Segment, RAMP_RATE};
use crate::ProcedureError;

/// The most segments a channel's program may have (the loop's limit).
pub const MAX_SEGMENTS: usize = 999;

/// The `[program]` table of an experiment file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProgramConfig {
    /// Channels the display must have. Default 5.
    #[serde(default = "default_channels")]
    pub channels: usize,
    /// Presentations of each stimulus. Default 1.
    #[serde(default = "default_repetitions")]
    pub repetitions: usize,
    /// The pause after each presentation \[s\]. Default 30.
    #[serde(default = "default_isi_s")]
    pub isi_s: f64,
    /// Ask for a 0–100 rating after each presentation. Default true.
    #[serde(default = "default_rating")]
    pub rating: bool,
    /// The stimuli, in order.
    pub stimuli: Vec<ZoneStimulus>,
}

fn default_channels() -> usize {
    5
}
fn default_repetitions() -> usize {
    1
}
fn default_isi_s() -> f64 {
    30.0
}
fn default_rating() -> bool {
    true
}

/// One multi-zone stimulus: each channel's segments, keyed by the channel's number as text (`"0"`, `"1"`, …).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZoneStimulus {
    /// The stimulus' name (in the session CSV).
    pub name: String,
    /// Every channel's set-point before and after the stimulus \[°C\]. Default 32.
    #[serde(default = "default_baseline_c")]
    pub baseline_c: f64,
    /// The channels' segments.
    pub channels: BTreeMap<String, Vec<Segment>>,
}

fn default_baseline_c() -> f64 {
    32.0
}

/// One presentation: the stimulus, its repetition, and each channel's segments by channel number.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ZoneTrial {
    /// 0-based index in the session.
    pub index: usize,
    /// The stimulus' name.
    pub name: String,
    /// 1-based repetition.
    pub repetition: usize,
    /// The baseline \[°C\].
    pub baseline_c: f64,
    /// Each channel's segments.
    pub channels: BTreeMap<usize, Vec<Segment>>,
    /// The pause after it \[s\].
    pub isi_s: f64,
}

impl ProgramConfig {
    /// Checks the table: channels 1–64, every stimulus' channels below `channels`, 1–999 segments each, temperatures
    /// 0–50 °C, positive rates and durations, and every channel's first segment a ramp or step away from the
    /// baseline (so that every channel's first set-point change is on the program's first tick).
    pub fn validate(&self) -> Result<(), ProcedureError> {
        Rule::Within { min: 1.0, max: 64.0 }.check("program.channels", self.channels as f64)?;
        Rule::Within { min: 1.0, max: 1000.0 }.check("program.repetitions", self.repetitions as f64)?;
        Rule::Within { min: 0.0, max: 3600.0 }.check("program.isi_s", self.isi_s)?;
        if self.stimuli.is_empty() {
            return Err(ProcedureError::invalid(
                "program.stimuli",
                "[]",
                "at least one stimulus",
            ));
        }
        self.stimuli.iter().try_for_each(|s| s.validate(self.channels))
    }

    /// Every presentation in order.
    pub fn trials(&self) -> Result<Vec<ZoneTrial>, ProcedureError> {
        self.validate()?;
        let mut trials = Vec::new();
        for stimulus in &self.stimuli {
            for repetition in 1..=self.repetitions {
                trials.push(ZoneTrial {
                    index: trials.len(),
                    name: stimulus.name.clone(),
                    repetition,
                    baseline_c: stimulus.baseline_c,
                    channels: stimulus.channel_segments()?,
                    isi_s: self.isi_s,
                });
            }
        }
        Ok(trials)
    }
}

impl ZoneStimulus {
    fn channel_segments(&self) -> Result<BTreeMap<usize, Vec<Segment>>, ProcedureError> {
        self.channels
            .iter()
            .map(|(key, segments)| {
                let channel = key.trim().parse::<usize>().map_err(|_| {
                    ProcedureError::invalid(
                        &format!("program.stimuli.{}.channels", self.name),
                        key,
                        "a channel number",
                    )
                })?;
                Ok((channel, segments.clone()))
            })
            .collect()
    }

    fn validate(&self, channels: usize) -> Result<(), ProcedureError> {
        let key = format!("program.stimuli.{}", self.name);
        Rule::Within { min: 0.0, max: 50.0 }.check(format!("{key}.baseline_c"), self.baseline_c)?;
        let map = self.channel_segments()?;
        if map.is_empty() {
            return Err(ProcedureError::invalid(
                &format!("{key}.channels"),
                "{}",
                "at least one channel",
            ));
        }
        for (channel, segments) in &map {
            let at = format!("{key}.channels.{channel}");
            let below_channels = Rule::Below {
                max: channels as f64,
                what: "program.channels",
            };
            below_channels.check(format!("{key}.channels"), *channel as f64)?;
            let segment_count = Rule::Within {
                min: 1.0,
                max: MAX_SEGMENTS as f64,
            };
            segment_count.check(format!("{at} (segments)"), segments.len() as f64)?;
            segments.iter().try_for_each(|s| check_segment(&at, s))?;
            let starts = match segments[0] {
                Segment::Ramp { to_c, .. } | Segment::Step { to_c } => to_c != self.baseline_c,
                Segment::Hold { .. } => false,
            };
            if !starts {
                return Err(ProcedureError::invalid(
                    &at,
                    "its first segment",
                    "a ramp or step away from the baseline",
                ));
            }
        }
        Ok(())
    }
}

fn check_segment(at: &str, segment: &Segment) -> Result<(), ProcedureError> {
    let target = Rule::Within { min: 0.0, max: 50.0 };
    match *segment {
        Segment::Ramp { to_c, rate_c_per_s, .. } => {
            target.check(format!("{at}.to_c"), to_c)?;
            RAMP_RATE.check(format!("{at}.rate_c_s"), rate_c_per_s)?;
        }
        Segment::Step { to_c } => {
            target.check(format!("{at}.to_c"), to_c)?;
        }
        Segment::Hold { hold_s, .. } => {
            Rule::PositiveUpTo { max: 3600.0 }.check(format!("{at}.hold_s"), hold_s)?;
        }
    }
    Ok(())
}

/// The nominal start time of every segment from the program's first tick \[s\], and the end of the last one as a final
/// element: ramps take `|to_c − from| / rate_c_s` from the set-point the previous segment left (`baseline_c` first),
/// holds their `hold_s` (a segment ended early by a response is counted whole), steps no time (the envelope's rate
/// limit is the display's, not the program's).
pub fn segment_times_s(baseline_c: f64, segments: &[Segment]) -> Vec<f64> {
    let mut times = vec![0.0];
    let (mut t, mut setpoint_c) = (0.0, baseline_c);
    for segment in segments {
        match *segment {
            Segment::Ramp { to_c, rate_c_per_s, .. } => {
                t += (to_c - setpoint_c).abs() / rate_c_per_s;
                setpoint_c = to_c;
            }
            Segment::Step { to_c } => setpoint_c = to_c,
            Segment::Hold { hold_s, .. } => t += hold_s,
        }
        times.push(t);
    }
    times
}
