//! A running daemon as a [`ProgramDisplay`]: programs, responses and program events over its WebSocket
//! (`docs/api.md`: `program`, `response`, the `program_event` messages and telemetry), through [`WsLink`].

use std::collections::BTreeMap;

use serde_json::Value;
use thermode_procedures::Segment;
use thermode_protocol::program::{ProgramEventKind, ProgramRequest, ResponseInput, ResponseKind, SegmentSpec, Until};
use thermode_protocol::{Done, Request, Response};

use super::display::{ChannelPlate, Cutoff, DisplayEvent, ProgramDisplay, ProgramStart, ResponseAt};
use crate::runner::live::DisplayLink;
use crate::runner::ws_link::WsLink;
use crate::runner::StimulusError;

/// A procedure's segment as the wire writes it.
fn spec(segment: &Segment) -> SegmentSpec {
    let until = |u: Option<thermode_procedures::Until>| u.map(|_| Until::Response);
    match *segment {
        Segment::Ramp {
            to_c,
            rate_c_per_s,
            until: u,
        } => SegmentSpec {
            to_c: Some(to_c),
            rate_c_per_s: Some(rate_c_per_s),
            until: until(u),
            ..SegmentSpec::default()
        },
        Segment::Hold { hold_s, until: u } => SegmentSpec {
            hold_s: Some(hold_s),
            until: until(u),
            ..SegmentSpec::default()
        },
        Segment::Step { to_c } => SegmentSpec {
            to_c: Some(to_c),
            ..SegmentSpec::default()
        },
    }
}

fn unexpected(request: &str) -> StimulusError {
    StimulusError::Device(format!("the display answered `{request}` with another reply"))
}

/// The best plate temperature a reply or sample gives: the envelope's estimate, else the sensor, else NaN.
fn plate_of(estimate_c: Option<f64>, sensor_c: Option<f64>) -> f64 {
    estimate_c.or(sensor_c).unwrap_or(f64::NAN)
}

impl ProgramDisplay for WsLink {
    fn channel_count(&self) -> usize {
        WsLink::channel_count(self)
    }

    fn start(&mut self, program: &BTreeMap<usize, Vec<Segment>>) -> Result<ProgramStart, StimulusError> {
        self.keep_messages();
        let channels = program
            .iter()
            .map(|(channel, segments)| (channel.to_string(), segments.iter().map(spec).collect()))
            .collect();
        match self.done(Request::Program(ProgramRequest { channels }))? {
            Done::Program {
                start_tick,
                start_time_s,
                cutoffs,
                ..
            } => Ok(ProgramStart {
                start_tick,
                start_time_s,
                cutoffs: cutoffs
                    .iter()
                    .map(|c| Cutoff {
                        channel: c.channel,
                        segment: c.segment,
                        requested_c: c.requested_c,
                        cutoff_c: c.cutoff_c,
                    })
                    .collect(),
            }),
            _ => Err(unexpected("program")),
        }
    }

    fn next_event(&mut self) -> Result<DisplayEvent, StimulusError> {
        loop {
            match self.next_message()? {
                Response::Telemetry(telemetry) => {
                    let number = |v: Option<f64>| v.unwrap_or(f64::NAN);
                    let channels = telemetry
                        .channels
                        .iter()
                        .map(|c| ChannelPlate {
                            channel: c.channel,
                            setpoint_c: number(c.display_setpoint_c),
                            sensor_c: number(c.sensor_c),
                            plate_c: plate_of(c.plate_estimate_c, c.sensor_c),
                            fault: c.fault,
                        })
                        .collect();
                    return Ok(DisplayEvent::Sample {
                        time_s: telemetry.time_s,
                        channels,
                    });
                }
                Response::ProgramEvent(event) => match event.event {
                    ProgramEventKind::SegmentStart => {
                        return Ok(DisplayEvent::SegmentStart {
                            channel: event.channel,
                            segment: event.segment.unwrap_or(0),
                            tick: event.tick,
                            time_s: event.time_s,
                            to_c: event.to_c,
                            cutoff_c: event.cutoff_c,
                        })
                    }
                    ProgramEventKind::ProgramEnd => {
                        return Ok(DisplayEvent::ProgramEnd {
                            channel: event.channel,
                            tick: event.tick,
                            time_s: event.time_s,
                        })
                    }
                    // The runner has the response from its reply.
                    ProgramEventKind::Response => continue,
                    ProgramEventKind::ProgramStopped => {
                        let reason = event.reason.unwrap_or_default();
                        return Err(StimulusError::Device(format!(
                            "the program on channel {} stopped at loop time {:.2} s: {reason}",
                            event.channel, event.time_s
                        )));
                    }
                },
                _ => continue,
            }
        }
    }

    fn respond(&mut self, channel: usize, rating: Option<f64>) -> Result<ResponseAt, StimulusError> {
        let input = ResponseInput {
            channel: channel as i64,
            kind: if rating.is_some() {
                ResponseKind::Rating
            } else {
                ResponseKind::Button
            },
            value: rating,
        };
        match self.done(Request::Response(input))? {
            Done::Response {
                sensor_c,
                plate_estimate_c,
                setpoint_c,
                ended_segment,
                applied,
                ..
            } => Ok(ResponseAt {
                tick: applied.tick,
                time_s: applied.time_s,
                sensor_c: sensor_c.unwrap_or(f64::NAN),
                plate_c: plate_of(plate_estimate_c, sensor_c),
                setpoint_c: setpoint_c.unwrap_or(f64::NAN),
                ended_segment,
            }),
            _ => Err(unexpected("response")),
        }
    }

    fn describe(&self) -> Value {
        DisplayLink::describe(self)
    }
}
