//! The display set-up shared by the commands that run a display in real time (`serve`, `demo`, `bench`,
//! `identify`, `lab run --device`): the `--device`, `--device-file`, `--channels`, `--controller` and `--seed`
//! arguments ([`DisplayArgs`]) and the device with its pipelines built from them ([`build_display`]).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::Args;
use thermode_device::config::CalibrationConfig;
use thermode_device::{CalibratedDevice, DefaultFinger, Device, DeviceConfig, SimulatedDisplay, MAX_CHANNELS};
use thermode_link::spec::{is_hardware, open_display, HardwareContext};
use thermode_pipeline::self_test::Verdict;
use thermode_pipeline::{gains_for_device, ControllerKind, PipelineConfig, SelfTestState};
use thermode_platform::Clock;
use thermode_protocol::status::DeviceFileKind;
use thermode_runtime::engine::{pipeline_engines, pipeline_engines_per_channel};
use thermode_runtime::EngineFactory;

use crate::controller::{ControllerArg, DISPLAY_CONTROLLERS};
use crate::{identified, resolve};

/// How the display is set up (shared by serve, demo and bench).
#[derive(Args, Debug, Clone)]
pub struct DisplayArgs {
    /// The display: `sim` (the simulated display), `serial:PATH` (thermode's own protocol), `mecom:PATH[@ADDR][?OPTIONS]`
    /// or `mecom-tcp:HOST:PORT[?OPTIONS]` (Meerstetter TEC controllers; `@ADDR` an RS-485 address;
    /// `mode=current|temperature`), `tcs2:PATH` (a QST.Lab TCS II); a real display or `thermode emulate`. Given
    /// several times (real devices only), one display of all their channels in that order; several addresses on one
    /// port share it as one bus. See docs/hardware.md.
    #[arg(
        long,
        value_name = "sim|serial:PATH|mecom:PATH[@ADDR]|mecom-tcp:HOST:PORT|tcs2:PATH",
        default_value = "sim"
    )]
    pub device: Vec<String>,
    /// Device file (TOML) describing the display's hardware; default: the built-in default display.
    #[arg(long = "device-file", value_name = "FILE")]
    pub device_file: Option<PathBuf>,
    /// Number of channels (fingers) of the simulated display, 1 to 10 [default: 5; a serial device reports its own].
    #[arg(long, value_name = "N")]
    pub channels: Option<usize>,
    /// Controller of every channel.
    #[arg(long, default_value = "model", value_parser = ControllerArg::parser(&DISPLAY_CONTROLLERS))]
    pub controller: ControllerArg,
    /// Seed of the simulated sensor noise.
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub seed: u64,
}

impl DisplayArgs {
    /// The arguments of a display on the one device `device` (a spelling of `--device`).
    pub fn one(device: &str, device_file: Option<PathBuf>, controller: ControllerArg, seed: u64) -> Self {
        DisplayArgs {
            device: vec![device.to_string()],
            device_file,
            channels: None,
            controller,
            seed,
        }
    }

    /// Whether the display is the simulated one (`--device sim`, the default).
    pub fn is_sim(&self) -> bool {
        self.device.is_empty() || self.device == ["sim"]
    }

    /// The display's name: its device, or its devices joined by ` + `.
    pub fn label(&self) -> String {
        if self.device.is_empty() {
            return "sim".to_string();
        }
        self.device.join(" + ")
    }
}

/// A display ready for the loop.
pub struct Display {
    /// The device.
    pub device: Box<dyn Device + Send>,
    /// One pipeline per channel.
    pub engines: EngineFactory,
    /// `sim`, `serial:PATH`, or several devices joined by ` + `.
    pub label: String,
    /// Finger names.
    pub names: Vec<String>,
    /// Human description for the start-up banner.
    pub description: String,
    /// What each channel's device file is (`/api/status` reports it per channel).
    pub file_kinds: Vec<DeviceFileKind>,
    /// What the operator must know about the device file a real display runs, one line each (which file, or a
    /// warning); `serve` prints them in its banner, the other commands on standard error.
    pub notices: Vec<String>,
}

/// Finger names for five (one hand) or ten (two hands) channels.
fn finger_names(count: usize) -> Vec<String> {
    const HAND: [&str; 5] = ["thumb", "index", "middle", "ring", "little"];
    match count {
        5 => HAND.iter().map(|s| s.to_string()).collect(),
        10 => ["left", "right"]
            .iter()
            .flat_map(|side| HAND.iter().map(move |f| format!("{side} {f}")))
            .collect(),
        _ => Vec::new(),
    }
}

