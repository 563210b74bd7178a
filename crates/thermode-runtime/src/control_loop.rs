//! The control loop: one std thread that ticks every channel at a fixed rate on an injected [`Clock`].
//!
//! Loop time is the clock's time at each tick's deadline, so a real device stamping its readings with the same clock
//! (a serial device is handed the loop's clock) and the envelope agree. Per tick, in order: the device's physics advance to the
//! tick's time (simulated devices); a newly tripped [`Interlock`] stops all; the urgent lane (stop-all, client gone)
//! is emptied, then queued commands are applied (at most [`LoopConfig::commands_per_tick`]: [`MAX_COMMANDS_PER_TICK`]
//! at 1 kHz, proportionally more at lower rates, so the whole queue drains within a period at 62.5 Hz and below);
//! contacts of disconnected clients whose grace period ends before the next tick are released (never later than
//! the grace period, at most one period earlier); each channel is read, its engine ticks (renderer → controller → safety envelope) and the gated drive
//! is applied; the snapshot is published (`try_lock`, never waiting) and a [`TickRecord`] goes to the recorder
//! queue (never waiting; a full queue drops and counts the record).
//!
//! No allocation and no async on this path: statuses, statistics windows and records are pre-allocated or on the
//! stack; a new contact's name arrives already allocated inside its command.
//!
//! Stop-all releases every channel (the display renders air) and, in addition, holds that channel's drive at 0 A
//! until the channel's next command: "stop" makes the display passive, not merely neutral. A channel whose device
//! read fails also gets 0 A for that tick. When the loop stops, every drive goes to 0 A at once
//! ([`Device::all_off`]: a serial display's `AllOff`, `DriveCommand::off` on every channel otherwise), and
//! [`LoopHandle::stop`] says whether the device took it.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, SyncSender, TryRecvError, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;

use thermode_device::{Device, DeviceError, Measures, Reading, MAX_CHANNELS};
use thermode_model::params::Rule;
use thermode_safety::{DoseLedger, DriveCommand, FaultCode};

use crate::command::{
    Applied, AtResponse, Command, CommandError, CommandReceiver, CommandSender, Owner, Queued, Reply, ResponseKind,
    URGENT_QUEUE_LEN,
};
use crate::engine::{ChannelEngine, EngineError, EngineFactory, SelfTestState, Stimulus, Telemetry};
use crate::error::RuntimeError;
use crate::interlock::Interlock;
use crate::limits::StimulusLimits;
use crate::program::{Executor, Program};
use crate::snapshot::{
    ChannelStatus, LoopStats, MaterialProperties, Mode, ProgramStop, RecordRow, Shared, Snapshot, TickRecord,
};
use crate::stats::Window;
use thermode_platform::rt::Realtime;
use thermode_platform::Clock;
use thermode_platform::{Tick, Ticker};

/// Highest loop rate \[Hz\]: the top of the physical range of loop rates ([`thermode_model::limits::LOOP_RATE`]).
pub const MAX_RATE_HZ: f64 = thermode_model::limits::LOOP_RATE.max;
/// Lowest loop rate \[Hz\]: the bottom of [`thermode_model::limits::LOOP_RATE`].
pub const MIN_RATE_HZ: f64 = thermode_model::limits::LOOP_RATE.min;
/// Most ordinary commands applied in one tick at 1 kHz; at lower rates proportionally more (see
/// [`LoopConfig::commands_per_tick`]); the rest wait for the next tick.
pub const MAX_COMMANDS_PER_TICK: usize = 64;
/// Longest loop-statistics window \[ticks\] (10 s at 1 kHz).
pub const MAX_STATS_WINDOW_TICKS: usize = 10_000;
/// The fault reported for a channel whose engine failed (panicked): its drive request can no longer be computed.
pub const ENGINE_FAILED: FaultCode = FaultCode::NonFiniteCommand;
/// Attempts to take the snapshot lock per tick before the publish is skipped.
const PUBLISH_ATTEMPTS: usize = 4;
/// How long the loop waits between retries of a skipped publish, while it waits for its next deadline \[s\].
const PUBLISH_RETRY_S: f64 = 2e-4;
/// Loop time between refreshes of the published statistics \[s\].
const STATS_REFRESH_S: f64 = 1.0;

/// Settings of the control loop.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopConfig {
    /// Tick rate \[Hz\]. Default 100; range [`MIN_RATE_HZ`]..=[`MAX_RATE_HZ`].
    pub rate_hz: f64,
    /// Grace period after a WebSocket client disconnects before its contacts are released \[s\]. Default 2;
    /// range 0..=60.
    pub release_after_disconnect_s: f64,
    /// Capacity of the command queue \[commands\]. Default 1024; at least 1.
    pub command_queue_len: usize,
    /// Length of the loop-statistics window \[s\]. Default 10; the window holds at most
    /// [`MAX_STATS_WINDOW_TICKS`] ticks.
    pub stats_window_s: f64,
    /// Ask for real-time scheduling (`SCHED_FIFO` at [`thermode_platform::rt::DEFAULT_FIFO_PRIORITY`]) for the loop
    /// thread and locked memory for the process, where the system grants them ([`LoopHandle::realtime`] says what
    /// was obtained). Default false (`thermode serve` asks unless `--no-realtime`).
    pub realtime: bool,
}

impl Default for LoopConfig {
    fn default() -> Self {
        LoopConfig {
            rate_hz: 100.0,
            release_after_disconnect_s: 2.0,
            command_queue_len: 1024,
            stats_window_s: 10.0,
            realtime: false,
        }
    }
}

