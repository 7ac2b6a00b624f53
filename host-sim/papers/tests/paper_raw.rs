//! The paper's own estimator (eqs. 10–19) on the raw fast signals: regression identity,
//! convergence on the nominal set, identifiability, and the literal ±50 % test.
//!
//! All runs are noise-free, as in the paper. About 3 s of simulated time in total
//! (≈ 1 µs per RK4 step of the 134-state ODE, 1.4–1.7 M steps per simulated second).

use paragyro_core::physics::{OMEGA0_TABLE2_RAD_S, TABLE2};
use paragyro_papers::paper_raw::{
    LambdaReading, Pump, RawConfig, RawRun, Segment, SwitchOptions, ZForm, identifiability,
    paper_sets, paper_switch, settle_time, simulate, symmetric_eigen, theta_rel_errors,
};
use paragyro_simulator::plant::Theta;

const NAMES: [&str; 14] = [
    "θ11", "θ12", "θ13", "θ14", "θ15", "θ16", "θ17", "θ18", "θ21", "θ22", "θ23", "θ24", "θ25",
    "θ26",
];

fn nominal() -> Theta {
    paper_sets(&TABLE2)[0]
}

fn pump_literal() -> f64 {
    1.0265f64.sqrt()
}

fn run_nominal(cfg: &RawConfig, duration_s: f64) -> RawRun {
    let seg = Segment {
        duration_s,
        theta: nominal(),
        omega: pump_literal(),
    };
    simulate(cfg, &[seg]).expect("valid configuration")
}

