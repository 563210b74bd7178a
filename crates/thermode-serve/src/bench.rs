//! `thermode bench`: the loop's timing at a given rate and channel count, and the latency from a `touch` message
//! sent over the WebSocket to the drive command that carries it, in loop periods. Figures only: nothing here
//! asserts anything about speed.
//!
//! The daemon runs as `thermode serve` would (real clock, loopback, the given device and engines); a tap on the
//! per-tick records gives every tick's wake time and every channel's contact and drive.
//! - *Period deviation*: |measured wake-to-wake period − nominal period| over the run.
//! - *Lateness*: wake time − deadline.
//! - *Touch latency*: a WebSocket client touches aluminium on one channel after another (and releases it again). For
//!   each touch, counted in ticks after the last tick that began before the message was sent: the first tick
//!   whose drive command is computed with the touch (`applied`, 1 = the very next tick), and the first tick whose
//!   drive current differs from the pre-touch current by more than [`DRIVE_CHANGE_A`] (`drive_changed`); and the
//!   time from sending to the start of that tick, in periods.
//! - *`stop_all` under a program flood* (`flooders` > 0, instead of the touches): that many clients send
//!   999-segment programs on every channel back to back without waiting for their replies (about 17 KB per
//!   channel), while a fresh client connects every touch interval and times its `stop_all` from sending to the
//!   reply (and from connecting to the reply).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver};
use std::sync::Arc;
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use serde::Serialize;
use thermode_device::Device;
use tokio_tungstenite::tungstenite::{Message, Utf8Bytes};

use crate::daemon::{Daemon, DaemonConfig, ServerConfig};
use crate::error::ServeError;
use thermode_model::params::Rule;
use thermode_platform::{Clock, MonotonicClock};
use thermode_runtime::control_loop::LoopConfig;
use thermode_runtime::engine::EngineFactory;
use thermode_runtime::snapshot::TickRecord;
use thermode_runtime::CoreConfig;

/// A drive change larger than this marks the touch's effect on the drive \[A\].
pub const DRIVE_CHANGE_A: f64 = 0.05;

/// What to measure.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchConfig {
    /// Loop rate \[Hz\]. Default 1000.
    pub rate_hz: f64,
    /// Length of the measured run \[s\]. Default 10.
    pub duration_s: f64,
    /// Interval between touches (each is released half-way) \[s\]. Default 0.5.
    pub touch_interval_s: f64,
    /// WebSocket clients subscribed to telemetry at the fastest rate (100 Hz), reading everything. Default 0.
    pub subscribers: usize,
    /// Ask for real-time scheduling and locked memory for the loop ([`LoopConfig::realtime`]). Default false.
    pub realtime: bool,
    /// WebSocket clients flooding the daemon with 999-segment programs; when above 0, `stop_all` from a fresh
    /// client is timed instead of the touches. Default 0.
    pub flooders: usize,
}

impl Default for BenchConfig {
    fn default() -> Self {
        BenchConfig {
            rate_hz: 1000.0,
            duration_s: 10.0,
            touch_interval_s: 0.5,
            subscribers: 0,
            realtime: false,
            flooders: 0,
        }
    }
}

/// Percentiles of a sample.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Spread {
    /// Samples.
    pub count: usize,
    /// Smallest.
    pub min: f64,
    /// Median.
    pub p50: f64,
    /// 99th percentile (nearest rank).
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

impl Spread {
    /// `p50 … µs   p99 … µs   max … µs` of a spread of seconds.
    fn micros(&self) -> String {
        format!(
            "p50 {:8.1} µs   p99 {:8.1} µs   max {:8.1} µs",
            self.p50 * 1e6,
            self.p99 * 1e6,
            self.max * 1e6
        )
    }

    /// The spread of `values` (NaN ignored; all zero when empty).
    pub fn of(values: &[f64]) -> Spread {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return Spread::default();
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let rank = |p: f64| v[((p * n as f64).ceil() as usize).clamp(1, n) - 1];
        Spread {
            count: n,
            min: v[0],
            p50: rank(0.5),
            p99: rank(0.99),
            max: v[n - 1],
        }
    }
}

