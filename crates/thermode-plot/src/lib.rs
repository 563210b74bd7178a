//! thermode-plot: figures for thermode written as SVG or PNG files.
//!
//! A [`Figure`] is a grid of [`Panel`]s; each panel has axes, labels and [`Series`] drawn as lines, dashed lines,
//! points or bars. The legend stands in a column to the right of the axes, never over the data, and its swatches
//! are drawn in each series' own style (a dashed series has a dashed swatch), so series of one colour that differ
//! only in style stay apart. [`write_figure`] picks the format from the file extension (`.svg` or `.png`) and writes
//! atomically (a temporary file in the same folder, then a rename), so a failed plot never leaves half a file.
//! The PNG text uses DejaVu Sans, embedded in the binary (licence in `assets/DejaVuSans-LICENSE.txt`), so no system
//! font is needed at run time.

use std::path::{Path, PathBuf};
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;
use thermode_platform::WriteError;
use thiserror::Error;

/// The embedded font (DejaVu Sans, Bitstream Vera licence).
static FONT_BYTES: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
static REGISTER_FONT: Once = Once::new();

/// Why a figure could not be written.
#[derive(Debug, Error)]
pub enum PlotError {
    /// The file name does not end in `.svg` or `.png`.
    #[error("{path}: plots are written as .svg or .png")]
    UnsupportedFormat {
        /// The file asked for.
        path: PathBuf,
    },
    /// The figure has no panel, or a panel has no finite point to draw.
    #[error("nothing to plot: {0}")]
    Empty(String),
    /// Drawing failed inside the plotting library.
    #[error("drawing failed: {0}")]
    Drawing(String),
    /// The file could not be written.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The file system's error.
        error: std::io::Error,
    },
}

/// How one series is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SeriesStyle {
    /// A solid line through the points in order.
    Line,
    /// A dashed line through the points in order.
    Dashed,
    /// A filled circle at each point.
    Points,
    /// A bar from y = 0 to each point, `width` in x units, centred on x.
    Bars {
        /// Bar width in x units.
        width: f64,
    },
}

/// One labelled data series.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// (x, y) points; non-finite points are skipped.
    pub points: Vec<(f64, f64)>,
    /// How the series is drawn.
    pub style: SeriesStyle,
    /// Index into the palette; series with the same index share a colour (e.g. real and simulated aluminium).
    pub color: usize,
}

impl Series {
    /// A series with the given style and palette colour.
    pub fn new(label: impl Into<String>, points: Vec<(f64, f64)>, style: SeriesStyle, color: usize) -> Self {
        Series {
            label: label.into(),
            points,
            style,
            color,
        }
    }
}

/// One set of axes.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Panel {
    /// Title above the axes.
    pub title: String,
    /// Label of the x axis (with its unit).
    pub x_label: String,
    /// Label of the y axis (with its unit).
    pub y_label: String,
    /// The data.
    pub series: Vec<Series>,
    /// Fixed x range; `None` fits the data.
    pub x_range: Option<(f64, f64)>,
    /// Fixed y range; `None` fits the data with a margin.
    pub y_range: Option<(f64, f64)>,
}

impl Panel {
    /// A close-up of this panel over `from..=to` on the x axis, titled `title`: every series keeps only its points
    /// inside the window (so the y axis fits them), and the x axis spans exactly the window.
    pub fn window(&self, from: f64, to: f64, title: impl Into<String>) -> Panel {
        Panel {
            title: title.into(),
            series: self
                .series
                .iter()
                .map(|s| Series {
                    points: s
                        .points
                        .iter()
                        .copied()
                        .filter(|(x, _)| *x >= from && *x <= to)
                        .collect(),
                    ..s.clone()
                })
                .collect(),
            x_range: Some((from, to)),
            ..self.clone()
        }
    }
}

/// A grid of panels written to one file.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// Panels, filled row by row.
    pub panels: Vec<Panel>,
    /// Panels per row (at least 1).
    pub columns: usize,
    /// Width of one panel (px). Default 800.
    pub panel_width_px: u32,
    /// Height of one panel (px). Default 500.
    pub panel_height_px: u32,
}

impl Figure {
    /// A figure of one panel, 800 × 500 px.
    pub fn single(panel: Panel) -> Self {
        Figure::grid(vec![panel], 1)
    }

    /// A figure of several panels, `columns` per row, each 800 × 500 px.
    pub fn grid(panels: Vec<Panel>, columns: usize) -> Self {
        Figure {
            panels,
            columns: columns.max(1),
            panel_width_px: 800,
            panel_height_px: 500,
        }
    }

