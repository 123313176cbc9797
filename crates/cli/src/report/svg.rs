//! Line plots as SVG (plotters), shared by `simulate`, `fit` and `diagnose`: drawn into a
//! string, written as a file and inlined in the HTML reports from the same text.

use std::path::Path;

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// One line.
pub struct Series<'a> {
    pub label: String,
    pub x: &'a [f64],
    pub y: &'a [f64],
    pub color: RGBColor,
    /// Drawn thinner (e.g. measurements under a simulation).
    pub thin: bool,
}

/// One panel (its own y axis; panels share the x axis range).
pub struct Panel<'a> {
    pub y_label: String,
    pub series: Vec<Series<'a>>,
}

/// A panel of a measured channel (`measured_label`) with the simulation at a fit's start and
/// end drawn over it (`start`, `calibrated`), as the fit report and the stage plots draw it; a
/// channel that is played back, not simulated (`end` empty), shows the measurement alone.
pub fn start_end_panel<'a>(
    t: &'a [f64],
    y_label: String,
    measured_label: &str,
    meas: &'a [f64],
    start: &'a [f64],
    end: &'a [f64],
) -> Panel<'a> {
    let series = |label: &str, y, color, thin| Series {
        label: label.into(),
        x: t,
        y,
        color,
        thin,
    };
    let mut v = vec![series(measured_label, meas, MEASURED, true)];
    if !end.is_empty() {
        v.push(series("start", start, START, true));
        v.push(series("calibrated", end, SIMULATED, false));
    }
    Panel { y_label, series: v }
}

pub const MEASURED: RGBColor = RGBColor(90, 90, 90);
pub const SIMULATED: RGBColor = RGBColor(214, 39, 40);
pub const START: RGBColor = RGBColor(31, 119, 180);
/// An input as the playback imposes it where it differs from the record (the smoothed |V|).
pub const PLAYED: RGBColor = RGBColor(255, 127, 14);
pub const EXTRA: RGBColor = RGBColor(44, 160, 44);

/// Decorations of one panel beyond its lines (all optional; `Decor::default()` draws nothing).
#[derive(Debug, Clone, Default)]
pub struct Decor {
    /// Shaded x intervals over the panel's full height (e.g. an implicated time window).
    pub spans: Vec<Span>,
    /// Shaded horizontal bands over the panel's full width (e.g. a ±σ noise band).
    pub y_bands: Vec<YBand>,
    /// Labelled points (e.g. a spectral peak).
    pub markers: Vec<Marker>,
}

/// A shaded interval `x0..x1` of the x axis.
#[derive(Debug, Clone)]
pub struct Span {
    pub label: String,
    pub x0: f64,
    pub x1: f64,
    pub color: RGBColor,
}

/// A shaded band `y0..y1` of the y axis.
#[derive(Debug, Clone)]
pub struct YBand {
    pub label: String,
    pub y0: f64,
    pub y1: f64,
    pub color: RGBColor,
}

/// A labelled point.
#[derive(Debug, Clone)]
pub struct Marker {
    pub label: String,
    pub x: f64,
    pub y: f64,
    pub color: RGBColor,
}

/// Colour of shaded windows.
pub const HIGHLIGHT: RGBColor = RGBColor(255, 150, 0);
/// Colour of noise bands.
pub const NOISE: RGBColor = RGBColor(150, 150, 150);

fn range(panel: &Panel, decor: Option<&Decor>) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    let extra = decor
        .map(|d| {
            let mut v: Vec<f64> = d.y_bands.iter().flat_map(|b| [b.y0, b.y1]).collect();
            v.extend(d.markers.iter().map(|m| m.y));
            v
        })
        .unwrap_or_default();
    for v in panel
        .series
        .iter()
        .flat_map(|s| s.y.iter())
        .chain(extra.iter())
        .filter(|v| v.is_finite())
    {
        lo = lo.min(*v);
        hi = hi.max(*v);
    }
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    // At least 0.1 % of the magnitude (1e-3 around 1 pu, as before), relative for small
    // quantities such as residuals and spectra.
    let pad = ((hi - lo) * 0.08).max(1e-3 * hi.abs().max(lo.abs()));
    let pad = if pad > 0.0 { pad } else { 1e-3 };
    // Room above for marker labels.
    let top = if decor.is_some_and(|d| !d.markers.is_empty()) {
        0.12 * (hi - lo + 2.0 * pad)
    } else {
        0.0
    };
    (lo - pad, hi + pad + top)
}

/// Decimals of the y tick labels for an axis spanning `span`: 3 (as before) unless the ticks
/// are finer.
fn y_decimals(span: f64) -> usize {
    if span > 0.0 && span.is_finite() {
        ((-(span / 5.0).log10()).ceil() + 1.0).clamp(3.0, 9.0) as usize
    } else {
        3
    }
}

/// Draws stacked panels into an SVG file.
pub fn draw(path: &Path, title: &str, x_label: &str, panels: &[Panel]) -> Result<(), String> {
    draw_with(path, title, x_label, panels, &[])
}

