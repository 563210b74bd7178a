//! `thermode serve`: the daemon — a display (the simulated five-finger display by default, or a real one over
//! `serial:PATH`) rendered in real time by the control loop, driven through the contact API (WebSocket, HTTP, OSC)
//! and watched on the live dashboard. The display set-up it shares with other commands is [`crate::display`].
//!
//! SIGINT (Ctrl-C) and SIGTERM stop it cleanly ([`crate::signals`]): every drive to 0 A at once (`AllOff` on a
//! serial display), the recording flushed and synced, one summary line on standard error, exit code 0 — or 2 when
//! the recording failed at any time during the run (the summary line says so).

use std::net::IpAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use thermode_model::params::Rule;
use thermode_platform::{Clock, MonotonicClock};
use thermode_runtime::recorder::RecordErrorPolicy;
use thermode_runtime::{CoreConfig, LoopConfig};
use thermode_serve::lsl::LslConfig;
use thermode_serve::{Daemon, DaemonConfig, ServerConfig};

use crate::display::{build_display, describe_self_tests, DisplayArgs};
use crate::signals::StopSignals;

/// What a failed recording does (`--on-record-error`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OnRecordError {
    /// Release every stimulus and refuse new ones until an operator acknowledges (ack_recording, dashboard).
    Stop,
    /// Report the failure everywhere and go on without recording.
    Continue,
}

/// Arguments of `thermode serve`.
#[derive(Args, Debug, Clone)]
pub struct ServeArgs {
    #[command(flatten)]
    pub display: DisplayArgs,
    /// Control-loop rate [Hz], 1 to 1000.
    #[arg(long, value_name = "HZ", default_value_t = 100.0, allow_negative_numbers = true)]
    pub rate: f64,
    /// Address to listen on. Anything but loopback requires --token.
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1")]
    pub bind: IpAddr,
    /// HTTP/WebSocket port (0 picks a free one).
    #[arg(long, value_name = "P", default_value_t = thermode_serve::DEFAULT_PORT)]
    pub port: u16,
    /// OSC (UDP) port (0 picks a free one). OSC listens on loopback binds only.
    #[arg(long = "osc-port", value_name = "P", default_value_t = thermode_serve::DEFAULT_OSC_PORT)]
    pub osc_port: u16,
    /// Do not listen for OSC.
    #[arg(long = "no-osc")]
    pub no_osc: bool,
    /// With --token, listen for OSC all the same: OSC carries no token, so it then listens on loopback only and
    /// anyone on this machine can drive the display through it.
    #[arg(long = "osc-without-token")]
    pub osc_without_token: bool,
    /// Shared secret every client must present (`Authorization: Bearer T` or `?token=T`); required off loopback.
    #[arg(long, value_name = "T")]
    pub token: Option<String>,
    /// A web origin (e.g. `https://app.example`) allowed to open the WebSocket; repeatable.
    #[arg(long = "allow-origin", value_name = "ORIGIN")]
    pub allow_origin: Vec<String>,
    /// Write one CSV per session (one row per tick per channel) into this directory. A name ending in .arrow or
    /// .feather (Arrow IPC) or .parquet: the CSV goes into that file's folder, and when serve stops the session is
    /// also written to that file (the CSV's columns and values).
    #[arg(long, value_name = "DIR")]
    pub record: Option<PathBuf>,
    /// When the recording cannot be written (a full disk): `stop` releases every stimulus and refuses new ones until
    /// an operator acknowledges; `continue` goes on unrecorded. Both report it on stderr, in /api/status, on the
    /// dashboard and to every WebSocket client.
    #[arg(long = "on-record-error", value_enum, default_value = "stop")]
    pub on_record_error: OnRecordError,
    /// Largest session file [bytes]; reaching it fails the recording as a full disk would.
    #[arg(long = "record-max-bytes", value_name = "BYTES")]
    pub record_max_bytes: Option<u64>,
    /// Release a disconnected client's contacts after this grace period [s].
    #[arg(
        long = "release-after",
        value_name = "S",
        default_value_t = 2.0,
        allow_negative_numbers = true
    )]
    pub release_after: f64,
    /// Lease of the HTTP commands (POST /api/command): when no command arrives for this long, the contacts made
    /// over HTTP are released after the grace period (--release-after) [s], above 0, at most a day.
    #[arg(
        long = "command-lease",
        value_name = "S",
        default_value_t = 30.0,
        allow_negative_numbers = true
    )]
    pub command_lease: f64,
    /// Stop after this many seconds (default: run until interrupted).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub duration: Option<f64>,
    /// Directory of the dose ledger, which keeps each channel's thermal dose across restarts (see `thermode dose`)
    /// [default: $XDG_STATE_HOME/thermode, else ~/.local/state/thermode].
    #[arg(long = "state-dir", value_name = "DIR")]
    pub state_dir: Option<PathBuf>,
    /// Do not ask for real-time scheduling (SCHED_FIFO) of the control loop and locked memory. By default both are
    /// asked for and used where the system grants them (the banner and /api/status say whether it did).
    #[arg(long = "no-realtime")]
    pub no_realtime: bool,
    /// Publish Lab Streaming Layer streams: `thermode telemetry` (every channel's target, skin, sensor, set-point and
    /// current at the loop rate) and `thermode markers` (touch, release, set-point, stop, fault and client markers).
    /// Loads liblsl at start (THERMODE_LIBLSL, PYLSL_LIB, the system's, then the pylsl package's; docs/api.md).
    #[arg(long)]
    pub lsl: bool,
    /// Name prefix of the LSL streams (with --lsl).
    #[arg(long = "lsl-name", value_name = "NAME", default_value = "thermode", requires = "lsl")]
    pub lsl_name: String,
}

