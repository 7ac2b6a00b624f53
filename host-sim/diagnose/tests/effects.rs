//! Each effect's signature appears in the simulated record: noise-free records of the
//! `characterise` scenario (first 3 s) with and without the effect, same everything else.

use paragyro_core::Cplx;
use paragyro_simulator::effects::{EffectSpec, LIBRARY, OUT_OF_LIBRARY};
use paragyro_simulator::record::{Record, RecordOptions, simulate_record_with};
use paragyro_simulator::scenario::Scenario;

fn rec(effects: &[&str]) -> Record {
    let mut sc = Scenario::load("characterise").unwrap();
    sc.duration_s = 3.0;
    sc.sim.noise_pm_rthz = 0.0;
    let opts = RecordOptions {
        seed: Some(1),
        effects: effects
            .iter()
            .map(|e| e.parse::<EffectSpec>().unwrap())
            .collect(),
        rate_table: true,
        temp: Some((25.0, 10.0)),
    };
    simulate_record_with(&sc, &opts, &mut |_| {}).unwrap().0
}

fn diff(a: &Record, b: &Record, k: usize) -> [f64; 4] {
    let (r, s) = (&a.rows[k].lockin, &b.rows[k].lockin);
    let c = |p: Cplx<f64>, q: Cplx<f64>| (p.re - q.re).hypot(p.im - q.im);
    [
        (r.x0_um - s.x0_um).abs(),
        c(r.x_um[0], s.x_um[0]),
        (r.y0_um - s.y0_um).abs(),
        c(r.y_um[0], s.y_um[0]),
    ]
}

#[test]
fn every_effect_changes_the_record() {
    let clean = rec(&[]);
    let sizes = [
        "geometric_nonlinearity=1e-5",
        "angular_vibration=30",
        "electrostatic_softening=1e-4",
        "feedthrough=1e-3",
        "nonlinear_damping=1e-5",
        "anisodamping=1e-5",
        "force_leak=1e-3",
        "thermal_drift=-30",
        "lockin_mismatch=0.05",
        "quadratic_stiffness=1e-5",
        "readout_gain=0.01",
    ];
    assert_eq!(sizes.len(), LIBRARY.len() + OUT_OF_LIBRARY.len());
    for s in sizes {
        let r = rec(&[s]);
        let worst = (0..r.rows.len())
            .map(|k| diff(&r, &clean, k).into_iter().fold(0.0, f64::max))
            .fold(0.0, f64::max);
        println!("{s}: largest channel difference {worst:.3e} µm");
        assert!(worst > 1e-5, "{s}: {worst}");
    }
}

/// Feedthrough: the sense DC channel moves by C·s with no motion needed.
#[test]
fn feedthrough_offsets_the_sense_dc() {
    let (clean, ft) = (rec(&[]), rec(&["feedthrough=1e-3"]));
    let k = 1000; // 2 s: s = 1 ± 10 % dither
    let s = (ft.rows[k].pump_amp_v / ft.header.pump_amp_ref_v).powi(2);
    let dy0 = ft.rows[k].lockin.y0_um - clean.rows[k].lockin.y0_um;
    // the DC channel is the lock-in's low-passed C·s(t): within the dither's change over
    // the low-pass delay of the sample value
    assert!((dy0 - 1e-3 * s).abs() < 2e-5, "{dy0} vs {}", 1e-3 * s);
}

/// Lock-in mismatch: the envelopes differ while they move fast (the start-up), hardly in
/// the dithered steady state.
#[test]
fn lockin_mismatch_lives_in_transients() {
    let (clean, lm) = (rec(&[]), rec(&["lockin_mismatch=0.05"]));
    let rms = |a: usize, b: usize| {
        ((a..b).map(|k| diff(&lm, &clean, k)[1].powi(2)).sum::<f64>() / (b - a) as f64).sqrt()
    };
    let (startup, steady) = (rms(10, 150), rms(1000, 1400));
    println!("start-up {startup:.3e}, steady {steady:.3e}");
    assert!(startup > 5.0 * steady, "{startup} vs {steady}");
}

