//! Tests of the whole step: bad input, stuck channels, jumps, in-place building.

extern crate std;
use super::*;
use crate::complex::Cplx;
use crate::config::Config;
use crate::output::event;
use crate::sample::{Lockin, Sample};

#[test]
fn validated_build_and_initial_pump_match_build() {
    let cfg = Config::table2();
    let a = cfg.build::<f32>().unwrap();
    let b = cfg.validated().unwrap().build::<f32>();
    assert_eq!(std::format!("{a:?}"), std::format!("{b:?}"));
    // built in place over a blank one (which steps without panicking)
    let mut c = Estimator::<f32>::blank();
    for k in 0..300 {
        let _ = c.step(&sample(k, 21_000.0));
    }
    c.rebuild(cfg.validated().unwrap());
    assert_eq!(std::format!("{a:?}"), std::format!("{c:?}"));
    assert_eq!(
        cfg.initial_pump_hz().to_bits(),
        a.initial_pump_hz().to_bits()
    );
    let mut bad = cfg;
    bad.fs_hz = f64::NAN;
    assert_eq!(bad.validated().unwrap_err().field, "fs_hz");
}

/// A plausible steady sample of the Table 2 gyro with a little variation (so that no
/// channel is stuck).
fn sample(k: u64, pump_hz: f64) -> Sample<f32> {
    // every channel moves a little (real data always carries noise)
    let d = |i: u64| (((k + 3 * i) * 7919) % 13) as f32 * 1e-5;
    Sample {
        lockin: Lockin {
            x0_um: 0.0204 + d(0),
            x_um: [
                Cplx::new(1.2 + d(1), -1.27 + d(2)),
                Cplx::new(1e-4 + d(3), d(4)),
                Cplx::new(0.001 + d(5), 0.002 + d(6)),
            ],
            y0_um: 0.0207 - d(7),
            y_um: [
                Cplx::new(0.9 + d(8), 1.2 - d(9)),
                Cplx::new(d(10), 1e-4 + d(11)),
                Cplx::new(0.0005 + d(12), -0.001 + d(13)),
            ],
        },
        accel_mps2: [98.0665, 98.0665],
        pump_hz,
        pump_scale: 1.0,
        temp_c: None,
    }
}

fn run_to(est: &mut Estimator<f32>, n: u64) -> f64 {
    let mut pump = est.initial_pump_hz();
    for k in 0..n {
        pump = est.step(&sample(k, pump)).pump_hz_next;
    }
    pump
}

fn check_bad(mutate: impl Fn(&mut Sample<f32>), field: &str) {
    let mut est = Config::table2().build::<f32>().unwrap();
    let pump = run_to(&mut est, 600); // past the start-up gate: the RLS updates
    let before = est.theta();
    let c0 = est.counters();
    let mut s = sample(600, pump);
    mutate(&mut s);
    let out = est.step(&s);
    assert!(!out.health.inputs_valid, "{field}: not flagged");
    assert!(!out.updated, "{field}: the RLS used a bad sample");
    assert!(out.events & event::BAD_INPUT != 0, "{field}: no event");
    assert_eq!(est.theta(), before, "{field}: estimate not held");
    assert_eq!(
        est.counters().bad_samples,
        c0.bad_samples + 1,
        "{field}: counter"
    );
    assert!(out.pump_hz_next.is_finite() && out.pump_hz_next > 0.0);
    // recovery: good samples are gated for bad_input_gate_s, then used again
    let mut pump = out.pump_hz_next;
    let gate = (est.config().monitor.bad_input_gate_s * 500.0) as u64;
    for k in 0..gate + 5 {
        let o = est.step(&sample(601 + k, pump));
        pump = o.pump_hz_next;
        assert!(o.health.inputs_valid);
        if k + 1 < gate {
            assert!(!o.updated, "{field}: updated during the recovery gate");
        }
        if k > gate + 1 {
            assert!(o.updated, "{field}: never recovered");
        }
    }
}

#[test]
fn nan_inf_saturated_are_flagged_skipped_and_counted() {
    check_bad(|s| s.lockin.x_um[0].re = f32::NAN, "NaN in A1");
    check_bad(|s| s.lockin.y0_um = f32::INFINITY, "+Inf in Y0");
    check_bad(|s| s.lockin.y_um[2].im = f32::NEG_INFINITY, "-Inf in B3");
    check_bad(|s| s.accel_mps2[1] = f32::NAN, "NaN accelerometer");
    check_bad(|s| s.pump_hz = f64::NAN, "NaN pump");
    check_bad(|s| s.lockin.x_um[0].re = 20.0, "saturated A1");
    check_bad(|s| s.lockin.x0_um = -25.0, "saturated X0");
    check_bad(|s| s.accel_mps2[0] = 1e4, "saturated accelerometer");
    let mut est = Config::table2().build::<f32>().unwrap();
    run_to(&mut est, 600);
    assert_eq!(est.counters().non_finite, 0);
}