    fn size_px(&self) -> (u32, u32) {
        let columns = self.columns.max(1);
        let rows = self.panels.len().div_ceil(columns).max(1);
        (self.panel_width_px * columns as u32, self.panel_height_px * rows as u32)
    }
}

/// The colour of palette entry `index` (a colour-blind-safe set, repeating).
pub fn palette(index: usize) -> RGBColor {
    const COLORS: [RGBColor; 8] = [
        RGBColor(0, 114, 178),
        RGBColor(213, 94, 0),
        RGBColor(0, 158, 115),
        RGBColor(204, 121, 167),
        RGBColor(86, 180, 233),
        RGBColor(230, 159, 0),
        RGBColor(0, 0, 0),
        RGBColor(240, 228, 66),
    ];
    COLORS[index % COLORS.len()]
}

/// Whether `path` names a figure [`write_figure`] can write: it ends in `.svg` or `.png` (any case).
pub fn is_figure_path(path: &Path) -> bool {
    let extension = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    matches!(extension.as_deref(), Some("svg" | "png"))
}

/// Writes `figure` to `path`; the format follows the extension (`svg` or `png`, any case).
pub fn write_figure(figure: &Figure, path: &Path) -> Result<(), PlotError> {
    let extension = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match extension.as_deref() {
        Some("svg") => {
            let text = svg_string(figure)?;
            write_atomically(path, |tmp| {
                std::fs::write(tmp, text.as_bytes()).map_err(|source| io(path, source))
            })
        }
        Some("png") => write_atomically(path, |tmp| {
            let root = BitMapBackend::new(tmp, figure.size_px()).into_drawing_area();
            draw_figure(figure, &root)?;
            root.present().map_err(|e| PlotError::Drawing(e.to_string()))
        }),
        _ => Err(PlotError::UnsupportedFormat {
            path: path.to_path_buf(),
        }),
    }
}

/// Renders `figure` as an SVG document.
pub fn svg_string(figure: &Figure) -> Result<String, PlotError> {
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, figure.size_px()).into_drawing_area();
        draw_figure(figure, &root)?;
        root.present().map_err(|e| PlotError::Drawing(e.to_string()))?;
    }
    Ok(text)
}

fn io(path: &Path, error: std::io::Error) -> PlotError {
    PlotError::Io {
        path: path.to_path_buf(),
        error,
    }
}

/// Writes `path` through the one atomic writer (`thermode_platform::write_atomically`: a temporary file with the
/// same extension, so the PNG encoder sees it, synced and renamed); errors name `path`, never the temporary file.
fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<(), PlotError>) -> Result<(), PlotError> {
    thermode_platform::write_atomically(path, write).map_err(|e| match e {
        WriteError::Fill(e) => e,
        WriteError::Io { path, source } => PlotError::Io { path, error: source },
    })
}

fn draw_figure<DB: DrawingBackend>(figure: &Figure, root: &DrawingArea<DB, Shift>) -> Result<(), PlotError> {
    REGISTER_FONT.call_once(|| {
        // The bytes are the embedded DejaVu Sans; registration cannot fail for a valid TrueType file.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT_BYTES);
    });
    if figure.panels.is_empty() {
        return Err(PlotError::Empty("the figure has no panel".into()));
    }
    root.fill(&WHITE).map_err(drawing)?;
    let columns = figure.columns.max(1);
    let rows = figure.panels.len().div_ceil(columns);
    let areas = root.split_evenly((rows, columns));
    for (panel, area) in figure.panels.iter().zip(areas.iter()) {
        draw_panel(panel, area)?;
    }
    Ok(())
}

fn drawing<E: std::fmt::Debug>(error: E) -> PlotError {
    PlotError::Drawing(format!("{error:?}"))
}

fn finite_points(series: &Series) -> impl Iterator<Item = (f64, f64)> + '_ {
    series
        .points
        .iter()
        .copied()
        .filter(|(x, y)| x.is_finite() && y.is_finite())
}

/// (low, high) of one axis.
type AxisRange = (f64, f64);

