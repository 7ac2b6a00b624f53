//! Outputs of a run: `summary.json`, `trace.csv` (and `trace_twin.csv`), PNG plots for a MEMS
//! engineer, and plain-text summaries for the terminal.
//!
//! The plots use the plotters bitmap backend with the DejaVu Sans font embedded in the binary,
//! so they render the same on a machine without system fonts:
//!
//! | file | content |
//! |---|---|
//! | `theta_drive.png` | θ11…θ18 estimate vs truth (paper Figs 9–10), zoomed on the truth |
//! | `theta_sense.png` | θ21…θ26 estimate vs truth (Fig. 11) |
//! | `theta_rel_error.png` | log10 of the relative error of all 14 θ, with the 0.1 %, 1 %, 10 % levels |
//! | `physical.png` | the 12 physical parameters (Figs 12–14) and the rate in °/s |
//! | `amplitudes_pump.png` | sense/drive amplitudes (with the twin run), pump frequency and centre, retune and change-detection periods |
//!
//! The text summaries read the typed [`RunSummary`]: the scenario's measures whose name
//! contains `sense_amp` are listed with their ratios, the other scalar values one group per
//! line.

use std::fmt::Write as _;
use std::fs;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use plotters::prelude::*;

use crate::plot::*;
use crate::summary::RunSummary;
use crate::trace::{
    HEALTH_NAMES, PHYS_NAMES, RunResult, THETA_DRIVE_NAMES, THETA_SENSE_NAMES, TraceRow,
};

/// Smallest half-height of an estimate-vs-truth panel, relative to |truth|.
const ZOOM_FLOOR: f64 = 0.02;

/// Bit index of a health flag in `TraceRow::health`.
fn health_bit(name: &str) -> Option<u32> {
    HEALTH_NAMES
        .iter()
        .position(|n| *n == name)
        .map(|i| i as u32)
}

/// Meaning of each θ (eq. 25 order).
const THETA_DRIVE_MEANING: [&str; 8] = [
    "−μx",
    "−(ωx²−γ²+2β1)",
    "−(ωxy²−γ')",
    "−(μxy−2γ)",
    "−(2β3+αx)",
    "−2β1",
    "−2β3",
    "c_ax (1)",
];
const THETA_SENSE_MEANING: [&str; 6] = [
    "−μy",
    "−(ωy²−γ²)",
    "−(ωxy²+γ')",
    "−(μxy+2γ)",
    "−αy",
    "c_ay (1)",
];
/// Display names of `PHYS_NAMES`.
const PHYS_PRETTY: [&str; 12] = [
    "μx", "μy", "μxy", "ωx²", "ωy²", "ωxy²", "αx", "αy", "β1", "β3", "γ", "γ'",
];

/// Writes all outputs of a run into `dir` (created if needed) and returns the files written:
/// `summary.json`, `trace.csv`, `trace_twin.csv` (when there is a twin run) and the five PNGs.
pub fn write_outputs(dir: &Path, result: &RunResult) -> Result<Vec<PathBuf>> {
    fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the output directory {}", dir.display()))?;
    let mut files = Vec::new();

    let path = dir.join("summary.json");
    let json = result.summary.to_json_pretty()?;
    fs::write(&path, json).with_context(|| format!("cannot write {}", path.display()))?;
    files.push(path);

    let path = dir.join("trace.csv");
    write_csv(&path, &result.trace)?;
    files.push(path);
    if let Some(twin) = &result.twin {
        let path = dir.join("trace_twin.csv");
        write_csv(&path, twin)?;
        files.push(path);
    }

    type PlotFn = fn(&Path, &RunResult) -> Result<()>;
    let plots: [(&str, PlotFn); 5] = [
        ("theta_drive.png", plot_theta_drive),
        ("theta_sense.png", plot_theta_sense),
        ("theta_rel_error.png", plot_rel_error),
        ("physical.png", plot_physical),
        ("amplitudes_pump.png", plot_amplitudes_pump),
    ];
    for (name, plot) in plots {
        let path = dir.join(name);
        plot(&path, result).with_context(|| format!("cannot draw {}", path.display()))?;
        files.push(path);
    }
    Ok(files)
}

// ---------------------------------------------------------------------------------------------
// CSV
// ---------------------------------------------------------------------------------------------

