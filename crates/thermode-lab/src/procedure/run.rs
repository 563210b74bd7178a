//! Runs a procedure session: each trial of the procedure's state machine as a program on the display, the
//! responder watching the plate and answering, every trial's row, events and trace on disk before the next starts.
//!
//! Before the first trial (and before any trial that does not continue the previous one from a plate away from its
//! baseline) the plate goes to the baseline at [`TO_BASELINE_RATE_C_PER_S`] and holds the file's `adaptation_s` while the finger
//! adapts. A single-channel procedure's trial is its plan's segments on `channel`: a ramp that a press ends
//! (method of limits: the response is sent the moment the responder presses, applied on the display's next tick,
//! and the plate at that tick is the delivered temperature), or a trapezoid answered yes/no afterwards (delivered:
//! the plate's mean over the plateau). A multi-zone program's trial is all its channels' segments started on one
//! tick, then the pause, then a rating.

use std::collections::{BTreeMap, BTreeSet};
use std::io::Write;

use thermode_procedures::program::{segment_times_s, ZoneTrial};
use thermode_procedures::{Procedure, ProcedureFile, Response, Segment, TrialPlan};

use super::answers::ProcedureResponder;
use super::display::{ChannelPlate, DisplayEvent, ProgramDisplay, ProgramStart, ResponseAt};
use super::session::{number, EventRow, ProcedureRow, ProcedureSession};
use super::ProcedureRunError;

/// The rate the plate goes to a trial's baseline at before it \[°C/s\] (the DFNS return rate).
pub const TO_BASELINE_RATE_C_PER_S: f64 = 1.0;
/// The traces' sampling interval \[s\] (100 Hz, the daemon's telemetry).
pub const TRACE_INTERVAL_S: f64 = 0.01;
/// A set-point this close to a baseline is at it \[°C\].
const AT_BASELINE_C: f64 = 0.01;

/// What a session did.
#[derive(Debug, Clone, PartialEq)]
pub struct ProcedureSummary {
    /// Trials in the session file.
    pub trials: usize,
    /// Trials recorded before this run (a resume).
    pub resumed_after: usize,
    /// The procedure's final estimate \[°C, magnitude\], if it has one.
    pub estimate_c: Option<f64>,
}

/// A procedure session ready to run.
pub struct ProcedureRunner<'a> {
    /// The experiment file.
    pub file: &'a ProcedureFile,
    /// The display.
    pub display: &'a mut dyn ProgramDisplay,
    /// Who answers.
    pub responder: &'a mut dyn ProcedureResponder,
    /// The session files.
    pub session: &'a mut ProcedureSession,
    /// The channel of a single-channel procedure.
    pub channel: usize,
    /// Progress lines (one per trial).
    pub out: &'a mut dyn Write,
}

/// What one presented program gave.
#[derive(Debug, Default)]
struct Presented {
    start_tick: u64,
    start_time_s: f64,
    /// The watched channel's first segment's cut-off \[°C\] (NaN: not clipped).
    cutoff_c: f64,
    events: Vec<EventRow>,
    trace: Trace,
    response: Option<ResponseAt>,
    /// The watched channel's plate averaged over the plateau segment \[°C\] (NaN: none).
    plateau_c: f64,
    /// The watched channel's plate at the end of its first segment \[°C\].
    first_segment_end_c: f64,
    /// The watched channel's newest set-point \[°C\].
    setpoint_c: f64,
}

/// How the runner watches a program.
#[derive(Debug, Clone, Copy)]
struct Watch {
    trial: usize,
    channel: usize,
    /// The segment a press ends (`until: response`), if the responder may press.
    until_segment: Option<usize>,
    /// The plateau segment, if the delivered intensity is its mean.
    plateau_segment: Option<usize>,
    /// Whether the responder is shown the samples.
    responding: bool,
}

/// A trial's plate trace at [`TRACE_INTERVAL_S`].
#[derive(Debug, Default)]
struct Trace {
    channels: Vec<usize>,
    rows: Vec<(f64, Vec<ChannelPlate>)>,
}

