//! Stimulus programs: a list of segments per channel (a ramp to a temperature at a rate, a step as fast as the
//! envelope allows, a hold), some of which a participant's response ends early (`until: response`), and the pure
//! executor that turns a program into one display set-point per tick ([`Executor`]).
//!
//! Pure: no I/O, no clock, no allocation per tick ([`Executor::step`] and [`Executor::respond`] only do arithmetic
//! on the program built before the loop took it). The control loop feeds each set-point through the channel's
//! engine, so every set-point still passes the safety envelope.
//!
//! Timing: a segment starts on a tick, and its set-point of that tick already moves by `rate × dt` (the set-point
//! applies until the next tick). A ramp of `d` °C at `r` °C/s at `f` Hz therefore reaches its target on the
//! `ceil(d·f/r)`-th tick counted from its start tick (inclusive), and the next segment starts on the tick after:
//! from 32 to 31 °C at 1 °C/s at 1000 Hz, the start tick's set-point is 31.999 °C, the 1000th tick's 31 °C. A hold
//! of `h` s lasts `ceil(h·f)` ticks (at least one). A response on a segment with `until: response` ends it: the
//! next tick starts the next segment, continuing from the set-point the response stopped.

use thermode_model::params::{BadValue, Range, Rule};
use thermode_pipeline::stimulus::DIRECT_RATE;
use thiserror::Error;

use crate::limits::StimulusLimits;

/// Most segments a channel's program may have.
pub const MAX_SEGMENTS: usize = 999;

/// The targets a program may name \[°C\]: physically meaningful temperatures. A target beyond the display's range
/// (but within this one) is clipped to the range and reported as a cut-off, never refused.
pub const PROGRAM_TARGET: Range = Range {
    name: "to_c [°C]",
    min: -50.0,
    max: 150.0,
};

/// The longest hold \[s\] (one hour).
pub const HOLD: Range = Range {
    name: "hold_s [s]",
    min: 0.0,
    max: 3600.0,
};

/// Distance to a target under which a ramp counts as arrived \[°C\] (absorbs the rounding of `rate × time`).
const ARRIVED_C: f64 = 1e-9;
/// Time under which a hold counts as over \[s\] (absorbs the rounding of summed periods).
const HOLD_SLACK_S: f64 = 1e-9;

/// One segment of a program.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Segment {
    /// The set-point goes to `to_c` \[°C\] at `rate_c_per_s` \[°C/s\].
    Ramp {
        /// Target \[°C\] (already clipped to the display's range in a [`Program`]).
        to_c: f64,
        /// Rate \[°C/s\], from [`DIRECT_RATE`]'s minimum to the channel's rate limit.
        rate_c_per_s: f64,
        /// A response on the channel ends the ramp early.
        until_response: bool,
    },
    /// The set-point goes to `to_c` \[°C\] as fast as the envelope allows (its rate limit).
    Step {
        /// Target \[°C\] (already clipped to the display's range in a [`Program`]).
        to_c: f64,
    },
    /// The set-point stays where it is for `hold_s` \[s\].
    Hold {
        /// Duration \[s\], in [`HOLD`]; with `until_response`, the longest wait for the response.
        hold_s: f64,
        /// A response on the channel ends the hold early.
        until_response: bool,
    },
}

impl Segment {
    /// The segment's target \[°C\] (ramps and steps).
    pub fn to_c(&self) -> Option<f64> {
        match *self {
            Segment::Ramp { to_c, .. } | Segment::Step { to_c } => Some(to_c),
            Segment::Hold { .. } => None,
        }
    }

    /// Whether a response ends the segment early.
    pub fn until_response(&self) -> bool {
        match *self {
            Segment::Ramp { until_response, .. } | Segment::Hold { until_response, .. } => until_response,
            Segment::Step { .. } => false,
        }
    }
}

