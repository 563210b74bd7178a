//! `thermode simulate`: a finger rests in air, touches one or more materials at t = 0, and the chosen skin model
//! gives the receptor temperature (and, for kron and fv, the display set-point of paper eq. 7). Writes a CSV, a plot
//! like the paper's Figure 3, and prints the temperatures at 1, 5, 10, 30 and 90 s.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use thermode_model::limits;
use thermode_model::materials::Material;
use thermode_model::simulate::{
    simulate, simulate_kron_into, Initial, KronColumns, KronRows, ModelKind, SimulationSpec, Trace,
};
use thermode_platform::csv_text::{self, CsvText, Precision};
use thermode_plot::{write_figure, Figure, Marker, Panel, Series, SeriesStyle};
use thermode_render::figure::EARLY_WINDOW_S;

use crate::output::{
    check_columnar_precision, check_outputs, columnar_format, create_folder_of, csv_precision, is_stdout, print_stdout,
    write_atomically, write_columnar, ColumnarStream,
};
use crate::resolve;
use thermode_table::{Table, Values};

/// The skin model to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModelArg {
    /// The paper's three-layer model (Kron); receptor = epidermis centre.
    Kron,
    /// The finite-volume reference (object heat capacity, contact resistance), refined until grid-independent.
    Fv,
    /// Two semi-infinite bodies, analytic (the paper's model (a)).
    SemiInfinite,
}

impl From<ModelArg> for ModelKind {
    fn from(arg: ModelArg) -> Self {
        match arg {
            ModelArg::Kron => ModelKind::Kron,
            ModelArg::Fv => ModelKind::Fv,
            ModelArg::SemiInfinite => ModelKind::SemiInfinite,
        }
    }
}

/// Arguments of `thermode simulate`.
#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// Material from the library (see `thermode materials`); repeat for several; `all-paper` = the paper's five.
    #[arg(long = "material", value_name = "NAME", required_unless_present = "material_files")]
    materials: Vec<String>,
    /// A material file (TOML); repeatable.
    #[arg(long = "material-file", value_name = "FILE")]
    material_files: Vec<PathBuf>,
    /// Skin model.
    #[arg(long, value_enum, default_value = "kron")]
    model: ModelArg,
    /// Skin file (TOML); default: the built-in fingertip.
    #[arg(long, value_name = "FILE")]
    skin: Option<PathBuf>,
    /// Contact duration [s].
    #[arg(long, value_name = "S", default_value_t = 90.0, allow_negative_numbers = true)]
    duration: f64,
    /// Output interval and kron time step [s].
    #[arg(long, value_name = "S", default_value_t = 0.01, allow_negative_numbers = true)]
    dt: f64,
    /// Air temperature [°C].
    #[arg(long, value_name = "C", default_value_t = 23.0, allow_negative_numbers = true)]
    ambient: f64,
    /// Object temperature [°C]; default: the ambient temperature.
    #[arg(long = "object-temp", value_name = "C", allow_negative_numbers = true)]
    object_temp: Option<f64>,
    /// Finger at contact: steady (in air at ambient), uniform:C (every layer at C), surface:C (calibrated so the
    /// resting surface is at C).
    #[arg(long, value_name = "STATE", default_value = "steady")]
    initial: String,
    /// Contact resistance skin–object [m²K/W]; default 1e-3 for fv (light touch), 0 for semi-infinite; kron has none.
    #[arg(long = "contact-resistance", value_name = "M2K_W", allow_negative_numbers = true)]
    contact_resistance: Option<f64>,
    /// Conductance between the model's receptor node and the display plate for the display inverse [W/m²K].
    #[arg(long = "display-conductance", value_name = "W_M2K", default_value_t = thermode_model::inverse::DEFAULT_DISPLAY_CONDUCTANCE_W_M2K, allow_negative_numbers = true)]
    display_conductance: f64,
    /// fv only: run the default grid refined N times (each level about doubles the cells), without the
    /// convergence check; default: refine until converged.
    #[arg(long = "fv-level", value_name = "N")]
    fv_level: Option<u32>,
    /// fv only: local error tolerance of the adaptive time steps [K].
    #[arg(long = "fv-tolerance", value_name = "K", default_value_t = thermode_model::fv::DEFAULT_TOLERANCE_C, allow_negative_numbers = true)]
    fv_tolerance: f64,
    /// Write the trajectory as CSV (one row per step; a `material` column names the material); `-`: standard output.
    /// A name ending in .arrow or .feather writes Arrow IPC (Feather v2), .parquet Parquet: the same columns, every
    /// number exact.
    #[arg(long, value_name = "FILE.csv")]
    out: Option<PathBuf>,
    /// Draw skin temperature against time (.svg or .png).
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
    /// Decimal places of the CSV's numbers (0-12, correctly rounded as `{:.N}` rounds them; `time_s` stays exact);
    /// default: every number exact, the shortest digits that read back as the same value (larger, and about four
    /// times slower to write).
    #[arg(long, value_name = "DECIMALS", value_parser = clap::value_parser!(u8).range(0..=i64::from(csv_text::MAX_DECIMALS)))]
    precision: Option<u8>,
}

