//! The control loop on a manual clock: commands take effect at the next tick, stop-all holds every drive at 0 A,
//! a disconnected client's contacts are released exactly after the grace period, missed deadlines are counted,
//! device failures and faults switch the drive off, and hostile commands that bypass the API validation are
//! refused again by the pipeline — with no drive ever outside the envelope.

use crate::common;

use std::sync::{Arc, Mutex};

use common::{pipelines, trackers, SpyDevice, SpyLog};
use thermode_device::{DeviceConfig, Fault};
use thermode_model::materials;
use thermode_platform::{Clock, ManualClock};
use thermode_runtime::command::Reply;
use thermode_runtime::{Command, CommandError, EngineFactory, LoopConfig, LoopHandle, Mode, Owner, Snapshot};
use thermode_safety::{EnvelopeConfig, FaultCode};

const PERIOD_S: f64 = 0.01;

/// A loop on a manual clock with a spy device.
struct Rig {
    /// Index of the newest deadline the clock was moved to (times are `index · period`, never accumulated sums).
    index: std::cell::Cell<u64>,
    handle: LoopHandle,
    clock: Arc<ManualClock>,
    log: Arc<Mutex<SpyLog>>,
    control: Arc<Mutex<common::SpyControl>>,
}

impl Rig {
    fn new(channels: usize, engines: EngineFactory, config: LoopConfig) -> Rig {
        let device = SpyDevice::new(channels);
        let (log, control) = (device.log.clone(), device.control.clone());
        let clock = Arc::new(ManualClock::new());
        let handle = LoopHandle::spawn(
            config,
            Box::new(device),
            engines,
            clock.clone(),
            Vec::new(),
            Arc::default(),
        )
        .expect("loop");
        let rig = Rig {
            index: std::cell::Cell::new(0),
            handle,
            clock,
            log,
            control,
        };
        rig.wait_time(0.0);
        rig
    }

    fn snapshot(&self) -> Snapshot {
        self.handle.snapshot()
    }

    fn wait_time(&self, t: f64) {
        let ok = common::wait_until(10.0, || {
            self.snapshot().time_s >= t - 1e-9 && self.snapshot().stats.ticks > 0
        });
        assert!(ok, "the loop did not reach {t} s (at {} s)", self.snapshot().time_s);
    }

    /// Runs `n` ticks, one period each.
    fn step(&self, n: usize) {
        for _ in 0..n {
            self.index.set(self.index.get() + 1);
            self.clock.set(self.index.get() as f64 * PERIOD_S);
            self.wait_time(self.clock.now_s());
        }
    }

    /// Sends `command`, runs one tick, returns the loop's answer (as the loop sends it, a large `Err` included).
    #[allow(clippy::result_large_err)]
    fn ask(&self, command: Command) -> Reply {
        let answer = self.handle.commands().request(command).expect("queued");
        self.step(1);
        answer.blocking_recv().expect("answered")
    }

    fn currents_since(&self, channel: usize, since_s: f64) -> Vec<f64> {
        let log = self.log.lock().expect("log");
        log.applied
            .iter()
            .filter(|a| a.channel == channel && a.time_s >= since_s - 1e-9)
            .map(|a| a.current_a)
            .collect()
    }
}

fn touch(channel: usize, name: &str, owner: Owner) -> Command {
    touch_at(channel, name, 23.0, owner)
}

fn touch_at(channel: usize, name: &str, object_c: f64, owner: Owner) -> Command {
    Command::touch(
        channel,
        materials::find(name).expect("library material"),
        object_c,
        owner,
    )
}

