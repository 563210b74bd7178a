//! `thermode identify`: measures a display with no finger on it and writes its device file: an excitation inside
//! the safety envelope (steps and a pseudo-random sequence of direct set-points), recorded, and the thermal
//! parameters fitted with their confidence (`thermode_render::identify`, `thermode_control::identify`).
//!
//! The Peltier voltage fixes the absolute scale of the parameters (from temperatures alone only their ratios are
//! known), so only a display that reports it is identified whole: the simulated display (`--device sim`, whose
//! hidden hardware `--plant-device` sets; run in simulated time) and Meerstetter TEC controllers in current mode
//! (`--device mecom:…`, in real time). Thermode's own protocol carries no voltage and is refused.
//!
//! A temperature-commanded device (a TCS II, `tcs2:PATH`; a MeCom controller with `?mode=temperature`) regulates its
//! plate itself: what its sensor alone tells is identified from set-point steps through its own regulation
//! ([`thermode_render::identify_steps`]): the sensor's lag (from the bare plate relaxing with the output off on a
//! MeCom controller; an upper bound from the steps' tails on a TCS II, which cannot switch its output off) and the
//! plate's closed-loop response. The identified file differs from the believed one in the sensor's time constant and
//! its uncertainty, which the safety envelope's plate estimate uses.
//!
//! `--save` stores the identified file of a real device in the state directory under the device's identity
//! ([`crate::identified`]), where `serve`, `lab run --device` and `bench` find it.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::Args;
use thermode_control::identify::{IdSample, PARAMETERS};
use thermode_device::{Device, DeviceConfig, Reading};
use thermode_model::params::Rule;
use thermode_pipeline::self_test::{RestWatch, REST_DRIFT_C_PER_S, REST_WINDOW_S};
use thermode_platform::{utc_iso8601, Clock, MonotonicClock};
use thermode_render::identify::{fit, record, sample_of, Excitation, DURATION_S, RATE_HZ};
use thermode_render::identify_steps::{self, StepExcitation, StepIdentification, StepMethod, StepRecord};
use thermode_safety::DriveCommand;

use crate::controller::ControllerArg;
use crate::display::{build_display, DisplayArgs};
use crate::identified;

use crate::output::{check_outputs, print_stdout, write_atomically};
use crate::progress::Progress;
use crate::resolve;

/// A fit whose sensor residual exceeds this many times the sensor's noise is refused: 10 (the fits of a bare
/// display measured 1.0–2.5; with a finger resting on the plate, 57).
const MAX_RESIDUAL_NOISES: f64 = 10.0;

/// Arguments of `thermode identify`.
#[derive(Args, Debug)]
pub struct IdentifyArgs {
    /// The display: `sim` (the simulated display, in simulated time), `mecom:PATH` / `mecom-tcp:HOST:PORT` (a
    /// Meerstetter TEC controller, in real time: whole in current mode, its sensor's lag with `?mode=temperature`)
    /// or `tcs2:PATH` (a TCS II: its sensor's lag, an upper bound); thermode's own protocol reports no voltage.
    #[arg(
        long,
        value_name = "sim|mecom:PATH|mecom-tcp:HOST:PORT|tcs2:PATH",
        default_value = "sim"
    )]
    device: String,
    /// The device file the controller starts from (TOML); default: the built-in default display.
    #[arg(long = "device-file", value_name = "FILE")]
    device_file: Option<PathBuf>,
    /// With `--device sim`: the device file of the simulated hardware (what identify has to find); default: the
    /// `--device-file`.
    #[arg(long = "plant-device", value_name = "FILE")]
    plant_device: Option<PathBuf>,
    /// Seed of the simulated sensor noise.
    #[arg(long, value_name = "N", default_value_t = 1)]
    seed: u64,
    /// Length of the excitation [s], 30 to 160 (the whole sequence; shorter runs stop it early). A
    /// temperature-commanded device runs its steps until each settles instead.
    #[arg(long, value_name = "S", default_value_t = DURATION_S)]
    duration: f64,
    /// Write the identified device file here; default: print it (unless --save).
    #[arg(long, value_name = "FILE.toml")]
    out: Option<PathBuf>,
    /// Store the identified device file in the state directory under the device's identity
    /// (`STATE_DIR/devices/mecom-SN<serial>.toml`), where `serve`, `lab run --device` and `bench` find it for that
    /// device when no --device-file is given. Real devices only.
    #[arg(long)]
    save: bool,
    /// The state directory of --save (as `serve --state-dir`) [default: $XDG_STATE_HOME/thermode, else
    /// ~/.local/state/thermode].
    #[arg(long = "state-dir", value_name = "DIR", requires = "save")]
    state_dir: Option<PathBuf>,
}