/// Times at which the summary reports the receptor temperature [s].
const SUMMARY_TIMES_S: [f64; 5] = [1.0, 5.0, 10.0, 30.0, 90.0];

/// Runs `thermode simulate`.
pub fn run(args: &SimulateArgs) -> Result<()> {
    let materials = resolve::materials(&args.materials, &args.material_files)?;
    let skin = resolve::skin(args.skin.as_deref())?;
    let initial: Initial = args.initial.parse()?;
    let specs: Vec<SimulationSpec> = materials
        .into_iter()
        .map(|material| SimulationSpec {
            model: args.model.into(),
            skin: skin.clone(),
            duration_s: args.duration,
            dt_s: args.dt,
            ambient_c: args.ambient,
            object_c: args.object_temp.unwrap_or(args.ambient),
            initial,
            contact_resistance_m2k_w: args.contact_resistance,
            display_conductance_w_m2k: args.display_conductance,
            fv_level: args.fv_level,
            fv_tolerance_c: args.fv_tolerance,
            ..SimulationSpec::new(args.model.into(), material)
        })
        .collect();
    // Every number is checked, and the results of all materials (held together until written) must fit in
    // memory, before the first simulation starts.
    for spec in &specs {
        spec.validate()
            .with_context(|| format!("simulating {}", spec.material.name))?;
    }
    let bytes = specs.iter().fold(0u64, |sum, s| sum.saturating_add(s.result_bytes()));
    if let Err(message) = limits::check_result_bytes(bytes) {
        bail!(
            "simulating {} material(s): {message}: use a longer --dt, a shorter --duration or fewer materials",
            specs.len()
        );
    }
    check_outputs(&[("--out", args.out.as_deref()), ("--plot", args.plot.as_deref())])?;
    check_columnar_precision(args.out.as_deref(), args.precision)?;
    // A kron run's Arrow or Parquet file is written on a second thread while the runs compute; CSV, and the fv and
    // semi-infinite runs (whose rows come out whole at the end), are written after.
    let streamed = args
        .out
        .as_deref()
        .filter(|path| args.model == ModelArg::Kron && columnar_format(path).is_some());
    let traces = match streamed {
        Some(path) => simulate_kron_writing(specs, path)?,
        None => simulate_each(specs)?,
    };
    for (material, trace) in &traces {
        eprintln!("{}: {}", material.name, trace.resolution);
    }
    if let Some(path) = args.out.as_deref().filter(|_| streamed.is_none()) {
        if !write_columnar(path, || tables(&traces))? {
            write_csv(path, &traces, csv_precision(args.precision))?;
        }
    }
    if let Some(path) = &args.plot {
        write_plot(path, &traces, args.model)?;
    }
    // With the CSV on standard output the summary goes to standard error, so the CSV stays parseable.
    if args.out.as_deref().is_some_and(is_stdout) {
        eprint!("{}", summary(&traces));
        Ok(())
    } else {
        print_stdout(&summary(&traces))
    }
}

