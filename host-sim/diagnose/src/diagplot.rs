//! Plots of the sim-to-real diagnosis: where the gap lies (axis × channel), the candidate
//! ranking, the gap over time, and recorded versus re-simulated envelopes.

use std::path::{Path, PathBuf};

use anyhow::Result;
use plotters::prelude::*;

use crate::diagnose::Diagnosis;
use paragyro_simulator::plot::{Area, Band, Line, Panel, TAB10, draw_panel, figure, min_max};

/// Writes where.png, ranking.png, time.png and (after a re-simulation) envelopes.png.
pub fn plots(dir: &Path, d: &Diagnosis) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    let p = dir.join("where.png");
    let shares: Vec<(String, f64, RGBColor)> = d
        .plots
        .shares
        .iter()
        .map(|(l, v)| {
            (
                l.clone(),
                *v,
                if l.starts_with("drive") {
                    TAB10[3]
                } else {
                    TAB10[0]
                },
            )
        })
        .collect();
    bars(
        &p,
        "where the gap lies: share of the explainable gap energy",
        "share of the gap",
        &shares,
    )?;
    out.push(p);
    let p = dir.join("ranking.png");
    let rank: Vec<(String, f64, RGBColor)> = d
        .plots
        .ranking
        .iter()
        .map(|(e, gc, sig)| {
            (
                e.to_string(),
                gc.max(-0.2),
                if *sig { TAB10[2] } else { TAB10[7] },
            )
        })
        .collect();
    bars(
        &p,
        &format!(
            "which effect: held-out gap closure (green: significant) — verdict {}",
            d.report.verdict
        ),
        "gap closure (held-out)",
        &rank,
    )?;
    out.push(p);
    let p = dir.join("time.png");
    time_plot(&p, d)?;
    out.push(p);
    if !d.plots.envelopes.is_empty() {
        let p = dir.join("envelopes.png");
        envelope_plot(&p, d)?;
        out.push(p);
    }
    Ok(out)
}

