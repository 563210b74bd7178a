//! `thermode emulate --protocol mecom|tcs2`: the device side of a Meerstetter TEC controller (MeCom, on a
//! pseudo-terminal or `--tcp ADDR`) or of a QST.Lab TCS II stimulator (on a pseudo-terminal), with the simulated
//! display behind it, so `--device mecom:PATH`, `mecom-tcp:HOST:PORT` and `tcs2:PATH` work without hardware.
//!
//! The first line on standard output is what the host connects to (a pseudo-terminal path, or the TCP address with
//! the port picked), flushed at once; the emulator then runs in real time until the process is ended.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use thermode_device::{DefaultFinger, Device, NoFinger, PlateFinger, SimulatedDisplay};
use thermode_link::mecom::emulator::{MecomBus, MecomEmulator, MecomEmulatorConfig};
use thermode_link::runner::{spawn_reference_thermometer, Firmware, PtyFirmware, RunEnd, SensorError, TcpFirmware};
use thermode_link::tcs2::emulator::{Tcs2Emulator, Tcs2EmulatorConfig};
use thermode_platform::{Clock, MonotonicClock};

use crate::resolve;

/// The protocol `thermode emulate` speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Protocol {
    /// thermode's own protocol (`docs/protocol.md`).
    Own,
    /// A Meerstetter TEC controller (MeCom).
    Mecom,
    /// A QST.Lab TCS II stimulator.
    Tcs2,
}

/// The protocol of `thermode emulate` and the options of its MeCom and TCS II emulators (flattened into
/// `EmulateArgs`).
#[derive(Args, Debug)]
pub struct HardwareArgs {
    /// The protocol spoken: `own` (thermode's), `mecom` (a Meerstetter TEC controller) or `tcs2` (a QST.Lab TCS II).
    #[arg(long, value_enum, default_value = "own")]
    pub protocol: Protocol,
    /// MeCom only: listen on this TCP address (e.g. `127.0.0.1:0`; the first line printed is the address) instead
    /// of a pseudo-terminal.
    #[arg(long, value_name = "ADDR")]
    pub tcp: Option<String>,
    /// MeCom only: the device address, 1 to 254 (frames to address 0 are answered too). Given several times, one
    /// controller of `--channels` instances at each address, all on one port (an RS-485 bus; no `--trace`).
    #[arg(long, value_name = "N", default_value = "1")]
    pub address: Vec<u8>,
    /// MeCom only: answer as an older firmware without the newer commands (`?VM` metadata "command not available";
    /// max temperature change 4012, live set voltage 50002 and actual voltage 1021 "parameter not available").
    #[arg(long = "old-firmware")]
    pub old_firmware: bool,
    /// Every protocol: the plate sensor's offset error [°C]: it reads gain · T + offset (see `--sensor-gain`), and
    /// the device regulates, cuts, clamps and reports on that reading (a mounted sensor off the truth, for
    /// `thermode calibrate` and the tests of the device-side lines under a calibration).
    #[arg(
        long = "sensor-offset-c",
        value_name = "C",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    pub sensor_offset_c: f64,
    /// Every protocol: the plate sensor's gain error [-] (see `--sensor-offset-c`).
    #[arg(long = "sensor-gain", value_name = "G", default_value_t = 1.0)]
    pub sensor_gain: f64,
    /// MeCom on a pseudo-terminal only: offer a reference thermometer of this channel's true plate on a second
    /// pseudo-terminal (its path is the second line printed): one temperature in °C per line every 0.1 s, with
    /// Gaussian noise of 0.01 °C.
    #[arg(long = "reference-channel", value_name = "N")]
    pub reference_channel: Option<usize>,
    /// TCS II only: stream temperature lines at this rate [Hz] even when muted (a test of the host).
    #[arg(long = "stream-hz", value_name = "HZ")]
    pub stream_hz: Option<f64>,
    /// No finger on the simulated plates (the bare display `thermode identify` and the start-up self-test measure).
    #[arg(long = "no-finger")]
    pub no_finger: bool,
}

impl HardwareArgs {
    /// The emulated plate sensor's error (`--sensor-gain`, `--sensor-offset-c`).
    pub fn sensor_error(&self) -> SensorError {
        SensorError {
            gain: self.sensor_gain,
            offset_c: self.sensor_offset_c,
        }
    }
}