/// Runs the simulation of every spec in turn.
fn simulate_each(specs: Vec<SimulationSpec>) -> Result<Vec<(Material, Trace)>> {
    let run = |spec: SimulationSpec| {
        let trace = simulate(&spec).with_context(|| format!("simulating {}", spec.material.name))?;
        Ok((spec.material, trace))
    };
    specs.into_iter().map(run).collect()
}

/// Rows of a kron run handed to the writer at a time (64 KiB of each column): the last piece, written after the
/// run ends, is small, and a 90 s run at 1 ms is 11 record batches.
const PIECE_ROWS: usize = 8192;

/// Runs the kron simulations of `specs` and writes the Arrow or Parquet file `path` on a second thread while they
/// compute, each piece of rows as soon as it is computed, from the runs' own columns (no copy).
fn simulate_kron_writing(specs: Vec<SimulationSpec>, path: &Path) -> Result<Vec<(Material, Trace)>> {
    let mut runs = Vec::with_capacity(specs.len());
    for spec in &specs {
        runs.push(KronColumns::new(spec).with_context(|| format!("simulating {}", spec.material.name))?);
    }
    let filled = &mut runs;
    std::thread::scope(|scope| {
        let stream = ColumnarStream::start(scope, path).context("not an Arrow or Parquet output")?;
        for (spec, run) in specs.iter().zip(filled.iter_mut()) {
            let names = run.names.clone();
            let material = &spec.material.name;
            simulate_kron_into(spec, run, PIECE_ROWS, &mut |rows| {
                stream.send(rows_table(material, &names, rows));
            })
            .with_context(|| format!("simulating {material}"))?;
        }
        stream.finish()
    })?;
    let traces = specs.into_iter().zip(runs).map(|(spec, run)| {
        let trace = run.into_trace(&spec);
        (spec.material, trace)
    });
    Ok(traces.collect())
}

/// Rows of a kron run of `material` as the CSV's columns, borrowed.
fn rows_table<'a>(material: &str, names: &[String], rows: KronRows<'a>) -> Table<'a> {
    let mut table = Table::new();
    table.push("time_s", Values::F64(rows.time_s.into()));
    for (name, values) in names.iter().zip(rows.values) {
        table.push(name.as_str(), Values::F64(values.into()));
    }
    table.push(
        "material",
        Values::Repeat {
            text: material.to_string(),
            rows: rows.time_s.len(),
        },
    );
    table
}

fn write_csv(path: &Path, traces: &[(Material, Trace)], precision: Precision) -> Result<()> {
    let (_, first) = &traces[0];
    let mut header = vec!["time_s"];
    header.extend(first.columns.iter().map(|(name, _)| name.as_str()));
    header.push("material");
    write_atomically(path, |sink| {
        sink.write_all(format!("{}\n", header.join(",")).as_bytes())?;
        for (material, trace) in traces {
            let mut row_end = CsvText::new();
            row_end.push_byte(b',');
            row_end.push_field(&material.name);
            row_end.push_byte(b'\n');
            let columns: Vec<&[f64]> = trace.columns.iter().map(|(_, values)| values.as_slice()).collect();
            let copies = earlier_equal_columns(&columns);
            csv_text::write_rows(sink, trace.time_s.len(), |rows, text| {
                let mut spans = vec![(0, 0); columns.len()];
                for row in rows {
                    text.push_f64(trace.time_s[row]);
                    for (column, values) in columns.iter().enumerate() {
                        text.push_byte(b',');
                        let start = text.len();
                        match copies[column] {
                            Some(earlier) => text.push_earlier(spans[earlier]),
                            None => text.push_number(values[row], precision),
                        }
                        spans[column] = (start, text.len());
                    }
                    text.push_bytes(row_end.as_bytes());
                }
            })?;
        }
        Ok(())
    })
}