#[test]
fn a_touch_takes_effect_at_the_next_tick_and_cools_only_its_channel() {
    let rig = Rig::new(5, pipelines(), LoopConfig::default());
    rig.step(50);
    let before = rig.snapshot();
    let reply = rig.ask(touch(1, "aluminium", Owner::Script)).expect("touch accepted");
    assert_eq!(
        reply.tick,
        before.tick + 1,
        "applied at the first tick after it was queued"
    );
    rig.step(100);
    let after = rig.snapshot();
    let ch = |i: usize| &after.channels[i];
    assert_eq!(
        (&*ch(1).label, ch(1).mode, ch(1).telemetry.contact),
        ("aluminium", Mode::Touch, true)
    );
    let air_target = ch(0).telemetry.target_skin_c;
    let touched_target = ch(1).telemetry.target_skin_c;
    assert!(
        touched_target < air_target - 0.5,
        "1 s on aluminium: target {touched_target} °C vs air {air_target} °C; aluminium must feel cold"
    );
    for i in [2, 3, 4] {
        assert_eq!(
            ch(i).telemetry.target_skin_c,
            air_target,
            "channel {i} must not feel channel 1's touch"
        );
        assert_eq!(&*ch(i).label, "air");
    }
    let cooling = rig.currents_since(1, reply.time_s);
    let strongest = cooling.iter().copied().fold(0.0, f64::min);
    assert!(
        strongest < -0.1,
        "the drive must cool after the touch; most negative current {strongest} A"
    );
    rig.ask(Command::Release { channel: 1 }).expect("release");
    let released = rig.snapshot();
    assert_eq!(
        (&*released.channels[1].label, released.channels[1].mode),
        ("air", Mode::Air)
    );
}

#[test]
fn stop_all_holds_every_drive_at_exactly_zero_until_the_next_command() {
    let rig = Rig::new(4, pipelines(), LoopConfig::default());
    rig.step(20);
    rig.ask(touch(0, "aluminium", Owner::Script)).expect("touch 0");
    rig.ask(touch(1, "steel", Owner::Client(3))).expect("touch 1");
    rig.step(100);
    let stop = rig.ask(Command::StopAll).expect("stop");
    rig.step(100);
    let snapshot = rig.snapshot();
    for (i, c) in snapshot.channels.iter().enumerate() {
        assert_eq!(
            (&*c.label, c.held_off, c.owner),
            ("air", true, Owner::Nobody),
            "channel {i}"
        );
        let currents = rig.currents_since(i, stop.time_s);
        assert!(currents.len() >= 100, "channel {i}: {} commands", currents.len());
        assert!(
            currents.iter().all(|&a| a == 0.0),
            "channel {i} drove {currents:?} after stop-all"
        );
    }
    let touch_again = rig.ask(touch(2, "wood", Owner::Script)).expect("touch 2");
    rig.step(50);
    let driven = rig.currents_since(2, touch_again.time_s);
    assert!(
        driven.iter().any(|&a| a != 0.0),
        "channel 2 must drive again after its next command"
    );
    for i in [0, 1, 3] {
        assert!(
            rig.currents_since(i, touch_again.time_s).iter().all(|&a| a == 0.0),
            "channel {i} must stay at 0 A until its own next command"
        );
    }
}

/// A stop-all during a warm touch holds for 60 s without any fault (the stuck-drive count does not run while the
/// drive is held off), and the next command behaves like one on a fresh channel: a direct set-point of 40 °C at the
/// paper's 2 °C/s is reached without the plate passing it by 0.5 °C (a controller left running through the hold
/// would have wound up; the tuned pid on a fresh channel peaks at 40.43 °C).
fn stop_all_holds_without_faults_case(engines: EngineFactory) {
    let rig = Rig::new(2, engines, LoopConfig::default());
    rig.step(100);
    // Warm enough to drive hard, not so hot that the thermal dose caps the next set-point.
    rig.ask(touch_at(0, "copper", 44.0, Owner::Script)).expect("warm touch");
    rig.ask(touch_at(1, "copper", -20.0, Owner::Script))
        .expect("cold touch");
    rig.step(500);
    rig.ask(Command::StopAll).expect("stop");
    for second in 1..=60 {
        rig.step(100);
        for (i, c) in rig.snapshot().channels.iter().enumerate() {
            assert_eq!(c.telemetry.fault, None, "channel {i} faulted {second} s into the hold");
        }
    }
    for channel in 0..2 {
        rig.log.lock().expect("log").max_plate_c = f64::NEG_INFINITY;
        let start = rig
            .ask(Command::direct(channel, 40.0, 2.0, Owner::Script))
            .expect("accepted after the hold");
        rig.step(2000);
        let max_plate_c = rig.log.lock().expect("log").max_plate_c;
        assert!(
            max_plate_c < 40.5,
            "channel {channel}: plate peaked at {max_plate_c} °C after a 40 °C set-point (sent at {} s)",
            start.time_s
        );
        assert!(
            max_plate_c > 39.5,
            "channel {channel}: the plate only reached {max_plate_c} °C"
        );
        assert_eq!(
            rig.snapshot().channels[channel].telemetry.fault,
            None,
            "channel {channel}"
        );
        rig.ask(Command::Release { channel }).expect("release");
    }
}