/// What each channel's start-up self-test found (one line per channel that ran one; nothing for a simulated
/// display or a temperature-commanded device).
pub fn describe_self_tests(tests: &[SelfTestState]) -> Vec<String> {
    tests
        .iter()
        .enumerate()
        .filter_map(|(channel, test)| match test {
            SelfTestState::NotRun | SelfTestState::Running => None,
            SelfTestState::Done(report) => Some(match report.verdict() {
                Verdict::NotAsFiled(_) => format!(
                    "channel {channel}: {report}; the channel stays off (fault E106). A finger on the display during \
                     the test slows its answer: restart with the display bare, or give the display its own device file"
                ),
                Verdict::Inconclusive(_) => format!(
                    "channel {channel}: {report}; the channel is held off, untested (fault E108), until clear_fault \
                     tests it again"
                ),
                Verdict::Matches => format!("channel {channel}: {report}"),
            }),
            SelfTestState::Interrupted => Some(format!(
                "channel {channel}: the self-test was stopped before its end; the channel is held off, untested (fault \
                 E108), until clear_fault tests it again"
            )),
        })
        .collect()
}

/// The pipeline of every channel of a display run on `device_config` with `controller`, checked.
fn pipeline_of(device_config: DeviceConfig, controller: ControllerArg) -> Result<PipelineConfig> {
    let controller = match controller {
        ControllerArg::Model => ControllerKind::Model,
        ControllerArg::Pid => ControllerKind::Pid(gains_for_device(&device_config)?.0),
        ControllerArg::Both => bail!("a display runs one controller: --controller model or pid"),
    };
    let pipeline = PipelineConfig::new(device_config, controller);
    pipeline.validate()?;
    Ok(pipeline)
}

/// Opens the real display of `args` for `pipeline` (its device file and envelope set the devices' own limits).
fn open_hardware(
    args: &DisplayArgs,
    pipeline: &PipelineConfig,
    clock: &Arc<dyn Clock>,
) -> Result<Box<dyn Device + Send>> {
    let context = HardwareContext {
        device: pipeline.device,
        envelope: pipeline.envelope,
    };
    let label = args.label();
    open_display(&args.device, &context, clock.clone()).with_context(|| format!("cannot open {label}"))
}

/// The identified device file stored in `state_dir` for each device of `device` (labelled `label` when it is one
/// unnamed device), in the order of its parts; `None` for a device without one.
fn stored_files(state_dir: &Path, label: &str, device: &dyn Device) -> Result<Vec<Option<identified::Stored>>> {
    device
        .parts()
        .iter()
        .map(|part| identified::find(state_dir, &identified::device_of(part, label), part.identity.as_deref()))
        .collect()
}

/// The pipeline the devices' own limits are set from on a display whose devices run `pipelines` (one per channel):
/// the first, with the slowest sensor of them all and the lowest drive limit (a MeCom controller's object
/// thresholds leave room for its sensor's lag; one controller on a bus of several takes the bus's settings).
fn most_cautious(pipelines: &[PipelineConfig]) -> Option<PipelineConfig> {
    let mut cautious = pipelines.first()?.clone();
    for p in pipelines {
        let (sensor, drive) = (&mut cautious.device.sensor, &mut cautious.device.drive);
        sensor.time_constant_s = sensor.time_constant_s.max(p.device.sensor.time_constant_s);
        drive.current_limit_a = drive.current_limit_a.min(p.device.drive.current_limit_a);
        let envelope = &mut cautious.envelope;
        envelope.sensor_time_constant_s = envelope.sensor_time_constant_s.max(p.envelope.sensor_time_constant_s);
    }
    Some(cautious)
}

