//! The five figures of a run (see the table in the module documentation of
//! [`crate::report`]).

use std::path::Path;

use anyhow::Result;
use plotters::prelude::*;

use super::{
    PHYS_PRETTY, THETA_DRIVE_MEANING, THETA_SENSE_MEANING, fmt_rel, health_bit, settle_time,
    time_range, twin_label,
};
use crate::plot::*;
use crate::trace::{RunResult, THETA_DRIVE_NAMES, THETA_SENSE_NAMES, TraceRow};

/// Smallest half-height of an estimate-vs-truth panel, relative to |truth|.
const ZOOM_FLOOR: f64 = 0.02;

/// Event times for the vertical lines: deduplicated (closer than 1 % of the run), at most 60.
fn event_times(result: &RunResult) -> Vec<f64> {
    let (t0, t1) = time_range(result);
    let tol = (t1 - t0) * 1e-2;
    let mut ts: Vec<f64> = result
        .events
        .iter()
        .map(|e| e.t_s)
        .filter(|t| t.is_finite())
        .collect();
    ts.sort_by(f64::total_cmp);
    let mut out: Vec<f64> = Vec::new();
    for t in ts {
        if out.last().is_none_or(|&l| t - l > tol) {
            out.push(t);
        }
        if out.len() == 60 {
            break;
        }
    }
    out
}

/// The p-quantile (0..=1) of finite values.
fn quantile(mut v: Vec<f64>, p: f64) -> Option<f64> {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let i = ((v.len() - 1) as f64 * p).round() as usize;
    Some(v[i.min(v.len() - 1)])
}

/// y range of an estimate-vs-truth panel: the truth ± max(`floor`·|truth|, 3 × the 75th
/// percentile of |estimate − truth| after `t_settle`), capped at 10·|truth|. Start-up spikes
/// and re-identification transients are clipped at the panel edges rather than flattening the
/// plot, and a small drift of the truth (e.g. ωy² 1.0265 → 1.03) stays visible.
pub(super) fn zoom_range(
    t: &[f64],
    truth: &[f64],
    est: &[f64],
    t_settle: f64,
    floor: f64,
) -> (f64, f64) {
    let Some((tlo, thi)) = min_max(truth.iter().copied()) else {
        return min_max(est.iter().copied())
            .map(|(a, b)| pad(a, b))
            .unwrap_or((-1.0, 1.0));
    };
    let tabs = tlo.abs().max(thi.abs());
    let dev: Vec<f64> = t
        .iter()
        .zip(truth.iter().zip(est))
        .filter(|(t, _)| **t >= t_settle)
        .map(|(_, (tr, e))| (e - tr).abs())
        .collect();
    let spread = 3.0 * quantile(dev, 0.75).unwrap_or(0.0);
    let mut margin = (floor * tabs).max(spread);
    if tabs > 0.0 {
        margin = margin.min(10.0 * tabs);
    }
    if margin.is_nan() || margin <= 0.0 {
        margin = if tabs > 0.0 {
            floor.max(1e-3) * tabs
        } else {
            1e-12
        };
    }
    (tlo - margin, thi + margin)
}

/// A small padding around [a, b].
fn pad(a: f64, b: f64) -> (f64, f64) {
    let span = b - a;
    let m = if span > 0.0 {
        0.05 * span
    } else {
        0.05 * a.abs().max(1e-12)
    };
    (a - m, b + m)
}

fn figure_title(result: &RunResult, what: &str) -> String {
    format!("{} ({}): {what}", result.scenario, result.precision)
}

