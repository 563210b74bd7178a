//! The daemon: the loop core and the network side (HTTP + WebSocket on one port, OSC on another, LSL), started
//! together by [`Daemon::start`] and stopped by [`Daemon::stop`] (or [`Daemon::shutdown`]): the loop first (every
//! drive to 0 A at once), then the network side, then the dose ledger and the recorder (flushed and synced).
//!
//! Security rules applied here, before anything listens: a non-loopback bind address needs a token
//! ([`ServeError::InsecureBind`] otherwise). OSC cannot carry a token: it listens only on loopback binds, and when
//! a token is set not at all unless [`ServerConfig::osc_without_token`] asks for it (then on loopback only).
//!
//! The loop core itself (dose ledger, recorder, loop, ledger writer) is `thermode_runtime::LoopCore`; the daemon
//! binds the sockets before it starts it, attaches the adapters to its ports, and stops them between the loop's
//! stop and the core's final writes.

use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpListener, UdpSocket};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize};
use std::sync::Arc;
use std::time::Duration;

use thermode_device::Device;
use thermode_model::params::Rule;
use thermode_pipeline::stimulus::OBJECT_TEMPERATURE;
use thermode_platform::Clock;
use thermode_runtime::command::CommandSender;
use thermode_runtime::control_loop::LoopHandle;
use thermode_runtime::engine::EngineFactory;
use thermode_runtime::interlock::Interlock;
use thermode_runtime::recorder::RecordStatus;
use thermode_runtime::snapshot::Snapshot;
use thermode_runtime::{CoreConfig, CoreStop, LoopCore};

use crate::api::access::Access;
use crate::api::protocol::RequestLimits;
use crate::api::{router, App, Info, NetLimits, OscCounters};
use crate::error::ServeError;
use crate::lsl::{LslConfig, LslCounters, LslStreams, MarkerSender};

/// Default HTTP/WebSocket port.
pub const DEFAULT_PORT: u16 = 8765;
/// Default OSC (UDP) port.
pub const DEFAULT_OSC_PORT: u16 = 9000;
/// Longest accepted token \[characters\].
pub const MAX_TOKEN_CHARS: usize = 256;

/// Settings of the network side.
#[derive(Debug, Clone, PartialEq)]
pub struct ServerConfig {
    /// Address to listen on. Default 127.0.0.1 (loopback). Any other address requires `token`.
    pub bind: IpAddr,
    /// HTTP/WebSocket port; 0 picks a free one. Default [`DEFAULT_PORT`].
    pub port: u16,
    /// OSC port (0 picks a free one), or `None` for no OSC. Default `Some(`[`DEFAULT_OSC_PORT`]`)`. OSC cannot
    /// carry the token: it is off when a token is set (unless [`ServerConfig::osc_without_token`]), and it listens
    /// on loopback only.
    pub osc_port: Option<u16>,
    /// Listen for OSC even though a token is set (OSC itself is not authenticated): on loopback only (127.0.0.1,
    /// or `::1` on an IPv6 loopback bind). Default false.
    pub osc_without_token: bool,
    /// The shared secret every request must present; required on non-loopback binds. Printable ASCII without
    /// spaces, 1 to 256 characters. Default none.
    pub token: Option<String>,
    /// Web origins (e.g. `https://app.example`) allowed to connect besides the daemon's own pages. Default none.
    pub allowed_origins: Vec<String>,
    /// Network limits.
    pub net: NetLimits,
    /// Largest message answered with a reply \[bytes\]; larger ones get `too_large`. Default 16384.
    pub max_message_bytes: usize,
    /// Fastest telemetry subscription \[Hz\]; also at most the loop rate. Default 100.
    pub max_subscribe_hz: f64,
    /// Object temperature of a touch that gives none \[°C\]. Default 23. Within the pipeline's object range
    /// (`thermode_pipeline::stimulus::OBJECT_TEMPERATURE`). The stimulus limits themselves (display range, rate limit) are not set here:
    /// they are those of the envelopes the channel engines run ([`thermode_runtime::ChannelEngine::limits`]).
    pub default_object_c: f64,
}

impl Default for ServerConfig {
    fn default() -> Self {
        ServerConfig {
            bind: IpAddr::V4(Ipv4Addr::LOCALHOST),
            port: DEFAULT_PORT,
            osc_port: Some(DEFAULT_OSC_PORT),
            osc_without_token: false,
            token: None,
            allowed_origins: Vec::new(),
            net: NetLimits::default(),
            max_message_bytes: 16 * 1024,
            max_subscribe_hz: 100.0,
            default_object_c: 23.0,
        }
    }
}