/// The device identify ran on, as its identified file is known: its `--device` spelling and what it reported that
/// tells it apart (a MeCom controller's serial number), if anything.
struct Identity {
    device: String,
    identity: Option<String>,
}

/// Runs `thermode identify`.
pub fn run(args: &IdentifyArgs) -> Result<()> {
    let sim = args.device == "sim";
    let known = ["mecom:", "mecom-tcp:", "tcs2:"];
    if !(sim || known.iter().any(|p| args.device.starts_with(p))) {
        bail!(
            "--device {}: identify needs the Peltier voltage, which thermode's own protocol does not report; it runs \
             on `sim`, on Meerstetter TEC controllers (`mecom:PATH`, `mecom-tcp:HOST:PORT`) and, their sensor's lag \
             only, on temperature-commanded devices (`tcs2:PATH`, `mecom:PATH?mode=temperature`)",
            args.device
        );
    }
    if args.plant_device.is_some() && !sim {
        bail!("--plant-device sets the simulated display's hardware; it needs --device sim");
    }
    if args.save && sim {
        bail!("--save stores a real device's identified file; the simulated display is built from its file exactly");
    }
    let state_dir = match args.save {
        true => Some(super::dose::state_dir(args.state_dir.as_deref())?),
        false => None,
    };
    let duration = Rule::Within {
        min: 30.0,
        max: DURATION_S,
    };
    duration.check("--duration [s]", args.duration)?;
    let believed = resolve::device_config(args.device_file.as_deref())?;
    let plant = match &args.plant_device {
        Some(path) => resolve::device_config(Some(path))?,
        None => believed,
    };
    // Every input read and the output's folder writable before minutes of excitation.
    check_outputs(&[("--out", args.out.as_deref())])?;
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    let device = match sim {
        true => None,
        false => {
            let display = DisplayArgs::one(&args.device, args.device_file.clone(), ControllerArg::Model, args.seed);
            Some(build_display(&display, &clock, None)?.device)
        }
    };
    let device = match device {
        Some(device) if !device.measures().drive_current => {
            return identify_temperature_commanded(args, &believed, device, &clock, state_dir.as_deref());
        }
        device => device,
    };
    eprintln!(
        "identify: {} s of excitation on {}, no finger on the plate…",
        args.duration, args.device
    );
    let (samples, identity) = match device {
        None => {
            let _simulating = Progress::spinner("identify: simulating the excitation");
            (record(&believed, &plant, args.seed, args.duration)?, None)
        }
        Some(device) => {
            let (samples, identity) = record_in_real_time(args, &believed, device, &clock)?;
            (samples, Some(identity))
        }
    };
    let progress = Progress::spinner("identify: fitting the model");
    let (fit, device) = fit(&believed, &samples)?;
    progress.finish();
    let origin = resolve::device_origin(args.device_file.as_deref());
    let mut lines = vec![
        format!(
            "Identified by `thermode identify` on {} from {origin} ({} s of excitation, no finger).",
            args.device, args.duration
        ),
        format!(
            "RMS residuals: sensor {:.4} °C, hot side {:.4} °C, voltage {:.5} V; {} iterations.",
            fit.rms_residuals[0], fit.rms_residuals[1], fit.rms_residuals[2], fit.iterations
        ),
        "Standard deviation of each fitted parameter (relative; the water in °C):".to_string(),
    ];
    for (name, sd) in PARAMETERS.iter().zip(fit.relative_sd) {
        lines.push(match *name {
            "water_c" => format!("  {name}: ±{sd:.4} °C"),
            _ => format!("  {name}: ±{:.3} %", 100.0 * sd),
        });
    }
    eprintln!("{}", lines.join("\n"));
    let sensor_sd_c = sensor_sd_c(&believed);
    if fit.rms_residuals[0] > MAX_RESIDUAL_NOISES * sensor_sd_c {
        bail!(
            "the model does not explain the record (sensor residual {:.3} °C against {sensor_sd_c:.3} °C of noise): \
             was a finger or an object on the plate, or does the display differ from the model's structure? \
             Nothing written",
            fit.rms_residuals[0]
        );
    }
    let header: String = lines.iter().map(|l| format!("# {l}\n")).collect();
    let text = format!("{header}{}", device.to_toml_string());
    write_identified(args, state_dir.as_deref().zip(identity.as_ref()), &text)
}

