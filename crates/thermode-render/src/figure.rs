//! The paper's Figure 3 for the simulated system: the real contact (the ground truth: the simulated finger touching
//! the real material) against the displayed contact (the simulated finger on the display), per material, one panel
//! per controller, and beside it the first [`EARLY_WINDOW_S`] seconds of contact, where nearly all of the rendering
//! error lives. A single material also shows the renderer's target and the plate temperature; several materials
//! each carry a marker, so that curves that run together (wood and rubber) stay apart.

use thermode_plot::{Figure, Marker, Panel, Series, SeriesStyle};

use crate::run::RenderRun;

/// Most points drawn per series; longer series are thinned evenly (the curves are smooth at that density).
pub const MAX_POINTS_PER_SERIES: usize = 2000;

/// Length of the close-up of the first seconds after contact \[s\]: 5.
pub const EARLY_WINDOW_S: f64 = 5.0;

/// (time, value) pairs of one column within `window` (all if `None`), thinned to at most
/// [`MAX_POINTS_PER_SERIES`].
fn curve(time_s: &[f64], values: &[f64], window: Option<(f64, f64)>) -> Vec<(f64, f64)> {
    let inside = |t: f64| window.is_none_or(|(from, to)| t >= from && t <= to);
    let points: Vec<(f64, f64)> = time_s
        .iter()
        .zip(values)
        .filter(|(t, _)| inside(**t))
        .map(|(t, v)| (*t, *v))
        .collect();
    let stride = points.len().div_ceil(MAX_POINTS_PER_SERIES).max(1);
    points.into_iter().step_by(stride).collect()
}

/// The figure of `runs`: one row per controller (in order of first appearance), each with the whole run and the
/// first [`EARLY_WINDOW_S`] seconds after contact, showing the truth (solid) and the displayed skin temperature
/// (dashed) of every material in one colour per material.
pub fn figure3(runs: &[RenderRun]) -> Figure {
    let mut controllers: Vec<&str> = Vec::new();
    for run in runs {
        if !controllers.contains(&run.summary.controller.as_str()) {
            controllers.push(&run.summary.controller);
        }
    }
    let early = runs
        .iter()
        .map(|r| (-r.spec.pre_contact_s.min(0.5), EARLY_WINDOW_S))
        .next();
    let panels = controllers
        .iter()
        .flat_map(|c| [panel(runs, c, None), panel(runs, c, early)])
        .collect::<Vec<_>>();
    Figure::grid(panels, 2)
}

/// The panel of `controller`'s runs over `window` (the whole run if `None`).
fn panel(runs: &[RenderRun], controller: &str, window: Option<(f64, f64)>) -> Panel {
    let runs: Vec<&RenderRun> = runs.iter().filter(|r| r.summary.controller == controller).collect();
    let single = runs.len() == 1;
    let mut series = Vec::new();
    for (index, run) in runs.iter().enumerate() {
        let t = &run.trajectory;
        let name = &run.spec.material.name;
        let colour = if single { 0 } else { index };
        if single {
            // Drawn first, so the truth and the displayed skin stay visible where they coincide with them.
            series.push(Series::new(
                "target (renderer)",
                curve(&t.time_s, &t.target_skin_c, window),
                SeriesStyle::Line,
                1,
            ));
            series.push(Series::new(
                "plate (display_c)",
                curve(&t.time_s, &t.display_c, window),
                SeriesStyle::Dashed,
                2,
            ));
        }
        let marked = |s: Series| if single { s } else { s.with_marker(Marker::nth(colour)) };
        series.push(marked(Series::new(
            format!("{name} real (truth)"),
            curve(&t.time_s, &t.truth_skin_c, window),
            SeriesStyle::Line,
            colour,
        )));
        series.push(marked(Series::new(
            format!("{name} displayed (skin)"),
            curve(&t.time_s, &t.skin_c, window),
            SeriesStyle::Dashed,
            colour,
        )));
    }
    let renderer = runs.first().map_or("", |r| r.spec.pipeline.renderer.name());
    let title = match window {
        None => format!("Real and displayed contact — controller {controller}, renderer {renderer}"),
        Some((_, to)) => format!("The first {to} s — controller {controller}"),
    };
    Panel {
        title,
        x_label: "time since contact [s]".into(),
        y_label: if single {
            "temperature [°C]"
        } else {
            "skin (receptor) temperature [°C]"
        }
        .into(),
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
        let c = curve(&t, &t, None);
        assert!(c.len() <= MAX_POINTS_PER_SERIES, "{} points", c.len());
        assert_eq!(c[0], (0.0, 0.0));
        assert_eq!(c[1], (5.0, 5.0));
        let short = curve(&t[..10], &t[..10], None);
        assert_eq!(short.len(), 10);
        let early = curve(&t, &t, Some((-0.5, 5.0)));
        assert_eq!(early, (0..=5).map(|k| (k as f64, k as f64)).collect::<Vec<_>>());
    }
}