impl LoopConfig {
    /// Checks every field: each number against its rule, named by its key.
    pub fn validate(&self) -> Result<(), RuntimeError> {
        let rate = Rule::Within {
            min: MIN_RATE_HZ,
            max: MAX_RATE_HZ,
        };
        rate.check("rate_hz", self.rate_hz)?;
        let grace = Rule::Within { min: 0.0, max: 60.0 };
        grace.check("release_after_disconnect_s", self.release_after_disconnect_s)?;
        Rule::AtLeast { min: 1.0 }.check("command_queue_len", self.command_queue_len as f64)?;
        Rule::Positive.check("stats_window_s", self.stats_window_s)?;
        Ok(())
    }

    /// The period \[s\].
    pub fn period_s(&self) -> f64 {
        1.0 / self.rate_hz
    }

    /// Most ordinary commands applied per tick: [`MAX_COMMANDS_PER_TICK`] per millisecond of period, at least
    /// [`MAX_COMMANDS_PER_TICK`], at most the queue length (64 at 1 kHz, 640 at 100 Hz, the whole default queue at
    /// 62.5 Hz and below).
    pub fn commands_per_tick(&self) -> usize {
        let per_ms = (MAX_COMMANDS_PER_TICK as f64 * self.period_s() * 1000.0).ceil() as usize;
        per_ms.clamp(MAX_COMMANDS_PER_TICK, self.command_queue_len.max(MAX_COMMANDS_PER_TICK))
    }

    fn stats_window_ticks(&self) -> usize {
        ((self.stats_window_s * self.rate_hz).ceil() as usize).clamp(1, MAX_STATS_WINDOW_TICKS)
    }
}

/// A running control loop: its command queue, its published state, and its thread.
#[derive(Debug)]
pub struct LoopHandle {
    commands: CommandSender,
    shared: Arc<Shared>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Option<Result<(), DeviceError>>>>,
    channel_count: usize,
    limits: Vec<StimulusLimits>,
    config: LoopConfig,
    link: Option<Arc<thermode_device::LinkHealth>>,
    parts: Vec<thermode_device::DevicePart>,
    realtime: Realtime,
    self_tests: Vec<SelfTestState>,
}

/// The longest the loop ticks for its channels' start-up self-tests before it takes commands \[s\]: 120 (a test
/// waits up to 20 s for its display to rest and records 2.5 s, or five of a slow sensor's time constants; the
/// channels still testing then are held off, their displays refused as untested).
pub const SELF_TEST_LIMIT_S: f64 = 120.0;

/// What the loop thread reports once its engines are built and their start-up self-tests are done: the published
/// state, each channel's limits, what real-time treatment it obtained, and the self-tests.
type Started = Result<
    (
        Arc<Shared>,
        CommandSender,
        Vec<StimulusLimits>,
        Realtime,
        Vec<SelfTestState>,
    ),
    RuntimeError,
>;

impl LoopHandle {
    /// Starts the loop on its own thread. `engines` builds one engine per device channel on that thread. Each of
    /// `feeds` receives a [`TickRecord`] per tick (the recorder, the bench); the loop never waits for them. The loop
    /// obeys `interlock` (the recorder trips it; `Arc::default()` for one nobody trips). Returns once the engines
    /// are built (their error, if any, is returned) and their start-up self-tests are done
    /// ([`LoopHandle::self_tests`]).
    pub fn spawn(
        config: LoopConfig,
        device: Box<dyn Device + Send>,
        engines: EngineFactory,
        clock: Arc<dyn Clock>,
        feeds: Vec<SyncSender<TickRecord>>,
        interlock: Arc<Interlock>,
    ) -> Result<LoopHandle, RuntimeError> {
        config.validate()?;
        let count = device.channel_count();
        if count == 0 || count > MAX_CHANNELS {
            return Err(RuntimeError::Config(format!(
                "a device of {count} channels (1 to {MAX_CHANNELS})"
            )));
        }
        let link = device.link_health();
        let parts = device.parts();
        let (ready, started) = sync_channel::<Started>(1);
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (stop, config) = (stop.clone(), config.clone());
            std::thread::Builder::new()
                .name("thermode-loop".into())
                .spawn(move || {
                    let built = engines(count)
                        .map_err(RuntimeError::Engine)
                        .and_then(|engines| ControlLoop::new(&config, device, engines, feeds, interlock));
                    let mut control = match built {
                        Ok(control) => control,
                        Err(e) => {
                            let _ = ready.send(Err(e));
                            return None;
                        }
                    };
                    let mut ticker = match Ticker::new(config.period_s(), clock.now_s()) {
                        Ok(ticker) => ticker,
                        Err(e) => {
                            let _ = ready.send(Err(RuntimeError::Config(e.to_string())));
                            return None;
                        }
                    };
                    let limits = control.channel_limits();
                    // After the engines are built (they allocate), before the first tick.
                    let realtime = if config.realtime {
                        request_realtime_alone()
                    } else {
                        Realtime::not_requested("not requested")
                    };
                    // Before anyone holds the handle, so no command can reach a display under test.
                    let self_tests = control.self_tests(clock.as_ref(), &mut ticker, &stop);
                    let _ = ready.send(Ok((control.shared(), control.commands(), limits, realtime, self_tests)));
                    Some(control.run(clock.as_ref(), ticker, &stop))
                })
                .map_err(|source| RuntimeError::Io {
                    context: "cannot start the control-loop thread".into(),
                    source,
                })?
        };
        let (shared, commands, limits, realtime, self_tests) = match started.recv() {
            Ok(result) => result?,
            Err(_) => {
                return Err(RuntimeError::Config(
                    "the control-loop thread ended while starting".into(),
                ))
            }
        };
        Ok(LoopHandle {
            commands,
            shared,
            stop,
            thread: Some(thread),
            channel_count: count,
            limits,
            config,
            link,
            parts,
            realtime,
            self_tests,
        })
    }

    /// Each channel's start-up self-test of its display, as it ended before the loop took its first command.
    pub fn self_tests(&self) -> &[SelfTestState] {
        &self.self_tests
    }

    /// What real-time treatment the loop thread obtained (scheduling, locked memory).
    pub fn realtime(&self) -> &Realtime {
        &self.realtime
    }

    /// The health of the device's link, for a device with one (a serial display).
    pub fn link_health(&self) -> Option<Arc<thermode_device::LinkHealth>> {
        self.link.clone()
    }

    /// The devices the display is made of, each with its channels and link ([`Device::parts`]).
    pub fn device_parts(&self) -> &[thermode_device::DevicePart] {
        &self.parts
    }

    /// Each channel's stimulus limits, as its engine reported them (the loop enforces them).
    pub fn channel_limits(&self) -> &[StimulusLimits] {
        &self.limits
    }

    /// The limits every channel accepts: the intersection of [`LoopHandle::channel_limits`].
    pub fn stimulus_limits(&self) -> StimulusLimits {
        self.limits
            .iter()
            .fold(StimulusLimits::absolute(), |all, one| all.intersection(one))
    }

    /// A sender for the command queue.
    pub fn commands(&self) -> CommandSender {
        self.commands.clone()
    }

    /// The published state.
    pub fn shared(&self) -> Arc<Shared> {
        self.shared.clone()
    }

    /// A copy of the newest snapshot.
    pub fn snapshot(&self) -> Snapshot {
        self.shared.snapshot()
    }

    /// Number of channels.
    pub fn channel_count(&self) -> usize {
        self.channel_count
    }

    /// The loop's configuration.
    pub fn config(&self) -> &LoopConfig {
        &self.config
    }

    /// Stops the loop and waits for its thread: its last act switches every drive to 0 A at once
    /// ([`Device::all_off`]). Returns the device's answer to that, or `None` if the loop had already stopped (or its
    /// thread panicked).
    pub fn stop(&mut self) -> Option<Result<(), DeviceError>> {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.take().and_then(|thread| thread.join().ok().flatten())
    }
}