/// The figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BenchReport {
    /// Loop rate \[Hz\].
    pub rate_hz: f64,
    /// Channels.
    pub channels: usize,
    /// Measured run \[s\].
    pub duration_s: f64,
    /// Ticks run.
    pub ticks: u64,
    /// Deadlines missed (no tick of their own).
    pub missed_deadlines: u64,
    /// Tick records the tap could not take.
    pub dropped_records: u64,
    /// |period − nominal| \[s\].
    pub period_deviation_s: Spread,
    /// Wake time − deadline \[s\].
    pub lateness_s: Spread,
    /// Work per tick (every channel: read, render, control, envelope, apply) \[s\], from the loop's own window.
    pub work_p50_s: f64,
    /// 99th percentile of the work per tick \[s\].
    pub work_p99_s: f64,
    /// Largest work per tick \[s\].
    pub work_max_s: f64,
    /// Touch → first tick computing with it \[ticks\].
    pub touch_applied_ticks: Spread,
    /// Touch → first drive change above [`DRIVE_CHANGE_A`] \[ticks\].
    pub touch_drive_changed_ticks: Spread,
    /// Touch sent → start of the tick that changed the drive \[periods\].
    pub touch_drive_changed_periods: Spread,
    /// Telemetry subscribers during the run.
    pub subscribers: usize,
    /// Telemetry messages they received.
    pub telemetry_messages: u64,
    /// What real-time treatment the loop obtained.
    pub realtime: String,
    /// Clients flooding programs during the run.
    pub flooders: usize,
    /// A fresh client's `stop_all` sent → its reply, under the flood \[s\] (empty without flooders).
    pub stop_all_reply_s: Spread,
    /// The same client's connect → the `stop_all` reply \[s\].
    pub stop_all_connect_reply_s: Spread,
}

impl std::fmt::Display for BenchReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ticks = |s: &Spread| {
            format!(
                "min {:5.2}   p50 {:5.2}   max {:5.2}   (n = {})",
                s.min, s.p50, s.max, s.count
            )
        };
        writeln!(
            f,
            "loop: {} Hz, {} channels, {:.1} s: {} ticks, {} missed deadlines ({:.2} %), {} dropped records",
            self.rate_hz,
            self.channels,
            self.duration_s,
            self.ticks,
            self.missed_deadlines,
            missed_percent(self.ticks, self.missed_deadlines),
            self.dropped_records
        )?;
        writeln!(f, "  real time         {}", self.realtime)?;
        writeln!(
            f,
            "  subscribers       {} at 100 Hz, {} telemetry messages received",
            self.subscribers, self.telemetry_messages
        )?;
        writeln!(f, "  period deviation  {}", self.period_deviation_s.micros())?;
        writeln!(f, "  wake lateness     {}", self.lateness_s.micros())?;
        writeln!(
            f,
            "  work per tick     p50 {:8.1} µs   p99 {:8.1} µs   max {:8.1} µs",
            self.work_p50_s * 1e6,
            self.work_p99_s * 1e6,
            self.work_max_s * 1e6
        )?;
        if self.flooders > 0 {
            let millis = |s: &Spread| {
                let ms = |x: f64| x * 1e3;
                let (p50, p99, max) = (ms(s.p50), ms(s.p99), ms(s.max));
                format!(
                    "p50 {p50:6.1} ms   p99 {p99:6.1} ms   max {max:6.1} ms   (n = {})",
                    s.count
                )
            };
            writeln!(
                f,
                "stop_all from a fresh client, {} clients flooding programs:",
                self.flooders
            )?;
            writeln!(f, "  sent → reply       {}", millis(&self.stop_all_reply_s))?;
            return write!(f, "  connect → reply    {}", millis(&self.stop_all_connect_reply_s));
        }
        writeln!(f, "touch over WebSocket → drive, in loop periods:")?;
        writeln!(f, "  applied (ticks)         {}", ticks(&self.touch_applied_ticks))?;
        writeln!(
            f,
            "  drive changed (ticks)   {}",
            ticks(&self.touch_drive_changed_ticks)
        )?;
        write!(
            f,
            "  drive changed (periods) {}",
            ticks(&self.touch_drive_changed_periods)
        )
    }
}