impl Trace {
    fn push(&mut self, time_s: f64, channels: &[ChannelPlate]) {
        let due = self
            .rows
            .last()
            .is_none_or(|(last, _)| time_s - last >= TRACE_INTERVAL_S - 1e-9);
        if due {
            let kept = channels
                .iter()
                .filter(|c| self.channels.contains(&c.channel))
                .copied()
                .collect();
            self.rows.push((time_s, kept));
        }
    }

    fn to_csv(&self) -> String {
        let single = self.channels.len() == 1;
        let mut text = String::from("loop_time_s");
        for channel in &self.channels {
            let prefix = if single { String::new() } else { format!("ch{channel}_") };
            for name in ["setpoint_c", "sensor_c", "plate_c"] {
                text.push_str(&format!(",{prefix}{name}"));
            }
        }
        text.push('\n');
        for (time_s, plates) in &self.rows {
            text.push_str(&number(*time_s));
            for plate in plates {
                for value in [plate.setpoint_c, plate.sensor_c, plate.plate_c] {
                    text.push(',');
                    text.push_str(&number(value));
                }
            }
            text.push('\n');
        }
        text
    }
}

impl ProcedureRunner<'_> {
    /// Runs the session to its end (resuming after its recorded trials).
    pub fn run(self) -> Result<ProcedureSummary, ProcedureRunError> {
        match self.file.procedure()? {
            Some(procedure) => self.run_single(procedure),
            None => self.run_zones(),
        }
    }

    fn run_single(mut self, mut procedure: Box<dyn Procedure + Send>) -> Result<ProcedureSummary, ProcedureRunError> {
        let resumed_after = replay(procedure.as_mut(), self.session.rows())?;
        let mut setpoint_c = f64::NAN;
        while let Some(plan) = procedure.next_trial() {
            let trial = self.session.rows().len() + 1;
            let at_baseline = (setpoint_c - plan.baseline_c).abs() <= AT_BASELINE_C;
            if !plan.continues_previous && !at_baseline {
                let to_baseline = BTreeMap::from([(self.channel, adaptation(plan.baseline_c, self.file.adaptation_s))]);
                self.present(&to_baseline, Watch::silent(trial, self.channel))?;
            }
            self.responder.begin(&plan)?;
            let watch = Watch {
                trial,
                channel: self.channel,
                until_segment: plan.until_response.then_some(0),
                plateau_segment: (plan.plateau_s > 0.0).then_some(1),
                responding: true,
            };
            let presented = self.present(&BTreeMap::from([(self.channel, plan.segments())]), watch)?;
            setpoint_c = presented.setpoint_c;
            let response = self.answer(&plan, &presented)?;
            procedure.record(response)?;
            let row = self.single_row(trial, &plan, &presented, response, procedure.estimate_c());
            self.finish(row, presented)?;
        }
        Ok(ProcedureSummary {
            trials: self.session.rows().len(),
            resumed_after,
            estimate_c: procedure.estimate_c(),
        })
    }

    fn run_zones(mut self) -> Result<ProcedureSummary, ProcedureRunError> {
        let config = self.file.program.as_ref().ok_or(ProcedureRunError::NoProgram)?;
        let needed = config.channels;
        if self.display.channel_count() < needed {
            return Err(ProcedureRunError::Channels {
                needed,
                display: self.display.channel_count(),
            });
        }
        let trials = config.trials()?;
        let resumed_after = self.session.rows().len();
        for (index, trial) in trials.iter().enumerate().skip(resumed_after) {
            let number = index + 1;
            let first = *trial.channels.keys().next().ok_or(ProcedureRunError::NoProgram)?;
            let to_baseline = trial
                .channels
                .keys()
                .map(|&c| (c, adaptation(trial.baseline_c, self.file.adaptation_s)))
                .collect();
            self.present(&to_baseline, Watch::silent(number, first))?;
            let plan = zone_plan(trial);
            self.responder.begin(&plan)?;
            let mut program = trial.channels.clone();
            if trial.isi_s > 0.0 {
                for segments in program
                    .values_mut()
                    .filter(|s| s.len() < thermode_procedures::program::MAX_SEGMENTS)
                {
                    segments.push(Segment::Hold {
                        hold_s: trial.isi_s,
                        until: None,
                    });
                }
            }
            let watch = Watch {
                trial: number,
                channel: first,
                until_segment: None,
                plateau_segment: None,
                responding: true,
            };
            let mut presented = self.present(&program, watch)?;
            let rating = match config.rating {
                true => self.responder.rating(&trial.name)?,
                false => None,
            };
            if let Some(value) = rating {
                let at = self.display.respond(first, Some(value))?;
                presented
                    .events
                    .push(response_event(number, first, &at, "rating", value));
                presented.response = Some(at);
            }
            let row = ProcedureRow {
                label: trial.name.clone(),
                run: trial.repetition,
                channel: first,
                baseline_c: trial.baseline_c,
                intensity_c: f64::NAN,
                target_c: f64::NAN,
                rate_c_per_s: f64::NAN,
                delivered_c: f64::NAN,
                response: if rating.is_some() { "rating" } else { "none" }.to_string(),
                rating: rating.unwrap_or(f64::NAN),
                estimate_c: f64::NAN,
                ..self.row_base(number, &presented)
            };
            self.finish(row, presented)?;
        }
        Ok(ProcedureSummary {
            trials: self.session.rows().len(),
            resumed_after,
            estimate_c: None,
        })
    }

    /// The response to a single-channel trial from what it presented.
    fn answer(&mut self, plan: &TrialPlan, presented: &Presented) -> Result<Response, ProcedureRunError> {
        if plan.until_response {
            let delivered_c = match presented.response {
                Some(at) => at.plate_c,
                // No press: the ramp ended at its target, or at the display's cut-off.
                None if presented.cutoff_c.is_finite() => presented.cutoff_c,
                None => plan.target_c(),
            };
            let cold_tsl = plan.label == "TSL" && plan.intensity_c < 0.0;
            let paradoxical_heat = cold_tsl && presented.response.is_some() && self.responder.paradoxical_heat(plan)?;
            return Ok(Response {
                detected: presented.response.is_some(),
                delivered_c,
                paradoxical_heat,
            });
        }
        let delivered_c = match presented.plateau_c.is_finite() {
            true => presented.plateau_c,
            false => presented.first_segment_end_c,
        };
        Ok(Response::yes_no(self.responder.yes_no(plan)?, delivered_c))
    }

    fn single_row(
        &self,
        trial: usize,
        plan: &TrialPlan,
        presented: &Presented,
        response: Response,
        estimate_c: Option<f64>,
    ) -> ProcedureRow {
        let answer = match (plan.until_response, response.detected) {
            (true, true) => "press",
            (true, false) => "none",
            (false, true) => "yes",
            (false, false) => "no",
        };
        ProcedureRow {
            label: plan.label.clone(),
            run: plan.run,
            channel: self.channel,
            baseline_c: plan.baseline_c,
            intensity_c: plan.intensity_c,
            target_c: plan.target_c(),
            rate_c_per_s: plan.rate_c_per_s,
            delivered_c: response.delivered_c,
            response: answer.to_string(),
            rating: f64::NAN,
            paradoxical_heat: response.paradoxical_heat,
            estimate_c: estimate_c.unwrap_or(f64::NAN),
            ..self.row_base(trial, presented)
        }
    }

    /// The fields every row takes from its presentation.
    fn row_base(&self, trial: usize, presented: &Presented) -> ProcedureRow {
        ProcedureRow {
            trial,
            cutoff_c: presented.cutoff_c,
            response_tick: presented.response.map(|r| r.tick),
            response_time_s: presented.response.map_or(f64::NAN, |r| r.time_s),
            start_tick: presented.start_tick,
            start_time_s: presented.start_time_s,
            ..ProcedureRow::default()
        }
    }

    /// Writes the trace, then the events and the row; prints the trial's line.
    fn finish(&mut self, mut row: ProcedureRow, presented: Presented) -> Result<(), ProcedureRunError> {
        row.curve_file = self.session.write_trace(row.trial, &presented.trace.to_csv())?;
        let line = describe_row(&row);
        self.session.append(row, &presented.events)?;
        writeln!(self.out, "{line}").map_err(ProcedureRunError::Console)
    }

    /// Runs `program` to its end on every channel, watching `watch.channel`.
    fn present(
        &mut self,
        program: &BTreeMap<usize, Vec<Segment>>,
        watch: Watch,
    ) -> Result<Presented, ProcedureRunError> {
        let start: ProgramStart = self.display.start(program)?;
        let mut presented = Presented {
            start_tick: start.start_tick,
            start_time_s: start.start_time_s,
            cutoff_c: start
                .cutoffs
                .iter()
                .find(|c| c.channel == watch.channel && c.segment == 0)
                .map_or(f64::NAN, |c| c.cutoff_c),
            plateau_c: f64::NAN,
            first_segment_end_c: f64::NAN,
            setpoint_c: f64::NAN,
            trace: Trace {
                channels: program.keys().copied().collect(),
                rows: Vec::new(),
            },
            ..Presented::default()
        };
        let mut ended = BTreeSet::new();
        let mut segment = None;
        let mut last_time_s = start.start_time_s;
        let mut plateau = (0.0, 0usize);
        let due_s = start.start_time_s + nominal_duration_s(program) + PROGRAM_END_SLACK_S;
        while ended.len() < program.len() {
            match self.display.next_event()? {
                DisplayEvent::Sample { time_s, channels } if time_s >= start.start_time_s => {
                    check_channels(program, &channels, time_s, due_s)?;
                    presented.trace.push(time_s, &channels);
                    let Some(plate) = channels.iter().find(|c| c.channel == watch.channel) else {
                        continue;
                    };
                    presented.setpoint_c = plate.setpoint_c;
                    if segment == Some(0) {
                        presented.first_segment_end_c = plate.plate_c;
                    }
                    if segment.is_some() && segment == watch.plateau_segment {
                        plateau = (plateau.0 + plate.plate_c, plateau.1 + 1);
                    }
                    let dt_s = time_s - last_time_s;
                    last_time_s = time_s;
                    if !watch.responding || dt_s <= 0.0 || ended.contains(&watch.channel) {
                        continue;
                    }
                    let press = self.responder.watch(dt_s, plate.plate_c)?;
                    if press && presented.response.is_none() && segment.is_some() && segment == watch.until_segment {
                        let at = self.display.respond(watch.channel, None)?;
                        presented.setpoint_c = at.setpoint_c;
                        presented
                            .events
                            .push(response_event(watch.trial, watch.channel, &at, "button", f64::NAN));
                        presented.response = Some(at);
                    }
                }
                DisplayEvent::Sample { .. } => {}
                DisplayEvent::SegmentStart {
                    channel,
                    segment: started,
                    tick,
                    time_s,
                    to_c,
                    cutoff_c,
                } => {
                    if channel == watch.channel {
                        segment = Some(started);
                    }
                    presented.events.push(EventRow {
                        trial: watch.trial,
                        event: "segment_start".into(),
                        channel,
                        segment: Some(started),
                        tick,
                        time_s,
                        to_c: to_c.unwrap_or(f64::NAN),
                        cutoff_c: cutoff_c.unwrap_or(f64::NAN),
                        value: f64::NAN,
                        ..EventRow::default()
                    });
                }
                DisplayEvent::ProgramEnd { channel, tick, time_s } => {
                    ended.insert(channel);
                    presented.events.push(EventRow {
                        trial: watch.trial,
                        event: "program_end".into(),
                        channel,
                        tick,
                        time_s,
                        to_c: f64::NAN,
                        cutoff_c: f64::NAN,
                        value: f64::NAN,
                        ..EventRow::default()
                    });
                }
            }
        }
        if plateau.1 > 0 {
            presented.plateau_c = plateau.0 / plateau.1 as f64;
        }
        Ok(presented)
    }
}