/// Why a program was refused (nothing changed).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ProgramError {
    /// More segments than [`MAX_SEGMENTS`].
    #[error("channel {channel}: a program has at most {max} segments per channel, this one has {count}")]
    TooManySegments {
        /// The channel.
        channel: usize,
        /// Segments given.
        count: usize,
        /// The limit ([`MAX_SEGMENTS`]).
        max: usize,
    },
    /// No segment.
    #[error("channel {channel}: a program needs at least one segment")]
    Empty {
        /// The channel.
        channel: usize,
    },
    /// A number out of its range.
    #[error("channel {channel}, segment {segment}: {source}")]
    BadValue {
        /// The channel.
        channel: usize,
        /// The segment (from 0).
        segment: usize,
        /// The refused number.
        source: BadValue,
    },
}

/// A target that was beyond the display's range and clipped to it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cutoff {
    /// The segment (from 0).
    pub segment: usize,
    /// The target asked for \[°C\].
    pub requested_c: f64,
    /// The target used: the display's limit \[°C\].
    pub cutoff_c: f64,
}

/// A checked program for one channel: every number in range, every target within the display's range (clipped,
/// with the clipping kept as [`Cutoff`]s), at most [`MAX_SEGMENTS`] segments.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    segments: Vec<Segment>,
    /// Per segment: its clipping, when its target was beyond the display's range.
    cutoffs: Vec<Option<Cutoff>>,
    /// The rate of steps \[°C/s\]: the channel's rate limit.
    step_rate_c_per_s: f64,
    /// The limits the segments were checked (and clipped) against.
    checked_against: StimulusLimits,
}

impl Program {
    /// Checks `segments` for `channel` against `limits` (the channel's display range and rate limit): ramp rates
    /// from [`DIRECT_RATE`]'s minimum to the rate limit, holds in [`HOLD`], targets in [`PROGRAM_TARGET`] and clipped
    /// to the display's range.
    pub fn new(channel: usize, segments: Vec<Segment>, limits: &StimulusLimits) -> Result<Program, ProgramError> {
        if segments.is_empty() {
            return Err(ProgramError::Empty { channel });
        }
        if segments.len() > MAX_SEGMENTS {
            return Err(ProgramError::TooManySegments {
                channel,
                count: segments.len(),
                max: MAX_SEGMENTS,
            });
        }
        let mut cutoffs = Vec::with_capacity(segments.len());
        let mut checked = Vec::with_capacity(segments.len());
        for (index, segment) in segments.into_iter().enumerate() {
            let bad = |source| ProgramError::BadValue {
                channel,
                segment: index,
                source,
            };
            let (segment, cutoff) = check_segment(segment, limits).map_err(bad)?;
            checked.push(segment);
            cutoffs.push(cutoff.map(|(requested_c, cutoff_c)| Cutoff {
                segment: index,
                requested_c,
                cutoff_c,
            }));
        }
        Ok(Program {
            segments: checked,
            cutoffs,
            step_rate_c_per_s: limits.max_rate_c_per_s,
            checked_against: *limits,
        })
    }

    /// Checks again, without allocating, that the program fits `limits` (those of the channel the loop runs it
    /// on): every number in range and every target within the display's range already. Checked against the very
    /// limits it was built with, it fits without a second pass (the loop would otherwise spend about half a
    /// millisecond on each 999-segment program of a flood).
    pub fn fits(&self, channel: usize, limits: &StimulusLimits) -> Result<(), ProgramError> {
        if *limits == self.checked_against {
            return Ok(());
        }
        for (index, segment) in self.segments.iter().enumerate() {
            let bad = |source| ProgramError::BadValue {
                channel,
                segment: index,
                source,
            };
            let (_, cutoff) = check_segment(*segment, limits).map_err(bad)?;
            if let Some((requested_c, _)) = cutoff {
                return Err(bad(BadValue {
                    name: limits.display_c.name.into(),
                    value: requested_c,
                    rule: Rule::Within {
                        min: limits.display_c.min,
                        max: limits.display_c.max,
                    },
                }));
            }
        }
        Ok(())
    }

    /// The segments, targets clipped.
    pub fn segments(&self) -> &[Segment] {
        &self.segments
    }

