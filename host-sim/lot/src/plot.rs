//! The lot report's plots: a parameter's deviations over the lot as a histogram against
//! its tolerance band (the simulator's figure, fonts and palette, as the diagnosis's plots).

use std::path::Path;

use anyhow::Result;
use paragyro_simulator::plot::{FONT, TAB10, figure, min_max};
use plotters::prelude::*;

/// What one histogram shows.
pub(crate) struct Hist<'a> {
    pub title: &'a str,
    pub x_desc: &'a str,
    /// The values, already in the axis's unit.
    pub values: &'a [f64],
    /// The band's limits in the same unit.
    pub lo: Option<f64>,
    pub hi: Option<f64>,
}

const BINS: usize = 30;

/// The histogram's x range: the values and the limits, 5 % wider each side.
fn x_range(h: &Hist<'_>) -> (f64, f64) {
    let all = h.values.iter().copied().chain(h.lo).chain(h.hi);
    let (lo, hi) = min_max(all).unwrap_or((-1.0, 1.0));
    let w = hi - lo;
    let pad = if w > 0.0 {
        0.05 * w
    } else {
        (0.05 * lo.abs()).max(1e-12)
    };
    (lo - pad, hi + pad)
}

/// Writes the histogram to `path`: bins inside the limits blue, outside red, the band
/// shaded green, the limits as red lines.
pub(crate) fn histogram(path: &Path, h: &Hist<'_>) -> Result<()> {
    let (_root, body) = figure(path, h.title)?;
    let (x0, x1) = x_range(h);
    let width = (x1 - x0) / BINS as f64;
    let mut counts = [0usize; BINS];
    for &v in h.values.iter().filter(|v| v.is_finite()) {
        let i = (((v - x0) / width).floor().max(0.0) as usize).min(BINS - 1);
        counts[i] += 1;
    }
    let top = counts.iter().copied().max().unwrap_or(0).max(1) as f64 * 1.15;
    let mut chart = ChartBuilder::on(&body)
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, 0.0..top)?;
    chart
        .configure_mesh()
        .x_desc(h.x_desc)
        .y_desc("devices")
        .x_label_formatter(&|v| {
            if v.abs() < 1e-9 * (x1 - x0) {
                "0".into()
            } else if x1 - x0 < 1e-2 {
                format!("{v:.2e}")
            } else {
                format!("{v:.3}")
            }
        })
        // device counts: whole numbers only
        .y_label_formatter(&|v| {
            if (v - v.round()).abs() < 1e-6 {
                format!("{v:.0}")
            } else {
                String::new()
            }
        })
        .label_style((FONT, 18))
        .axis_desc_style((FONT, 18))
        .draw()?;
    let band = (h.lo.unwrap_or(x0).max(x0), h.hi.unwrap_or(x1).min(x1));
    if h.lo.is_some() || h.hi.is_some() {
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(band.0, 0.0), (band.1, top)],
                TAB10[2].mix(0.15).filled(),
            )))?
            .label("tolerance band")
            .legend(|(x, y)| {
                Rectangle::new([(x, y - 6), (x + 16, y + 6)], TAB10[2].mix(0.3).filled())
            });
    }
    for (i, &c) in counts.iter().enumerate().filter(|(_, c)| **c > 0) {
        let a = x0 + i as f64 * width;
        let b = a + width;
        let inside = h.lo.is_none_or(|lo| a >= lo) && h.hi.is_none_or(|hi| b <= hi);
        let color = if inside { TAB10[0] } else { TAB10[3] };
        chart.draw_series(std::iter::once(Rectangle::new(
            [(a + 0.05 * width, 0.0), (b - 0.05 * width, c as f64)],
            color.filled(),
        )))?;
    }
    for lim in [h.lo, h.hi].into_iter().flatten() {
        chart.draw_series(LineSeries::new(
            [(lim, 0.0), (lim, top)],
            TAB10[3].stroke_width(2),
        ))?;
    }
    if h.lo.is_some() || h.hi.is_some() {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font((FONT, 18))
            .position(SeriesLabelPosition::UpperRight)
            .draw()?;
    }
    Ok(())
}
