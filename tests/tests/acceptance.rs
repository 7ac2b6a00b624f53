//! Acceptance of the foundation issue, from seeded runs of the built-in scenarios
//! (simulated gyro → f32 core, as on the chip). Limits from the issue / FINDINGS.md.

use paragyro_simulator::runner::Precision;
use paragyro_tests::{all_within_from, rel, run_builtin, theta_err, theta_name};

/// `identify`, full length (10 s): every θ within 1e-3 except θ14 ≤ 2 % and θ17 ≤ 1 %;
/// rate within 0.3 % of 150 °/s; all θ within 10 % by 0.2 s after the dither starts.
/// The f64 instantiation runs beside it on the same data and meets the same limits.
#[test]
fn identify_full_length_f32_and_f64() {
    for precision in [Precision::F32, Precision::F64] {
        let r = run_builtin("identify", precision, None);
        let last = r.trace.last().unwrap();
        assert!((last.t_s - 10.0).abs() < 1e-9);
        for j in 0..14 {
            let lim = match j {
                3 => 0.02,
                6 => 0.01,
                _ => 1e-3,
            };
            let e = theta_err(last, j);
            assert!(
                e <= lim,
                "{precision:?}: {} error {e:.3e} > {lim:e}",
                theta_name(j)
            );
        }
        let re = rel(last.rate_dps_slow, 150.0);
        assert!(
            re <= 3e-3,
            "{precision:?}: rate {} °/s ({re:.2e})",
            last.rate_dps_slow
        );
        // all θ within 10 % by 0.2 s after the dither starts (t = 1 s), and stay there
        let t = all_within_from(&r.trace, 0.10, 1.0, 10.0).expect("never all within 10 %");
        assert!(
            t <= 1.2,
            "{precision:?}: all θ within 10 % only from {t:.3} s"
        );
        // no parameter change: the change detector stays quiet, no retune needed
        assert_eq!(r.summary.counters.resets_drive, 0, "{precision:?}");
        assert_eq!(r.summary.counters.resets_sense, 0, "{precision:?}");
    }
}

/// f32 stays close to f64 on the same data (ARCHITECTURE §5: f32 within 1.5× of the f64
/// errors). Error levels are rms over the last 2 s of a 6 s run (a single sample of a
/// noisy estimate says little), and every θ of the f32 core stays within a quarter of
/// its acceptance limit of the f64 one.
#[test]
fn f32_tracks_f64() {
    let a = run_builtin("identify", Precision::F32, Some(6.0));
    let b = run_builtin("identify", Precision::F64, Some(6.0));
    let rms = |r: &paragyro_simulator::trace::RunResult,
               f: &dyn Fn(&paragyro_simulator::trace::TraceRow) -> f64| {
        let rows: Vec<_> = r.trace.iter().filter(|x| x.t_s >= 4.0).collect();
        (rows.iter().map(|x| f(x).powi(2)).sum::<f64>() / rows.len() as f64).sqrt()
    };
    let rate = |x: &paragyro_simulator::trace::TraceRow| rel(x.rate_dps_est, 150.0);
    let (ea, eb) = (rms(&a, &rate), rms(&b, &rate));
    assert!(
        ea <= 1.5 * eb,
        "rms rate error f32 {ea:.2e} vs f64 {eb:.2e}"
    );
    for j in [3usize, 6] {
        let f = move |x: &paragyro_simulator::trace::TraceRow| theta_err(x, j);
        let (x, y) = (rms(&a, &f), rms(&b, &f));
        assert!(
            x <= 1.5 * y,
            "{}: rms error f32 {x:.2e} vs f64 {y:.2e}",
            theta_name(j)
        );
    }
    let (la, lb) = (a.trace.last().unwrap(), b.trace.last().unwrap());
    for j in 0..14 {
        let lim = match j {
            3 => 0.02,
            6 => 0.01,
            _ => 1e-3,
        };
        let (x, y) = if j < 8 {
            (la.theta_drive_est[j], lb.theta_drive_est[j])
        } else {
            (la.theta_sense_est[j - 8], lb.theta_sense_est[j - 8])
        };
        let tru = if j < 8 {
            la.theta_drive_true[j]
        } else {
            la.theta_sense_true[j - 8]
        };
        let d = rel(x, tru) - rel(y, tru);
        assert!(
            d.abs() <= 0.25 * lim,
            "{}: f32 {x:e} vs f64 {y:e}",
            theta_name(j)
        );
    }
}

