//! The plotting kit shared by every figure of the project (runs, diagnosis, the papers'
//! reproductions): a titled figure with the DejaVu Sans font embedded in the binary (so it
//! renders the same on a machine without system fonts), one palette (matplotlib's tab10),
//! panels of polylines, reference lines, event lines and shaded bands, and a brush that
//! draws thick lines without plotters' unbounded mitre spikes.

use std::path::Path;
use std::sync::Once;

use anyhow::Result;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
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
    figure_sized(path, (FIG_W, FIG_H), title)
}

/// As [`figure`] with a canvas of `size` pixels (for grids of many panels).
pub fn figure_sized<'a>(
    path: &'a Path,
    size: (u32, u32),
    title: &str,
) -> Result<(Area<'a>, Area<'a>)> {
    ensure_fonts();
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE)?;
    let body = root.titled(title, (FONT, 22).into_font().style(FontStyle::Bold))?;
    Ok((root, body))
}

/// `rows × cols` panels of `body`, row by row.
pub fn grid<'a>(body: &Area<'a>, rows: usize, cols: usize) -> Vec<Area<'a>> {
    body.split_evenly((rows, cols))
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

/// Shape of a [`Marker`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MarkerKind {
    /// Filled triangle pointing up.
    TriUp,
    /// Light triangle with a dark outline pointing down.
    TriDown,
    /// Filled circle.
    Circle,
}

/// A scatter point.
pub struct Marker {
    pub x: f64,
    pub y: f64,
    pub kind: MarkerKind,
    pub color: RGBColor,
    /// Half-size in pixels.
    pub size: f64,
    pub label: Option<String>,
}

/// A vertical arrow at `x` from `y0` to `y1` (a jump).
pub struct Arrow {
    pub x: f64,
    pub y0: f64,
    pub y1: f64,
    pub color: RGBColor,
}

/// What happens to the points of a line outside the panel's range.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Clip {
    /// y clamped into the range (a time series that leaves the axis runs along its edge).
    #[default]
    ClampY,
    /// Points outside the x or y range dropped, the line split there (curves in a window).
    Drop,
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
    /// Labelled vertical lines (dashed, dark; the label at the top).
    pub marked_x: Vec<(f64, String)>,
    pub markers: Vec<Marker>,
    pub arrows: Vec<Arrow>,
    /// Points outside the range: clamped (default) or dropped.
    pub clip: Clip,
    pub legend: Option<SeriesLabelPosition>,
    /// Legend text size, pixels (smaller for a long legend in a small panel).
    pub legend_font_px: u32,
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
            marked_x: Vec::new(),
            markers: Vec::new(),
            arrows: Vec::new(),
            clip: Clip::ClampY,
            legend: None,
            legend_font_px: 13,
        }
    }

    /// A log10 y axis: the data are given as log10 values, the ticks read 1eN.
    pub fn log_y(mut self) -> Self {
        self.y_fmt = fmt_log_tick;
        self
    }
}

