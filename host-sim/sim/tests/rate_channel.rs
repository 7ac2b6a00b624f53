//! The fast rate channel on seeded, short closed-loop runs (issue 10): step, sine and
//! chirp responses, no covariance reset and a quiet slow θ during rate moves, the rate's
//! validity flag when the drive loses its lock, and the rate noise against the
//! Cramér–Rao bound over a small Monte Carlo of seeds.

use paragyro_simulator::rate_response::{self, Options, T0_S};
use paragyro_simulator::runner::Precision;
use paragyro_simulator::summary::RateValidity;

fn opts(seed: u64) -> Options {
    Options {
        precision: Precision::F32,
        seed,
        allan_s: None,
        allan_zero_memory_s: None,
        allan_forgetting: None,
        allan_settle_s: 0.0,
        allan_warm_start: false,
    }
}

/// A 100 °/s step: the fast rate is within 1 % of the step from 25 ms on (issue 10's
/// target; 0.58 % at seed 1: the wide filter's curvature correction keeps the channel's
/// own tone at the pump dither out of the margin, core/src/rate.rs), no reset, the slow θ stay within a few σ of their steady-state scatter.
#[test]
fn step_response() {
    let (r, tr) = rate_response::step(&opts(1)).unwrap();
    assert!(r.max_err_after_25ms_pct < 1.0, "{r:?}");
    assert_eq!(r.resets, 0, "{r:?}");
    assert!(r.slow_theta_max_dev_sigma < 5.0, "{r:?}");
    // and it really moved: 20 ms after the step the fast rate is past 90 % of it, while
    // the slow one has not left the old rate
    let at = tr.iter().find(|x| x.t_s >= T0_S + 0.02).unwrap();
    assert!(at.rate_dps_est > 240.0, "{}", at.rate_dps_est);
    assert!(
        (at.rate_dps_slow - 150.0).abs() < 5.0,
        "{}",
        at.rate_dps_slow
    );
    assert!(at.rate_valid);
}

/// A 10 Hz sine of ±50 °/s: gain within 3 %, the lag of the lock-in and the channel's
/// filter (−17° at seed 1), no reset.
#[test]
fn sine_10hz() {
    let (r, _) = rate_response::sine(&opts(2), 10.0, 50.0, 1.5).unwrap();
    assert!((r.gain - 1.0).abs() < 0.03, "{r:?}");
    assert!((-25.0..-10.0).contains(&r.phase_deg), "{r:?}");
    assert_eq!(r.resets, 0, "{r:?}");
    assert!(r.slow_theta_max_dev_sigma < 5.0, "{r:?}");
}

/// A chirp 2 → 200 Hz: flat (±1 dB) to 20 Hz, −3 dB above 70 Hz, no reset.
#[test]
fn chirp_bandwidth() {
    let r = rate_response::chirp(&opts(3), 2.0, 200.0, 20.0, 6.0).unwrap();
    let bw = r.bandwidth_3db_hz.expect("a -3 dB crossing");
    assert!((70.0..150.0).contains(&bw), "{bw}");
    for p in r.points.iter().filter(|p| p.f_hz < 20.0) {
        assert!(p.mag_db.abs() < 1.0, "{p:?}");
    }
    assert_eq!(r.resets, 0);
}

/// The pump voltage goes to zero at 3 s: the parametric drive dies and with it the lock;
/// the rate flag is up before and down within 0.5 s after.
#[test]
fn rate_flag_drops_without_drive_lock() {
    let ev = format!("[[event]]\nt_s = {T0_S}\nkind = \"pump_scale\"\ns = 0.0\n");
    let sc = rate_response::scenario(&ev, T0_S + 1.0).unwrap();
    let tr = rate_response::trace(&sc, Precision::F32, 4).unwrap();
    let before = tr.iter().filter(|r| r.t_s > T0_S - 0.5 && r.t_s < T0_S);
    assert!(before.clone().all(|r| r.rate_valid), "valid before");
    let after: Vec<_> = tr.iter().filter(|r| r.t_s > T0_S + 0.5).collect();
    assert!(!after.is_empty() && after.iter().all(|r| !r.rate_valid));
}