/// `drift-retune`: ω̂y² within 1e-4 of 1.03 by 0.5 s after the ramp ends (t = 3 s) and
/// from then on; sense amplitude after the retune ≥ before the drift (prototype 109 %);
/// the twin without retune reports the loss (prototype 52 %).
#[test]
fn drift_retune() {
    let r = run_builtin("drift-retune", Precision::F32, None);
    assert_drift_retune_targets(&r, "drift-retune");
}

/// `drift-retune` while the rate moves (issue 10): the same drift and targets with a
/// 5 Hz ±50 °/s sine on the 150 °/s from start-up to the end
/// (`host-sim/scenarios/drift-retune-rate-sine.toml`). The slow RLS takes the rate as a
/// random walk (`rate.walk_dps`): with the rate a constant of the slow RLS the estimate
/// does not settle under the sine and does not retune. At most 30 resets here (18
/// measured; the drift's own re-identification takes 13 on `drift-retune`).
#[test]
fn drift_retune_while_the_rate_moves() {
    let r = run_scenario_file("drift-retune-rate-sine.toml");
    assert_drift_retune_targets(&r, "drift-retune-rate-sine");
    let c = &r.summary.counters;
    assert!(
        c.resets_sense + c.resets_drive <= 30,
        "{} + {} covariance resets",
        c.resets_sense,
        c.resets_drive
    );
}

/// A rate step on a settled device (`host-sim/scenarios/rate-step.toml`: 150 → 100 °/s at
/// 3 s): the slow RLS is gated through the step, and its own departure from the new rate
/// kept renewing the gate, so it held the old rate to the end (`rate_dps_slow` 149.97, gated
/// on 99.9 % of the samples after the step). Once the narrow channel's rate is still, a
/// hand-over gives the slow RLS its averaged rate: from 2 s after the step the slow rate must
/// be within the gate's deviation (`rate.gate_dev_dps`, 1 °/s) of 100 and ungated, without
/// a covariance reset, and the fast rate within 1 % from 25 ms after the step (0.1 s means).
#[test]
fn the_slow_rate_takes_a_step_after_a_hold() {
    let r = run_scenario_file("rate-step.toml");
    const GATED: u32 = 1 << 6;
    assert_eq!(paragyro_simulator::trace::HEALTH_NAMES[6], "gated");
    for row in &r.trace {
        if row.t_s >= 5.0 {
            assert!(
                (row.rate_dps_slow - 100.0).abs() < 1.0 && row.health & GATED == 0,
                "t = {:.3} s: slow rate {} °/s, health {:#b}",
                row.t_s,
                row.rate_dps_slow,
                row.health
            );
        }
    }
    // the fast rate, averaged over 0.1 s windows (its per-sample noise is 0.24 °/s rms)
    let after: Vec<_> = r.trace.iter().filter(|row| row.t_s >= 3.025).collect();
    for w in after.chunks(50) {
        let mean = w.iter().map(|row| row.rate_dps_est).sum::<f64>() / w.len() as f64;
        assert!(
            (mean - 100.0).abs() <= 0.5,
            "fast rate {mean} °/s over {:.3}–{:.3} s",
            w[0].t_s,
            w[w.len() - 1].t_s
        );
    }
    assert_eq!(r.trace.last().map(|row| row.resets), Some(0));
}