#[test]
fn stuck_channel_is_flagged() {
    let mut est = Config::table2().build::<f32>().unwrap();
    let mut pump = run_to(&mut est, 600);
    let limit = est.config().monitor.stuck_samples as u64;
    let frozen = sample(600, pump).lockin.y_um[0];
    let mut flagged_at = None;
    for k in 0..limit + 10 {
        let mut s = sample(600 + k, pump);
        s.lockin.y_um[0] = frozen; // B1 stuck
        let before = est.theta();
        let o = est.step(&s);
        pump = o.pump_hz_next;
        if !o.health.inputs_valid {
            flagged_at.get_or_insert(k);
            assert_eq!(est.theta(), before, "estimate not held on a stuck sample");
        }
    }
    assert_eq!(
        flagged_at,
        Some(limit),
        "stuck channel flagged after {limit} repeats"
    );
    assert!(est.counters().stuck >= 10);
}

#[test]
fn no_valid_sample_yet_holds_the_centre() {
    let mut est = Config::table2().build::<f32>().unwrap();
    let p0 = est.initial_pump_hz();
    let mut s = sample(0, p0);
    s.lockin.x0_um = f32::NAN;
    for _ in 0..10 {
        let o = est.step(&s);
        assert_eq!(o.pump_hz_next, p0);
        assert!(!o.health.inputs_valid && !o.updated);
    }
    let (t1, _) = est.theta();
    assert_eq!(t1, est.nominal_theta().0);
}

#[test]
fn config_errors_name_the_field() {
    let mut c = Config::table2();
    c.rls.forgetting = 1.5;
    assert_eq!(c.build::<f32>().unwrap_err().field, "rls.forgetting");
    let mut c = Config::table2();
    c.lockin_lpf_hz = f64::NAN;
    assert_eq!(c.build::<f64>().unwrap_err().field, "lockin_lpf_hz");
    let mut c = Config::table2();
    c.nominal.mu_xy = 0.0; // θ14 nominal would be zero: columns cannot be scaled
    let e = c.build::<f32>().unwrap_err();
    assert_eq!(e.field, "nominal");
    let msg = std::format!("{e}");
    assert!(msg.contains("nominal") && msg.contains("θ"), "{msg}");
    let mut c = Config::table2();
    c.dither.freq_hz = 100.0;
    assert_eq!(c.build::<f32>().unwrap_err().field, "dither.freq_hz");
}

#[test]
fn jump_gates_and_resets() {
    let mut est = Config::table2().build::<f64>().unwrap();
    let mut pump = run_to_f64(&mut est, 700);
    est.command_pump_centre(22000.0, true);
    let gate = (est.config().monitor.gate_jump_s * 500.0) as u64;
    for k in 0..gate + 3 {
        let o = est.step(&sample_f64(700 + k, pump));
        pump = o.pump_hz_next;
        if k + 1 < gate {
            assert!(!o.updated && o.health.gated);
        }
    }
    assert!((pump - 22000.0).abs() < 30.0, "pump {pump}");
    assert_eq!(est.counters().jumps, 1);
    assert!((est.pump_centre_hz() - 22000.0).abs() < 1e-6);
}

#[test]
fn pump_commands_out_of_range_are_refused() {
    let mut est = Config::table2().build::<f32>().unwrap();
    let centre = est.pump_centre_hz();
    // the fuzzed sequence of regression nan-pump-1, reduced: an absurd centre, then a
    // dither "below 5 % of it"; both must be refused, or the pump becomes NaN
    for bad in [
        1.3e181,
        -1.0,
        0.0,
        f64::NAN,
        f64::INFINITY,
        centre * 1.51,
        centre * 0.49,
    ] {
        assert!(!est.command_pump_centre(bad, true), "{bad} accepted");
        assert!(!est.command_pump_centre(bad, false), "{bad} accepted");
    }
    assert!(!est.set_dither_pump_hz(3.9e160));
    assert!(!est.set_dither_pump_hz(f64::NAN));
    assert_eq!(est.pump_centre_hz(), centre);
    assert_eq!(est.counters().jumps, 0);
    let mut pump = est.initial_pump_hz();
    for k in 0..50 {
        let o = est.step(&sample(k, pump));
        assert!(
            o.pump_hz_next.is_finite(),
            "tick {k}: pump {}",
            o.pump_hz_next
        );
        pump = o.pump_hz_next;
    }
    // within ±50 %: accepted
    assert!(est.command_pump_centre(centre * 1.49, false));
    assert!(est.command_pump_centre(centre * 0.51, true));
    assert!(est.set_dither_pump_hz(10.0));
    assert_eq!(est.counters().jumps, 1);
}