impl Watch {
    /// A program nobody answers (the way to a baseline).
    fn silent(trial: usize, channel: usize) -> Watch {
        Watch {
            trial,
            channel,
            until_segment: None,
            plateau_segment: None,
            responding: false,
        }
    }
}

/// How long past its nominal end a program may run before the runner calls it lost \[s\] (steps at the envelope's
/// rate and the loop's rounding take a little longer than the nominal times).
pub const PROGRAM_END_SLACK_S: f64 = 30.0;

/// A program's nominal duration: its longest channel's segments, ramps at their rates, holds whole \[s\].
fn nominal_duration_s(program: &BTreeMap<usize, Vec<Segment>>) -> f64 {
    program
        .values()
        .map(|segments| {
            // The start is unknown here (the plate's set-point): count each ramp from the previous target, the first
            // one from its own target's distance to 0 °C at worst.
            let from_c = segments.iter().find_map(|s| match s {
                Segment::Ramp { to_c, .. } | Segment::Step { to_c } => Some(*to_c),
                Segment::Hold { .. } => None,
            });
            segment_times_s(from_c.unwrap_or(0.0), segments)
                .last()
                .copied()
                .unwrap_or(0.0)
                + FIRST_RAMP_ALLOWANCE_S
        })
        .fold(0.0, f64::max)
}