/// Starts the daemon of `args` and prints where it listens.
pub fn start(args: &ServeArgs) -> Result<Daemon> {
    let (daemon, display) = start_quiet(args)?;
    print_banner(&daemon, &display, args);
    Ok(daemon)
}

/// Starts `display` as `serve` would, for `thermode lab run --device`: on loopback at a free port, without OSC,
/// with a random token of its own (so no other local program can drive it), the dose ledger in `state_dir` (the
/// default when `None`). Prints no banner: only the notices about the display's device file (which file runs, or a
/// warning), on standard error. Returns the daemon and its token.
pub fn start_private(display: &DisplayArgs, state_dir: Option<PathBuf>) -> Result<(Daemon, String)> {
    use std::hash::BuildHasher;
    let random = std::collections::hash_map::RandomState::new();
    let token = format!("{:016x}{:016x}", random.hash_one(1u8), random.hash_one(2u8));
    let args = ServeArgs {
        display: display.clone(),
        rate: 100.0,
        bind: IpAddr::from([127, 0, 0, 1]),
        port: 0,
        osc_port: 0,
        no_osc: true,
        osc_without_token: false,
        token: Some(token.clone()),
        allow_origin: Vec::new(),
        record: None,
        on_record_error: OnRecordError::Stop,
        record_max_bytes: None,
        release_after: 2.0,
        command_lease: 30.0,
        duration: None,
        state_dir,
        no_realtime: false,
        lsl: false,
        lsl_name: "thermode".to_string(),
    };
    let (daemon, display) = start_quiet(&args)?;
    for line in &display.notices {
        eprintln!("thermode: {line}");
    }
    Ok((daemon, token))
}

/// What the banner says about the display: its description and the notices about its device file.
struct Started {
    description: String,
    notices: Vec<String>,
}

