//! Plain-text summaries of a run for the terminal.

use std::fmt::Write as _;

use super::{
    PHYS_PRETTY, THETA_DRIVE_MEANING, THETA_SENSE_MEANING, fmt_rel, fmt_sci, settle_time,
    time_range, twin_label,
};
use crate::summary::RunSummary;
use crate::trace::{HEALTH_NAMES, PHYS_NAMES, RunResult, THETA_DRIVE_NAMES, THETA_SENSE_NAMES};

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
    let v = crate::summary::RateValidity::of_trace(&result.trace);
    let _ = match v.worst_valid_at_s {
        Some(t) => writeln!(
            s,
            "  rate valid on {} of {} samples; worst valid error {:.2} °/s (t = {t:.3} s)",
            v.valid, v.samples, v.worst_valid_err_dps
        ),
        None => writeln!(s, "  rate valid on 0 of {} samples", v.samples),
    };
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
