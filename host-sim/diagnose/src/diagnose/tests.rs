use std::f64::consts::TAU;

use super::columns::{NSYN, ProjTables};
use super::lsq::solve_spd;

#[test]
fn projection_of_known_waveforms() {
    // f = 1 + 2cos φ − 3 sin 3φ → [f]0 = 1, [f]1 = 2, [f]3 = 3i (e^{−ikφ} convention)
    let mut f = [0.0; NSYN];
    for j in 0..NSYN {
        let ph = TAU * j as f64 / NSYN as f64;
        f[j] = 1.0 + 2.0 * ph.cos() - 3.0 * (3.0 * ph).sin();
    }
    let p = ProjTables::new().project(&f);
    for (a, b) in p.iter().zip([1.0, 2.0, 0.0, 0.0, 3.0]) {
        assert!((a - b).abs() < 1e-12, "{p:?}");
    }
}

#[test]
fn spd_solver_handles_collinear_columns() {
    // two identical columns: the solve must stay finite and reproduce b
    let g = [2.0, 2.0, 2.0, 2.0];
    let (x, _) = solve_spd(&g, &[4.0, 4.0], 2);
    assert!(x.iter().all(|v| v.is_finite()));
    assert!((2.0 * x[0] + 2.0 * x[1] - 4.0).abs() < 1e-6, "{x:?}");
    let g = [4.0, 1.0, 1.0, 3.0];
    let (x, inv) = solve_spd(&g, &[1.0, 2.0], 2);
    assert!((4.0 * x[0] + x[1] - 1.0).abs() < 1e-9 && (x[0] + 3.0 * x[1] - 2.0).abs() < 1e-9);
    assert!((inv[0] - 3.0 / 11.0).abs() < 1e-9);
}

/// The rows' noise profile has mean 1 (the totals against the noise are those of one level
/// for all rows) and every entry positive.
#[test]
fn noise_row_profile_has_mean_one() {
    let p = super::NOISE_ROW_PROFILE;
    let mean = p.iter().sum::<f64>() / p.len() as f64;
    assert!((mean - 1.0).abs() < 1e-3, "mean {mean}");
    assert!(p.iter().all(|&v| v > 0.0));
}

/// The rows' scatter at the noise is positive on every row and below the row's mean
/// energy (`NOISE_ROW_PROFILE` × 1.030, the mean the profile was normalised by).
#[test]
fn noise_row_scatter_is_positive_and_below_each_rows_level() {
    for (s, p) in super::NOISE_ROW_SCATTER
        .iter()
        .zip(super::NOISE_ROW_PROFILE)
    {
        assert!(*s > 0.0 && *s < 1.030 * p, "scatter {s} against level {p}");
    }
}

/// The confirmation's budget is counted in seconds of record: as many whole-record runs as
/// `CONFIRM_BUDGET_S` holds, at least `CONFIRM_RUNS`; a budget the caller sets stands.
#[test]
fn the_budget_of_runs_follows_the_records_length() {
    use super::Options;
    use super::confirm::{CONFIRM_BUDGET_S, CONFIRM_RUNS};
    let o = Options::default();
    assert_eq!((CONFIRM_BUDGET_S, CONFIRM_RUNS), (120.0, 2));
    let runs: Vec<usize> = [60.0, 20.0, 30.0, 40.0, 19.99, 300.0, 0.0, f64::NAN]
        .iter()
        .map(|&d| o.confirm_runs_for(d))
        .collect();
    assert_eq!(runs, [2, 6, 4, 3, 6, 2, 2, 2]);
    let set = Options {
        confirm_runs: Some(1),
        ..Options::default()
    };
    assert_eq!(set.confirm_runs_for(20.0), 1);
}
