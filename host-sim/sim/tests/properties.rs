//! Property tests (proptest) for the invariants a few fixed cases cannot cover:
//!
//! * the record CSV round-trips: any header and any rows of finite values, written and read
//!   back, give the same header and the same rows bit for bit (−0, subnormals and extreme
//!   magnitudes included), with the optional columns present exactly when some row has one;
//! * the scenario loader never panics: random text, and a built-in scenario mangled at a
//!   random place, either load or give an error that names the file, and a syntax error
//!   names its line and column inside the text.
//!
//! (There is no scenario writer, so the scenario side checks the error path only.)

use paragyro_simulator::lockin::MAX_LPF_ORDER;
use paragyro_simulator::record::{
    HEADER_KEYS, Record, RecordHeader, RecordRow, parse_record, write_record_to,
};
use paragyro_simulator::scenario::{Scenario, ScenarioErrorKind};
use proptest::prelude::*;

/// Any finite f64, either sign, subnormals and zeros included.
fn finite() -> impl Strategy<Value = f64> {
    use proptest::num::f64::{NEGATIVE, NORMAL, POSITIVE, SUBNORMAL, ZERO};
    POSITIVE | NEGATIVE | NORMAL | SUBNORMAL | ZERO
}

/// A positive finite header value.
fn positive() -> impl Strategy<Value = f64> {
    use proptest::num::f64::{NORMAL, POSITIVE, SUBNORMAL};
    POSITIVE | NORMAL | SUBNORMAL
}

/// Extra `# key: value` lines: one-word keys that are not standard keys, one-line values
/// without surrounding blanks (the reader trims them).
fn extras() -> impl Strategy<Value = Vec<(String, String)>> {
    let key = "[a-z_][a-z0-9_]{0,12}"
        .prop_filter("a standard key", |k| !HEADER_KEYS.contains(&k.as_str()));
    let value = prop_oneof![Just(String::new()), "[!-~]([ -~]{0,20}[!-~])?"];
    prop::collection::vec((key, value), 0..4)
}

fn header() -> impl Strategy<Value = RecordHeader> {
    (
        (positive(), positive(), 1.0f64..1e4),
        (1..=MAX_LPF_ORDER, positive(), positive()),
        extras(),
    )
        .prop_map(
            |((f0_hz, l0_um, fs_hz), (lockin_lpf_order, lockin_lpf_hz, pump_amp_ref_v), extra)| {
                RecordHeader {
                    f0_hz,
                    l0_um,
                    fs_hz,
                    lockin_lpf_order,
                    lockin_lpf_hz,
                    pump_amp_ref_v,
                    extra,
                }
            },
        )
}

/// One row's values after `t_s`, and its optional columns.
type RowValues = ([f64; 18], Option<f64>, Option<f64>);

fn row_values() -> impl Strategy<Value = RowValues> {
    (
        prop::array::uniform18(finite()),
        prop::option::of(finite()),
        prop::option::of(finite()),
    )
}

/// A record: a regular time axis from `t0` at the header's rate, any finite values.
fn record() -> impl Strategy<Value = Record> {
    (
        header(),
        0.0f64..1e3,
        prop::collection::vec(row_values(), 1..12),
    )
        .prop_map(|(header, t0, rows)| {
            let rows = rows
                .into_iter()
                .enumerate()
                .map(|(k, (v, temp, rate))| {
                    let mut req = [0.0; 19];
                    req[0] = t0 + k as f64 / header.fs_hz;
                    req[1..].copy_from_slice(&v);
                    RecordRow::from_required(&req, temp, rate)
                })
                .collect();
            Record {
                header,
                rows,
                warnings: Vec::new(),
            }
        })
}

