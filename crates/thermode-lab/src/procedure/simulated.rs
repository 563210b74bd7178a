//! The simulated display of `lab run --simulate` for procedures, in virtual time: the loop's program executor
//! (`thermode_runtime::program`), each channel's render pipeline and safety envelope in direct mode, and the
//! simulated Peltier display with a finger resting on every plate, stepped tick by tick as fast as the machine goes.
//! What the daemon does each tick for a program, done here without threads or a clock: a session is bit-identical
//! run after run. With a person answering at the keyboard it is paced to real time ([`SimulatedProgramDisplay::paced`]).
//!
//! A response takes effect on the next tick, as on the daemon: [`ProgramDisplay::respond`] runs that tick and gives
//! its plate and set-point. The plate a participant feels is the simulated plate itself (`plate_c`).

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

use serde_json::json;
use thermode_device::{DefaultFinger, Device, SimulatedDisplay};
use thermode_pipeline::{ChannelPipeline, PipelineConfig, Stimulus};
use thermode_platform::Clock;
use thermode_procedures::Segment;
use thermode_runtime::program::{Executor, Program, Segment as LoopSegment};
use thermode_runtime::StimulusLimits;

use super::display::{ChannelPlate, Cutoff, DisplayEvent, ProgramDisplay, ProgramStart, ResponseAt};
use crate::runner::StimulusError;

/// The loop rate of the simulated display \[Hz\]: the daemon's default.
pub const SIMULATED_RATE_HZ: f64 = 1000.0;
/// How far a paced display's virtual time may run ahead of its clock before it sleeps \[s\].
pub const PACE_SLACK_S: f64 = 0.005;

/// One channel: its pipeline, limits and running program.
struct Channel {
    pipeline: ChannelPipeline,
    limits: StimulusLimits,
    program: Option<Executor>,
    /// The newest set-point after the envelope \[°C\] (NaN before the first tick).
    setpoint_c: f64,
}

/// The simulated display in virtual time (module documentation).
pub struct SimulatedProgramDisplay {
    device: SimulatedDisplay<DefaultFinger>,
    channels: Vec<Channel>,
    dt_s: f64,
    /// The next tick's number.
    tick: u64,
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
    /// noise seeded with `seed`; the display first ticks for `settle_s` \[s\] in air so that it starts at rest.
    pub fn new(pipeline: &PipelineConfig, channels: usize, seed: u64, settle_s: f64) -> Result<Self, StimulusError> {
        let device =
            SimulatedDisplay::<DefaultFinger>::fingertips(&pipeline.device, channels, seed).map_err(device_error)?;
        let channels = (0..channels)
            .map(|_| {
                let pipeline = ChannelPipeline::new(pipeline).map_err(device_error)?;
                let limits = StimulusLimits::of_envelope(pipeline.envelope().config());
                Ok(Channel {
                    pipeline,
                    limits,
                    program: None,
                    setpoint_c: f64::NAN,
                })
            })
            .collect::<Result<Vec<_>, StimulusError>>()?;
        let mut display = SimulatedProgramDisplay {
            device,
            channels,
            dt_s: 1.0 / SIMULATED_RATE_HZ,
            tick: 0,
            queue: VecDeque::new(),
            pace: None,
            description: json!({
                "display": "simulated (virtual time)",
                "rate_hz": SIMULATED_RATE_HZ,
                "controller": pipeline.controller.name(),
                "seed": seed,
            }),
        };
        let settle_ticks = (settle_s * SIMULATED_RATE_HZ).ceil() as u64;
        for _ in 0..settle_ticks {
            display.step()?;
        }
        display.queue.clear();
        Ok(display)
    }

    /// Paces the display to `clock` from now on: virtual time never runs ahead of it by more than
    /// [`PACE_SLACK_S`] (a person at the keyboard answers in real time).
    pub fn paced(mut self, clock: Arc<dyn Clock>) -> Self {
        let origin_s = clock.now_s() - self.tick as f64 * self.dt_s;
        self.pace = Some((clock, origin_s));
        self.description["paced"] = json!("real time");
        self
    }

