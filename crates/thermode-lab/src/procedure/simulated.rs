//! The simulated display of `lab run --simulate` for procedures, in virtual time: the daemon's loop core
//! (`thermode_runtime::ControlLoop`, stepped by its virtual-time driver `VirtualLoop`) with each channel's render
//! pipeline and safety envelope, driving the simulated Peltier display with a finger resting on every plate, tick by
//! tick as fast as the machine goes. Programs and responses are the loop's own commands, so a program runs here
//! exactly as on the daemon; a session is bit-identical run after run. With a person answering at the keyboard it is
//! paced to real time ([`SimulatedProgramDisplay::paced`]).
//!
//! A response takes effect on the next tick, as on the daemon: [`ProgramDisplay::respond`] runs that tick and gives
//! its plate and set-point. The plate a participant feels is the simulated plate itself (`plate_c`).

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

use serde_json::json;
use thermode_device::{DefaultFinger, SimulatedDisplay};
use thermode_pipeline::{ChannelPipeline, PipelineConfig};
use thermode_platform::Clock;
use thermode_procedures::Segment;
use thermode_runtime::command::ResponseKind;
use thermode_runtime::program::{Program, Segment as LoopSegment};
use thermode_runtime::{Command, ControlLoop, LoopConfig, Owner, VirtualLoop};

use super::display::{ChannelPlate, Cutoff, DisplayEvent, ProgramDisplay, ProgramStart, ResponseAt};
use crate::runner::StimulusError;

/// The loop rate of the simulated display \[Hz\]: the daemon's default.
pub const SIMULATED_RATE_HZ: f64 = 1000.0;
/// How far a paced display's virtual time may run ahead of its clock before it sleeps \[s\].
pub const PACE_SLACK_S: f64 = 0.005;

/// The simulated display in virtual time (module documentation).
pub struct SimulatedProgramDisplay {
    display: VirtualLoop<SimulatedDisplay<DefaultFinger>, ChannelPipeline>,
    queue: VecDeque<DisplayEvent>,
    description: serde_json::Value,
    /// Real-time pacing (a person answers): the clock and its time at virtual time 0 \[s\].
    pace: Option<(Arc<dyn Clock>, f64)>,
}

fn device_error(e: impl std::fmt::Display) -> StimulusError {
    StimulusError::Device(e.to_string())
}

impl SimulatedProgramDisplay {
    /// `channels` channels of the display `pipeline` describes (its device file and controller), the plates' sensor
    /// noise seeded with `seed`; the display first ticks for `settle_s` \[s\] (at least one tick) in air so that it
    /// starts at rest.
    pub fn new(pipeline: &PipelineConfig, channels: usize, seed: u64, settle_s: f64) -> Result<Self, StimulusError> {
        let device =
            SimulatedDisplay::<DefaultFinger>::fingertips(&pipeline.device, channels, seed).map_err(device_error)?;
        let engines = (0..channels)
            .map(|_| ChannelPipeline::new(pipeline).map_err(device_error))
            .collect::<Result<Vec<_>, StimulusError>>()?;
        let config = LoopConfig {
            rate_hz: SIMULATED_RATE_HZ,
            ..LoopConfig::default()
        };
        let core = ControlLoop::new(&config, device, engines, Vec::new(), Default::default()).map_err(device_error)?;
        let mut display = SimulatedProgramDisplay {
            display: VirtualLoop::new(core, 0.0, 1.0 / SIMULATED_RATE_HZ),
            queue: VecDeque::new(),
            pace: None,
            description: json!({
                "display": "simulated (virtual time)",
                "rate_hz": SIMULATED_RATE_HZ,
                "controller": pipeline.controller.name(),
                "seed": seed,
            }),
        };
        let settle_ticks = ((settle_s * SIMULATED_RATE_HZ).ceil() as u64).max(1);
        for _ in 0..settle_ticks {
            display.step()?;
        }
        display.queue.clear();
        Ok(display)
    }

    /// Paces the display to `clock` from now on: virtual time never runs ahead of it by more than
    /// [`PACE_SLACK_S`] (a person at the keyboard answers in real time).
    pub fn paced(mut self, clock: Arc<dyn Clock>) -> Self {
        let origin_s = clock.now_s() - self.display.next_time_s();
        self.pace = Some((clock, origin_s));
        self.description["paced"] = json!("real time");
        self
    }

