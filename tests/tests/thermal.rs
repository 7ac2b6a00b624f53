//! Temperature: a warm-up is followed as a drift (no covariance reset, the rate valid), a
//! jump is still detected and retuned (`core/src/drift.rs`); with the die temperature in
//! the samples the modes' coefficients are learned, a temperature cycle is followed, and a
//! warm start at another temperature starts at 2·f_y there (`core/src/thermal.rs`). The
//! runs are the scenario's seed (1) but where a test names its seeds.

use std::any::Any;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use paragyro_core::persist::Start;
use paragyro_simulator::runner::{Precision, RunOptions, closed_loop, core_config, run};
use paragyro_simulator::scenario::{EventKind, Scenario};
use paragyro_simulator::trace::{RunResult, TraceRow};

fn run_f32(sc: &Scenario) -> RunResult {
    let opts = RunOptions {
        precision: Precision::F32,
        seed: None,
    };
    run(sc, &opts, &mut |_| {}).expect("run failed")
}

/// What `make` gives for `sc`, made once per test binary: several tests read the same runs
/// (the warm-up as written, and without its sensor) and the same oracle. Keyed by `what`
/// and the scenario as printed; a test asking while another makes it waits for it.
fn shared<T: Send + Sync + 'static>(what: &str, sc: &Scenario, make: impl FnOnce() -> T) -> Arc<T> {
    type Cell = Arc<OnceLock<Arc<dyn Any + Send + Sync>>>;
    static CELLS: OnceLock<Mutex<HashMap<String, Cell>>> = OnceLock::new();
    let cell = CELLS
        .get_or_init(Default::default)
        .lock()
        .unwrap()
        .entry(format!("{what} {sc:?}"))
        .or_default()
        .clone();
    let v = cell.get_or_init(|| Arc::new(make()) as Arc<dyn Any + Send + Sync>);
    v.clone().downcast::<T>().expect("one type per key")
}

/// [`run_f32`] of `sc`, shared between the tests (see [`shared`]).
fn run_shared(sc: &Scenario) -> Arc<RunResult> {
    shared("run f32", sc, || run_f32(sc))
}

/// The oracle twin's sense amplitude for `sc` on its seed, shared between the tests.
fn oracle_shared(sc: &Scenario) -> Arc<Vec<(f64, f64)>> {
    shared("oracle", sc, || {
        paragyro_simulator::thermal::oracle_sense_amp(sc, sc.seed).expect("oracle")
    })
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
    let r = run_shared(&sc);
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
    let valid = valid_share(&r, 5.0, 25.0);
    assert!(
        valid >= 0.99,
        "rate valid on {:.1} % of the ramp",
        100.0 * valid
    );
    // the identified ω_y² follows the truth through the ramp
    let worst = ramp
        .iter()
        .map(|x| (x.phys_est[4] - x.phys_true[4]).abs())
        .fold(0.0, f64::max);
    assert!(worst < 3e-6, "ω̂y² {worst:e} off during the warm-up");
    // the die temperature reaches the core (the scenario's ADXL355-like sensor): one
    // 10 K ramp teaches both frequency coefficients to within 2 ppm/K
    let tcf = last.tcf_ppm_k;
    assert!(
        (tcf[0] + 30.0).abs() < 2.0 && (tcf[1] + 33.0).abs() < 2.0,
        "learned TCFs {tcf:?} ppm/K (truth −30, −33)"
    );

    // without the sensor the walk alone follows the same ramp
    sc.temperature.as_mut().expect("a profile").sensor = false;
    let walk = run_shared(&sc);
    assert_eq!(resets_after(&walk, 2.5), 0, "resets without the sensor");
    assert!(
        walk.trace
            .iter()
            .all(|x| x.tcf_ppm_k.iter().all(|v| v.is_nan()))
    );
    // and without drift tracking either, the detector reads it as jumps
    sc.estimator.drift_kappa = Some(0.0);
    let off = run_f32(&sc);
    let resets = off.trace.last().expect("a trace").resets;
    assert!(resets > 50, "{resets} resets without drift tracking");
}

