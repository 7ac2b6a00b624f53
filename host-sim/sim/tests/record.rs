//! The record format (`paragyro-record 1`): round trip, every malformed case, the simulated
//! record against the runner, and the open-loop replay.

use std::path::PathBuf;

use paragyro_core::{Cplx, Sample};
use paragyro_simulator::record::{
    self, EffectSpec, OPTIONAL_COLUMNS, REQUIRED_COLUMNS, Record, RecordErrorKind, RecordHeader,
    RecordOptions, RecordRow, parse_record, read_record, replay, simulate_record,
    simulate_record_with, truth_path, write_record, write_record_to, write_simulated_record,
};
use paragyro_simulator::runner::{self, Precision, RunOptions};
use paragyro_simulator::scenario::Scenario;

/// A fresh scratch directory for one test.
fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("paragyro-record-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn header() -> RecordHeader {
    RecordHeader {
        f0_hz: 2.618 / 3.8581e-5 / (2.0 * std::f64::consts::PI),
        l0_um: 1.0,
        fs_hz: 500.0,
        lockin_lpf_order: 4,
        lockin_lpf_hz: 150.0,
        pump_amp_ref_v: 1.0,
        extra: vec![("device".into(), "bench unit #3".into())],
    }
}

/// A synthetic record with awkward numbers: NaN, ±inf, −0, subnormals, huge and tiny
/// values, values that `{}` would print with many digits.
fn synthetic(n: usize, temp: bool, rate: bool) -> Record {
    let awkward = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        -0.0,
        5e-324,
        1e-300,
        1.7976931348623157e308,
        0.1 + 0.2,
        -1.234_567_890_123_456_7e-7,
        1e16,
        9_999_999_999_999_998.0,
        1e-5,
        std::f64::consts::PI,
    ];
    let rows = (0..n)
        .map(|k| {
            let mut v = [0.0; 19];
            v[0] = k as f64 / 500.0;
            for (j, x) in v.iter_mut().enumerate().skip(1) {
                *x = if (k + j) % 5 == 0 {
                    awkward[(k * 7 + j) % awkward.len()]
                } else {
                    ((k * 31 + j * 17) as f64).sin() * 10f64.powi((j as i32 % 7) - 3)
                };
            }
            let t = (temp && k % 3 != 0).then_some(25.0 + k as f64 * 1e-3);
            let r = (rate && k % 4 != 1).then_some(if k == 2 { f64::NAN } else { 150.0 });
            RecordRow::from_required(&v, t, r)
        })
        .collect();
    Record {
        header: header(),
        rows,
        warnings: Vec::new(),
    }
}

fn same_bits(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits()
}

fn assert_bit_exact(a: &Record, b: &Record) {
    let h = (&a.header, &b.header);
    assert!(same_bits(h.0.f0_hz, h.1.f0_hz));
    assert!(same_bits(h.0.l0_um, h.1.l0_um));
    assert!(same_bits(h.0.fs_hz, h.1.fs_hz));
    assert!(same_bits(h.0.lockin_lpf_hz, h.1.lockin_lpf_hz));
    assert!(same_bits(h.0.pump_amp_ref_v, h.1.pump_amp_ref_v));
    assert_eq!(h.0.lockin_lpf_order, h.1.lockin_lpf_order);
    assert_eq!(h.0.extra, h.1.extra);
    assert_eq!(a.rows.len(), b.rows.len());
    for (k, (x, y)) in a.rows.iter().zip(&b.rows).enumerate() {
        for (j, (u, v)) in x.required().iter().zip(y.required().iter()).enumerate() {
            assert!(
                same_bits(*u, *v),
                "row {k} column {}: {u:e} vs {v:e}",
                REQUIRED_COLUMNS[j]
            );
        }
        let opt = |p: Option<f64>, q: Option<f64>| match (p, q) {
            (None, None) => true,
            (Some(p), Some(q)) => same_bits(p, q),
            _ => false,
        };
        assert!(opt(x.temp_c, y.temp_c), "row {k} temp_c");
        assert!(opt(x.rate_ref_dps, y.rate_ref_dps), "row {k} rate_ref_dps");
    }
}