impl ServerConfig {
    /// Refuses an insecure or malformed configuration (see the module documentation).
    pub fn validate(&self) -> Result<(), ServeError> {
        if let Some(token) = &self.token {
            let printable = token.chars().all(|c| c.is_ascii_graphic());
            if token.is_empty() || token.len() > MAX_TOKEN_CHARS || !printable {
                return Err(ServeError::Config(format!(
                    "the token must be 1 to {MAX_TOKEN_CHARS} printable ASCII characters without spaces"
                )));
            }
        } else if !self.bind.is_loopback() {
            return Err(ServeError::InsecureBind {
                addr: self.bind.to_string(),
            });
        }
        self.net.validate()?;
        let message = Rule::Within {
            min: 1.0,
            max: self.net.hard_message_bytes as f64,
        };
        message.check("max_message_bytes", self.max_message_bytes as f64)?;
        OBJECT_TEMPERATURE.check(self.default_object_c)?;
        Ok(())
    }

    /// Whether OSC will listen: a port is given, and either no token is set and the bind is loopback, or a token is
    /// set and [`ServerConfig::osc_without_token`] asks for OSC all the same (it then listens on loopback).
    pub fn osc_enabled(&self) -> bool {
        match (&self.osc_port, &self.token) {
            (None, _) => false,
            (Some(_), None) => self.bind.is_loopback(),
            (Some(_), Some(_)) => self.osc_without_token,
        }
    }

    /// OSC listens without authentication while a token protects everything else (say so loudly).
    pub fn osc_unauthenticated(&self) -> bool {
        self.osc_enabled() && self.token.is_some()
    }

    /// The address OSC binds: the bind address when it is loopback, else the loopback of its family.
    fn osc_bind(&self) -> IpAddr {
        match self.bind {
            ip if ip.is_loopback() => ip,
            IpAddr::V6(_) if !self.bind.is_unspecified() => IpAddr::V6(std::net::Ipv6Addr::LOCALHOST),
            _ => IpAddr::V4(Ipv4Addr::LOCALHOST),
        }
    }
}

/// Everything [`Daemon::start`] needs besides the device, the engines and the clock.
#[derive(Debug, Clone, Default)]
pub struct DaemonConfig {
    /// The loop core: the loop, the recording, the state directory of the dose ledger.
    pub core: CoreConfig,
    /// The network side.
    pub server: ServerConfig,
    /// The device as shown in `/api/status` (e.g. `sim`).
    pub device_label: String,
    /// A name per channel (e.g. the fingers), or empty.
    pub channel_names: Vec<String>,
    /// What each channel's device file is, as `/api/status` reports it (channels past the list: its last entry;
    /// an empty list: `datasheet`). Default empty.
    pub device_files: Vec<thermode_protocol::status::DeviceFileKind>,
    /// Lab Streaming Layer outlets (`serve --lsl`), or `None` (then liblsl is never loaded). The daemon fills in
    /// the rate, the channel count and the device label. Default `None`.
    pub lsl: Option<LslConfig>,
    /// Extra consumers of the per-tick records (the bench); the loop never waits for them. Default none.
    pub taps: Vec<std::sync::mpsc::SyncSender<thermode_runtime::snapshot::TickRecord>>,
}

/// What [`Daemon::stop`] did: the loop core's stop.
pub type StopReport = CoreStop;

/// A running daemon.
#[derive(Debug)]
pub struct Daemon {
    runtime: Option<tokio::runtime::Runtime>,
    core: LoopCore,
    lsl: Option<LslStreams>,
    /// The program-event thread (`crate::program_events`), joined once the loop has stopped.
    events: Option<std::thread::JoinHandle<()>>,
    http_addr: SocketAddr,
    osc_addr: Option<SocketAddr>,
    token: Option<String>,
}