/// Data bounds of a panel, widened by the bars' half widths and, for y, by 5 % (bars include y = 0).
fn panel_ranges(panel: &Panel) -> Result<(AxisRange, AxisRange), PlotError> {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for series in &panel.series {
        let half = match series.style {
            SeriesStyle::Bars { width } => width.abs() / 2.0,
            _ => 0.0,
        };
        for (x, y) in finite_points(series) {
            x0 = x0.min(x - half);
            x1 = x1.max(x + half);
            y0 = y0.min(y);
            y1 = y1.max(y);
            if half > 0.0 {
                y0 = y0.min(0.0);
                y1 = y1.max(0.0);
            }
        }
    }
    if !x0.is_finite() {
        return Err(PlotError::Empty(format!("panel `{}` has no finite point", panel.title)));
    }
    let widen = |lo: f64, hi: f64, share: f64| {
        let span = if hi > lo { hi - lo } else { lo.abs().max(1.0) };
        (lo - share * span, hi + share * span)
    };
    let x = panel
        .x_range
        .unwrap_or_else(|| if x1 > x0 { (x0, x1) } else { widen(x0, x1, 0.05) });
    let y = panel.y_range.unwrap_or_else(|| widen(y0, y1, 0.05));
    Ok((x, y))
}

/// Width of the legend column to the right of a panel's axes (px): 230, room for about 28 characters.
pub const LEGEND_WIDTH_PX: u32 = 230;

fn draw_panel<DB: DrawingBackend>(panel: &Panel, area: &DrawingArea<DB, Shift>) -> Result<(), PlotError> {
    let ((x0, x1), (y0, y1)) = panel_ranges(panel)?;
    let labelled: Vec<&Series> = panel.series.iter().filter(|s| !s.label.is_empty()).collect();
    let width_px = area.dim_in_pixel().0;
    let (plot_area, legend_area) = if labelled.is_empty() || width_px < 2 * LEGEND_WIDTH_PX {
        (area.clone(), None)
    } else {
        let (left, right) = area.split_horizontally(width_px - LEGEND_WIDTH_PX);
        (left, Some(right))
    };
    let mut chart = ChartBuilder::on(&plot_area)
        .caption(&panel.title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(drawing)?;
    chart
        .configure_mesh()
        .x_desc(panel.x_label.as_str())
        .y_desc(panel.y_label.as_str())
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 16))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(drawing)?;
    for series in &panel.series {
        draw_series(&mut chart, series)?;
    }
    match legend_area {
        Some(legend) => draw_legend(&legend, &labelled),
        None if labelled.is_empty() => Ok(()),
        // Too narrow for a column: the legend goes inside the axes.
        None => chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .label_font(("sans-serif", 14))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(drawing),
    }
}

/// Vertical distance between legend entries (px).
const LEGEND_ROW_PX: i32 = 22;

/// The legend column: one row per labelled series, a swatch in the series' style and its label.
fn draw_legend<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, series: &[&Series]) -> Result<(), PlotError> {
    let top_px = 50;
    for (row, s) in series.iter().enumerate() {
        let y = top_px + row as i32 * LEGEND_ROW_PX;
        draw_swatch(area, s, (8, y))?;
        area.draw(&Text::new(s.label.as_str(), (48, y - 8), ("sans-serif", 14)))
            .map_err(drawing)?;
    }
    Ok(())
}

/// A 32 px swatch of `series`' style whose left end is at `(x, y)` (px, y at the middle).
fn draw_swatch<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    series: &Series,
    (x, y): (i32, i32),
) -> Result<(), PlotError> {
    let color = palette(series.color);
    let stroke = ShapeStyle::from(color).stroke_width(3);
    match series.style {
        SeriesStyle::Line => area.draw(&PathElement::new(vec![(x, y), (x + 32, y)], stroke)),
        SeriesStyle::Dashed => [(0, 8), (12, 20), (24, 32)]
            .into_iter()
            .try_for_each(|(a, b)| area.draw(&PathElement::new(vec![(x + a, y), (x + b, y)], stroke))),
        SeriesStyle::Points => area.draw(&Circle::new((x + 16, y), 4, color.filled())),
        SeriesStyle::Bars { .. } => area.draw(&Rectangle::new(
            [(x + 8, y - 6), (x + 24, y + 6)],
            color.mix(0.75).filled(),
        )),
    }
    .map_err(drawing)
}

type Chart<'a, DB> =
    ChartContext<'a, DB, Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>>;