/// The warning for a real display run on a datasheet device file (`origin`).
fn datasheet_warning(label: &str, origin: &str, state_dir: Option<&Path>, can_identify: bool) -> String {
    let looked = state_dir.map_or_else(String::new, |dir| {
        format!(
            " (no identified file for it in {})",
            dir.join(identified::DEVICES_DIR).display()
        )
    });
    let remedy = match can_identify {
        true => format!("identify the display once, bare: `thermode identify --device {label} --save`"),
        false => "identify each device once, bare, on its own: `thermode identify --device DEVICE --save`".to_string(),
    };
    format!(
        "WARNING: {label} runs on a datasheet device file, {origin}{looked}: the model controller and the \
         safety envelope's plate forecast use the datasheet's values, and the envelope's margins are the datasheet's \
         (a plant off its file, e.g. a sensor 30 % slower, makes the model controller overshoot by about 0.65 °C); \
         {remedy}"
    )
}

/// Builds the device and the pipelines from the arguments; `clock` stamps a serial device's readings. A real
/// display without `--device-file` runs the identified device file stored for it in `state_dir`
/// ([`crate::identified`]) when there is one (None: look nowhere); which file runs is said in
/// [`Display::notices`].
pub fn build_display(args: &DisplayArgs, clock: &Arc<dyn Clock>, state_dir: Option<&Path>) -> Result<Display> {
    let given_text = args.device_file.as_deref().map(resolve::read).transpose()?;
    let device_config = resolve::device_config(args.device_file.as_deref())?;
    let file_kind = identified::kind_of(&device_config, given_text.as_deref());
    let mut pipeline = pipeline_of(device_config, args.controller)?;
    let (mut pipelines, mut file_kinds) = (Vec::new(), vec![file_kind]);
    let label = args.label();
    let mut notices = Vec::new();
    let (device, label): (Box<dyn Device + Send>, String) = if args.is_sim() {
        // The simulated display is built from this very file, so the file is exact for it.
        pipeline.device = device_config.exact_for_its_simulation();
        let count = args.channels.unwrap_or(5);
        if count == 0 || count > MAX_CHANNELS {
            bail!("--channels must be 1 to {MAX_CHANNELS}, not {count}");
        }
        let display = SimulatedDisplay::<DefaultFinger>::fingertips(&device_config, count, args.seed)?;
        (Box::new(display), label)
    } else if args.device.iter().all(|d| is_hardware(d)) {
        let real = open_real(args, pipeline.clone(), file_kind, clock, state_dir, &mut notices)?;
        if let Some(n) = args.channels.filter(|&n| n != real.device.channel_count()) {
            bail!(
                "--channels {n}, but {label} has {} channels",
                real.device.channel_count()
            );
        }
        (pipelines, file_kinds) = (real.pipelines, real.kinds);
        (real.device, label)
    } else if args.device.len() > 1 && args.device.iter().any(|d| d == "sim") {
        bail!("--device sim is the simulated display alone; several --device name real devices only");
    } else {
        bail!(
            "--device must be `sim`, `serial:PATH`, `mecom:PATH[@ADDR]`, `mecom-tcp:HOST:PORT` or `tcs2:PATH`, not {:?}",
            args.device.iter().find(|d| !is_hardware(d)).unwrap_or(&label)
        );
    };
    let count = device.channel_count();
    let names = finger_names(count);
    let what = if label == "sim" {
        "simulated display".to_string()
    } else {
        format!("display on {label}")
    };
    let fingers = if names.is_empty() {
        String::new()
    } else {
        format!(" ({})", names.join(", "))
    };
    let plural = if count == 1 { "" } else { "s" };
    let description = format!(
        "{what}, {count} channel{plural}{fingers}, {} controller",
        pipeline.controller.name()
    );
    let engines = match pipelines.is_empty() {
        true => pipeline_engines(pipeline),
        false => pipeline_engines_per_channel(pipelines),
    };
    Ok(Display {
        device,
        engines,
        label,
        names,
        description,
        file_kinds,
        notices,
    })
}

/// A real display ready for the loop: its device and, per channel, its pipeline and what its device file is.
struct Real {
    device: Box<dyn Device + Send>,
    pipelines: Vec<PipelineConfig>,
    kinds: Vec<DeviceFileKind>,
}