/// Time allowed for a program's first ramp from wherever the plate stands (50 °C at the slowest 1 °C/s would take
/// 50 s) \[s\].
const FIRST_RAMP_ALLOWANCE_S: f64 = 60.0;

/// Refuses a sample in which a program channel has faulted, or that comes after the program was due to end.
fn check_channels(
    program: &BTreeMap<usize, Vec<Segment>>,
    channels: &[ChannelPlate],
    time_s: f64,
    due_s: f64,
) -> Result<(), ProcedureRunError> {
    if let Some(faulted) = channels
        .iter()
        .find(|c| c.fault != 0 && program.contains_key(&c.channel))
    {
        return Err(ProcedureRunError::Display(crate::runner::StimulusError::Device(
            format!(
                "channel {} faulted (code {}) during the trial; its drive is off; the completed trials are saved",
                faulted.channel, faulted.fault
            ),
        )));
    }
    if time_s > due_s {
        return Err(ProcedureRunError::Display(crate::runner::StimulusError::Device(
            format!(
                "the program was due to end by loop time {due_s:.1} s and has not (no program_end event); the \
             completed trials are saved"
            ),
        )));
    }
    Ok(())
}

/// The way to a baseline: a ramp at [`TO_BASELINE_RATE_C_PER_S`], then `adaptation_s` \[s\] there.
fn adaptation(baseline_c: f64, adaptation_s: f64) -> Vec<Segment> {
    let mut segments = vec![Segment::Ramp {
        to_c: baseline_c,
        rate_c_per_s: TO_BASELINE_RATE_C_PER_S,
        until: None,
    }];
    if adaptation_s > 0.0 {
        segments.push(Segment::Hold {
            hold_s: adaptation_s,
            until: None,
        });
    }
    segments
}

