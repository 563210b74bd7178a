//! `thermode tune`: finds the PID gains and sensor-filter cut-off of the paper's controller structure that minimise
//! the mean RMS skin error over the paper's five materials on one display, and writes them as a gains file.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use thermode_pipeline::controllers::gains_to_toml_string;
use thermode_render::tune::{tune_with_progress, TuneResult, TuneSpec};

use crate::cmd::render::RendererArg;
use crate::output::{check_outputs, print_stdout, write_atomically};
use crate::progress::Progress;
use crate::resolve;

/// Arguments of `thermode tune`.
#[derive(Args, Debug)]
pub struct TuneArgs {
    /// Device file (TOML); default: the built-in default display.
    #[arg(long, value_name = "FILE")]
    device_file: Option<PathBuf>,
    /// Write the gains file here; default: print it.
    #[arg(long, value_name = "GAINS.toml")]
    out: Option<PathBuf>,
    /// Renderer (and display-inverse finger model) to tune for.
    #[arg(long, value_enum, default_value = "fv")]
    model: RendererArg,
    /// Seed of the simulated sensor noise (as `thermode render --seed`).
    #[arg(long, value_name = "N", default_value_t = thermode_render::run::DEFAULT_SEED)]
    seed: u64,
    /// Largest number of objective evaluations (each renders the five materials for 95 s).
    #[arg(long = "max-evaluations", value_name = "N", default_value_t = thermode_render::tune::DEFAULT_MAX_EVALUATIONS)]
    max_evaluations: usize,
}

/// Runs `thermode tune`.
pub fn run(args: &TuneArgs) -> Result<()> {
    let device = resolve::device_config(args.device_file.as_deref())?;
    let origin = resolve::device_origin(args.device_file.as_deref());
    check_outputs(&[("--out", args.out.as_deref())])?;
    let mut spec = TuneSpec::new(device);
    spec.renderer = args.model.into();
    spec.seed = args.seed;
    spec.max_evaluations = args.max_evaluations;
    let started = Instant::now();
    let progress = Progress::bar(spec.max_evaluations as u64, "evaluations (at most)", "tune");
    let result = tune_with_progress(&spec, &mut |n, value, _| {
        progress.line(&format!("evaluation {n:4}: mean RMS skin error {value:.5} °C"));
        progress.at(n as u64);
    })
    .context("tuning")?;
    progress.finish();
    eprintln!("{}", report(&result, started.elapsed().as_secs_f64()));
    let text = gains_to_toml_string(&result.gains, &header(&result, &origin, &spec));
    match &args.out {
        Some(path) => write_atomically(path, |sink| Ok(sink.write_all(text.as_bytes())?)),
        None => print_stdout(&text),
    }
}

/// The comment on top of the gains file.
fn header(result: &TuneResult, origin: &str, spec: &TuneSpec) -> String {
    let materials: Vec<&str> = result.per_material_c.iter().map(|(m, _)| m.as_str()).collect();
    let per_material: Vec<String> = result
        .per_material_c
        .iter()
        .map(|(m, v)| format!("{m} {v:.4}"))
        .collect();
    format!(
        "PID gains of the paper's structure (low-pass filtered sensor, PID), tuned by `thermode tune` for {origin}\n\
         (renderer {}, tick {} Hz, seed {}): mean RMS skin error (skin − target, 0–90 s after contact) over\n\
         {} — start {:.4} °C, tuned {:.4} °C after {} evaluations.\n\
         Per material [°C]: {}.\n\
         Parameters at a search bound: {}.",
        spec.renderer.name(),
        thermode_render::run::DEFAULT_RATE_HZ,
        spec.seed,
        materials.join(", "),
        result.start_objective_c,
        result.objective_c,
        result.evaluations,
        per_material.join(", "),
        if result.at_bound.is_empty() {
            "none".to_string()
        } else {
            result.at_bound.join(", ")
        }
    )
}

/// What the tuner found, for standard error.
fn report(result: &TuneResult, seconds: f64) -> String {
    let g = &result.gains;
    let s = &result.start;
    let mut out = format!(
        "start  kp {:.5} A/°C  ki {:.5} A/(°C·s)  kd {:.5} A·s/°C  filter {:.3} Hz  objective {:.5} °C\n\
         tuned  kp {:.5} A/°C  ki {:.5} A/(°C·s)  kd {:.5} A·s/°C  filter {:.3} Hz  objective {:.5} °C\n",
        s.kp_a_per_c,
        s.ki_a_per_c_s,
        s.kd_a_s_per_c,
        s.filter_cutoff_hz,
        result.start_objective_c,
        g.kp_a_per_c,
        g.ki_a_per_c_s,
        g.kd_a_s_per_c,
        g.filter_cutoff_hz,
        result.objective_c
    );
    for (material, rms) in &result.per_material_c {
        out.push_str(&format!("  {material:<10} RMS skin error {rms:.5} °C\n"));
    }
    out.push_str(&format!("{} evaluations in {seconds:.1} s", result.evaluations));
    if !result.at_bound.is_empty() {
        out.push_str(&format!(
            "\nwarning: at a search bound: {} (the optimum may lie beyond it)",
            result.at_bound.join(", ")
        ));
    }
    out
}