/// Estimate-vs-truth panel for one quantity.
#[allow(clippy::too_many_arguments)]
fn est_truth_panel(
    result: &RunResult,
    caption: &str,
    truth: impl Fn(&TraceRow) -> f64,
    est: impl Fn(&TraceRow) -> f64,
    floor: f64,
    x_desc: bool,
    legend: bool,
    vlines: &[f64],
) -> Panel {
    let tr = &result.trace;
    let t: Vec<f64> = tr.iter().map(|r| r.t_s).collect();
    let tv: Vec<f64> = tr.iter().map(&truth).collect();
    let ev: Vec<f64> = tr.iter().map(&est).collect();
    let y = zoom_range(&t, &tv, &ev, settle_time(tr), floor);
    let final_err = tr
        .last()
        .map(|r| fmt_rel(truth(r), est(r)))
        .unwrap_or_else(|| "n/a".into());
    let mut p = Panel::new(
        format!("{caption}    final error {final_err}"),
        time_range(result),
        y,
    );
    if x_desc {
        p.x_desc = Some("time (s)".into());
    }
    p.vlines = vlines.to_vec();
    p.lines.push(
        Line::new(t.iter().copied().zip(tv).collect(), TRUE_COLOR, 2)
            .dashed()
            .label("true"),
    );
    p.lines
        .push(Line::new(t.into_iter().zip(ev).collect(), EST_COLOR, 1).label("estimate"));
    if legend {
        p.legend = Some(SeriesLabelPosition::UpperRight);
    }
    p
}

pub(super) fn plot_theta_drive(path: &Path, result: &RunResult) -> Result<()> {
    let (root, body) = figure(
        path,
        &figure_title(result, "drive parameters θ1 (eq. 25 order)"),
    )?;
    let vlines = event_times(result);
    for (i, area) in body.split_evenly((4, 2)).iter().enumerate() {
        let p = est_truth_panel(
            result,
            &format!("θ1{} = {}", i + 1, THETA_DRIVE_MEANING[i]),
            |r| r.theta_drive_true[i],
            |r| r.theta_drive_est[i],
            ZOOM_FLOOR,
            i >= 6,
            i == 0,
            &vlines,
        );
        draw_panel(area, &p)?;
    }
    root.present()?;
    Ok(())
}

pub(super) fn plot_theta_sense(path: &Path, result: &RunResult) -> Result<()> {
    let (root, body) = figure(
        path,
        &figure_title(result, "sense parameters θ2 (eq. 25 order)"),
    )?;
    let vlines = event_times(result);
    for (i, area) in body.split_evenly((3, 2)).iter().enumerate() {
        let p = est_truth_panel(
            result,
            &format!("θ2{} = {}", i + 1, THETA_SENSE_MEANING[i]),
            |r| r.theta_sense_true[i],
            |r| r.theta_sense_est[i],
            ZOOM_FLOOR,
            i >= 4,
            i == 0,
            &vlines,
        );
        draw_panel(area, &p)?;
    }
    root.present()?;
    Ok(())
}

/// log10 of |est − true|/|true| (NaN where undefined), floored at 1e-12.
fn log_rel_err(est: f64, truth: f64) -> f64 {
    if truth == 0.0 || !truth.is_finite() || !est.is_finite() {
        f64::NAN
    } else {
        (((est - truth) / truth).abs().max(1e-12)).log10()
    }
}