fn response_event(trial: usize, channel: usize, at: &ResponseAt, kind: &str, value: f64) -> EventRow {
    EventRow {
        trial,
        event: "response".into(),
        channel,
        segment: at.ended_segment,
        tick: at.tick,
        time_s: at.time_s,
        to_c: f64::NAN,
        cutoff_c: f64::NAN,
        kind: kind.into(),
        value,
    }
}

/// A multi-zone trial as the plan a responder begins with: its first channel's first target.
fn zone_plan(trial: &ZoneTrial) -> TrialPlan {
    let first_target_c = trial
        .channels
        .values()
        .next()
        .and_then(|segments| match segments.first() {
            Some(Segment::Ramp { to_c, .. } | Segment::Step { to_c }) => Some(*to_c),
            _ => None,
        })
        .unwrap_or(trial.baseline_c);
    TrialPlan {
        index: trial.index,
        label: trial.name.clone(),
        run: trial.repetition,
        baseline_c: trial.baseline_c,
        intensity_c: first_target_c - trial.baseline_c,
        rate_c_per_s: f64::NAN,
        until_response: false,
        plateau_s: 0.0,
        return_c: Some(trial.baseline_c),
        return_rate_c_per_s: f64::NAN,
        isi_s: trial.isi_s,
        pain: false,
        continues_previous: false,
    }
}