    /// The cut-off temperature \[°C\] of `segment` when its target was clipped.
    pub fn cutoff_c(&self, segment: usize) -> Option<f64> {
        self.cutoffs.get(segment).copied().flatten().map(|c| c.cutoff_c)
    }

    /// Every clipped target, in segment order.
    pub fn cutoffs(&self) -> impl Iterator<Item = Cutoff> + '_ {
        self.cutoffs.iter().flatten().copied()
    }

    /// The rate of a segment's set-point \[°C/s\] (a step's is the channel's rate limit; a hold's 0).
    fn rate_c_per_s(&self, segment: &Segment) -> f64 {
        match *segment {
            Segment::Ramp { rate_c_per_s, .. } => rate_c_per_s,
            Segment::Step { .. } => self.step_rate_c_per_s,
            Segment::Hold { .. } => 0.0,
        }
    }
}

/// One segment checked against `limits`, its target clipped to the display's range: the segment and, if clipped,
/// (requested, cut-off) \[°C\].
fn check_segment(segment: Segment, limits: &StimulusLimits) -> Result<(Segment, Option<(f64, f64)>), BadValue> {
    let clip = |to_c: f64| -> Result<(f64, Option<(f64, f64)>), BadValue> {
        PROGRAM_TARGET.check(to_c)?;
        let used_c = to_c.clamp(limits.display_c.min, limits.display_c.max);
        Ok((used_c, (used_c != to_c).then_some((to_c, used_c))))
    };
    Ok(match segment {
        Segment::Ramp {
            to_c,
            rate_c_per_s,
            until_response,
        } => {
            let rate = Rule::Within {
                min: DIRECT_RATE.min,
                max: limits.max_rate_c_per_s,
            };
            rate.check("rate_c_s [°C/s]", rate_c_per_s)?;
            let (to_c, cutoff) = clip(to_c)?;
            let ramp = Segment::Ramp {
                to_c,
                rate_c_per_s,
                until_response,
            };
            (ramp, cutoff)
        }
        Segment::Step { to_c } => {
            let (to_c, cutoff) = clip(to_c)?;
            (Segment::Step { to_c }, cutoff)
        }
        Segment::Hold { hold_s, .. } => {
            HOLD.check(hold_s)?;
            (segment, None)
        }
    })
}

/// What one tick of a program gives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProgramTick {
    /// The set-point of this tick \[°C\] (before the envelope).
    pub setpoint_c: f64,
    /// The segment that started on this tick, if one did.
    pub started: Option<usize>,
    /// The program ended on this tick (its last segment was over; the set-point holds from now on).
    pub ended: bool,
}

/// Runs a [`Program`] tick by tick: the set-point of each tick, which segment starts when, responses.
#[derive(Debug, Clone, PartialEq)]
pub struct Executor {
    program: Program,
    /// The running segment.
    index: usize,
    /// The set-point when the running segment started \[°C\].
    from_c: f64,
    /// The newest set-point \[°C\].
    setpoint_c: f64,
    /// Time since the running segment started, its first tick included \[s\].
    elapsed_s: f64,
    /// No tick yet: the first segment starts on the next one.
    fresh: bool,
    /// The running segment is over: the next tick starts the next segment (or ends the program).
    over: bool,
    /// Every segment is over.
    finished: bool,
}

impl Executor {
    /// A program starting from the set-point `from_c` \[°C\] (where the display stands) on the next tick.
    pub fn new(program: Program, from_c: f64) -> Self {
        Executor {
            program,
            index: 0,
            from_c,
            setpoint_c: from_c,
            elapsed_s: 0.0,
            fresh: true,
            over: false,
            finished: false,
        }
    }

    /// A response on the channel: ends the running segment if it waits for one (`until: response`); returns the
    /// segment it ended. The next tick starts the next segment.
    pub fn respond(&mut self) -> Option<usize> {
        let running = !self.fresh && !self.over && !self.finished;
        let segment = self.program.segments[self.index];
        (running && segment.until_response()).then(|| {
            self.over = true;
            self.index
        })
    }

