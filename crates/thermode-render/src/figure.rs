//! The paper's Figure 3 for the simulated system: the real contact (the ground truth: the simulated finger touching
//! the real material) against the displayed contact (the simulated finger on the display), per material, one panel
//! per controller. A single material also shows the renderer's target and the plate temperature.

use thermode_plot::{Figure, Panel, Series, SeriesStyle};

use crate::run::RenderRun;

/// Most points drawn per series; longer series are thinned evenly (the curves are smooth at that density).
pub const MAX_POINTS_PER_SERIES: usize = 2000;

/// (time, value) pairs of one column, thinned to at most [`MAX_POINTS_PER_SERIES`].
fn curve(time_s: &[f64], values: &[f64]) -> Vec<(f64, f64)> {
    let stride = time_s.len().div_ceil(MAX_POINTS_PER_SERIES).max(1);
    time_s
        .iter()
        .zip(values)
        .step_by(stride)
        .map(|(t, v)| (*t, *v))
        .collect()
}

/// The figure of `runs`: one panel per controller (in order of first appearance), each with the truth (solid) and
/// the displayed skin temperature (dashed) of every material in one colour per material.
pub fn figure3(runs: &[RenderRun]) -> Figure {
    let mut controllers: Vec<&str> = Vec::new();
    for run in runs {
        if !controllers.contains(&run.summary.controller.as_str()) {
            controllers.push(&run.summary.controller);
        }
    }
    let panels = controllers.iter().map(|c| panel(runs, c)).collect::<Vec<_>>();
    let columns = panels.len().min(2);
    Figure::grid(panels, columns)
}

fn panel(runs: &[RenderRun], controller: &str) -> Panel {
    let runs: Vec<&RenderRun> = runs.iter().filter(|r| r.summary.controller == controller).collect();
    let single = runs.len() == 1;
    let mut series = Vec::new();
    for (index, run) in runs.iter().enumerate() {
        let t = &run.trajectory;
        let name = &run.spec.material.name;
        let colour = if single { 0 } else { index };
        series.push(Series::new(
            format!("{name} real (truth)"),
            curve(&t.time_s, &t.truth_skin_c),
            SeriesStyle::Line,
            colour,
        ));
        series.push(Series::new(
            format!("{name} displayed (skin)"),
            curve(&t.time_s, &t.skin_c),
            SeriesStyle::Dashed,
            colour,
        ));
        if single {
            series.push(Series::new(
                "target",
                curve(&t.time_s, &t.target_skin_c),
                SeriesStyle::Line,
                1,
            ));
            series.push(Series::new(
                "display (plate)",
                curve(&t.time_s, &t.display_c),
                SeriesStyle::Dashed,
                2,
            ));
        }
    }
    let renderer = runs.first().map_or("", |r| r.spec.pipeline.renderer.name());
    Panel {
        title: format!("Real and displayed contact — controller {controller}, renderer {renderer}"),
        x_label: "time since contact [s]".into(),
        y_label: "skin (receptor) temperature [°C]".into(),
        series,
        ..Panel::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_series_are_thinned_evenly_and_short_ones_kept() {
        let t: Vec<f64> = (0..10_000).map(|k| k as f64).collect();
        let c = curve(&t, &t);
        assert!(c.len() <= MAX_POINTS_PER_SERIES, "{} points", c.len());
        assert_eq!(c[0], (0.0, 0.0));
        assert_eq!(c[1], (5.0, 5.0));
        let short = curve(&t[..10], &t[..10]);
        assert_eq!(short.len(), 10);
    }
}