/// Replays the recorded rows into `procedure`; every row must be the trial the procedure asks for.
fn replay(procedure: &mut dyn Procedure, rows: &[ProcedureRow]) -> Result<usize, ProcedureRunError> {
    for row in rows {
        let plan = procedure
            .next_trial()
            .ok_or_else(|| resume_error(row, "the procedure has no trial left here".into()))?;
        let same = plan.label == row.label && plan.run == row.run && (plan.intensity_c - row.intensity_c).abs() < 1e-6;
        if !same {
            return Err(resume_error(
                row,
                format!(
                    "the file has {} run {} at {} °C where the procedure asks for {} run {} at {} °C",
                    row.label,
                    row.run,
                    number(row.intensity_c),
                    plan.label,
                    plan.run,
                    number(plan.intensity_c)
                ),
            ));
        }
        let detected = match row.response.as_str() {
            "press" | "yes" => true,
            "none" | "no" => false,
            other => {
                return Err(resume_error(
                    row,
                    format!("the response `{other}` is not one this trial gives"),
                ))
            }
        };
        check_delivered(row, &plan)?;
        procedure.record(Response {
            detected,
            delivered_c: row.delivered_c,
            paradoxical_heat: row.paradoxical_heat,
        })?;
        check_estimate(row, procedure.estimate_c())?;
    }
    Ok(rows.len())
}

/// How far \[°C\] a recorded delivery may lie outside the span from the trial's baseline to its target (the plate
/// overshoots a ramp's end by a few tenths at most).
const DELIVERED_SLACK_C: f64 = 1.0;

fn resume_error(row: &ProcedureRow, message: String) -> ProcedureRunError {
    ProcedureRunError::Resume {
        trial: row.trial,
        message,
    }
}

/// A recorded delivery the trial could have given: a finite plate between its baseline and its target (or the
/// display's cut-off), within [`DELIVERED_SLACK_C`]; the procedure would otherwise be fed a stimulus it never gave.
fn check_delivered(row: &ProcedureRow, plan: &TrialPlan) -> Result<(), ProcedureRunError> {
    let end_c = match row.cutoff_c.is_finite() {
        true => row.cutoff_c,
        false => plan.target_c(),
    };
    let low_c = plan.baseline_c.min(end_c) - DELIVERED_SLACK_C;
    let high_c = plan.baseline_c.max(end_c) + DELIVERED_SLACK_C;
    match row.delivered_c.is_finite() && (low_c..=high_c).contains(&row.delivered_c) {
        true => Ok(()),
        false => Err(resume_error(
            row,
            format!(
                "`delivered_c` = {} °C is not a plate this trial can deliver (it ramps from {} to {} °C; at most \
                 {DELIVERED_SLACK_C} °C beyond)",
                Some(number(row.delivered_c))
                    .filter(|shown| !shown.is_empty())
                    .unwrap_or_else(|| "empty".into()),
                number(plan.baseline_c),
                number(end_c)
            ),
        )),
    }
}

/// The recorded estimate is the one the replayed procedure gives after the trial (both absent, or equal to 1e-6
/// °C): a row whose estimate was edited or lost does not resume.
fn check_estimate(row: &ProcedureRow, replayed_c: Option<f64>) -> Result<(), ProcedureRunError> {
    let same = match replayed_c {
        Some(c) => (c - row.estimate_c).abs() <= 1e-6,
        None => !row.estimate_c.is_finite(),
    };
    match same {
        true => Ok(()),
        false => Err(resume_error(
            row,
            format!(
                "`estimate_c` = `{}` where the replayed procedure gives `{}`",
                number(row.estimate_c),
                replayed_c.map(number).unwrap_or_default()
            ),
        )),
    }
}

fn describe_row(row: &ProcedureRow) -> String {
    let mut line = format!("trial {:>3} {} run {}: {}", row.trial, row.label, row.run, row.response);
    if row.delivered_c.is_finite() {
        line.push_str(&format!(" at {:.2} °C", row.delivered_c));
    }
    if row.rating.is_finite() {
        line.push_str(&format!(" {:.0}", row.rating));
    }
    if row.cutoff_c.is_finite() {
        line.push_str(&format!(" (the display's cut-off {} °C applied)", number(row.cutoff_c)));
    }
    if row.estimate_c.is_finite() {
        line.push_str(&format!("; estimate {:.3} °C", row.estimate_c));
    }
    line
}