/// Starts the daemon of `args`; returns it and what the banner says about the display.
fn start_quiet(args: &ServeArgs) -> Result<(Daemon, Started)> {
    // Every option is checked before a port is opened or a device touched.
    check_duration(args.duration)?;
    if let Some(file) = args
        .record
        .as_deref()
        .filter(|r| crate::record_columnar::is_columnar(r))
    {
        crate::output::check_outputs(&[("--record", Some(file))])?;
        crate::record_columnar::check_targets(file)?;
    }
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    let server = ServerConfig {
        bind: args.bind,
        port: args.port,
        osc_port: (!args.no_osc).then_some(args.osc_port),
        osc_without_token: args.osc_without_token,
        token: args.token.clone(),
        allowed_origins: args.allow_origin.clone(),
        net: thermode_serve::api::NetLimits {
            command_lease_s: args.command_lease,
            ..thermode_serve::api::NetLimits::default()
        },
        ..ServerConfig::default()
    };
    // Refuse an insecure bind before touching any hardware.
    server.validate()?;
    let state_dir = super::dose::state_dir(args.state_dir.as_deref())?;
    let display = build_display(&args.display, &clock, Some(&state_dir))?;
    let config = DaemonConfig {
        core: CoreConfig {
            loop_config: LoopConfig {
                rate_hz: args.rate,
                release_after_disconnect_s: args.release_after,
                realtime: !args.no_realtime,
                ..LoopConfig::default()
            },
            record_dir: args.record.as_deref().map(crate::record_columnar::record_folder),
            record_policy: match args.on_record_error {
                OnRecordError::Stop => RecordErrorPolicy::Stop,
                OnRecordError::Continue => RecordErrorPolicy::Continue,
            },
            record_max_bytes: args.record_max_bytes,
            state_dir: Some(state_dir),
        },
        server,
        device_label: display.label,
        channel_names: display.names.clone(),
        device_files: display.file_kinds,
        lsl: args.lsl.then(|| LslConfig {
            name: args.lsl_name.clone(),
            source_id: args.lsl_name.clone(),
            ..LslConfig::default()
        }),
        taps: Vec::new(),
    };
    let started = Started {
        description: display.description,
        notices: display.notices,
    };
    let daemon = Daemon::start(config, display.device, display.engines, clock)?;
    Ok((daemon, started))
}

fn print_banner(daemon: &Daemon, display: &Started, args: &ServeArgs) {
    let addr = daemon.http_addr();
    println!("thermode serve: {}, {} Hz", display.description, args.rate);
    for line in &display.notices {
        println!("  device file  {line}");
    }
    println!("  dashboard  {}", daemon.dashboard_url());
    println!("  WebSocket  ws://{addr}/api/ws");
    match daemon.osc_addr() {
        Some(osc) if args.token.is_some() => println!(
            "  OSC        udp://{osc}  WARNING: OSC carries no token; anyone on this machine can drive the display \
             through it (--osc-without-token)"
        ),
        Some(osc) => println!("  OSC        udp://{osc}"),
        None if args.no_osc => println!("  OSC        off"),
        None if args.token.is_some() => {
            println!("  OSC        off (OSC carries no token; --osc-without-token enables it on loopback)")
        }
        None => println!("  OSC        off (OSC has no authentication: it listens on loopback binds only)"),
    }
    if let Some(path) = daemon.recording_path() {
        let policy = match args.on_record_error {
            OnRecordError::Stop => "on a write error every stimulus stops until acknowledged",
            OnRecordError::Continue => "on a write error stimuli go on unrecorded",
        };
        println!("  recording  {} ({policy})", path.display());
    }
    if let Some((clock, _, library)) = daemon.lsl() {
        println!(
            "  LSL        streams \"{0} telemetry\" and \"{0} markers\" (liblsl {library}; LSL clock = loop time + {1:.6} s)",
            args.lsl_name, clock.offset_s
        );
    }
    if let Some(realtime) = daemon.realtime() {
        println!("  real time  {}", realtime.describe());
    }
    if let Some(path) = daemon.ledger_path() {
        println!("  dose       {}", path.display());
    }
    for line in describe_self_tests(daemon.self_tests()) {
        println!("  self-test  {line}");
    }
    if args.token.is_some() {
        println!("  clients must present the token (Authorization: Bearer … or ?token=…)");
    }
    match args.duration {
        Some(s) => println!("running for {s} s"),
        None => println!("press Ctrl-C to stop"),
    }
}

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    /// `--duration` passed.
    Duration,
    /// A stop signal arrived (its name, e.g. `SIGTERM`).
    Signal(&'static str),
}

/// `--duration`: a finite number of seconds ≥ 0, if given.
fn check_duration(duration_s: Option<f64>) -> Result<()> {
    if let Some(d) = duration_s {
        Rule::NonNegative.check("--duration [s]", d)?;
    }
    Ok(())
}

