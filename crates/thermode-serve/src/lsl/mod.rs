//! `serve --lsl`: Lab Streaming Layer outlets of the daemon, fed off the loop thread.
//!
//! Two streams per daemon (one display):
//! - **telemetry** (`thermode telemetry`, type `Thermal`, `double64`, nominal rate = the loop rate): per display
//!   channel `c`, five channels `ch{c}_target_c`, `ch{c}_skin_c`, `ch{c}_sensor_c`, `ch{c}_setpoint_c` (°C) and
//!   `ch{c}_current_a` (A), in that order ([`TELEMETRY_FIELDS`]), labelled with unit and type in the stream's XML
//!   description (`<desc><channels><channel><label/><unit/><type/>`);
//! - **markers** (`thermode markers`, type `Markers`, one string channel, irregular): one JSON object per event —
//!   `touch` (channel, material, object_temp_c), `release`, `setpoint` (channel, temp_c, rate_c_per_s), `stop`,
//!   `fault` (channel, code), `fault_cleared`, and the clients' own markers (`marker`: text, channel), sent with
//!   the API request `marker` (docs/api.md).
//!
//! The loop hands every tick's [`TickRecord`] to a bounded queue ([`LSL_QUEUE_TICKS`]) and never waits (a full
//! queue drops the record and counts it, as for the recorder). The streaming thread pushes each tick as one
//! telemetry sample and derives the loop's events by comparing each channel's row with the previous tick's.
//!
//! **Timestamps.** Every sample is stamped with the LSL clock at its tick: loop time + [`LslClock::offset_s`],
//! the offset measured once at the start (both are the system's monotonic clock, so it holds). A loop event is
//! stamped with the time of the tick whose sample first shows it (the same timestamp as that telemetry sample); a
//! client marker with the loop clock's time when the daemon received it, so it lies within one loop period of the
//! telemetry sample of the tick that follows.

pub mod ffi;

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use serde_json::json;
use thermode_platform::Clock;

pub use ffi::{ChannelSpec, Liblsl, LslError, Outlet, StreamSpec};
use thermode_runtime::snapshot::{Mode, RecordRow, TickRecord};

/// Capacity of the queue from the loop to the streaming thread \[ticks\] (10 s at 100 Hz).
pub const LSL_QUEUE_TICKS: usize = 1024;
/// Capacity of the queue of client markers \[markers\]; a marker sent while it is full is refused (`busy`).
pub const MARKER_QUEUE_LEN: usize = 256;
/// Longest client marker text \[characters\].
pub const MAX_MARKER_CHARS: usize = 1024;
/// The telemetry fields of each display channel, in stream order: (suffix, unit, LSL type).
pub const TELEMETRY_FIELDS: [(&str, &str, &str); 5] = [
    ("target_c", "degC", "Temperature"),
    ("skin_c", "degC", "Temperature"),
    ("sensor_c", "degC", "Temperature"),
    ("setpoint_c", "degC", "Temperature"),
    ("current_a", "A", "Current"),
];

/// How loop time maps to the LSL clock: `lsl = loop + offset_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LslClock {
    /// LSL clock minus loop clock \[s\], measured at the start.
    pub offset_s: f64,
    /// The LSL clock at the start \[s\].
    pub lsl_at_start_s: f64,
    /// The loop clock at the same instant \[s\].
    pub loop_at_start_s: f64,
}

impl LslClock {
    /// The LSL time of loop time `loop_s` \[s\].
    pub fn lsl_time_s(&self, loop_s: f64) -> f64 {
        loop_s + self.offset_s
    }
}

/// What the streams are called and what they carry.
#[derive(Debug, Clone, PartialEq)]
pub struct LslConfig {
    /// Stream name prefix. Default `thermode`: streams `thermode telemetry` and `thermode markers`.
    pub name: String,
    /// Source id prefix (a recorder reconnects to the same source); default `thermode`.
    pub source_id: String,
    /// The loop rate \[Hz\] (the telemetry stream's nominal rate). Default 100.
    pub rate_hz: f64,
    /// Number of display channels. Default 1.
    pub channels: usize,
    /// The device label (`sim`, `serial:…`), written into the description. Default empty.
    pub device: String,
}

impl Default for LslConfig {
    fn default() -> Self {
        LslConfig {
            name: "thermode".into(),
            source_id: "thermode".into(),
            rate_hz: 100.0,
            channels: 1,
            device: String::new(),
        }
    }
}

/// A client's marker, on its way to the marker stream.
#[derive(Debug, Clone, PartialEq)]
pub struct ClientMarker {
    /// Loop time when the daemon received it \[s\].
    pub time_s: f64,
    /// The text.
    pub text: String,
    /// The channel it concerns, if any.
    pub channel: Option<usize>,
}