/// A horizontal bar chart.
fn bars(path: &Path, title: &str, x_desc: &str, items: &[(String, f64, RGBColor)]) -> Result<()> {
    let (_root, body) = figure(path, title)?;
    let n = items.len().max(1);
    let hi = items.iter().map(|i| i.1).fold(0.0f64, f64::max).max(0.05) * 1.1;
    let lo = items.iter().map(|i| i.1).fold(0.0f64, f64::min);
    let labels: Vec<String> = items.iter().map(|i| i.0.clone()).collect();
    let mut chart = ChartBuilder::on(&body)
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(260)
        .build_cartesian_2d(lo..hi, -0.5f64..(n as f64 - 0.5))?;
    chart
        .configure_mesh()
        .disable_y_mesh()
        .y_labels(n)
        .y_label_formatter(&|v| {
            let i = v.round();
            if (v - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < labels.len() {
                labels[labels.len() - 1 - i as usize].clone()
            } else {
                String::new()
            }
        })
        .x_desc(x_desc)
        .label_style(("sans-serif", 18))
        .axis_desc_style(("sans-serif", 18))
        .draw()?;
    for (i, (_, v, c)) in items.iter().enumerate() {
        let y = (n - 1 - i) as f64;
        chart.draw_series(std::iter::once(Rectangle::new(
            [(0.0, y - 0.35), (*v, y + 0.35)],
            c.filled(),
        )))?;
    }
    Ok(())
}

fn time_plot(path: &Path, d: &Diagnosis) -> Result<()> {
    let (_root, body) = figure(
        path,
        "when: the gap over time (0.5 s windows) and its CUSUM",
    )?;
    let (top, bottom) = body.split_vertically(body.dim_in_pixel().1 / 2);
    let pd = &d.plots;
    let x = (
        pd.t.first().copied().unwrap_or(0.0),
        pd.t.last().copied().unwrap_or(1.0),
    );
    let spans = |p: &mut Panel| {
        p.bands.push(Band {
            x0: pd.fit_span.0,
            x1: pd.fit_span.1,
            color: TAB10[2].mix(0.12),
        });
        p.bands.push(Band {
            x0: pd.hold_span.0,
            x1: pd.hold_span.1,
            color: TAB10[1].mix(0.15),
        });
        p.band_labels.push(("fit span".into(), TAB10[2].mix(0.12)));
        p.band_labels
            .push(("held-out span".into(), TAB10[1].mix(0.15)));
    };
    let (lo, hi) = min_max(pd.windows.iter().map(|w| w.1)).unwrap_or((0.0, 1.0));
    let mut p = Panel::new(
        "gap energy per sample (baseline − floor, weighted rows)".into(),
        x,
        pad(lo.min(0.0), hi),
    );
    p.y_desc = "gap energy".into();
    spans(&mut p);
    p.lines
        .push(Line::new(pd.windows.clone(), TAB10[3], 2).label("windowed gap"));
    p.legend = Some(SeriesLabelPosition::UpperLeft);
    draw_panel(&top, &p)?;
    let (lo, hi) = min_max(pd.cusum.iter().map(|w| w.1)).unwrap_or((0.0, 1.0));
    let mut p = Panel::new(
        "CUSUM of the windowed gap about its mean".into(),
        x,
        pad(lo, hi),
    );
    p.y_desc = "CUSUM".into();
    p.x_desc = Some("time (s)".into());
    spans(&mut p);
    p.lines
        .push(Line::new(pd.cusum.clone(), TAB10[4], 2).label("CUSUM"));
    p.legend = Some(SeriesLabelPosition::UpperLeft);
    draw_panel(&bottom, &p)?;
    Ok(())
}

fn pad(lo: f64, hi: f64) -> (f64, f64) {
    let s = (hi - lo).abs().max(1e-12);
    (lo - 0.05 * s, hi + 0.05 * s)
}

fn envelope_plot(path: &Path, d: &Diagnosis) -> Result<()> {
    let (_root, body) = figure(
        path,
        "how far: recorded versus re-simulated envelopes on the held-out span, before / after adding the effect",
    )?;
    let (left, right) = body.split_horizontally(body.dim_in_pixel().0 / 2);
    let (lt, lb) = left.split_vertically(left.dim_in_pixel().1 / 2);
    let (rt, rb) = right.split_vertically(right.dim_in_pixel().1 / 2);
    let e = &d.plots.envelopes;
    let x = (
        e.first().map_or(0.0, |v| v[0]),
        e.last().map_or(1.0, |v| v[0]),
    );
    let s = |i: usize| e.iter().map(|v| (v[0], v[i])).collect::<Vec<_>>();
    let env = |area: &Area<'_>,
               cap: &str,
               i_rec: usize,
               i_b: usize,
               i_a: usize,
               last: bool|
     -> Result<()> {
        let (lo, hi) =
            min_max(e.iter().flat_map(|v| [v[i_rec], v[i_b], v[i_a]])).unwrap_or((0.0, 1.0));
        let mut p = Panel::new(cap.into(), x, pad(lo, hi));
        p.y_desc = "amplitude (µm)".into();
        if last {
            p.x_desc = Some("time (s)".into());
        }
        p.lines
            .push(Line::new(s(i_rec), RGBColor(20, 20, 20), 2).label("record"));
        p.lines.push(
            Line::new(s(i_b), TAB10[3], 1)
                .dashed()
                .label("simulator (model)"),
        );
        p.lines
            .push(Line::new(s(i_a), TAB10[2], 1).label("simulator + effect"));
        p.legend = Some(SeriesLabelPosition::LowerRight);
        draw_panel(area, &p)
    };
    let err = |area: &Area<'_>, cap: &str, i_b: usize, i_a: usize, last: bool| -> Result<()> {
        let (_, hi) = min_max(e.iter().flat_map(|v| [v[i_b], v[i_a]])).unwrap_or((0.0, 1.0));
        let mut p = Panel::new(cap.into(), x, (0.0, hi.max(1e-12) * 1.05));
        p.y_desc = "|record − simulator| (µm)".into();
        if last {
            p.x_desc = Some("time (s)".into());
        }
        p.lines.push(Line::new(s(i_b), TAB10[3], 1).label("model"));
        p.lines
            .push(Line::new(s(i_a), TAB10[2], 1).label("model + effect"));
        p.legend = Some(SeriesLabelPosition::UpperRight);
        draw_panel(area, &p)
    };
    env(&lt, "drive |x1|", 1, 3, 5, false)?;
    env(&lb, "sense |y1|", 2, 4, 6, true)?;
    err(&rt, "drive: error of the simulated x1", 7, 9, false)?;
    err(&rb, "sense: error of the simulated y1", 8, 10, true)?;
    Ok(())
}
