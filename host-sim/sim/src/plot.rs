//! The plotting kit shared by every figure of the project (runs, diagnosis, the papers'
//! reproductions): a titled figure with the DejaVu Sans font embedded in the binary (so it
//! renders the same on a machine without system fonts), one palette (matplotlib's tab10),
//! panels of polylines, reference lines, event lines and shaded bands, and a brush that
//! draws thick lines without plotters' unbounded mitre spikes.

use std::path::Path;
use std::sync::Once;

use anyhow::Result;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

/// Font family name the embedded DejaVu Sans is registered under.
pub const FONT: &str = "sans-serif";
/// Figure size, pixels.
pub const FIG_W: u32 = 1400;
pub const FIG_H: u32 = 900;

pub type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

pub fn ensure_fonts() {
    static FONTS: Once = Once::new();
    FONTS.call_once(|| {
        // Failure shows up as a drawing error later (FontUnavailable), which is reported.
        let _ = register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
        let _ = register_font(FONT, FontStyle::Bold, dejavu::sans::bold());
    });
}

/// A figure: white canvas with the title; returns the root and the area below the title.
pub fn figure<'a>(path: &'a Path, title: &str) -> Result<(Area<'a>, Area<'a>)> {
    ensure_fonts();
    let root = BitMapBackend::new(path, (FIG_W, FIG_H)).into_drawing_area();
    root.fill(&WHITE)?;
    let body = root.titled(title, (FONT, 22).into_font().style(FontStyle::Bold))?;
    Ok((root, body))
}

/// Offsets, in pixels, at which a line of `width` pixels is drawn as several 1-px lines
/// (plotters draws thick lines with unbounded mitred corners, which turn every sharp turn
/// into a spike). Scale them by the data size of one pixel.
pub fn thick_brush(width: u32) -> &'static [(f64, f64)] {
    match width {
        0 | 1 => &[(0.0, 0.0)],
        2 => &[(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)],
        _ => &[(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)],
    }
}

/// The plots' palette (matplotlib's tab10), shared by every plotting module.
pub const TAB10: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];
pub const EST_COLOR: RGBColor = RGBColor(31, 119, 180);
pub const TRUE_COLOR: RGBColor = RGBColor(20, 20, 20);
pub const EVENT_COLOR: RGBColor = RGBColor(150, 150, 150);

/// One polyline of a panel.
pub struct Line {
    pub pts: Vec<(f64, f64)>,
    pub color: RGBColor,
    pub width: u32,
    pub dashed: bool,
    pub label: Option<String>,
}

impl Line {
    pub fn new(pts: Vec<(f64, f64)>, color: RGBColor, width: u32) -> Self {
        Line {
            pts,
            color,
            width,
            dashed: false,
            label: None,
        }
    }
    pub fn dashed(mut self) -> Self {
        self.dashed = true;
        self
    }
    pub fn label(mut self, l: impl Into<String>) -> Self {
        self.label = Some(l.into());
        self
    }
}

/// A shaded time interval.
pub struct Band {
    pub x0: f64,
    pub x1: f64,
    pub color: RGBAColor,
}

/// Everything one panel shows.
pub struct Panel {
    pub caption: String,
    pub x: (f64, f64),
    pub y: (f64, f64),
    pub x_desc: Option<String>,
    pub y_desc: String,
    pub y_fmt: fn(f64) -> String,
    pub lines: Vec<Line>,
    /// Horizontal reference lines (value, colour, legend label).
    pub hlines: Vec<(f64, RGBColor, String)>,
    /// Event times (dashed vertical lines).
    pub vlines: Vec<f64>,
    pub bands: Vec<Band>,
    /// Legend entries for the bands.
    pub band_labels: Vec<(String, RGBAColor)>,
    pub legend: Option<SeriesLabelPosition>,
}

impl Panel {
    pub fn new(caption: String, x: (f64, f64), y: (f64, f64)) -> Self {
        Panel {
            caption,
            x,
            y,
            x_desc: None,
            y_desc: String::new(),
            y_fmt: fmt_tick,
            lines: Vec::new(),
            hlines: Vec::new(),
            vlines: Vec::new(),
            bands: Vec::new(),
            band_labels: Vec::new(),
            legend: None,
        }
    }
}

/// Axis tick label: compact, enough digits for a zoomed axis.
pub fn fmt_tick(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".into()
    } else if (1e-2..1e5).contains(&a) {
        let s = format!("{v:.5}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_string()
    } else {
        let s = format!("{v:.3e}");
        // 1.200e-5 → 1.2e-5
        match s.split_once('e') {
            Some((m, e)) if m.contains('.') => {
                format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.'))
            }
            _ => s,
        }
    }
}