impl Drop for LoopHandle {
    fn drop(&mut self) {
        let _ = self.stop();
    }
}

/// Per-channel state the loop owns.
struct Slot<E> {
    engine: E,
    /// The engine's limits, read once when the loop starts.
    limits: StimulusLimits,
    reading: Reading,
    /// The engine panicked once: it is never called again and the channel's drive stays at 0 A.
    failed: bool,
    /// The channel's stimulus program, while one is set (kept after its end until the channel's next command, so
    /// that no tick frees it).
    program: Option<Executor>,
}

/// Counters published with the snapshot.
#[derive(Debug, Default, Clone, Copy)]
struct Counters {
    applied: u64,
    refused: u64,
    withdrawn: u64,
    device_errors: u64,
}

/// The loop core, one tick at a time: commands drained, programs started and stepped, every channel read → tick
/// → apply, the recorder fed, the snapshot published. It has no thread and no clock of its own: the real-time
/// driver ([`LoopHandle::spawn`]) steps it on its thread at the clock's deadlines; a virtual-time driver
/// ([`crate::virtual_time::VirtualLoop`]) steps it as fast as the machine goes for the lab's simulated displays and
/// `thermode render`. `D` is the display, `E` each channel's engine (the daemon holds boxed ones).
pub struct ControlLoop<D, E> {
    device: D,
    /// What the device measures or drives itself (read once: it does not change).
    measures: Measures,
    slots: Vec<Slot<E>>,
    status: Vec<ChannelStatus>,
    commands: CommandReceiver,
    /// The sending end of `commands`, handed out by [`ControlLoop::commands`].
    sender: CommandSender,
    /// The newest tick's number (0 before the first).
    tick_index: u64,
    shared: Arc<Shared>,
    feeds: Vec<SyncSender<TickRecord>>,
    /// Answers of this tick's commands, sent after the publish.
    answers: Vec<(crate::reply::ReplySender<Reply>, Reply)>,
    periods: Window,
    work: Window,
    stats: LoopStats,
    counters: Counters,
    release_after_s: f64,
    period_s: f64,
    commands_per_tick: usize,
    /// Commands sent before this sequence number are cancelled (a stop-all with this number was applied).
    cancel_before_seq: u64,
    interlock: Arc<Interlock>,
    /// The interlock's trips already acted on.
    interlock_trips: u64,
    air: Arc<str>,
    /// The label of a channel running a program.
    program_label: Arc<str>,
    last_woke_s: Option<f64>,
    next_stats_s: f64,
    time_s: f64,
    /// The tick whose snapshot a reader kept the loop from publishing, until a retry lands.
    publish_pending: Option<u64>,
}

/// A reading that is not one: before the first successful read (the envelope refuses it as non-finite).
const NO_READING: Reading = Reading {
    sensor_c: f64::NAN,
    hot_side_c: f64::NAN,
    time_s: 0.0,
    sample_seq: 0,
    current_a: 0.0,
    voltage_v: f64::NAN,
    heating_limit_a: f64::INFINITY,
};

