//! `thermode render`: renders the touch of one or more materials on the simulated display — renderer, display
//! inverse, controller, safety envelope, plant — next to the ground truth, and writes the trajectory (CSV), the
//! paper's Figure 3 for the simulated system (plot) and the summary metrics (text or JSON).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use thermode_control::PidGains;
use thermode_device::DeviceConfig;
use thermode_pipeline::controllers::GainsSource;
use thermode_pipeline::pipeline::render_envelope_with_rate;
use thermode_pipeline::self_test::Verdict;
use thermode_pipeline::{gains_for_device, ControllerKind, PipelineConfig, RendererKind};
use thermode_plot::write_figure;
use thermode_render::figure::figure3;
use thermode_render::run::{
    render_all_with_progress, write_csv, RenderRun, DEFAULT_DURATION_S, DEFAULT_PRE_CONTACT_S, DEFAULT_RATE_HZ,
};
use thermode_render::summary::{summary_table, RenderSummary};
use thermode_render::RenderSpec;

use crate::controller::{ControllerArg, RENDER_CONTROLLERS};
use crate::output::{
    check_columnar_precision, check_outputs, create_folder_of, csv_precision, is_stdout, print_stdout,
    write_atomically, write_columnar,
};
use crate::progress::Progress;
use crate::resolve;
use thermode_table::{Table, Values};

/// The renderer (and display-inverse finger model).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RendererArg {
    /// The paper's three-layer model (Kron); receptor at the epidermis centre (T1).
    Kron,
    /// The finite-volume reference (physics-true); receptor at the skin surface.
    Fv,
}

impl From<RendererArg> for RendererKind {
    fn from(arg: RendererArg) -> Self {
        match arg {
            RendererArg::Kron => RendererKind::Kron,
            RendererArg::Fv => RendererKind::Fv,
        }
    }
}

/// Format of the summary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormatArg {
    /// Aligned text table.
    Text,
    /// A JSON array, one object per run.
    Json,
}

/// Arguments of `thermode render`.
#[derive(Args, Debug)]
pub struct RenderArgs {
    /// Material from the library (see `thermode materials`); repeatable; `all-paper` = the paper's five.
    #[arg(long = "material", value_name = "NAME", required_unless_present = "material_files")]
    materials: Vec<String>,
    /// A material file (TOML, the format of `simulate --material-file` and `thermode materials`); repeatable.
    #[arg(long = "material-file", value_name = "FILE")]
    material_files: Vec<PathBuf>,
    /// Controller.
    #[arg(long, default_value = "model", value_parser = ControllerArg::parser(&RENDER_CONTROLLERS))]
    controller: ControllerArg,
    /// Renderer: the finger model that computes the target and runs on the display. The target is its receptor
    /// (fv: the skin surface; kron: T1, the centre of the epidermis), and the simulated finger (`skin_c`) and the
    /// truth (`truth_skin_c`) are read at that same depth in the simulated finger's skin.
    #[arg(long, value_enum, default_value = "fv")]
    model: RendererArg,
    /// Device file (TOML); default: the built-in default display.
    #[arg(long, value_name = "FILE")]
    device_file: Option<PathBuf>,
    /// Device file of the simulated hardware when it differs from the one the controller believes (`--device-file`):
    /// how the pipeline copes with a display that is not its datasheet. Default: the same file.
    #[arg(long = "plant-device", value_name = "FILE")]
    plant_device: Option<PathBuf>,
    /// PID gains file (TOML); default: the tuned gains of the shipped display that matches the device.
    #[arg(long = "pid-gains", value_name = "FILE")]
    pid_gains: Option<PathBuf>,
    /// Skin file of the simulated finger (TOML); default: the built-in fingertip (the controller's own model).
    #[arg(long = "finger-skin", value_name = "FILE")]
    finger_skin: Option<PathBuf>,
    /// Contact conductance between the simulated finger and the plate [W/m²K]; default: the device file's.
    #[arg(long = "finger-contact", value_name = "W_M2K", allow_negative_numbers = true)]
    finger_contact: Option<f64>,
    /// Object temperature at the touch [°C]; default: the ambient 23 °C.
    #[arg(long = "object-temp", value_name = "C", allow_negative_numbers = true)]
    object_temp: Option<f64>,
    /// Recorded time after the touch [s].
    #[arg(long, value_name = "S", default_value_t = DEFAULT_DURATION_S, allow_negative_numbers = true)]
    duration: f64,
    /// Time the finger rests on the display rendering air before the touch [s].
    #[arg(long = "pre-contact", value_name = "S", default_value_t = DEFAULT_PRE_CONTACT_S, allow_negative_numbers = true)]
    pre_contact: f64,
    /// Time after the touch at which the finger lets go [s]; default: never.
    #[arg(long = "release-at", value_name = "S", allow_negative_numbers = true)]
    release_at: Option<f64>,
    /// Tick rate of the pipeline [Hz].
    #[arg(long, value_name = "HZ", default_value_t = DEFAULT_RATE_HZ, allow_negative_numbers = true)]
    rate: f64,
    /// Set-point rate limit of the safety envelope [°C/s], at most 300; default: the device file's
    /// render.max_setpoint_rate_c_per_s (20 for the default display).
    #[arg(long = "max-rate", value_name = "C_PER_S", allow_negative_numbers = true)]
    max_rate: Option<f64>,
    /// Seed of the simulated sensor noise.
    #[arg(long, value_name = "N", default_value_t = thermode_render::run::DEFAULT_SEED)]
    seed: u64,
    /// Write every tick of every run as CSV; `-`: standard output (the summary then goes to standard error). A name
    /// ending in .arrow or .feather writes Arrow IPC (Feather v2), .parquet Parquet: the same columns, every number
    /// exact.
    #[arg(long, value_name = "FILE.csv")]
    out: Option<PathBuf>,
    /// Draw the paper's Figure 3 for the simulated system (.svg or .png).
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
    /// Decimal places of the CSV's numbers (0-12, correctly rounded as `{:.N}` rounds them; `time_s` stays exact);
    /// default: every number exact, the shortest digits that read back as the same value (larger, and about four
    /// times slower to write).
    #[arg(long, value_name = "DECIMALS", value_parser = clap::value_parser!(u8).range(0..=i64::from(thermode_platform::csv_text::MAX_DECIMALS)))]
    precision: Option<u8>,
    /// Print the summary metrics (also printed when neither --out nor --plot is given).
    #[arg(long)]
    summary: bool,
    /// Format of the summary.
    #[arg(long, value_enum, default_value = "text")]
    format: FormatArg,
}