#[test]
fn stop_all_holds_without_faults_and_the_next_command_starts_fresh_pid() {
    stop_all_holds_without_faults_case(common::pid_pipelines());
}

#[test]
fn stop_all_holds_without_faults_and_the_next_command_starts_fresh_model() {
    stop_all_holds_without_faults_case(pipelines());
}

#[test]
fn a_disconnected_clients_contacts_are_released_exactly_after_the_grace_period() {
    let grace_s = 2.0;
    let config = LoopConfig {
        release_after_disconnect_s: grace_s,
        ..LoopConfig::default()
    };
    let rig = Rig::new(5, trackers(), config);
    rig.ask(touch(1, "wood", Owner::Client(7))).expect("client 7 touches 1");
    rig.ask(touch(2, "wood", Owner::Client(7))).expect("client 7 touches 2");
    rig.ask(touch(3, "steel", Owner::Osc)).expect("osc touches 3");
    let gone = rig.ask(Command::ClientGone { client: 7, at_s: None }).expect("gone");
    let release_at = rig.snapshot().channels[1].release_at_s.expect("a pending release");
    assert!(
        (release_at - (gone.time_s + grace_s)).abs() < 1e-12,
        "release at {release_at} s vs disconnect {} s + {grace_s} s",
        gone.time_s
    );
    rig.ask(touch(2, "aluminium", Owner::Client(8)))
        .expect("client 8 takes channel 2 over");
    let ticks_to_release = ((release_at - rig.snapshot().time_s) / PERIOD_S).round() as usize;
    rig.step(ticks_to_release - 1);
    let before = rig.snapshot();
    assert_eq!(
        &*before.channels[1].label, "wood",
        "released early, at {} s",
        before.time_s
    );
    rig.step(1);
    let after = rig.snapshot();
    assert!((after.time_s - release_at).abs() < 1e-9, "at {} s", after.time_s);
    assert_eq!(&*after.channels[1].label, "air", "not released at {} s", after.time_s);
    assert_eq!(
        &*after.channels[2].label, "aluminium",
        "a contact taken over by another client stays"
    );
    assert_eq!(
        &*after.channels[3].label, "steel",
        "OSC contacts have no connection and stay"
    );
    assert!(
        !after.channels[1].held_off,
        "a timed release renders air, it does not hold the drive off"
    );
}

#[test]
fn missed_deadlines_are_counted_and_period_statistics_measured() {
    let rig = Rig::new(2, trackers(), LoopConfig::default());
    rig.step(150);
    assert_eq!(rig.snapshot().stats.missed_deadlines, 0);
    // The next deadline is 10 ms away; the loop wakes 55 ms from now: deadlines at +10…+40 ms are missed and the
    // tick runs for the one at +50 ms.
    rig.index.set(rig.index.get() + 5);
    rig.clock.set(rig.index.get() as f64 * PERIOD_S + 0.005);
    rig.wait_time(rig.index.get() as f64 * PERIOD_S);
    let s = rig.snapshot();
    assert_eq!(s.stats.missed_deadlines, 4, "missed deadlines after a 55 ms stall");
    rig.step(120);
    let s = rig.snapshot();
    assert_eq!(s.stats.missed_deadlines, 4);
    assert!(
        (s.stats.period.p50_s - PERIOD_S).abs() < 1e-9,
        "p50 period {} s",
        s.stats.period.p50_s
    );
    assert!(
        (s.stats.period.max_s - 0.055).abs() < 1e-9,
        "max period {} vs 0.055 s",
        s.stats.period.max_s
    );
    assert_eq!(s.stats.ticks, 1 + 150 + 1 + 120, "ticks run (the first at t = 0)");
}

