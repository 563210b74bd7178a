//! The display seam of the procedures: what a display must do to run a procedure's trials as programs
//! ([`ProgramDisplay`]) and what it reports back (program starts, plate samples, segment events, responses).
//!
//! Two displays implement it: the simulated display in virtual time ([`super::simulated::SimulatedProgramDisplay`],
//! `lab run --simulate`) and a running daemon over its WebSocket (`runner::ws_link::WsLink`, `lab run --display` and
//! `--device`). Every set-point of either passes the channel's safety envelope.

use std::collections::BTreeMap;

use thermode_procedures::Segment;

use crate::runner::StimulusError;

/// A target a display clipped to its range (the display's cut-off, reported per trial).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cutoff {
    /// The channel.
    pub channel: usize,
    /// The segment (from 0).
    pub segment: usize,
    /// The target asked for \[°C\].
    pub requested_c: f64,
    /// The display's limit used instead \[°C\].
    pub cutoff_c: f64,
}

/// A program started: every channel's first set-point is that of `start_tick`.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgramStart {
    /// The tick of every channel's first set-point.
    pub start_tick: u64,
    /// Loop time of that tick \[s\].
    pub start_time_s: f64,
    /// Every clipped target.
    pub cutoffs: Vec<Cutoff>,
}

/// One channel in a plate sample. Numbers the display cannot measure are NaN.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelPlate {
    /// The channel.
    pub channel: usize,
    /// The display set-point after the envelope \[°C\].
    pub setpoint_c: f64,
    /// The plate sensor \[°C\].
    pub sensor_c: f64,
    /// The best temperature of the plate the display has \[°C\]: the true plate on the simulated display, the
    /// envelope's plate estimate on a real one (its sensor where it has no estimate).
    pub plate_c: f64,
    /// The channel's latched safety fault code (0: none).
    pub fault: u16,
}

/// What a display reports while a program runs.
#[derive(Debug, Clone, PartialEq)]
pub enum DisplayEvent {
    /// A sample of every channel's plate (100 Hz on a daemon's telemetry, every tick on the simulated display).
    Sample {
        /// Loop time \[s\].
        time_s: f64,
        /// The channels.
        channels: Vec<ChannelPlate>,
    },
    /// A segment started on a channel.
    SegmentStart {
        /// The channel.
        channel: usize,
        /// The segment (from 0).
        segment: usize,
        /// The tick of its first set-point.
        tick: u64,
        /// Loop time of that tick \[s\].
        time_s: f64,
        /// Its target \[°C\] (ramps and steps; clipped).
        to_c: Option<f64>,
        /// The display's limit the target was clipped to \[°C\], if it was.
        cutoff_c: Option<f64>,
    },
    /// A channel's program is over; its set-point holds.
    ProgramEnd {
        /// The channel.
        channel: usize,
        /// The tick.
        tick: u64,
        /// Loop time \[s\].
        time_s: f64,
    },
}

/// A response as the display applied it: the tick it took effect on and the plate there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResponseAt {
    /// The tick the response took effect on.
    pub tick: u64,
    /// Loop time of that tick \[s\].
    pub time_s: f64,
    /// The plate sensor at that tick \[°C\] (NaN where not measured).
    pub sensor_c: f64,
    /// The plate at that tick \[°C\]: the true plate on the simulated display, the envelope's estimate on a real one
    /// (its sensor where it has none; NaN where neither is measured).
    pub plate_c: f64,
    /// The set-point of that tick \[°C\].
    pub setpoint_c: f64,
    /// The `until: response` segment the response ended, if any.
    pub ended_segment: Option<usize>,
}

/// A display that runs programs: the procedures' port to the loop.
pub trait ProgramDisplay {
    /// The display's channels.
    fn channel_count(&self) -> usize;
    /// Starts `program` (each channel's segments) with every channel's first set-point on one tick.
    fn start(&mut self, program: &BTreeMap<usize, Vec<Segment>>) -> Result<ProgramStart, StimulusError>;
    /// The next thing the display reports (blocks on a real display; an error when its link is lost).
    fn next_event(&mut self) -> Result<DisplayEvent, StimulusError>;
    /// A participant's response on `channel` (a button, or a rating 0–100), applied on the display's next tick.
    fn respond(&mut self, channel: usize, rating: Option<f64>) -> Result<ResponseAt, StimulusError>;
    /// What the display is, for the session sidecar.
    fn describe(&self) -> serde_json::Value;
}