impl<D: Device, E: ChannelEngine> ControlLoop<D, E> {
    /// A loop core for `device` with one engine per channel; each of `feeds` receives a [`TickRecord`] per tick
    /// (never waited for); the core obeys `interlock`. Commands reach it through [`ControlLoop::commands`] (drained
    /// at each step) or [`ControlLoop::command`] (applied at once). `config` is its driver's to check: the
    /// real-time driver holds it to [`LoopConfig::validate`], a virtual-time one steps at its caller's rate.
    pub fn new(
        config: &LoopConfig,
        device: D,
        engines: Vec<E>,
        feeds: Vec<SyncSender<TickRecord>>,
        interlock: Arc<Interlock>,
    ) -> Result<Self, RuntimeError> {
        if engines.len() != device.channel_count() {
            return Err(RuntimeError::Config(format!(
                "{} engines for a device of {} channels",
                engines.len(),
                device.channel_count()
            )));
        }
        let air: Arc<str> = Arc::from("air");
        let mut slots = Vec::with_capacity(engines.len());
        for engine in engines {
            slots.push(Slot {
                limits: engine.limits(),
                engine,
                reading: NO_READING,
                failed: false,
                program: None,
            });
        }
        let status: Vec<ChannelStatus> = slots
            .iter()
            .enumerate()
            .map(|(channel, slot)| {
                let (dose, spent) = (slot.engine.dose(), slot.engine.dose_budget_spent());
                air_status(channel, &air, dose, spent)
            })
            .collect();
        let stats = LoopStats {
            rate_hz: config.rate_hz,
            period_s: config.period_s(),
            ..LoopStats::default()
        };
        let shared = Arc::new(Shared::new(Snapshot {
            tick: 0,
            time_s: 0.0,
            channels: status.clone(),
            stats,
            commands_applied: 0,
            commands_refused: 0,
            commands_withdrawn: 0,
            device_errors: 0,
            running: true,
        }));
        let window = config.stats_window_ticks();
        let (queue, queue_receiver) = sync_channel(config.command_queue_len);
        let (urgent, urgent_receiver) = sync_channel(URGENT_QUEUE_LEN);
        Ok(ControlLoop {
            measures: device.measures(),
            device,
            slots,
            status,
            commands: CommandReceiver {
                urgent: urgent_receiver,
                queue: queue_receiver,
            },
            sender: CommandSender::new(queue, urgent),
            tick_index: 0,
            shared,
            feeds,
            answers: Vec::with_capacity(config.commands_per_tick() + URGENT_QUEUE_LEN),
            periods: Window::new(window),
            work: Window::new(window),
            stats,
            counters: Counters::default(),
            release_after_s: config.release_after_disconnect_s,
            period_s: config.period_s(),
            commands_per_tick: config.commands_per_tick(),
            cancel_before_seq: 0,
            interlock_trips: interlock.stops(),
            interlock,
            air,
            program_label: Arc::from("program"),
            last_woke_s: None,
            next_stats_s: STATS_REFRESH_S,
            time_s: 0.0,
            publish_pending: None,
        })
    }

    /// Where commands go: drained at each step, at most [`LoopConfig::commands_per_tick`] (and the whole urgent
    /// lane) per tick.
    pub fn commands(&self) -> CommandSender {
        self.sender.clone()
    }

    /// What the core publishes ([`ControlLoop::publish`]).
    pub fn shared(&self) -> Arc<Shared> {
        self.shared.clone()
    }

    /// Every channel as the newest tick left it.
    pub fn status(&self) -> &[ChannelStatus] {
        &self.status
    }

    /// Each channel's limits, read from its engine when the core was built.
    pub fn channel_limits(&self) -> Vec<StimulusLimits> {
        self.slots.iter().map(|slot| slot.limits).collect()
    }

    /// The display.
    pub fn device(&self) -> &D {
        &self.device
    }

    /// The display, mutable (a virtual-time driver advances a simulated display's physics).
    pub fn device_mut(&mut self) -> &mut D {
        &mut self.device
    }

    /// Channel `channel`'s engine (`None`: no such channel).
    pub fn engine(&self, channel: usize) -> Option<&E> {
        self.slots.get(channel).map(|slot| &slot.engine)
    }

    /// Applies `command` at once, between ticks, as the step would have at the next tick (a virtual-time driver
    /// with nothing else in its queue), stamped with the newest tick; counted like every other command.
    pub fn command(&mut self, command: Command) -> Reply {
        let answer = self.apply(command, self.tick_index);
        self.count(&answer);
        answer
    }

    /// Counts an applied or refused command.
    fn count(&mut self, answer: &Reply) {
        match answer {
            Ok(_) => self.counters.applied += 1,
            Err(_) => self.counters.refused += 1,
        }
    }

    /// Brings the device to loop time `time_s` \[s\] ([`Device::poll`]: a simulated display's physics, a polled
    /// link's requests); the real-time driver calls it before each step.
    pub fn poll(&mut self, time_s: f64) {
        self.device.poll(time_s);
    }

    /// Ticks until `stop`; then every drive to 0 A (the device's answer is returned).
    fn run(mut self, clock: &dyn Clock, mut ticker: Ticker, stop: &AtomicBool) -> Result<(), DeviceError> {
        while let Some(tick) = ticker.wait(clock, stop) {
            self.tick_once(clock, &tick, ticker.missed_total());
            self.retry_publish(clock, ticker.next_deadline_s());
        }
        self.shutdown()
    }

    /// One tick of the loop: the step, its accounting, the snapshot and the answers.
    fn tick_once(&mut self, clock: &dyn Clock, tick: &Tick, missed_total: u64) {
        self.poll(tick.scheduled_s);
        self.step(tick);
        let done_s = clock.now_s();
        self.account(tick, done_s, missed_total);
        self.publish(tick.index);
        self.send_answers();
    }

    /// Sends the answers of the newest step's commands (after its publish, so that a client told "ok" sees the
    /// change in the status).
    pub fn send_answers(&mut self) {
        for (reply, answer) in self.answers.drain(..) {
            reply.send(answer);
        }
    }

    /// Ticks while any channel's start-up self-test is under way (at most [`SELF_TEST_LIMIT_S`] of loop time), then
    /// returns where each stands. Called before the loop's handle exists: no command can arrive meanwhile.
    fn self_tests(&mut self, clock: &dyn Clock, ticker: &mut Ticker, stop: &AtomicBool) -> Vec<SelfTestState> {
        let running = |control: &Self| {
            control
                .slots
                .iter()
                .any(|slot| !slot.failed && slot.engine.self_test_state() == SelfTestState::Running)
        };
        let limit_ticks = (SELF_TEST_LIMIT_S / ticker.period_s()).ceil() as u64;
        for _ in 0..limit_ticks {
            if !running(self) {
                break;
            }
            let Some(tick) = ticker.wait(clock, stop) else { break };
            self.tick_once(clock, &tick, ticker.missed_total());
            self.retry_publish(clock, ticker.next_deadline_s());
        }
        if running(self) {
            // Never past the limit on a display under test: the channels still testing are held off.
            self.stop_all();
        }
        self.slots.iter().map(|slot| slot.engine.self_test_state()).collect()
    }

