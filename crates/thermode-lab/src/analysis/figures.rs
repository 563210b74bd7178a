//! The figures of the analysis as `thermode_plot` figures: Figure 4 (classification probability against Δc and Δk,
//! real and simulated side by side, correct answers at zero) and Figure 3 (mean temperature curves, real solid and
//! simulated dashed, one colour per material).

use thermode_plot::{Figure, Panel, Series, SeriesStyle};

use super::curves::CurveAnalysis;
use super::figure4::{DeltaBin, Figure4};

/// Width of a real + simulated bar pair in the Δc panel [cal/(g·°C)].
const C_BAR_WIDTH: f64 = 0.02;
/// Width of a real + simulated bar pair in the Δk panel [cal/(cm·s·°C)].
const K_BAR_WIDTH: f64 = 0.02;

/// Figure 4: two panels, Δc and Δk, each with the real and the simulated classification probabilities as bars (real
/// left, simulated right of each Δ) and a dashed line at Δ = 0.
pub fn figure4(numbers: &Figure4) -> Figure {
    let c_panel = delta_panel(
        "Figure 4 (left): specific heat",
        &format!("Δc = c identified − c presented [{}]", numbers.c_unit),
        (&numbers.real.delta_c, &numbers.simulated.delta_c),
        C_BAR_WIDTH,
    );
    let k_panel = delta_panel(
        "Figure 4 (right): conductivity",
        &format!("Δk = k identified − k presented [{}]", numbers.k_unit),
        (&numbers.real.delta_k, &numbers.simulated.delta_k),
        K_BAR_WIDTH,
    );
    Figure::grid(vec![c_panel, k_panel], 2)
}

fn delta_panel(title: &str, x_label: &str, (real, simulated): (&[DeltaBin], &[DeltaBin]), width: f64) -> Panel {
    let bars = |bins: &[DeltaBin], offset: f64| -> Vec<(f64, f64)> {
        bins.iter().map(|b| (b.delta + offset, b.probability)).collect()
    };
    let all = || real.iter().chain(simulated);
    let top = all().map(|b| b.probability).fold(0.05, f64::max);
    let low = all().map(|b| b.delta).fold(0.0, f64::min) - width;
    let high = all().map(|b| b.delta).fold(0.0, f64::max) + width;
    let style = SeriesStyle::Bars { width: width / 2.0 };
    let zero_line = vec![(0.0, 0.0), (0.0, top * 1.05)];
    Panel {
        title: title.to_string(),
        x_label: x_label.to_string(),
        y_label: "classification probability".to_string(),
        series: vec![
            Series::new("real", bars(real, -width / 4.0), style, 0),
            Series::new("simulated", bars(simulated, width / 4.0), style, 1),
            Series::new("correct (Δ = 0)", zero_line, SeriesStyle::Dashed, 2),
        ],
        x_range: Some((low, high)),
        y_range: Some((0.0, top * 1.1)),
    }
}

/// Figure 3: the mean curves of every material, real solid and simulated dashed in the material's colour.
pub fn figure3(curves: &CurveAnalysis) -> Figure {
    let mut series = Vec::new();
    for (color, material) in curves.materials.iter().enumerate() {
        let to_points = |mean: &[[f64; 2]]| mean.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>();
        if let Some(real) = &material.real {
            let label = format!("{} real", material.material);
            series.push(Series::new(
                label,
                to_points(&real.mean_curve),
                SeriesStyle::Line,
                color,
            ));
        }
        if let Some(sim) = &material.simulated {
            let label = format!("{} simulated", material.material);
            series.push(Series::new(
                label,
                to_points(&sim.mean_curve),
                SeriesStyle::Dashed,
                color,
            ));
        }
    }
    Figure::single(Panel {
        title: "Figure 3: mean finger temperature, real (solid) and simulated (dashed)".to_string(),
        x_label: "time since contact [s]".to_string(),
        y_label: "finger temperature [°C]".to_string(),
        series,
        x_range: None,
        y_range: None,
    })
}
