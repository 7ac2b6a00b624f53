//! The snapshot codec and the warm start.

extern crate std;
use super::*;
use crate::config::Config;

fn settled_snapshot(est: &Estimator<f32>) -> Snapshot {
    let (t1, t2) = theta_from_physical(&est.config().nominal);
    let mut t1s = t1;
    t1s[1] *= 1.01; // a learned value, not the design's
    let p = crate::physics::physical_from_theta(&t1s, &t2);
    Snapshot {
        config_crc: config_crc(est.config()),
        health_bits: SETTLED_BIT | 1,
        theta1: t1s,
        theta2: t2,
        pump_centre_hz: est.pump_centre_hz() + 3.0,
        traces: [8e-6, 6e-6],
        temp_c: 25.0,
        // ω_x², ω_y² falling 60 and 66 ppm/K (frequency TCFs of −30 and −33 ppm/K):
        // θ12, θ22 (−ω² + …) rise by as much of ω²
        dtheta_dt: [60e-6 * p.wx2, 66e-6 * p.wy2],
        dtheta_dt_var: [1e-16, 1e-16],
        // the design's μxy + 2 % (in °/s: 2e-6 of μxy is ≈ 3.9 °/s of rate), a mean of
        // an hour of updates
        zero: [1.02 * est.config().nominal.mu_xy, 72_000.0],
    }
}

#[test]
fn crc32_matches_the_standard_check_value() {
    assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    assert_eq!(crc32(b""), 0);
}

#[test]
fn encode_decode_round_trip_bit_exact() {
    let est = Config::table2().build::<f32>().unwrap();
    let s = settled_snapshot(&est);
    let bytes = s.encode();
    assert_eq!(&bytes[..4], b"PGWS");
    assert_eq!(Snapshot::decode(&bytes), Ok(s));
    // a longer buffer (a flash slot) reads its first SNAPSHOT_LEN bytes
    let mut long = [0xFFu8; 300];
    long[..SNAPSHOT_LEN].copy_from_slice(&bytes);
    assert_eq!(Snapshot::decode(&long), Ok(s));
}

#[test]
fn every_single_bit_flip_and_truncation_is_refused() {
    let est = Config::table2().build::<f32>().unwrap();
    let bytes = settled_snapshot(&est).encode();
    for i in 0..SNAPSHOT_LEN * 8 {
        let mut b = bytes;
        b[i / 8] ^= 1 << (i % 8);
        assert!(
            Snapshot::decode(&b).is_err(),
            "bit {i} flipped and accepted"
        );
    }
    assert_eq!(
        Snapshot::decode(&bytes[..SNAPSHOT_LEN - 1]),
        Err(SnapshotError::Short)
    );
    assert_eq!(
        Snapshot::decode(&[0xFF; SNAPSHOT_LEN]),
        Err(SnapshotError::Magic)
    );
    let mut v2 = bytes;
    v2[4] = 1;
    assert_eq!(Snapshot::decode(&v2), Err(SnapshotError::Version(1)));
}

#[test]
fn warm_start_restores_theta_and_pump_centre() {
    let mut est = Config::table2().build::<f32>().unwrap();
    let s = settled_snapshot(&est);
    assert_eq!(est.boot_from(Some(&s.encode())), Start::Warm);
    let (t1, t2) = est.theta();
    assert_eq!((t1, t2), (s.theta1, s.theta2));
    assert!((est.pump_centre_hz() - s.pump_centre_hz).abs() < 1e-6);
    assert!((est.initial_pump_hz() - s.pump_centre_hz).abs() < 1e-6);
    // the covariance restarts at the stored trace per parameter
    let (tr1, tr2) = est.traces();
    assert!(
        (tr1 - 8e-6).abs() < 1e-9 && (tr2 - 6e-6).abs() < 1e-9,
        "{tr1} {tr2}"
    );
}

#[test]
fn unusable_records_leave_the_design_with_a_flag() {
    let cfg = Config::table2();
    let fresh = cfg.build::<f32>().unwrap();
    let design = fresh.theta();
    let s = settled_snapshot(&fresh);
    let cold = |rec: Option<&[u8]>| {
        let mut est = cfg.build::<f32>().unwrap();
        let start = est.boot_from(rec);
        assert_eq!(est.theta(), design, "{start:?}: the design was changed");
        assert_eq!(est.pump_centre_hz(), fresh.pump_centre_hz());
        start
    };
    assert_eq!(cold(None), Start::Cold(SnapshotError::Missing));
    let mut torn = s.encode();
    torn[40] ^= 0x10;
    assert_eq!(cold(Some(&torn)), Start::Cold(SnapshotError::Crc));
    assert_eq!(cold(Some(&[0u8; 10])), Start::Cold(SnapshotError::Short));
    let foreign = Snapshot {
        config_crc: s.config_crc ^ 1,
        ..s
    };
    assert_eq!(
        cold(Some(&foreign.encode())),
        Start::Cold(SnapshotError::Config)
    );
    let unsettled = Snapshot {
        health_bits: 1,
        ..s
    };
    let mut nan = s;
    nan.theta2[1] = f64::NAN;
    let mut far = s;
    far.pump_centre_hz *= 1.2;
    let mut wild = s;
    wild.theta1[0] *= 10.0;
    for bad in [unsettled, nan, far, wild] {
        assert_eq!(
            cold(Some(&bad.encode())),
            Start::Cold(SnapshotError::Implausible)
        );
    }
    // another configuration's estimator refuses this one's snapshot
    let mut other = cfg;
    other.pump_centre_hz += 10.0;
    let mut est = other.build::<f32>().unwrap();
    assert_eq!(
        est.boot_from(Some(&s.encode())),
        Start::Cold(SnapshotError::Config)
    );
}