    /// One tick at loop time `tick.scheduled_s`: commands drained, every channel read → tick → apply, the recorder
    /// fed. The device is where the driver left it ([`ControlLoop::poll`] in real time); the answers wait for
    /// [`ControlLoop::send_answers`].
    pub fn step(&mut self, tick: &Tick) {
        self.time_s = tick.scheduled_s;
        self.tick_index = tick.index;
        let trips = self.interlock.stops();
        if trips != self.interlock_trips {
            self.interlock_trips = trips;
            self.stop_all();
        }
        for status in &mut self.status {
            status.program.next_tick();
        }
        self.drain_commands(tick.index);
        self.expire_leases();
        for channel in 0..self.slots.len() {
            self.tick_channel(channel, tick.dt_s);
        }
        self.complete_response_answers();
        self.feed_record(tick);
    }

    fn tick_channel(&mut self, channel: usize, dt_s: f64) {
        let time_s = self.time_s;
        let link_ok = match self.device.read(channel) {
            Ok(reading) => {
                self.slots[channel].reading = reading;
                self.status[channel].device_cut = None;
                true
            }
            Err(error) => {
                self.counters.device_errors += 1;
                if let DeviceError::Cut { cut, reading, .. } = error {
                    self.status[channel].device_cut = Some(cut);
                    // A device that goes on measuring while cut: the plate is seen (its dose counted from it).
                    if let Some(reading) = reading {
                        self.slots[channel].reading = reading;
                    }
                }
                false
            }
        };
        let slot = &mut self.slots[channel];
        let status = &mut self.status[channel];
        let programmed = program_setpoint(slot, status, dt_s);
        let ticked = if slot.failed {
            None
        } else {
            let (engine, reading) = (&mut slot.engine, &slot.reading);
            catch_unwind(AssertUnwindSafe(|| {
                if let Some(stimulus) = programmed {
                    // Checked when the program was built (its set-points stay within the channel's range and
                    // rate): a refusal cannot happen, and would leave the previous set-point in force.
                    let _ = engine.set_stimulus(stimulus);
                }
                let ticked = engine.tick(time_s, dt_s, reading);
                (ticked, (engine.dose(), engine.dose_budget_spent()))
            }))
            .ok()
        };
        let (command, mut telemetry) = match ticked {
            Some(((command, telemetry), (dose, spent))) => {
                (status.dose, status.dose_budget_spent) = (dose, spent);
                (Some(command), telemetry)
            }
            None => {
                // The engine panicked (a bug): this channel is off for the rest of the session.
                slot.failed = true;
                let mut telemetry = status.telemetry;
                (telemetry.time_s, telemetry.fault) = (time_s, Some(ENGINE_FAILED));
                (None, telemetry)
            }
        };
        let result = match command {
            Some(command) if !status.held_off && link_ok => self.device.apply(channel, &command),
            _ => {
                telemetry.current_a = 0.0;
                self.device.apply(channel, &DriveCommand::off())
            }
        };
        if result.is_err() {
            self.counters.device_errors += 1;
        }
        status.link_ok = link_ok;
        status.engine_failed = slot.failed;
        status.telemetry = unknown_unmeasured(telemetry, self.measures);
        let running = slot.program.as_ref().is_some_and(|e| !e.finished());
        let stop = match (telemetry.fault, status.device_cut) {
            (Some(code), _) => Some(ProgramStop::Fault(code)),
            (None, Some(cut)) => Some(ProgramStop::DeviceCut(cut)),
            (None, None) => None,
        };
        if let (true, Some(stop)) = (running, stop) {
            self.stop_program(channel, stop);
        }
    }

    /// Stops `channel`'s program before its end (a fault, a device cut): the channel renders air, so nothing of
    /// the program resumes when the cause clears (a program that kept its clock through a fault jumped from 38.9 to
    /// 45 °C at 12 °C/s after `clear_fault`, where it asked 2 °C/s), and the tick's mark says why.
    fn stop_program(&mut self, channel: usize, stop: ProgramStop) {
        self.release(channel);
        let mark = &mut self.status[channel].program;
        mark.segment = None;
        mark.stopped = Some(stop);
    }

    /// The urgent lane first (all of it), then at most `commands_per_tick` ordinary commands.
    fn drain_commands(&mut self, tick: u64) {
        for _ in 0..URGENT_QUEUE_LEN {
            match self.commands.urgent.try_recv() {
                Ok(request) => self.take(request, tick),
                Err(TryRecvError::Empty | TryRecvError::Disconnected) => break,
            }
        }
        for _ in 0..self.commands_per_tick {
            match self.commands.queue.try_recv() {
                Ok(request) => self.take(request, tick),
                Err(TryRecvError::Empty | TryRecvError::Disconnected) => return,
            }
        }
    }

    /// Applies one queued command unless its requester withdrew it or a later stop-all cancelled it.
    fn take(&mut self, request: Queued, tick: u64) {
        let Queued {
            command,
            reply,
            claim,
            seq,
        } = request;
        if claim.is_some_and(|claim| !claim.take()) {
            // The requester gave up waiting and was told "busy": it must not happen now.
            self.counters.withdrawn += 1;
            return;
        }
        let answer = if seq < self.cancel_before_seq {
            Err(CommandError::Cancelled)
        } else {
            if matches!(command, Command::StopAll) {
                self.cancel_before_seq = seq;
            }
            self.apply(command, tick)
        };
        self.count(&answer);
        if let Some(reply) = reply {
            // Answered after this tick's snapshot is published, so a client that got "ok" sees the change in
            // the status. Capacity for every command a tick can take is reserved: no allocation.
            self.answers.push((reply, answer));
        }
    }