#[test]
fn a_failing_read_gets_zero_current_then_a_latched_fault_that_can_be_cleared() {
    let rig = Rig::new(3, pipelines(), LoopConfig::default());
    rig.step(30);
    rig.control.lock().expect("control").failing_reads.push(2);
    let failing_from = rig.snapshot().time_s + PERIOD_S;
    rig.step(50);
    let s = rig.snapshot();
    assert!(
        !s.channels[2].link_ok && s.device_errors >= 50,
        "errors {}",
        s.device_errors
    );
    let currents = rig.currents_since(2, failing_from);
    assert!(
        currents.iter().all(|&a| a == 0.0),
        "drive during failed reads: {currents:?}"
    );
    assert_eq!(
        s.channels[2].telemetry.fault,
        Some(FaultCode::SensorStale),
        "no fresh sample for 0.5 s"
    );
    let refused = rig.ask(touch(2, "wood", Owner::Script));
    assert!(
        matches!(refused, Err(CommandError::Faulted { channel: 2, .. })),
        "{refused:?}"
    );
    rig.control.lock().expect("control").failing_reads.clear();
    rig.step(5);
    rig.ask(Command::ClearFault { channel: 2 })
        .expect("the cause is gone: clear");
    rig.step(1);
    assert_eq!(rig.snapshot().channels[2].telemetry.fault, None);
    rig.ask(touch(2, "wood", Owner::Script)).expect("touch after clearing");
}

#[test]
fn a_device_cut_is_shown_on_its_channel_with_zero_current_until_the_device_releases_it() {
    use thermode_device::DeviceCut;
    use thermode_serve::api::protocol::channel_status;
    let rig = Rig::new(2, pipelines(), LoopConfig::default());
    rig.step(20);
    rig.control
        .lock()
        .expect("control")
        .cut_reads
        .push((1, DeviceCut::OverTemperature));
    let cut_from = rig.snapshot().time_s + PERIOD_S;
    rig.step(30);
    let s = rig.snapshot();
    assert_eq!(s.channels[1].device_cut, Some(DeviceCut::OverTemperature));
    assert_eq!(s.channels[0].device_cut, None, "the other channel");
    let currents = rig.currents_since(1, cut_from);
    assert!(currents.iter().all(|&a| a == 0.0), "drive while cut: {currents:?}");
    let json = serde_json::to_value(channel_status(&s.channels[1], None)).expect("serialises");
    println!("status of the cut channel: {json}");
    assert_eq!(json["device_cut"], "over_temperature");
    let description = json["device_cut_description"].as_str().unwrap_or_default();
    assert!(
        description.contains("over-temperature cut") && description.contains("heating off"),
        "{description}"
    );
    rig.control.lock().expect("control").cut_reads.clear();
    rig.step(2);
    assert_eq!(
        rig.snapshot().channels[1].device_cut,
        None,
        "cleared by the next good read"
    );
}

fn open_sensor_case(engines: EngineFactory) {
    let rig = Rig::new(2, engines, LoopConfig::default());
    rig.step(20);
    rig.control.lock().expect("control").inject.push((0, Fault::SensorOpen));
    let open_from = rig.snapshot().time_s + 2.0 * PERIOD_S;
    rig.step(30);
    let s = rig.snapshot();
    assert_eq!(s.channels[0].telemetry.fault, Some(FaultCode::SensorOpen));
    assert_eq!(s.channels[1].telemetry.fault, None, "the other channel is unaffected");
    let after_latch: Vec<f64> = rig.currents_since(0, open_from + PERIOD_S);
    assert!(
        after_latch.iter().all(|&a| a == 0.0),
        "drive with an open sensor: {after_latch:?}"
    );
    let refused = rig.ask(Command::ClearFault { channel: 0 });
    assert!(
        matches!(refused, Err(CommandError::FaultPersists { channel: 0, .. })),
        "{refused:?}"
    );
    rig.control.lock().expect("control").clear.push(0);
    rig.step(10);
    rig.ask(Command::ClearFault { channel: 0 })
        .expect("repaired sensor: clear");
}

#[test]
fn an_open_sensor_latches_a_fault_that_persists_until_repaired_pid() {
    open_sensor_case(common::pid_pipelines());
}

#[test]
fn an_open_sensor_latches_a_fault_that_persists_until_repaired_model() {
    open_sensor_case(pipelines());
}

/// An engine that panics on every tick once a direct set-point of exactly 44.4 °C arrives (a stand-in for a bug).
struct Booby {
    inner: thermode_runtime::TrackingEngine,
    armed: bool,
}