    /// The segment running (`None` before the first tick and after the end).
    pub fn segment(&self) -> Option<usize> {
        (!self.fresh && !self.finished).then_some(self.index)
    }

    /// Whether every segment is over.
    pub fn finished(&self) -> bool {
        self.finished
    }

    /// The newest set-point \[°C\].
    pub fn setpoint_c(&self) -> f64 {
        self.setpoint_c
    }

    /// The program.
    pub fn program(&self) -> &Program {
        &self.program
    }

    /// One tick of `dt_s` \[s\] (the interval until the next tick): this tick's set-point, and the segment that
    /// started on it.
    pub fn step(&mut self, dt_s: f64) -> ProgramTick {
        let mut tick = ProgramTick {
            setpoint_c: self.setpoint_c,
            started: None,
            ended: false,
        };
        if self.finished {
            return tick;
        }
        if self.fresh {
            self.fresh = false;
            tick.started = Some(self.start(0));
        } else if self.over {
            if self.index + 1 < self.program.segments.len() {
                tick.started = Some(self.start(self.index + 1));
            } else {
                self.finished = true;
                tick.ended = true;
                return tick;
            }
        }
        self.elapsed_s += dt_s.max(0.0);
        self.setpoint_c = self.advance();
        tick.setpoint_c = self.setpoint_c;
        tick
    }

    fn start(&mut self, index: usize) -> usize {
        (self.index, self.from_c, self.elapsed_s, self.over) = (index, self.setpoint_c, 0.0, false);
        index
    }

