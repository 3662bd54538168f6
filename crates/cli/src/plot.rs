//! Figures: stacked time-series panels sharing one time axis, written as SVG (no fonts needed).

use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::prelude::*;

use crate::record_csv::write_atomically;

/// One curve of a panel.
pub struct Series<'a> {
    /// Legend text.
    pub label: &'a str,
    /// Values, one per time sample.
    pub values: &'a [f64],
    /// Colour.
    pub color: RGBColor,
}

/// One panel: a title for its y axis and its curves.
pub struct Panel<'a> {
    /// Y-axis description with unit.
    pub y_label: &'a str,
    /// Curves.
    pub series: Vec<Series<'a>>,
}

/// Draws `panels` stacked over the common time axis `t` [s] into the SVG file `path`.
pub fn time_series_svg(path: &Path, title: &str, t: &[f64], panels: &[Panel<'_>]) -> Result<()> {
    let mut svg = String::new();
    {
        let height = 260 * panels.len() as u32 + 60;
        let root = SVGBackend::with_string(&mut svg, (1000, height)).into_drawing_area();
        let draw = |e: &dyn std::fmt::Display| anyhow!("drawing {}: {e}", path.display());
        root.fill(&WHITE).map_err(|e| draw(&e))?;
        let root = root
            .titled(title, ("sans-serif", 20))
            .map_err(|e| draw(&e))?;
        let areas = root.split_evenly((panels.len(), 1));
        let (t0, t1) = (
            t.first().copied().unwrap_or(0.0),
            t.last().copied().unwrap_or(1.0),
        );
        for (area, panel) in areas.iter().zip(panels) {
            let (mut lo, mut hi) = panel
                .series
                .iter()
                .flat_map(|s| s.values.iter().copied())
                .filter(|v| v.is_finite())
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                    (lo.min(v), hi.max(v))
                });
            if hi <= lo {
                (lo, hi) = (lo.min(0.0) - 1.0, hi.max(0.0) + 1.0);
            }
            let pad = 0.05 * (hi - lo);
            let mut chart = ChartBuilder::on(area)
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(80)
                .build_cartesian_2d(t0..t1, (lo - pad)..(hi + pad))
                .map_err(|e| draw(&e))?;
            chart
                .configure_mesh()
                .x_desc("t [s]")
                .y_desc(panel.y_label)
                .draw()
                .map_err(|e| draw(&e))?;
            for s in &panel.series {
                let color = s.color;
                chart
                    .draw_series(LineSeries::new(
                        t.iter().copied().zip(s.values.iter().copied()),
                        color.stroke_width(1),
                    ))
                    .map_err(|e| draw(&e))?
                    .label(s.label)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|e| draw(&e))?;
        }
        root.present().map_err(|e| draw(&e))?;
    }
    write_atomically(path, svg.as_bytes())
}