/// The simulated display behind an emulator, and its trace.
#[derive(Debug, Clone, Copy)]
pub struct DisplayArgs<'a> {
    /// Number of channels, 1 to 10.
    pub channels: usize,
    /// The device file (None: the built-in default display).
    pub device_file: Option<&'a Path>,
    /// Seed of the sensor noise.
    pub seed: u64,
    /// Where the trace of the true plate goes (None: no trace).
    pub trace: Option<&'a Path>,
    /// A symbolic link published to the pseudo-terminal (None: none), so a restarted emulator is found there.
    pub link: Option<&'a Path>,
}

/// Creates (replaces) the trace file `path`, unbuffered so each step's rows reach it whole; its folder is created
/// if missing (the path policy, `crate::output`).
pub fn trace_file(path: &Path) -> Result<Box<dyn std::io::Write + Send>> {
    crate::output::create_folder_of(path)?;
    let file = std::fs::File::create(path).with_context(|| format!("cannot create the trace {}", path.display()))?;
    Ok(Box::new(file))
}

/// Points the symbolic link `link` at `target`, replacing whatever is there in one step (rename).
pub fn publish_link(link: &std::path::Path, target: &str) -> Result<()> {
    let mut tmp = link.as_os_str().to_owned();
    tmp.push(format!(".{}.tmp", std::process::id()));
    let tmp = PathBuf::from(tmp);
    let _ = std::fs::remove_file(&tmp);
    std::os::unix::fs::symlink(target, &tmp).with_context(|| format!("cannot create the link {}", tmp.display()))?;
    std::fs::rename(&tmp, link).with_context(|| format!("cannot publish the link {}", link.display()))
}

/// Removes the symbolic link `link` if it still points at `path` (this emulator's pseudo-terminal).
pub fn remove_link(link: &Path, path: &str) {
    if std::fs::read_link(link).is_ok_and(|target| target.as_os_str() == path) {
        let _ = std::fs::remove_file(link);
    }
}

/// Runs the MeCom or TCS II emulator of `args` over the display of `display`.
pub fn run(args: &HardwareArgs, display: &DisplayArgs<'_>) -> Result<()> {
    let device = resolve::device_config(display.device_file)?;
    let (channels, seed) = (display.channels, display.seed);
    let trace = display.trace.map(trace_file).transpose()?;
    if args.address.len() > 1 {
        return serve_bus(args, display);
    }
    let (firmware, what, spelling) = match args.no_finger {
        true => firmware(
            args,
            SimulatedDisplay::<NoFinger>::fingertips(&device, channels, seed)?,
            trace,
        )?,
        false => firmware(
            args,
            SimulatedDisplay::<DefaultFinger>::fingertips(&device, channels, seed)?,
            trace,
        )?,
    };
    serve_firmware(args, firmware, &what, spelling, display.link)
}

/// Serves one MeCom controller of `display.channels` instances at each of `args.address` on one port (a bus), each
/// over its own simulated display (seeds `display.seed`, `display.seed + 1`, …).
fn serve_bus(args: &HardwareArgs, display: &DisplayArgs<'_>) -> Result<()> {
    if args.protocol != Protocol::Mecom || display.trace.is_some() {
        bail!("several --address are for --protocol mecom, without --trace");
    }
    let device = resolve::device_config(display.device_file)?;
    let mut controllers: Vec<Box<dyn Firmware>> = Vec::new();
    for (index, &address) in args.address.iter().enumerate() {
        let seed = display.seed + index as u64;
        let one = HardwareArgs {
            address: vec![address],
            tcp: None,
            ..*args
        };
        let controller = match args.no_finger {
            true => firmware(
                &one,
                SimulatedDisplay::<NoFinger>::fingertips(&device, display.channels, seed)?,
                None,
            )?,
            false => firmware(
                &one,
                SimulatedDisplay::<DefaultFinger>::fingertips(&device, display.channels, seed)?,
                None,
            )?,
        };
        controllers.push(controller.0);
    }
    let addresses: Vec<String> = args.address.iter().map(u8::to_string).collect();
    let what = format!(
        "a MeCom bus of {} controllers at addresses {}, {} instances each",
        addresses.len(),
        addresses.join(", "),
        display.channels
    );
    let bus: Box<dyn Firmware> = Box::new(MecomBus::new(controllers));
    serve_firmware(args, bus, &what, "mecom:", display.link)
}