    /// The running segment's set-point after `elapsed_s`; marks the segment over when it is.
    fn advance(&mut self) -> f64 {
        let segment = self.program.segments[self.index];
        match segment.to_c() {
            Some(to_c) => {
                let distance_c = to_c - self.from_c;
                let travelled_c = self.program.rate_c_per_s(&segment) * self.elapsed_s;
                if distance_c.abs() - travelled_c <= ARRIVED_C {
                    self.over = true;
                    to_c
                } else {
                    self.from_c + travelled_c.copysign(distance_c)
                }
            }
            None => {
                let Segment::Hold { hold_s, .. } = segment else {
                    unreachable!("only holds have no target")
                };
                self.over = self.elapsed_s >= hold_s - HOLD_SLACK_S;
                self.from_c
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use thermode_safety::EnvelopeConfig;

    /// The default envelope's limits: 15–48 °C, 10 °C/s.
    fn limits() -> StimulusLimits {
        StimulusLimits::of_envelope(&EnvelopeConfig::default())
    }

    fn ramp(to_c: f64, rate_c_per_s: f64, until_response: bool) -> Segment {
        Segment::Ramp {
            to_c,
            rate_c_per_s,
            until_response,
        }
    }

    fn program(segments: Vec<Segment>) -> Program {
        Program::new(0, segments, &limits()).unwrap_or_else(|e| panic!("{e}"))
    }

    /// Ticks until the program ends (at most `max` ticks): every set-point and the ticks segments started on.
    fn run(executor: &mut Executor, dt_s: f64, max: usize) -> (Vec<f64>, Vec<(usize, usize)>) {
        let (mut setpoints, mut starts) = (Vec::new(), Vec::new());
        for tick in 0..max {
            let step = executor.step(dt_s);
            if step.ended {
                break;
            }
            if let Some(segment) = step.started {
                starts.push((tick, segment));
            }
            setpoints.push(step.setpoint_c);
        }
        (setpoints, starts)
    }

    #[test]
    fn a_program_fits_the_limits_it_was_built_for_and_not_a_narrower_channel() {
        let built = program(vec![ramp(46.0, 8.0, false), Segment::Step { to_c: 20.0 }]);
        assert_eq!(built.fits(3, &limits()), Ok(()));
        let cooler = StimulusLimits {
            display_c: Range {
                max: 40.0,
                ..limits().display_c
            },
            ..limits()
        };
        match built.fits(3, &cooler) {
            Err(ProgramError::BadValue {
                channel: 3,
                segment: 0,
                source,
            }) => {
                assert_eq!(
                    (source.value, source.rule),
                    (46.0, Rule::Within { min: 15.0, max: 40.0 })
                );
            }
            other => panic!("a 46 °C target on a channel of 15-40 °C: {other:?}"),
        }
        let slower = StimulusLimits {
            max_rate_c_per_s: 5.0,
            ..limits()
        };
        match built.fits(3, &slower) {
            Err(ProgramError::BadValue { segment: 0, source, .. }) => assert_eq!(source.value, 8.0),
            other => panic!("an 8 °C/s ramp on a channel limited to 5 °C/s: {other:?}"),
        }
    }

    #[test]
    fn a_one_degree_per_second_ramp_at_1000_hz_arrives_on_its_thousandth_tick() {
        // 32 → 31 °C at 1 °C/s, 1 ms ticks: the k-th tick (from 1) stands at 32 − 0.001·k, so 31 °C on tick 1000
        // (index 999); the hold of 0.5 s starts on index 1000 and lasts 500 ticks.
        let mut executor = Executor::new(
            program(vec![
                ramp(31.0, 1.0, false),
                Segment::Hold {
                    hold_s: 0.5,
                    until_response: false,
                },
            ]),
            32.0,
        );
        let (setpoints, starts) = run(&mut executor, 0.001, 5000);
        assert_eq!(starts, vec![(0, 0), (1000, 1)], "segment starts (tick, segment)");
        assert_eq!(setpoints.len(), 1500, "1000 ramp ticks and 500 hold ticks");
        for (k, &setpoint_c) in setpoints[..1000].iter().enumerate() {
            let expected_c = 32.0 - 0.001 * (k + 1) as f64;
            assert!(
                (setpoint_c - expected_c).abs() < 1e-12,
                "tick {k}: set-point {setpoint_c} °C, arithmetic {expected_c} °C"
            );
        }
        assert!(
            (setpoints[998] - 31.001).abs() < 1e-12,
            "one tick before the target: {} °C",
            setpoints[998]
        );
        assert_eq!(setpoints[999], 31.0, "the 1000th tick is on the target");
        assert!(setpoints[1000..].iter().all(|&c| c == 31.0), "the hold holds 31 °C");
        assert!(executor.finished());
    }

    #[test]
    fn a_ramp_that_does_not_divide_evenly_arrives_on_the_ceiling_tick() {
        // 32 → 30 °C at 3 °C/s at 100 Hz: 0.03 °C a tick, 2/0.03 = 66.7 → the 67th tick (index 66) is 30 °C.
        let mut executor = Executor::new(
            program(vec![ramp(30.0, 3.0, false), Segment::Step { to_c: 32.0 }]),
            32.0,
        );
        let (setpoints, starts) = run(&mut executor, 0.01, 1000);
        assert_eq!(
            starts[1],
            (67, 1),
            "the step starts on the tick after the ramp's arrival"
        );
        assert!(
            (setpoints[65] - (32.0 - 0.03 * 66.0)).abs() < 1e-12,
            "{}",
            setpoints[65]
        );
        assert_eq!(setpoints[66], 30.0);
        // The step runs at the envelope's 10 °C/s: 0.1 °C a tick, 20 ticks back to 32 °C.
        assert!((setpoints[67] - 30.1).abs() < 1e-12, "{}", setpoints[67]);
        assert_eq!(
            setpoints.len(),
            67 + 20,
            "the step arrives on its 20th tick: {:?}",
            &setpoints[80..]
        );
        assert_eq!(*setpoints.last().expect("ticks"), 32.0);
    }

    #[test]
    fn a_response_ends_an_until_response_ramp_and_the_return_runs_at_its_rate() {
        // Method of limits: 32 → 0 °C at 1 °C/s until the response, back to 32 °C at 1 °C/s. 0 °C is clipped to the
        // display's 15 °C. The response after 2.5 s (tick index 2499, set-point 29.5 °C) ends the ramp there.
        let limits_run = program(vec![ramp(0.0, 1.0, true), ramp(32.0, 1.0, false)]);
        assert_eq!(
            limits_run.cutoff_c(0),
            Some(15.0),
            "0 °C is clipped to the display's 15 °C"
        );
        let cut: Vec<Cutoff> = limits_run.cutoffs().collect();
        assert_eq!(
            cut,
            vec![Cutoff {
                segment: 0,
                requested_c: 0.0,
                cutoff_c: 15.0
            }]
        );
        let mut executor = Executor::new(limits_run, 32.0);
        assert_eq!(executor.respond(), None, "before the first tick nothing runs");
        let mut last_c = 0.0;
        for _ in 0..2500 {
            last_c = executor.step(0.001).setpoint_c;
        }
        assert!((last_c - 29.5).abs() < 1e-9, "{last_c}");
        assert_eq!(executor.respond(), Some(0), "the response ends the ramp");
        assert_eq!(
            executor.respond(),
            None,
            "a second response in the same tick ends nothing more"
        );
        let next = executor.step(0.001);
        assert_eq!(next.started, Some(1), "the return starts on the next tick");
        assert!((next.setpoint_c - 29.501).abs() < 1e-9, "{}", next.setpoint_c);
        assert_eq!(executor.respond(), None, "the return does not wait for a response");
        let mut ticks = 1;
        while !executor.step(0.001).ended {
            ticks += 1;
        }
        assert_eq!(ticks, 2500, "2.5 °C back at 1 °C/s: 2500 ticks of 1 ms");
        assert_eq!(executor.setpoint_c(), 32.0);
    }

    #[test]
    fn a_hold_until_response_ends_at_the_response_or_its_time() {
        let hold = |hold_s| Segment::Hold {
            hold_s,
            until_response: true,
        };
        let mut executor = Executor::new(program(vec![hold(1.0), Segment::Step { to_c: 30.0 }]), 32.0);
        for _ in 0..10 {
            executor.step(0.01);
        }
        assert_eq!(executor.respond(), Some(0));
        assert_eq!(executor.step(0.01).started, Some(1));
        let mut timed_out = Executor::new(program(vec![hold(0.05), hold(0.0)]), 32.0);
        let (setpoints, starts) = run(&mut timed_out, 0.01, 100);
        assert_eq!(
            starts,
            vec![(0, 0), (5, 1)],
            "0.05 s of 10 ms ticks, then a zero hold lasting one tick"
        );
        assert_eq!(setpoints.len(), 6);
    }

    #[test]
    fn the_segment_limit_is_999_and_its_refusal_names_it() {
        let hold = Segment::Hold {
            hold_s: 0.1,
            until_response: false,
        };
        assert!(Program::new(3, vec![hold; MAX_SEGMENTS], &limits()).is_ok());
        let refused = Program::new(3, vec![hold; MAX_SEGMENTS + 1], &limits());
        let message = refused.expect_err("1000 segments").to_string();
        assert!(message.contains("999") && message.contains("1000"), "{message}");
        assert_eq!(
            Program::new(0, vec![], &limits()),
            Err(ProgramError::Empty { channel: 0 })
        );
    }

    #[test]
    fn bad_numbers_are_refused_with_their_segment() {
        for (segment, what) in [
            (ramp(30.0, 11.0, false), "rate_c_s"),
            (ramp(30.0, 0.0, false), "rate_c_s"),
            (ramp(f64::NAN, 1.0, false), "to_c"),
            (Segment::Step { to_c: 1000.0 }, "to_c"),
            (
                Segment::Hold {
                    hold_s: -1.0,
                    until_response: false,
                },
                "hold_s",
            ),
        ] {
            let refused = Program::new(2, vec![Segment::Step { to_c: 30.0 }, segment], &limits());
            match refused {
                Err(ProgramError::BadValue {
                    channel: 2,
                    segment: 1,
                    ref source,
                }) => assert!(source.to_string().contains(what), "{source}"),
                other => panic!("{segment:?}: {other:?}"),
            }
        }
    }
}