/// The `trace.csv` header: t_s, pump_hz, pump_centre_hz, pump_scale, th1*_true, th2*_true,
/// th1*_est, th2*_est, `<phys>_true`, `<phys>_est`, rate_dps_true, rate_dps_est, drive_amp_um,
/// sense_amp_um, one 0/1 column per health flag, resets, bad_samples.
pub fn csv_header() -> Vec<String> {
    let mut h: Vec<String> = ["t_s", "pump_hz", "pump_centre_hz", "pump_scale"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let theta = THETA_DRIVE_NAMES.iter().chain(THETA_SENSE_NAMES.iter());
    h.extend(theta.clone().map(|n| format!("{n}_true")));
    h.extend(theta.map(|n| format!("{n}_est")));
    h.extend(PHYS_NAMES.iter().map(|n| format!("{n}_true")));
    h.extend(PHYS_NAMES.iter().map(|n| format!("{n}_est")));
    for s in [
        "rate_dps_true",
        "rate_dps_est",
        "drive_amp_um",
        "sense_amp_um",
    ] {
        h.push(s.to_string());
    }
    h.extend(HEALTH_NAMES.iter().map(|n| n.to_string()));
    h.push("resets".into());
    h.push("bad_samples".into());
    h
}

/// Shortest representation that parses back to the same f64 (plain for ordinary magnitudes,
/// exponent form otherwise; `NaN`, `inf`, `-inf` for the non-finite values).
fn fmt_f64(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 || (1e-4..1e15).contains(&a) || !x.is_finite() {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

fn csv_row(r: &TraceRow, out: &mut String) {
    out.clear();
    let mut push = |x: f64| {
        if !out.is_empty() {
            out.push(',');
        }
        out.push_str(&fmt_f64(x));
    };
    for x in [r.t_s, r.pump_hz, r.pump_centre_hz, r.pump_scale] {
        push(x);
    }
    let all = r
        .theta_drive_true
        .iter()
        .chain(&r.theta_sense_true)
        .chain(&r.theta_drive_est)
        .chain(&r.theta_sense_est)
        .chain(&r.phys_true)
        .chain(&r.phys_est);
    for &x in all {
        push(x);
    }
    for x in [
        r.rate_dps_true,
        r.rate_dps_est,
        r.drive_amp_um,
        r.sense_amp_um,
    ] {
        push(x);
    }
    for bit in 0..HEALTH_NAMES.len() {
        out.push_str(if r.health >> bit & 1 == 1 { ",1" } else { ",0" });
    }
    let _ = write!(out, ",{},{}", r.resets, r.bad_samples);
}

fn write_csv(path: &Path, rows: &[TraceRow]) -> Result<()> {
    let file =
        fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = BufWriter::new(file);
    writeln!(w, "{}", csv_header().join(","))?;
    let mut line = String::with_capacity(2048);
    for r in rows {
        csv_row(r, &mut line);
        writeln!(w, "{line}")?;
    }
    w.flush()
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

/// Time range of the trace (and the twin's).
fn time_range(result: &RunResult) -> (f64, f64) {
    let ts = result
        .trace
        .iter()
        .chain(result.twin.iter().flatten())
        .map(|r| r.t_s)
        .filter(|t| t.is_finite());
    let (lo, hi) = ts.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
        (lo.min(t), hi.max(t))
    });
    if lo.is_finite() && hi > lo {
        (lo, hi)
    } else if lo.is_finite() {
        (lo, lo + 1.0)
    } else {
        (0.0, 1.0)
    }
}

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

/// When the estimates can be expected to mean something: the first sample with
/// `excitation_ok`, else the first `settled`, else 10 % into the run.
fn settle_time(trace: &[TraceRow]) -> f64 {
    for name in ["excitation_ok", "settled"] {
        if let Some(bit) = health_bit(name)
            && let Some(r) = trace.iter().find(|r| r.health >> bit & 1 == 1)
        {
            return r.t_s;
        }
    }
    match (trace.first(), trace.last()) {
        (Some(a), Some(b)) => a.t_s + 0.1 * (b.t_s - a.t_s),
        _ => 0.0,
    }
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
fn zoom_range(t: &[f64], truth: &[f64], est: &[f64], t_settle: f64, floor: f64) -> (f64, f64) {
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

/// Fixed-width scientific notation: `-1.045200e+00`.
fn fmt_sci(x: f64) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    let s = format!("{x:.6e}");
    match s.split_once('e') {
        Some((m, e)) => {
            let e: i32 = e.parse().unwrap_or(0);
            format!("{m}e{}{:02}", if e < 0 { '-' } else { '+' }, e.abs())
        }
        None => s,
    }
}

fn fmt_rel(true_v: f64, est: f64) -> String {
    if !(true_v.is_finite() && est.is_finite()) {
        "n/a".into()
    } else if true_v == 0.0 {
        format!("abs {:.1e}", (est - true_v).abs())
    } else {
        format!("{:.1e}", ((est - true_v) / true_v).abs())
    }
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

// ---------------------------------------------------------------------------------------------
// The five figures
// ---------------------------------------------------------------------------------------------

fn plot_theta_drive(path: &Path, result: &RunResult) -> Result<()> {
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

fn plot_theta_sense(path: &Path, result: &RunResult) -> Result<()> {
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

fn plot_rel_error(path: &Path, result: &RunResult) -> Result<()> {
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

fn plot_physical(path: &Path, result: &RunResult) -> Result<()> {
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
fn health_bands(trace: &[TraceRow], name: &str, color: RGBAColor, min_w: f64) -> Vec<Band> {
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

/// The twin run's legend label: "without retune" when the pump centres of the two runs
/// differ; else the plant parameters in which the twin differs (e.g. "twin: ωy² = 1.03");
/// else "twin run".
fn twin_label(result: &RunResult) -> String {
    let Some(twin) = result.twin.as_deref() else {
        return "twin run".into();
    };
    let centres_differ = result
        .trace
        .iter()
        .zip(twin)
        .any(|(a, b)| (a.pump_centre_hz - b.pump_centre_hz).abs() > 1e-6);
    if centres_differ {
        return "without retune".into();
    }
    if let (Some(a), Some(b)) = (result.trace.first(), twin.first()) {
        let diffs: Vec<String> = (0..12)
            .filter(|&i| a.phys_true[i] != b.phys_true[i])
            .map(|i| format!("{} = {}", PHYS_PRETTY[i], fmt_tick(b.phys_true[i])))
            .collect();
        if !diffs.is_empty() {
            return format!("twin: {}", diffs.join(", "));
        }
    }
    "twin run".into()
}

fn plot_amplitudes_pump(path: &Path, result: &RunResult) -> Result<()> {
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

// ---------------------------------------------------------------------------------------------
// Text summaries
// ---------------------------------------------------------------------------------------------

/// The measures of the summary whose name contains `sense_amp` (not `ratio`) and that have a
/// value, and their ratios to a reference (the one whose name contains "before", else ends
/// in "_tuned", else the first).
fn sense_amp_lines(summary: &RunSummary) -> Vec<String> {
    let amps: Vec<(&str, f64)> = summary
        .measures
        .iter()
        .filter(|(k, _)| k.contains("sense_amp") && !k.contains("ratio"))
        .filter_map(|(k, v)| v.map(|x| (k.as_str(), x)))
        .collect();
    if amps.is_empty() {
        return Vec::new();
    }
    let reference = amps
        .iter()
        .position(|(k, _)| k.contains("before"))
        .or_else(|| amps.iter().position(|(k, _)| k.ends_with("_tuned")))
        .unwrap_or(0);
    let (ref_name, ref_v) = amps[reference];
    let mut lines = vec!["Sense amplitude measures (mean |B1|):".to_string()];
    for (k, v) in &amps {
        let mut line = format!("  {k:<28} {v:>9.4} µm");
        if *k != ref_name && ref_v != 0.0 {
            let _ = write!(line, "   = {:.3} × {ref_name}", v / ref_v);
        }
        lines.push(line);
    }
    lines
}

/// A scalar of the summary as the text summary shows it.
#[derive(Clone, Copy, Debug)]
enum Scalar {
    /// A count.
    Int(u64),
    /// A number (non-finite: shown as `null`, as in the JSON).
    Float(f64),
    /// Absent (an optional value without data).
    Null,
}

impl From<f64> for Scalar {
    fn from(x: f64) -> Self {
        Scalar::Float(x)
    }
}

impl From<u32> for Scalar {
    fn from(x: u32) -> Self {
        Scalar::Int(x.into())
    }
}

impl From<Option<f64>> for Scalar {
    fn from(x: Option<f64>) -> Self {
        x.map_or(Scalar::Null, Scalar::Float)
    }
}

/// A scalar for the text summary (numbers with 6 significant digits).
fn fmt_scalar(v: Scalar) -> String {
    let float = |x: f64| {
        let a = x.abs();
        if x == 0.0 || (1e-3..1e6).contains(&a) {
            format!("{}", (x * 1e6).round() / 1e6)
        } else {
            format!("{x:.5e}")
        }
    };
    match v {
        Scalar::Int(i) if i <= i64::MAX as u64 => i.to_string(),
        Scalar::Int(i) => float(i as f64),
        Scalar::Float(x) if x.is_finite() => float(x),
        Scalar::Float(_) | Scalar::Null => "null".into(),
    }
}

/// The summary values the text summary does not show elsewhere, as (key, line) in key
/// order: one line per group (`parent: k v, k v`) or per top-level value (`k: v`). The
/// sense-amplitude measures and ratios, θ, the physical parameters and the rates have
/// their own sections.
fn summary_value_lines(s: &RunSummary) -> Vec<(String, String)> {
    let group = |parent: &str, items: &[(&str, Scalar)]| {
        let list: Vec<String> = items
            .iter()
            .map(|(k, v)| format!("{k} {}", fmt_scalar(*v)))
            .collect();
        (parent.to_string(), format!("{parent}: {}", list.join(", ")))
    };
    let settle = |p: &crate::summary::ThetaPair<Option<f64>>| -> Vec<(&str, Scalar)> {
        let names = THETA_DRIVE_NAMES.iter().chain(&THETA_SENSE_NAMES);
        let vals = p.drive.iter().chain(&p.sense);
        names
            .zip(vals)
            .map(|(n, v)| (*n, Scalar::from(*v)))
            .collect()
    };
    let conv = &s.convergence_after_dither_start;
    let c = &s.counters;
    let mut out = vec![
        group(
            "convergence_after_dither_start.within_10pct_s",
            &settle(&conv.within_10pct_s),
        ),
        group(
            "convergence_after_dither_start.within_1pct_s",
            &settle(&conv.within_1pct_s),
        ),
        group(
            "counters",
            &[
                ("bad_samples", c.bad_samples.into()),
                ("jumps", c.jumps.into()),
                ("resets_drive", c.resets_drive.into()),
                ("resets_sense", c.resets_sense.into()),
                ("retune_aborts", c.retune_aborts.into()),
                ("retunes", c.retunes.into()),
                ("samples", c.samples.into()),
                ("updates", c.updates.into()),
            ],
        ),
    ];
    let mut top: Vec<(&str, Scalar)> = vec![
        ("pump_centre_final_hz", s.pump_centre_final_hz.into()),
        ("rate_rel_err", s.rate_rel_err.into()),
        ("seed", Scalar::Int(s.seed)),
        ("sim_seconds", s.sim_seconds.into()),
        ("wall_seconds", s.wall_seconds.into()),
        ("wy2_est_final", s.wy2_est_final.into()),
        ("wy2_true_final", s.wy2_true_final.into()),
    ];
    if let Some(v) = s.twin_pump_centre_final_hz {
        top.push(("twin_pump_centre_final_hz", v.into()));
    }
    // (as the sections above: θ, physical, rates, names)
    let shown = [
        "physical_true",
        "physical_est",
        "theta_",
        "rate_dps_",
        "scenario",
        "precision",
    ];
    for (k, v) in &s.measures {
        if !k.contains("sense_amp") && !shown.iter().any(|p| k.starts_with(p)) {
            top.push((k, (*v).into()));
        }
    }
    out.extend(
        top.into_iter()
            .map(|(k, v)| (k.to_string(), format!("{k}: {}", fmt_scalar(v)))),
    );
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

/// Names of the health flags set in `health`.
fn health_flags(health: u32) -> String {
    let set: Vec<&str> = HEALTH_NAMES
        .iter()
        .enumerate()
        .filter(|(i, _)| health >> i & 1 == 1)
        .map(|(_, n)| *n)
        .collect();
    if set.is_empty() {
        "(none)".into()
    } else {
        set.join(", ")
    }
}

/// A readable plain-text summary of a run: θ true/estimate/relative error for drive and
/// sense, the physical parameters, rate, ωy², the sense-amplitude measures and ratios from the
/// summary JSON, other summary values, final health and the events.
pub fn print_summary(result: &RunResult) -> String {
    let mut s = String::new();
    let tr = &result.trace;
    let (t0, t1) = time_range(result);
    let _ = writeln!(
        s,
        "Scenario '{}' ({}): {} samples over {:.3} s{}",
        result.scenario,
        result.precision,
        tr.len(),
        if tr.is_empty() { 0.0 } else { t1 - t0 },
        match &result.twin {
            Some(t) => format!(", twin run ({}) {} samples", twin_label(result), t.len()),
            None => String::new(),
        }
    );
    let Some(last) = tr.last() else {
        s.push_str("(empty trace)\n");
        return s;
    };

    let _ = writeln!(s, "\nFinal estimates at t = {:.3} s", last.t_s);
    let header = format!(
        "  {:<6} {:<16} {:>15} {:>15} {:>10}",
        "", "", "true", "estimate", "rel.err"
    );
    let row = |s: &mut String, name: &str, meaning: &str, t: f64, e: f64| {
        let _ = writeln!(
            s,
            "  {name:<6} {meaning:<16} {:>15} {:>15} {:>10}",
            fmt_sci(t),
            fmt_sci(e),
            fmt_rel(t, e)
        );
    };
    let _ = writeln!(s, "Drive θ1:\n{header}");
    for i in 0..8 {
        row(
            &mut s,
            THETA_DRIVE_NAMES[i],
            THETA_DRIVE_MEANING[i],
            last.theta_drive_true[i],
            last.theta_drive_est[i],
        );
    }
    let _ = writeln!(s, "Sense θ2:\n{header}");
    for i in 0..6 {
        row(
            &mut s,
            THETA_SENSE_NAMES[i],
            THETA_SENSE_MEANING[i],
            last.theta_sense_true[i],
            last.theta_sense_est[i],
        );
    }
    let _ = writeln!(s, "Physical parameters (corrected Table 3):\n{header}");
    for i in 0..12 {
        row(
            &mut s,
            PHYS_PRETTY[i],
            PHYS_NAMES[i],
            last.phys_true[i],
            last.phys_est[i],
        );
    }
    let rate_err = last.rate_dps_est - last.rate_dps_true;
    let _ = writeln!(
        s,
        "\nRate: true {:.3} °/s, estimated {:.3} °/s (error {:+.3} °/s, {:+.3} %)",
        last.rate_dps_true,
        last.rate_dps_est,
        rate_err,
        if last.rate_dps_true != 0.0 {
            100.0 * rate_err / last.rate_dps_true
        } else {
            f64::NAN
        }
    );
    let t_settle = settle_time(tr);
    let first = tr.iter().find(|r| r.t_s >= t_settle).unwrap_or(last);
    let _ = writeln!(
        s,
        "ωy² (wy2): true {:.6} at t = {:.2} s, {:.6} at the end; estimated {:.6} at the end",
        first.phys_true[4], first.t_s, last.phys_true[4], last.phys_est[4]
    );
    let _ = write!(
        s,
        "Pump centre: {:.2} Hz at the start, {:.2} Hz at the end",
        tr[0].pump_centre_hz, last.pump_centre_hz
    );
    s.push('\n');

    let amps = sense_amp_lines(&result.summary);
    if !amps.is_empty() {
        s.push('\n');
        for l in amps {
            let _ = writeln!(s, "{l}");
        }
    }

    // Values not shown above, one line per group.
    let others = summary_value_lines(&result.summary);
    if !others.is_empty() {
        let _ = writeln!(s, "\nSummary values:");
        for (_, line) in others.iter().take(40) {
            let _ = writeln!(s, "  {line}");
        }
    }

    let _ = writeln!(
        s,
        "\nHealth at the end: {}; covariance resets {}, bad samples {}",
        health_flags(last.health),
        last.resets,
        last.bad_samples
    );
    if !result.events.is_empty() {
        let _ = writeln!(s, "Events:");
        for e in result.events.iter().take(30) {
            let _ = writeln!(s, "  t = {:>8.3} s  {}", e.t_s, e.what);
        }
        if result.events.len() > 30 {
            let _ = writeln!(s, "  ... and {} more", result.events.len() - 30);
        }
    }
    s
}

/// A few lines for the `run` command: final rate, worst θ, measures, resets and bad samples.
pub fn short_summary(result: &RunResult) -> String {
    let mut s = String::new();
    let Some(last) = result.trace.last() else {
        return format!("{} ({}): empty trace\n", result.scenario, result.precision);
    };
    let _ = writeln!(
        s,
        "{} ({}): {} samples, t = {:.3} s",
        result.scenario,
        result.precision,
        result.trace.len(),
        last.t_s
    );
    let _ = writeln!(
        s,
        "  rate: true {:.3} °/s, estimated {:.3} °/s",
        last.rate_dps_true, last.rate_dps_est
    );
    let worst = THETA_DRIVE_NAMES
        .iter()
        .zip(last.theta_drive_true.iter().zip(&last.theta_drive_est))
        .chain(
            THETA_SENSE_NAMES
                .iter()
                .zip(last.theta_sense_true.iter().zip(&last.theta_sense_est)),
        )
        .filter(|(_, (t, e))| **t != 0.0 && t.is_finite() && e.is_finite())
        .map(|(n, (t, e))| (*n, ((e - t) / t).abs()))
        .max_by(|a, b| a.1.total_cmp(&b.1));
    if let Some((name, err)) = worst {
        let _ = writeln!(s, "  worst θ relative error at the end: {name} {err:.2e}");
    }
    for l in sense_amp_lines(&result.summary) {
        let _ = writeln!(s, "  {l}");
    }
    let _ = writeln!(
        s,
        "  health: {}; resets {}, bad samples {}, events {}",
        health_flags(last.health),
        last.resets,
        last.bad_samples,
        result.events.len()
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::summary::{Convergence, PhysicalValues, RunCounters, ThetaPair};
    use crate::trace::{Event, Precision};

    fn synthetic_row(k: usize, twin: bool) -> TraceRow {
        let t = k as f64 * 0.002;
        let (drive, sense) = (
            [
                -1e-3, -1.0452, -2e-3, -2.28e-5, -2.4296e-3, -0.0452, -1.266e-4, 1.0,
            ],
            [-1e-3, -1.0265, -2e-3, -1.77e-4, -1.264e-3, 1.0],
        );
        let conv = (-t * 5.0).exp(); // converging estimate
        let wobble = (t * 40.0).sin() * 1e-3;
        let mut row = TraceRow {
            t_s: t,
            pump_hz: 21883.95 + 21.6 * (2.0 * std::f64::consts::PI * 2.0 * t).sin(),
            pump_centre_hz: 21883.95 + if t > 0.4 { 30.0 } else { 0.0 },
            pump_scale: 1.0,
            theta_drive_true: drive,
            theta_sense_true: sense,
            theta_drive_est: drive.map(|v| v * (1.0 + 0.3 * conv + wobble)),
            theta_sense_est: sense.map(|v| v * (1.0 - 0.2 * conv + wobble)),
            phys_true: [
                1e-3, 1e-3, 1e-4, 1.0, 1.0265, 2e-3, 2.303e-3, 1.264e-3, 0.0226, 6.33e-5,
                3.8581e-5, 0.0,
            ],
            phys_est: [0.0; 12],
            rate_dps_true: 150.0,
            rate_dps_est: 150.0 * (1.0 + 0.1 * conv) + wobble,
            drive_amp_um: 1.75 * (1.0 - (-t * 20.0).exp()),
            sense_amp_um: if twin { 0.77 } else { 1.5 } * (1.0 - (-t * 10.0).exp()),
            health: (k as u32 / 7) & 0xff,
            resets: (k / 100) as u32,
            bad_samples: 0,
        };
        row.phys_est = row
            .phys_true
            .map(|v| v * (1.0 + 0.1 * conv) + 1e-9 * wobble);
        if k == 10 {
            row.theta_drive_est[0] = f64::NAN; // a NaN sample must be skipped
            row.rate_dps_est = f64::INFINITY;
        }
        row
    }

    fn synthetic_summary() -> RunSummary {
        let last = synthetic_row(299, false);
        RunSummary {
            scenario: "synthetic".into(),
            precision: Precision::F32,
            seed: 7,
            sim_seconds: last.t_s,
            theta_true: ThetaPair {
                drive: last.theta_drive_true,
                sense: last.theta_sense_true,
            },
            theta_est: ThetaPair {
                drive: last.theta_drive_est,
                sense: last.theta_sense_est,
            },
            theta_rel_err: ThetaPair::default(),
            physical_true: PhysicalValues::from_array(last.phys_true),
            physical_est: PhysicalValues::from_array(last.phys_est),
            rate_dps_true: 150.0,
            rate_dps_est: 150.2,
            rate_rel_err: 1.3e-3,
            wy2_true_final: 1.0265,
            wy2_est_final: 1.0266,
            pump_centre_final_hz: 21913.95,
            convergence_after_dither_start: Convergence {
                within_10pct_s: ThetaPair::from_fn(|j| (j != 3).then_some(0.25)),
                within_1pct_s: ThetaPair::from_fn(|_| None),
            },
            counters: RunCounters {
                resets_drive: 2,
                retunes: 1,
                ..RunCounters::default()
            },
            measures: [
                ("sense_amp_before_drift", Some(1.5)),
                ("sense_amp_after_drift", Some(0.78)),
                ("sense_amp_after_retune", Some(1.64)),
                ("sense_amp_missing", None),
                ("quiet_window", None),
            ]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
            sense_amp_ratio: None,
            sense_amp_after_drift_ratio: Some(0.52),
            sense_amp_after_retune_ratio: Some(1.09),
            twin_pump_centre_final_hz: Some(21883.95),
            wall_seconds: 1.5,
        }
    }

    fn synthetic_result() -> RunResult {
        RunResult {
            scenario: "synthetic".into(),
            precision: Precision::F32,
            trace: (0..300).map(|k| synthetic_row(k, false)).collect(),
            events: vec![
                Event {
                    t_s: 0.2,
                    what: "ramp wy2".into(),
                },
                Event {
                    t_s: 0.35,
                    what: "change detected".into(),
                },
            ],
            summary: synthetic_summary(),
            twin: Some((0..300).map(|k| synthetic_row(k, true)).collect()),
        }
    }

    fn parse_field(s: &str) -> f64 {
        s.parse::<f64>()
            .unwrap_or_else(|e| panic!("bad number '{s}': {e}"))
    }

    fn same(a: f64, b: f64) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    #[test]
    fn fmt_f64_round_trips() {
        for x in [
            0.0,
            -0.0,
            1.0,
            -1.0452,
            3.8581e-5,
            1e-300,
            6.02e23,
            21883.952639786974,
            f64::MIN_POSITIVE,
            f64::MAX,
            std::f64::consts::PI,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ] {
            assert!(same(parse_field(&fmt_f64(x)), x), "{x} → {}", fmt_f64(x));
        }
        assert!(parse_field(&fmt_f64(f64::NAN)).is_nan());
        assert!(fmt_f64(1e-300).len() < 12);
    }

    #[test]
    fn writes_all_outputs_and_the_csv_parses_back() {
        let dir = std::env::temp_dir().join(format!("paragyro-report-test-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        let result = synthetic_result();
        let files = write_outputs(&dir, &result).unwrap();
        let names: Vec<String> = files
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        for want in [
            "summary.json",
            "trace.csv",
            "trace_twin.csv",
            "theta_drive.png",
            "theta_sense.png",
            "theta_rel_error.png",
            "physical.png",
            "amplitudes_pump.png",
        ] {
            assert!(names.iter().any(|n| n == want), "{want} missing: {names:?}");
            assert!(dir.join(want).is_file());
        }

        // summary.json is the summary, keys in alphabetical order, one per measure.
        let text = fs::read_to_string(dir.join("summary.json")).unwrap();
        assert_eq!(text, result.summary.to_json_pretty().unwrap());
        let keys: Vec<&str> = text
            .lines()
            .filter(|l| l.starts_with("  \""))
            .filter_map(|l| l.split('"').nth(1))
            .collect();
        let mut sorted = keys.clone();
        sorted.sort_unstable();
        assert_eq!(keys, sorted);
        for want in [
            "convergence_after_dither_start",
            "quiet_window",
            "sense_amp_before_drift",
            "sense_amp_after_retune_ratio",
            "twin_pump_centre_final_hz",
            "wall_seconds",
        ] {
            assert!(keys.contains(&want), "{want} missing: {keys:?}");
        }
        assert!(
            !keys.contains(&"sense_amp_ratio"),
            "absent ratios are left out"
        );
        assert!(text.contains("\"sense_amp_missing\": null"), "{text}");
        assert!(text.contains("\"th14\": null"), "{text}");
        assert!(text.contains("\"precision\": \"f32\""), "{text}");

        // trace.csv: header, one row per sample, numbers round-trip.
        let csv = fs::read_to_string(dir.join("trace.csv")).unwrap();
        let mut lines = csv.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let ncol = 4 + 2 * 14 + 2 * 12 + 4 + HEALTH_NAMES.len() + 2;
        assert_eq!(header.len(), ncol);
        assert_eq!(header, csv_header());
        assert_eq!(header[0], "t_s");
        assert_eq!(header[4], "th11_true");
        assert_eq!(header[18], "th11_est");
        assert_eq!(header[32], "mu_x_true");
        assert_eq!(header[44], "mu_x_est");
        assert_eq!(header[ncol - 1], "bad_samples");
        let rows: Vec<&str> = lines.collect();
        assert_eq!(rows.len(), result.trace.len());
        for (line, r) in rows.iter().zip(&result.trace) {
            let f: Vec<&str> = line.split(',').collect();
            assert_eq!(f.len(), ncol);
            let v: Vec<f64> = f[..60].iter().map(|s| parse_field(s)).collect();
            let mut want = vec![r.t_s, r.pump_hz, r.pump_centre_hz, r.pump_scale];
            want.extend(r.theta_drive_true);
            want.extend(r.theta_sense_true);
            want.extend(r.theta_drive_est);
            want.extend(r.theta_sense_est);
            want.extend(r.phys_true);
            want.extend(r.phys_est);
            want.extend([
                r.rate_dps_true,
                r.rate_dps_est,
                r.drive_amp_um,
                r.sense_amp_um,
            ]);
            for (i, (a, b)) in v.iter().zip(&want).enumerate() {
                assert!(same(*a, *b), "column {} ({}): {a} vs {b}", i, header[i]);
            }
            for bit in 0..HEALTH_NAMES.len() {
                let want = if r.health >> bit & 1 == 1 { "1" } else { "0" };
                assert_eq!(f[60 + bit], want);
            }
            assert_eq!(f[ncol - 2].parse::<u32>().unwrap(), r.resets);
            assert_eq!(f[ncol - 1].parse::<u32>().unwrap(), r.bad_samples);
        }

        // The PNGs are real images of some size.
        for name in names.iter().filter(|n| n.ends_with(".png")) {
            let bytes = fs::read(dir.join(name)).unwrap();
            assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{name} is not a PNG");
            assert!(
                bytes.len() > 20_000,
                "{name} too small: {} bytes",
                bytes.len()
            );
            // IHDR: width and height.
            let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
            let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
            assert_eq!((w, h), (FIG_W, FIG_H), "{name}");
        }
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn summary_text_has_the_tables_and_ratios() {
        let result = synthetic_result();
        let s = print_summary(&result);
        for want in [
            "synthetic",
            "th14",
            "th26",
            "wy2",
            "Rate: true 150.000",
            "sense_amp_after_retune",
            "× sense_amp_before_drift",
            "0.520 × sense_amp_before_drift",
            "change detected",
            "wall_seconds: 1.5",
            "quiet_window: null",
            "seed: 7",
            "twin_pump_centre_final_hz: 21883.95",
            "counters: bad_samples 0, jumps 0, resets_drive 2, resets_sense 0, \
             retune_aborts 0, retunes 1, samples 0, updates 0",
            "within_10pct_s: th11 0.25, th12 0.25, th13 0.25, th14 null, th15 0.25",
        ] {
            assert!(s.contains(want), "'{want}' missing from:\n{s}");
        }
        let short = short_summary(&result);
        assert!(short.contains("worst θ relative error"), "{short}");
        let empty = RunResult {
            trace: Vec::new(),
            twin: None,
            ..synthetic_result()
        };
        assert!(print_summary(&empty).contains("empty trace"));
        assert!(short_summary(&empty).contains("empty trace"));
    }

    #[test]
    fn zoom_range_clips_startup_spikes() {
        let t: Vec<f64> = (0..1000).map(|k| k as f64 * 0.002).collect();
        let truth = vec![-2.28e-5; 1000];
        let est: Vec<f64> = t
            .iter()
            .map(|&t| if t < 0.5 { -1e-2 } else { -2.28e-5 * 1.01 })
            .collect();
        let (lo, hi) = zoom_range(&t, &truth, &est, 1.0, 0.2);
        assert!((lo + 2.28e-5 * 1.2).abs() < 1e-12 && (hi + 2.28e-5 * 0.8).abs() < 1e-12);
        // A 10 % transient after the settle time is clipped, not zoomed out to.
        let est: Vec<f64> = t
            .iter()
            .map(|&t| {
                if (1.0..1.1).contains(&t) {
                    -1e-2
                } else {
                    -2.28e-5 * 1.01
                }
            })
            .collect();
        let (lo, hi) = zoom_range(&t, &truth, &est, 0.5, 0.02);
        assert!(lo > -2.28e-5 * 1.1 && hi < -2.28e-5 * 0.9, "{lo} {hi}");
        // Truth 0 (γ' = 0): the range comes from the spread.
        let zero = vec![0.0; 1000];
        let est: Vec<f64> = t.iter().map(|&t| 1e-7 * (t * 9.0).sin()).collect();
        let (lo, hi) = zoom_range(&t, &zero, &est, 0.0, 0.2);
        assert!(lo < 0.0 && hi > 0.0 && hi < 4e-7, "{lo} {hi}");
    }

    #[test]
    fn bands_and_segments() {
        let rows: Vec<TraceRow> = (0..100)
            .map(|k| {
                let mut r = synthetic_row(k, false);
                r.health = if (20..30).contains(&k) || k == 60 {
                    1 << 7
                } else {
                    0
                };
                r
            })
            .collect();
        let b = health_bands(&rows, "retuning", RED.mix(0.2), 0.01);
        assert_eq!(b.len(), 2);
        assert!((b[0].x0 - 0.039).abs() < 1e-9 && (b[0].x1 - 0.059).abs() < 1e-9);
        assert!((b[1].x1 - b[1].x0 - 0.01).abs() < 1e-12, "minimum width");
        let s = segments(
            &[(0.0, 1.0), (1.0, f64::NAN), (2.0, 5.0), (3.0, -5.0)],
            (-1.0, 2.0),
        );
        assert_eq!(s, vec![vec![(0.0, 1.0)], vec![(2.0, 2.0), (3.0, -1.0)]]);
    }
}
