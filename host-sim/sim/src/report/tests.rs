//! Tests of the run outputs: files, CSV round trip, plots, text summaries.

use plotters::prelude::*;

use super::figures::{health_bands, zoom_range};
use super::*;
use crate::plot::*;
use crate::summary::{
    Convergence, PhysicalValues, RateValidity, RunCounters, RunSummary, ThetaPair,
};
use crate::trace::{Event, Precision};

fn synthetic_row(k: usize, twin: bool) -> TraceRow {
    let t = k as f64 * 0.002;
    let (drive, sense) = (
        [
            -1e-3, -1.0452, -2e-3, -2.28e-5, -2.4296e-3, -0.0452, -1.266e-4, 1.0,
        ],
        [-1e-3, -1.0265, -2e-3, -1.77e-4, -1.264e-3, 1.0],
    );
    let conv = (-t * 5.0).exp(); // converging estimate
    let wobble = (t * 40.0).sin() * 1e-3;
    let mut row = TraceRow {
        t_s: t,
        pump_hz: 21883.95 + 21.6 * (2.0 * std::f64::consts::PI * 2.0 * t).sin(),
        pump_centre_hz: 21883.95 + if t > 0.4 { 30.0 } else { 0.0 },
        pump_scale: 1.0,
        theta_drive_true: drive,
        theta_sense_true: sense,
        theta_drive_est: drive.map(|v| v * (1.0 + 0.3 * conv + wobble)),
        theta_sense_est: sense.map(|v| v * (1.0 - 0.2 * conv + wobble)),
        phys_true: [
            1e-3, 1e-3, 1e-4, 1.0, 1.0265, 2e-3, 2.303e-3, 1.264e-3, 0.0226, 6.33e-5, 3.8581e-5,
            0.0,
        ],
        phys_est: [0.0; 12],
        rate_dps_true: 150.0,
        rate_dps_est: 150.0 * (1.0 + 0.1 * conv) + wobble,
        drive_amp_um: 1.75 * (1.0 - (-t * 20.0).exp()),
        sense_amp_um: if twin { 0.77 } else { 1.5 } * (1.0 - (-t * 10.0).exp()),
        health: (k as u32 / 7) & 0xff,
        resets: (k / 100) as u32,
        bad_samples: 0,
        rate_dps_slow: 150.0 * (1.0 + 0.1 * conv),
        quadrature_dps: 3837.0,
        rate_valid: k > 20,
        temp_c: 25.0 + 0.01 * k as f64,
        drift_ppm_s: [0.5 * k as f64, -2.0],
        tcf_ppm_k: [-30.0 + k as f64, f64::NAN],
        drift_alarms: (k / 300) as u32,
    };
    row.phys_est = row
        .phys_true
        .map(|v| v * (1.0 + 0.1 * conv) + 1e-9 * wobble);
    if k == 10 {
        row.theta_drive_est[0] = f64::NAN; // a NaN sample must be skipped
        row.rate_dps_est = f64::INFINITY;
    }
    row
}