#[test]
fn round_trip_is_bit_exact_with_nan_and_optional_columns() {
    let dir = scratch("roundtrip");
    let rec = synthetic(600, true, true);
    let path = dir.join("r.csv");
    write_record(&path, &rec).unwrap();
    let back = read_record(&path).unwrap();
    assert_bit_exact(&rec, &back);
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.starts_with("# format: paragyro-record 1\n# f0_hz: "));
    assert!(text.contains("# device: bench unit #3\n"));
    let cols = text.lines().find(|l| !l.starts_with('#')).unwrap();
    assert_eq!(
        cols,
        format!("{},temp_c,rate_ref_dps", REQUIRED_COLUMNS.join(","))
    );
    assert!(text.contains(",nan,"), "NaN is written as nan");
    // NaN rows are kept, with one warning
    assert_eq!(back.warnings.len(), 1, "{:?}", back.warnings);
    assert!(back.warnings[0].contains("NaN"), "{:?}", back.warnings);
    // the same through the in-memory parser
    assert_bit_exact(&rec, &parse_record(&text, "r.csv").unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn optional_columns_only_when_some_row_has_them() {
    for (temp, rate, want) in [
        (false, false, ""),
        (true, false, ",temp_c"),
        (false, true, ",rate_ref_dps"),
    ] {
        let rec = synthetic(20, temp, rate);
        let mut buf = Vec::new();
        write_record_to(&mut buf, &rec).unwrap();
        let text = String::from_utf8(buf).unwrap();
        let cols = text.lines().find(|l| !l.starts_with('#')).unwrap();
        assert_eq!(cols, format!("{}{want}", REQUIRED_COLUMNS.join(",")));
        let back = parse_record(&text, "x.csv").unwrap();
        assert_bit_exact(&rec, &back);
    }
}

// ---------------------------------------------------------------------------------------------
// Malformed records: each error names the file, the line, the column number and name
// ---------------------------------------------------------------------------------------------

const HEAD: &str = "# format: paragyro-record 1\n# f0_hz: 10799.814\n# l0_um: 1\n# fs_hz: 500\n\
                    # lockin_lpf_order: 4\n# lockin_lpf_hz: 150\n# pump_amp_ref_v: 1\n";
/// Line of the header row in texts built from `HEAD`.
const COLS_LINE: usize = 8;

fn data_row(k: usize) -> Vec<String> {
    let mut v = vec![
        format!("{}", k as f64 / 500.0),
        "21883.9526".into(),
        "1".into(),
        "98.0665".into(),
        "98.0665".into(),
    ];
    v.extend((0..14).map(|j| format!("{}", 0.25 * j as f64 - 1.0 + k as f64 * 1e-4)));
    v
}

/// `HEAD`, the standard header row, `n` rows; `edit(k, fields)` may change row k.
fn text_with(n: usize, edit: impl Fn(usize, &mut Vec<String>)) -> String {
    let mut s = String::from(HEAD);
    s.push_str(&REQUIRED_COLUMNS.join(","));
    s.push('\n');
    for k in 0..n {
        let mut f = data_row(k);
        edit(k, &mut f);
        s.push_str(&f.join(","));
        s.push('\n');
    }
    s
}

fn fails(text: &str) -> record::RecordError {
    parse_record(text, "rec.csv").expect_err("the record must be rejected")
}

/// The message starts with `rec.csv:LINE:COL: ` and names `what`.
fn check(e: &record::RecordError, kind: RecordErrorKind, line: usize, col: usize, what: &str) {
    let msg = e.to_string();
    println!("{msg}");
    assert_eq!(e.kind, kind, "{msg}");
    assert_eq!((e.line, e.column), (Some(line), Some(col)), "{msg}");
    assert!(msg.starts_with(&format!("rec.csv:{line}:{col}: ")), "{msg}");
    assert!(msg.contains(what), "{msg} should name {what}");
}

#[test]
fn valid_text_parses() {
    let rec = parse_record(&text_with(200, |_, _| {}), "rec.csv").unwrap();
    assert_eq!(rec.rows.len(), 200);
    assert!(rec.warnings.is_empty());
    assert_eq!(rec.header.lockin_lpf_order, 4);
    assert_eq!(
        rec.rows[3].lockin.x_um[0],
        Cplx::new(-0.75 + 3e-4, -0.5 + 3e-4)
    );
}

#[test]
fn malformed_number_names_line_and_column() {
    // row 114 sits on line 9 + 114 = 123; x1_re_um is the 7th column
    let text = text_with(200, |k, f| {
        if k == 114 {
            f[6] = "abc".into();
        }
    });
    let e = fails(&text);
    assert_eq!(
        e.to_string(),
        "rec.csv:123:7: column 'x1_re_um': expected a number, found 'abc'"
    );
    assert_eq!(e.kind, RecordErrorKind::Number);
}

#[test]
fn empty_required_field_is_an_error() {
    let text = text_with(10, |k, f| {
        if k == 4 {
            f[18] = String::new();
        }
    });
    check(
        &fails(&text),
        RecordErrorKind::Number,
        COLS_LINE + 5,
        19,
        "column 'y3_im_um': expected a number, found an empty field",
    );
}

#[test]
fn empty_file() {
    for text in ["", "\n\n  \n"] {
        check(
            &fails(text),
            RecordErrorKind::Empty,
            1,
            1,
            "the file is empty",
        );
    }
}

#[test]
fn missing_format_line() {
    let text = text_with(3, |_, _| {}).replacen("# format: paragyro-record 1\n", "", 1);
    check(
        &fails(&text),
        RecordErrorKind::Format,
        1,
        1,
        "header 'format': the first line must be '# format: paragyro-record 1'",
    );
    // a plain CSV
    let e = fails("t_s,pump_hz\n0,1\n");
    check(&e, RecordErrorKind::Format, 1, 1, "header 'format'");
}

#[test]
fn wrong_format_or_version() {
    let text = text_with(3, |_, _| {}).replacen("paragyro-record 1", "other-record 1", 1);
    check(
        &fails(&text),
        RecordErrorKind::Format,
        1,
        11,
        "header 'format': expected 'paragyro-record 1', found 'other-record 1'",
    );
    let text = text_with(3, |_, _| {}).replacen("paragyro-record 1", "paragyro-record 2", 1);
    check(
        &fails(&text),
        RecordErrorKind::Format,
        1,
        11,
        "header 'format': unsupported version '2'",
    );
}

#[test]
fn missing_header_key() {
    let text = text_with(3, |_, _| {}).replacen("# lockin_lpf_hz: 150\n", "", 1);
    // the header row moves up to line 7: the key is missing before it
    check(
        &fails(&text),
        RecordErrorKind::Header,
        COLS_LINE - 1,
        1,
        "header 'lockin_lpf_hz': required header line '# lockin_lpf_hz: <value>' is missing",
    );
}

#[test]
fn bad_header_values() {
    let text = text_with(3, |_, _| {}).replacen("# f0_hz: 10799.814", "# f0_hz: fast", 1);
    check(
        &fails(&text),
        RecordErrorKind::Header,
        2,
        10,
        "header 'f0_hz': expected a positive number, found 'fast'",
    );
    let text =
        text_with(3, |_, _| {}).replacen("# lockin_lpf_order: 4", "# lockin_lpf_order: 4.5", 1);
    check(
        &fails(&text),
        RecordErrorKind::Header,
        5,
        21,
        "header 'lockin_lpf_order': expected an integer 1..=8, found '4.5'",
    );
    let text = text_with(3, |_, _| {}).replacen("# fs_hz: 500", "# fs_hz: -500", 1);
    check(
        &fails(&text),
        RecordErrorKind::Header,
        4,
        10,
        "header 'fs_hz': expected a positive number, found '-500'",
    );
}

#[test]
fn repeated_header_key() {
    let text = text_with(3, |_, _| {}).replacen("# l0_um: 1\n", "# l0_um: 1\n# l0_um: 2\n", 1);
    check(
        &fails(&text),
        RecordErrorKind::Header,
        4,
        3,
        "header 'l0_um': repeated (first on line 3)",
    );
}

#[test]
fn missing_required_columns_are_named() {
    let cols: Vec<&str> = REQUIRED_COLUMNS
        .iter()
        .copied()
        .filter(|c| *c != "x3_im_um" && *c != "y0_um")
        .collect();
    let mut text = String::from(HEAD);
    text.push_str(&cols.join(","));
    text.push('\n');
    text.push_str(&vec!["0"; cols.len()].join(","));
    text.push('\n');
    let e = fails(&text);
    check(
        &e,
        RecordErrorKind::Columns,
        COLS_LINE,
        12,
        "column 'x3_im_um': required column is missing",
    );
    assert!(e.to_string().contains("'x3_im_um', 'y0_um'"), "{e}");
}

#[test]
fn repeated_column() {
    let text = text_with(3, |_, _| {}).replacen("y3_im_um", "y3_im_um,x0_um", 1);
    check(
        &fails(&text),
        RecordErrorKind::Columns,
        COLS_LINE,
        20,
        "column 'x0_um': repeated (first as column 6)",
    );
}

#[test]
fn wrong_field_count() {
    let text = text_with(10, |k, f| {
        if k == 6 {
            f.push("1".into());
        }
    });
    check(
        &fails(&text),
        RecordErrorKind::Row,
        COLS_LINE + 7,
        20,
        "the row has 20 fields, expected 19 (as the header row on line 8)",
    );
    let text = text_with(10, |k, f| {
        if k == 2 {
            f.truncate(12);
        }
    });
    check(
        &fails(&text),
        RecordErrorKind::Row,
        COLS_LINE + 3,
        13,
        "column 'y0_um': the row has 12 fields, expected 19",
    );
}

#[test]
fn time_must_increase() {
    let text = text_with(10, |k, f| {
        if k == 5 {
            f[0] = "0.006".into(); // row 4 is at 0.008
        }
    });
    check(
        &fails(&text),
        RecordErrorKind::Time,
        COLS_LINE + 6,
        1,
        "column 't_s': time does not increase: 0.006 s after 0.008 s on line 13",
    );
}

#[test]
fn time_must_be_regular() {
    // a dropped sample
    let text = text_with(10, |k, f| {
        if k >= 7 {
            f[0] = format!("{}", (k + 1) as f64 / 500.0);
        }
    });
    check(
        &fails(&text),
        RecordErrorKind::Time,
        COLS_LINE + 8,
        1,
        "column 't_s': irregular sampling: step of",
    );
    // 0.5 % jitter is fine, 2 % is not
    let ok = text_with(10, |k, f| {
        if k == 3 {
            f[0] = format!("{}", 3.01 / 500.0);
        }
    });
    assert!(parse_record(&ok, "rec.csv").is_ok());
    let bad = text_with(10, |k, f| {
        if k == 3 {
            f[0] = format!("{}", 3.02 / 500.0);
        }
    });
    check(
        &fails(&bad),
        RecordErrorKind::Time,
        COLS_LINE + 4,
        1,
        "expected 1/fs_hz = 0.002 s within 1 %",
    );
    // NaN time
    let nan = text_with(10, |k, f| {
        if k == 2 {
            f[0] = "nan".into();
        }
    });
    check(
        &fails(&nan),
        RecordErrorKind::Time,
        COLS_LINE + 3,
        1,
        "column 't_s': expected a finite time, found 'nan'",
    );
}

#[test]
fn no_header_row_or_no_rows() {
    check(
        &fails(HEAD),
        RecordErrorKind::Columns,
        COLS_LINE,
        1,
        "header row: missing",
    );
    check(
        &fails(&text_with(0, |_, _| {})),
        RecordErrorKind::Row,
        COLS_LINE + 1,
        1,
        "no sample rows",
    );
}

#[test]
fn unreadable_file_is_named() {
    let p = std::env::temp_dir().join("paragyro-record-no-such-file.csv");
    let e = read_record(&p).unwrap_err();
    assert_eq!(e.kind, RecordErrorKind::Io);
    assert!(
        e.to_string()
            .starts_with(&format!("{}: cannot read the record", p.display())),
        "{e}"
    );
}

// ---------------------------------------------------------------------------------------------
// Leniency
// ---------------------------------------------------------------------------------------------

#[test]
fn unknown_column_warns_and_data_is_read() {
    let mut text = String::from(HEAD);
    text.push_str("# operator: jd\n# a free comment\n");
    // an unknown column in the middle, columns reordered, optional temp_c
    let mut cols: Vec<&str> = REQUIRED_COLUMNS.to_vec();
    cols.swap(5, 12);
    cols.insert(3, "board_mv");
    cols.push("temp_c");
    text.push_str(&cols.join(","));
    text.push_str("\r\n");
    for k in 0..20 {
        let f = data_row(k);
        let mut g: Vec<String> = f.clone();
        g.swap(5, 12);
        g.insert(3, "3300".into());
        g.push(if k % 2 == 0 {
            "21.5".into()
        } else {
            String::new()
        });
        text.push_str(&g.join(","));
        text.push_str("\r\n");
    }
    let rec = parse_record(&format!("\u{feff}{text}"), "rec.csv").unwrap();
    assert_eq!(rec.rows.len(), 20);
    assert_eq!(rec.warnings.len(), 1, "{:?}", rec.warnings);
    assert_eq!(
        rec.warnings[0],
        "rec.csv:10:4: column 'board_mv' is not part of paragyro-record 1: ignored"
    );
    assert_eq!(rec.header.extra, vec![("operator".into(), "jd".into())]);
    let r = &rec.rows[4];
    let want = data_row(4);
    assert_eq!(r.lockin.x0_um, want[5].parse::<f64>().unwrap());
    assert_eq!(r.lockin.y0_um, want[12].parse::<f64>().unwrap());
    assert_eq!(r.ax_mps2, 98.0665);
    assert_eq!(r.temp_c, Some(21.5));
    assert_eq!(rec.rows[5].temp_c, None);
    assert_eq!(r.rate_ref_dps, None);
}

#[test]
fn nan_data_rows_are_kept() {
    let text = text_with(10, |k, f| {
        if k == 3 || k == 7 {
            f[13] = "NaN".into();
        }
    });
    let rec = parse_record(&text, "rec.csv").unwrap();
    assert_eq!(rec.rows.len(), 10);
    assert!(rec.rows[3].lockin.y_um[0].re.is_nan());
    assert_eq!(rec.warnings.len(), 1);
    assert!(
        rec.warnings[0].starts_with("rec.csv:12: 2 row(s) have NaN"),
        "{:?}",
        rec.warnings
    );
    // the core flags and skips them
    let cfg = record::config_for(&rec);
    let out = replay::<f64>(&rec, &cfg).unwrap();
    assert_eq!(out.last().unwrap().counters.bad_samples, 2);
}

#[test]
fn sixty_seconds_parse_fast() {
    let rec = synthetic(30_000, true, false);
    let mut buf = Vec::new();
    let t0 = std::time::Instant::now();
    write_record_to(&mut buf, &rec).unwrap();
    let tw = t0.elapsed();
    let text = String::from_utf8(buf).unwrap();
    let t0 = std::time::Instant::now();
    let back = parse_record(&text, "60s.csv").unwrap();
    let tr = t0.elapsed();
    println!(
        "30 000 rows ({} bytes): write {tw:?}, read {tr:?}",
        text.len()
    );
    assert_eq!(back.rows.len(), 30_000);
    assert!(tr.as_secs_f64() < 1.0 && tw.as_secs_f64() < 1.0);
}

#[test]
fn to_sample_converts_pump_voltage_to_scale() {
    let mut h = header();
    h.pump_amp_ref_v = 2.0;
    let row = synthetic(3, false, false).rows[1];
    let mut row = RecordRow {
        pump_amp_v: 2.2,
        ..row
    };
    row.lockin.x_um[0] = Cplx::new(1.5, -0.5);
    row.ax_mps2 = 9.81;
    let s: Sample<f64> = row.to_sample(&h);
    assert!((s.pump_scale - 1.21).abs() < 1e-15);
    assert_eq!(s.lockin.x_um[0].re, 1.5);
    assert_eq!(s.lockin.x_um[0].im, -0.5);
    assert_eq!(s.accel_mps2[0], 9.81);
    assert_eq!(s.pump_hz, row.pump_hz);
    let s32: Sample<f32> = row.to_sample(&h);
    assert_eq!(s32.lockin.x_um[0].re, 1.5f32);
    assert!((s32.pump_scale - 1.21f32).abs() < 1e-6);
}

// ---------------------------------------------------------------------------------------------
// Simulated records
// ---------------------------------------------------------------------------------------------

fn identify(duration_s: f64) -> Scenario {
    let mut sc = Scenario::builtin("identify").unwrap();
    sc.duration_s = duration_s;
    sc
}

fn rel(a: f64, b: f64) -> f64 {
    if b == 0.0 {
        a.abs()
    } else {
        ((a - b) / b).abs()
    }
}

/// Simulates `sc` as a record and with `runner::simulate` (f64 core, same seed), checks that
/// the rows are what the runner's core saw, writes and reads the record back, replays it
/// open-loop with the runner's configuration and returns the worst relative difference of
/// the final θ̂ (and of every sample's θ̂22) from the runner's.
fn record_vs_runner(sc: &Scenario, seed: u64, name: &str) -> f64 {
    let (rec, truth) = simulate_record(sc, Some(seed)).unwrap();
    let opts = RunOptions {
        precision: Precision::F64,
        seed: Some(seed),
    };
    let run = runner::simulate::<f64>(sc, &opts, &mut |_| {}).unwrap();
    assert_eq!(rec.rows.len(), run.trace.len());
    assert_eq!(rec.rows.len(), (sc.duration_s * 500.0).round() as usize + 1);
    for (r, t) in rec.rows.iter().zip(&run.trace) {
        assert!(same_bits(r.t_s, t.t_s), "t {} vs {}", r.t_s, t.t_s);
        assert!(same_bits(r.pump_hz, t.pump_hz), "{} pump", t.t_s);
        assert!(same_bits(r.x_abs(1), t.drive_amp_um), "{} |A1|", t.t_s);
        assert!(same_bits(r.y_abs(1), t.sense_amp_um), "{} |B1|", t.t_s);
        let s = (r.pump_amp_v / rec.header.pump_amp_ref_v).powi(2);
        assert!(rel(s, t.pump_scale) < 3e-16, "{} s {s}", t.t_s);
        assert!(rel(r.ax_mps2, 98.0665) < 1e-12 && rel(r.ay_mps2, 98.0665) < 1e-12);
        assert_eq!((r.temp_c, r.rate_ref_dps), (None, None));
    }
    // the pump moves (dither from 1 s)
    let (pmin, pmax) = rec.rows.iter().fold((f64::MAX, f64::MIN), |(a, b), r| {
        (a.min(r.pump_hz), b.max(r.pump_hz))
    });
    assert!(pmax - pmin > 10.0, "pump {pmin}..{pmax}");
    assert_eq!(rec.header.f0_hz, sc.sim.f0_hz);
    assert_eq!(rec.header.lockin_lpf_hz, sc.sim.lockin_lpf_hz);
    assert_eq!(rec.header.lockin_lpf_order, sc.sim.lockin_lpf_order);
    assert_eq!(truth.seed, seed);
    assert_eq!(truth.samples, rec.rows.len());

    // through a file, bit-exact
    let dir = scratch(name);
    let path = dir.join("sim.csv");
    write_record(&path, &rec).unwrap();
    let back = read_record(&path).unwrap();
    assert_bit_exact(&rec, &back);
    assert!(back.warnings.is_empty(), "{:?}", back.warnings);
    let _ = std::fs::remove_dir_all(&dir);

    // open-loop replay with the runner's configuration
    let cfg = runner::core_config(sc);
    let est = replay::<f64>(&back, &cfg).unwrap();
    assert_eq!(est.len(), run.trace.len());
    let last = run.trace.last().unwrap();
    let fin = est.last().unwrap();
    let mut worst = 0.0f64;
    for j in 0..8 {
        worst = worst.max(rel(fin.theta_drive[j], last.theta_drive_est[j]));
    }
    for j in 0..6 {
        worst = worst.max(rel(fin.theta_sense[j], last.theta_sense_est[j]));
    }
    println!(
        "{name}: replay vs runner: worst final θ̂ relative difference {worst:.2e}, rate {} vs {} °/s",
        fin.rate_dps, last.rate_dps_slow
    );
    for (e, t) in est.iter().zip(&run.trace) {
        worst = worst.max(rel(e.theta_sense[1], t.theta_sense_est[1]));
    }
    assert!(rel(fin.rate_dps, last.rate_dps_slow) < 1e-10);
    assert_eq!(fin.health, last.health);
    assert_eq!(fin.counters.bad_samples, last.bad_samples);
    // the core commanded this very pump in the closed loop
    for (e, r) in est.iter().zip(back.rows.iter().skip(1)) {
        assert!(same_bits(e.pump_hz_cmd, r.pump_hz), "{}", r.t_s);
    }
    worst
}

/// `identify` (3 s): the pump-voltage dither makes s = (√s)² differ from the runner's s by
/// one ulp on about half the samples; θ̂17 (the s coefficient) carries it to 1.2e-11
/// (how far depends on which ticks the re-linearisations fall on), five orders below the
/// estimate's own scatter: bounded at 1e-10.
#[test]
fn simulated_record_is_what_the_runner_sees_and_replays_to_its_estimate() {
    let worst = record_vs_runner(&identify(3.0), 7, "sim");
    assert!(worst < 1e-10, "θ̂ differs by {worst:e}");
}

/// Without the pump-voltage dither s ≡ 1 is exact in the record: the replay is the
/// runner's estimate bit for bit.
#[test]
fn replay_without_voltage_dither_is_bit_exact() {
    let mut sc = identify(3.0);
    sc.estimator.dither_scale_frac = 0.0;
    let worst = record_vs_runner(&sc, 3, "sim-exact");
    assert_eq!(worst, 0.0);
}

#[test]
fn truth_goes_beside_the_csv_never_into_it() {
    let dir = scratch("truth");
    let out = dir.join("sub").join("short.csv");
    let sc = identify(0.2);
    let (files, rec) =
        write_simulated_record(&sc, &out, &RecordOptions::default(), &mut |_| {}).unwrap();
    assert_eq!(files.csv, out);
    assert_eq!(files.truth, dir.join("sub").join("short.truth.json"));
    assert_eq!(rec.rows.len(), 101);
    // the truth file is the typed truth of the same simulation, with the record's name
    let (_, mut truth) = simulate_record_with(&sc, &RecordOptions::default(), &mut |_| {}).unwrap();
    assert_eq!(truth.scenario, "identify");
    assert_eq!(truth.seed, 1);
    assert!(truth.effects.is_empty() && truth.events.is_empty());
    assert_eq!(truth.noise_pm_rthz, 1.0);
    assert_eq!(truth.lockin.lpf_order, 4);
    for end in [&truth.plant_start, &truth.plant_end] {
        assert_eq!(end.physical.wy2, 1.0265, "{end:?}");
    }
    truth.record = Some(Some("short.csv".into()));
    let text = std::fs::read_to_string(&files.truth).unwrap();
    assert_eq!(
        text,
        paragyro_simulator::summary::to_json_pretty(&truth).unwrap()
    );
    for key in [
        "\"record\": \"short.csv\"",
        "\"format\": \"paragyro-record-truth 1\"",
        "\"th11\": ",
        "\"th26\": ",
        "\"wy2\": 1.0265",
        "\"events\": []",
    ] {
        assert!(text.contains(key), "{key} missing from {text}");
    }

    let text = std::fs::read_to_string(&out).unwrap();
    let cols = text.lines().find(|l| !l.starts_with('#')).unwrap();
    assert_eq!(cols, REQUIRED_COLUMNS.join(","), "no truth columns");
    for l in text.lines().take_while(|l| l.starts_with('#')) {
        let key = l[1..].split(':').next().unwrap().trim();
        assert!(
            record::HEADER_KEYS.contains(&key)
                || [
                    "generator",
                    "device",
                    record::SIM_OMEGA_MAX_KEY,
                    record::SIM_STEPS_PER_PERIOD_KEY,
                ]
                .contains(&key),
            "header line {l}"
        );
    }
    for word in ["th1", "th2", "wy2", "mu_", "rate_dps", "seed", "truth"] {
        assert!(!text.contains(word), "'{word}' in the record");
    }
    let back = read_record(&out).unwrap();
    assert_bit_exact(&rec, &back);
    assert!(OPTIONAL_COLUMNS.iter().all(|c| !cols.contains(c)));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn truth_path_naming() {
    assert_eq!(
        truth_path(std::path::Path::new("a/b.csv")),
        PathBuf::from("a/b.truth.json")
    );
    assert_eq!(
        truth_path(std::path::Path::new("rec")),
        PathBuf::from("rec.truth.json")
    );
    assert_eq!(
        truth_path(std::path::Path::new("x.data.CSV")),
        PathBuf::from("x.data.truth.json")
    );
}

#[test]
fn unknown_effects_are_rejected_and_known_ones_recorded() {
    // an unknown effect cannot reach the simulator: its name is rejected when parsed
    let e = "drive_feedthrough=0.1".parse::<EffectSpec>().unwrap_err();
    assert!(
        e.to_string().contains("unknown effect 'drive_feedthrough'"),
        "{e}"
    );
    // a thermal drift without a temperature profile gets the default one, in temp_c
    let opts = RecordOptions {
        effects: vec!["thermal_drift=-30".parse().unwrap()],
        ..RecordOptions::default()
    };
    let (rec, truth) = simulate_record_with(&identify(0.1), &opts, &mut |_| {}).unwrap();
    assert!(rec.rows.iter().all(|r| r.temp_c.is_some()));
    assert_eq!(truth.effects.len(), 1);
    assert_eq!(truth.effects[0].to_string(), "thermal_drift=-30");
}

#[test]
fn rate_table_writes_the_reference_rate() {
    let opts = RecordOptions {
        rate_table: true,
        ..RecordOptions::default()
    };
    let (rec, truth) = simulate_record_with(&identify(0.1), &opts, &mut |_| {}).unwrap();
    assert!(rec.rows.iter().all(|r| r.rate_ref_dps == Some(150.0)));
    assert!(truth.rate_table);
}

#[test]
fn config_for_takes_the_header_and_the_first_pump() {
    let mut rec = synthetic(5, false, false);
    rec.header.f0_hz = 12_000.0;
    rec.header.lockin_lpf_hz = 120.0;
    rec.header.lockin_lpf_order = 3;
    rec.header.pump_amp_ref_v = 2.5;
    rec.rows[0].pump_hz = f64::NAN;
    rec.rows[1].pump_hz = 24_300.0;
    rec.rows[2].pump_hz = 24_400.0;
    let c = record::config_for(&rec);
    assert_eq!(c.f0_hz, 12_000.0);
    assert_eq!(c.lockin_lpf_hz, 120.0);
    assert_eq!(c.lockin_lpf_order, 3);
    assert_eq!(c.pump_amp_ref_v, 2.5);
    assert_eq!(c.pump_centre_hz, 24_300.0);
    assert_eq!(c.fs_hz, 500.0);
    assert!(c.validate().is_ok(), "{:?}", c.validate());
}

#[test]
fn replay_to_dir_with_f32_core() {
    let dir = scratch("replay");
    let (rec, _) = simulate_record(&identify(1.5), None).unwrap();
    let out = record::write_replay(&rec, "identify.csv", &dir, Precision::F32).unwrap();
    assert_eq!(out.files.len(), 2);
    let csv = std::fs::read_to_string(dir.join("estimates.csv")).unwrap();
    assert_eq!(csv.lines().count(), rec.rows.len() + 1);
    assert!(csv.starts_with("t_s,pump_hz,pump_scale,th11_est,"));
    let s = &out.summary;
    assert_eq!(s.precision, Precision::F32);
    assert_eq!(s.samples, 751);
    let last = s.last.as_ref().expect("final estimates");
    assert_eq!(last.counters.bad_samples, 0);
    assert!(last.rate_dps_est.is_finite());
    // summary.json is the typed summary, keys sorted
    let text = std::fs::read_to_string(dir.join("summary.json")).unwrap();
    assert_eq!(
        text,
        paragyro_simulator::summary::to_json_pretty(s).unwrap()
    );
    assert!(text.contains("\"precision\": \"f32\""), "{text}");
    assert!(text.contains("\"health_final\": ["), "{text}");
    assert!(out.text.starts_with("Replayed identify.csv: 751 samples"));
    println!("{}", out.text);
    // a configuration at another rate is refused
    let mut cfg = record::config_for(&rec);
    cfg.fs_hz = 1000.0;
    assert!(replay::<f64>(&rec, &cfg).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}