/// `characterise` (seed 25): the pump's scale dither pushes the drive out of its
/// parametric band and it rings down (|x1| to 0.2–1.3 µm and below about a ≈ 1.7 µm
/// median, from 14 s) while the lock holds; the fast row, given the slow θ, is wrong at
/// the bottom and while the drive re-locks. Before 14 s the dithers' meeting phases dip the
/// amplitude to ≈ 42 % of its median for ≈ 40 ms at a time, and the row is right there.
/// Asserted (core `rate::DRIVE_RING2`, `RING_HOLD`): wherever the amplitude is below 25 %
/// of its median (and above the lock threshold) the flag is down; a sample flagged valid
/// below 40 % of it (the way down, before the ring-down's depth) is within 2 °/s of the
/// truth, the bound of the run's other valid samples (1.9 °/s measured at 16.49 s); before 14 s the rate is valid on ≥ 99.5 % of the samples, the dips included.
#[test]
fn rate_flag_drops_while_the_drive_rings_down_and_holds_through_the_dither_dips() {
    let sc = paragyro_simulator::scenario::Scenario::builtin("characterise").unwrap();
    let tr = rate_response::trace(&sc, Precision::F32, 25).unwrap();
    let mut amps: Vec<f64> = tr.iter().map(|r| r.drive_amp_um).collect();
    amps.sort_by(f64::total_cmp);
    let median = amps[amps.len() / 2];
    let below = |k: f64| {
        tr.iter()
            .filter(move |r| r.t_s > 2.0 && r.drive_amp_um < k * median && r.drive_amp_um > 0.2)
    };
    let deep: Vec<_> = below(0.25).collect();
    assert!(deep.len() > 10, "{} samples ringing down", deep.len());
    let bad: Vec<_> = deep.iter().filter(|r| r.rate_valid).collect();
    assert!(
        bad.is_empty(),
        "{} of {} valid while ringing down: {:?}",
        bad.len(),
        deep.len(),
        bad.first().map(|r| (r.t_s, r.drive_amp_um, r.rate_dps_est))
    );
    for r in below(0.4).filter(|r| r.rate_valid) {
        let err = r.rate_dps_est - r.rate_dps_true;
        assert!(err.abs() < 2.0, "valid {err:.2} °/s off at {} s", r.t_s);
    }
    let dithered: Vec<_> = tr.iter().filter(|r| r.t_s > 2.5 && r.t_s < 14.0).collect();
    let dips = dithered
        .iter()
        .filter(|r| r.drive_amp_um < 0.5 * median)
        .count();
    assert!(dips > 50, "{dips} samples in the dithers' dips");
    let valid = dithered.iter().filter(|r| r.rate_valid).count();
    assert!(
        valid as f64 >= 0.995 * dithered.len() as f64,
        "{valid} of {} valid before 14 s",
        dithered.len()
    );
}

/// `characterise` (seed 1): at the pump scale 1.15 (from 14 s) the drive loses its lock
/// again and again, and a lock loss can make the slow θ jump (the slow rate 153.6 → 144.0
/// °/s in 10 ms at 18.28 s) with the narrow channel's rate, so the gate does not see it.
/// The flag waits, after a lock loss, for a gate length of samples on which the slow
/// identification is settled: no valid sample more than 4 °/s off (2.85 °/s measured,
/// where the drive's amplitude dips), and more than 6 000 of the 10 001 samples still
/// valid (6 416 measured).
#[test]
fn rate_flag_waits_for_the_slow_identification_after_a_lock_loss() {
    let sc = paragyro_simulator::scenario::Scenario::builtin("characterise").unwrap();
    let tr = rate_response::trace(&sc, Precision::F32, 1).unwrap();
    let valid = tr.iter().filter(|r| r.rate_valid).count();
    assert!(valid > 6000, "{valid} valid samples of {}", tr.len());
    assert_valid_within(&tr, 4.0);
}

