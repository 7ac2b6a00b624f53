//! Shared helpers for the end-to-end tests in `tests/tests/`.

use paragyro_simulator::runner::{Precision, RunOptions, run};
use paragyro_simulator::scenario::Scenario;
use paragyro_simulator::trace::{RunResult, TraceRow};

/// Runs a built-in scenario (optionally shortened) with the core in `precision`.
pub fn run_builtin(name: &str, precision: Precision, duration_s: Option<f64>) -> RunResult {
    let mut sc = Scenario::builtin(name).unwrap_or_else(|| panic!("no built-in scenario {name}"));
    if let Some(d) = duration_s {
        sc.duration_s = d;
        sc.measures.retain(|m| m.to_s <= d);
        sc.events.retain(|e| e.t_s <= d);
    }
    run(
        &sc,
        &RunOptions {
            precision,
            seed: None,
        },
        &mut |_| {},
    )
    .expect("run failed")
}

/// |est − true| / |true|.
pub fn rel(est: f64, tru: f64) -> f64 {
    (est - tru).abs() / tru.abs()
}

/// Relative error of θ component j (0..8 drive, 8..14 sense) at one row.
pub fn theta_err(r: &TraceRow, j: usize) -> f64 {
    if j < 8 {
        rel(r.theta_drive_est[j], r.theta_drive_true[j])
    } else {
        rel(r.theta_sense_est[j - 8], r.theta_sense_true[j - 8])
    }
}

/// Name of θ component j.
pub fn theta_name(j: usize) -> String {
    if j < 8 {
        format!("θ1{}", j + 1)
    } else {
        format!("θ2{}", j - 7)
    }
}

/// The first time ≥ `t0` from which every θ stays within `tol` until `t_end`
/// (exclusive), or None.
pub fn all_within_from(trace: &[TraceRow], tol: f64, t0: f64, t_end: f64) -> Option<f64> {
    let rows: Vec<&TraceRow> = trace
        .iter()
        .filter(|r| r.t_s >= t0 && r.t_s < t_end)
        .collect();
    let bad = rows
        .iter()
        .rposition(|r| (0..14).any(|j| theta_err(r, j).is_nan() || theta_err(r, j) >= tol));
    match bad {
        None => Some(t0),
        Some(i) if i + 1 == rows.len() => None,
        Some(i) => Some(rows[i + 1].t_s),
    }
}