/// Tick label of a log10 axis: 10^v.
pub fn fmt_log_tick(v: f64) -> String {
    if (v - v.round()).abs() < 1e-9 {
        format!("1e{}", v.round() as i64)
    } else {
        String::new()
    }
}

/// Splits a polyline at non-finite points and clamps y into the panel's range.
pub fn segments(pts: &[(f64, f64)], y: (f64, f64)) -> Vec<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    let mut cur = Vec::new();
    for &(t, v) in pts {
        if t.is_finite() && v.is_finite() {
            cur.push((t, v.clamp(y.0, y.1)));
        } else if !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

pub fn draw_panel(area: &Area<'_>, p: &Panel) -> Result<()> {
    let (x0, x1) = p.x;
    let (y0, y1) = p.y;
    let mut chart = ChartBuilder::on(area)
        .caption(&p.caption, (FONT, 15))
        .margin(5)
        .margin_right(16)
        .x_label_area_size(if p.x_desc.is_some() { 38 } else { 22 })
        .y_label_area_size(if p.y_desc.is_empty() { 70 } else { 88 })
        .build_cartesian_2d(x0..x1, y0..y1)?;
    let y_fmt = p.y_fmt;
    let tiny = 1e-6 * (y1 - y0).abs();
    // Tick values that are 0 up to rounding print as 0 (not 1.7e-18).
    let y_formatter = move |v: &f64| y_fmt(if v.abs() < tiny { 0.0 } else { *v });
    let mut mesh = chart.configure_mesh();
    mesh.bold_line_style(RGBColor(215, 215, 215))
        .light_line_style(RGBColor(240, 240, 240))
        .x_labels(10)
        .y_labels(6)
        .y_label_formatter(&y_formatter)
        .label_style((FONT, 12))
        .axis_desc_style((FONT, 13));
    if let Some(d) = &p.x_desc {
        mesh.x_desc(d.as_str());
    }
    if !p.y_desc.is_empty() {
        mesh.y_desc(p.y_desc.as_str());
    }
    mesh.draw()?;

    for b in &p.bands {
        chart.draw_series(std::iter::once(Rectangle::new(
            [(b.x0.max(x0), y0), (b.x1.min(x1), y1)],
            b.color.filled(),
        )))?;
    }
    for (label, color) in &p.band_labels {
        let c = *color;
        chart
            .draw_series(std::iter::empty::<Rectangle<(f64, f64)>>())?
            .label(label.as_str())
            .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 18, y + 6)], c.filled()));
    }
    for &t in &p.vlines {
        if t >= x0 && t <= x1 {
            chart.draw_series(DashedLineSeries::new(
                vec![(t, y0), (t, y1)],
                5,
                4,
                EVENT_COLOR.stroke_width(1),
            ))?;
        }
    }
    for (v, color, label) in &p.hlines {
        if *v < y0 || *v > y1 {
            continue;
        }
        let style = color.stroke_width(2);
        chart
            .draw_series(DashedLineSeries::new(
                vec![(x0, *v), (x1, *v)],
                10,
                6,
                style,
            ))?
            .label(label.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], style));
    }
    // Thick lines: plotters joins thick polylines with unbounded miters, which makes long
    // spikes at sharp zig-zags (jump transients). Draw them instead as 1-px polylines with a
    // brush of one-pixel offsets.
    let (pw, ph) = chart.plotting_area().dim_in_pixel();
    let dx = (x1 - x0) / f64::from(pw.max(1));
    let dy = (y1 - y0) / f64::from(ph.max(1));
    for line in &p.lines {
        let thin = line.color.stroke_width(1);
        let legend_style = line.color.stroke_width(line.width.max(1));
        let brush = thick_brush(line.width);
        let mut labelled = false;
        for &(ox, oy) in brush {
            let shifted: Vec<(f64, f64)> = line
                .pts
                .iter()
                .map(|&(t, v)| (t + ox * dx, v + oy * dy))
                .collect();
            for seg in segments(&shifted, p.y) {
                let anno = if line.dashed {
                    chart.draw_series(DashedLineSeries::new(seg, 8, 5, thin))?
                } else {
                    chart.draw_series(LineSeries::new(seg, thin))?
                };
                if !labelled && let Some(label) = &line.label {
                    labelled = true;
                    anno.label(label.as_str()).legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], legend_style)
                    });
                }
            }
        }
    }
    if let Some(pos) = &p.legend {
        chart
            .configure_series_labels()
            .position(pos.clone())
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .label_font((FONT, 13))
            .draw()?;
    }
    Ok(())
}


/// Finite values' (min, max).
pub fn min_max(v: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = v
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(x), hi.max(x))
        });
    (lo <= hi).then_some((lo, hi))
}