/// The sensor's noise \[°C\] of `device`: its noise and its resolution's quantisation, in quadrature.
fn sensor_sd_c(device: &DeviceConfig) -> f64 {
    device.sensor.noise_c.hypot(device.sensor.resolution_c / 12f64.sqrt())
}

/// Writes the identified file `text`: saved in the state directory under the identity (with `--save`: `saved`),
/// to `--out`, or printed when neither is given.
fn write_identified(args: &IdentifyArgs, saved: Option<(&Path, &Identity)>, text: &str) -> Result<()> {
    if let Some((dir, identity)) = saved {
        save(dir, identity, text)?;
    }
    match &args.out {
        Some(path) => write_atomically(path, |sink| Ok(sink.write_all(text.as_bytes())?)),
        None if args.save => Ok(()),
        None => print_stdout(text),
    }
}

/// Stores `text` (the identified device file) in `state_dir` as the identified file of `identity`, atomically.
fn save(state_dir: &Path, identity: &Identity, text: &str) -> Result<()> {
    let path = identified::path_in(state_dir, &identity.device, identity.identity.as_deref());
    let folder = path.parent().unwrap_or(state_dir);
    std::fs::create_dir_all(folder).with_context(|| format!("cannot create {}", folder.display()))?;
    let now_s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() as i64);
    let stored = identified::stored_text(
        &identity.device,
        identity.identity.as_deref(),
        &utc_iso8601(now_s),
        text,
    );
    write_atomically(&path, |sink| Ok(sink.write_all(stored.as_bytes())?))?;
    let who = identity.identity.as_deref().map_or_else(
        || "known by its port: it reports no serial number".to_string(),
        |i| format!("identity {i}"),
    );
    eprintln!(
        "identify: saved as the identified device file of {} ({who}): {}; serve, lab run --device and bench use it \
         for that device when no --device-file is given",
        identity.device,
        path.display()
    );
    Ok(())
}

/// Runs the excitation on `device` (the hardware of `args`) in real time (channel 0) and returns the record and the
/// device's identity; every drive is switched off at the end, also after an error.
fn record_in_real_time(
    args: &IdentifyArgs,
    believed: &DeviceConfig,
    mut device: Box<dyn Device + Send>,
    clock: &Arc<dyn Clock>,
) -> Result<(Vec<IdSample>, Identity)> {
    let identity = identity_of(args, device.as_ref());
    wait_for_rest(device.as_mut(), clock)?;
    let mut excitation = Excitation::new(believed)?;
    let ticks = (args.duration * RATE_HZ).round() as usize;
    let mut samples = Vec::with_capacity(ticks + 1);
    let progress = Progress::seconds(args.duration, "identify: excitation");
    let mut tick = 0;
    drive_in_real_time(device.as_mut(), clock, |now_s, dt_s, reading| {
        progress.at_s(tick as f64 * dt_s);
        samples.push(sample_of(reading));
        tick += 1;
        if tick > ticks {
            return Ok(None);
        }
        Ok(Some(excitation.tick(now_s, dt_s, reading)?))
    })?;
    progress.finish();
    Ok((samples, identity))
}