/// Draws stacked panels into an SVG file, panel `k` decorated by `decor[k]` (panels beyond
/// `decor.len()` are drawn plain).
pub fn draw_with(
    path: &Path,
    title: &str,
    x_label: &str,
    panels: &[Panel],
    decor: &[Decor],
) -> Result<(), String> {
    let svg = render(title, x_label, panels, decor)
        .map_err(|e| format!("plot {}: {e}", path.display()))?;
    std::fs::write(path, svg).map_err(|e| format!("plot {}: {e}", path.display()))
}

/// Draws stacked panels into SVG text, panel `k` decorated by `decor[k]`.
pub fn render(
    title: &str,
    x_label: &str,
    panels: &[Panel],
    decor: &[Decor],
) -> Result<String, String> {
    let mut text = String::new();
    {
        let height = 60 + 260 * panels.len() as u32;
        let root = SVGBackend::with_string(&mut text, (1000, height)).into_drawing_area();
        let err = |e: &dyn std::fmt::Display| e.to_string();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let root = root
            .titled(title, ("sans-serif", 22))
            .map_err(|e| err(&e))?;
        let areas = root.split_evenly((panels.len(), 1));
        let (x0, x1) = panels
            .iter()
            .flat_map(|p| p.series.iter())
            .flat_map(|s| s.x.iter().copied())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
        let (x0, x1) = if x0 < x1 { (x0, x1) } else { (0.0, 1.0) };
        for (k, (panel, area)) in panels.iter().zip(areas.iter()).enumerate() {
            let d = decor.get(k);
            let (y0, y1) = range(panel, d);
            let decimals = y_decimals(y1 - y0);
            let mut chart = ChartBuilder::on(area)
                .margin(12)
                .x_label_area_size(38)
                .y_label_area_size(70)
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(|e| err(&e))?;
            chart
                .configure_mesh()
                .x_desc(x_label)
                .y_desc(panel.y_label.as_str())
                .light_line_style(RGBColor(235, 235, 235))
                .label_style(("sans-serif", 14))
                .y_label_formatter(&|v| {
                    format!(
                        "{:.*}",
                        decimals,
                        if v.abs() < 1e-12 * (y1 - y0).max(1e-300) {
                            0.0
                        } else {
                            *v
                        }
                    )
                })
                .draw()
                .map_err(|e| err(&e))?;
            if let Some(d) = d {
                for b in &d.y_bands {
                    let c = b.color;
                    chart
                        .draw_series(std::iter::once(Rectangle::new(
                            [(x0, b.y0), (x1, b.y1)],
                            c.mix(0.25).filled(),
                        )))
                        .map_err(|e| err(&e))?
                        .label(b.label.as_str())
                        .legend(move |(x, y)| {
                            Rectangle::new([(x, y - 5), (x + 22, y + 5)], c.mix(0.4).filled())
                        });
                }
                for s in &d.spans {
                    let c = s.color;
                    let (a, b) = (s.x0.max(x0), s.x1.min(x1));
                    if !(b > a) {
                        continue;
                    }
                    chart
                        .draw_series(std::iter::once(Rectangle::new(
                            [(a, y0), (b, y1)],
                            c.mix(0.18).filled(),
                        )))
                        .map_err(|e| err(&e))?
                        .label(s.label.as_str())
                        .legend(move |(x, y)| {
                            Rectangle::new([(x, y - 5), (x + 22, y + 5)], c.mix(0.35).filled())
                        });
                }
            }
            for s in &panel.series {
                let style = ShapeStyle {
                    color: s.color.to_rgba(),
                    filled: false,
                    stroke_width: if s.thin { 1 } else { 2 },
                };
                let pts: Vec<(f64, f64)> =
                    s.x.iter()
                        .zip(s.y)
                        .filter(|(x, y)| x.is_finite() && y.is_finite())
                        .map(|(x, y)| (*x, *y))
                        .collect();
                let color = s.color;
                chart
                    .draw_series(LineSeries::new(pts, style))
                    .map_err(|e| err(&e))?
                    .label(s.label.as_str())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 22, y)], color.stroke_width(2))
                    });
            }
            if let Some(d) = d {
                for m in d
                    .markers
                    .iter()
                    .filter(|m| m.x.is_finite() && m.y.is_finite())
                {
                    let c = m.color;
                    // The label reads away from the right edge, where the legend is.
                    let right = m.x > x0 + 0.4 * (x1 - x0);
                    let font = ("sans-serif", 15).into_font().color(&c);
                    let (font, dx) = if right {
                        (font.pos(Pos::new(HPos::Right, VPos::Bottom)), -8)
                    } else {
                        (font.pos(Pos::new(HPos::Left, VPos::Bottom)), 8)
                    };
                    let el = EmptyElement::at((m.x, m.y))
                        + Circle::new((0, 0), 5, c.filled())
                        + Text::new(m.label.clone(), (dx, -4), font);
                    chart
                        .draw_series(std::iter::once(el))
                        .map_err(|e| err(&e))?;
                }
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(180, 180, 180))
                .label_font(("sans-serif", 14))
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(|e| err(&e))?;
        }
        root.present().map_err(|e| err(&e))?;
    }
    Ok(text)
}
