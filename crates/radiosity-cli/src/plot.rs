//! The convergence plot of `solve --plot FILE`: residual (log scale) against solver time
//! (log scale) and against sweeps, one line per solver, with a legend and the 1e-3 level
//! marked. Drawn with plotters' bitmap backend into memory and encoded by the library's
//! PNG encoder; text uses an embedded subset of DejaVu Sans (assets/, Bitstream Vera
//! licence) through ab_glyph, so no system font or fontconfig is needed.

use anyhow::{anyhow, Result};
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};
use radiosity::solve::IterationRecord;

static FONT: &[u8] = include_bytes!("../assets/DejaVuSans-subset.ttf");

/// The plot's lowest residual: a tenth of the smallest iterative residual; a direct
/// solve (~1e-16) is drawn at it, on the bottom edge.
fn floor(series: &[Series]) -> f64 {
    let min = series
        .iter()
        .filter(|s| s.history.len() > 1)
        .flat_map(|s| s.history.iter().map(|r| r.residual))
        .filter(|r| *r > 0.0)
        .fold(1.0, f64::min);
    (min / 10.0).max(1e-16)
}

/// One line of the plot.
pub struct Series {
    /// Legend label.
    pub label: String,
    /// The solver's history.
    pub history: Vec<IterationRecord>,
}

/// The plot as PNG bytes.
pub fn convergence_png(title: &str, series: &[Series], width: u32, height: u32) -> Result<Vec<u8>> {
    register_font("sans-serif", FontStyle::Normal, FONT).map_err(|_| anyhow!("the embedded plot font is invalid"))?;
    let mut buf = vec![255u8; (width * height * 3) as usize];
    draw(&mut buf, title, series, width, height).map_err(|e| anyhow!("drawing the plot: {e}"))?;
    Ok(radiosity::output::png::encode_rgb8(width as usize, height as usize, &buf)?)
}

const COLOURS: [RGBColor; 8] = [
    RGBColor(0, 0, 0),
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
];

fn draw(buf: &mut [u8], title: &str, series: &[Series], width: u32, height: u32) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::with_buffer(buf, (width, height)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(title, ("sans-serif", 22))?;
    let (left, right) = root.split_horizontally(width / 2);

    let floor = floor(series);
    let points = |f: &dyn Fn(&IterationRecord) -> f64| -> Vec<Vec<(f64, f64)>> {
        series.iter().map(|s| s.history.iter().map(|r| (f(r), r.residual.max(floor))).collect()).collect()
    };
    let by_time = points(&|r| r.seconds.max(1e-6));
    let by_sweep = points(&|r| r.sweeps);
    let all = || by_time.iter().flatten();
    let y_min = floor / 1.2;
    let t_min = all().map(|p| p.0).fold(f64::INFINITY, f64::min).min(1.0) / 1.5;
    let t_max = all().map(|p| p.0).fold(0.0, f64::max).max(t_min * 10.0) * 1.5;
    let s_max = by_sweep.iter().flatten().map(|p| p.0).fold(0.0, f64::max).max(1.0) * 1.05;

    // Left: against time.
    let mut chart = ChartBuilder::on(&left)
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d((t_min..t_max).log_scale(), (y_min..2.0).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("solver time (s)")
        .y_desc("relative residual / unshot power")
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .x_label_formatter(&|x| format!("{x}"))
        .label_style(("sans-serif", 14))
        .draw()?;
    chart.draw_series(LineSeries::new([(t_min, 1e-3), (t_max, 1e-3)], ShapeStyle::from(RGBColor(160, 160, 160)).stroke_width(1)))?;
    for (k, pts) in by_time.iter().enumerate() {
        let c = COLOURS[k % COLOURS.len()];
        chart.draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))?;
        if pts.len() <= 2 {
            chart.draw_series(pts.iter().map(|p| Circle::new(*p, 4, c.filled())))?;
        }
    }

    // Right: against sweeps.
    let mut chart = ChartBuilder::on(&right)
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..s_max, (y_min..2.0).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("iterations (sweeps; progressive: shots / elements)")
        .y_desc("relative residual / unshot power")
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .label_style(("sans-serif", 14))
        .draw()?;
    chart.draw_series(LineSeries::new([(0.0, 1e-3), (s_max, 1e-3)], ShapeStyle::from(RGBColor(160, 160, 160)).stroke_width(1)))?;
    // The legend sits top right of this panel, where the lines have already fallen.
    for (k, (s, pts)) in series.iter().zip(&by_sweep).enumerate() {
        let c = COLOURS[k % COLOURS.len()];
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))?
            .label(&s.label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        if pts.len() <= 2 {
            chart.draw_series(pts.iter().map(|p| Circle::new(*p, 4, c.filled())))?;
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .draw()?;
    root.present()?;
    Ok(())
}