/// Longest wait for the plate to rest before an excitation \[s\]: 180 (a plate a `serve` left at 45 °C relaxes to
/// within the rest slope in about a minute on the default display).
const REST_WAIT_LIMIT_S: f64 = 180.0;

/// Waits, output off, until channel 0's plate and hot side rest (their least-squares slopes over
/// [`REST_WINDOW_S`] below [`REST_DRIFT_C_PER_S`], as the self-test judges rest), at most [`REST_WAIT_LIMIT_S`]:
/// the fit starts from a plate at rest, which one a `serve` just left is not.
fn wait_for_rest(device: &mut (dyn Device + Send), clock: &Arc<dyn Clock>) -> Result<()> {
    let mut watch = RestWatch::new(REST_WINDOW_S, (4.0 * REST_WINDOW_S * RATE_HZ) as usize);
    let progress = Progress::seconds(REST_WAIT_LIMIT_S, "identify: waiting for the plate to rest");
    let mut started_s = None;
    drive_in_real_time(device, clock, |now_s, _, reading| {
        let start_s = *started_s.get_or_insert(now_s);
        progress.at_s(now_s - start_s);
        watch.push(reading);
        let drift = watch.drift_c_per_s();
        if drift.is_some_and(|(plate, hot)| plate.abs() < REST_DRIFT_C_PER_S && hot.abs() < REST_DRIFT_C_PER_S) {
            return Ok(None);
        }
        if now_s - start_s > REST_WAIT_LIMIT_S {
            let (plate, hot) = drift.unwrap_or((f64::NAN, f64::NAN));
            bail!(
                "the plate did not come to rest within {REST_WAIT_LIMIT_S} s with its output off (slopes: plate \
                 {plate:.3} °C/s, hot side {hot:.3} °C/s, at most {REST_DRIFT_C_PER_S} allowed): is a finger or an \
                 object on it? Nothing written"
            );
        }
        Ok(Some(DriveCommand::off()))
    })?;
    progress.finish();
    Ok(())
}

/// The identity of the device of `args` as `device` reports it.
fn identity_of(args: &IdentifyArgs, device: &dyn Device) -> Identity {
    Identity {
        device: args.device.clone(),
        identity: device.parts().first().and_then(|p| p.identity.clone()),
    }
}

/// Runs `step` on channel 0 of `device` at [`RATE_HZ`] in real time (`step` gets the tick's time \[s\], its length
/// \[s\] and the reading, and returns the command to apply, or `None` to stop); every drive is switched off at the
/// end, also after an error.
fn drive_in_real_time(
    device: &mut (dyn Device + Send),
    clock: &Arc<dyn Clock>,
    mut step: impl FnMut(f64, f64, &Reading) -> Result<Option<DriveCommand>>,
) -> Result<()> {
    let dt_s = 1.0 / RATE_HZ;
    let start_s = clock.now_s();
    let run = (|| -> Result<()> {
        for tick in 0.. {
            let deadline_s = start_s + tick as f64 * dt_s;
            while clock.now_s() < deadline_s {
                clock.sleep_until(deadline_s);
            }
            let now_s = clock.now_s();
            device.poll(now_s);
            let reading = device.read(0)?;
            match step(now_s, dt_s, &reading)? {
                Some(drive) => device.apply(0, &drive)?,
                None => return Ok(()),
            }
        }
        Ok(())
    })();
    let off = device.all_off().context("switching the drive off after the excitation");
    run?;
    off?;
    Ok(())
}