    /// One tick of every channel: the programs' set-points through the envelopes, the drives applied, the plant
    /// advanced; queues the tick's events and its sample.
    fn step(&mut self) -> Result<(), StimulusError> {
        let (tick, time_s, dt_s) = (self.tick, self.tick as f64 * self.dt_s, self.dt_s);
        if let Some((clock, origin_s)) = &self.pace {
            let deadline_s = origin_s + time_s;
            if deadline_s - clock.now_s() > PACE_SLACK_S {
                clock.sleep_until(deadline_s);
            }
        }
        let mut plates = Vec::with_capacity(self.channels.len());
        for (index, channel) in self.channels.iter_mut().enumerate() {
            let reading = self.device.read(index).map_err(device_error)?;
            if let Some(executor) = channel.program.as_mut().filter(|e| !e.finished()) {
                let step = executor.step(dt_s);
                if let Some(segment) = step.started {
                    let program = executor.program();
                    self.queue.push_back(DisplayEvent::SegmentStart {
                        channel: index,
                        segment,
                        tick,
                        time_s,
                        to_c: program.segments()[segment].to_c(),
                        cutoff_c: program.cutoff_c(segment),
                    });
                }
                if step.ended {
                    self.queue.push_back(DisplayEvent::ProgramEnd {
                        channel: index,
                        tick,
                        time_s,
                    });
                }
                let direct = Stimulus::Direct {
                    temp_c: step.setpoint_c,
                    rate_c_per_s: channel.limits.max_rate_c_per_s,
                };
                channel.pipeline.set_stimulus(direct).map_err(device_error)?;
            }
            let (command, telemetry) = channel.pipeline.tick(time_s, dt_s, &reading);
            if let Some(fault) = telemetry.fault {
                return Err(StimulusError::Device(format!(
                    "channel {index} of the simulated display faulted: {fault}"
                )));
            }
            self.device.apply(index, &command).map_err(device_error)?;
            channel.setpoint_c = telemetry.display_setpoint_c;
            plates.push(ChannelPlate {
                channel: index,
                setpoint_c: telemetry.display_setpoint_c,
                sensor_c: reading.sensor_c,
                plate_c: self.device.channel(index).map_err(device_error)?.state().plate_c,
                fault: 0,
            });
        }
        self.device.advance(dt_s);
        self.tick += 1;
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
        self.channels.len()
    }

    fn start(&mut self, program: &BTreeMap<usize, Vec<Segment>>) -> Result<ProgramStart, StimulusError> {
        let mut built = Vec::with_capacity(program.len());
        let mut cutoffs = Vec::new();
        for (&index, segments) in program {
            let channel = self.channels.get(index).ok_or_else(|| {
                StimulusError::Device(format!(
                    "the simulated display has {} channel(s); channel {index} does not exist",
                    self.channels.len()
                ))
            })?;
            let checked = Program::new(index, segments.iter().map(loop_segment).collect(), &channel.limits)
                .map_err(device_error)?;
            cutoffs.extend(checked.cutoffs().map(|c| Cutoff {
                channel: index,
                segment: c.segment,
                requested_c: c.requested_c,
                cutoff_c: c.cutoff_c,
            }));
            built.push((index, checked));
        }
        for (index, checked) in built {
            let setpoint_c = self.channels[index].setpoint_c;
            let from_c = match setpoint_c.is_finite() {
                true => setpoint_c,
                false => self.device.read(index).map_err(device_error)?.sensor_c,
            };
            self.channels[index].program = Some(Executor::new(checked, from_c));
        }
        Ok(ProgramStart {
            start_tick: self.tick,
            start_time_s: self.tick as f64 * self.dt_s,
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

    fn respond(&mut self, channel: usize, _rating: Option<f64>) -> Result<ResponseAt, StimulusError> {
        let ended_segment = self
            .channels
            .get_mut(channel)
            .ok_or_else(|| StimulusError::Device(format!("no channel {channel}")))?
            .program
            .as_mut()
            .and_then(Executor::respond);
        let tick = self.tick;
        self.step()?;
        let sample = self.queue.iter().rev().find_map(|event| match event {
            DisplayEvent::Sample { channels, .. } => channels.iter().find(|c| c.channel == channel).copied(),
            _ => None,
        });
        let plate = sample.ok_or_else(|| StimulusError::Device("the response's tick has no sample".into()))?;
        Ok(ResponseAt {
            tick,
            time_s: tick as f64 * self.dt_s,
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