#[test]
fn the_warm_up_onset_is_not_a_cascade_of_resets_on_any_seed() {
    // before its coefficient is learned, the temperature's rate opens the walk (core
    // `thermal`): the ramp's sudden onset is followed, not read as jumps that cascade. On
    // seeds 2 and 5 the narrow rate channel's in-phase deviation crosses its gate before
    // the quadrature's at the onset: the gate that opens ends as the quadrature departs too
    // (core `rate`, a drift, not a move of the rate); held for its whole 0.3 s, the change
    // detector would reset both axes at its end. Without the sensor the walk alone holds
    // the onset on every seed: the wander learned before a reset is kept (relearned from
    // the drifting device, it would take the drift for wander and each reset would bring
    // the next) and the drive walks with the sense's drift (core `drift`).
    // the twelve runs on the machine's cores (each one thread), in this order
    let cases: Vec<(u64, bool)> = (1..=6)
        .flat_map(|seed| [(seed, true), (seed, false)])
        .collect();
    let next = std::sync::atomic::AtomicUsize::new(0);
    let done = Mutex::new(Vec::new());
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get().min(cases.len()));
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some(&(seed, sensor)) = cases.get(i) else {
                        break;
                    };
                    let mut sc = warm_up();
                    sc.seed = seed;
                    sc.temperature.as_mut().expect("a profile").sensor = sensor;
                    let r = run_shared(&sc);
                    let w = (
                        seed,
                        sensor,
                        resets_after(&r, 2.5),
                        valid_share(&r, 5.0, 25.0),
                    );
                    done.lock().unwrap().push((i, w));
                }
            });
        }
    });
    let mut done = done.into_inner().unwrap();
    done.sort_by_key(|d| d.0);
    let seen: Vec<_> = done.into_iter().map(|d| d.1).collect();
    assert_eq!(seen.len(), cases.len());
    assert!(
        seen.iter().all(|w| w.2 == 0 && w.3 >= 0.99),
        "(seed, sensor, resets, rate valid during the ramp): {seen:?}"
    );
}

#[test]
fn without_the_die_temperature_a_slow_warm_up_is_followed_by_the_walk_alone() {
    // 10 K over 100 s (0.1 K/s; ω_x² −6.0 ppm/s, ω_y² −6.6 ppm/s) without the sensor: the
    // drive's drift does not stand out of its own wander, and with the forgetting alone
    // its lag would reach the change detector; the drive walks with the sense's measured
    // drift, and a reset keeps the wander (core `drift`).
    let mut sc = warm_up();
    let t = sc.temperature.as_mut().expect("a profile");
    t.points = vec![[0.0, 25.0], [5.0, 25.0], [105.0, 35.0]];
    t.sensor = false;
    sc.duration_s = 107.0;
    let r = run_f32(&sc);
    assert_eq!(resets_after(&r, 2.5), 0, "resets during the ramp");
    let valid = valid_share(&r, 5.0, 105.0);
    assert!(
        valid >= 0.99,
        "rate valid on {:.2} % of the ramp",
        100.0 * valid
    );
    // the drive walks with the sense's measured drift (θ22 = −(ω_y² − γ²) rising at
    // 6.6 ppm/s of itself)
    let mid = r.trace.iter().find(|x| x.t_s >= 55.0).expect("in the run");
    let [d12, d22] = mid.drift_ppm_s;
    assert!(
        d12 == d22 && (d22 - 6.6).abs() < 1.0,
        "{:?}",
        mid.drift_ppm_s
    );
}

/// The share of the samples in [from, to) s whose rate is flagged valid.
fn valid_share(r: &RunResult, from: f64, to: f64) -> f64 {
    let span: Vec<_> = r
        .trace
        .iter()
        .filter(|x| (from..to).contains(&x.t_s))
        .collect();
    span.iter().filter(|x| x.rate_valid).count() as f64 / span.len() as f64
}

/// Covariance resets after `t_s`.
fn resets_after(r: &RunResult, t_s: f64) -> u32 {
    let at = r.trace.iter().find(|x| x.t_s >= t_s).expect("in the run");
    r.trace.last().expect("a trace").resets - at.resets
}

/// The warm-up, then back: 25 → 35 °C over 5–25 s, held 5 s, 35 → 25 °C over 30–50 s.
fn cycle() -> Scenario {
    let mut sc = warm_up();
    sc.duration_s = 52.0;
    let t = sc.temperature.as_mut().expect("a profile");
    t.points = vec![
        [0.0, 25.0],
        [5.0, 25.0],
        [25.0, 35.0],
        [30.0, 35.0],
        [50.0, 25.0],
    ];
    sc
}