/// log10 of a positive value, NaN (a gap in the line) otherwise.
pub fn log10_or_gap(v: f64) -> f64 {
    if v > 0.0 { v.log10() } else { f64::NAN }
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

/// Splits a polyline where it leaves the panel (non-finite or outside either range);
/// the points outside are dropped.
pub fn segments_inside(pts: &[(f64, f64)], x: (f64, f64), y: (f64, f64)) -> Vec<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    let mut cur = Vec::new();
    for &(a, b) in pts {
        let inside =
            a.is_finite() && b.is_finite() && (x.0..=x.1).contains(&a) && (y.0..=y.1).contains(&b);
        if inside {
            cur.push((a, b));
        } else if !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// Splits a sequence into maximal runs of equal `key`, each run extended by the first
/// point of the next one so that consecutive runs join (e.g. a branch drawn solid where
/// stable and dashed where not).
pub fn split_runs<T: Copy>(pts: &[T], key: impl Fn(&T) -> bool) -> Vec<(bool, Vec<T>)> {
    let mut out: Vec<(bool, Vec<T>)> = Vec::new();
    for p in pts {
        let k = key(p);
        match out.last_mut() {
            Some((kk, seg)) if *kk == k => seg.push(*p),
            Some((_, seg)) => {
                seg.push(*p);
                out.push((k, vec![*p]));
            }
            None => out.push((k, vec![*p])),
        }
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
    // the data size of one pixel (thick lines, marker and label offsets)
    let (pw, ph) = chart.plotting_area().dim_in_pixel();
    let dx = (x1 - x0) / f64::from(pw.max(1));
    let dy = (y1 - y0) / f64::from(ph.max(1));
    draw_marked_x(&mut chart, p, (dx, dy))?;
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
            let segs = match p.clip {
                Clip::ClampY => segments(&shifted, p.y),
                Clip::Drop => segments_inside(&shifted, p.x, p.y),
            };
            for seg in segs {
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
    draw_arrows(&mut chart, p, (dx, dy))?;
    draw_markers(&mut chart, p, (dx, dy))?;
    if let Some(pos) = &p.legend {
        chart
            .configure_series_labels()
            .position(pos.clone())
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .label_font((FONT, p.legend_font_px))
            .draw()?;
    }
    Ok(())
}

type Chart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A triangle of half-size `s` pixels around (x, y), pointing up or down; `px` is the data
/// size of one pixel.
fn triangle(x: f64, y: f64, up: bool, s: f64, px: (f64, f64)) -> Vec<(f64, f64)> {
    let (dx, dy) = px;
    let sg = if up { 1.0 } else { -1.0 };
    vec![
        (x - s * dx, y - sg * 0.8 * s * dy),
        (x + s * dx, y - sg * 0.8 * s * dy),
        (x, y + sg * s * dy),
    ]
}

fn draw_marked_x(chart: &mut Chart<'_, '_>, p: &Panel, px: (f64, f64)) -> Result<()> {
    let ((x0, x1), (y0, y1)) = (p.x, p.y);
    for (k, (xv, label)) in p.marked_x.iter().enumerate() {
        if *xv < x0 || *xv > x1 {
            continue;
        }
        let st = RGBColor(60, 60, 60).stroke_width(1);
        chart.draw_series(DashedLineSeries::new(vec![(*xv, y0), (*xv, y1)], 6, 4, st))?;
        if !label.is_empty() {
            chart.draw_series(std::iter::once(Text::new(
                label.clone(),
                (*xv + 4.0 * px.0, y1 - (6.0 + 18.0 * k as f64) * px.1),
                (FONT, 13).into_font(),
            )))?;
        }
    }
    Ok(())
}

fn draw_arrows(chart: &mut Chart<'_, '_>, p: &Panel, px: (f64, f64)) -> Result<()> {
    let ((x0, x1), (y0, y1)) = (p.x, p.y);
    let dy = px.1;
    for a in &p.arrows {
        if a.x < x0 || a.x > x1 {
            continue;
        }
        let (ya, yb) = (a.y0.clamp(y0, y1), a.y1.clamp(y0, y1));
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(a.x, ya), (a.x, yb)],
            a.color.stroke_width(2),
        )))?;
        let up = yb > ya;
        let head = triangle(a.x, yb - if up { 7.0 } else { -7.0 } * dy, up, 7.0, px);
        chart.draw_series(std::iter::once(Polygon::new(head, a.color.filled())))?;
    }
    Ok(())
}

fn draw_markers(chart: &mut Chart<'_, '_>, p: &Panel, px: (f64, f64)) -> Result<()> {
    let ((x0, x1), (y0, y1)) = (p.x, p.y);
    for m in &p.markers {
        if m.x < x0 || m.x > x1 || m.y < y0 || m.y > y1 {
            continue;
        }
        let (col, s, kind) = (m.color, m.size, m.kind);
        let shape = match kind {
            MarkerKind::TriUp => triangle(m.x, m.y, true, s, px),
            MarkerKind::TriDown => triangle(m.x, m.y, false, s, px),
            MarkerKind::Circle => (0..16)
                .map(|k| {
                    let a = std::f64::consts::TAU * f64::from(k) / 16.0;
                    (m.x + s * px.0 * a.cos(), m.y + s * px.1 * a.sin())
                })
                .collect(),
        };
        let fill = if kind == MarkerKind::TriDown {
            col.mix(0.35).filled()
        } else {
            col.filled()
        };
        if kind == MarkerKind::TriDown {
            let mut outline = shape.clone();
            outline.push(shape[0]);
            chart.draw_series(std::iter::once(PathElement::new(
                outline,
                col.stroke_width(1),
            )))?;
        }
        let anno = chart.draw_series(std::iter::once(Polygon::new(shape, fill)))?;
        if let Some(l) = &m.label {
            anno.label(l.as_str())
                .legend(move |(x, y)| Polygon::new(legend_marker(kind, x, y), col.filled()));
        }
    }
    Ok(())
}

/// The marker's shape in a legend entry at (x, y), pixels.
fn legend_marker(kind: MarkerKind, x: i32, y: i32) -> Vec<(i32, i32)> {
    match kind {
        MarkerKind::TriUp => vec![(x + 3, y + 5), (x + 15, y + 5), (x + 9, y - 6)],
        MarkerKind::TriDown => vec![(x + 3, y - 5), (x + 15, y - 5), (x + 9, y + 6)],
        MarkerKind::Circle => (0..12)
            .map(|k| {
                let a = std::f64::consts::TAU * f64::from(k) / 12.0;
                (
                    x + 9 + (5.0 * a.cos()).round() as i32,
                    y + (5.0 * a.sin()).round() as i32,
                )
            })
            .collect(),
    }
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
