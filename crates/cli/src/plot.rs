//! Line plots as SVG (plotters), shared by `simulate`, `fit` and `diagnose`.

use std::path::Path;

use plotters::prelude::*;

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

pub const MEASURED: RGBColor = RGBColor(90, 90, 90);
pub const SIMULATED: RGBColor = RGBColor(214, 39, 40);
pub const START: RGBColor = RGBColor(31, 119, 180);
pub const EXTRA: RGBColor = RGBColor(44, 160, 44);

fn range(panel: &Panel) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for s in &panel.series {
        for &v in s.y.iter().filter(|v| v.is_finite()) {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = ((hi - lo) * 0.08).max(1e-3);
    (lo - pad, hi + pad)
}

/// Draws stacked panels into an SVG file.
pub fn draw(path: &Path, title: &str, x_label: &str, panels: &[Panel]) -> Result<(), String> {
    let height = 60 + 260 * panels.len() as u32;
    let root = SVGBackend::new(path, (1000, height)).into_drawing_area();
    let err = |e: &dyn std::fmt::Display| format!("plot {}: {e}", path.display());
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let root = root.titled(title, ("sans-serif", 22)).map_err(|e| err(&e))?;
    let areas = root.split_evenly((panels.len(), 1));
    let (x0, x1) = panels
        .iter()
        .flat_map(|p| p.series.iter())
        .flat_map(|s| s.x.iter().copied())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    let (x0, x1) = if x0 < x1 { (x0, x1) } else { (0.0, 1.0) };
    for (panel, area) in panels.iter().zip(areas.iter()) {
        let (y0, y1) = range(panel);
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
            .y_label_formatter(&|v| format!("{:.3}", if v.abs() < 1e-12 { 0.0 } else { *v }))
            .draw()
            .map_err(|e| err(&e))?;
        for s in &panel.series {
            let style = ShapeStyle { color: s.color.to_rgba(), filled: false, stroke_width: if s.thin { 1 } else { 2 } };
            let pts: Vec<(f64, f64)> =
                s.x.iter().zip(s.y).filter(|(x, y)| x.is_finite() && y.is_finite()).map(|(x, y)| (*x, *y)).collect();
            let color = s.color;
            chart
                .draw_series(LineSeries::new(pts, style))
                .map_err(|e| err(&e))?
                .label(s.label.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 22, y)], color.stroke_width(2)));
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
    Ok(())
}