/// The CSV's columns of every material's trace as one table each (Arrow and Parquet outputs).
fn tables(traces: &[(Material, Trace)]) -> Vec<Table<'_>> {
    traces.iter().map(trace_table).collect()
}

fn trace_table((material, trace): &(Material, Trace)) -> Table<'_> {
    let mut table = Table::new();
    table.push("time_s", Values::F64(trace.time_s.as_slice().into()));
    for (name, values) in &trace.columns {
        table.push(name.as_str(), Values::F64(values.as_slice().into()));
    }
    table.push(
        "material",
        Values::Repeat {
            text: material.name.clone(),
            rows: trace.time_s.len(),
        },
    );
    table
}

/// For each column, the first earlier column holding the same numbers bit for bit (kron's skin surface is its
/// epidermis): its text is copied in each row instead of written again.
fn earlier_equal_columns(columns: &[&[f64]]) -> Vec<Option<usize>> {
    let same = |a: &[f64], b: &[f64]| a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
    (0..columns.len())
        .map(|column| (0..column).find(|&earlier| same(columns[earlier], columns[column])))
        .collect()
}

fn write_plot(path: &Path, traces: &[(Material, Trace)], model: ModelArg) -> Result<()> {
    let mut series = Vec::new();
    for (index, (material, trace)) in traces.iter().enumerate() {
        let curve = |name: &str| {
            let values = trace.column(name).unwrap_or_default();
            trace
                .time_s
                .iter()
                .copied()
                .zip(values.iter().copied())
                .collect::<Vec<_>>()
        };
        let skin = Series::new(
            material.name.as_str(),
            curve("skin_surface_c"),
            SeriesStyle::Line,
            index,
        );
        // Several materials each carry a marker: curves that run together (wood and rubber) stay apart.
        series.push(if traces.len() > 1 {
            skin.with_marker(Marker::nth(index))
        } else {
            skin
        });
        if traces.len() == 1 && trace.column("display_setpoint_c").is_some() {
            series.push(Series::new(
                "display set-point",
                curve("display_setpoint_c"),
                SeriesStyle::Dashed,
                index + 1,
            ));
        }
    }
    let model_name = model
        .to_possible_value()
        .map(|v| v.get_name().to_string())
        .unwrap_or_default();
    let panel = Panel {
        title: format!("Skin temperature on contact ({model_name} model)"),
        x_label: "time since contact [s]".into(),
        y_label: "receptor temperature [°C]".into(),
        series,
        ..Panel::default()
    };
    let early = panel.window(0.0, EARLY_WINDOW_S, format!("The first {EARLY_WINDOW_S} s"));
    create_folder_of(path)?;
    Ok(write_figure(&Figure::grid(vec![panel, early], 2), path)?)
}

/// A table of the receptor temperature at the summary times, one row per material.
fn summary(traces: &[(Material, Trace)]) -> String {
    let mut out = format!("{:<16} {:>9} {:>8}", "material", "effusivity", "t=0");
    for t in SUMMARY_TIMES_S {
        out.push_str(&format!(" {:>8}", format!("{t} s")));
    }
    out.push_str("   (receptor temperature, °C)\n");
    for (material, trace) in traces {
        let start = trace.skin_surface_at(0.0).unwrap_or(f64::NAN);
        out.push_str(&format!(
            "{:<16} {:>9.0} {:>8.2}",
            material.name,
            material.effusivity(),
            start
        ));
        for t in SUMMARY_TIMES_S {
            match trace.skin_surface_at(t) {
                Some(value) => out.push_str(&format!(" {value:>8.2}")),
                None => out.push_str(&format!(" {:>8}", "-")),
            }
        }
        out.push('\n');
    }
    out
}