/// A run (f32, the file's seed) of a scenario file of `host-sim/scenarios/` that is not
/// built in.
fn run_scenario_file(name: &str) -> paragyro_simulator::trace::RunResult {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../host-sim/scenarios")
        .join(name);
    let sc = paragyro_simulator::scenario::Scenario::from_file(&path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let opts = paragyro_simulator::runner::RunOptions {
        precision: Precision::F32,
        seed: None,
    };
    paragyro_simulator::runner::run(&sc, &opts, &mut |_| {}).expect("run failed")
}

/// The targets of `drift-retune` (above) on a run of it.
fn assert_drift_retune_targets(r: &paragyro_simulator::trace::RunResult, name: &str) {
    for row in r.trace.iter().filter(|row| row.t_s >= 3.0) {
        let e = rel(row.phys_est[4], 1.03);
        assert!(
            e <= 1e-4,
            "{name}: ω̂y² = {} at t = {:.3} s ({e:.2e})",
            row.phys_est[4],
            row.t_s
        );
    }
    let s = &r.summary;
    let before = s.measure("sense_amp_before_drift").unwrap();
    let after_drift = s.measure("sense_amp_after_drift").unwrap();
    let after_retune = s.measure("sense_amp_after_retune").unwrap();
    assert!(
        (before - 1.496).abs() < 0.01,
        "{name}: before drift {before}"
    );
    assert!(
        after_retune >= before,
        "{name}: after retune {after_retune} < before {before}"
    );
    let loss = after_drift / before;
    assert!(
        loss < 0.6 && loss > 0.45,
        "{name}: twin without retune: {loss:.3} of the amplitude (prototype 0.52)"
    );
    assert!(s.counters.retunes >= 1, "{name}: no retune happened");
    assert!(
        s.counters.resets_sense >= 1,
        "{name}: the drift was not detected"
    );
    let wy2 = s.wy2_est_final;
    assert!(rel(wy2, 1.03) < 1e-5, "{name}: final ω̂y² {wy2}");
    // the pump centre now sits at 2·sqrt(ω̂y²)·f0
    let f0 = paragyro_simulator::scenario::DEFAULT_F0_HZ;
    let centre = s.pump_centre_final_hz;
    assert!(
        (centre - 2.0 * 1.03f64.sqrt() * f0).abs() < 1.0,
        "{name}: pump centre {centre} Hz"
    );
}

/// `paper-switch`: after each switch every θ within 10 % within 1.5 s; θ14 and θ17
/// within 5 % at the end.
#[test]
fn paper_switch() {
    let r = run_builtin("paper-switch", Precision::F32, None);
    for (ts, te) in [(3.0, 6.0), (6.0, 9.0 + 1e-9)] {
        let t = all_within_from(&r.trace, 0.10, ts, te).unwrap_or(f64::INFINITY);
        assert!(
            t - ts <= 1.5,
            "switch at {ts} s: all θ within 10 % only after {:.3} s",
            t - ts
        );
    }
    let last = r.trace.last().unwrap();
    for j in [3, 6] {
        let e = theta_err(last, j);
        assert!(e <= 0.05, "{} at the end: {e:.3e}", theta_name(j));
    }
}

/// The rate's zero (μ̂xy, core `rate.zero_memory_s`) is held with a long memory: on a
/// static 60 s run at 150 °/s the rate's Allan deviation at τ = 3 s is under a third of
/// what it is when the rate takes the slow RLS's 2 s μ̂xy every sample (its wander, the
/// drive's θ14, is the low-frequency noise the hold removes), and no covariance resets.
#[test]
fn the_rates_zero_is_held_out_of_its_low_frequencies() {
    use paragyro_simulator::rate_response::{T0_S, scenario, trace};
    let adev_3s = |memory_s: Option<f64>| {
        let mut sc = scenario("", T0_S + 60.0).unwrap();
        sc.estimator.rate_zero_memory_s = memory_s;
        let tr = trace(&sc, Precision::F32, 1).unwrap();
        assert_eq!(tr.last().unwrap().resets, 0, "{memory_s:?}: resets");
        let y: Vec<f64> = tr
            .iter()
            .filter(|r| r.t_s >= T0_S)
            .map(|r| r.rate_dps_est)
            .collect();
        let m = 1500; // 3 s at 500 Hz
        let mean = |a: &[f64]| a.iter().sum::<f64>() / a.len() as f64;
        let means: Vec<f64> = y.chunks_exact(m).map(mean).collect();
        let d2: Vec<f64> = means.windows(2).map(|w| (w[1] - w[0]).powi(2)).collect();
        (mean(&d2) / 2.0).sqrt()
    };
    let held = adev_3s(None);
    let direct = adev_3s(Some(0.0));
    assert!(
        held < direct / 3.0,
        "ADEV at 3 s: held zero {held:.4} °/s against {direct:.4} °/s without"
    );
}
