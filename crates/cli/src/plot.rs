//! Figures: stacked time-series panels sharing one time axis, and x–y plots, each written as
//! SVG and PNG. Text is drawn with the DejaVu Sans font shipped in `assets/` (its licence is
//! beside it), so PNGs need no system fonts.

use std::path::{Path, PathBuf};
use std::sync::Once;

use anyhow::{anyhow, Result};
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::output;

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

/// Measured data (grey), model (blue), a second model (red).
/// `measured − model`, sample by sample (as long as the shorter), for a residual panel.
pub fn residual(measured: &[f64], model: &[f64]) -> Vec<f64> {
    measured.iter().zip(model).map(|(y, m)| y - m).collect()
}

pub const MEASURED: RGBColor = RGBColor(120, 120, 120);
/// The model's colour.
pub const MODEL: RGBColor = RGBColor(20, 80, 200);
/// A second curve's colour.
pub const OTHER: RGBColor = RGBColor(200, 40, 40);

/// Figure width \[px\]; curves longer than twice this are reduced to their min/max envelope per
/// pixel column, which looks the same and keeps the files small.
const WIDTH: u32 = 1000;

static FONT: Once = Once::new();

fn register_font() {
    FONT.call_once(|| {
        let bytes: &'static [u8] = include_bytes!("../assets/DejaVuSans.ttf");
        // The font is compiled in and known good; a failure would only lose the text.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, bytes);
    });
}

/// `(t, y)` points of a curve, reduced to the min and max of each of `buckets` time slices.
fn envelope(t: &[f64], y: &[f64], buckets: usize) -> Vec<(f64, f64)> {
    let n = t.len().min(y.len());
    if n <= 2 * buckets {
        return t.iter().copied().zip(y.iter().copied()).take(n).collect();
    }
    let mut out = Vec::with_capacity(2 * buckets);
    for b in 0..buckets {
        let (from, to) = (
            b * n / buckets,
            ((b + 1) * n / buckets).max(b * n / buckets + 1),
        );
        let slice = &y[from..to];
        let (mut imin, mut imax) = (0, 0);
        for (i, v) in slice.iter().enumerate() {
            if *v < slice[imin] {
                imin = i;
            }
            if *v > slice[imax] {
                imax = i;
            }
        }
        let (a, b) = (imin.min(imax), imin.max(imax));
        out.push((t[from + a], slice[a]));
        if b != a {
            out.push((t[from + b], slice[b]));
        }
    }
    out
}

fn draw_err(path: &Path) -> impl Fn(&dyn std::fmt::Display) -> anyhow::Error + '_ {
    move |e| anyhow!("drawing {}: {e}", path.display())
}

/// Draws the legend of the labelled series of `chart` on a white box with a black border.
fn draw_legend<'a, DB: DrawingBackend + 'a, CT: plotters::coord::CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    draw: &impl Fn(&dyn std::fmt::Display) -> anyhow::Error,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| draw(&e))
}

fn draw_time_series<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    path: &Path,
    title: &str,
    t: &[f64],
    panels: &[Panel<'_>],
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let draw = draw_err(path);
    root.fill(&WHITE).map_err(|e| draw(&e))?;
    let root = root
        .titled(title, ("sans-serif", 20))
        .map_err(|e| draw(&e))?;
    let areas = root.split_evenly((panels.len(), 1));
    let (t0, t1) = (
        t.first().copied().unwrap_or(0.0),
        t.last().copied().unwrap_or(1.0),
    );
    let t1 = if t1 > t0 { t1 } else { t0 + 1.0 };
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
                    envelope(t, s.values, WIDTH as usize),
                    color.stroke_width(1),
                ))
                .map_err(|e| draw(&e))?
                .label(s.label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
        }
        draw_legend(&mut chart, &draw)?;
    }
    root.present().map_err(|e| draw(&e))?;
    Ok(())
}

/// `stem.svg` and `stem.png` (appended: a stem may hold dots, `paper_2.5V_fit`).
fn paths(stem: &Path) -> (PathBuf, PathBuf) {
    let with = |ext: &str| {
        let mut name = stem.as_os_str().to_owned();
        name.push(".");
        name.push(ext);
        PathBuf::from(name)
    };
    (with("svg"), with("png"))
}