pub(super) fn plot_rel_error(path: &Path, result: &RunResult) -> Result<()> {
    let (root, body) = figure(
        path,
        &figure_title(
            result,
            "relative error |estimate − true| / |true| of the 14 parameters",
        ),
    )?;
    let vlines = event_times(result);
    let x = time_range(result);
    let (top, bottom) = body.split_vertically(body.dim_in_pixel().1 / 2);
    let levels = [
        (-3.0, RGBColor(0, 150, 0), "0.1 %"),
        (-2.0, RGBColor(230, 140, 0), "1 %"),
        (-1.0, RGBColor(200, 0, 0), "10 %"),
    ];
    let tr = &result.trace;
    for (area, drive) in [(top, true), (bottom, false)] {
        let n = if drive { 8 } else { 6 };
        let mut p = Panel::new(
            if drive {
                "drive θ11…θ18".into()
            } else {
                "sense θ21…θ26".into()
            },
            x,
            (-7.0, 1.0),
        );
        p.y_fmt = fmt_log_tick;
        p.y_desc = "relative error".into();
        if !drive {
            p.x_desc = Some("time (s)".into());
        }
        p.vlines = vlines.clone();
        p.hlines = levels
            .iter()
            .map(|(v, c, l)| (*v, *c, l.to_string()))
            .collect();
        for i in 0..n {
            let (name, pts): (&str, Vec<(f64, f64)>) = if drive {
                (
                    THETA_DRIVE_NAMES[i],
                    tr.iter()
                        .map(|r| {
                            (
                                r.t_s,
                                log_rel_err(r.theta_drive_est[i], r.theta_drive_true[i]),
                            )
                        })
                        .collect(),
                )
            } else {
                (
                    THETA_SENSE_NAMES[i],
                    tr.iter()
                        .map(|r| {
                            (
                                r.t_s,
                                log_rel_err(r.theta_sense_est[i], r.theta_sense_true[i]),
                            )
                        })
                        .collect(),
                )
            };
            let name = name.replace("th", "θ");
            p.lines.push(Line::new(pts, TAB10[i], 1).label(name));
        }
        p.legend = Some(SeriesLabelPosition::UpperRight);
        draw_panel(&area, &p)?;
    }
    root.present()?;
    Ok(())
}

pub(super) fn plot_physical(path: &Path, result: &RunResult) -> Result<()> {
    let (root, body) = figure(
        path,
        &figure_title(result, "physical parameters (corrected Table 3) and rate"),
    )?;
    let vlines = event_times(result);
    let (grid, rate_area) = body.split_vertically(body.dim_in_pixel().1 * 3 / 4);
    for (i, area) in grid.split_evenly((3, 4)).iter().enumerate() {
        let p = est_truth_panel(
            result,
            PHYS_PRETTY[i],
            |r| r.phys_true[i],
            |r| r.phys_est[i],
            ZOOM_FLOOR,
            false,
            i == 0,
            &vlines,
        );
        draw_panel(area, &p)?;
    }
    let mut p = est_truth_panel(
        result,
        "angular rate Ωz (°/s): true vs from the estimated γ = (θ14 − θ24)/4",
        |r| r.rate_dps_true,
        |r| r.rate_dps_est,
        0.01,
        true,
        true,
        &vlines,
    );
    p.y_desc = "°/s".into();
    draw_panel(&rate_area, &p)?;
    root.present()?;
    Ok(())
}

/// Contiguous periods where a health bit is set, as shaded bands (at least `min_w` wide).
pub(super) fn health_bands(
    trace: &[TraceRow],
    name: &str,
    color: RGBAColor,
    min_w: f64,
) -> Vec<Band> {
    let Some(bit) = health_bit(name) else {
        return Vec::new();
    };
    let half = trace
        .windows(2)
        .next()
        .map_or(0.0, |w| 0.5 * (w[1].t_s - w[0].t_s).abs());
    let mut out: Vec<Band> = Vec::new();
    let mut start: Option<f64> = None;
    let mut last = 0.0;
    for r in trace {
        let on = r.health >> bit & 1 == 1;
        match (on, start) {
            (true, None) => start = Some(r.t_s),
            (false, Some(s)) => {
                out.push(band(s - half, last + half, min_w, color));
                start = None;
            }
            _ => {}
        }
        last = r.t_s;
    }
    if let Some(s) = start {
        out.push(band(s - half, last + half, min_w, color));
    }
    out
}

fn band(x0: f64, x1: f64, min_w: f64, color: RGBAColor) -> Band {
    let w = x1 - x0;
    if w < min_w {
        let c = 0.5 * (x0 + x1);
        Band {
            x0: c - 0.5 * min_w,
            x1: c + 0.5 * min_w,
            color,
        }
    } else {
        Band { x0, x1, color }
    }
}