fn synthetic_summary() -> RunSummary {
    let last = synthetic_row(299, false);
    RunSummary {
        scenario: "synthetic".into(),
        precision: Precision::F32,
        seed: 7,
        sim_seconds: last.t_s,
        theta_true: ThetaPair {
            drive: last.theta_drive_true,
            sense: last.theta_sense_true,
        },
        theta_est: ThetaPair {
            drive: last.theta_drive_est,
            sense: last.theta_sense_est,
        },
        theta_rel_err: ThetaPair::default(),
        physical_true: PhysicalValues::from_array(last.phys_true),
        physical_est: PhysicalValues::from_array(last.phys_est),
        rate_dps_true: 150.0,
        rate_dps_est: 150.2,
        rate_rel_err: 1.3e-3,
        rate_validity: RateValidity::default(),
        wy2_true_final: 1.0265,
        wy2_est_final: 1.0266,
        pump_centre_final_hz: 21913.95,
        convergence_after_dither_start: Convergence {
            within_10pct_s: ThetaPair::from_fn(|j| (j != 3).then_some(0.25)),
            within_1pct_s: ThetaPair::from_fn(|_| None),
        },
        counters: RunCounters {
            resets_drive: 2,
            retunes: 1,
            ..RunCounters::default()
        },
        measures: [
            ("sense_amp_before_drift", Some(1.5)),
            ("sense_amp_after_drift", Some(0.78)),
            ("sense_amp_after_retune", Some(1.64)),
            ("sense_amp_missing", None),
            ("quiet_window", None),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect(),
        sense_amp_ratio: None,
        sense_amp_after_drift_ratio: Some(0.52),
        sense_amp_after_retune_ratio: Some(1.09),
        twin_pump_centre_final_hz: Some(21883.95),
        wall_seconds: 1.5,
    }
}

fn synthetic_result() -> RunResult {
    RunResult {
        scenario: "synthetic".into(),
        precision: Precision::F32,
        trace: (0..300).map(|k| synthetic_row(k, false)).collect(),
        events: vec![
            Event {
                t_s: 0.2,
                what: "ramp wy2".into(),
            },
            Event {
                t_s: 0.35,
                what: "change detected".into(),
            },
        ],
        summary: synthetic_summary(),
        twin: Some((0..300).map(|k| synthetic_row(k, true)).collect()),
    }
}

fn parse_field(s: &str) -> f64 {
    s.parse::<f64>()
        .unwrap_or_else(|e| panic!("bad number '{s}': {e}"))
}

fn same(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

#[test]
fn fmt_f64_round_trips() {
    for x in [
        0.0,
        -0.0,
        1.0,
        -1.0452,
        3.8581e-5,
        1e-300,
        6.02e23,
        21883.952639786974,
        f64::MIN_POSITIVE,
        f64::MAX,
        std::f64::consts::PI,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ] {
        assert!(same(parse_field(&fmt_f64(x)), x), "{x} → {}", fmt_f64(x));
    }
    assert!(parse_field(&fmt_f64(f64::NAN)).is_nan());
    assert!(fmt_f64(1e-300).len() < 12);
}

#[test]
fn writes_all_outputs_and_the_csv_parses_back() {
    let dir = std::env::temp_dir().join(format!("paragyro-report-test-{}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    let result = synthetic_result();
    let files = write_outputs(&dir, &result).unwrap();
    let names: Vec<String> = files
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    for want in [
        "summary.json",
        "trace.csv",
        "trace_twin.csv",
        "theta_drive.png",
        "theta_sense.png",
        "theta_rel_error.png",
        "physical.png",
        "amplitudes_pump.png",
    ] {
        assert!(names.iter().any(|n| n == want), "{want} missing: {names:?}");
        assert!(dir.join(want).is_file());
    }

    // summary.json is the summary, keys in alphabetical order, one per measure.
    let text = fs::read_to_string(dir.join("summary.json")).unwrap();
    assert_eq!(text, result.summary.to_json_pretty().unwrap());
    let keys: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("  \""))
        .filter_map(|l| l.split('"').nth(1))
        .collect();
    let mut sorted = keys.clone();
    sorted.sort_unstable();
    assert_eq!(keys, sorted);
    for want in [
        "convergence_after_dither_start",
        "quiet_window",
        "sense_amp_before_drift",
        "sense_amp_after_retune_ratio",
        "twin_pump_centre_final_hz",
        "wall_seconds",
    ] {
        assert!(keys.contains(&want), "{want} missing: {keys:?}");
    }
    assert!(
        !keys.contains(&"sense_amp_ratio"),
        "absent ratios are left out"
    );
    assert!(text.contains("\"sense_amp_missing\": null"), "{text}");
    assert!(text.contains("\"th14\": null"), "{text}");
    assert!(text.contains("\"precision\": \"f32\""), "{text}");

    // trace.csv: header, one row per sample, numbers round-trip.
    let csv = fs::read_to_string(dir.join("trace.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let ncol = 4 + 2 * 14 + 2 * 12 + 4 + HEALTH_NAMES.len() + 2 + 3 + 5 + 1;
    assert_eq!(header.len(), ncol);
    assert_eq!(header, csv_header());
    assert_eq!(header[0], "t_s");
    assert_eq!(header[4], "th11_true");
    assert_eq!(header[18], "th11_est");
    assert_eq!(header[32], "mu_x_true");
    assert_eq!(header[44], "mu_x_est");
    assert_eq!(header[ncol - 10], "bad_samples");
    assert_eq!(header[ncol - 7], "rate_valid");
    assert_eq!(header[ncol - 6], "temp_c");
    assert_eq!(header[ncol - 2], "tcf_wy_ppm_k");
    assert_eq!(header[ncol - 1], "drift_alarms");
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), result.trace.len());
    for (line, r) in rows.iter().zip(&result.trace) {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), ncol);
        let v: Vec<f64> = f[..60].iter().map(|s| parse_field(s)).collect();
        let mut want = vec![r.t_s, r.pump_hz, r.pump_centre_hz, r.pump_scale];
        want.extend(r.theta_drive_true);
        want.extend(r.theta_sense_true);
        want.extend(r.theta_drive_est);
        want.extend(r.theta_sense_est);
        want.extend(r.phys_true);
        want.extend(r.phys_est);
        want.extend([
            r.rate_dps_true,
            r.rate_dps_est,
            r.drive_amp_um,
            r.sense_amp_um,
        ]);
        for (i, (a, b)) in v.iter().zip(&want).enumerate() {
            assert!(same(*a, *b), "column {} ({}): {a} vs {b}", i, header[i]);
        }
        for bit in 0..HEALTH_NAMES.len() {
            let want = if r.health >> bit & 1 == 1 { "1" } else { "0" };
            assert_eq!(f[60 + bit], want);
        }
        assert_eq!(f[ncol - 11].parse::<u32>().unwrap(), r.resets);
        assert_eq!(f[ncol - 10].parse::<u32>().unwrap(), r.bad_samples);
        assert!(same(parse_field(f[ncol - 9]), r.rate_dps_slow));
        assert!(same(parse_field(f[ncol - 8]), r.quadrature_dps));
        assert_eq!(f[ncol - 7], if r.rate_valid { "1" } else { "0" });
        assert!(same(parse_field(f[ncol - 6]), r.temp_c));
        assert!(same(parse_field(f[ncol - 5]), r.drift_ppm_s[0]));
        assert!(same(parse_field(f[ncol - 4]), r.drift_ppm_s[1]));
        assert!(same(parse_field(f[ncol - 3]), r.tcf_ppm_k[0]));
        assert!(same(parse_field(f[ncol - 2]), r.tcf_ppm_k[1]));
        assert_eq!(f[ncol - 1].parse::<u32>().unwrap(), r.drift_alarms);
    }

    // The PNGs are real images of some size.
    for name in names.iter().filter(|n| n.ends_with(".png")) {
        let bytes = fs::read(dir.join(name)).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{name} is not a PNG");
        assert!(
            bytes.len() > 20_000,
            "{name} too small: {} bytes",
            bytes.len()
        );
        // IHDR: width and height.
        let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
        let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
        assert_eq!((w, h), (FIG_W, FIG_H), "{name}");
    }
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn summary_text_has_the_tables_and_ratios() {
    let result = synthetic_result();
    let s = print_summary(&result);
    for want in [
        "synthetic",
        "th14",
        "th26",
        "wy2",
        "Rate: true 150.000",
        "sense_amp_after_retune",
        "× sense_amp_before_drift",
        "0.520 × sense_amp_before_drift",
        "change detected",
        "wall_seconds: 1.5",
        "quiet_window: null",
        "seed: 7",
        "twin_pump_centre_final_hz: 21883.95",
        "counters: bad_samples 0, jumps 0, resets_drive 2, resets_sense 0, \
         retune_aborts 0, retunes 1, samples 0, updates 0",
        "within_10pct_s: th11 0.25, th12 0.25, th13 0.25, th14 null, th15 0.25",
    ] {
        assert!(s.contains(want), "'{want}' missing from:\n{s}");
    }
    let short = short_summary(&result);
    assert!(short.contains("worst θ relative error"), "{short}");
    let empty = RunResult {
        trace: Vec::new(),
        twin: None,
        ..synthetic_result()
    };
    assert!(print_summary(&empty).contains("empty trace"));
    assert!(short_summary(&empty).contains("empty trace"));
}

#[test]
fn zoom_range_clips_startup_spikes() {
    let t: Vec<f64> = (0..1000).map(|k| k as f64 * 0.002).collect();
    let truth = vec![-2.28e-5; 1000];
    let est: Vec<f64> = t
        .iter()
        .map(|&t| if t < 0.5 { -1e-2 } else { -2.28e-5 * 1.01 })
        .collect();
    let (lo, hi) = zoom_range(&t, &truth, &est, 1.0, 0.2);
    assert!((lo + 2.28e-5 * 1.2).abs() < 1e-12 && (hi + 2.28e-5 * 0.8).abs() < 1e-12);
    // A 10 % transient after the settle time is clipped, not zoomed out to.
    let est: Vec<f64> = t
        .iter()
        .map(|&t| {
            if (1.0..1.1).contains(&t) {
                -1e-2
            } else {
                -2.28e-5 * 1.01
            }
        })
        .collect();
    let (lo, hi) = zoom_range(&t, &truth, &est, 0.5, 0.02);
    assert!(lo > -2.28e-5 * 1.1 && hi < -2.28e-5 * 0.9, "{lo} {hi}");
    // Truth 0 (γ' = 0): the range comes from the spread.
    let zero = vec![0.0; 1000];
    let est: Vec<f64> = t.iter().map(|&t| 1e-7 * (t * 9.0).sin()).collect();
    let (lo, hi) = zoom_range(&t, &zero, &est, 0.0, 0.2);
    assert!(lo < 0.0 && hi > 0.0 && hi < 4e-7, "{lo} {hi}");
}

#[test]
fn bands_and_segments() {
    let rows: Vec<TraceRow> = (0..100)
        .map(|k| {
            let mut r = synthetic_row(k, false);
            r.health = if (20..30).contains(&k) || k == 60 {
                1 << 7
            } else {
                0
            };
            r
        })
        .collect();
    let b = health_bands(&rows, "retuning", RED.mix(0.2), 0.01);
    assert_eq!(b.len(), 2);
    assert!((b[0].x0 - 0.039).abs() < 1e-9 && (b[0].x1 - 0.059).abs() < 1e-9);
    assert!((b[1].x1 - b[1].x0 - 0.01).abs() < 1e-12, "minimum width");
    let s = segments(
        &[(0.0, 1.0), (1.0, f64::NAN), (2.0, 5.0), (3.0, -5.0)],
        (-1.0, 2.0),
    );
    assert_eq!(s, vec![vec![(0.0, 1.0)], vec![(2.0, 2.0), (3.0, -1.0)]]);
}
