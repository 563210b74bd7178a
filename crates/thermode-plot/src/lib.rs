//! thermode-plot: figures for thermode written as SVG or PNG files, laid out for a paper.
//!
//! A [`Figure`] is an optional title over a grid of [`Panel`]s; each panel has a letter (`a`, `b`, … when there is
//! more than one), a title, axes and [`Series`] drawn as lines, dashed lines, points or bars, optionally with
//! [`Marker`]s that keep overlapping curves apart. Titles are sized to fit inside the canvas; tick labels carry only
//! the decimals their step needs (never `1.0` or `-0`); the grid is one light grey line per labelled tick. The
//! figure has one legend, a column to the right of all panels, never over the data: one entry per distinct series,
//! its swatch in the series' own style and marker. [`write_figure`] picks the format from the file extension
//! (`.svg` or `.png`; plotters offers no PDF backend) and writes atomically (a temporary file in the same folder,
//! then a rename), so a failed plot never leaves half a file. The PNG text uses DejaVu Sans, embedded in the binary
//! (licence in `assets/DejaVuSans-LICENSE.txt`), so no system font is needed at run time.

mod marks;
pub mod svg_text;
mod ticks;

use std::path::{Path, PathBuf};
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use thermode_platform::WriteError;
use thiserror::Error;

pub use marks::Marker;
pub use ticks::{tick_decimals, tick_label, tick_values, TICKS_PER_AXIS};

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
    /// Marker drawn at a few points along the series (`None`: none).
    pub marker: Option<Marker>,
}

impl Series {
    /// A series with the given style and palette colour.
    pub fn new(label: impl Into<String>, points: Vec<(f64, f64)>, style: SeriesStyle, color: usize) -> Self {
        Series {
            label: label.into(),
            points,
            style,
            color,
            marker: None,
        }
    }