/// `thermode identify` on the temperature-commanded `device` (opened from `args`): the steps of
/// [`identify_steps`] in real time on channel 0, the sensor's lag fitted, the file written (and saved in
/// `state_dir` with `--save`).
fn identify_temperature_commanded(
    args: &IdentifyArgs,
    believed: &DeviceConfig,
    mut device: Box<dyn Device + Send>,
    clock: &Arc<dyn Clock>,
    state_dir: Option<&Path>,
) -> Result<()> {
    let method = match args.device.starts_with("tcs2:") {
        true => StepMethod::Tail,
        false => StepMethod::Relaxation,
    };
    let identity = identity_of(args, device.as_ref());
    eprintln!(
        "identify: {} regulates its plate itself: its sensor's lag is identified from set-point steps ({}), no \
         finger on the plate…",
        args.device,
        match method {
            StepMethod::Relaxation => "the bare plate relaxing with the output off after each plateau",
            StepMethod::Tail => "the steps' tails: an upper bound, the device cannot switch its output off",
        }
    );
    let record = record_steps(device.as_mut(), clock, believed, method)?;
    drop(device);
    let found = identify_steps::identify_steps(&record, method, believed)?;
    let identified = identify_steps::identified_device(believed, &found.lag)?;
    let lines = step_lines(args, &found, believed);
    eprintln!("{}", lines.join("\n"));
    let sensor_sd_c = sensor_sd_c(believed);
    if found.lag.rms_c > MAX_RESIDUAL_NOISES * sensor_sd_c {
        bail!(
            "the model does not explain the steps (residual {:.3} °C against {sensor_sd_c:.3} °C of noise): was a \
             finger or an object on the plate? Nothing written",
            found.lag.rms_c
        );
    }
    let header: String = lines.iter().map(|l| format!("# {l}\n")).collect();
    let text = format!("{header}{}", identified.to_toml_string());
    write_identified(args, state_dir.map(|dir| (dir, &identity)), &text)
}

/// Runs the steps of `method` on channel 0 of `device` in real time and returns the record.
fn record_steps(
    device: &mut (dyn Device + Send),
    clock: &Arc<dyn Clock>,
    believed: &DeviceConfig,
    method: StepMethod,
) -> Result<StepRecord> {
    let mut excitation = StepExcitation::new(believed, method)?;
    let progress = Progress::spinner("identify: steps");
    drive_in_real_time(device, clock, |now_s, dt_s, reading| {
        let drive = excitation.tick(now_s, dt_s, reading)?;
        Ok((!excitation.done()).then_some(drive))
    })?;
    progress.finish();
    Ok(excitation.into_record())
}

/// The header lines of a file identified from steps: how, the lag with its uncertainty and each window's, and the
/// plate's closed-loop response to each step.
fn step_lines(args: &IdentifyArgs, found: &StepIdentification, believed: &DeviceConfig) -> Vec<String> {
    let origin = resolve::device_origin(args.device_file.as_deref());
    let (how, what) = match found.method {
        StepMethod::Relaxation => ("relaxations of the bare plate with the output off", "the sensor's lag"),
        StepMethod::Tail => (
            "tails of regulated set-point steps",
            "an upper bound of the sensor's lag",
        ),
    };
    let lag = &found.lag;
    let mut lines = vec![
        format!(
            "Identified by `thermode identify` on {} from {origin} (temperature-commanded: {how}, no finger).",
            args.device
        ),
        format!(
            "Sensor time constant ({what}): {:.4} ± {:.4} s (the file had {} s); RMS residual {:.4} °C.",
            lag.time_constant_s, lag.sd_s, believed.sensor.time_constant_s, lag.rms_c
        ),
    ];
    for (k, w) in found.windows.iter().enumerate() {
        let plate = match w.plate_time_constant_s.is_finite() {
            true => format!(", plate relaxing with {:.2} s", w.plate_time_constant_s),
            false => String::new(),
        };
        lines.push(format!(
            "  window {k}: {:.4} ± {:.4} s{plate}",
            w.time_constant_s, w.sd_s
        ));
    }
    for r in &found.responses {
        lines.push(format!(
            "Plate's closed-loop response to {:+.1} °C to {:.1} °C: within 10 % in {:.2} s, overshoot {:.2} °C.",
            r.step_c, r.setpoint_c, r.rise_s, r.overshoot_c
        ));
    }
    lines.push(
        "Not identified (no current or voltage from the device): the module, the heat capacities, the water; the \
         believed file's values are kept."
            .to_string(),
    );
    lines
}
