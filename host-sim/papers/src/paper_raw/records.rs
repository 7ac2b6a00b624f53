//! Helpers on records: relative θ errors, settling times and physical parameters.

use paragyro_core::physics::{Physical, physical_from_theta};

use super::simulate::RawRecord;

/// |est − true| / |true| (absolute error where the truth is 0; NaN stays NaN).
pub fn rel_err(est: f64, truth: f64) -> f64 {
    if truth != 0.0 {
        ((est - truth) / truth).abs()
    } else {
        (est - truth).abs()
    }
}

/// Relative errors of the 14 θ components of a record (θ11…θ18, θ21…θ26).
pub fn theta_rel_errors(r: &RawRecord) -> [f64; 14] {
    let mut out = [0.0; 14];
    for j in 0..8 {
        out[j] = rel_err(r.theta_drive_est[j], r.theta_drive_true[j]);
    }
    for j in 0..6 {
        out[8 + j] = rel_err(r.theta_sense_est[j], r.theta_sense_true[j]);
    }
    out
}

/// Time from `t0` after which the relative error of θ component `j` (0..14) stays below
/// `tol` up to and including `t1` (`Some(0)` if it always does, `None` if it is not below at
/// `t1`). Only records with `t0 < t ≤ t1` count.
pub fn settle_time(records: &[RawRecord], j: usize, tol: f64, t0: f64, t1: f64) -> Option<f64> {
    let win: Vec<&RawRecord> = records
        .iter()
        .filter(|r| r.t_s > t0 && r.t_s <= t1 + 1e-12)
        .collect();
    let bad = |r: &RawRecord| {
        let e = theta_rel_errors(r)[j];
        e.is_nan() || e >= tol
    };
    match win.iter().rposition(|r| bad(r)) {
        None => Some(0.0),
        Some(i) if i + 1 == win.len() => None,
        Some(i) => Some(win[i].t_s - t0),
    }
}

/// Physical parameters (corrected Table 3) of the estimate and of the truth of a record.
pub fn physical_of(r: &RawRecord) -> (Physical, Physical) {
    (
        physical_from_theta(&r.theta_drive_est, &r.theta_sense_est),
        physical_from_theta(&r.theta_drive_true, &r.theta_sense_true),
    )
}