fn bits(v: Option<f64>) -> Option<u64> {
    v.map(f64::to_bits)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn record_csv_round_trips_bit_for_bit(rec in record()) {
        let mut buf = Vec::new();
        write_record_to(&mut buf, &rec).expect("a valid record is written");
        let text = String::from_utf8(buf).expect("the record is UTF-8");
        let back = match parse_record(&text, "prop.csv") {
            Ok(b) => b,
            Err(e) => return Err(TestCaseError::fail(format!("{e}\n{text}"))),
        };
        let h = (&rec.header, &back.header);
        prop_assert_eq!(h.0.f0_hz.to_bits(), h.1.f0_hz.to_bits());
        prop_assert_eq!(h.0.l0_um.to_bits(), h.1.l0_um.to_bits());
        prop_assert_eq!(h.0.fs_hz.to_bits(), h.1.fs_hz.to_bits());
        prop_assert_eq!(h.0.lockin_lpf_order, h.1.lockin_lpf_order);
        prop_assert_eq!(h.0.lockin_lpf_hz.to_bits(), h.1.lockin_lpf_hz.to_bits());
        prop_assert_eq!(h.0.pump_amp_ref_v.to_bits(), h.1.pump_amp_ref_v.to_bits());
        prop_assert_eq!(&h.0.extra, &h.1.extra);
        prop_assert!(back.warnings.is_empty(), "{:?}", back.warnings);
        prop_assert_eq!(rec.rows.len(), back.rows.len());
        let any_temp = rec.rows.iter().any(|r| r.temp_c.is_some());
        let any_rate = rec.rows.iter().any(|r| r.rate_ref_dps.is_some());
        let head = text.lines().find(|l| l.starts_with("t_s,")).unwrap_or_default();
        prop_assert_eq!(head.contains(",temp_c"), any_temp);
        prop_assert_eq!(head.contains(",rate_ref_dps"), any_rate);
        for (a, b) in rec.rows.iter().zip(&back.rows) {
            prop_assert_eq!(a.required().map(f64::to_bits), b.required().map(f64::to_bits));
            prop_assert_eq!(bits(a.temp_c), bits(b.temp_c));
            prop_assert_eq!(bits(a.rate_ref_dps), bits(b.rate_ref_dps));
        }
        // and the text is a fixed point: written again, the same bytes
        let mut again = Vec::new();
        write_record_to(&mut again, &back).expect("written again");
        prop_assert_eq!(text.as_bytes(), &again[..]);
    }

    #[test]
    fn random_text_never_panics_the_scenario_loader(text in "\\PC{0,200}") {
        check_load(&text)?;
    }

    #[test]
    fn a_mangled_builtin_never_panics_and_names_the_place(
        which in 0usize..5,
        at in 0.0f64..1.0,
        cut in 0usize..40,
        insert in "[\\[\\]={}\"'#.,a-z0-9 \n-]{0,12}",
    ) {
        let (name, _) = Scenario::builtin_names()[which];
        let text = builtin_text(name);
        let mut pos = (at * text.len() as f64) as usize;
        while !text.is_char_boundary(pos) {
            pos -= 1;
        }
        let mut end = (pos + cut).min(text.len());
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        let mangled = format!("{}{insert}{}", &text[..pos], &text[end..]);
        check_load(&mangled)?;
    }
}

/// The embedded TOML of a built-in scenario.
fn builtin_text(name: &str) -> String {
    let path = format!("{}/../scenarios/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// Loads `text` as `prop.toml`: an error names the file first; a syntax error names a line
/// and a column that exist in the text; a located error's line is inside the text.
fn check_load(text: &str) -> Result<(), TestCaseError> {
    let Err(e) = Scenario::from_toml_str(text, "prop.toml") else {
        return Ok(());
    };
    let shown = e.to_string();
    prop_assert!(shown.starts_with("prop.toml"), "{shown}");
    prop_assert!(!e.message.is_empty(), "{shown}");
    let lines = text.split('\n').count();
    if e.kind == ScenarioErrorKind::Syntax {
        let (Some(line), Some(col)) = (e.line, e.column) else {
            return Err(TestCaseError::fail(format!("no line:col in '{shown}'")));
        };
        prop_assert!(
            shown.starts_with(&format!("prop.toml:{line}:{col}: ")),
            "{shown}"
        );
        prop_assert!(
            line >= 1 && line <= lines,
            "line {line} of {lines}: {shown}"
        );
        let width = text
            .split('\n')
            .nth(line - 1)
            .map_or(0, |l| l.chars().count());
        prop_assert!(
            col >= 1 && col <= width + 1,
            "column {col} of {width}: {shown}"
        );
    } else if let Some(line) = e.line {
        prop_assert!(
            line >= 1 && line <= lines,
            "line {line} of {lines}: {shown}"
        );
    }
    Ok(())
}
