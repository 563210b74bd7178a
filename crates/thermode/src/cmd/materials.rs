//! `thermode materials`: lists the built-in material library as a table or as JSON.

use anyhow::Result;
use clap::{Args, ValueEnum};
use thermode_model::materials::{self, Material};
use thermode_model::units;
use thermode_protocol::MaterialInfo;

use crate::output::print_stdout;

/// Output format of `thermode materials`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MaterialsFormat {
    /// Aligned text table.
    Table,
    /// A JSON array of objects (SI units plus effusivity and diffusivity).
    Json,
}

/// Arguments of `thermode materials`.
#[derive(Args, Debug)]
pub struct MaterialsArgs {
    /// Output format.
    #[arg(long, value_enum, default_value = "table")]
    format: MaterialsFormat,
    /// Show the table in the paper's cgs-calorie units (cal/cm·s·°C, g/cm³, cal/g·°C) instead of SI.
    #[arg(long)]
    cgs: bool,
}

/// Runs `thermode materials`.
pub fn run(args: &MaterialsArgs) -> Result<()> {
    let library = materials::library();
    let text = match args.format {
        MaterialsFormat::Json => {
            let rows: Vec<MaterialInfo> = library.iter().map(MaterialInfo::from).collect();
            serde_json::to_string_pretty(&rows)? + "\n"
        }
        MaterialsFormat::Table => table(&library, args.cgs),
    };
    print_stdout(&text)
}

fn table(library: &[Material], cgs: bool) -> String {
    let header = if cgs {
        format!(
            "{:<16} {:>12} {:>9} {:>10} {:>10} {:>7}  source\n",
            "name", "k cal/cm·s·°C", "ρ g/cm³", "c cal/g·°C", "e SI", "Δx mm"
        )
    } else {
        format!(
            "{:<16} {:>12} {:>9} {:>10} {:>10} {:>7}  source\n",
            "name", "k W/m·K", "ρ kg/m³", "c J/kg·K", "e SI", "Δx mm"
        )
    };
    let mut out = header;
    for m in library {
        let (k, rho, c) = if cgs {
            (
                units::conductivity_to_cgs(m.conductivity_w_mk),
                units::density_to_cgs(m.density_kg_m3),
                units::specific_heat_to_cgs(m.specific_heat_j_kgk),
            )
        } else {
            (m.conductivity_w_mk, m.density_kg_m3, m.specific_heat_j_kgk)
        };
        out.push_str(&format!(
            "{:<16} {:>12} {:>9} {:>10} {:>10.0} {:>7.1}  {}\n",
            m.name,
            format_significant(k),
            format_significant(rho),
            format_significant(c),
            m.effusivity(),
            m.thickness_m * 1000.0,
            m.source
        ));
    }
    out
}

/// Formats with four significant digits, without switching to exponent notation for ordinary magnitudes.
fn format_significant(value: f64) -> String {
    if value == 0.0 || !value.is_finite() {
        return format!("{value}");
    }
    let digits = (3 - value.abs().log10().floor() as i32).clamp(0, 8) as usize;
    format!("{value:.digits$}")
}
