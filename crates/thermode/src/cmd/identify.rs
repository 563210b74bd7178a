//! `thermode identify`: measures a display with no finger on it and writes its device file: an excitation inside
//! the safety envelope (steps and a pseudo-random sequence of direct set-points), recorded, and the thermal
//! parameters fitted with their confidence (`thermode_render::identify`, `thermode_control::identify`).
//!
//! The Peltier voltage fixes the absolute scale of the parameters (from temperatures alone only their ratios are
//! known), so only a display that reports it can be identified: the simulated display (`--device sim`, whose
//! hidden hardware `--plant-device` sets; run in simulated time) and Meerstetter TEC controllers in current mode
//! (`--device mecom:…`, in real time; thermode's own protocol and the TCS II carry no voltage).

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::Args;
use thermode_control::identify::{IdSample, PARAMETERS};
use thermode_device::DeviceConfig;
use thermode_model::params::Rule;
use thermode_platform::{Clock, MonotonicClock};
use thermode_render::identify::{fit, record, sample_of, Excitation, DURATION_S, RATE_HZ};

use crate::controller::ControllerArg;
use crate::display::{build_display, DisplayArgs};

use crate::output::{check_outputs, print_stdout, write_atomically};
use crate::progress::Progress;
use crate::resolve;

/// A fit whose sensor residual exceeds this many times the sensor's noise is refused: 10 (the fits of a bare
/// display measured 1.0–2.5; with a finger resting on the plate, 57).
const MAX_RESIDUAL_NOISES: f64 = 10.0;

/// Arguments of `thermode identify`.
#[derive(Args, Debug)]
pub struct IdentifyArgs {
    /// The display: `sim` (the simulated display, in simulated time) or `mecom:PATH` / `mecom-tcp:HOST:PORT` (a
    /// Meerstetter TEC controller in current mode, in real time); the others report no Peltier voltage.
    #[arg(long, value_name = "sim|mecom:PATH|mecom-tcp:HOST:PORT", default_value = "sim")]
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
    /// Length of the excitation [s], 30 to 160 (the whole sequence; shorter runs stop it early).
    #[arg(long, value_name = "S", default_value_t = DURATION_S)]
    duration: f64,
    /// Write the identified device file here; default: print it.
    #[arg(long, value_name = "FILE.toml")]
    out: Option<PathBuf>,
}

/// Runs `thermode identify`.
pub fn run(args: &IdentifyArgs) -> Result<()> {
    let sim = args.device == "sim";
    if !(sim || args.device.starts_with("mecom:") || args.device.starts_with("mecom-tcp:")) {
        bail!(
            "--device {}: identify needs the Peltier voltage, which thermode's own protocol and the TCS II do not \
             report; it runs on `sim` and on Meerstetter TEC controllers (`mecom:PATH`, `mecom-tcp:HOST:PORT`)",
            args.device
        );
    }
    if args.plant_device.is_some() && !sim {
        bail!("--plant-device sets the simulated display's hardware; it needs --device sim");
    }
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
    eprintln!(
        "identify: {} s of excitation on {}, no finger on the plate…",
        args.duration, args.device
    );
    let samples = if sim {
        let _simulating = Progress::spinner("identify: simulating the excitation");
        record(&believed, &plant, args.seed, args.duration)?
    } else {
        record_in_real_time(args, &believed)?
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
    let sensor_sd_c = believed
        .sensor
        .noise_c
        .hypot(believed.sensor.resolution_c / 12f64.sqrt());
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
    match &args.out {
        Some(path) => write_atomically(path, |sink| Ok(sink.write_all(text.as_bytes())?)),
        None => print_stdout(&text),
    }
}

/// Runs the excitation on the hardware of `args` in real time (channel 0) and returns the record; every drive is
/// switched off at the end, also after an error.
fn record_in_real_time(args: &IdentifyArgs, believed: &DeviceConfig) -> Result<Vec<IdSample>> {
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    let display = DisplayArgs::one(&args.device, args.device_file.clone(), ControllerArg::Model, args.seed);
    let mut device = build_display(&display, &clock)?.device;
    let mut excitation = Excitation::new(believed)?;
    let dt_s = 1.0 / RATE_HZ;
    let ticks = (args.duration * RATE_HZ).round() as usize;
    let mut samples = Vec::with_capacity(ticks + 1);
    let start_s = clock.now_s();
    let progress = Progress::seconds(args.duration, "identify: excitation");
    let run = (|| -> Result<()> {
        for tick in 0..=ticks {
            progress.at_s(tick as f64 * dt_s);
            let deadline_s = start_s + tick as f64 * dt_s;
            while clock.now_s() < deadline_s {
                clock.sleep_until(deadline_s);
            }
            let now_s = clock.now_s();
            device.poll(now_s);
            let reading = device.read(0)?;
            samples.push(sample_of(&reading));
            if tick < ticks {
                let drive = excitation.tick(now_s, dt_s, &reading)?;
                device.apply(0, &drive)?;
            }
        }
        Ok(())
    })();
    progress.finish();
    let off = device.all_off().context("switching the drive off after the excitation");
    run?;
    off?;
    Ok(samples)
}