pub(super) fn plot_amplitudes_pump(path: &Path, result: &RunResult) -> Result<()> {
    let (root, body) = figure(path, &figure_title(result, "amplitudes and pump"))?;
    let vlines = event_times(result);
    let x = time_range(result);
    let (top, bottom) = body.split_vertically(body.dim_in_pixel().1 / 2);
    let tr = &result.trace;
    let twin = result.twin.as_deref().unwrap_or(&[]);
    let label = twin_label(result);

    // Amplitudes.
    let amp_max = min_max(
        tr.iter()
            .chain(twin)
            .flat_map(|r| [r.sense_amp_um, r.drive_amp_um]),
    )
    .map_or(1.0, |(_, hi)| hi);
    let mut p = Panel::new(
        "fundamental amplitudes from the lock-in".into(),
        x,
        (0.0, if amp_max > 0.0 { amp_max * 1.08 } else { 1.0 }),
    );
    p.y_desc = "amplitude (µm)".into();
    p.vlines = vlines.clone();
    let series = |rows: &[TraceRow], f: fn(&TraceRow) -> f64| -> Vec<(f64, f64)> {
        rows.iter().map(|r| (r.t_s, f(r))).collect()
    };
    p.lines.push(
        Line::new(series(tr, |r| r.sense_amp_um), RGBColor(31, 119, 180), 2).label("sense |B1|"),
    );
    p.lines.push(
        Line::new(series(tr, |r| r.drive_amp_um), RGBColor(214, 39, 40), 2).label("drive |A1|"),
    );
    if !twin.is_empty() {
        p.lines.push(
            Line::new(series(twin, |r| r.sense_amp_um), RGBColor(23, 190, 207), 2)
                .dashed()
                .label(format!("sense |B1|, {label}")),
        );
        p.lines.push(
            Line::new(series(twin, |r| r.drive_amp_um), RGBColor(255, 127, 14), 2)
                .dashed()
                .label(format!("drive |A1|, {label}")),
        );
    }
    p.legend = Some(SeriesLabelPosition::LowerRight);
    draw_panel(&top, &p)?;

    // Pump.
    let pump_vals = tr
        .iter()
        .chain(twin)
        .flat_map(|r| [r.pump_hz, r.pump_centre_hz]);
    let (lo, hi) = min_max(pump_vals).unwrap_or((0.0, 1.0));
    let span = (hi - lo).max(10.0);
    let mid = 0.5 * (lo + hi);
    let y = (mid - 0.6 * span, mid + 0.6 * span);
    let mut p = Panel::new("pump frequency 2Ω/2π".into(), x, y);
    p.y_desc = "pump (Hz)".into();
    p.x_desc = Some("time (s)".into());
    p.vlines = vlines;
    let min_w = (x.1 - x.0) / 500.0;
    let retune_c = RGBColor(44, 160, 44).mix(0.22);
    let change_c = RGBColor(214, 39, 40).mix(0.35);
    let retune_bands = health_bands(tr, "retuning", retune_c, min_w);
    let change_bands = health_bands(tr, "change_detected", change_c, min_w);
    if !retune_bands.is_empty() {
        p.band_labels.push(("retuning".into(), retune_c));
    }
    if !change_bands.is_empty() {
        p.band_labels.push(("change detected".into(), change_c));
    }
    p.bands = retune_bands;
    p.bands.extend(change_bands);
    p.lines.push(
        Line::new(series(tr, |r| r.pump_hz), RGBColor(120, 150, 200), 1)
            .label("pump (with dither)"),
    );
    p.lines
        .push(Line::new(series(tr, |r| r.pump_centre_hz), TRUE_COLOR, 2).label("pump centre"));
    if !twin.is_empty() {
        p.lines.push(
            Line::new(
                series(twin, |r| r.pump_centre_hz),
                RGBColor(255, 127, 14),
                2,
            )
            .dashed()
            .label(format!("pump centre, {label}")),
        );
    }
    p.legend = Some(SeriesLabelPosition::UpperLeft);
    draw_panel(&bottom, &p)?;
    root.present()?;
    Ok(())
}