/// Through the ωy² drift of `drift-retune` (seed 1) the fast row, solved with the slow θ22
/// of before the drift, reads the drift as rate; the change detector needs a few samples
/// to see it. The narrow channel's quadrature leaves the slow θ23 at once, and the flag
/// follows it: no valid sample more than 2 °/s off (39.7 °/s at 2.01 s before the
/// quadrature test; the valid ones elsewhere are within ≈ 1 °/s).
#[test]
fn rate_flag_drops_while_the_device_drifts() {
    let sc = paragyro_simulator::scenario::Scenario::builtin("drift-retune").unwrap();
    let tr = rate_response::trace(&sc, Precision::F32, 1).unwrap();
    let valid_after_start = tr.iter().filter(|r| r.t_s > 1.6 && r.rate_valid).count();
    assert!(
        valid_after_start > 2000,
        "{valid_after_start} valid samples"
    );
    assert_valid_within(&tr, 2.0);
}

/// No sample flagged valid is more than `tol` °/s off the true rate.
fn assert_valid_within(tr: &[paragyro_simulator::trace::TraceRow], tol: f64) {
    let v = RateValidity::of_trace(tr);
    assert!(
        v.worst_valid_err_dps < tol,
        "valid while {:.1} °/s off at {:?} s",
        v.worst_valid_err_dps,
        v.worst_valid_at_s
    );
}

/// The same drift while the rate moves (a 5 Hz ±50 °/s sine from 1.9 s, settled, to the
/// end; the slow identification re-identifies and retunes through the rate walk,
/// host-sim/docs/rate-channel.md): the rate is never flagged valid while wrong:
/// within 10 °/s, where valid, of the truth delayed by the channel's own delay
/// (`rate_response::design_delay_s`, 6.6 ms; 5.8 °/s measured; against the undelayed
/// truth the lag alone is ≈ 12° at 5 Hz, 10 °/s, and the worst valid sample 15.8 °/s
/// off). The validity flag's quadrature test (core/src/rate.rs, "Validity") keeps it so.
#[test]
fn rate_flag_is_never_valid_and_wrong_when_the_device_drifts_under_motion() {
    let ev = "[[event]]\nt_s = 1.9\nkind = \"rate_sine\"\namplitude_dps = 50.0\nfreq_hz = 5.0\nduration_s = 6.1\n";
    let base = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../scenarios/drift-retune.toml"
    ))
    .unwrap();
    let sc = paragyro_simulator::scenario::Scenario::from_toml_str(
        &format!("{base}\n{ev}"),
        "drift-retune with a 5 Hz sine from 1.9 s",
    )
    .unwrap();
    let tr = rate_response::trace(&sc, Precision::F32, 1).unwrap();
    let delay = rate_response::design_delay_s(&paragyro_simulator::runner::core_config(&sc));
    assert!((delay - 6.6e-3).abs() < 0.1e-3, "design delay {delay} s");
    // the true rate `delay` earlier, interpolated between samples
    let truth_at = |t: f64| -> f64 {
        let i = tr.partition_point(|r| r.t_s <= t).clamp(1, tr.len() - 1);
        let (a, b) = (&tr[i - 1], &tr[i]);
        let w = ((t - a.t_s) / (b.t_s - a.t_s)).clamp(0.0, 1.0);
        a.rate_dps_true + w * (b.rate_dps_true - a.rate_dps_true)
    };
    let v = RateValidity::of(
        tr.iter()
            .map(|r| (r.rate_valid, r.rate_dps_est, truth_at(r.t_s - delay), r.t_s)),
    );
    assert!(v.valid > 2000, "{} valid samples", v.valid);
    assert!(
        v.worst_valid_err_dps < 10.0,
        "valid while {:.1} °/s off the delayed truth at {:?} s",
        v.worst_valid_err_dps,
        v.worst_valid_at_s
    );
}