/// Renders a figure of `size` into `stem.svg` and `stem.png` (each written atomically) with
/// `draw`, and returns both paths.
fn render(
    stem: &Path,
    size: (u32, u32),
    draw_svg: impl FnOnce(DrawingArea<SVGBackend<'_>, Shift>, &Path) -> Result<()>,
    draw_png: impl FnOnce(DrawingArea<BitMapBackend<'_>, Shift>, &Path) -> Result<()>,
) -> Result<[PathBuf; 2]> {
    register_font();
    let (svg_path, png_path) = paths(stem);
    let mut svg = String::new();
    draw_svg(
        SVGBackend::with_string(&mut svg, size).into_drawing_area(),
        &svg_path,
    )?;
    output::write_generated(&svg_path, svg.as_bytes())?;
    let mut pixels = vec![0u8; size.0 as usize * size.1 as usize * 3];
    draw_png(
        BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area(),
        &png_path,
    )?;
    let mut png = Vec::new();
    {
        use image::ImageEncoder;
        image::codecs::png::PngEncoder::new(&mut png)
            .write_image(&pixels, size.0, size.1, image::ColorType::Rgb8)
            .map_err(|e| anyhow!("encoding {}: {e}", png_path.display()))?;
    }
    output::write_generated(&png_path, &png)?;
    Ok([svg_path, png_path])
}

/// Draws `panels` stacked over the common time axis `t` \[s\] into `stem.svg` and `stem.png`.
pub fn time_series(
    stem: &Path,
    title: &str,
    t: &[f64],
    panels: &[Panel<'_>],
) -> Result<[PathBuf; 2]> {
    let size = (WIDTH, 260 * panels.len() as u32 + 60);
    render(
        stem,
        size,
        |root, p| draw_time_series(root, p, title, t, panels),
        |root, p| draw_time_series(root, p, title, t, panels),
    )
}

/// An x–y figure: measured points and a model curve.
pub struct XyPlot<'a> {
    /// Title.
    pub title: &'a str,
    /// X-axis description with unit.
    pub x_label: &'a str,
    /// Y-axis description with unit.
    pub y_label: &'a str,
    /// Measured points and their legend.
    pub points: (&'a str, &'a [(f64, f64)]),
    /// Model curve and its legend.
    pub curve: (&'a str, &'a [(f64, f64)]),
}

fn draw_xy<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    path: &Path,
    plot: &XyPlot<'_>,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let draw = draw_err(path);
    root.fill(&WHITE).map_err(|e| draw(&e))?;
    let all = plot.points.1.iter().chain(plot.curve.1);
    let (x0, x1, y0, y1) = all.fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(a, b, c, d), &(x, y)| (a.min(x), b.max(x), c.min(y), d.max(y)),
    );
    let pad = |lo: f64, hi: f64| {
        let p = if hi > lo { 0.05 * (hi - lo) } else { 1.0 };
        (lo - p)..(hi + p)
    };
    let mut chart = ChartBuilder::on(&root)
        .caption(plot.title, ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(80)
        .build_cartesian_2d(pad(x0, x1), pad(y0, y1))
        .map_err(|e| draw(&e))?;
    chart
        .configure_mesh()
        .x_desc(plot.x_label)
        .y_desc(plot.y_label)
        .draw()
        .map_err(|e| draw(&e))?;
    chart
        .draw_series(LineSeries::new(
            plot.curve.1.iter().copied(),
            MODEL.stroke_width(2),
        ))
        .map_err(|e| draw(&e))?
        .label(plot.curve.0)
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], MODEL));
    chart
        .draw_series(
            plot.points
                .1
                .iter()
                .map(|&(x, y)| Circle::new((x, y), 5, OTHER.filled())),
        )
        .map_err(|e| draw(&e))?
        .label(plot.points.0)
        .legend(|(x, y)| Circle::new((x + 10, y), 5, OTHER.filled()));
    draw_legend(&mut chart, &draw)?;
    root.present().map_err(|e| draw(&e))?;
    Ok(())
}

/// Draws an [`XyPlot`] into `stem.svg` and `stem.png`.
pub fn xy(stem: &Path, plot: &XyPlot<'_>) -> Result<[PathBuf; 2]> {
    render(
        stem,
        (WIDTH, 600),
        |root, p| draw_xy(root, p, plot),
        |root, p| draw_xy(root, p, plot),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envelope_keeps_every_extreme() {
        let t: Vec<f64> = (0..10_000).map(f64::from).collect();
        let y: Vec<f64> = t
            .iter()
            .map(|x| (x * 0.37).sin() + if *x == 5000.0 { 9.0 } else { 0.0 })
            .collect();
        let e = envelope(&t, &y, 100);
        assert!(e.len() <= 200);
        assert!(e.iter().any(|&(x, v)| x == 5000.0 && v > 8.0));
        let lo = e.iter().fold(f64::INFINITY, |m, p| m.min(p.1));
        assert!((lo - y.iter().fold(f64::INFINITY, |m, v| m.min(*v))).abs() < 1e-12);
    }
}