/// Runs `thermode render`.
pub fn run(args: &RenderArgs) -> Result<()> {
    let specs = specs(args)?;
    check_outputs(&[("--out", args.out.as_deref()), ("--plot", args.plot.as_deref())])?;
    check_columnar_precision(args.out.as_deref(), args.precision)?;
    let progress = Progress::bar(specs.len() as u64, "runs", "render");
    let runs = render_all_with_progress(&specs, &|| progress.step()).context("rendering")?;
    progress.finish();
    for run in &runs {
        if let Some(report) = run.self_test.filter(|r| r.verdict() != Verdict::Matches) {
            let outcome = match report.verdict() {
                Verdict::Inconclusive(_) => "held off, untested, before the touch",
                _ => "refused before the touch",
            };
            eprintln!(
                "{} ({}): self-test: {report}; the display was {outcome}",
                run.summary.material, run.summary.controller
            );
        }
        if let Some(fault) = &run.summary.first_fault {
            eprintln!(
                "{} ({}): fault {fault} at t = {:.2} s; the drive was switched off",
                run.summary.material,
                run.summary.controller,
                run.summary.first_fault_time_s.unwrap_or(f64::NAN)
            );
        }
    }
    if let Some(path) = &args.out {
        if !write_columnar(path, || tables(&runs))? {
            write_atomically(path, |sink| {
                write_csv(&runs, csv_precision(args.precision), sink).map_err(anyhow::Error::from)
            })?;
        }
    }
    if let Some(path) = &args.plot {
        create_folder_of(path)?;
        write_figure(&figure3(&runs), path).with_context(|| format!("cannot write {}", path.display()))?;
    }
    if args.summary || (args.out.is_none() && args.plot.is_none()) {
        let summaries: Vec<_> = runs.iter().map(|r| r.summary.clone()).collect();
        let text = match args.format {
            FormatArg::Text => summary_table(&summaries),
            FormatArg::Json => serde_json::to_string_pretty(&summaries_json(&summaries)?)? + "\n",
        };
        if args.out.as_deref().is_some_and(is_stdout) {
            // The CSV is on standard output: the summary goes to standard error.
            eprint!("{text}");
        } else {
            print_stdout(&text)?;
        }
    }
    Ok(())
}

/// Every run's rows as one table each, with the CSV's columns (`thermode_render::run::CSV_HEADER`) and values:
/// `contact` 0 or 1, `fault` the code (null without fault), `fault_description` null without fault.
fn tables(runs: &[RenderRun]) -> Vec<Table<'_>> {
    runs.iter().map(run_table).collect()
}