    fn apply(&mut self, command: Command, tick: u64) -> Reply {
        let applied = Applied {
            tick,
            time_s: self.time_s,
            at_response: None,
        };
        match command {
            Command::Stimulate {
                channel,
                stimulus,
                label,
                owner,
            } => {
                let material = match &stimulus {
                    Stimulus::Touch { material, .. } => Some(MaterialProperties::of(material)),
                    _ => None,
                };
                let (mode, object_c, direct) = match &stimulus {
                    Stimulus::Touch { object_c, .. } => (Mode::Touch, Some(*object_c), None),
                    Stimulus::Direct { temp_c, rate_c_per_s } => (Mode::Direct, None, Some((*temp_c, *rate_c_per_s))),
                    Stimulus::Air => {
                        self.exists(channel)?;
                        self.release(channel);
                        return Ok(applied);
                    }
                };
                self.usable(channel)?;
                self.budget_left(channel)?;
                if self.interlock.engaged() {
                    return Err(CommandError::RecordingFailed);
                }
                if self.interlock.dose_held() {
                    return Err(CommandError::DoseNotRecorded);
                }
                self.set(channel, stimulus)?;
                self.slots[channel].program = None;
                let status = &mut self.status[channel];
                (status.label, status.mode, status.object_c, status.direct) = (label, mode, object_c, direct);
                status.material = material;
                status.program.segment = None;
                claim(status, owner);
            }
            Command::Program { programs, owner } => self.start_programs(programs, owner)?,
            Command::ProgramStop { channel } => {
                self.exists(channel)?;
                // The engine stays in direct mode at the program's last set-point: it holds there.
                self.slots[channel].program = None;
                self.status[channel].program.segment = None;
            }
            Command::Response { channel, kind, value } => return self.respond(channel, kind, value, applied),
            Command::Release { channel } => {
                self.exists(channel)?;
                self.release(channel);
            }
            Command::ClearFault { channel } => {
                self.exists(channel)?;
                let time_s = self.time_s;
                let slot = &mut self.slots[channel];
                let cleared = if slot.failed {
                    Err(EngineError::Failed)
                } else {
                    let engine = &mut slot.engine;
                    catch_unwind(AssertUnwindSafe(|| engine.clear_fault(time_s))).unwrap_or(Err(EngineError::Failed))
                };
                cleared.map_err(|cause| CommandError::FaultPersists { channel, cause })?;
                self.status[channel].telemetry.fault = None;
            }
            Command::StopAll => self.stop_all(),
            Command::ClientGone { client, at_s } => {
                let at_s = at_s.unwrap_or(self.time_s).min(self.time_s) + self.release_after_s;
                for status in &mut self.status {
                    if status.owner == Owner::Client(client) && status.mode != Mode::Air {
                        status.release_at_s = Some(at_s);
                    }
                }
            }
        }
        Ok(applied)
    }

    /// Starts every program of `programs` on this tick, or none: each channel must be usable, have dose budget
    /// left and a temperature to start from, and its program must fit the channel's own limits.
    fn start_programs(&mut self, programs: Vec<(usize, Program)>, owner: Owner) -> Result<(), CommandError> {
        let mut starts_c = [f64::NAN; MAX_CHANNELS];
        for (index, (channel, program)) in programs.iter().enumerate() {
            self.usable(*channel)?;
            self.budget_left(*channel)?;
            program.fits(*channel, &self.slots[*channel].limits)?;
            starts_c[index] = self
                .start_c(*channel)
                .ok_or(CommandError::NoStartTemperature { channel: *channel })?;
        }
        if self.interlock.engaged() {
            return Err(CommandError::RecordingFailed);
        }
        if self.interlock.dose_held() {
            return Err(CommandError::DoseNotRecorded);
        }
        for (index, (channel, program)) in programs.into_iter().enumerate() {
            let rate_c_per_s = self.slots[channel].limits.max_rate_c_per_s;
            let from_c = starts_c[index];
            self.set(
                channel,
                Stimulus::Direct {
                    temp_c: from_c,
                    rate_c_per_s,
                },
            )?;
            self.slots[channel].program = Some(Executor::new(program, from_c));
            let status = &mut self.status[channel];
            let label = self.program_label.clone();
            (status.label, status.mode, status.object_c, status.direct) = (label, Mode::Direct, None, None);
            claim(status, owner);
        }
        Ok(())
    }

    /// Where a program on `channel` starts \[°C\]: the display's newest set-point, else the plate estimate, else
    /// the sensor, within the channel's display range; `None` before any of them is known.
    fn start_c(&self, channel: usize) -> Option<f64> {
        let t = &self.status[channel].telemetry;
        let range = self.slots[channel].limits.display_c;
        [t.display_setpoint_c, t.plate_estimate_c, t.sensor_c]
            .into_iter()
            .find(|c| c.is_finite())
            .map(|c| c.clamp(range.min, range.max))
    }

    /// A response on `channel`: ends a running `until: response` segment (the next segment starts on this tick);
    /// the answer's plate and set-point are filled in once this tick's channels have ticked.
    fn respond(&mut self, channel: usize, kind: ResponseKind, value: Option<f64>, applied: Applied) -> Reply {
        self.exists(channel)?;
        let ended_segment = self.slots[channel].program.as_mut().and_then(Executor::respond);
        self.status[channel].program.response = Some((kind, value, ended_segment));
        Ok(Applied {
            at_response: Some(AtResponse {
                channel,
                sensor_c: f64::NAN,
                plate_estimate_c: f64::NAN,
                setpoint_c: f64::NAN,
                ended_segment,
            }),
            ..applied
        })
    }