fn draw_series<DB: DrawingBackend>(chart: &mut Chart<'_, DB>, series: &Series) -> Result<(), PlotError> {
    let color = palette(series.color);
    let points: Vec<(f64, f64)> = finite_points(series).collect();
    let style = ShapeStyle::from(color).stroke_width(2);
    let annotation = match series.style {
        SeriesStyle::Line => chart.draw_series(LineSeries::new(points, style)).map_err(drawing)?,
        SeriesStyle::Dashed => chart
            .draw_series(DashedLineSeries::new(points, 8, 5, style))
            .map_err(drawing)?,
        SeriesStyle::Points => chart
            .draw_series(points.into_iter().map(|p| Circle::new(p, 4, color.filled())))
            .map_err(drawing)?,
        SeriesStyle::Bars { width } => {
            let half = width.abs() / 2.0;
            chart
                .draw_series(
                    points
                        .into_iter()
                        .map(|(x, y)| Rectangle::new([(x - half, 0.0), (x + half, y)], color.mix(0.75).filled())),
                )
                .map_err(drawing)?
        }
    };
    if !series.label.is_empty() {
        // Used only when the panel is too narrow for the legend column.
        let dashed = series.style == SeriesStyle::Dashed;
        annotation.label(series.label.as_str()).legend(move |(x, y)| {
            let end = if dashed { x + 8 } else { x + 18 };
            PathElement::new(vec![(x, y), (end, y)], color.stroke_width(3))
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Figure {
        let line = Series::new(
            "cooling",
            (0..50).map(|i| (i as f64, 33.0 - (i as f64).sqrt())).collect(),
            SeriesStyle::Line,
            0,
        );
        let dashed = Series::new("target", vec![(0.0, 33.0), (49.0, 27.0)], SeriesStyle::Dashed, 1);
        let bars = Series::new(
            "share",
            vec![(-1.0, 0.2), (0.0, 0.6), (1.0, f64::NAN)],
            SeriesStyle::Bars { width: 0.8 },
            2,
        );
        let first = Panel {
            title: "Skin".into(),
            x_label: "time [s]".into(),
            y_label: "T [°C]".into(),
            series: vec![line, dashed],
            ..Panel::default()
        };
        let second = Panel {
            title: "Bars".into(),
            series: vec![bars],
            ..Panel::default()
        };
        Figure::grid(vec![first, second], 2)
    }

    #[test]
    fn svg_contains_labels_and_geometry() {
        let svg = svg_string(&sample()).expect("svg");
        assert!(
            svg.starts_with("<svg"),
            "not an SVG document: {}",
            &svg[..40.min(svg.len())]
        );
        for text in ["Skin", "time [s]", "cooling", "target", "Bars"] {
            assert!(svg.contains(text), "SVG lacks `{text}`");
        }
        assert!(svg.contains("<polyline") || svg.contains("<path"), "SVG has no line");
        assert!(svg.contains("<rect"), "SVG has no bar");
    }

    #[test]
    fn png_and_svg_files_are_written_and_bad_names_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let png = dir.path().join("figure.png");
        write_figure(&sample(), &png).expect("png");
        let bytes = std::fs::read(&png).expect("read png");
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
        assert!(bytes.len() > 5_000, "PNG suspiciously small: {} bytes", bytes.len());
        let svg = dir.path().join("figure.SVG");
        write_figure(&sample(), &svg).expect("svg");
        let err = write_figure(&sample(), &dir.path().join("figure.jpg")).unwrap_err();
        assert!(matches!(err, PlotError::UnsupportedFormat { .. }), "{err}");
        let leftovers: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .filter_map(|e| e.ok())
            .map(|e| e.file_name())
            .collect();
        assert_eq!(leftovers.len(), 2, "temporary files left behind: {leftovers:?}");
        let missing = dir.path().join("no-such-dir").join("f.svg");
        assert!(matches!(write_figure(&sample(), &missing), Err(PlotError::Io { .. })));
    }

    #[test]
    fn a_window_keeps_only_its_points_and_spans_exactly_the_window() {
        let panel = &sample().panels[0];
        let early = panel.window(0.0, 5.0, "first 5 s");
        assert_eq!(early.x_range, Some((0.0, 5.0)));
        assert_eq!(early.series[0].points.len(), 6, "{:?}", early.series[0].points);
        assert!(early
            .series
            .iter()
            .all(|s| s.points.iter().all(|(x, _)| (0.0..=5.0).contains(x))));
        let svg = svg_string(&Figure::grid(vec![panel.clone(), early], 2)).expect("svg");
        assert!(svg.contains("first 5 s"));
    }

    #[test]
    fn empty_data_is_an_error_not_a_panic() {
        let panel = Panel {
            series: vec![Series::new("nan", vec![(f64::NAN, 1.0)], SeriesStyle::Line, 0)],
            ..Panel::default()
        };
        assert!(matches!(svg_string(&Figure::single(panel)), Err(PlotError::Empty(_))));
        assert!(matches!(svg_string(&Figure::grid(vec![], 1)), Err(PlotError::Empty(_))));
    }
}