impl Daemon {
    /// Checks the configuration, binds the sockets, and starts the loop, the recorder and the network side.
    pub fn start(
        mut config: DaemonConfig,
        device: Box<dyn Device + Send>,
        engines: EngineFactory,
        clock: Arc<dyn Clock>,
    ) -> Result<Daemon, ServeError> {
        let mut taps = std::mem::take(&mut config.taps);
        let server = &config.server;
        server.validate()?;
        config.core.loop_config.validate()?;
        let http = bind_tcp(SocketAddr::new(server.bind, server.port))?;
        let http_addr = local_addr(&http, server.bind)?;
        let osc = match server.osc_port.filter(|_| server.osc_enabled()) {
            Some(port) => Some(bind_udp(SocketAddr::new(server.osc_bind(), port))?),
            None => None,
        };
        let osc_addr = osc
            .as_ref()
            .map(|s| s.local_addr())
            .transpose()
            .map_err(|source| ServeError::Io {
                context: "OSC socket".into(),
                source,
            })?;
        let prepared = LoopCore::prepare(config.core.clone(), clock.as_ref())?;
        let (lsl, markers) = match &config.lsl {
            Some(wanted) => {
                let (streams, feed, markers) = start_lsl(wanted, &config, device.channel_count(), clock.as_ref())?;
                taps.push(feed);
                if let Some(path) = prepared.recording_path() {
                    write_lsl_sidecar(&path, &streams, &wanted.name)?;
                }
                (Some(streams), Some(markers))
            }
            None => (None, None),
        };
        let events_csv = prepared
            .recording_path()
            .map(|p| crate::program_events::events_csv_path(&p));
        let events = crate::program_events::start(events_csv).map_err(|source| ServeError::Io {
            context: "cannot start the program-event thread".into(),
            source,
        })?;
        taps.push(events.feed);
        let core = prepared.start(device, engines, clock.clone(), taps)?;
        let control = core.control().expect("a core just started has its loop");
        let realtime_loop = control.realtime().cpu.is_some();
        let limits = request_limits(&config, control);
        limits.stimulus.object_c.check(limits.default_object_c)?;
        let app = Arc::new(App {
            commands: control.commands(),
            shared: control.shared(),
            limits,
            net: server.net.clone(),
            access: Access::new(server.token.clone(), http_addr.port(), server.allowed_origins.clone()),
            info: Info {
                device: config.device_label.clone(),
                channel_names: config.channel_names.clone(),
                device_files: config.device_files.clone(),
                osc_port: osc_addr.map(|a| a.port()),
                http_port: http_addr.port(),
                recording: core.recording_path().map(|p| p.display().to_string()),
            },
            osc: Arc::new(OscCounters::default()),
            dose_ledger: core.dose_ledger(),
            recording: core.recording(),
            record_events: core.recording().as_deref().map(crate::api::record_events),
            record_policy: config.core.record_policy,
            interlock: core.interlock(),
            clock,
            reply_wait: Duration::from_secs_f64(
                server.net.reply_timeout_s.max(2.0 * config.core.loop_config.period_s()),
            ),
            clients: AtomicUsize::new(0),
            next_client: AtomicU64::new(1),
            command_lease: crate::api::command::CommandLease::new(server.net.requests_per_s, server.net.burst),
            http: Arc::new(crate::api::server::HttpCounters::default()),
            http_cap: crate::api::server::fitted_cap(
                server.net.max_http_connections,
                thermode_platform::rt::open_files_limit(),
            ),
            link: control.link_health(),
            parts: control.device_parts().to_vec(),
            realtime: control.realtime().clone(),
            history: Arc::new(crate::api::history::History::default()),
            markers,
            program_events: events.sender,
            lsl: lsl.as_ref().map(|s| crate::lsl::LslInfo {
                library: s.library().to_string(),
                clock: s.clock(),
                counters: s.counters(),
            }),
        });
        let runtime = start_network(app, http, osc, realtime_loop)?;
        Ok(Daemon {
            runtime: Some(runtime),
            core,
            lsl,
            events: Some(events.thread),
            http_addr,
            osc_addr,
            token: server.token.clone(),
        })
    }

    /// The HTTP/WebSocket address actually bound.
    pub fn http_addr(&self) -> SocketAddr {
        self.http_addr
    }

    /// The OSC address, when OSC listens.
    pub fn osc_addr(&self) -> Option<SocketAddr> {
        self.osc_addr
    }

    /// The dashboard URL (with `?token=` when a token is set, so the printed link just works).
    pub fn dashboard_url(&self) -> String {
        let host = match self.http_addr.ip() {
            ip if ip.is_unspecified() => "127.0.0.1".to_string(),
            IpAddr::V6(ip) => format!("[{ip}]"),
            IpAddr::V4(ip) => ip.to_string(),
        };
        let query = self
            .token
            .as_ref()
            .map_or(String::new(), |t| format!("?token={}", query_escape(t)));
        format!("http://{host}:{}/{query}", self.http_addr.port())
    }