impl thermode_runtime::ChannelEngine for Booby {
    fn set_stimulus(&mut self, stimulus: thermode_runtime::Stimulus) -> Result<(), thermode_runtime::EngineError> {
        self.armed = matches!(stimulus, thermode_runtime::Stimulus::Direct { temp_c, .. } if temp_c == 44.4);
        self.inner.set_stimulus(stimulus)
    }

    fn tick(
        &mut self,
        now_s: f64,
        dt_s: f64,
        reading: &thermode_device::Reading,
    ) -> (thermode_safety::DriveCommand, thermode_runtime::Telemetry) {
        assert!(!self.armed, "booby trap");
        self.inner.tick(now_s, dt_s, reading)
    }

    fn clear_fault(&mut self, now_s: f64) -> Result<Option<FaultCode>, thermode_runtime::EngineError> {
        self.inner.clear_fault(now_s)
    }

    fn limits(&self) -> thermode_runtime::StimulusLimits {
        self.inner.limits()
    }

    fn hold(&mut self) {
        self.inner.hold();
    }

    fn dose(&self) -> thermode_safety::DoseLedger {
        self.inner.dose()
    }

    fn dose_budget_spent(&self) -> bool {
        self.inner.dose_budget_spent()
    }

    fn restore_dose(&mut self, saved: &thermode_safety::DoseLedger) -> Result<(), thermode_runtime::EngineError> {
        self.inner.restore_dose(saved)
    }
}

#[test]
fn a_panicking_engine_switches_only_its_channel_off_for_good() {
    let limit_a = DeviceConfig::default().drive.current_limit_a;
    let engines: EngineFactory = Box::new(move |count| {
        (0..count)
            .map(|_| {
                let inner = thermode_runtime::TrackingEngine::new(32.0, 0.5, limit_a)?;
                Ok(Box::new(Booby { inner, armed: false }) as Box<dyn thermode_runtime::ChannelEngine>)
            })
            .collect()
    });
    let rig = Rig::new(2, engines, LoopConfig::default());
    rig.step(5);
    let trap = Command::direct(0, 44.4, 1.0, Owner::Script);
    let armed = rig.ask(trap).expect("accepted: the bug strikes at the next tick");
    rig.step(20);
    let s = rig.snapshot();
    assert!(s.channels[0].engine_failed && s.channels[0].telemetry.fault.is_some());
    assert!(!s.channels[1].engine_failed, "the other channel keeps running");
    assert!(rig.currents_since(0, armed.time_s + PERIOD_S).iter().all(|&a| a == 0.0));
    assert!(matches!(
        rig.ask(touch(0, "wood", Owner::Script)),
        Err(CommandError::Faulted { .. })
    ));
    assert!(matches!(
        rig.ask(Command::ClearFault { channel: 0 }),
        Err(CommandError::FaultPersists { .. })
    ));
    rig.ask(touch(1, "wood", Owner::Script)).expect("channel 1 still works");
}

#[test]
fn a_full_command_queue_refuses_with_busy_and_loses_nothing_it_accepted() {
    let config = LoopConfig {
        command_queue_len: 2,
        ..LoopConfig::default()
    };
    let rig = Rig::new(3, trackers(), config);
    let commands = rig.handle.commands();
    let a = commands.request(touch(0, "wood", Owner::Script)).expect("1st queued");
    let b = commands.request(touch(1, "wood", Owner::Script)).expect("2nd queued");
    let c = commands.request(touch(2, "wood", Owner::Script));
    assert!(matches!(c, Err(CommandError::Busy)), "3rd: {c:?}");
    rig.step(1);
    assert!(a.blocking_recv().expect("answer").is_ok() && b.blocking_recv().expect("answer").is_ok());
    let s = rig.snapshot();
    assert_eq!(
        (&*s.channels[0].label, &*s.channels[1].label, &*s.channels[2].label),
        ("wood", "wood", "air")
    );
}

