//! The text of a written SVG figure read back, for checks a reader would make by eye: which texts stick out of the
//! canvas (titles clipped at an edge) and which tick labels carry a needless decimal or a negative zero. Widths are
//! estimated at 0.6 em per character, wider than DejaVu Sans' average, so the estimate errs on the side of "clipped".

/// One `<text>` element of an SVG.
#[derive(Debug, Clone, PartialEq)]
pub struct SvgText {
    /// The text, trimmed.
    pub content: String,
    /// The anchor's x (px).
    pub x: f64,
    /// `start`, `middle` or `end`.
    pub anchor: String,
    /// Font size (px).
    pub font_px: f64,
    /// Whether the text is rotated (an axis description on the y axis).
    pub rotated: bool,
}

fn attribute(tag: &str, name: &str) -> Option<String> {
    let start = tag.find(&format!(" {name}=\""))? + name.len() + 3;
    Some(tag[start..].split('"').next()?.to_string())
}

/// Every `<text>` element of `svg`, in document order.
pub fn svg_texts(svg: &str) -> Vec<SvgText> {
    svg.split("<text")
        .skip(1)
        .filter_map(|element| {
            let (tag, rest) = element.split_once('>')?;
            let content = rest.split("</text>").next().unwrap_or_default().trim().to_string();
            let number = |name: &str| {
                attribute(tag, name)
                    .and_then(|v| v.parse::<f64>().ok())
                    .unwrap_or(f64::NAN)
            };
            Some(SvgText {
                content,
                x: number("x"),
                anchor: attribute(tag, "text-anchor").unwrap_or_default(),
                font_px: number("font-size"),
                rotated: attribute(tag, "transform").is_some(),
            })
        })
        .collect()
}

/// The canvas width of `svg` (its `width` attribute, px).
pub fn canvas_width_px(svg: &str) -> Option<f64> {
    let tag = svg.split("<svg").nth(1)?.split('>').next()?;
    attribute(tag, "width")?.parse().ok()
}

/// Horizontal texts of `svg` that may stick out of a canvas `width_px` wide, each as
/// "`text`: from … to … px of …".
pub fn texts_outside(svg: &str, width_px: f64) -> Vec<String> {
    svg_texts(svg)
        .iter()
        .filter(|t| !t.rotated)
        .filter_map(|t| {
            let width = 0.6 * t.font_px * t.content.chars().count() as f64;
            let left = match t.anchor.as_str() {
                "middle" => t.x - width / 2.0,
                "end" => t.x - width,
                _ => t.x,
            };
            let outside = !(left >= 0.0 && left + width <= width_px);
            outside.then(|| {
                format!(
                    "`{}`: from {left:.0} to {:.0} px of {width_px}",
                    t.content,
                    left + width
                )
            })
        })
        .collect()
}

/// The texts of `svg` that are numbers (the tick labels).
pub fn number_texts(svg: &str) -> Vec<String> {
    svg_texts(svg)
        .into_iter()
        .map(|t| t.content)
        .filter(|c| c.parse::<f64>().is_ok())
        .collect()
}

/// The numbers of `svg` written with a needless trailing `.0` or as a negative zero.
pub fn badly_written_numbers(svg: &str) -> Vec<String> {
    number_texts(svg)
        .into_iter()
        .filter(|c| c.ends_with(".0") || (c.starts_with('-') && c.parse::<f64>() == Ok(0.0)))
        .collect()
}