/// The timer's floor: a thread that only sleeps to the same deadlines, with the same real-time request, and does
/// nothing else. What it misses, the machine misses whatever the loop does (`thermode bench --floor`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FloorReport {
    /// Rate \[Hz\].
    pub rate_hz: f64,
    /// Measured run \[s\].
    pub duration_s: f64,
    /// Ticks woken.
    pub ticks: u64,
    /// Deadlines missed (no wake of their own).
    pub missed_deadlines: u64,
    /// |period − nominal| \[s\].
    pub period_deviation_s: Spread,
    /// Wake time − deadline \[s\].
    pub lateness_s: Spread,
    /// What real-time treatment the thread obtained.
    pub realtime: String,
}

impl std::fmt::Display for FloorReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "timer floor: {} Hz, {:.1} s, an empty loop: {} ticks, {} missed deadlines ({:.2} %)",
            self.rate_hz,
            self.duration_s,
            self.ticks,
            self.missed_deadlines,
            missed_percent(self.ticks, self.missed_deadlines)
        )?;
        writeln!(f, "  real time         {}", self.realtime)?;
        writeln!(f, "  period deviation  {}", self.period_deviation_s.micros())?;
        write!(f, "  wake lateness     {}", self.lateness_s.micros())
    }
}

/// Missed deadlines as a percentage of all deadlines (woken or missed).
fn missed_percent(ticks: u64, missed: u64) -> f64 {
    100.0 * missed as f64 / (ticks + missed).max(1) as f64
}

/// The period deviation |wake-to-wake − `period_s`| and the lateness (wake − deadline) of `(woke_s, deadline_s)`
/// pairs in order \[s\].
fn timing(wakes: &[(f64, f64)], period_s: f64) -> (Spread, Spread) {
    let deviation: Vec<f64> = wakes.windows(2).map(|w| (w[1].0 - w[0].0 - period_s).abs()).collect();
    let lateness: Vec<f64> = wakes.iter().map(|(woke_s, deadline_s)| woke_s - deadline_s).collect();
    (Spread::of(&deviation), Spread::of(&lateness))
}

/// How long a bench may run \[s\].
const BENCH_DURATION: Rule = Rule::Within { min: 0.1, max: 3600.0 };

/// Measures the timer's floor at `rate_hz` for `duration_s` \[s\], asking for real-time scheduling when `realtime`.
pub fn timer_floor(rate_hz: f64, duration_s: f64, realtime: bool) -> Result<FloorReport, ServeError> {
    Rule::Within {
        min: 1.0,
        max: 10_000.0,
    }
    .check("rate_hz", rate_hz)?;
    BENCH_DURATION.check("duration_s", duration_s)?;
    let thread = std::thread::Builder::new()
        .name("thermode-floor".into())
        .spawn(move || {
            let obtained = if realtime {
                thermode_runtime::control_loop::request_realtime_alone()
            } else {
                thermode_platform::rt::Realtime::not_requested("not asked (--realtime)")
            };
            let clock = MonotonicClock::new();
            let period_s = 1.0 / rate_hz;
            let stop = std::sync::atomic::AtomicBool::new(false);
            let mut ticker = thermode_platform::Ticker::new(period_s, clock.now_s() + period_s)
                .map_err(|e| ServeError::Config(e.to_string()))?;
            let mut wakes = Vec::new();
            while let Some(tick) = ticker.wait(&clock, &stop) {
                wakes.push((tick.woke_s, tick.scheduled_s));
                if tick.scheduled_s - ticker.start_s() >= duration_s {
                    break;
                }
            }
            let (period_deviation_s, lateness_s) = timing(&wakes, period_s);
            Ok(FloorReport {
                rate_hz,
                duration_s,
                ticks: wakes.len() as u64,
                missed_deadlines: ticker.missed_total(),
                period_deviation_s,
                lateness_s,
                realtime: obtained.describe(),
            })
        });
    let thread = thread.map_err(|source| ServeError::Io {
        context: "cannot start the floor thread".into(),
        source,
    })?;
    thread
        .join()
        .unwrap_or_else(|_| Err(ServeError::Config("the floor thread panicked".into())))
}

/// A touch sent by the bench client.
#[derive(Debug, Clone, Copy)]
struct Sent {
    channel: usize,
    at_s: f64,
}