    /// Fills each response's answer with its channel as this tick left it.
    fn complete_response_answers(&mut self) {
        for (_, answer) in &mut self.answers {
            if let Ok(Applied {
                at_response: Some(at), ..
            }) = answer
            {
                let t = &self.status[at.channel].telemetry;
                (at.sensor_c, at.plate_estimate_c, at.setpoint_c) =
                    (t.sensor_c, t.plate_estimate_c, t.display_setpoint_c);
            }
        }
    }

    /// Releases every channel and holds its drive at 0 A until its next command.
    fn stop_all(&mut self) {
        for channel in 0..self.slots.len() {
            self.release(channel);
            self.status[channel].held_off = true;
            let slot = &mut self.slots[channel];
            let engine = &mut slot.engine;
            if !slot.failed && catch_unwind(AssertUnwindSafe(|| engine.hold())).is_err() {
                slot.failed = true;
            }
        }
    }

    fn exists(&self, channel: usize) -> Result<(), CommandError> {
        let count = self.slots.len();
        if channel < count {
            Ok(())
        } else {
            Err(CommandError::UnknownChannel { channel, count })
        }
    }

    /// The channel exists and has no latched fault.
    fn usable(&self, channel: usize) -> Result<(), CommandError> {
        self.exists(channel)?;
        if self.slots[channel].failed {
            return Err(CommandError::Faulted {
                channel,
                fault: ENGINE_FAILED,
            });
        }
        match self.status[channel].telemetry.fault {
            Some(fault) => Err(CommandError::Faulted { channel, fault }),
            None => Ok(()),
        }
    }

    /// The channel's thermal-dose budget is not spent (a spent channel is off: only air is accepted).
    fn budget_left(&self, channel: usize) -> Result<(), CommandError> {
        let status = &self.status[channel];
        if status.dose_budget_spent {
            Err(CommandError::DoseBudgetSpent {
                channel,
                cem43_min: status.dose.cem43_min,
            })
        } else {
            Ok(())
        }
    }

    /// Gives `stimulus` to `channel`'s engine once it passes the channel's limits.
    fn set(&mut self, channel: usize, stimulus: Stimulus) -> Result<(), CommandError> {
        let slot = &mut self.slots[channel];
        let refused = |cause| CommandError::Rejected { channel, cause };
        slot.limits.check(&stimulus).map_err(refused)?;
        let engine = &mut slot.engine;
        match catch_unwind(AssertUnwindSafe(|| engine.set_stimulus(stimulus))) {
            Ok(result) => result.map_err(refused),
            Err(_) => {
                slot.failed = true;
                Err(CommandError::Faulted {
                    channel,
                    fault: ENGINE_FAILED,
                })
            }
        }
    }

    /// Air on `channel`; clears the stop-all hold (a release is a command too).
    fn release(&mut self, channel: usize) {
        // An engine must always accept air; if one ever refused, the drive below is still held at 0 A.
        let slot = &mut self.slots[channel];
        slot.program = None;
        let engine = &mut slot.engine;
        let accepted = !slot.failed
            && matches!(
                catch_unwind(AssertUnwindSafe(|| engine.set_stimulus(Stimulus::Air))),
                Ok(Ok(()))
            );
        let status = &mut self.status[channel];
        let label = self.air.clone();
        (status.label, status.mode, status.object_c, status.direct) = (label, Mode::Air, None, None);
        status.material = None;
        (status.owner, status.release_at_s, status.held_off) = (Owner::Nobody, None, !accepted);
        status.program.segment = None;
    }

    /// Releases the contacts whose release time comes before the next tick (so a release is never later than its
    /// time, and at most one period earlier).
    fn expire_leases(&mut self) {
        let horizon_s = self.time_s + self.period_s * (1.0 - 1e-6);
        for channel in 0..self.status.len() {
            if self.status[channel].release_at_s.is_some_and(|at| horizon_s > at) {
                self.release(channel);
            }
        }
    }

    fn feed_record(&mut self, tick: &Tick) {
        if self.feeds.is_empty() {
            return;
        }
        let record = TickRecord {
            tick: tick.index,
            time_s: self.time_s,
            woke_s: tick.woke_s,
            len: self.status.len(),
            rows: std::array::from_fn(|i| match self.status.get(i) {
                Some(s) => RecordRow {
                    label: s.label.clone(),
                    mode: s.mode,
                    object_c: s.object_c,
                    material: s.material,
                    direct: s.direct,
                    held_off: s.held_off,
                    telemetry: s.telemetry,
                    program: s.program,
                },
                None => RecordRow {
                    label: self.air.clone(),
                    mode: Mode::Air,
                    object_c: None,
                    material: None,
                    direct: None,
                    held_off: false,
                    telemetry: crate::snapshot::EMPTY_TELEMETRY,
                    program: crate::snapshot::ProgramMark::default(),
                },
            }),
        };
        let mut closed = None;
        for (index, feed) in self.feeds.iter().enumerate() {
            match feed.try_send(record.clone()) {
                Ok(()) => {}
                Err(TrySendError::Full(_)) => {
                    self.shared.dropped_records.fetch_add(1, Ordering::Relaxed);
                }
                Err(TrySendError::Disconnected(_)) => closed = Some(index),
            }
        }
        if let Some(index) = closed {
            // Happens once per feed in a session (a consumer that went away); not a per-tick cost.
            self.feeds.swap_remove(index);
        }
    }

    /// Timing bookkeeping after a tick's work is done at clock time `done_s`.
    fn account(&mut self, tick: &Tick, done_s: f64, missed_total: u64) {
        if let Some(last) = self.last_woke_s {
            self.periods.record(tick.woke_s - last);
        }
        self.last_woke_s = Some(tick.woke_s);
        self.work.record(done_s - tick.woke_s);
        self.stats.ticks += 1;
        self.stats.missed_deadlines = missed_total;
        if self.time_s >= self.next_stats_s {
            self.stats.period = self.periods.summary();
            self.stats.work = self.work.summary();
            self.next_stats_s = self.time_s + STATS_REFRESH_S;
        }
    }

