//! The figures of the analysis as `thermode_plot` figures: Figure 4 (classification probability against Δc and Δk,
//! real and simulated side by side, correct answers at zero) and Figure 3 (mean temperature curves, real solid and
//! simulated dashed, one colour and marker per material), laid out for a paper: the figure's title over lettered
//! panels, one legend per figure.

use thermode_plot::{Figure, Marker, Panel, Series, SeriesStyle};

use super::curves::CurveAnalysis;
use super::figure4::{DeltaBin, Figure4};

/// Bar pairs (real + simulated) that fit side by side across the span of a Δ panel: 24.
const BAR_PAIRS_PER_SPAN: f64 = 24.0;
/// Narrowest bar pair [the Δ's cgs unit]: 0.02.
const MIN_BAR_PAIR_WIDTH: f64 = 0.02;
/// Width of one panel of Figure 4 (px): 700.
const FIGURE4_PANEL_WIDTH_PX: u32 = 700;
/// Height of one panel of Figure 4 (px): 480.
const FIGURE4_PANEL_HEIGHT_PX: u32 = 480;

/// Figure 4 as the paper lays it out: panel a for Δc, panel b for Δk, each with the real and the simulated
/// classification probabilities as bars (real left, simulated right of each Δ) and a dashed line at Δ = 0.
pub fn figure4(numbers: &Figure4) -> Figure {
    let c_panel = delta_panel(
        "specific heat",
        &format!("Δc = c identified − c presented [{}]", numbers.c_unit),
        (&numbers.real.delta_c, &numbers.simulated.delta_c),
    );
    let k_panel = delta_panel(
        "thermal conductivity",
        &format!("Δk = k identified − k presented [{}]", numbers.k_unit),
        (&numbers.real.delta_k, &numbers.simulated.delta_k),
    );
    Figure {
        panel_width_px: FIGURE4_PANEL_WIDTH_PX,
        panel_height_px: FIGURE4_PANEL_HEIGHT_PX,
        ..Figure::grid(vec![c_panel, k_panel], 2)
    }
    .with_title("Figure 4: classification probability against the difference between identified and presented material")
}

fn delta_panel(title: &str, x_label: &str, (real, simulated): (&[DeltaBin], &[DeltaBin])) -> Panel {
    let bars = |bins: &[DeltaBin], offset: f64| -> Vec<(f64, f64)> {
        bins.iter().map(|b| (b.delta + offset, b.probability)).collect()
    };
    let all = || real.iter().chain(simulated);
    let top = all().map(|b| b.probability).fold(0.05, f64::max);
    let (low_delta, high_delta) = (
        all().map(|b| b.delta).fold(0.0, f64::min),
        all().map(|b| b.delta).fold(0.0, f64::max),
    );
    let width = ((high_delta - low_delta) / BAR_PAIRS_PER_SPAN).max(MIN_BAR_PAIR_WIDTH);
    let (low, high) = (low_delta - width, high_delta + width);
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

/// Figure 3: the mean curves of every material, real solid and simulated dashed in the material's colour, each
/// material with its own marker (wood and rubber run close together).
pub fn figure3(curves: &CurveAnalysis) -> Figure {
    let mut series = Vec::new();
    for (color, material) in curves.materials.iter().enumerate() {
        let to_points = |mean: &[[f64; 2]]| mean.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>();
        if let Some(real) = &material.real {
            let label = format!("{} real", material.material);
            series.push(
                Series::new(label, to_points(&real.mean_curve), SeriesStyle::Line, color)
                    .with_marker(Marker::nth(color)),
            );
        }
        if let Some(sim) = &material.simulated {
            let label = format!("{} simulated", material.material);
            series.push(
                Series::new(label, to_points(&sim.mean_curve), SeriesStyle::Dashed, color)
                    .with_marker(Marker::nth(color)),
            );
        }
    }
    Figure::single(Panel {
        title: String::new(),
        x_label: "time since contact [s]".to_string(),
        y_label: "finger temperature [°C]".to_string(),
        series,
        x_range: None,
        y_range: None,
    })
    .with_title("Figure 3: mean finger temperature, real (solid) and simulated (dashed)")
}