/// One tick as the bench keeps it.
struct Row {
    woke_s: f64,
    deadline_s: f64,
    air: [bool; thermode_device::MAX_CHANNELS],
    current_a: [f64; thermode_device::MAX_CHANNELS],
}

/// Runs the bench on `device` with `engines`.
pub fn run(
    config: &BenchConfig,
    device: Box<dyn Device + Send>,
    engines: EngineFactory,
) -> Result<BenchReport, ServeError> {
    BENCH_DURATION.check("duration_s", config.duration_s)?;
    let interval = Rule::Within { min: 0.01, max: 60.0 };
    interval.check("touch_interval_s", config.touch_interval_s)?;
    let channels = device.channel_count();
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    let (tap, records) = sync_channel::<TickRecord>(1 << 16);
    let collector = std::thread::spawn(move || collect(records));
    let daemon_config = DaemonConfig {
        core: CoreConfig {
            loop_config: LoopConfig {
                rate_hz: config.rate_hz,
                realtime: config.realtime,
                ..LoopConfig::default()
            },
            ..CoreConfig::default()
        },
        server: ServerConfig {
            port: 0,
            osc_port: None,
            net: crate::api::NetLimits {
                max_connections: config.subscribers + config.flooders + 2,
                max_http_connections: (config.subscribers + config.flooders + 2).max(127) + 1,
                ..crate::api::NetLimits::default()
            },
            ..ServerConfig::default()
        },
        device_label: "bench".into(),
        taps: vec![tap],
        ..DaemonConfig::default()
    };
    let daemon = Daemon::start(daemon_config, device, engines, clock.clone())?;
    let realtime = daemon.realtime().map(|r| r.describe()).unwrap_or_default();
    let sent = drive_client(&daemon, config, channels, clock.as_ref());
    let snapshot = daemon.snapshot();
    let dropped_records = daemon.dropped_records();
    daemon.shutdown()?;
    let rows = collector
        .join()
        .map_err(|_| ServeError::Config("bench collector panicked".into()))?;
    let driven = sent?;
    let stats = snapshot.map(|s| s.stats).unwrap_or_default();
    let mut report = report(config, channels, &rows, &driven.touches, stats);
    report.dropped_records = dropped_records;
    report.subscribers = config.subscribers;
    report.telemetry_messages = driven.telemetry_messages;
    report.realtime = realtime;
    report.flooders = config.flooders;
    report.stop_all_reply_s = Spread::of(&driven.stop_all_reply_s);
    report.stop_all_connect_reply_s = Spread::of(&driven.stop_all_connect_reply_s);
    Ok(report)
}

fn collect(records: Receiver<TickRecord>) -> Vec<Row> {
    let mut rows = Vec::with_capacity(1 << 16);
    while let Ok(record) = records.recv() {
        let mut row = Row {
            woke_s: record.woke_s,
            deadline_s: record.time_s,
            air: [true; thermode_device::MAX_CHANNELS],
            current_a: [0.0; thermode_device::MAX_CHANNELS],
        };
        for (i, r) in record.channels().iter().enumerate() {
            row.air[i] = r.mode == thermode_runtime::snapshot::Mode::Air;
            row.current_a[i] = r.telemetry.current_a;
        }
        rows.push(row);
    }
    rows
}

/// What the clients measured.
struct Driven {
    /// When each touch was sent (none under a flood).
    touches: Vec<Sent>,
    /// Telemetry messages the subscribers received.
    telemetry_messages: u64,
    /// `stop_all` sent → reply \[s\] (only under a flood).
    stop_all_reply_s: Vec<f64>,
    /// Connect → `stop_all` reply \[s\].
    stop_all_connect_reply_s: Vec<f64>,
}

/// The bench client's I/O error.
fn client_error(e: impl std::fmt::Display) -> ServeError {
    ServeError::Io {
        context: "bench client".into(),
        source: std::io::Error::other(e.to_string()),
    }
}

