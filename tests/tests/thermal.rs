//! Temperature: a warm-up is followed as a drift (no covariance reset, the rate valid), a
//! jump is still detected and retuned (`core/src/drift.rs`).

use paragyro_simulator::runner::{Precision, RunOptions, run};
use paragyro_simulator::scenario::{EventKind, Scenario};
use paragyro_simulator::trace::RunResult;

fn run_f32(sc: &Scenario) -> RunResult {
    let opts = RunOptions {
        precision: Precision::F32,
        seed: None,
    };
    run(sc, &opts, &mut |_| {}).expect("run failed")
}

fn warm_up() -> Scenario {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../host-sim/scenarios/warm-up.toml"
    );
    Scenario::from_file(std::path::Path::new(path)).expect("warm-up.toml")
}

#[test]
fn a_10_k_warm_up_is_followed_as_a_drift_without_resets() {
    let mut sc = warm_up();
    let r = run_f32(&sc);
    let first = &r.trace[0];
    let last = r.trace.last().expect("a trace");
    // the plant moved with the die temperature: 10 K at −33 ppm/K is −660 ppm on ω_y²
    assert_eq!((first.temp_c, last.temp_c), (25.0, 35.0));
    let fy: f64 = 1.0 - 33e-6 * 10.0;
    assert!((last.phys_true[4] / first.phys_true[4] - fy * fy).abs() < 1e-12);
    // after start-up (2.5 s) not one covariance reset: the change detector reads the
    // warm-up as the drift it is
    let at = |t: f64| r.trace.iter().find(|x| x.t_s >= t).expect("in the run");
    assert_eq!(
        last.resets,
        at(2.5).resets,
        "covariance resets during the warm-up"
    );
    let ramp: Vec<_> = r
        .trace
        .iter()
        .filter(|x| (5.0..25.0).contains(&x.t_s))
        .collect();
    let valid = ramp.iter().filter(|x| x.rate_valid).count() as f64 / ramp.len() as f64;
    assert!(
        valid >= 0.95,
        "rate valid on {:.1} % of the ramp",
        100.0 * valid
    );
    // the identified ω_y² follows the truth through the ramp
    let worst = ramp
        .iter()
        .map(|x| (x.phys_est[4] - x.phys_true[4]).abs())
        .fold(0.0, f64::max);
    assert!(worst < 3e-6, "ω̂y² {worst:e} off during the warm-up");

    // the same warm-up without drift tracking: the detector reads it as jumps
    sc.estimator.drift_kappa = Some(0.0);
    let off = run_f32(&sc);
    let resets = off.trace.last().expect("a trace").resets;
    assert!(resets > 50, "{resets} resets without drift tracking");
}

#[test]
fn a_jump_of_the_sense_frequency_is_still_detected_and_retuned() {
    // drift-retune with its ωy² change made a jump: +0.3 % within 10 ms
    let mut sc = Scenario::builtin("drift-retune").expect("built in");
    for e in &mut sc.events {
        if let EventKind::Ramp { to, duration_s, .. } = &mut e.kind {
            *to = 1.0265 * 1.003;
            *duration_s = 0.01;
        }
    }
    let r = run_f32(&sc);
    let before = r
        .trace
        .iter()
        .find(|x| x.t_s >= 1.99)
        .expect("in the run")
        .resets;
    let after = r
        .trace
        .iter()
        .find(|x| x.t_s >= 2.3)
        .expect("in the run")
        .resets;
    assert!(after > before, "the jump was not detected");
    assert!(
        r.events
            .iter()
            .any(|e| e.what.contains("retune") && e.t_s > 2.0),
        "no retune after the jump"
    );
    let amp = r.summary.measures["sense_amp_after_retune"].expect("measured");
    // the pump back at 2ω_y: the sense amplitude of `drift-retune` after its retune
    assert!(amp > 1.6, "sense amplitude after the retune {amp}");
}

#[test]
fn the_thermal_report_reads_the_warm_up() {
    let sc = warm_up();
    let r = run_f32(&sc);
    let t = paragyro_simulator::thermal::ThermalReport::of(&sc, &r.trace).expect("a report");
    assert_eq!((t.change_s, t.temp_c), ((5.0, 25.0), (25.0, 35.0)));
    assert_eq!(t.resets_after_startup, 0);
    assert_eq!(t.bins.len(), 10);
    assert!(t.bins.iter().all(|b| b.samples == 1000));
    // the drift the core follows is the truth's: 2·33 ppm/K × 0.5 K/s = 33 ppm/s
    assert!(
        (t.wy2_rate_max_ppm_s - 33.0).abs() < 0.1,
        "{}",
        t.wy2_rate_max_ppm_s
    );
    assert!(
        (t.drift_th22_max_ppm_s / t.wy2_rate_max_ppm_s - 1.0).abs() < 0.2,
        "followed {} ppm/s",
        t.drift_th22_max_ppm_s
    );
    // the sense amplitude against the oracle twin whose pump sits at 2·f_y: ≥ 98 % at every
    // second of the warm-up
    let oracle = paragyro_simulator::thermal::oracle_sense_amp(&sc, sc.seed).expect("oracle");
    assert_eq!(oracle.len(), r.trace.len());
    let t = t.with_oracle(&r.trace, &oracle);
    let worst = t.sense_amp_vs_oracle_min.expect("20 whole seconds");
    assert!(
        worst >= 0.98,
        "sense amplitude {:.1} % of the oracle's",
        100.0 * worst
    );
    let md = t.markdown();
    assert!(
        md.contains("| covariance resets after start-up | 0 |"),
        "{md}"
    );
    assert!(md.contains("against the oracle twin's"), "{md}");
    // a scenario without a temperature profile has no thermal report
    let plain = Scenario::builtin("drift-retune").expect("built in");
    assert!(paragyro_simulator::thermal::ThermalReport::of(&plain, &r.trace).is_err());
}
