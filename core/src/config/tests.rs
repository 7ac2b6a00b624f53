//! Validation: every field that can be wrong is rejected with an error naming it
//! (property tests over the fields and their bad values), and valid configurations
//! around Table 2 build.

extern crate std;
use super::*;
use proptest::prelude::*;
use std::format;

/// What a field must be, and so which values break it.
#[derive(Clone, Copy, Debug)]
enum Rule {
    /// finite and > 0
    Pos,
    /// finite and ≥ 0
    NonNeg,
    /// finite
    Finite,
    /// in (0, 1]
    Unit,
}

type Setter = fn(&mut Config, f64);

/// Every real-valued field with its dotted name, its rule and a setter.
const FIELDS: &[(&str, Rule, Setter)] = &[
    ("f0_hz", Rule::Pos, |c, v| c.f0_hz = v),
    ("fs_hz", Rule::Pos, |c, v| c.fs_hz = v),
    ("l0_um", Rule::Pos, |c, v| c.l0_um = v),
    ("lockin_lpf_hz", Rule::Pos, |c, v| c.lockin_lpf_hz = v),
    ("pump_amp_ref_v", Rule::Pos, |c, v| c.pump_amp_ref_v = v),
    ("nominal.mu_x", Rule::Pos, |c, v| c.nominal.mu_x = v),
    ("nominal.mu_y", Rule::Pos, |c, v| c.nominal.mu_y = v),
    ("nominal.wx2", Rule::Pos, |c, v| c.nominal.wx2 = v),
    ("nominal.wy2", Rule::Pos, |c, v| c.nominal.wy2 = v),
    ("nominal.beta1", Rule::Pos, |c, v| c.nominal.beta1 = v),
    ("nominal.mu_xy", Rule::Finite, |c, v| c.nominal.mu_xy = v),
    ("nominal.wxy2", Rule::Finite, |c, v| c.nominal.wxy2 = v),
    ("nominal.alpha_x", Rule::Finite, |c, v| {
        c.nominal.alpha_x = v
    }),
    ("nominal.alpha_y", Rule::Finite, |c, v| {
        c.nominal.alpha_y = v
    }),
    ("nominal.beta3", Rule::Finite, |c, v| c.nominal.beta3 = v),
    ("nominal.gamma", Rule::Finite, |c, v| c.nominal.gamma = v),
    ("nominal.gamma_p", Rule::Finite, |c, v| {
        c.nominal.gamma_p = v
    }),
    ("nominal.c_ax", Rule::Finite, |c, v| c.nominal.c_ax = v),
    ("nominal.c_ay", Rule::Finite, |c, v| c.nominal.c_ay = v),
    ("pump_centre_hz", Rule::Pos, |c, v| c.pump_centre_hz = v),
    ("dither.pump_hz", Rule::NonNeg, |c, v| c.dither.pump_hz = v),
    ("dither.freq_hz", Rule::Pos, |c, v| c.dither.freq_hz = v),
    ("dither.start_s", Rule::NonNeg, |c, v| c.dither.start_s = v),
    ("dither.taper_s", Rule::NonNeg, |c, v| c.dither.taper_s = v),
    ("dither.scale_frac", Rule::NonNeg, |c, v| {
        c.dither.scale_frac = v
    }),
    ("dither.scale_freq_hz", Rule::Pos, |c, v| {
        c.dither.scale_freq_hz = v
    }),
    ("svf_hz", Rule::Pos, |c, v| c.svf_hz = v),
    ("noise_pm_rthz", Rule::Pos, |c, v| c.noise_pm_rthz = v),
    ("row_sigma_drive[0]", Rule::Pos, |c, v| {
        c.row_sigma_drive[0] = v
    }),
    ("row_sigma_drive[4]", Rule::Pos, |c, v| {
        c.row_sigma_drive[4] = v
    }),
    ("row_sigma_sense[2]", Rule::Pos, |c, v| {
        c.row_sigma_sense[2] = v
    }),
    ("rls.forgetting", Rule::Unit, |c, v| c.rls.forgetting = v),
    ("rls.p0", Rule::Pos, |c, v| c.rls.p0 = v),
    ("rls.p_reset", Rule::Pos, |c, v| c.rls.p_reset = v),
    ("rls.relinearize_s", Rule::NonNeg, |c, v| {
        c.rls.relinearize_s = v
    }),
    ("monitor.gate_startup_s", Rule::NonNeg, |c, v| {
        c.monitor.gate_startup_s = v
    }),
    ("monitor.gate_jump_s", Rule::NonNeg, |c, v| {
        c.monitor.gate_jump_s = v
    }),
    ("monitor.bad_input_gate_s", Rule::NonNeg, |c, v| {
        c.monitor.bad_input_gate_s = v
    }),
    ("monitor.change_threshold", Rule::Pos, |c, v| {
        c.monitor.change_threshold = v
    }),
    ("monitor.change_alpha", Rule::Unit, |c, v| {
        c.monitor.change_alpha = v
    }),
    ("monitor.change_hold_s", Rule::NonNeg, |c, v| {
        c.monitor.change_hold_s = v
    }),
    ("monitor.change_drift_margin", Rule::NonNeg, |c, v| {
        c.monitor.change_drift_margin = v
    }),
    ("monitor.full_scale_um", Rule::Pos, |c, v| {
        c.monitor.full_scale_um = v
    }),
    ("monitor.accel_full_scale_mps2", Rule::Pos, |c, v| {
        c.monitor.accel_full_scale_mps2 = v
    }),
    ("monitor.excitation_min_fraction", Rule::NonNeg, |c, v| {
        c.monitor.excitation_min_fraction = v
    }),
    ("retune.ramp_s", Rule::Pos, |c, v| c.retune.ramp_s = v),
    ("retune.max_rate_hz_per_s", Rule::Pos, |c, v| {
        c.retune.max_rate_hz_per_s = v
    }),
    ("retune.track_hz", Rule::NonNeg, |c, v| {
        c.retune.track_hz = v
    }),
    ("retune.deadband_hz", Rule::NonNeg, |c, v| {
        c.retune.deadband_hz = v
    }),
    ("retune.settle_window_s", Rule::Pos, |c, v| {
        c.retune.settle_window_s = v
    }),
    ("retune.settle_tol", Rule::Pos, |c, v| {
        c.retune.settle_tol = v
    }),
    ("retune.lock_min_um", Rule::NonNeg, |c, v| {
        c.retune.lock_min_um = v
    }),
    ("retune.lock_lost_s", Rule::NonNeg, |c, v| {
        c.retune.lock_lost_s = v
    }),
    ("retune.min_interval_s", Rule::NonNeg, |c, v| {
        c.retune.min_interval_s = v
    }),
    ("rate.walk_dps", Rule::NonNeg, |c, v| c.rate.walk_dps = v),
    ("rate.zero_memory_s", Rule::NonNeg, |c, v| {
        c.rate.zero_memory_s = v
    }),
];