/// Touches and releases over a WebSocket for the run's duration (or, with flooders, times a fresh client's
/// `stop_all` as often), with `config.subscribers` telemetry subscribers reading alongside.
fn drive_client(
    daemon: &Daemon,
    config: &BenchConfig,
    channels: usize,
    clock: &dyn Clock,
) -> Result<Driven, ServeError> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(client_error)?;
    // The clients stand for other processes: off the loop's CPU, as the daemon's network threads are.
    if let Some(cpus) = config
        .realtime
        .then(thermode_runtime::control_loop::network_cpus)
        .flatten()
    {
        let _ = thermode_platform::rt::pin_current_thread(&cpus);
    }
    let url = format!("ws://{}/api/ws", daemon.http_addr());
    let received = Arc::new(AtomicU64::new(0));
    let flooding = Arc::new(AtomicBool::new(true));
    let program = flood_program(channels);
    let flooders: Vec<_> = (0..config.flooders)
        .map(|_| {
            let (url, program, flooding) = (url.clone(), program.clone(), flooding.clone());
            std::thread::spawn(move || flood(&url, program, &flooding))
        })
        .collect();
    let driven = runtime.block_on(async {
        let mut subscribers = Vec::new();
        for id in 0..config.subscribers {
            let (mut sub, _) = tokio_tungstenite::connect_async(url.as_str())
                .await
                .map_err(client_error)?;
            let text = format!(r#"{{"type":"subscribe","id":{id},"rate_hz":100}}"#);
            sub.send(Message::Text(text.into())).await.map_err(client_error)?;
            let received = received.clone();
            subscribers.push(tokio::spawn(async move {
                while let Some(Ok(message)) = sub.next().await {
                    if message.is_text() {
                        received.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }));
        }
        tokio::time::sleep(Duration::from_millis(500)).await; // settle
        received.store(0, Ordering::Relaxed);
        let mut driven = if config.flooders > 0 {
            time_stop_all(&url, config, clock).await
        } else {
            touch_and_release(&url, config, channels, clock).await
        }?;
        for subscriber in subscribers {
            subscriber.abort();
        }
        driven.telemetry_messages = received.load(Ordering::Relaxed);
        Ok(driven)
    });
    flooding.store(false, Ordering::Relaxed);
    for flooder in flooders {
        let _ = flooder.join();
    }
    driven
}

/// Touches aluminium on one channel after another and releases it again, for the run's duration.
async fn touch_and_release(
    url: &str,
    config: &BenchConfig,
    channels: usize,
    clock: &dyn Clock,
) -> Result<Driven, ServeError> {
    let (mut ws, _) = tokio_tungstenite::connect_async(url).await.map_err(client_error)?;
    let start_s = clock.now_s();
    let mut touches = Vec::new();
    let mut k = 0usize;
    while clock.now_s() - start_s < config.duration_s {
        let channel = k % channels;
        for (kind, extra) in [("touch", r#","material":"aluminium""#), ("release", "")] {
            let text = format!(r#"{{"type":"{kind}","id":{k},"channel":{channel}{extra}}}"#);
            let at_s = clock.now_s();
            ws.send(Message::Text(text.into())).await.map_err(client_error)?;
            let _reply = ws.next().await;
            if kind == "touch" {
                touches.push(Sent { channel, at_s });
            }
            tokio::time::sleep(Duration::from_secs_f64(config.touch_interval_s / 2.0)).await;
        }
        k += 1;
    }
    let _ = ws.close(None).await;
    Ok(Driven {
        touches,
        telemetry_messages: 0,
        stop_all_reply_s: Vec::new(),
        stop_all_connect_reply_s: Vec::new(),
    })
}

/// A fresh client every touch interval: connects, sends `stop_all`, waits for its reply.
async fn time_stop_all(url: &str, config: &BenchConfig, clock: &dyn Clock) -> Result<Driven, ServeError> {
    let (mut reply_s, mut connect_reply_s) = (Vec::new(), Vec::new());
    let start_s = clock.now_s();
    while clock.now_s() - start_s < config.duration_s {
        let connect_s = clock.now_s();
        let (mut ws, _) = tokio_tungstenite::connect_async(url).await.map_err(client_error)?;
        let sent_s = clock.now_s();
        let text = r#"{"type":"stop_all","id":"stop"}"#;
        ws.send(Message::Text(text.into())).await.map_err(client_error)?;
        while let Some(Ok(message)) = ws.next().await {
            if message.to_text().is_ok_and(|t| t.contains(r#""id":"stop""#)) {
                let replied_s = clock.now_s();
                reply_s.push(replied_s - sent_s);
                connect_reply_s.push(replied_s - connect_s);
                break;
            }
        }
        let _ = ws.close(None).await;
        tokio::time::sleep(Duration::from_secs_f64(config.touch_interval_s)).await;
    }
    Ok(Driven {
        touches: Vec::new(),
        telemetry_messages: 0,
        stop_all_reply_s: reply_s,
        stop_all_connect_reply_s: connect_reply_s,
    })
}

/// A `program` of [`thermode_runtime::program::MAX_SEGMENTS`] 1 ms holds on each of `channels` channels.
fn flood_program(channels: usize) -> Utf8Bytes {
    let holds = vec![r#"{"hold_s":0.001}"#; thermode_runtime::program::MAX_SEGMENTS].join(",");
    let per_channel: Vec<String> = (0..channels).map(|c| format!(r#""{c}":[{holds}]"#)).collect();
    format!(
        r#"{{"type":"program","id":1,"channels":{{{}}}}}"#,
        per_channel.join(",")
    )
    .into()
}

/// One flooding client on its own thread: sends `program` back to back, reading (and dropping) the replies,
/// while `flooding` holds.
fn flood(url: &str, program: Utf8Bytes, flooding: &AtomicBool) {
    let Ok(runtime) = tokio::runtime::Builder::new_current_thread().enable_all().build() else {
        return;
    };
    runtime.block_on(async {
        let Ok((ws, _)) = tokio_tungstenite::connect_async(url).await else {
            return;
        };
        let (mut sink, mut replies) = ws.split();
        let drain = tokio::spawn(async move { while let Some(Ok(_)) = replies.next().await {} });
        while flooding.load(Ordering::Relaxed) {
            if sink.send(Message::Text(program.clone())).await.is_err() {
                break;
            }
            tokio::task::yield_now().await;
        }
        drain.abort();
    });
}

fn report(
    config: &BenchConfig,
    channels: usize,
    rows: &[Row],
    sent: &[Sent],
    stats: thermode_runtime::snapshot::LoopStats,
) -> BenchReport {
    let period_s = 1.0 / config.rate_hz;
    let wakes: Vec<(f64, f64)> = rows.iter().map(|r| (r.woke_s, r.deadline_s)).collect();
    let (period_deviation_s, lateness_s) = timing(&wakes, period_s);
    let mut applied = Vec::new();
    let mut changed = Vec::new();
    let mut changed_periods = Vec::new();
    for touch in sent {
        let Some(before) = rows.iter().rposition(|r| r.woke_s < touch.at_s) else {
            continue;
        };
        let ch = touch.channel;
        let base_a = rows[before].current_a[ch];
        let after = &rows[before + 1..];
        if let Some(k) = after.iter().position(|r| !r.air[ch]) {
            applied.push((k + 1) as f64);
        }
        if let Some(k) = after
            .iter()
            .position(|r| (r.current_a[ch] - base_a).abs() > DRIVE_CHANGE_A)
        {
            changed.push((k + 1) as f64);
            changed_periods.push((after[k].woke_s - touch.at_s) / period_s);
        }
    }
    let first = rows.first().map_or(0.0, |r| r.woke_s);
    let last = rows.last().map_or(0.0, |r| r.woke_s);
    BenchReport {
        rate_hz: config.rate_hz,
        channels,
        duration_s: last - first,
        ticks: stats.ticks,
        missed_deadlines: stats.missed_deadlines,
        dropped_records: 0,
        period_deviation_s,
        lateness_s,
        work_p50_s: stats.work.p50_s,
        work_p99_s: stats.work.p99_s,
        work_max_s: stats.work.max_s,
        touch_applied_ticks: Spread::of(&applied),
        touch_drive_changed_ticks: Spread::of(&changed),
        touch_drive_changed_periods: Spread::of(&changed_periods),
        subscribers: 0,
        telemetry_messages: 0,
        realtime: String::new(),
        flooders: 0,
        stop_all_reply_s: Spread::default(),
        stop_all_connect_reply_s: Spread::default(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_of_a_known_sample() {
        let s = Spread::of(&[3.0, 1.0, 2.0, f64::NAN]);
        assert_eq!((s.count, s.min, s.p50, s.max), (3, 1.0, 2.0, 3.0));
        assert_eq!(Spread::of(&[]), Spread::default());
    }
}