fn sample_f64(k: u64, pump_hz: f64) -> Sample<f64> {
    let s = sample(k, pump_hz);
    let c = |z: Cplx<f32>| Cplx::new(z.re as f64, z.im as f64);
    Sample {
        lockin: Lockin {
            x0_um: s.lockin.x0_um as f64,
            x_um: s.lockin.x_um.map(c),
            y0_um: s.lockin.y0_um as f64,
            y_um: s.lockin.y_um.map(c),
        },
        accel_mps2: [98.0665, 98.0665],
        pump_hz,
        pump_scale: 1.0,
        temp_c: None,
    }
}

fn run_to_f64(est: &mut Estimator<f64>, n: u64) -> f64 {
    let mut pump = est.initial_pump_hz();
    for k in 0..n {
        pump = est.step(&sample_f64(k, pump)).pump_hz_next;
    }
    pump
}

/// The rule of step.rs, stage 4, replayed from the outputs: `latch` = the meter said
/// "excited" since start-up and the last covariance reset.
#[derive(Default)]
struct HoldModel {
    latch: bool,
    /// Updates the rule holds (no forgetting).
    held: u64,
    /// Covariance resets seen (change alarms or a jump).
    resets: u64,
}

impl HoldModel {
    /// Steps `n` samples from `k0` (the pump fed back), replaying the rule.
    fn run(&mut self, est: &mut Estimator<f32>, (k0, n): (u64, u64), pump: &mut f64) {
        for k in k0..k0 + n {
            let o = est.step(&sample(k, *pump));
            *pump = o.pump_hz_next;
            // the latch is read before this sample's excitation counts
            self.held += (self.latch && o.updated && !o.health.excitation_ok) as u64;
            self.latch |= o.health.excitation_ok;
            if o.events & (event::CHANGE_DRIVE | event::CHANGE_SENSE) != 0 {
                self.latch = false;
                self.resets += 1;
            }
        }
    }

    fn check(&self, est: &Estimator<f32>) {
        let (s1, s2) = est.rls_stats();
        assert_eq!(
            (s1.forgetting_held, s2.forgetting_held),
            (self.held, self.held)
        );
    }
}

#[test]
fn forgetting_is_held_only_once_excitation_is_lost() {
    // the synthetic samples are no gyro: the change detector would fire on them all the
    // time, so it is switched off here (the commanded jump below still resets)
    let mut cfg = Config::table2();
    cfg.monitor.change_threshold = 1e30;
    let mut est = cfg.build::<f32>().unwrap();
    let mut pump = est.initial_pump_hz();
    let mut m = HoldModel::default();
    // start-up: gated, then updates before the dither (1 s) and the meter's rise: the
    // RLS forgets as before, nothing is held
    m.run(&mut est, (0, 2000), &mut pump);
    assert!(est.health().excitation_ok);
    assert_eq!(m.held, 0);
    m.check(&est);
    // the dither switched off: once the meter falls, the updates are held
    est.set_dither(false);
    m.run(&mut est, (2000, 2000), &mut pump);
    assert!(!est.health().excitation_ok);
    std::println!("dither off: {} updates held, {} resets", m.held, m.resets);
    assert_eq!(m.resets, 0);
    assert!(m.held > 1500, "{} updates held", m.held);
    m.check(&est);
    // on again: forgetting resumes once the meter has risen
    est.set_dither(true);
    m.run(&mut est, (4000, 1000), &mut pump);
    assert!(est.health().excitation_ok);
    m.check(&est);
    // off again, then a covariance reset (a commanded jump): no excited memory is left
    // to hold, so the RLS forgets as at start-up until the meter sees the dither again
    est.set_dither(false);
    m.run(&mut est, (5000, 1000), &mut pump);
    m.check(&est);
    let held = m.held;
    est.command_pump_centre(est.pump_centre_hz(), true);
    m.latch = false;
    let u = est.rls_stats().0.updates;
    m.run(&mut est, (6000, 1500), &mut pump);
    assert!(
        est.rls_stats().0.updates > u,
        "the RLS updates after the jump's gate"
    );
    assert!(!est.health().excitation_ok);
    assert_eq!(m.held, held);
    m.check(&est);
}

#[test]
fn a_device_never_excited_keeps_forgetting() {
    // dither configured off: the meter never says excited, the RLS forgets (with the
    // trace bound) as it always did
    let mut cfg = Config::table2();
    cfg.dither.enabled = false;
    let mut est = cfg.build::<f32>().unwrap();
    let mut pump = est.initial_pump_hz();
    let mut m = HoldModel::default();
    m.run(&mut est, (0, 3000), &mut pump);
    assert!(!m.latch);
    let (s1, s2) = est.rls_stats();
    assert!(s1.updates > 0 && s2.updates > 0);
    assert_eq!((s1.forgetting_held, s2.forgetting_held), (0, 0));
}