#[test]
fn a_temperature_cycle_is_followed_with_the_die_temperature() {
    let mut sc = cycle();
    let r = run_f32(&sc);
    assert_eq!(resets_after(&r, 2.5), 0, "resets over the cycle");
    let ramps: Vec<&TraceRow> = r
        .trace
        .iter()
        .filter(|x| (5.0..25.0).contains(&x.t_s) || (30.0..50.0).contains(&x.t_s))
        .collect();
    let valid = ramps.iter().filter(|x| x.rate_valid).count() as f64 / ramps.len() as f64;
    assert!(
        valid >= 0.95,
        "rate valid on {:.1} % of the ramps",
        100.0 * valid
    );
    // without the sensor the cooling ramp's sudden onset (0 → −33 ppm/s within a sample,
    // before its drift stands out) sets the change detector off; its level crosses the
    // threshold by little (a lag that grew), so the drift column alone is re-opened and
    // walks (core `drift`, `DriftTracker::open`) instead of a reset, which would bring the
    // next: the resets come faster than the quiet windows after each
    sc.temperature.as_mut().expect("a profile").sensor = false;
    let walk = run_f32(&sc);
    let last = walk.trace.last().expect("a trace");
    assert_eq!(
        resets_after(&walk, 2.5),
        0,
        "resets over the cycle without the sensor"
    );
    assert!(
        last.drift_alarms >= 1,
        "the onset's alarm was not read as a drift"
    );
    let valid = valid_share(&walk, 30.0, 50.0);
    assert!(
        valid >= 0.98,
        "rate valid on {:.1} % of the cooling ramp without the sensor",
        100.0 * valid
    );
}

#[test]
fn a_ramp_onset_held_through_a_rate_gate_is_taken_up_by_its_column() {
    // the 10 K warm-up from 30.4 s on seed 4 without the sensor: at the sudden onset the
    // narrow rate channel's deviation opens the rate gate, which holds the slow RLS for
    // 0.3 s while the drift goes on; at the gate's end the detector's level crosses its
    // threshold by 18.5× on the sense (a jump's innovations cross by orders more). The
    // alarm re-opens the drift column alone (`monitor::DRIFT_MARGIN`): no reset (resetting
    // both axes there sets off a run of resets that lasts the ramp)
    let mut sc = warm_up();
    sc.seed = 4;
    sc.duration_s = 52.4;
    let t = sc.temperature.as_mut().expect("a profile");
    t.points = vec![[0.0, 25.0], [30.4, 25.0], [50.4, 35.0]];
    t.sensor = false;
    let r = run_f32(&sc);
    let last = r.trace.last().expect("a trace");
    assert_eq!(resets_after(&r, 2.5), 0, "resets during the ramp");
    assert!(last.drift_alarms >= 1, "no alarm read as a drift");
    let valid = valid_share(&r, 30.4, 50.4);
    assert!(
        valid >= 0.97,
        "rate valid on {:.1} % of the ramp",
        100.0 * valid
    );
}

#[test]
fn a_2_k_warm_up_over_300_s_teaches_the_tcfs_without_resets() {
    // the slowest case: 0.0067 K/s, ω_y² moving 0.44 ppm/s
    let mut sc = warm_up();
    let t = sc.temperature.as_mut().expect("a profile");
    t.points = vec![[0.0, 25.0], [5.0, 25.0], [305.0, 27.0]];
    sc.duration_s = 307.0;
    let r = run_f32(&sc);
    assert_eq!(resets_after(&r, 2.5), 0, "resets during the ramp");
    let tcf = r.trace.last().expect("a trace").tcf_ppm_k;
    assert!(
        (tcf[0] + 30.0).abs() < 2.0 && (tcf[1] + 33.0).abs() < 2.0,
        "learned TCFs {tcf:?} ppm/K (truth −30, −33)"
    );
}

#[test]
fn a_warm_start_at_another_temperature_starts_at_its_2_f_y() {
    // a record written at the end of the warm-up (35 °C), the coefficients learned
    let sc = warm_up();
    let build = || core_config(&sc).build::<f32>().expect("configuration");
    let mut est = build();
    closed_loop(&sc, sc.seed, &mut est, |_| {}, |_| {}).expect("the warm-up");
    let rec = est.snapshot();
    assert!(
        (rec.temp_c - 35.0).abs() < 0.2,
        "written at {} °C",
        rec.temp_c
    );
    assert!(rec.dtheta_dt.iter().all(|v| v.is_finite()), "{rec:?}");
    // restored on a board that reads 25 °C: the pump on its first tick within 0.5 Hz of
    // twice the sense resonance at 25 °C (the record's own centre is 7 Hz away)
    let f0 = core_config(&sc).f0_hz;
    let two_fy = |t_s: f64| 2.0 * f0 * sc.plant_at(t_s).phys[4].sqrt();
    let (at_25, at_35) = (two_fy(0.0), two_fy(26.0));
    assert!((rec.pump_centre_hz - at_25).abs() > 5.0);
    let mut warm = build();
    assert_eq!(
        warm.boot_from_at(Some(&rec.encode()), Some(25.0)),
        Start::Warm
    );
    let off = warm.initial_pump_hz() - at_25;
    assert!(off.abs() < 0.5, "pump {off:+.3} Hz from 2·f_y(25 °C)");
    // without a reading at boot: the record as taken, at 35 °C's pump
    let mut blind = build();
    assert_eq!(blind.boot_from(Some(&rec.encode())), Start::Warm);
    assert!((blind.initial_pump_hz() - at_35).abs() < 2.5);
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
    let r = run_shared(&sc);
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
    // the ramp's sudden onset is its worst part (the drift tracker's lead catching up):
    // without its first 0.5 s the rms falls, and the mean is a share of the rms
    assert!(
        t.rate_err_rms_after_onset_dps < t.rate_err_rms_during_dps,
        "rms after the onset {} against {} during",
        t.rate_err_rms_after_onset_dps,
        t.rate_err_rms_during_dps
    );
    assert!(t.rate_err_mean_during_dps.abs() < t.rate_err_rms_during_dps);
    // the sense amplitude against the oracle twin whose pump sits at 2·f_y: ≥ 98 % at every
    // second of the warm-up
    let oracle = oracle_shared(&sc);
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
    assert!(md.contains("rms after its first 0.5 s / mean"), "{md}");
    // a scenario without a temperature profile has no thermal report
    let plain = Scenario::builtin("drift-retune").expect("built in");
    assert!(paragyro_simulator::thermal::ThermalReport::of(&plain, &r.trace).is_err());
}

