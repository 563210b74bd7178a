//! Multi-zone programs (`procedure = "program"`): stimuli that give several channels a list of segments each, all
//! starting on the same tick — the thermal grill, temporal summation, thermal icons. Each stimulus is presented
//! `repetitions` times, in the file's order, with a pause of `isi_s` after each; with `rating` the participant rates
//! each presentation (0–100).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::error::{check_positive, check_range};
use crate::plan::Segment;
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
        if self.channels == 0 || self.channels > 64 {
            return Err(ProcedureError::bad(
                "program.channels",
                self.channels,
                "an integer from 1 to 64",
            ));
        }
        if self.repetitions == 0 || self.repetitions > 1000 {
            return Err(ProcedureError::bad(
                "program.repetitions",
                self.repetitions,
                "an integer from 1 to 1000",
            ));
        }
        check_range("program.isi_s", self.isi_s, 0.0, 3600.0)?;
        if self.stimuli.is_empty() {
            return Err(ProcedureError::bad("program.stimuli", "[]", "at least one stimulus"));
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
                    ProcedureError::bad(
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
        check_range(&format!("{key}.baseline_c"), self.baseline_c, 0.0, 50.0)?;
        let map = self.channel_segments()?;
        if map.is_empty() {
            return Err(ProcedureError::bad(
                &format!("{key}.channels"),
                "{}",
                "at least one channel",
            ));
        }
        for (channel, segments) in &map {
            let at = format!("{key}.channels.{channel}");
            if *channel >= channels {
                return Err(ProcedureError::bad(
                    &at,
                    channel,
                    &format!("a channel below {channels}"),
                ));
            }
            if segments.is_empty() || segments.len() > MAX_SEGMENTS {
                return Err(ProcedureError::bad(&at, segments.len(), "1 to 999 segments"));
            }
            segments.iter().try_for_each(|s| check_segment(&at, s))?;
            let starts = match segments[0] {
                Segment::Ramp { to_c, .. } | Segment::Step { to_c } => to_c != self.baseline_c,
                Segment::Hold { .. } => false,
            };
            if !starts {
                return Err(ProcedureError::bad(
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
    match *segment {
        Segment::Ramp { to_c, rate_c_per_s, .. } => {
            check_range(&format!("{at}.to_c"), to_c, 0.0, 50.0)?;
            check_positive(&format!("{at}.rate_c_s"), rate_c_per_s, 300.0).map(drop)
        }
        Segment::Step { to_c } => check_range(&format!("{at}.to_c"), to_c, 0.0, 50.0).map(drop),
        Segment::Hold { hold_s, .. } => check_positive(&format!("{at}.hold_s"), hold_s, 3600.0).map(drop),
    }
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