fn run_table(run: &RenderRun) -> Table<'_> {
    let t = &run.trajectory;
    let mut table = Table::new();
    for (name, values) in t.numbers() {
        table.push(name, Values::F64(values.into()));
    }
    table.push(
        "contact",
        Values::I64(t.contact.iter().map(|&c| Some(i64::from(c))).collect()),
    );
    table.push(
        "fault",
        Values::I64(t.fault.iter().map(|f| f.map(|f| i64::from(f.code()))).collect()),
    );
    for (name, text) in [
        ("material", run.spec.material.name.as_str()),
        ("controller", run.summary.controller.as_str()),
        ("renderer", run.spec.pipeline.renderer.name()),
    ] {
        table.push(
            name,
            Values::Repeat {
                text: text.to_string(),
                rows: t.len(),
            },
        );
    }
    let descriptions = t.fault.iter().map(|f| f.map(|f| f.description().to_string()));
    table.push("fault_description", Values::Text(descriptions.collect()));
    table
}

/// The summaries as JSON objects whose window keys follow the windows actually used (`rms_skin_5_10_c` for a 10 s
/// run; [`RenderSummary::json_key`]).
fn summaries_json(summaries: &[RenderSummary]) -> Result<Vec<serde_json::Value>> {
    summaries
        .iter()
        .map(|s| {
            let serde_json::Value::Object(fields) = serde_json::to_value(s)? else {
                anyhow::bail!("a summary is not a JSON object");
            };
            Ok(serde_json::Value::Object(
                fields
                    .into_iter()
                    .map(|(key, value)| (s.json_key(&key), value))
                    .collect(),
            ))
        })
        .collect()
}

fn pid_gains(args: &RenderArgs, device: &DeviceConfig) -> Result<PidGains> {
    if let Some(path) = &args.pid_gains {
        return resolve::gains(path);
    }
    let (gains, source) = gains_for_device(device)?;
    if source == GainsSource::DefaultFallback && args.controller != ControllerArg::Model {
        eprintln!(
            "note: the device matches no shipped display; pid uses the default display's tuned gains \
             (run `thermode tune --device-file FILE --out GAINS.toml` and pass --pid-gains GAINS.toml)"
        );
    }
    Ok(gains)
}