/// Counters of the streaming thread.
#[derive(Debug, Default)]
pub struct LslCounters {
    /// Telemetry samples pushed.
    pub samples: AtomicU64,
    /// Markers pushed (loop events and client markers).
    pub markers: AtomicU64,
    /// Pushes liblsl refused.
    pub failed: AtomicU64,
}

/// The sending side of the client markers, held by the network side.
#[derive(Debug, Clone)]
pub struct MarkerSender {
    queue: SyncSender<ClientMarker>,
    clock: LslClock,
}

impl MarkerSender {
    /// Queues a marker; false if the queue is full or the streams are gone.
    pub fn send(&self, marker: ClientMarker) -> bool {
        !matches!(
            self.queue.try_send(marker),
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_))
        )
    }

    /// The clock mapping of the streams.
    pub fn clock(&self) -> LslClock {
        self.clock
    }
}

/// The running streams: their thread, the tick feed to hand to the loop, the marker sender.
#[derive(Debug)]
pub struct LslStreams {
    thread: Option<JoinHandle<()>>,
    /// Set when the streams are dropped without [`LslStreams::finish`] (a start that failed later): the thread
    /// ends without waiting for the loop's feed to close.
    stop: Arc<AtomicBool>,
    clock: LslClock,
    counters: Arc<LslCounters>,
    library: String,
}

/// What [`LslStreams::start`] returns besides the streams: the loop's feed and the network side's marker sender.
pub type LslStart = (LslStreams, SyncSender<TickRecord>, MarkerSender);

impl LslStreams {
    /// Loads liblsl ([`Liblsl::locate`]), creates both outlets and starts the streaming thread. `clock` is the
    /// loop's clock (for the offset to the LSL clock).
    pub fn start(config: &LslConfig, clock: &dyn Clock) -> Result<LslStart, LslError> {
        let lib = Liblsl::locate()?;
        let telemetry = lib.double_outlet(&telemetry_spec(config))?;
        let markers = lib.string_outlet(&marker_spec(config))?;
        let (lsl_at_start_s, loop_at_start_s) = (lib.local_clock(), clock.now_s());
        let lsl_clock = LslClock {
            offset_s: lsl_at_start_s - loop_at_start_s,
            lsl_at_start_s,
            loop_at_start_s,
        };
        let (feed, ticks) = sync_channel(LSL_QUEUE_TICKS);
        let (queue, client_markers) = sync_channel(MARKER_QUEUE_LEN);
        let counters = Arc::new(LslCounters::default());
        let stop = Arc::new(AtomicBool::new(false));
        let pusher = Pusher {
            stop: stop.clone(),
            telemetry,
            markers,
            clock: lsl_clock,
            counters: counters.clone(),
            previous: Vec::new(),
            values: Vec::with_capacity(config.channels * TELEMETRY_FIELDS.len()),
        };
        let thread = std::thread::Builder::new()
            .name("thermode-lsl".into())
            .spawn(move || pusher.run(&ticks, &client_markers))
            .map_err(|e| LslError::Create {
                what: format!("streaming thread ({e})"),
            })?;
        let streams = LslStreams {
            thread: Some(thread),
            stop,
            clock: lsl_clock,
            counters,
            library: lib.path().to_string(),
        };
        let sender = MarkerSender {
            queue,
            clock: lsl_clock,
        };
        Ok((streams, feed, sender))
    }

    /// The clock mapping.
    pub fn clock(&self) -> LslClock {
        self.clock
    }

    /// The streaming thread's counters.
    pub fn counters(&self) -> Arc<LslCounters> {
        self.counters.clone()
    }

    /// Where liblsl was loaded from.
    pub fn library(&self) -> &str {
        &self.library
    }

    /// Waits for the streaming thread, which ends once the loop has stopped (its feed closed) and every queued
    /// record and marker is pushed.
    pub fn finish(mut self) {
        self.join();
    }