/// The rate noise (noisy − noise-free run, same seed) against the bound of the same
/// transfer over three seeds: each within 0.7–2×, and their mean within 0.8–1.5×; against
/// a brick wall at 78 Hz (below the channel's −3 dB bandwidth, 79.2–79.5 Hz over seeds
/// 1–40: the bound smaller, the ratio larger) within 2× (issue 10's target; 1.43–1.55
/// on these seeds with the output section, above 2× on 5 of 20 seeds without it); the
/// deterministic error below 0.2 °/s rms.
#[test]
fn noise_against_crlb_monte_carlo() {
    let mut ratios = Vec::new();
    for seed in [11, 12, 13] {
        let n = rate_response::noise(&opts(seed), Some(78.0)).unwrap();
        assert!((0.7..2.0).contains(&n.ratio_same_g), "{n:?}");
        assert!(n.ratio_brickwall < 2.0, "{n:?}");
        // the noise-free run's own error (mostly the tone at the pump dither): 0.088 °/s
        // rms with the wide filter's curvature correction, 0.51 without it
        assert!(n.model_err_rms_dps < 0.2, "{n:?}");
        ratios.push(n.ratio_same_g);
    }
    let m = ratios.iter().sum::<f64>() / ratios.len() as f64;
    assert!((0.8..1.5).contains(&m), "{ratios:?}");
}

#[test]
fn the_ramp_fit_reads_a_known_scale_factor_bias_and_bow() {
    // a leg of −300..300 °/s read with a slope 1 + 500 ppm, a bias of 0.2 °/s and a bow
    // of 0.06 °/s at the ends (a parabola): the scale factor, the bias and the bow are what
    // the fit must find; each bin's mean truth is its samples' (so no quantisation of the
    // truth enters)
    let fs = 300.0;
    let bow = |x: f64| 0.06 * (x / fs).powi(2);
    let leg = (0..6000).map(|k| {
        let x = -fs + 2.0 * fs * (f64::from(k) + 0.5) / 6000.0;
        (x, (1.0 + 500e-6) * x + 0.2 + bow(x))
    });
    let f = rate_response::ramp_fit(leg, fs).unwrap();
    assert_eq!(f.bins, 30);
    assert!(
        (f.scale_factor_err_ppm - 500.0).abs() < 1.0,
        "{}",
        f.scale_factor_err_ppm
    );
    // the parabola's least-squares line sits at its mean (0.02 at 1/3 of the ends'
    // height); the largest bin off it is an end bin (≈ 0.06 − 0.02 less the bin's
    // averaging), ≈ 0.036 °/s = 120 ppm of 300
    assert!(
        (f.nonlinearity_ppm_fs - 120.0).abs() < 15.0,
        "{}",
        f.nonlinearity_ppm_fs
    );
    assert!((f.bias_dps - 0.22).abs() < 0.005, "{}", f.bias_dps);
    // too few rates to fit: an error, not a number
    assert!(rate_response::ramp_fit([(0.0, 0.0)].into_iter(), fs).is_err());
}

/// The static Allan run's record starts `allan_settle_s` after the start-up: with a settle
/// the figures of the record from the start-up (`from_start_up`) are those a run without
/// the settle gives (the same seed, the same first seconds), and the settled record's are
/// not; without a settle there is no second record. With `allan_warm_start` a third
/// record follows a warm start from the snapshot at the settle's end.
#[test]
fn the_allan_record_starts_after_the_settle() {
    let run = |settle: f64| {
        let o = Options {
            allan_settle_s: settle,
            ..opts(3)
        };
        rate_response::allan(&o, 0.0, 12.0).unwrap()
    };
    let cold = run(0.0);
    assert!(cold.from_start_up.is_none());
    assert_eq!(cold.settle_s, 0.0);
    let settled = run(6.0);
    assert_eq!(settled.settle_s, 6.0);
    let start = settled
        .from_start_up
        .as_ref()
        .expect("the start-up's figures");
    assert_eq!(start.arw_deg_rth, cold.figures.arw_deg_rth);
    assert_eq!(
        start.bias_instability_deg_h,
        cold.figures.bias_instability_deg_h
    );
    assert_ne!(settled.figures.arw_deg_rth, cold.figures.arw_deg_rth);
    assert_eq!(settled.tau_s, cold.tau_s, "the same record length");
    assert!(settled.after_warm_start.is_none());
    // with the warm start: the snapshot at the settle's end boots the device again (a
    // settled snapshot, else an error), its record as long, its figures its own
    let warm = rate_response::allan(
        &Options {
            allan_settle_s: 6.0,
            allan_warm_start: true,
            ..opts(3)
        },
        0.0,
        12.0,
    )
    .unwrap();
    let w = warm
        .after_warm_start
        .as_ref()
        .expect("the warm start's figures");
    assert!(w.arw_deg_rth.is_finite() && w.arw_deg_rth > 0.0, "{w:?}");
    assert_ne!(w.arw_deg_rth, start.arw_deg_rth);
    // a settle that is not a time is an error, not a run
    let bad = Options {
        allan_settle_s: f64::NAN,
        ..opts(3)
    };
    assert!(rate_response::allan(&bad, 0.0, 12.0).is_err());
}