/// A value that breaks `rule`: NaN, ±∞, or a finite value out of its range.
fn bad_value(rule: Rule) -> BoxedStrategy<f64> {
    let non_finite = prop_oneof![Just(f64::NAN), Just(f64::INFINITY), Just(f64::NEG_INFINITY)];
    match rule {
        Rule::Pos => prop_oneof![non_finite, -1e12f64..=0.0].boxed(),
        Rule::NonNeg => prop_oneof![non_finite, -1e12f64..-1e-300].boxed(),
        Rule::Finite => non_finite.boxed(),
        Rule::Unit => prop_oneof![non_finite, -1e3f64..=0.0, 1.0000001f64..1e3].boxed(),
    }
}

fn field_and_bad_value() -> impl Strategy<Value = (usize, f64)> {
    (0..FIELDS.len()).prop_flat_map(|i| (Just(i), bad_value(FIELDS[i].1)))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// One bad field in Table 2's configuration: rejected, and the error (and its
    /// message) names that field.
    #[test]
    fn a_bad_field_is_rejected_by_name((i, v) in field_and_bad_value()) {
        let (name, _, set) = FIELDS[i];
        let mut c = Config::table2();
        set(&mut c, v);
        let e = c.validate().unwrap_err();
        prop_assert_eq!(e.field, name, "value {}", v);
        let msg = format!("{}", e);
        prop_assert!(msg.contains(name), "{}", msg);
        prop_assert_eq!(c.validated().unwrap_err(), e);
    }

    /// Out of range though finite and positive: order and ratios between fields.
    #[test]
    fn out_of_range_fields_are_rejected_by_name(
        order in prop_oneof![Just(0usize), 9usize..1000],
        factor in 1.0f64..100.0,
        margin in 1.0f64..10.0,
        scale_frac in 0.300001f64..10.0,
    ) {
        let t2 = Config::table2();
        let check = |c: &Config, name: &str| -> Result<(), TestCaseError> {
            prop_assert_eq!(c.validate().map_err(|e| e.field), Err(name));
            Ok(())
        };
        let mut c = t2;
        c.lockin_lpf_order = order;
        check(&c, "lockin_lpf_order")?;
        let mut c = t2;
        c.retune.track_hz = c.retune.deadband_hz * (1.0 + factor);
        check(&c, "retune.track_hz")?;
        let mut c = t2;
        c.fs_hz = c.f0_hz * factor;
        check(&c, "fs_hz")?;
        let mut c = t2;
        c.lockin_lpf_hz = c.f0_hz * factor;
        check(&c, "lockin_lpf_hz")?;
        let mut c = t2;
        c.dither.pump_hz = 0.05 * c.pump_centre_hz * factor;
        check(&c, "dither.pump_hz")?;
        let mut c = t2;
        c.dither.freq_hz = c.fs_hz / 20.0 * (1.0 + factor);
        check(&c, "dither.freq_hz")?;
        let mut c = t2;
        c.dither.scale_freq_hz = c.fs_hz / 20.0 * (1.0 + factor);
        check(&c, "dither.scale_freq_hz")?;
        let mut c = t2;
        c.dither.scale_frac = scale_frac;
        check(&c, "dither.scale_frac")?;
        let mut c = t2;
        c.svf_hz = c.fs_hz / 10.0 * (1.0 + factor);
        check(&c, "svf_hz")?;
        let mut c = t2;
        c.rls.trace_bound_factor = 1.0 / (1.0 + factor);
        check(&c, "rls.trace_bound_factor")?;
        let mut c = t2;
        c.retune.band_margin = 0.5 * margin;
        check(&c, "retune.band_margin")?;
        let mut c = t2;
        c.nominal.mu_xy = 0.0;
        check(&c, "nominal")?;
    }

    /// Valid configurations around Table 2 (every field moved inside its range) pass
    /// and build in both precisions; the built estimator keeps the configuration.
    #[test]
    fn valid_configurations_build(
        f0_scale in 0.8f64..1.25,
        fs_hz in 200.0f64..2000.0,
        order in 1usize..=8,
        lpf_frac in 0.05f64..0.45,
        svf_frac in 0.01f64..0.1,
        dither_frac in 0.0f64..0.04,
        dither_freq_frac in 0.001f64..0.05,
        scale_frac in 0.0f64..=0.3,
        forgetting in 0.9f64..=1.0,
        p0 in 1.0f64..1e6,
        trace_bound_factor in 1.0f64..100.0,
        band_margin in 0.0f64..0.49,
        stuck in 0u32..200,
        nominal_scale in prop::array::uniform4(0.5f64..2.0),
    ) {
        let mut c = Config::table2();
        c.f0_hz *= f0_scale;
        c.fs_hz = fs_hz;
        c.lockin_lpf_order = order;
        c.lockin_lpf_hz = lpf_frac * fs_hz;
        c.svf_hz = svf_frac * fs_hz;
        c.pump_centre_hz *= f0_scale;
        c.dither.pump_hz = dither_frac * c.pump_centre_hz;
        c.dither.freq_hz = dither_freq_frac * fs_hz;
        c.dither.scale_freq_hz = dither_freq_frac * fs_hz * 0.7;
        c.dither.scale_frac = scale_frac;
        c.rls.forgetting = forgetting;
        c.rls.p0 = p0;
        c.rls.trace_bound_factor = trace_bound_factor;
        c.retune.band_margin = band_margin;
        c.monitor.stuck_samples = stuck;
        c.nominal.mu_x *= nominal_scale[0];
        c.nominal.wy2 *= nominal_scale[1];
        c.nominal.alpha_x *= nominal_scale[2];
        c.nominal.beta3 *= nominal_scale[3];
        prop_assert_eq!(c.validate(), Ok(()));
        let e32 = c.build::<f32>().unwrap();
        let e64 = c.build::<f64>().unwrap();
        prop_assert_eq!(e32.config(), &c);
        prop_assert_eq!(e64.config(), &c);
        prop_assert_eq!(e64.initial_pump_hz().to_bits(), c.initial_pump_hz().to_bits());
        prop_assert!(e32.initial_pump_hz().is_finite());
    }
}

#[test]
fn table2_is_valid_and_uses_the_physics_constants() {
    let c = Config::table2();
    assert_eq!(c.validate(), Ok(()));
    assert_eq!(c.f0_hz, crate::physics::F0_TABLE2_HZ);
    assert_eq!(
        c.omega0_rad_s(),
        2.0 * core::f64::consts::PI * crate::physics::F0_TABLE2_HZ
    );
    assert_eq!(c.l0_um, crate::physics::L0_TABLE2_UM);
    assert_eq!(Config::default(), c);
}

#[test]
fn the_table2_pump_centre_is_twice_the_sense_resonance() {
    let c = Config::table2();
    let want = 2.0 * libm::sqrt(TABLE2.wy2) * F0_TABLE2_HZ;
    assert_eq!(
        c.pump_centre_hz.to_bits(),
        want.to_bits(),
        "{} vs {want}",
        c.pump_centre_hz
    );
    assert_eq!(c.nominal.gamma, 0.0);
    assert_eq!(c.nominal.wy2, TABLE2.wy2);
}