#[test]
fn commands_that_bypass_the_api_validation_are_refused_by_the_loop_and_the_pipeline() {
    let rig = Rig::new(2, pipelines(), LoopConfig::default());
    rig.step(5);
    let mut broken = materials::find("wood").expect("wood");
    broken.conductivity_w_mk = -1.0;
    let hostile = [
        touch(9, "wood", Owner::Script),
        Command::touch(0, broken, 23.0, Owner::Script),
        touch_at(0, "wood", f64::NAN, Owner::Script),
        Command::direct(1, 1000.0, 1.0, Owner::Script),
        Command::direct(1, 30.0, f64::INFINITY, Owner::Script),
        Command::Release { channel: usize::MAX },
    ];
    for command in hostile {
        let text = format!("{command:?}");
        let reply = rig.ask(command);
        assert!(
            matches!(
                reply,
                Err(CommandError::Rejected { .. } | CommandError::UnknownChannel { .. })
            ),
            "{text}: {reply:?}"
        );
    }
    let s = rig.snapshot();
    assert!(s
        .channels
        .iter()
        .all(|c| &*c.label == "air" && c.telemetry.fault.is_none()));
    assert_eq!(s.commands_refused, 6);
}

/// A fixed-seed generator (xorshift64*) for the hostile command stream.
struct Xorshift(u64);

