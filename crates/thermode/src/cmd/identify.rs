//! `thermode identify`: measures a display with no finger on it and writes its device file: an excitation inside
//! the safety envelope (steps and a pseudo-random sequence of direct set-points), recorded, and the thermal
//! parameters fitted with their confidence (`thermode_render::identify`, `thermode_control::identify`).
//!
//! The Peltier voltage fixes the absolute scale of the parameters (from temperatures alone only their ratios are
//! known), so only a display that reports it can be identified: today the simulated display (`--device sim`, whose
//! hidden hardware `--plant-device` sets). The serial protocols do not carry the voltage yet.

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;
use thermode_control::identify::PARAMETERS;
use thermode_render::identify::{identify_simulated, DURATION_S};

use crate::output::{print_stdout, write_atomically};
use crate::resolve;

/// Arguments of `thermode identify`.
#[derive(Args, Debug)]
pub struct IdentifyArgs {
    /// The display: `sim` (the simulated display; the serial protocols do not report the Peltier voltage yet).
    #[arg(long, value_name = "sim", default_value = "sim")]
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
    /// Write the identified device file here; default: print it.
    #[arg(long, value_name = "FILE.toml")]
    out: Option<PathBuf>,
}

/// Runs `thermode identify`.
pub fn run(args: &IdentifyArgs) -> Result<()> {
    if args.device != "sim" {
        bail!(
            "--device {}: identify needs the Peltier voltage, which thermode's serial protocols do not carry yet; \
             it runs on the simulated display (`--device sim --plant-device FILE`)",
            args.device
        );
    }
    let believed = resolve::device_config(args.device_file.as_deref())?;
    let plant = match &args.plant_device {
        Some(path) => resolve::device_config(Some(path))?,
        None => believed,
    };
    eprintln!("identify: {DURATION_S} s of excitation on the simulated display, no finger on the plate…");
    let (fit, device) = identify_simulated(&believed, &plant, args.seed)?;
    let origin = resolve::device_origin(args.device_file.as_deref());
    let mut lines = vec![
        format!("Identified by `thermode identify` from {origin} ({DURATION_S} s of excitation, no finger)."),
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
    let header: String = lines.iter().map(|l| format!("# {l}\n")).collect();
    let text = format!("{header}{}", device.to_toml_string());
    match &args.out {
        Some(path) => write_atomically(path, |sink| Ok(sink.write_all(text.as_bytes())?)),
        None => print_stdout(&text),
    }
}