    /// This series with `marker` drawn at a few points along it.
    pub fn with_marker(self, marker: Marker) -> Self {
        Series {
            marker: Some(marker),
            ..self
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
    /// Title above all panels (`None`: none).
    pub title: Option<String>,
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
    /// A figure of one panel, 800 × 500 px (and the legend column).
    pub fn single(panel: Panel) -> Self {
        Figure::grid(vec![panel], 1)
    }

    /// A figure of several panels, `columns` per row, each 800 × 500 px (and the legend column).
    pub fn grid(panels: Vec<Panel>, columns: usize) -> Self {
        Figure {
            title: None,
            panels,
            columns: columns.max(1),
            panel_width_px: 800,
            panel_height_px: 500,
        }
    }

    /// This figure with `title` above its panels.
    pub fn with_title(self, title: impl Into<String>) -> Self {
        Figure {
            title: Some(title.into()),
            ..self
        }
    }

    /// Width and height of the canvas (px): the panels, the legend column if any series is labelled, the title
    /// band if there is a title.
    pub fn size_px(&self) -> (u32, u32) {
        let columns = self.columns.max(1);
        let rows = self.panels.len().div_ceil(columns).max(1);
        let labelled = self.panels.iter().flat_map(|p| &p.series).any(|s| !s.label.is_empty());
        let legend_px = if labelled { LEGEND_WIDTH_PX } else { 0 };
        let title_px = if self.title.is_some() { TITLE_BAND_PX } else { 0 };
        (
            self.panel_width_px * columns as u32 + legend_px,
            self.panel_height_px * rows as u32 + title_px,
        )
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

/// Height of the band that holds a figure's title (px): 44.
pub const TITLE_BAND_PX: u32 = 44;
/// Height of the band above each panel's axes that holds its letter and title (px): 36; none for a lone panel
/// without a title.
pub const PANEL_HEAD_PX: u32 = 36;
/// Width of the legend column to the right of a figure's panels (px): 240, room for about 28 characters.
pub const LEGEND_WIDTH_PX: u32 = 240;
/// Largest figure title (px): 22.
const TITLE_FONT_PX: u32 = 22;
/// Largest panel title (px): 18.
const PANEL_TITLE_FONT_PX: u32 = 18;
/// Room kept left of a panel title for the panel letter (px): 48.
const LETTER_ROOM_PX: u32 = 48;

fn draw_figure<DB: DrawingBackend>(figure: &Figure, root: &DrawingArea<DB, Shift>) -> Result<(), PlotError> {
    REGISTER_FONT.call_once(|| {
        // The bytes are the embedded DejaVu Sans; registration cannot fail for a valid TrueType file.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT_BYTES);
        let _ = plotters::style::register_font("sans-serif", FontStyle::Bold, FONT_BYTES);
    });
    if figure.panels.is_empty() {
        return Err(PlotError::Empty("the figure has no panel".into()));
    }
    root.fill(&WHITE).map_err(drawing)?;
    let main = match &figure.title {
        Some(title) => {
            let (band, rest) = root.split_vertically(TITLE_BAND_PX);
            draw_centred_title(&band, title, TITLE_FONT_PX, 16)?;
            rest
        }
        None => root.clone(),
    };
    let entries = marks::legend_entries(figure.panels.iter().flat_map(|p| &p.series));
    let body = if entries.is_empty() {
        main
    } else {
        let width_px = main.dim_in_pixel().0;
        let (body, legend) = main.split_horizontally(width_px.saturating_sub(LEGEND_WIDTH_PX));
        let first = &figure.panels[0];
        let head_px = if figure.panels.len() > 1 || !first.title.is_empty() {
            PANEL_HEAD_PX
        } else {
            0
        };
        marks::draw_legend(&legend, &entries, head_px as i32 + 16)?;
        body
    };
    let columns = figure.columns.max(1);
    let rows = figure.panels.len().div_ceil(columns);
    let areas = body.split_evenly((rows, columns));
    let lettered = figure.panels.len() > 1;
    for (index, (panel, area)) in figure.panels.iter().zip(areas.iter()).enumerate() {
        let letter = lettered.then(|| panel_letter(index));
        draw_panel(panel, area, letter.as_deref(), root)?;
    }
    Ok(())
}

/// The letter of the `index`-th panel: `a`, `b`, … `z`, then `aa`, `ab`, ….
pub fn panel_letter(index: usize) -> String {
    let letter = |i: usize| char::from(b'a' + (i % 26) as u8);
    match index / 26 {
        0 => letter(index).to_string(),
        n => format!("{}{}", letter(n - 1), letter(index)),
    }
}

/// `text` centred in `area` (horizontally, `top_px` from its top), as large as fits up to `max_px`, with 8 px
/// to spare on each side.
fn draw_centred_title<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    max_px: u32,
    top_px: i32,
) -> Result<(), PlotError> {
    let width_px = area.dim_in_pixel().0;
    let size = marks::fitted_font_px(area, text, max_px, width_px.saturating_sub(16))?;
    let style = TextStyle::from(("sans-serif", size)).pos(Pos::new(HPos::Center, VPos::Center));
    area.draw(&Text::new(text, (width_px as i32 / 2, top_px), style))
        .map_err(drawing)
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

/// Light grey of the grid lines (one grid, at the labelled ticks).
const GRID_COLOR: RGBColor = RGBColor(228, 228, 228);
/// Colour of the axes and their labels.
const AXIS_COLOR: RGBColor = RGBColor(60, 60, 60);

/// One panel in `area`: its letter (if any) and title in a band above the axes, then the axes, grid and series.
/// `root` is the figure's whole canvas (markers are drawn there, in pixels).
fn draw_panel<DB: DrawingBackend>(
    panel: &Panel,
    area: &DrawingArea<DB, Shift>,
    letter: Option<&str>,
    root: &DrawingArea<DB, Shift>,
) -> Result<(), PlotError> {
    let ((x0, x1), (y0, y1)) = panel_ranges(panel)?;
    let plot_area = if letter.is_none() && panel.title.is_empty() {
        area.clone()
    } else {
        let (head, plot_area) = area.split_vertically(PANEL_HEAD_PX);
        draw_panel_head(&head, panel, letter)?;
        plot_area
    };
    let mut chart = ChartBuilder::on(&plot_area)
        .margin_top(4)
        .margin_bottom(6)
        .margin_left(8)
        .margin_right(20)
        .x_label_area_size(48)
        .y_label_area_size(64)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(drawing)?;
    let (x_decimals, y_decimals) = (ticks::tick_decimals(x0, x1), ticks::tick_decimals(y0, y1));
    let x_format = move |v: &f64| ticks::tick_label(*v, x_decimals);
    let y_format = move |v: &f64| ticks::tick_label(*v, y_decimals);
    chart
        .configure_mesh()
        .x_labels(ticks::TICKS_PER_AXIS)
        .y_labels(ticks::TICKS_PER_AXIS)
        .x_label_formatter(&x_format)
        .y_label_formatter(&y_format)
        .max_light_lines(0)
        .bold_line_style(GRID_COLOR)
        .axis_style(AXIS_COLOR)
        .x_desc(panel.x_label.as_str())
        .y_desc(panel.y_label.as_str())
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 16))
        .draw()
        .map_err(drawing)?;
    for series in &panel.series {
        draw_series(&mut chart, series)?;
    }
    for series in panel.series.iter().filter(|s| s.marker.is_some()) {
        let points: Vec<(f64, f64)> = finite_points(series).collect();
        for point in marks::marker_points(&points, series.color) {
            let pixel = chart.backend_coord(&point);
            if let Some(marker) = series.marker {
                marks::draw_marker(root, marker, pixel, palette(series.color))?;
            }
        }
    }
    Ok(())
}

/// The band above a panel's axes: its letter in bold at the left, its title centred in the room left.
fn draw_panel_head<DB: DrawingBackend>(
    head: &DrawingArea<DB, Shift>,
    panel: &Panel,
    letter: Option<&str>,
) -> Result<(), PlotError> {
    let middle_px = PANEL_HEAD_PX as i32 / 2 + 4;
    if let Some(letter) = letter {
        let style = TextStyle::from(("sans-serif", 20, FontStyle::Bold)).pos(Pos::new(HPos::Left, VPos::Center));
        head.draw(&Text::new(letter, (12, middle_px), style)).map_err(drawing)?;
    }
    if panel.title.is_empty() {
        return Ok(());
    }
    let width_px = head.dim_in_pixel().0;
    let room_px = width_px.saturating_sub(2 * LETTER_ROOM_PX);
    let size = marks::fitted_font_px(head, &panel.title, PANEL_TITLE_FONT_PX, room_px)?;
    let style = TextStyle::from(("sans-serif", size)).pos(Pos::new(HPos::Center, VPos::Center));
    head.draw(&Text::new(
        panel.title.as_str(),
        (width_px as i32 / 2, middle_px),
        style,
    ))
    .map_err(drawing)
}

type Chart<'a, DB> =
    ChartContext<'a, DB, Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>>;

fn draw_series<DB: DrawingBackend>(chart: &mut Chart<'_, DB>, series: &Series) -> Result<(), PlotError> {
    let color = palette(series.color);
    let points: Vec<(f64, f64)> = finite_points(series).collect();
    let style = ShapeStyle::from(color).stroke_width(2);
    match series.style {
        SeriesStyle::Line => chart.draw_series(LineSeries::new(points, style)).map(drop),
        SeriesStyle::Dashed => chart.draw_series(DashedLineSeries::new(points, 9, 6, style)).map(drop),
        SeriesStyle::Points => chart
            .draw_series(points.into_iter().map(|p| Circle::new(p, 4, color.filled())))
            .map(drop),
        SeriesStyle::Bars { width } => {
            let half = width.abs() / 2.0;
            chart
                .draw_series(
                    points
                        .into_iter()
                        .map(|(x, y)| Rectangle::new([(x - half, 0.0), (x + half, y)], color.mix(0.8).filled())),
                )
                .map(drop)
        }
    }
    .map_err(drawing)
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

    use crate::svg_text::{badly_written_numbers, canvas_width_px, number_texts, svg_texts, texts_outside};

    #[test]
    fn titles_fit_the_canvas_ticks_are_plain_and_the_legend_is_listed_once() {
        let long = "Figure 3: mean finger temperature, real (solid) and simulated (dashed) of every material";
        let mut figure = sample().with_title(long);
        figure.panels[0].title = "a panel title long enough to be clipped if it kept its largest size".into();
        let shared = figure.panels[0].series[0].clone();
        figure.panels[1].series.push(shared);
        let svg = svg_string(&figure).expect("svg");
        let (width_px, _) = figure.size_px();
        let outside = texts_outside(&svg, width_px as f64);
        assert!(
            outside.is_empty(),
            "texts outside the {width_px} px canvas: {outside:?}"
        );
        let texts = svg_texts(&svg);
        for title in [long, "Bars", "a", "b"] {
            assert!(texts.iter().any(|t| t.content == title), "SVG lacks the text `{title}`");
        }
        let numbers = number_texts(&svg);
        assert!(numbers.len() >= 10, "too few tick labels: {numbers:?}");
        let bad = badly_written_numbers(&svg);
        assert!(
            bad.is_empty(),
            "tick labels with a needless decimal or a negative zero: {bad:?} of {numbers:?}"
        );
        assert_eq!(canvas_width_px(&svg), Some(width_px as f64));
        let legend_rows = texts.iter().filter(|t| t.content == "cooling").count();
        assert_eq!(
            legend_rows, 1,
            "the series drawn in both panels is listed {legend_rows} times"
        );
    }

    #[test]
    fn the_old_layout_would_have_been_caught() {
        // The check itself: a title centred at x = 285 px in 22 px type (plotters' caption of a 570 px wide axes area)
        // sticks out on the left, as the lab's Figure 3 title did.
        let svg = r#"<svg width="800" height="500"><text x="285" y="20" dy="0.76em" text-anchor="middle" font-family="sans-serif" font-size="17.741936">Figure 3: mean finger temperature, real (solid) and simulated (dashed)</text></svg>"#;
        assert_eq!(texts_outside(svg, 800.0).len(), 1, "{:?}", texts_outside(svg, 800.0));
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