    /// Publishes the snapshot; a reader holds the lock only while copying it, so a few yields suffice. Never
    /// waits on the lock: after a few attempts the publish is skipped (and counted), then retried between ticks by
    /// the real-time driver.
    pub fn publish(&mut self, tick: u64) {
        self.publish_pending = None;
        for _ in 0..PUBLISH_ATTEMPTS {
            if self.shared.try_publish(|snapshot| self.write(snapshot, tick, true)) {
                return;
            }
            std::thread::yield_now();
        }
        self.shared.skipped_publishes.fetch_add(1, Ordering::Relaxed);
        self.publish_pending = Some(tick);
    }

    /// Retries a publish a reader made the loop skip until it lands or the next deadline comes: a reader never
    /// sees a tick older than the newest for a whole period, and one waiting for a tick on a manual clock (which
    /// moves only when that tick is seen) is not left waiting for ever.
    fn retry_publish(&mut self, clock: &dyn Clock, next_deadline_s: f64) {
        while let Some(tick) = self.publish_pending {
            if clock.now_s() >= next_deadline_s {
                return;
            }
            if self.shared.try_publish(|snapshot| self.write(snapshot, tick, true)) {
                self.publish_pending = None;
                return;
            }
            clock.sleep_until((clock.now_s() + PUBLISH_RETRY_S).min(next_deadline_s));
        }
    }

    fn write(&self, snapshot: &mut Snapshot, tick: u64, running: bool) {
        snapshot.tick = tick;
        snapshot.time_s = self.time_s;
        snapshot.channels.clone_from(&self.status);
        snapshot.stats = self.stats;
        snapshot.commands_applied = self.counters.applied;
        snapshot.commands_refused = self.counters.refused;
        snapshot.commands_withdrawn = self.counters.withdrawn;
        snapshot.device_errors = self.counters.device_errors;
        snapshot.running = running;
    }

    /// Every drive to 0 A at once; the final snapshot says the loop stopped.
    pub fn shutdown(&mut self) -> Result<(), DeviceError> {
        let result = self.device.all_off();
        for status in &mut self.status {
            status.telemetry.current_a = 0.0;
        }
        let tick = self.stats.ticks;
        self.shared
            .publish(|snapshot| self.write(snapshot, tick.saturating_sub(1), false));
        result
    }
}

/// The status of a channel in air, nobody's, drive free.
fn air_status(channel: usize, air: &Arc<str>, dose: DoseLedger, dose_budget_spent: bool) -> ChannelStatus {
    ChannelStatus {
        channel,
        label: air.clone(),
        mode: Mode::Air,
        object_c: None,
        material: None,
        direct: None,
        held_off: false,
        owner: Owner::Nobody,
        release_at_s: None,
        link_ok: true,
        device_cut: None,
        engine_failed: false,
        telemetry: crate::snapshot::EMPTY_TELEMETRY,
        dose,
        dose_budget_spent,
        program: crate::snapshot::ProgramMark::default(),
    }
}

/// The program's set-point of this tick as the engine's direct stimulus (`None` without a running program), its
/// events noted in `status`.
fn program_setpoint<E>(slot: &mut Slot<E>, status: &mut ChannelStatus, dt_s: f64) -> Option<Stimulus> {
    let executor = slot.program.as_mut().filter(|e| !e.finished())?;
    let step = executor.step(dt_s);
    let mark = &mut status.program;
    mark.segment = executor.segment();
    mark.ended = step.ended;
    mark.started = step.started.map(|segment| {
        let program = executor.program();
        (segment, program.segments()[segment].to_c(), program.cutoff_c(segment))
    });
    Some(Stimulus::Direct {
        temp_c: step.setpoint_c,
        rate_c_per_s: slot.limits.max_rate_c_per_s,
    })
}

/// `telemetry` with what the device does not measure or drive itself as unknown (NaN, `null` on the wire): the hot
/// side of a device without one, and, on a temperature-commanded device, the current and the finger estimate built
/// on it (thermode's current does not reach its plate).
fn unknown_unmeasured(mut telemetry: Telemetry, measures: Measures) -> Telemetry {
    if !measures.drive_current {
        telemetry.requested_current_a = f64::NAN;
        telemetry.current_a = f64::NAN;
        telemetry.finger_c = f64::NAN;
    }
    if !measures.hot_side {
        telemetry.hot_side_c = f64::NAN;
    }
    telemetry
}

/// A new stimulus on a channel: it belongs to `owner`, any pending release and the stop-all hold end.
fn claim(status: &mut ChannelStatus, owner: Owner) {
    status.owner = owner;
    status.release_at_s = None;
    status.held_off = false;
}

/// Real-time scheduling and locked memory for the calling (loop) thread, and the last CPU to itself when there are
/// two or more (the network threads keep off it: see [`network_cpus`]).
pub fn request_realtime_alone() -> Realtime {
    let mut realtime = thermode_platform::rt::request_realtime(thermode_platform::rt::DEFAULT_FIFO_PRIORITY, true);
    if let Some((loop_cpu, _)) = thermode_platform::rt::split_cpus() {
        if thermode_platform::rt::pin_current_thread(&[loop_cpu]).is_ok() {
            realtime.cpu = Some(loop_cpu);
        }
    }
    realtime
}

/// The CPUs for every thread but a real-time loop's (all but the last, when there are two or more; see
/// [`LoopConfig::realtime`]).
pub fn network_cpus() -> Option<Vec<usize>> {
    thermode_platform::rt::split_cpus().map(|(_, others)| others)
}