/// Runs until `duration_s` has passed (forever without one) or a stop signal arrives, calling `every_100ms` in
/// between; a signal ends the wait at once.
pub fn run_for(duration_s: Option<f64>, signals: &StopSignals, mut every_100ms: impl FnMut(f64)) -> Result<Ended> {
    check_duration(duration_s)?;
    let start = Instant::now();
    let step = Duration::from_millis(100);
    loop {
        let elapsed_s = start.elapsed().as_secs_f64();
        let left = match duration_s {
            Some(d) if elapsed_s >= d => return Ok(Ended::Duration),
            Some(d) => Duration::from_secs_f64(d - elapsed_s).min(step),
            None => step,
        };
        every_100ms(elapsed_s);
        if let Some(signal) = signals.wait(left) {
            return Ok(Ended::Signal(signal.as_str()));
        }
    }
}

/// Stops the daemon (every drive to 0 A at once, then the network, then the recording, flushed and synced) and
/// reports one summary line on standard error (the loop time it stopped at, the drives, the recording), after a
/// signal as after `--duration` (which also prints the recording's line on standard output, as before). A device that did not take the all-off command is an error (exit 2), and so is a recording that
/// failed at any time during the run, even one that went on in a new file after an acknowledgement (exit 2; the
/// summary line says `the recording FAILED`).
pub fn finish(daemon: Daemon, ended: Ended) -> Result<()> {
    let path = daemon.recording_path();
    let recording = daemon.recording();
    let report = daemon.stop()?;
    let write_failures = recording.map_or(0, |r| r.events().failures);
    let failure = match (&report.recording_error, write_failures) {
        (Some(error), _) => Some(error.clone()),
        (None, 0) => None,
        (None, n) => Some(format!("{n} write failure(s) during the run")),
    };
    let recorded = match (&path, report.rows, &failure) {
        (Some(path), Some(rows), Some(error)) => {
            format!(
                "; the recording FAILED ({error}): {rows} whole rows in {}",
                path.display()
            )
        }
        (Some(path), Some(rows), None) => format!("; {rows} rows recorded to {} (flushed and synced)", path.display()),
        _ => String::new(),
    };
    let drives = match &report.all_off {
        Some(Ok(())) => "every drive set to 0 A",
        Some(Err(_)) => "the device did not take the all-off command",
        None => "the control loop had already stopped",
    };
    let stopped_at = format!("stopped at loop time {:.3} s, {drives}", report.last_tick_s);
    match ended {
        Ended::Signal(name) => eprintln!("thermode: {name}: {stopped_at}{recorded}"),
        Ended::Duration => {
            // The same summary as after a signal, on standard error; the recording's line stays on standard output.
            eprintln!("thermode: --duration passed: {stopped_at}{recorded}");
            if let (Some(path), Some(rows)) = (path, report.rows) {
                println!("recorded {rows} rows to {}", path.display());
            }
            if let Some(error) = &failure {
                eprintln!("thermode: the recording FAILED: {error}");
            }
        }
    }
    match (report.all_off, failure) {
        (Some(Err(e)), _) => Err(e).context("switching every drive off at the stop"),
        (_, Some(error)) => Err(anyhow::anyhow!(
            "the recording failed during the run ({error}): the session is incomplete"
        )),
        _ => Ok(()),
    }
}

/// Prints what the operator must know now (a failed recording, the device link), one line each on stderr.
pub fn print_notices(daemon: &Daemon) {
    for line in daemon.take_notices() {
        eprintln!("{line}");
    }
}

/// Runs `thermode serve`.
pub fn run(args: &ServeArgs) -> Result<()> {
    let signals = StopSignals::install()?;
    let daemon = start(args)?;
    let recording = daemon.recording();
    let ended = run_for(args.duration, &signals, |_| print_notices(&daemon))?;
    let finished = finish(daemon, ended);
    let columnar = args
        .record
        .as_deref()
        .filter(|r| crate::record_columnar::is_columnar(r));
    if let (Some(file), Some(recording)) = (columnar, recording) {
        let rows = crate::record_columnar::write_session(file, &recording)?;
        eprintln!("thermode: the session's {rows} rows also written to {}", file.display());
    }
    finished
}