/// Runs the warm-up `sc` (f32) and asserts the targets on it: no covariance reset
/// after the start-up, the rate valid on ≥ 99 % of the ramp, its error rms during the ramp
/// ≤ 1.2× its rms before it, the sense amplitude ≥ 98 % of the oracle twin's (pump at
/// 2·f_y) at every second. `case` names the case in the failure messages.
fn assert_warm_up_targets(sc: &Scenario, case: &str) {
    let r = run_shared(sc);
    let rep = paragyro_simulator::thermal::ThermalReport::of(sc, &r.trace).expect("a report");
    let oracle = oracle_shared(sc);
    let rep = rep.with_oracle(&r.trace, &oracle);
    let ratio = rep.rate_err_rms_during_dps / rep.rate_err_rms_before_dps;
    let what = format!(
        "{case}: resets {}, valid {:.1} %, error {:.2}×, sense {:?}",
        rep.resets_after_startup,
        100.0 * rep.valid_during,
        ratio,
        rep.sense_amp_vs_oracle_min
    );
    assert_eq!(rep.resets_after_startup, 0, "{what}");
    assert!(rep.valid_during >= 0.99, "{what}");
    assert!(ratio <= 1.2, "{what}");
    assert!(
        rep.sense_amp_vs_oracle_min.expect("whole seconds") >= 0.98,
        "{what}"
    );
}

/// The targets on the CI's short warm-up, 10 K over 20 s (seed 1, the scenario's):
/// at −30/−33 ppm/K with and without the die temperature and at equal TCFs with it, no
/// covariance reset after the start-up, the rate valid on ≥ 99 % of the ramp, its error
/// rms during the ramp ≤ 1.2× its rms before it, the sense amplitude ≥ 98 % of the oracle
/// twin's at every second. Measured (`cargo run --release -p paragyro-sim -- thermal`,
/// `--tcf-ppm-k -30,-30`, `--no-sensor`): 1.05×, 1.08×, 1.18×; the rate valid on 99.2 %.
/// Not on every seed: host-sim/docs/benchmarks.md ("These rows are the scenario's seed").
#[test]
fn a_20_s_warm_up_holds_the_rate_on_its_seed() {
    for (tcf_wy, sensor) in [(-33.0, true), (-30.0, true), (-33.0, false)] {
        let mut sc = warm_up();
        let t = sc.temperature.as_mut().expect("a profile");
        t.tcf_wy_ppm_k = tcf_wy;
        t.sensor = sensor;
        assert_warm_up_targets(&sc, &format!("TCF {tcf_wy}, sensor {sensor}"));
    }
}

/// The targets on the 10 K warm-up over 40 s, at −30/−33 ppm/K and with equal
/// TCFs (−30/−30), the die temperature in the samples: no covariance reset after the
/// start-up, the rate's error rms during the ramp ≤ 1.2× its rms before it, and the sense
/// amplitude ≥ 98 % of the oracle twin's (pump at 2·f_y) at every second, and the rate
/// valid on ≥ 99 % of the ramp.
#[test]
fn a_40_s_warm_up_holds_the_rate_at_both_tcfs() {
    for tcf_wy in [-33.0, -30.0] {
        let mut sc = warm_up();
        let t = sc.temperature.as_mut().expect("a profile");
        t.points = vec![[0.0, 25.0], [5.0, 25.0], [45.0, 35.0]];
        t.tcf_wy_ppm_k = tcf_wy;
        sc.duration_s = 47.0;
        assert_warm_up_targets(&sc, &format!("TCF {tcf_wy}"));
    }
}