    /// The dose ledger file, when the daemon has a state directory.
    pub fn ledger_path(&self) -> Option<&Path> {
        self.core.ledger_path()
    }

    /// The session CSV, when recording.
    pub fn recording_path(&self) -> Option<PathBuf> {
        self.core.recording_path()
    }

    /// A sender for the loop's command queue (the demo script uses it).
    pub fn commands(&self) -> Option<CommandSender> {
        self.core.commands()
    }

    /// What real-time treatment the control loop obtained.
    pub fn realtime(&self) -> Option<thermode_platform::rt::Realtime> {
        self.core.control().map(|c| c.realtime().clone())
    }

    /// Each channel's start-up self-test of its display (empty once stopped).
    pub fn self_tests(&self) -> &[thermode_runtime::engine::SelfTestState] {
        self.core.control().map_or(&[], |c| c.self_tests())
    }

    /// A copy of the loop's newest snapshot.
    pub fn snapshot(&self) -> Option<Snapshot> {
        self.core.snapshot()
    }

    /// The recording's shared state, when recording.
    pub fn recording(&self) -> Option<Arc<RecordStatus>> {
        self.core.recording()
    }

    /// The interlock the loop obeys.
    pub fn interlock(&self) -> Arc<Interlock> {
        self.core.interlock()
    }

    /// What the operator must be told since the last call, one line each (a failed recording; the device link going
    /// down and coming back). `thermode serve` prints them on standard error.
    pub fn take_notices(&self) -> Vec<String> {
        self.core.take_notices()
    }

    /// The LSL streams' counters and clock mapping, when `--lsl` is on.
    pub fn lsl(&self) -> Option<(crate::lsl::LslClock, Arc<LslCounters>, String)> {
        self.lsl
            .as_ref()
            .map(|s| (s.clock(), s.counters(), s.library().to_string()))
    }

    /// Tick records the recorder or a tap could not take (their queue was full).
    pub fn dropped_records(&self) -> u64 {
        self.core.shared().map_or(0, |s| s.dropped_records())
    }

    /// Stops the loop first (its last act: every drive to 0 A at once, within one loop period), then the network
    /// side, then the dose ledger (its final write holds the loop's last tick) and the recorder (every queued row
    /// written, flushed and synced). Returns the rows recorded, if recording.
    pub fn shutdown(mut self) -> Result<Option<u64>, ServeError> {
        let report = self.stop_parts()?;
        match report.recording_error {
            Some(error) => Err(ServeError::Io {
                context: format!("the recording failed ({} rows written)", report.rows.unwrap_or(0)),
                source: std::io::Error::other(error),
            }),
            None => Ok(report.rows),
        }
    }

    /// As [`Daemon::shutdown`], with what the stop did.
    pub fn stop(mut self) -> Result<StopReport, ServeError> {
        self.stop_parts()
    }

    fn stop_parts(&mut self) -> Result<StopReport, ServeError> {
        self.core.stop_loop();
        if let Some(events) = self.events.take() {
            // It ends once the stopped loop's feed is gone and the last events are written.
            let _ = events.join();
        }
        if let Some(runtime) = self.runtime.take() {
            runtime.shutdown_timeout(Duration::from_millis(500));
        }
        if let Some(lsl) = self.lsl.take() {
            lsl.finish();
        }
        Ok(self.core.finish()?)
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.stop_parts();
    }
}

/// Starts the LSL streams for a device of `channels` channels at the loop's rate.
fn start_lsl(
    wanted: &LslConfig,
    config: &DaemonConfig,
    channels: usize,
    clock: &dyn Clock,
) -> Result<
    (
        LslStreams,
        std::sync::mpsc::SyncSender<thermode_runtime::snapshot::TickRecord>,
        MarkerSender,
    ),
    ServeError,
> {
    let lsl = LslConfig {
        rate_hz: config.core.loop_config.rate_hz,
        channels,
        device: config.device_label.clone(),
        ..wanted.clone()
    };
    Ok(LslStreams::start(&lsl, clock)?)
}

