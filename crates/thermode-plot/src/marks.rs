//! What tells series apart besides their colour: marker shapes drawn in pixels, the legend column of a figure
//! (one entry per distinct series of all its panels, each swatch in the series' own line style and marker), and
//! text sized to fit the room it has.

use std::mem::discriminant;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::{drawing, palette, PlotError, Series, SeriesStyle};

/// A marker drawn at a few points along a series, so that curves of similar colour or course stay apart where they
/// overlap (the legend shows it too).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Marker {
    /// A filled circle.
    Circle,
    /// A filled square.
    Square,
    /// A filled triangle pointing up.
    Triangle,
    /// A filled diamond.
    Diamond,
    /// A diagonal cross.
    Cross,
}

impl Marker {
    /// The marker of entry `index` (a distinct shape for each of five consecutive indices, repeating).
    pub fn nth(index: usize) -> Marker {
        const ALL: [Marker; 5] = [
            Marker::Circle,
            Marker::Square,
            Marker::Triangle,
            Marker::Diamond,
            Marker::Cross,
        ];
        ALL[index % ALL.len()]
    }
}

/// Half size of a marker (px): 5.
const MARKER_HALF_PX: i32 = 5;

/// Draws `marker` centred on `(x, y)` (px in `area`) in `color`.
pub(crate) fn draw_marker<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    marker: Marker,
    (x, y): (i32, i32),
    color: RGBColor,
) -> Result<(), PlotError> {
    let h = MARKER_HALF_PX;
    let fill = color.filled();
    match marker {
        Marker::Circle => area.draw(&Circle::new((x, y), h, fill)),
        Marker::Square => area.draw(&Rectangle::new([(x - h + 1, y - h + 1), (x + h - 1, y + h - 1)], fill)),
        Marker::Triangle => area.draw(&Polygon::new(
            vec![(x, y - h - 1), (x - h, y + h - 1), (x + h, y + h - 1)],
            fill,
        )),
        Marker::Diamond => area.draw(&Polygon::new(
            vec![(x, y - h - 1), (x + h, y), (x, y + h + 1), (x - h, y)],
            fill,
        )),
        Marker::Cross => {
            let stroke = color.stroke_width(3);
            area.draw(&PathElement::new(vec![(x - h, y - h), (x + h, y + h)], stroke))
                .and_then(|_| area.draw(&PathElement::new(vec![(x - h, y + h), (x + h, y - h)], stroke)))
        }
    }
    .map_err(drawing)
}

/// Markers drawn along one series: 8, spread over its x extent.
pub const MARKERS_PER_SERIES: usize = 8;

/// The points of `points` (ordered by x) that carry markers: the ones nearest to [`MARKERS_PER_SERIES`] evenly
/// spaced x positions, shifted by a fifth of a spacing per `phase`, so that the markers of overlapping series with
/// different phases do not cover each other.
pub(crate) fn marker_points(points: &[(f64, f64)], phase: usize) -> Vec<(f64, f64)> {
    let (Some(first), Some(last)) = (points.first(), points.last()) else {
        return Vec::new();
    };
    let span = last.0 - first.0;
    let shift = ((phase % 5) as f64 + 0.5) / 5.0;
    (0..MARKERS_PER_SERIES)
        .filter_map(|k| {
            let x = first.0 + span * (k as f64 + shift) / MARKERS_PER_SERIES as f64;
            points
                .iter()
                .copied()
                .min_by(|a, b| (a.0 - x).abs().total_cmp(&(b.0 - x).abs()))
        })
        .collect()
}

/// The distinct labelled series of `series` in order of first appearance: two series are one entry when their
/// label, colour, marker and kind of style are the same (a curve drawn in two panels is listed once).
pub(crate) fn legend_entries<'a>(series: impl Iterator<Item = &'a Series>) -> Vec<&'a Series> {
    let mut entries: Vec<&Series> = Vec::new();
    for s in series.filter(|s| !s.label.is_empty()) {
        let same = |e: &&Series| {
            e.label == s.label
                && e.color == s.color
                && e.marker == s.marker
                && discriminant(&e.style) == discriminant(&s.style)
        };
        if !entries.iter().any(same) {
            entries.push(s);
        }
    }
    entries
}

/// Vertical distance between legend entries (px).
const LEGEND_ROW_PX: i32 = 24;
/// Largest legend text (px).
const LEGEND_FONT_PX: u32 = 15;

/// The legend column: one row per entry from `top_px` down, a swatch in the series' style and its label.
pub(crate) fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[&Series],
    top_px: i32,
) -> Result<(), PlotError> {
    let text_left_px = 52;
    let room_px = area.dim_in_pixel().0.saturating_sub(text_left_px as u32 + 8);
    for (row, s) in entries.iter().enumerate() {
        let y = top_px + row as i32 * LEGEND_ROW_PX;
        draw_swatch(area, s, (8, y))?;
        let size = fitted_font_px(area, &s.label, LEGEND_FONT_PX, room_px)?;
        let style = TextStyle::from(("sans-serif", size)).pos(Pos::new(HPos::Left, VPos::Center));
        area.draw(&Text::new(s.label.as_str(), (text_left_px, y), style))
            .map_err(drawing)?;
    }
    Ok(())
}

/// A 36 px swatch of `series`' style whose left end is at `(x, y)` (px, y at the middle).
fn draw_swatch<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    series: &Series,
    (x, y): (i32, i32),
) -> Result<(), PlotError> {
    let color = palette(series.color);
    let stroke = ShapeStyle::from(color).stroke_width(3);
    match series.style {
        SeriesStyle::Line => area.draw(&PathElement::new(vec![(x, y), (x + 36, y)], stroke)),
        SeriesStyle::Dashed => [(0, 9), (14, 22), (27, 36)]
            .into_iter()
            .try_for_each(|(a, b)| area.draw(&PathElement::new(vec![(x + a, y), (x + b, y)], stroke))),
        SeriesStyle::Points => area.draw(&Circle::new((x + 18, y), 4, color.filled())),
        SeriesStyle::Bars { .. } => area.draw(&Rectangle::new(
            [(x + 10, y - 7), (x + 26, y + 7)],
            color.mix(0.75).filled(),
        )),
    }
    .map_err(drawing)?;
    match series.marker {
        Some(marker) => draw_marker(area, marker, (x + 18, y), color),
        None => Ok(()),
    }
}

/// Smallest text size [`fitted_font_px`] goes down to (px): 10.
const MIN_FONT_PX: u32 = 10;

/// The largest text size up to `max_px` at which `text` is at most `room_px` wide in `area` (at least
/// [`MIN_FONT_PX`]).
pub(crate) fn fitted_font_px<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    max_px: u32,
    room_px: u32,
) -> Result<u32, PlotError> {
    for size in (MIN_FONT_PX..=max_px).rev() {
        let (width, _) = area
            .estimate_text_size(text, &TextStyle::from(("sans-serif", size)))
            .map_err(drawing)?;
        if width <= room_px {
            return Ok(size);
        }
    }
    Ok(MIN_FONT_PX)
}