/// The Allan report's zero share is the rate's zero's own movement: with the zero taken
/// from the slow RLS every sample (`allan_zero_memory_s` 0) its 2 s estimate's wander is
/// nearly all of the rate's deviation at τ ≈ 1 s, and held (the core's mean, 6–18 s
/// after the start-up: still learning) under a fifth of that; the zero's curve has a point at every τ of the rate's, and the figure at the
/// minimum is that curve's value there.
#[test]
fn the_allan_report_gives_the_rate_zeros_own_share() {
    let run = |memory: Option<f64>| {
        let o = Options {
            allan_settle_s: 6.0,
            allan_zero_memory_s: memory,
            ..opts(3)
        };
        rate_response::allan(&o, 0.0, 12.0).unwrap()
    };
    let at_1s = |a: &rate_response::AllanResult| {
        let i = nearest_1s(a);
        (a.zero_adev_dps[i], a.adev_dps[i])
    };
    let held = run(None);
    let every = run(Some(0.0));
    for a in [&held, &every] {
        assert_eq!(a.zero_adev_dps.len(), a.tau_s.len());
        let i = a
            .tau_s
            .iter()
            .position(|t| *t == a.figures.tau_min_s)
            .unwrap();
        assert_eq!(a.zero_adev_dps[i], a.figures.zero_adev_at_min_dps);
        assert!(a.from_start_up.as_ref().unwrap().zero_adev_at_min_dps > 0.0);
    }
    let (z_every, r_every) = at_1s(&every);
    let (z_held, r_held) = at_1s(&held);
    assert!(
        z_every > 0.9 * r_every,
        "every sample: zero {z_every} of {r_every}"
    );
    assert!(z_held < r_held, "held: zero {z_held} of {r_held}");
    assert!(z_every > 5.0 * z_held, "{z_every} against {z_held}");
}

/// `allan_forgetting` sets the static runs' slow RLS memory and the report says which:
/// with the zero taken from the slow RLS every sample, a 10 s memory (λ = 0.9998) wanders
/// the zero less at τ ≈ 1 s than the base's 2 s; outside (0, 1] it is an error.
#[test]
fn the_allan_runs_take_the_slow_memory_asked_for() {
    let run = |forgetting: Option<f64>| {
        let o = Options {
            allan_settle_s: 6.0,
            allan_zero_memory_s: Some(0.0),
            allan_forgetting: forgetting,
            ..opts(3)
        };
        rate_response::allan(&o, 0.0, 12.0)
    };
    let zero_at_1s = |a: &rate_response::AllanResult| a.zero_adev_dps[nearest_1s(a)];
    let base = run(None).unwrap();
    let long = run(Some(0.9998)).unwrap();
    assert_eq!(base.forgetting, 0.999);
    assert_eq!(long.forgetting, 0.9998);
    let (b, l) = (zero_at_1s(&base), zero_at_1s(&long));
    assert!(
        l < 0.5 * b,
        "the zero at 1 s: {l} at 10 s against {b} at 2 s"
    );
    for bad in [0.0, 1.5, f64::NAN] {
        let e = run(Some(bad)).unwrap_err().to_string();
        assert!(e.contains("forgetting"), "{e}");
    }
}

/// The index of an Allan curve's τ nearest 1 s.
fn nearest_1s(a: &rate_response::AllanResult) -> usize {
    a.tau_s
        .iter()
        .enumerate()
        .min_by(|x, y| x.1.ln().abs().total_cmp(&y.1.ln().abs()))
        .unwrap()
        .0
}