fn fmt(v: &[f64]) -> String {
    v.iter()
        .zip(NAMES)
        .map(|(e, n)| format!("{n} {e:.1e}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The paper's eq. (15)/(17) identity Z = Φᵀθ (Z = X with θ + [3, 2, 0, …], or Z = D²X/Λ
/// with θ) holds with the true θ on noise-free data: this checks the 16 state variables
/// (8 Λ-filtered signals and their derivatives), their inputs and the regressor order (eq. 25,
/// components 3↔4 swapped against eq. 17 as printed).
///
/// The joint RK4 step preserves the identity exactly: the residual obeys r'' + 3r' + 2r = 0
/// as a linear function of the state, which RK4 integrates as its own linear ODE, so after
/// the e^{−τ} start transient (X(0) = 0.01 with the filters at rest) only rounding is left
/// (measured ≈ 2e-16 relative). A θ in the printed eq. (8)/(17) order (3↔4) or θ12 off by
/// 1e-6 relative is seen at once.
#[test]
fn regression_identity_holds_with_the_true_theta() {
    let worst = |run: &RawRun| {
        // records after 2 ms (136 τ: the start transient is e^{-136})
        let mut w = [0.0f64; 2];
        for r in run.records.iter().filter(|r| r.t_s >= 2e-3) {
            for (a, wa) in w.iter_mut().enumerate() {
                *wa = wa.max(r.e_true_rms[a] / r.z_rms[a]);
            }
        }
        w
    };
    for z_form in [ZForm::Literal, ZForm::D2] {
        let cfg = RawConfig {
            z_form,
            ..RawConfig::default()
        };
        let w = worst(&run_nominal(&cfg, 0.03));
        println!(
            "{z_form:?}: rms(Z − Φᵀθ)/rms(Z) ≤ drive {:.1e}, sense {:.1e}",
            w[0], w[1]
        );
        assert!(w[0] < 1e-12 && w[1] < 1e-12, "{z_form:?}: {w:?}");
    }
    // sensitivity: the eq. (8) order, and a 1e-6 relative error in θ12
    let mut swapped = nominal();
    swapped.drive.swap(2, 3);
    swapped.sense.swap(2, 3);
    let mut off = nominal();
    off.drive[1] *= 1.0 + 1e-6;
    off.sense[1] *= 1.0 + 1e-6;
    for (what, model, min) in [
        ("eq. (8) order", swapped, 1e-4),
        ("θ12, θ22 × (1 + 1e-6)", off, 1e-7),
    ] {
        let cfg = RawConfig {
            model_theta: Some(model),
            ..RawConfig::default()
        };
        let w = worst(&run_nominal(&cfg, 0.03));
        println!("with {what}: drive {:.1e}, sense {:.1e}", w[0], w[1]);
        assert!(w[0] > min && w[1] > min, "{what}: {w:?}");
    }
}

/// The paper's set-up exactly (eq. 25 plant, pump at √1.0265, P0 = 1e4·I, θ̂(0) = 0,
/// λ = 0.2 per τ, estimation from the start-up at X(0) = 0.01, no noise): all 14 θ converge
/// within the first ms and stay at rounding-driven 1e-12…1e-8. This is the regime of the
/// paper's Figs 9–11 (time axis in ms).
#[test]
fn nominal_set_converges_with_the_papers_lambda() {
    let run = run_nominal(&RawConfig::default(), 0.1);
    let last = run.records.last().expect("records");
    let err = theta_rel_errors(last);
    let t1: Vec<f64> = (0..14)
        .map(|j| settle_time(&run.records, j, 0.01, 0.0, last.t_s).unwrap_or(f64::INFINITY))
        .collect();
    println!("λ = 0.2/τ, 0.1 s: {}", fmt(&err));
    println!(
        "within 1 % after (s): {t1:?}; blow-up {:?}",
        run.estimator_blowup_s
    );
    assert!(run.estimator_blowup_s.is_none());
    // measured ≤ 1.4e-8 (θ14); rounding amplified by the wound-up P, so a loose bound
    for (j, e) in err.iter().enumerate() {
        assert!(*e < 1e-6, "{}: {e:e}", NAMES[j]);
    }
    // measured: every θ within 1 % from the 1 ms record on
    assert!(t1.iter().all(|t| *t <= 2e-3), "{t1:?}");
    let (pe, pt) = paragyro_papers::paper_raw::physical_of(last);
    let rate = |g: f64| paragyro_core::physics::rate_dps_from_gamma(g, OMEGA0_TABLE2_RAD_S);
    println!(
        "rate {:.6} °/s (true {:.6})",
        rate(pe.gamma),
        rate(pt.gamma)
    );
    assert!((pe.gamma / pt.gamma - 1.0).abs() < 1e-6);
}

/// The same start-up with a memory of seconds (λ = 0.5/s: the product's 0.999 per 500 Hz
/// sample). Noise-free, so errors are pure identifiability: after 0.5 s
///
/// * θ12, θ16, θ18, θ22, θ26 ≤ 1e-4 and the rest ≤ 1 % (measured: θ11 3.1e-3, θ13 1.4e-3,
///   θ15 3.4e-3, θ21 1.7e-3, θ24 8.4e-3, θ25 7.6e-4, θ23 8.2e-5),
/// * **θ14 is not identified (14 %, never within 10 %) and θ17 only slowly (4.5 %, 0.25 %
///   after 3 s).**
///
/// Why: the paper's only excitation is the pump; in the periodic steady state the raw
/// regressors leave one drive direction with no information at all — θ14 = −(μxy − 2γ), the
/// Y' coefficient that carries the rate (scaled condition number ≈ 7e17, weakest eigenvector
/// 0.999 along θ14) — and next a θ11/θ13 mix and θ17; in the sense axis θ24 = −(μxy + 2γ)
/// (≈ 1e14), then a θ21/θ23 mix and θ25. Only the start-up transient (first ~30 ms) carries
/// information on θ14, and with P0 = 1e4·I its weight is not enough. With λ = 0.2/τ the
/// estimate converges during the start-up (previous test) and, noise-free, nothing pulls it
/// away afterwards.
#[test]
fn nominal_set_with_slow_forgetting_leaves_theta14_unidentified() {
    let w0 = OMEGA0_TABLE2_RAD_S;
    let cfg = RawConfig {
        lambda_per_tau: LambdaReading::Product2s.per_tau(w0),
        info_window_s: Some((0.3, 0.5)),
        ..RawConfig::default()
    };
    let run = run_nominal(&cfg, 0.5);
    let last = run.records.last().expect("records");
    let err = theta_rel_errors(last);
    println!("λ = 0.5/s, 0.5 s: {}", fmt(&err));
    let tight = [1, 5, 7, 9, 13]; // θ12, θ16, θ18, θ22, θ26
    for j in 0..14 {
        let bound = if tight.contains(&j) {
            1e-4
        } else if j == 3 || j == 6 {
            continue;
        } else {
            1e-2
        };
        assert!(err[j] < bound, "{}: {:e} ≥ {bound:e}", NAMES[j], err[j]);
    }
    assert!(
        err[3] > 0.07 && err[3] < 0.3,
        "θ14 {:e} (measured 0.14)",
        err[3]
    );
    assert!(
        settle_time(&run.records, 3, 0.1, 0.0, last.t_s).is_none(),
        "θ14 never within 10 %"
    );
    assert!(
        err[6] > 0.01 && err[6] < 0.15,
        "θ17 {:e} (measured 0.045)",
        err[6]
    );

    // steady-state information, 0.3–0.5 s
    let th = nominal();
    let d = identifiability(run.info_drive.as_ref().expect("info"), &th.drive);
    let s = identifiability(run.info_sense.as_ref().expect("info"), &th.sense);
    println!(
        "steady state: drive cond {:.2e}, weakest θ1{:?}, direction {:?}",
        d.condition, d.weakest_components, d.weakest_directions[0]
    );
    println!(
        "steady state: sense cond {:.2e}, weakest θ2{:?}, direction {:?}",
        s.condition, s.weakest_components, s.weakest_directions[0]
    );
    assert!(d.condition > 1e15, "{:e}", d.condition);
    assert!(s.condition > 1e12, "{:e}", s.condition);
    assert_eq!(
        d.weakest_components[0], 4,
        "drive: θ14 is the blind direction"
    );
    assert_eq!(
        s.weakest_components[0], 4,
        "sense: θ24 is the blind direction"
    );
    assert!(d.weakest_directions[0][3].abs() > 0.99);
    assert!(s.weakest_directions[0][3].abs() > 0.95);
    assert_eq!(d.weakest_components[2], 7, "drive: θ17 third weakest");
    assert_eq!(s.weakest_components[2], 5, "sense: θ25 third weakest");
}

/// The literal ±50 % test: the pump stays at √1.0265, the +50 % set moves the drive's
/// natural frequency to √1.5678 ≈ 1.25, out of the parametric band, and the drive dies
/// (FINDINGS §3.5): below 1 % of its nominal amplitude 85 ms after the switch (measured,
/// 1 ms records), 2e-4 at the end of the set. The paper's estimator (λ = 0.2/τ, the plant's
/// step) does not survive the switch: its covariance, wound up to trace ≈ 4e11 during the
/// steady state, meets a regressor that leaves the old subspace, and the explicit RK4 step
/// diverges within a few steps (overflow right at the switch).
#[test]
fn literal_switch_kills_the_drive() {
    let opts = SwitchOptions {
        segment_s: 0.2,
        ..SwitchOptions::new(Pump::Literal, LambdaReading::PaperPerTau)
    };
    let r = paper_switch(&opts).expect("runs");
    let after = r.drive_below_1pct_after_s;
    println!(
        "nominal drive {:.4}, below 1 % after {after:?} s, end of +50 %: {:.2e}, end of −50 %: {:.2e}; \
         estimator blow-up {:?}, RK4 limit exceeded {:?}",
        r.drive_amp_nominal,
        r.drive_amp_rel_end[0],
        r.drive_amp_rel_end[1],
        r.run.estimator_blowup_s,
        r.run.rk4_limit_exceeded_s
    );
    assert!(
        (r.drive_amp_nominal - 1.75).abs() < 0.05,
        "{}",
        r.drive_amp_nominal
    );
    let after = after.expect("the drive must collapse");
    assert!(after > 0.05 && after < 0.12, "{after} (measured 0.085)");
    assert!(r.drive_amp_rel_end[0] < 1e-2 && r.drive_amp_rel_end[1] < 1e-2);
    // the sense loses its Coriolis drive with it
    assert!(r.segments[1].sense_amp_end < 1e-2 * r.segments[0].sense_amp_end);
    // nominal set identified before the switch …
    assert!(r.segments[0].final_rel_err.iter().all(|e| *e < 1e-6));
    // … and the estimator diverges at a switch (measured: within 10 µs of the second one,
    // 0.4 s, with 0.2 s sets; at the first one with 0.5 s sets)
    let t = r.run.estimator_blowup_s.expect("blow-up");
    let near = r.run.segment_starts_s[1..]
        .iter()
        .any(|s| t >= *s && t < s + 1e-3);
    assert!(near, "blow-up at {t} not at a switch");
    assert!(r.run.rk4_limit_exceeded_s.is_some_and(|e| e <= t));
}

/// On the paper's time scale (50 ms per set; its figures run in ms) the paper's estimator
/// tracks all three sets noise-free, literal pump or not, to ≤ 1e-7 within 2 ms of each switch.
/// With the pump re-centred and 0.2 s per set, the explicit step at the plant's h blows up at
/// the second switch (P wound up during the steady state), while 4× finer steps survive
/// (checked in the report: 512 steps/period tracks 0.5 s sets to ≤ 2e-6).
#[test]
fn paper_time_scale_tracks_long_sets_blow_up() {
    for pump in [Pump::Literal, Pump::Recentred] {
        let r =
            paper_switch(&SwitchOptions::ms_scale(pump, LambdaReading::PaperPerTau)).expect("runs");
        assert!(r.run.estimator_blowup_s.is_none(), "{pump:?}");
        for s in &r.segments {
            let worst = s.final_rel_err.iter().copied().fold(0.0, f64::max);
            let t10 = s
                .within_10pct_s
                .iter()
                .map(|t| t.unwrap_or(f64::INFINITY))
                .fold(0.0, f64::max);
            println!(
                "{pump:?} {}: worst {worst:.1e}, all within 10 % after {t10:.4} s",
                s.label
            );
            assert!(worst < 1e-7, "{pump:?} {}: {worst:e}", s.label);
            assert!(t10 < 2e-3, "{pump:?} {}: {t10}", s.label);
        }
    }
    let opts = SwitchOptions {
        segment_s: 0.2,
        ..SwitchOptions::new(Pump::Recentred, LambdaReading::PaperPerTau)
    };
    let r = paper_switch(&opts).expect("runs");
    println!(
        "variant, 0.2 s sets: blow-up {:?}, drive at the end of each set {:?}",
        r.run.estimator_blowup_s,
        r.segments
            .iter()
            .map(|s| s.drive_amp_end)
            .collect::<Vec<_>>()
    );
    // the re-centred pump keeps the drive alive …
    assert!(r.segments.iter().all(|s| s.drive_amp_end > 1.0));
    // … the estimator at the plant's step does not survive a switch
    let t = r.run.estimator_blowup_s.expect("blow-up");
    assert!((t - 0.4).abs() < 1e-3 || (t - 0.2).abs() < 1e-3, "{t}");
}

/// The paper's P0 = 1e4·I on a gyro that is already running (|Φ|² ≈ 0.5): h·ΦᵀP0Φ ≈ 670,
/// far beyond RK4's stability limit, and the estimator overflows within microseconds. The
/// paper's set-up only works because estimation starts with the start-up, when Φ is small.
#[test]
fn papers_p0_on_a_running_gyro_diverges() {
    let cfg = RawConfig {
        estimator_start_s: 0.3,
        ..RawConfig::default()
    };
    let run = run_nominal(&cfg, 0.31);
    let first = run
        .records
        .iter()
        .find(|r| r.t_s > 0.3 + 1e-9)
        .expect("records");
    println!(
        "h·ΦᵀP0Φ in the first ms: {:?}; RK4 limit exceeded {:?}, blow-up {:?}",
        first.h_phi_p_phi_max, run.rk4_limit_exceeded_s, run.estimator_blowup_s
    );
    assert!(first.h_phi_p_phi_max[0] > 100.0);
    let t = run.estimator_blowup_s.expect("blow-up");
    assert!(t > 0.3 && t < 0.3 + 1e-4, "{t}");
}

/// The λ readings and the Jacobi eigen-solver used for identifiability.
#[test]
fn lambda_readings_and_eigen_solver() {
    let w0 = OMEGA0_TABLE2_RAD_S;
    let l = LambdaReading::PaperPerTau;
    assert_eq!(l.per_tau(w0), 0.2);
    assert!((l.memory_s(w0) - 73.7e-6).abs() < 0.1e-6);
    assert!((LambdaReading::PerSecond.per_tau(w0) - 2.947e-6).abs() < 1e-9);
    assert!((LambdaReading::PerSecond.memory_s(w0) - 5.0).abs() < 1e-12);
    let p = LambdaReading::Product2s;
    assert!((p.per_tau(w0) - 7.372e-6).abs() < 1e-9);
    assert!(((-p.per_tau(w0) * w0 / 500.0).exp() - 0.999).abs() < 1e-15);

    let a = [4.0, 1.0, 0.0, 1.0, 3.0, 1.0, 0.0, 1.0, 2.0];
    let (vals, vecs) = symmetric_eigen(&a, 3);
    // eigenvalues of this matrix: 3 ± √3 and 3
    let expect = [3.0 + 3f64.sqrt(), 3.0, 3.0 - 3f64.sqrt()];
    for (v, e) in vals.iter().zip(expect) {
        assert!((v - e).abs() < 1e-12, "{vals:?}");
    }
    for (v, x) in vals.iter().zip(&vecs) {
        for i in 0..3 {
            let ax: f64 = (0..3).map(|k| a[3 * i + k] * x[k]).sum();
            assert!((ax - v * x[i]).abs() < 1e-12);
        }
    }
}