/// One render spec per controller and material, controllers outermost.
fn specs(args: &RenderArgs) -> Result<Vec<RenderSpec>> {
    let materials = resolve::materials(&args.materials, &args.material_files)?;
    let device = resolve::device_config(args.device_file.as_deref())?;
    let gains = pid_gains(args, &device)?;
    let hardware = match &args.plant_device {
        Some(path) => Some(resolve::device_config(Some(path))?),
        None => None,
    };
    let finger_skin = resolve::skin(args.finger_skin.as_deref())?;
    let controllers = match args.controller {
        ControllerArg::Pid => vec![ControllerKind::Pid(gains)],
        ControllerArg::Model => vec![ControllerKind::Model],
        ControllerArg::Both => vec![ControllerKind::Pid(gains), ControllerKind::Model],
    };
    let mut specs = Vec::new();
    for controller in controllers {
        for material in &materials {
            let mut pipeline = PipelineConfig::new(device, controller);
            pipeline.renderer = args.model.into();
            if let Some(rate) = args.max_rate {
                pipeline.envelope = render_envelope_with_rate(&device, rate);
            }
            let mut spec = RenderSpec::new(pipeline, material.clone());
            spec.finger_skin = finger_skin.clone();
            spec.finger_contact_w_m2k = args.finger_contact;
            spec.hardware = hardware;
            spec.object_c = args.object_temp;
            spec.duration_s = args.duration;
            spec.pre_contact_s = args.pre_contact;
            spec.release_at_s = args.release_at;
            spec.rate_hz = args.rate;
            spec.seed = args.seed;
            spec.validate()?;
            specs.push(spec);
        }
    }
    // All runs are held in memory together: refuse work that would not fit before any of it starts.
    thermode_render::run::check_result_bytes(&specs)?;
    Ok(specs)
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: RenderArgs,
    }

    fn parse(args: &[&str]) -> RenderArgs {
        let mut full = vec!["render"];
        full.extend_from_slice(args);
        Cli::try_parse_from(full).unwrap_or_else(|e| panic!("{e}")).args
    }

    #[test]
    fn all_paper_with_both_controllers_gives_ten_specs_in_order() {
        let args = parse(&["--material", "all-paper", "--controller", "both", "--duration", "2"]);
        let specs = specs(&args).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(specs.len(), 10);
        assert_eq!(specs[0].pipeline.controller.name(), "pid");
        assert_eq!(specs[9].pipeline.controller.name(), "model");
        assert_eq!(specs[4].material.name, "rubber");
        assert_eq!(
            specs[0].pipeline.envelope,
            thermode_pipeline::pipeline::render_envelope(&DeviceConfig::default())
        );
        assert_eq!(specs[0].pipeline.envelope.max_setpoint_rate_c_per_s, 20.0);
    }

    #[test]
    fn the_rate_limit_follows_the_device_file_unless_given() {
        let dir = std::env::temp_dir().join(format!("thermode-render-rate-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
        let device = dir.join("fast.toml");
        std::fs::write(&device, "[render]\nmax_setpoint_rate_c_per_s = 60\n").unwrap_or_else(|e| panic!("{e}"));
        let path = device.to_string_lossy().to_string();
        let rate = |extra: &[&str]| {
            let mut args = vec!["--material", "wood", "--device-file", path.as_str()];
            args.extend_from_slice(extra);
            let specs = specs(&parse(&args)).unwrap_or_else(|e| panic!("{e:#}"));
            let envelope = specs[0].pipeline.envelope;
            (envelope.max_setpoint_rate_c_per_s, envelope.max_measured_rate_c_per_s)
        };
        // The measured-rate plausibility bound stays 2.5 times above the set-point rate limit.
        assert_eq!(rate(&[]), (60.0, 150.0));
        assert_eq!(rate(&["--max-rate", "300"]), (300.0, 750.0));
        assert_eq!(rate(&["--max-rate", "5"]), (5.0, 50.0));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_material_file_is_rendered_alone_or_after_library_materials() {
        let dir = std::env::temp_dir().join(format!("thermode-render-material-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
        let file = dir.join("walnut.toml");
        let text = "name = \"walnut\"\nconductivity_w_mk = 0.15\ndensity_kg_m3 = 650\nspecific_heat_j_kgk = 1600\n";
        std::fs::write(&file, text).unwrap_or_else(|e| panic!("{e}"));
        let path = file.to_string_lossy().to_string();
        let alone = specs(&parse(&["--material-file", &path])).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(alone.len(), 1);
        assert_eq!(
            (alone[0].material.name.as_str(), alone[0].material.conductivity_w_mk),
            ("walnut", 0.15)
        );
        let both = specs(&parse(&["--material", "wood", "--material-file", &path])).unwrap_or_else(|e| panic!("{e:#}"));
        let names: Vec<&str> = both.iter().map(|s| s.material.name.as_str()).collect();
        assert_eq!(names, ["wood", "walnut"]);
        std::fs::write(
            &file,
            "name = \"bad\"\nconductivity_w_mk = -1\ndensity_kg_m3 = 650\nspecific_heat_j_kgk = 1600\n",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let err = specs(&parse(&["--material-file", &path]))
            .err()
            .map(|e| format!("{e:#}"));
        assert!(err.as_deref().is_some_and(|e| e.contains("conductivity")), "{err:?}");
        let missing = specs(&parse(&["--material-file", "/nonexistent/m.toml"]))
            .err()
            .map(|e| format!("{e:#}"));
        assert!(
            missing.as_deref().is_some_and(|e| e.contains("cannot read")),
            "{missing:?}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn bad_input_is_a_clear_error() {
        let err = |args: &[&str]| match specs(&parse(args)) {
            Ok(_) => panic!("{args:?} accepted"),
            Err(e) => format!("{e:#}"),
        };
        assert!(err(&["--material", "unobtainium"]).contains("unknown material"));
        assert!(err(&["--material", "wood", "--duration", "NaN"]).contains("duration"));
        assert!(err(&["--material", "wood", "--finger-contact", "-5"]).contains("contact"));
        assert!(err(&["--material", "wood", "--pre-contact", "-1"]).contains("pre-contact"));
        assert!(err(&["--material", "wood", "--rate", "0"]).contains("rate"));
        assert!(err(&["--material", "wood", "--max-rate", "301"]).contains("max_setpoint_rate"));
        assert!(err(&["--material", "wood", "--object-temp", "-300"]).contains("object temperature"));
        assert!(err(&["--material", "wood", "--duration", "3000", "--rate", "100000"]).contains("memory"));
        assert!(err(&["--material", "wood", "--release-at", "100"]).contains("release"));
        assert!(err(&["--material", "wood", "--device-file", "/nonexistent/device.toml"]).contains("cannot read"));
    }
}
