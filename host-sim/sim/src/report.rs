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
//! The text summaries read the typed [`RunSummary`](crate::summary::RunSummary): the scenario's measures whose name
//! contains `sense_amp` are listed with their ratios, the other scalar values one group per
//! line.

use std::fmt::Write as _;
use std::fs;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use crate::plot::fmt_tick;
use crate::trace::{
    HEALTH_NAMES, PHYS_NAMES, RunResult, THETA_DRIVE_NAMES, THETA_SENSE_NAMES, TraceRow,
};

mod figures;
#[cfg(test)]
mod tests;
mod text;

use figures::{
    plot_amplitudes_pump, plot_physical, plot_rel_error, plot_theta_drive, plot_theta_sense,
};
pub use text::{print_summary, short_summary};

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
/// sense_amp_um, one 0/1 column per health flag, resets, bad_samples, then the rate channel:
/// rate_dps_slow, quadrature_dps, rate_valid (0/1), then the die temperature temp_c (°C; NaN
/// without a `[temperature]` profile), the drift the core follows on θ12 and θ22,
/// drift_th12_ppm_s, drift_th22_ppm_s, and the frequency temperature coefficients it has
/// learned from the samples' temperature, tcf_wx_ppm_k, tcf_wy_ppm_k (ppm/K; NaN until
/// learned, and without a sensor), then drift_alarms (the change alarms read as a drift so
/// far, which opened the drift column's walk instead of a reset). `rate_dps_est` is the
/// fast rate.
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
    h.extend(
        [
            "rate_dps_slow",
            "quadrature_dps",
            "rate_valid",
            "temp_c",
            "drift_th12_ppm_s",
            "drift_th22_ppm_s",
            "tcf_wx_ppm_k",
            "tcf_wy_ppm_k",
        ]
        .map(String::from),
    );
    h.push("drift_alarms".into());
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
    for x in [r.rate_dps_slow, r.quadrature_dps] {
        out.push(',');
        out.push_str(&fmt_f64(x));
    }
    out.push_str(if r.rate_valid { ",1" } else { ",0" });
    for x in [
        r.temp_c,
        r.drift_ppm_s[0],
        r.drift_ppm_s[1],
        r.tcf_ppm_k[0],
        r.tcf_ppm_k[1],
    ] {
        out.push(',');
        out.push_str(&fmt_f64(x));
    }
    let _ = write!(out, ",{}", r.drift_alarms);
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
