//! `thermode emulate`: runs the device side of the serial protocol (`docs/protocol.md`) on a pseudo-terminal, with
//! the simulated display behind it, so the real hardware path (`--device serial:PATH`) works without hardware.
//! `--protocol mecom` or `tcs2` emulates a Meerstetter TEC controller or a TCS II stimulator instead
//! ([`super::emulate_hw`], `docs/hardware.md`).
//!
//! The first line on standard output is the path the host opens (e.g. `/dev/pts/7`), flushed at once; the
//! emulator then runs in real time (1 kHz firmware tick, reports every `--report-ms`) until the process is ended.
//! Link faults can be injected for tests of the host: corrupted bytes and dropped frames. `--trace FILE` writes the
//! true plate of every channel at every firmware tick (CSV, whole rows written and flushed tick by tick, so a reader
//! can follow it live and a killed emulator leaves no torn row), for every protocol. `--link PATH` publishes the pseudo-terminal under a
//! stable path (a symbolic link, replaced atomically), so a restarted emulator is found where the host looks for it
//! (`serve --device serial:PATH` re-opens the same path when its link fails).

use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Result;
use clap::Args;
use thermode_device::{DefaultFinger, NoFinger, PlateFinger, SimulatedDisplay};
use thermode_link::own::emulator::{Emulator, EmulatorConfig, LinkFaults, PtyEmulator};
use thermode_link::runner::RunEnd;
use thermode_platform::MonotonicClock;

use super::emulate_hw::{self, HardwareArgs, Protocol};
use crate::resolve;

/// Arguments of `thermode emulate`.
#[derive(Args, Debug)]
pub struct EmulateArgs {
    /// Number of channels (fingers), 1 to 10.
    #[arg(long, value_name = "N", default_value_t = 5)]
    channels: usize,
    /// Device file (TOML); default: the built-in default display.
    #[arg(long, value_name = "FILE")]
    device_file: Option<PathBuf>,
    /// Seed of the sensor noise and of the injected link faults.
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,
    /// Watchdog period [ms] (10 to 60000): drives go off when the host sends nothing valid for longer.
    #[arg(long = "watchdog-ms", value_name = "MS", default_value_t = 250)]
    watchdog_ms: u16,
    /// Interval between sensor reports [ms] (1 to 1000).
    #[arg(long = "report-ms", value_name = "MS", default_value_t = 10)]
    report_ms: u16,
    /// Fault injection: probability that a sent byte is corrupted, 0 to 1.
    #[arg(long = "corrupt-rate", value_name = "P", default_value_t = 0.0)]
    corrupt_rate: f64,
    /// Fault injection: probability that a sent frame is dropped, 0 to 1.
    #[arg(long = "drop-rate", value_name = "P", default_value_t = 0.0)]
    drop_rate: f64,
    /// Write one CSV row per channel per firmware tick to FILE (time_s,channel,plate_c,sensor_c,current_a: the true
    /// plate [°C], the sensor's latest sample [°C], the delivered current [A]); replaces FILE. Every protocol.
    #[arg(long, value_name = "FILE")]
    trace: Option<PathBuf>,
    /// The protocol and the options of the MeCom and TCS II emulators.
    #[command(flatten)]
    pub hardware: HardwareArgs,
    /// Also publish the pseudo-terminal as the symbolic link PATH (replaced if it exists; removed at a clean end),
    /// so a host opening PATH finds a restarted emulator there.
    #[arg(long, value_name = "PATH")]
    link: Option<PathBuf>,
}

/// Runs `thermode emulate`.
pub fn run(args: &EmulateArgs) -> Result<()> {
    if args.hardware.protocol != Protocol::Own {
        let display = emulate_hw::DisplayArgs {
            channels: args.channels,
            device_file: args.device_file.as_deref(),
            seed: args.seed,
            trace: args.trace.as_deref(),
            link: args.link.as_deref(),
        };
        return emulate_hw::run(&args.hardware, &display);
    }
    let device = resolve::device_config(args.device_file.as_deref())?;
    match args.hardware.no_finger {
        true => run_own(
            args,
            SimulatedDisplay::<NoFinger>::fingertips(&device, args.channels, args.seed)?,
        ),
        false => run_own(
            args,
            SimulatedDisplay::<DefaultFinger>::fingertips(&device, args.channels, args.seed)?,
        ),
    }
}

/// Runs thermode's own protocol over `display` until a signal or the host ends it.
fn run_own<F: PlateFinger + Send + 'static>(args: &EmulateArgs, display: SimulatedDisplay<F>) -> Result<()> {
    let config = EmulatorConfig {
        watchdog_ms: args.watchdog_ms,
        report_interval_ms: args.report_ms,
        fault_seed: args.seed,
        sensor: args.hardware.sensor_error(),
        ..EmulatorConfig::default()
    };
    let mut emulator = Emulator::new(display, config)?;
    emulator.set_link_faults(LinkFaults {
        corrupt_byte_rate: args.corrupt_rate,
        drop_frame_rate: args.drop_rate,
        mute: false,
    })?;
    if let Some(path) = &args.trace {
        emulator.trace_to(emulate_hw::trace_file(path)?);
    }
    let pty = PtyEmulator::spawn(emulator, Arc::new(MonotonicClock::new()))?;
    if let Some(link) = &args.link {
        emulate_hw::publish_link(link, pty.path())?;
    }
    let mut stdout = std::io::stdout().lock();
    writeln!(stdout, "{}", pty.path()).and_then(|()| stdout.flush())?;
    drop(stdout);
    let path = pty.path().to_string();
    eprintln!(
        "thermode emulate: {} channels, watchdog {} ms, a report every {} ms; connect with --device serial:{}",
        args.channels,
        args.watchdog_ms,
        args.report_ms,
        pty.path()
    );
    if let Some(link) = &args.link {
        eprintln!("thermode emulate: published as {}", link.display());
    }
    emulate_hw::stop_on_signal(pty.control())?;
    let ended = pty.wait();
    if let Some(link) = &args.link {
        // Removed only while it still points at this emulator's pseudo-terminal.
        if std::fs::read_link(link).is_ok_and(|target| target.as_os_str() == path.as_str()) {
            let _ = std::fs::remove_file(link);
        }
    }
    match ended? {
        RunEnd::Stopped | RunEnd::PortClosed | RunEnd::HostClosed => Ok(()),
    }
}