/// Opens the real display of `args` for `pipeline` (from `--device-file` or the default display, of kind
/// `file_kind`). Without `--device-file`, each device with an identified file stored in `state_dir` runs it on its
/// own channels (and the devices are opened again with the most cautious of the files' limits); which file runs
/// where, and a warning for a datasheet file, go into `notices`. A calibrated file's channels read through it.
fn open_real(
    args: &DisplayArgs,
    pipeline: PipelineConfig,
    file_kind: DeviceFileKind,
    clock: &Arc<dyn Clock>,
    state_dir: Option<&Path>,
    notices: &mut Vec<String>,
) -> Result<Real> {
    let label = args.label();
    let mut device = open_hardware(args, &pipeline, clock)?;
    let stored = match (&args.device_file, state_dir) {
        (None, Some(dir)) => stored_files(dir, &label, device.as_ref())?,
        _ => Vec::new(),
    };
    if let Some(path) = &args.device_file {
        notices.push(format!(
            "using the device file {} given by --device-file for {label} ({})",
            path.display(),
            identified::kind_name(file_kind)
        ));
    }
    let (mut pipelines, mut kinds) = (Vec::new(), Vec::new());
    for (part, stored) in device.parts().iter().zip(stored.iter().chain(std::iter::repeat(&None))) {
        let name = identified::device_of(part, &label);
        let (part_pipeline, kind) = match stored {
            Some(stored) => {
                notices.push(format!(
                    "using the identified device file {} for {name}{} (identified {})",
                    stored.path.display(),
                    part.identity.as_ref().map_or_else(String::new, |i| format!(" ({i})")),
                    stored.identified_at.as_deref().unwrap_or("at an unknown time")
                ));
                (pipeline_of(stored.config, args.controller)?, stored.kind())
            }
            None => (pipeline.clone(), file_kind),
        };
        pipelines.extend(std::iter::repeat_n(part_pipeline, part.channel_count));
        kinds.extend(std::iter::repeat_n(kind, part.channel_count));
    }
    if let Some(cautious) = stored
        .iter()
        .any(Option::is_some)
        .then(|| most_cautious(&pipelines))
        .flatten()
    {
        // The devices' own limits follow the files they run: opened again with them.
        drop(device);
        device = open_hardware(args, &cautious, clock)?;
    }
    warn_datasheet(args, device.as_ref(), &kinds, state_dir, notices);
    for part in device.parts() {
        if let Some(commands) = part.health.as_ref().and_then(|h| h.command_set()) {
            eprintln!("thermode: {}: {commands}", identified::device_of(&part, &label));
        }
    }
    let calibrations: Vec<_> = pipelines.iter().map(|p| p.device.calibration).collect();
    if calibrations.iter().any(|c| c.is_set()) {
        let regulates = match device.measures().drive_current {
            true => "",
            false => "; the set-points the device regulates to are sent on its sensor's scale",
        };
        let read_through = |c: &CalibrationConfig| {
            format!(
                "the plate sensor read through its calibration (gain {}, offset {} °C){regulates}",
                c.sensor_gain, c.sensor_offset_c
            )
        };
        if calibrations.windows(2).all(|w| w[0] == w[1]) {
            eprintln!("thermode: {}", read_through(&calibrations[0]));
        } else {
            for (channel, c) in calibrations.iter().enumerate().filter(|(_, c)| c.is_set()) {
                eprintln!("thermode: channel {channel}: {}", read_through(c));
            }
        }
        device = Box::new(CalibratedDevice::per_channel(device, calibrations));
    }
    // A real display is tested against its file before a finger can be on it; a temperature-commanded device
    // (its own controller sets the current) cannot take the test's current pulse.
    let self_test = device.measures().drive_current;
    for p in &mut pipelines {
        p.self_test_at_start = self_test;
        p.temperature_commanded = !device.measures().drive_current;
    }
    Ok(Real {
        device,
        pipelines,
        kinds,
    })
}

/// The warning for the devices of a real display that run a datasheet file (`kinds` per channel): one for the
/// display when every channel does, else one per such device.
fn warn_datasheet(
    args: &DisplayArgs,
    device: &dyn Device,
    kinds: &[DeviceFileKind],
    state_dir: Option<&Path>,
    notices: &mut Vec<String>,
) {
    let origin = resolve::device_origin(args.device_file.as_deref());
    let label = args.label();
    if kinds.iter().all(|&k| k == DeviceFileKind::Datasheet) {
        notices.push(datasheet_warning(&label, &origin, state_dir, args.device.len() == 1));
        return;
    }
    for part in device.parts() {
        if kinds.get(part.first_channel) == Some(&DeviceFileKind::Datasheet) {
            let name = identified::device_of(&part, &label);
            notices.push(datasheet_warning(&name, &origin, state_dir, true));
        }
    }
}
