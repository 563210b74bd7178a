//! The virtual-time driver of the loop core: [`VirtualLoop`] steps a [`ControlLoop`] tick after tick with no thread
//! and no clock, as fast as the machine goes, and advances a simulated display's physics between ticks. The lab's
//! simulated display and `thermode render` run on it; the same inputs give bit-identical runs.
//!
//! Each tick is the daemon's: commands drained (or given at once with [`ControlLoop::command`]), programs stepped,
//! every channel read → tick → apply, the recorder fed. Tick `k` is at loop time `start_s + k · dt_s`, every tick
//! `dt_s` after the previous one. The display is advanced by [`VirtualLoop::advance`], in equal substeps of the tick,
//! after the caller has seen what the tick left (the plate under the drive just applied).

use thermode_device::{PlateFinger, SimulatedDisplay};
use thermode_platform::Tick;

use crate::control_loop::ControlLoop;
use crate::engine::ChannelEngine;

/// A display whose physics a virtual-time driver advances by hand.
pub trait SimulatedPhysics: thermode_device::Device {
    /// Advances the physics by `dt_s` \[s\] with the drives last applied.
    fn advance(&mut self, dt_s: f64);
}

impl<F: PlateFinger> SimulatedPhysics for SimulatedDisplay<F> {
    fn advance(&mut self, dt_s: f64) {
        SimulatedDisplay::advance(self, dt_s);
    }
}

/// A loop core stepped in virtual time (module documentation).
pub struct VirtualLoop<D, E> {
    core: ControlLoop<D, E>,
    /// Loop time of tick 0 \[s\].
    start_s: f64,
    /// The tick \[s\].
    dt_s: f64,
    /// The next tick's number.
    next_index: u64,
}

impl<D: SimulatedPhysics, E: ChannelEngine> VirtualLoop<D, E> {
    /// Steps `core` from loop time `start_s` \[s\] every `dt_s` \[s\] (finite and positive: the caller's rate, checked
    /// where it was chosen).
    pub fn new(core: ControlLoop<D, E>, start_s: f64, dt_s: f64) -> Self {
        VirtualLoop {
            core,
            start_s,
            dt_s,
            next_index: 0,
        }
    }

    /// The core (its status, engines, display).
    pub fn core(&self) -> &ControlLoop<D, E> {
        &self.core
    }

    /// The core, mutable (commands applied at once, the display).
    pub fn core_mut(&mut self) -> &mut ControlLoop<D, E> {
        &mut self.core
    }

    /// The next tick's number.
    pub fn next_index(&self) -> u64 {
        self.next_index
    }

    /// Loop time of the next tick \[s\].
    pub fn next_time_s(&self) -> f64 {
        self.start_s + self.next_index as f64 * self.dt_s
    }

    /// Runs the next tick (its commands answered); returns its number. The display is not advanced.
    pub fn tick(&mut self) -> u64 {
        let index = self.next_index;
        let scheduled_s = self.next_time_s();
        let tick = Tick {
            index,
            scheduled_s,
            dt_s: self.dt_s,
            woke_s: scheduled_s,
            missed: 0,
        };
        self.core.step(&tick);
        self.core.send_answers();
        self.next_index += 1;
        index
    }

