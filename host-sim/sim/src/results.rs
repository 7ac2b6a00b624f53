//! The results table of host-sim/README.md "Results", measured: every built-in scenario through the core in
//! `f32` (as on the chip) and `f64` (host reference). `paragyro-sim results`.

use std::fmt::Write as _;

use crate::runner::{Precision, RunOptions, run, settle_time};
use crate::scenario::Scenario;
use crate::trace::{RunResult, TraceRow};

fn rel(e: f64, t: f64) -> f64 {
    (e - t).abs() / t.abs()
}

fn theta_err(r: &TraceRow, j: usize) -> f64 {
    if j < 8 {
        rel(r.theta_drive_est[j], r.theta_drive_true[j])
    } else {
        rel(r.theta_sense_est[j - 8], r.theta_sense_true[j - 8])
    }
}

/// Worst time (s after `t0`) at which all θ are within `tol` for good, up to `t1`.
fn all_within(trace: &[TraceRow], tol: f64, t0: f64, t1: f64) -> Option<f64> {
    let rows: Vec<TraceRow> = trace.iter().filter(|r| r.t_s < t1).cloned().collect();
    (0..14)
        .map(|j| settle_time(&rows, j, tol, t0))
        .try_fold(0.0f64, |a, t| t.map(|t| a.max(t)))
}

fn fmt_opt(v: Option<f64>, unit: &str) -> String {
    match v {
        Some(v) => format!("{v:.3}{unit}"),
        None => "never".into(),
    }
}

/// One scenario's line of numbers.
fn line(name: &str, r: &RunResult) -> String {
    let Some(last) = r.trace.last() else {
        return "empty trace".into();
    };
    let s = &r.summary;
    let mut out = String::new();
    match name {
        "identify" => {
            let worst_other = (0..14)
                .filter(|j| *j != 3 && *j != 6)
                .map(|j| theta_err(last, j))
                .fold(0.0, f64::max);
            let _ = write!(
                out,
                "θ14 {:.2} %, θ17 {:.2} %, other θ ≤ {:.1e}; identified rate {:.2} °/s ({:.3} %), fast rate output {:.2} °/s; all θ within 10 % {} after the dither starts",
                100.0 * theta_err(last, 3),
                100.0 * theta_err(last, 6),
                worst_other,
                last.rate_dps_slow,
                100.0 * rel(last.rate_dps_slow, last.rate_dps_true),
                last.rate_dps_est,
                fmt_opt(all_within(&r.trace, 0.1, 1.0, f64::INFINITY), " s")
            );
        }
        "drift-retune" => {
            let at3 = r
                .trace
                .iter()
                .find(|x| x.t_s >= 3.0)
                .map(|x| rel(x.phys_est[4], x.phys_true[4]));
            let g = |v: Option<f64>| v.unwrap_or(f64::NAN);
            let _ = write!(
                out,
                "ω̂y² error {:.1e} at 3.0 s, final ω̂y² {:.6}; sense amplitude {:.3} µm before the drift, {:.3} µm ({:.0} %) without retune, {:.3} µm ({:.0} %) after the retune",
                at3.unwrap_or(f64::NAN),
                s.wy2_est_final,
                g(s.measure("sense_amp_before_drift")),
                g(s.measure("sense_amp_after_drift")),
                100.0 * g(s.sense_amp_after_drift_ratio),
                g(s.measure("sense_amp_after_retune")),
                100.0 * g(s.sense_amp_after_retune_ratio),
            );
        }
        "paper-switch" => {
            let a = all_within(&r.trace, 0.1, 3.0, 6.0);
            let b = all_within(&r.trace, 0.1, 6.0, f64::INFINITY);
            let _ = write!(
                out,
                "all θ within 10 % {} after the +50 % switch, {} after the −50 % switch; at the end θ14 {:.2} %, θ17 {:.2} %",
                fmt_opt(a, " s"),
                fmt_opt(b, " s"),
                100.0 * theta_err(last, 3),
                100.0 * theta_err(last, 6)
            );
        }
        "paper-claim" => {
            let g = |v: Option<f64>| v.unwrap_or(f64::NAN);
            let _ = write!(
                out,
                "sense amplitude {:.3} µm at ωy² = 1.0265, {:.3} µm at 1.03 with the same pump: ratio {:.3} (paper: 0.20)",
                g(s.measure("sense_amp_tuned")),
                g(s.measure("sense_amp_detuned")),
                g(s.sense_amp_ratio)
            );
        }
        _ => {
            let _ = write!(
                out,
                "identified rate {:.2} °/s, fast rate output {:.2} °/s",
                last.rate_dps_slow, last.rate_dps_est
            );
        }
    }
    out
}

/// Runs the built-in scenarios in both precisions and returns a Markdown table.
pub fn results_table(progress: &mut dyn FnMut(&str)) -> anyhow::Result<String> {
    let mut md = String::from("| scenario | core | result | wall |\n|---|---|---|---|\n");
    for (name, _) in Scenario::builtin_names() {
        let sc = Scenario::builtin(name).ok_or_else(|| anyhow::anyhow!("no built-in {name}"))?;
        for p in [Precision::F32, Precision::F64] {
            progress(&format!("{name} ({})", p.name()));
            let r = run(
                &sc,
                &RunOptions {
                    precision: p,
                    seed: None,
                },
                &mut |_| {},
            )?;
            let wall = r.summary.wall_seconds;
            let sim = r.summary.sim_seconds * if r.twin.is_some() { 2.0 } else { 1.0 };
            let _ = writeln!(
                md,
                "| `{name}` | {} | {} | {wall:.1} s for {sim:.0} s simulated |",
                p.name(),
                line(name, &r)
            );
        }
    }
    Ok(md)
}