/// Writes `<recording stem>.lsl.json` beside the session CSV: the LSL clock and the loop clock at the same instant
/// and their offset (`lsl_time_s = time_s + lsl_offset_s` for the CSV's `time_s`).
fn write_lsl_sidecar(csv: &Path, streams: &LslStreams, name: &str) -> Result<(), ServeError> {
    let clock = streams.clock();
    let text = serde_json::json!({
        "recording": csv.file_name().map(|n| n.to_string_lossy().into_owned()),
        "lsl_clock_at_start_s": clock.lsl_at_start_s,
        "loop_time_at_start_s": clock.loop_at_start_s,
        "lsl_offset_s": clock.offset_s,
        "alignment": "lsl_time_s = time_s + lsl_offset_s (time_s: the recording's loop time column)",
        "telemetry_stream": format!("{name} telemetry"),
        "marker_stream": format!("{name} markers"),
        "liblsl": streams.library(),
    });
    let path = csv.with_extension("lsl.json");
    std::fs::write(&path, format!("{text:#}\n")).map_err(|source| ServeError::Io {
        context: format!("cannot write {}", path.display()),
        source,
    })
}

/// What the API checks requests against: the stimulus limits are those the loop's engines enforce.
fn request_limits(config: &DaemonConfig, control: &LoopHandle) -> RequestLimits {
    let server = &config.server;
    RequestLimits {
        channel_count: control.channel_count(),
        max_message_bytes: server.max_message_bytes,
        max_program_bytes: server.net.hard_message_bytes,
        stimulus: control.stimulus_limits(),
        max_subscribe_hz: server.max_subscribe_hz.min(config.core.loop_config.rate_hz),
        default_object_c: server.default_object_c,
    }
}

fn bind_tcp(addr: SocketAddr) -> Result<TcpListener, ServeError> {
    let listener = TcpListener::bind(addr).map_err(|source| ServeError::Bind {
        addr: addr.to_string(),
        source,
    })?;
    listener.set_nonblocking(true).map_err(|source| ServeError::Bind {
        addr: addr.to_string(),
        source,
    })?;
    Ok(listener)
}

fn bind_udp(addr: SocketAddr) -> Result<UdpSocket, ServeError> {
    let socket = UdpSocket::bind(addr).map_err(|source| ServeError::Bind {
        addr: format!("{addr} (OSC)"),
        source,
    })?;
    socket.set_nonblocking(true).map_err(|source| ServeError::Bind {
        addr: format!("{addr} (OSC)"),
        source,
    })?;
    Ok(socket)
}

fn local_addr(listener: &TcpListener, bind: IpAddr) -> Result<SocketAddr, ServeError> {
    listener.local_addr().map_err(|source| ServeError::Bind {
        addr: bind.to_string(),
        source,
    })
}

/// The tokio runtime of the network side, serving HTTP/WebSocket and OSC.
fn start_network(
    app: Arc<App>,
    http: TcpListener,
    osc: Option<UdpSocket>,
    keep_off_loop_cpu: bool,
) -> Result<tokio::runtime::Runtime, ServeError> {
    let mut builder = tokio::runtime::Builder::new_multi_thread();
    builder.worker_threads(2).thread_name("thermode-net").enable_all();
    if let Some(cpus) = keep_off_loop_cpu
        .then(thermode_runtime::control_loop::network_cpus)
        .flatten()
    {
        // Their socket traffic raises soft interrupts on the CPU that sends it: keep it off the loop's.
        builder.on_thread_start(move || {
            let _ = thermode_platform::rt::pin_current_thread(&cpus);
        });
    }
    let runtime = builder.build().map_err(|source| ServeError::Io {
        context: "cannot start the network runtime".into(),
        source,
    })?;
    let io_error = |source| ServeError::Io {
        context: "cannot register the listening sockets".into(),
        source,
    };
    let _entered = runtime.enter();
    let http = tokio::net::TcpListener::from_std(http).map_err(io_error)?;
    let osc = osc.map(tokio::net::UdpSocket::from_std).transpose().map_err(io_error)?;
    let routes = router(app.clone());
    let (net, cap, counters) = (app.net.clone(), app.http_cap, app.http.clone());
    runtime.spawn(crate::api::server::serve(http, routes, net, cap, counters));
    runtime.spawn(crate::api::history::sample(app.shared.clone(), app.history.clone()));
    if let Some(socket) = osc {
        runtime.spawn(crate::osc::serve(socket, app));
    }
    Ok(runtime)
}

/// Percent-escapes everything but unreserved characters.
fn query_escape(text: &str) -> String {
    text.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' | b'~' => (b as char).to_string(),
            _ => format!("%{b:02X}"),
        })
        .collect()
}