/// The emulator of `args.protocol` over `display` (tracing its plant into `trace`), what it is, and the `--device`
/// spelling that connects to it.
fn firmware<F: PlateFinger + Send + 'static>(
    args: &HardwareArgs,
    display: SimulatedDisplay<F>,
    trace: Option<Box<dyn std::io::Write + Send>>,
) -> Result<(Box<dyn Firmware>, String, &'static str)> {
    let channels = display.channel_count();
    Ok(match args.protocol {
        Protocol::Mecom => {
            let address = args.address.first().copied().unwrap_or(1);
            let config = MecomEmulatorConfig {
                address,
                old_firmware: args.old_firmware,
                sensor: args.sensor_error(),
                ..MecomEmulatorConfig::default()
            };
            let mut emulator = MecomEmulator::new(display, config)?;
            if let Some(trace) = trace {
                emulator.trace_to(trace);
            }
            let firmware = if args.old_firmware { " (older firmware)" } else { "" };
            let what = format!("a MeCom TEC controller{firmware} at address {address}, {channels} instances");
            let spelling = if args.tcp.is_some() { "mecom-tcp:" } else { "mecom:" };
            (Box::new(emulator), what, spelling)
        }
        Protocol::Tcs2 => {
            if args.tcp.is_some() {
                bail!("--tcp is for --protocol mecom only");
            }
            let config = Tcs2EmulatorConfig {
                forced_stream_hz: args.stream_hz,
                sensor: args.sensor_error(),
                ..Tcs2EmulatorConfig::default()
            };
            let mut emulator = Tcs2Emulator::new(display, config)?;
            if let Some(trace) = trace {
                emulator.trace_to(trace);
            }
            (
                Box::new(emulator),
                format!("a TCS II stimulator, {channels} zones"),
                "tcs2:",
            )
        }
        Protocol::Own => bail!("the own protocol is emulated by `thermode emulate` itself"),
    })
}

/// Serves `firmware` on TCP or a pseudo-terminal until it ends.
/// Stops the emulator whose runner `control` drives when SIGINT or SIGTERM arrives: the usual end of an emulator
/// started by hand, which then ends as after a stop (its `--link` removed, exit 0, as `serve`).
pub fn stop_on_signal<S: Copy + Send + Sync + 'static, C: Send + Sync + 'static>(
    control: &Arc<thermode_link::runner::Control<S, C>>,
) -> Result<()> {
    let signals = crate::signals::StopSignals::install()?;
    let control = Arc::clone(control);
    std::thread::Builder::new()
        .name("thermode-emulate-signals".into())
        .spawn(move || loop {
            if let Some(signal) = signals.wait(std::time::Duration::from_secs(3600)) {
                eprintln!("thermode emulate: {}: stopping", signal.as_str());
                control.stop();
                return;
            }
        })
        .context("cannot start the signal thread")?;
    Ok(())
}

fn serve_firmware(
    args: &HardwareArgs,
    firmware: Box<dyn Firmware>,
    what: &str,
    spelling: &str,
    link: Option<&Path>,
) -> Result<()> {
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    let mut stdout = std::io::stdout().lock();
    let end = if let Some(bind) = &args.tcp {
        let tcp = TcpFirmware::spawn(firmware, bind, clock)?;
        writeln!(stdout, "{}", tcp.address()).and_then(|()| stdout.flush())?;
        drop(stdout);
        eprintln!(
            "thermode emulate: {what}; connect with --device {spelling}{}",
            tcp.address()
        );
        stop_on_signal(tcp.control())?;
        tcp.wait()?
    } else {
        let pty = PtyFirmware::spawn(firmware, clock)?;
        if let Some(link) = link {
            publish_link(link, pty.path())?;
        }
        writeln!(stdout, "{}", pty.path()).and_then(|()| stdout.flush())?;
        if let Some(channel) = args.reference_channel {
            let reference = spawn_reference_thermometer(Arc::clone(pty.control()), channel, 0.01, 7, 0.1)?;
            writeln!(stdout, "{reference}").and_then(|()| stdout.flush())?;
            eprintln!("thermode emulate: a reference thermometer of channel {channel}'s plate on {reference}");
        }
        drop(stdout);
        eprintln!(
            "thermode emulate: {what}; connect with --device {spelling}{}",
            pty.path()
        );
        stop_on_signal(pty.control())?;
        let path = pty.path().to_string();
        let end = pty.wait();
        if let Some(link) = link {
            remove_link(link, &path);
        }
        end?
    };
    match end {
        RunEnd::Stopped | RunEnd::PortClosed | RunEnd::HostClosed => Ok(()),
    }
}