impl Xorshift {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn a_random_stream_of_extreme_commands_never_drives_outside_the_envelope() {
    let rig = Rig::new(3, pipelines(), LoopConfig::default());
    let envelope = EnvelopeConfig::default();
    let limit_a = DeviceConfig::default().drive.current_limit_a;
    let names = ["aluminium", "steel", "stone", "wood", "rubber"];
    let mut rng = Xorshift(0x7e57_5eed);
    for _ in 0..60 {
        let channel = (rng.next() % 3) as usize;
        let command = match rng.next() % 4 {
            0 => {
                let name = names[(rng.next() % 5) as usize];
                // frozen to scalding objects: the envelope must cope
                touch_at(channel, name, rng.uniform(-50.0, 150.0), Owner::Script)
            }
            1 => Command::direct(
                channel,
                rng.uniform(envelope.min_display_c, envelope.max_display_c),
                rng.uniform(0.1, envelope.max_setpoint_rate_c_per_s),
                Owner::Script,
            ),
            2 => Command::Release { channel },
            _ => Command::StopAll,
        };
        let _ = rig.ask(command);
        rig.step((rng.next() % 60) as usize);
    }
    let log = rig.log.lock().expect("log");
    let ceiling_c = envelope.max_display_c + envelope.limit_margin_c;
    let floor_c = envelope.min_display_c - envelope.limit_margin_c;
    assert!(
        log.max_abs_current_a <= limit_a,
        "|I| {} A vs limit {limit_a} A",
        log.max_abs_current_a
    );
    assert!(
        log.max_plate_c <= ceiling_c,
        "plate {} °C vs ceiling {ceiling_c} °C",
        log.max_plate_c
    );
    assert!(
        log.min_plate_c >= floor_c,
        "plate {} °C vs floor {floor_c} °C",
        log.min_plate_c
    );
    drop(log);
    let s = rig.snapshot();
    let faults: Vec<_> = s.channels.iter().filter_map(|c| c.telemetry.fault).collect();
    assert!(
        faults.is_empty(),
        "no fault expected from valid (if extreme) commands: {faults:?}"
    );
}

#[test]
fn stopping_the_loop_switches_every_drive_off() {
    let mut rig = Rig::new(3, pipelines(), LoopConfig::default());
    rig.step(10);
    rig.ask(touch(0, "aluminium", Owner::Script)).expect("touch");
    rig.step(30);
    rig.handle.stop();
    let log = rig.log.lock().expect("log");
    for channel in 0..3 {
        let last = log
            .applied
            .iter()
            .rev()
            .find(|a| a.channel == channel)
            .expect("commands");
        assert_eq!(last.current_a, 0.0, "channel {channel}'s last command");
    }
    assert!(!rig.handle.snapshot().running);
}

#[test]
fn a_command_withdrawn_after_its_wait_is_answered_busy_and_never_applied() {
    let rig = Rig::new(2, trackers(), LoopConfig::default());
    let answer = rig
        .handle
        .commands()
        .request(touch(0, "wood", Owner::Script))
        .expect("queued");
    // The clock does not move: the loop never takes the command within the wait.
    let reply = common::client_runtime().block_on(thermode_serve::api::answer_within(
        answer,
        std::time::Duration::from_millis(50),
    ));
    assert!(matches!(reply, Err(CommandError::Busy)), "{reply:?}");
    rig.step(3);
    let s = rig.snapshot();
    assert_eq!(
        &*s.channels[0].label, "air",
        "a withdrawn command must not happen later"
    );
    assert_eq!((s.commands_withdrawn, s.commands_applied), (1, 0), "withdrawn, applied");
    // A command the loop has taken is answered, however late the waiter is.
    let answer = rig
        .handle
        .commands()
        .request(touch(1, "wood", Owner::Script))
        .expect("queued");
    rig.step(1);
    let reply =
        common::client_runtime().block_on(thermode_serve::api::answer_within(answer, std::time::Duration::ZERO));
    assert!(reply.is_ok(), "{reply:?}");
}

#[test]
fn stop_all_jumps_the_queue_and_cancels_what_was_sent_before_it() {
    let config = LoopConfig {
        command_queue_len: 2000,
        ..LoopConfig::default()
    };
    let rig = Rig::new(3, trackers(), config);
    let commands = rig.handle.commands();
    // More than a tick's budget of ordinary commands, then a stop.
    let flood: Vec<_> = (0..1500)
        .map(|i| commands.request(touch(i % 3, "wood", Owner::Osc)).expect("queued"))
        .collect();
    let stop = commands.request(Command::StopAll).expect("stop queued");
    let after = commands
        .request(touch(2, "steel", Owner::Script))
        .expect("queued after the stop");
    let before = rig.snapshot().tick;
    rig.step(1);
    let applied = stop.blocking_recv().expect("answer").expect("stop applied");
    assert_eq!(applied.tick, before + 1, "the stop is applied at the very next tick");
    rig.step(3);
    for (i, answer) in flood.into_iter().enumerate() {
        let reply = answer.blocking_recv().expect("answer");
        assert!(matches!(reply, Err(CommandError::Cancelled)), "flood {i}: {reply:?}");
    }
    assert!(
        after.blocking_recv().expect("answer").is_ok(),
        "sent after the stop: applied"
    );
    let s = rig.snapshot();
    assert_eq!(
        (&*s.channels[0].label, &*s.channels[1].label, &*s.channels[2].label),
        ("air", "air", "steel")
    );
}

#[test]
fn at_one_hertz_a_disconnect_under_a_flood_releases_within_the_grace_period() {
    const RATE_HZ: f64 = 1.0;
    let config = LoopConfig {
        rate_hz: RATE_HZ,
        release_after_disconnect_s: 2.0,
        ..LoopConfig::default()
    };
    assert_eq!(
        config.commands_per_tick(),
        config.command_queue_len,
        "the whole queue drains per tick"
    );
    let device = SpyDevice::new(2);
    let clock = Arc::new(ManualClock::new());
    let handle = LoopHandle::spawn(
        config,
        Box::new(device),
        trackers(),
        clock.clone(),
        Vec::new(),
        Arc::default(),
    )
    .expect("loop");
    let wait_tick = |t: f64| {
        assert!(
            common::wait_until(10.0, || handle.snapshot().time_s >= t - 1e-9
                && handle.snapshot().stats.ticks > 0),
            "tick at {t} s"
        )
    };
    wait_tick(0.0);
    let commands = handle.commands();
    let touched = commands.request(touch(0, "copper", Owner::Client(3))).expect("queued");
    clock.set(1.0);
    wait_tick(1.0);
    touched.blocking_recv().expect("answer").expect("touch applied");
    // A full queue of OSC commands, then the client vanishes at 1.3 s.
    while commands.send(Command::Release { channel: 1 }).is_ok() {}
    let disconnect_s = 1.3;
    commands
        .send(Command::ClientGone {
            client: 3,
            at_s: Some(disconnect_s),
        })
        .expect("the urgent lane takes it although the queue is full");
    clock.set(2.0);
    wait_tick(2.0);
    let s = handle.snapshot();
    assert_eq!(
        s.channels[0].release_at_s,
        Some(disconnect_s + 2.0),
        "the grace runs from the disconnect"
    );
    clock.set(3.0);
    wait_tick(3.0);
    let s = handle.snapshot();
    assert_eq!(
        &*s.channels[0].label, "air",
        "released at {} s, no later than the disconnect at {disconnect_s} s + 2 s",
        s.time_s
    );
}