/// Thermal drift: the difference grows with the die temperature (10 K over 3 s).
#[test]
fn thermal_drift_grows_with_temperature() {
    let (clean, th) = (rec(&[]), rec(&["thermal_drift=-30"]));
    let sense =
        |a: usize, b: usize| (a..b).map(|k| diff(&th, &clean, k)[3]).sum::<f64>() / (b - a) as f64;
    let (early, late) = (sense(300, 500), sense(1300, 1500));
    println!("early {early:.3e}, late {late:.3e}");
    assert!(late > 2.0 * early, "{early} vs {late}");
    assert!(th.rows.iter().all(|r| r.temp_c.is_some()));
}

/// Angular vibration: the sense envelope beats against the clean one at the beat frequency.
#[test]
fn angular_vibration_beats_at_its_beat() {
    let (clean, v) = (rec(&[]), rec(&["angular_vibration=30@3.0"]));
    // complex DFT of the sense difference over 1–3 s on a ±10 Hz, 0.1 Hz grid (mean removed)
    let ks: Vec<usize> = (500..1500).collect();
    let d: Vec<(f64, f64, f64)> = ks
        .iter()
        .map(|&k| {
            (
                v.rows[k].t_s,
                v.rows[k].lockin.y_um[0].re - clean.rows[k].lockin.y_um[0].re,
                v.rows[k].lockin.y_um[0].im - clean.rows[k].lockin.y_um[0].im,
            )
        })
        .collect();
    let n = d.len() as f64;
    let (mr, mi) = (
        d.iter().map(|p| p.1).sum::<f64>() / n,
        d.iter().map(|p| p.2).sum::<f64>() / n,
    );
    let best = (-100..=100)
        .filter(|&i| i != 0)
        .map(|i| {
            let f = 0.1 * i as f64;
            let (mut re, mut im) = (0.0, 0.0);
            for &(t, a, b) in &d {
                let (s, c) = (std::f64::consts::TAU * f * t).sin_cos();
                // (a + ib)·e^{−i2πft}
                re += (a - mr) * c + (b - mi) * s;
                im += (b - mi) * c - (a - mr) * s;
            }
            (f, re.hypot(im))
        })
        .fold((0.0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    println!("strongest line of |Δy1| at {:.1} Hz", best.0);
    // the vibration pumps the sense mode at the beat against the reference, whose phase the
    // 5 Hz pump-frequency dither modulates (index ≈ 4 rad): lines at ±3 Hz + k·5 Hz, none
    // elsewhere
    let on_comb = [3.0f64, -3.0].iter().any(|b| {
        let r = (best.0 - b).rem_euclid(5.0);
        !(0.25..=4.75).contains(&r)
    });
    assert!(on_comb, "{best:?}");
}

mod properties {
    use paragyro_simulator::effects::{Effect, EffectSpec};
    use proptest::prelude::*;

    fn effect() -> impl Strategy<Value = Effect> {
        prop::sample::select(Effect::ALL.to_vec())
    }

    proptest! {
        /// Every effect round-trips through its name, its serde form and its spec text.
        #[test]
        fn every_effect_round_trips_through_its_name(
            e in effect(),
            size in -1e6f64..1e6,
            beat in -10f64..10.0,
        ) {
            prop_assert_eq!(e.name().parse::<Effect>(), Ok(e));
            prop_assert_eq!(e.to_string(), e.name());
            let v = serde_json::to_value(e).unwrap();
            prop_assert_eq!(v.as_str(), Some(e.name()));
            prop_assert_eq!(serde_json::from_value::<Effect>(v).unwrap(), e);
            let spec = EffectSpec { effect: e, size, param: e.takes_param().then_some(beat) };
            prop_assert_eq!(spec.to_string().parse::<EffectSpec>(), Ok(spec.clone()));
            let v = serde_json::to_value(&spec).unwrap();
            prop_assert_eq!(serde_json::from_value::<EffectSpec>(v).unwrap(), spec);
        }

        /// A name that is none of the effects' is rejected with the list of the valid ones.
        #[test]
        fn unknown_names_are_rejected_with_the_valid_ones(name in "[a-z_]{1,24}") {
            prop_assume!(Effect::ALL.iter().all(|e| e.name() != name));
            let err = name.parse::<Effect>().unwrap_err().to_string();
            prop_assert!(err.contains(&format!("unknown effect '{name}'")), "{}", err);
            for e in Effect::ALL {
                prop_assert!(err.contains(e.name()), "{} lacks {}", err, e);
            }
        }
    }
}