#[test]
fn a_record_taken_at_25_c_restored_at_35_c_starts_at_35_c() {
    let mut est = Config::table2().build::<f32>().unwrap();
    let s = settled_snapshot(&est);
    let wy2 = |t1: &[f64; 8], t2: &[f64; 6]| {
        let g = (t1[3] - t2[3]) / 4.0;
        -t2[1] + g * g
    };
    let wy2_25 = wy2(&s.theta1, &s.theta2);
    assert_eq!(est.boot_from_at(Some(&s.encode()), Some(35.0)), Start::Warm);
    let (t1, t2) = est.theta();
    // θ22 moved by its coefficient over 10 K: ω̂y² 660 ppm lower, and the pump with √ of it
    assert!((t2[1] - s.theta2[1] - 10.0 * s.dtheta_dt[1]).abs() < 1e-12);
    assert!((t1[1] - s.theta1[1] - 10.0 * s.dtheta_dt[0]).abs() < 1e-12);
    let ratio = wy2(&t1, &t2) / wy2_25;
    assert!((ratio - (1.0 - 660e-6)).abs() < 1e-9, "{ratio}");
    // the pump at 2·f_y(35 °C), 330 ppm (7.2 Hz) below 2·f_y(25 °C)
    let f0 = est.config().f0_hz;
    let want = 2.0 * f0 * wy2(&t1, &t2).sqrt();
    assert!((est.initial_pump_hz() - want).abs() < 1e-6);
    let at_25 = 2.0 * f0 * wy2_25.sqrt();
    assert!((at_25 - want - 330e-6 * at_25).abs() < 0.01, "{want}");
    // the coefficients are learned from the first tick on
    let th = est.thermal();
    for (got, want) in th.tcf_ppm_k.iter().zip([-30.0, -33.0]) {
        assert!((got - want).abs() < 0.2, "{:?}", th.tcf_ppm_k);
    }
    // without a temperature now, or without one in the record: the record as taken
    for (rec, now) in [
        (s, None),
        (
            Snapshot {
                temp_c: f64::NAN,
                ..s
            },
            Some(35.0),
        ),
    ] {
        let mut e = Config::table2().build::<f32>().unwrap();
        assert_eq!(e.boot_from_at(Some(&rec.encode()), now), Start::Warm);
        assert_eq!(e.theta(), (s.theta1, s.theta2));
        assert!((e.initial_pump_hz() - s.pump_centre_hz).abs() < 1e-6);
    }
}

#[test]
fn snapshot_of_an_estimator_is_what_it_holds() {
    let est = Config::table2().build::<f64>().unwrap();
    let s = est.snapshot();
    assert_eq!((s.theta1, s.theta2), est.theta());
    assert_eq!(s.pump_centre_hz, est.pump_centre_hz());
    assert_eq!(s.health_bits, est.health().bits());
    // not settled: refused at boot
    let mut e2 = Config::table2().build::<f64>().unwrap();
    assert_eq!(
        e2.boot_from(Some(&s.encode())),
        Start::Cold(SnapshotError::Implausible)
    );
}

#[test]
fn warm_start_shortens_the_start_up_gate_only() {
    let cfg = Config::table2();
    assert_eq!((cfg.monitor.gate_startup_s, cfg.fs_hz), (0.5, 500.0));
    let mut cold = cfg.build::<f32>().unwrap();
    let s = settled_snapshot(&cold);
    assert_eq!(cold.boot_from(None), Start::Cold(SnapshotError::Missing));
    let mut warm = cfg.build::<f32>().unwrap();
    assert_eq!(warm.boot_from(Some(&s.encode())), Start::Warm);
    let (c, w) = (cold.design_mut().watch, warm.design_mut().watch);
    assert_eq!((c.gate_startup, w.gate_startup), (250, 125));
    assert_eq!(w.gate_startup, (WARM_GATE_S * cfg.fs_hz) as u64);
    assert_eq!(
        (w.settle_window, w.gate_jump, w.gate_bad),
        (c.settle_window, c.gate_jump, c.gate_bad)
    );
}

/// A warm start goes on with the stored rate's zero (μxy) as a mean, its count capped at
/// [`crate::rate::ZERO_RESTORE_S`] of updates; a record without one (count 0) starts the
/// zero afresh as a cold start does; and a snapshot holds the zero the estimator holds.
#[test]
fn warm_start_restores_the_rates_zero_as_a_capped_mean() {
    let cfg = Config::table2();
    let mut est = cfg.build::<f32>().unwrap();
    let s = settled_snapshot(&est);
    assert_eq!(est.boot_from(Some(&s.encode())), Start::Warm);
    let cap = crate::rate::ZERO_RESTORE_S * cfg.fs_hz / crate::rate::ZERO_EVERY as f64;
    let (mu0, n0) = est.rate_zero();
    assert!((mu0 - s.zero[0]).abs() <= 1e-6 * s.zero[0].abs(), "{mu0}");
    assert_eq!(n0, cap);
    // kept through the first ticks (the nominal re-formed about the restored θ̂, the
    // zero held while the warm gate lasts)
    let sample = crate::sample::Sample::default();
    for _ in 0..10 {
        est.step(&sample);
    }
    let (mu, n) = est.rate_zero();
    assert_eq!(mu, mu0);
    assert_eq!(n, cap);
    assert_eq!(est.snapshot().zero, [mu, n]);
    // none stored: the mean starts afresh
    let mut e2 = cfg.build::<f32>().unwrap();
    let none = Snapshot {
        zero: [s.zero[0], 0.0],
        ..s
    };
    assert_eq!(e2.boot_from(Some(&none.encode())), Start::Warm);
    assert_eq!(e2.rate_zero().1, 0.0);
}