    /// One tick of the loop core (the programs' set-points through the envelopes, the drives applied), the tick's
    /// events and sample queued, then the plant advanced.
    fn step(&mut self) -> Result<(), StimulusError> {
        let time_s = self.display.next_time_s();
        if let Some((clock, origin_s)) = &self.pace {
            let deadline_s = origin_s + time_s;
            if deadline_s - clock.now_s() > PACE_SLACK_S {
                clock.sleep_until(deadline_s);
            }
        }
        let tick = self.display.tick();
        let core = self.display.core();
        let mut plates = Vec::with_capacity(core.status().len());
        for status in core.status() {
            let channel = status.channel;
            let mark = status.program;
            if let Some((segment, to_c, cutoff_c)) = mark.started {
                self.queue.push_back(DisplayEvent::SegmentStart {
                    channel,
                    segment,
                    tick,
                    time_s,
                    to_c,
                    cutoff_c,
                });
            }
            if mark.ended {
                self.queue.push_back(DisplayEvent::ProgramEnd { channel, tick, time_s });
            }
            if let Some(fault) = status.telemetry.fault {
                return Err(StimulusError::Device(format!(
                    "channel {channel} of the simulated display faulted: {fault}"
                )));
            }
            plates.push(ChannelPlate {
                channel,
                setpoint_c: status.telemetry.display_setpoint_c,
                sensor_c: status.telemetry.sensor_c,
                plate_c: core.device().channel(channel).map_err(device_error)?.state().plate_c,
                fault: 0,
            });
        }
        self.display.advance(1);
        self.queue.push_back(DisplayEvent::Sample {
            time_s,
            channels: plates,
        });
        Ok(())
    }
}

/// A procedure's segment as the loop's program takes it.
pub fn loop_segment(segment: &Segment) -> LoopSegment {
    match *segment {
        Segment::Ramp {
            to_c,
            rate_c_per_s,
            until,
        } => LoopSegment::Ramp {
            to_c,
            rate_c_per_s,
            until_response: until.is_some(),
        },
        Segment::Hold { hold_s, until } => LoopSegment::Hold {
            hold_s,
            until_response: until.is_some(),
        },
        Segment::Step { to_c } => LoopSegment::Step { to_c },
    }
}

impl ProgramDisplay for SimulatedProgramDisplay {
    fn channel_count(&self) -> usize {
        self.display.core().status().len()
    }

    fn start(&mut self, program: &BTreeMap<usize, Vec<Segment>>) -> Result<ProgramStart, StimulusError> {
        let core = self.display.core();
        let limits = core.channel_limits();
        let mut built = Vec::with_capacity(program.len());
        let mut cutoffs = Vec::new();
        for (&index, segments) in program {
            let channel_limits = limits.get(index).ok_or_else(|| {
                StimulusError::Device(format!(
                    "the simulated display has {} channel(s); channel {index} does not exist",
                    limits.len()
                ))
            })?;
            let checked = Program::new(index, segments.iter().map(loop_segment).collect(), channel_limits)
                .map_err(device_error)?;
            cutoffs.extend(checked.cutoffs().map(|c| Cutoff {
                channel: index,
                segment: c.segment,
                requested_c: c.requested_c,
                cutoff_c: c.cutoff_c,
            }));
            built.push((index, checked));
        }
        let owner = Owner::Nobody;
        self.display
            .core_mut()
            .command(Command::Program { programs: built, owner })
            .map_err(device_error)?;
        Ok(ProgramStart {
            start_tick: self.display.next_index(),
            start_time_s: self.display.next_time_s(),
            cutoffs,
        })
    }

    fn next_event(&mut self) -> Result<DisplayEvent, StimulusError> {
        if self.queue.is_empty() {
            self.step()?;
        }
        self.queue
            .pop_front()
            .ok_or_else(|| StimulusError::Device("the simulated display produced no sample".into()))
    }

    fn respond(&mut self, channel: usize, rating: Option<f64>) -> Result<ResponseAt, StimulusError> {
        let kind = match rating {
            Some(_) => ResponseKind::Rating,
            None => ResponseKind::Button,
        };
        let answer = self
            .display
            .core_mut()
            .command(Command::Response {
                channel,
                kind,
                value: rating,
            })
            .map_err(device_error)?;
        let ended_segment = answer.at_response.and_then(|at| at.ended_segment);
        let (tick, time_s) = (self.display.next_index(), self.display.next_time_s());
        self.step()?;
        let sample = self.queue.iter().rev().find_map(|event| match event {
            DisplayEvent::Sample { channels, .. } => channels.iter().find(|c| c.channel == channel).copied(),
            _ => None,
        });
        let plate = sample.ok_or_else(|| StimulusError::Device("the response's tick has no sample".into()))?;
        Ok(ResponseAt {
            tick,
            time_s,
            sensor_c: plate.sensor_c,
            plate_c: plate.plate_c,
            setpoint_c: plate.setpoint_c,
            ended_segment,
        })
    }

    fn describe(&self) -> serde_json::Value {
        self.description.clone()
    }
}