    /// Advances the display by one tick in `substeps` equal substeps (at least one) with the drives just applied.
    pub fn advance(&mut self, substeps: usize) {
        let substeps = substeps.max(1);
        let h_s = self.dt_s / substeps as f64;
        for _ in 0..substeps {
            self.core.device_mut().advance(h_s);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::{Command, Owner, ResponseKind};
    use crate::control_loop::LoopConfig;
    use crate::program::{Program, Segment};
    use thermode_device::{DefaultFinger, DeviceConfig};
    use thermode_pipeline::{ChannelPipeline, ControllerKind, PipelineConfig};

    type Display = VirtualLoop<SimulatedDisplay<DefaultFinger>, ChannelPipeline>;

    const RATE_HZ: f64 = 1000.0;

    fn display(seed: u64) -> Display {
        let device = DeviceConfig::default();
        let pipeline = PipelineConfig::new(device, ControllerKind::Model);
        let plant = SimulatedDisplay::fingertips(&device, 2, seed).expect("display");
        let engines = (0..2)
            .map(|_| ChannelPipeline::new(&pipeline).expect("pipeline"))
            .collect();
        let config = LoopConfig {
            rate_hz: RATE_HZ,
            ..LoopConfig::default()
        };
        let core = ControlLoop::new(&config, plant, engines, Vec::new(), Default::default()).expect("core");
        VirtualLoop::new(core, 0.0, 1.0 / RATE_HZ)
    }

    fn steps(display: &mut Display, ticks: usize) -> Vec<(f64, f64)> {
        (0..ticks)
            .map(|_| {
                display.tick();
                display.advance(1);
                let t = &display.core().status()[0].telemetry;
                (t.display_setpoint_c, t.sensor_c)
            })
            .collect()
    }

    /// A program runs on the virtual loop as the daemon runs it: a ramp at its rate to its target, an
    /// `until: response` hold ended by a response on the next tick, a step at the envelope's rate, the end marked; the
    /// other channel untouched; two runs of one seed bit-identical.
    #[test]
    fn a_program_ramps_holds_until_the_response_and_ends_the_same_every_run() {
        let run = || {
            let mut display = display(5);
            steps(&mut display, 500);
            let limits = display.core().channel_limits()[0];
            let segments = vec![
                Segment::Ramp {
                    to_c: 36.0,
                    rate_c_per_s: 2.0,
                    until_response: false,
                },
                Segment::Hold {
                    hold_s: 60.0,
                    until_response: true,
                },
                Segment::Step { to_c: 33.0 },
            ];
            let program = Program::new(0, segments, &limits).expect("program");
            let from_c = display.core().status()[0].telemetry.display_setpoint_c;
            let owner = Owner::Nobody;
            display
                .core_mut()
                .command(Command::Program {
                    programs: vec![(0, program)],
                    owner,
                })
                .expect("started");
            let ramp_s = (36.0 - from_c) / 2.0;
            let half_ticks = (ramp_s * RATE_HZ) as usize / 2;
            let mut trace = steps(&mut display, half_ticks);
            let half_c = trace.last().map_or(f64::NAN, |s| s.0);
            let expected_half_c = from_c + 2.0 * half_ticks as f64 / RATE_HZ;
            assert!(
                (half_c - expected_half_c).abs() < 0.01,
                "half-way set-point {half_c} °C, expected {expected_half_c} °C"
            );
            trace.extend(steps(&mut display, (ramp_s * RATE_HZ) as usize + 1000));
            let held_c = display.core().status()[0].telemetry.display_setpoint_c;
            assert_eq!(held_c, 36.0, "held at the ramp's target");
            assert_eq!(display.core().status()[0].program.segment, Some(1));
            let answer = display
                .core_mut()
                .command(Command::Response {
                    channel: 0,
                    kind: ResponseKind::Button,
                    value: None,
                })
                .expect("response");
            assert_eq!(answer.at_response.and_then(|at| at.ended_segment), Some(1));
            display.tick();
            let mark = display.core().status()[0].program;
            assert_eq!(
                mark.started.map(|s| s.0),
                Some(2),
                "the step starts on the response's tick"
            );
            let mut ticks = 0;
            while !display.core().status()[0].program.ended && ticks < 2000 {
                display.advance(1);
                display.tick();
                ticks += 1;
            }
            let expected = (3.0 / limits.max_rate_c_per_s * RATE_HZ).round() as i64;
            assert!(
                (ticks as i64 - expected).abs() <= 1,
                "the step to 33 °C ended {ticks} ticks after it started, expected {expected} (its rate limit)"
            );
            assert_eq!(display.core().status()[0].telemetry.display_setpoint_c, 33.0);
            let other = &display.core().status()[1];
            assert_eq!(other.program.segment, None, "channel 1 runs no program");
            trace
        };
        let (first, second) = (run(), run());
        assert_eq!(first.len(), second.len());
        let differing = first
            .iter()
            .zip(&second)
            .filter(|(a, b)| a.0.to_bits() != b.0.to_bits() || a.1.to_bits() != b.1.to_bits())
            .count();
        assert_eq!(
            differing,
            0,
            "{differing} of {} ticks differ between two runs",
            first.len()
        );
    }
}