    fn join(&mut self) {
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for LslStreams {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        self.join();
    }
}

/// The telemetry stream's description.
pub fn telemetry_spec(config: &LslConfig) -> StreamSpec {
    let channels = (0..config.channels)
        .flat_map(|c| {
            TELEMETRY_FIELDS.iter().map(move |(suffix, unit, kind)| ChannelSpec {
                label: format!("ch{c}_{suffix}"),
                unit: (*unit).into(),
                kind: (*kind).into(),
            })
        })
        .collect();
    StreamSpec {
        name: format!("{} telemetry", config.name),
        kind: "Thermal".into(),
        rate_hz: config.rate_hz,
        source_id: format!("{}-telemetry", config.source_id),
        channels,
        fields: description_fields(config),
    }
}

/// The marker stream's description.
pub fn marker_spec(config: &LslConfig) -> StreamSpec {
    StreamSpec {
        name: format!("{} markers", config.name),
        kind: "Markers".into(),
        rate_hz: 0.0,
        source_id: format!("{}-markers", config.source_id),
        channels: vec![ChannelSpec {
            label: "event".into(),
            unit: "json".into(),
            kind: "Marker".into(),
        }],
        fields: description_fields(config),
    }
}

fn description_fields(config: &LslConfig) -> Vec<(String, String)> {
    vec![
        ("manufacturer".into(), "thermode".into()),
        ("software_version".into(), env!("CARGO_PKG_VERSION").into()),
        ("device".into(), config.device.clone()),
        ("display_channels".into(), config.channels.to_string()),
    ]
}

/// The streaming thread's state.
struct Pusher {
    stop: Arc<AtomicBool>,
    telemetry: Outlet,
    markers: Outlet,
    clock: LslClock,
    counters: Arc<LslCounters>,
    /// The previous tick's rows (for the events).
    previous: Vec<RecordRow>,
    values: Vec<f64>,
}

impl Pusher {
    fn run(mut self, ticks: &Receiver<TickRecord>, client_markers: &Receiver<ClientMarker>) {
        loop {
            match ticks.recv_timeout(Duration::from_millis(20)) {
                Ok(record) => self.tick(&record),
                Err(RecvTimeoutError::Timeout) if self.stop.load(Ordering::Relaxed) => break,
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
            while let Ok(marker) = client_markers.try_recv() {
                self.client_marker(&marker);
            }
        }
        while let Ok(marker) = client_markers.try_recv() {
            self.client_marker(&marker);
        }
    }

    fn tick(&mut self, record: &TickRecord) {
        let stamp = self.clock.lsl_time_s(record.time_s);
        let rows = record.channels();
        for event in events(&self.previous, rows) {
            self.push_marker(&event, stamp);
        }
        for event in crate::program_events::of_record(record) {
            self.push_marker(&serde_json::to_string(&event).unwrap_or_default(), stamp);
        }
        self.values.clear();
        for row in rows {
            let t = &row.telemetry;
            let values = [t.target_skin_c, t.skin_c, t.sensor_c, t.display_setpoint_c, t.current_a];
            self.values.extend_from_slice(&values);
        }
        if self.telemetry.push_doubles(&self.values, stamp) {
            self.counters.samples.fetch_add(1, Ordering::Relaxed);
        } else {
            self.counters.failed.fetch_add(1, Ordering::Relaxed);
        }
        self.previous.clear();
        self.previous.extend_from_slice(rows);
    }

    fn client_marker(&mut self, marker: &ClientMarker) {
        let text = json!({"event": "marker", "text": marker.text, "channel": marker.channel}).to_string();
        self.push_marker(&text, self.clock.lsl_time_s(marker.time_s));
    }

    fn push_marker(&self, text: &str, stamp: f64) {
        if self.markers.push_string(text, stamp) {
            self.counters.markers.fetch_add(1, Ordering::Relaxed);
        } else {
            self.counters.failed.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// The loop's events between two ticks' rows, as marker texts (JSON), in channel order; a `stop` (some channel
/// newly held off) comes first. The first tick (`previous` empty) has no events.
pub fn events(previous: &[RecordRow], rows: &[RecordRow]) -> Vec<String> {
    let mut out = Vec::new();
    if previous.len() != rows.len() {
        return out;
    }
    if previous
        .iter()
        .zip(rows)
        .any(|(before, now)| now.held_off && !before.held_off)
    {
        out.push(json!({"event": "stop"}).to_string());
    }
    for (channel, (before, now)) in previous.iter().zip(rows).enumerate() {
        if let Some(event) = stimulus_event(channel, before, now) {
            out.push(event);
        }
        let (was, is) = (before.telemetry.fault, now.telemetry.fault);
        if is.is_some() && was != is {
            let (code, name) = is.map_or((None, None), |f| (Some(f.code()), Some(format!("{f:?}"))));
            out.push(json!({"event": "fault", "channel": channel, "code": code, "name": name}).to_string());
        } else if was.is_some() && is.is_none() {
            out.push(json!({"event": "fault_cleared", "channel": channel}).to_string());
        }
    }
    out
}

/// A touch, set-point or release of `channel` between two rows (a program's start is told by its own events).
fn stimulus_event(channel: usize, before: &RecordRow, now: &RecordRow) -> Option<String> {
    if now.program.started.is_some() {
        return None;
    }
    let changed = before.mode != now.mode
        || before.label != now.label
        || before.object_c != now.object_c
        || before.direct != now.direct;
    if !changed {
        return None;
    }
    let event = match now.mode {
        Mode::Touch => json!({
            "event": "touch", "channel": channel, "material": &*now.label, "object_temp_c": now.object_c,
        }),
        Mode::Direct => {
            let (temp_c, rate_c_per_s) = now.direct.map_or((None, None), |(t, r)| (Some(t), Some(r)));
            json!({"event": "setpoint", "channel": channel, "temp_c": temp_c, "rate_c_s": rate_c_per_s})
        }
        Mode::Air => json!({"event": "release", "channel": channel}),
    };
    Some(event.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use thermode_runtime::snapshot::EMPTY_TELEMETRY;
    use thermode_safety::FaultCode;

    fn row(mode: Mode, label: &str) -> RecordRow {
        RecordRow {
            label: Arc::from(label),
            mode,
            object_c: (mode == Mode::Touch).then_some(23.0),
            material: None,
            direct: (mode == Mode::Direct).then_some((36.0, 2.0)),
            held_off: false,
            telemetry: EMPTY_TELEMETRY,
            program: thermode_runtime::snapshot::ProgramMark::default(),
        }
    }

    fn kinds(events: &[String]) -> Vec<String> {
        events
            .iter()
            .map(|e| {
                serde_json::from_str::<serde_json::Value>(e).unwrap()["event"]
                    .as_str()
                    .unwrap()
                    .to_string()
            })
            .collect()
    }

    #[test]
    fn the_first_tick_and_an_unchanged_tick_have_no_events() {
        let rows = vec![row(Mode::Air, "air"), row(Mode::Touch, "wood")];
        assert!(events(&[], &rows).is_empty());
        assert!(events(&rows, &rows).is_empty());
    }

    #[test]
    fn touch_setpoint_release_stop_and_faults_are_named_per_channel() {
        let before = vec![row(Mode::Air, "air"), row(Mode::Touch, "wood"), row(Mode::Air, "air")];
        let mut now = vec![
            row(Mode::Touch, "aluminium"),
            row(Mode::Air, "air"),
            row(Mode::Direct, "direct"),
        ];
        now[2].telemetry.fault = Some(FaultCode::SensorOpen);
        now[1].held_off = true;
        let got = events(&before, &now);
        assert_eq!(
            kinds(&got),
            ["stop", "touch", "release", "setpoint", "fault"],
            "{got:?}"
        );
        let touch: serde_json::Value = serde_json::from_str(&got[1]).unwrap();
        assert_eq!(touch["channel"], 0);
        assert_eq!(touch["material"], "aluminium");
        let fault: serde_json::Value = serde_json::from_str(&got[4]).unwrap();
        assert_eq!(fault["code"], FaultCode::SensorOpen.code());
        let cleared = events(
            &now,
            &[
                row(Mode::Touch, "aluminium"),
                row(Mode::Air, "air"),
                row(Mode::Direct, "direct"),
            ],
        );
        assert_eq!(kinds(&cleared), ["fault_cleared"], "{cleared:?}");
    }

    #[test]
    fn a_new_setpoint_while_in_direct_mode_is_an_event() {
        let before = vec![row(Mode::Direct, "direct")];
        let mut now = before.clone();
        now[0].direct = Some((30.0, 1.0));
        assert_eq!(kinds(&events(&before, &now)), ["setpoint"]);
    }

    #[test]
    fn the_telemetry_stream_labels_five_fields_per_channel_with_units() {
        let spec = telemetry_spec(&LslConfig {
            channels: 2,
            ..LslConfig::default()
        });
        assert_eq!(spec.channels.len(), 10);
        assert_eq!(spec.channels[6].label, "ch1_skin_c");
        assert_eq!(spec.channels[9].unit, "A");
        assert_eq!(spec.rate_hz, 100.0);
        assert_eq!(marker_spec(&LslConfig::default()).rate_hz, 0.0);
    }

    #[test]
    fn a_missing_library_is_a_clear_error_naming_what_was_tried() {
        let error = Liblsl::open(std::path::Path::new("/nonexistent/liblsl.so")).unwrap_err();
        let text = error.to_string();
        assert!(
            text.contains("/nonexistent/liblsl.so") && text.contains("THERMODE_LIBLSL"),
            "{text}"
        );
    }
}

/// What `/api/status` says of the LSL streams.
#[derive(Debug, Clone)]
pub(crate) struct LslInfo {
    /// Where liblsl was loaded from.
    pub library: String,
    /// Loop time to LSL clock.
    pub clock: LslClock,
    /// The streaming thread's counters.
    pub counters: Arc<LslCounters>,
}
