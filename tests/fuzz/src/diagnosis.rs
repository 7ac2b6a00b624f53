//! The diagnosis on mutated records: its cheap path (no re-simulation, no confirmation
//! runs) over a short simulated record that the input edits, then written as CSV and read
//! back, so that only records the reader accepts are diagnosed (issue 31: the diagnosis is
//! total over them). Each record of the input is an opcode and its values:
//!
//! | opcode (`% 8`) | edit |
//! |---|---|
//! | 0 | a span of one column (the 18 data columns, `temp_c`, `rate_ref_dps`) scaled |
//! | 1 | a span of one column offset (a step) |
//! | 2 | a span of one column set to one value: any bit pattern (NaN, ±∞, huge, subnormal) |
//! | 3 | a span of one column held at its first value (a stuck channel) |
//! | 4 | the rate table reversed from a sample on (through a ramp of 0–255 samples), or dropped over a span |
//! | 5 | a temperature ramp added from a sample on, or the column dropped |
//! | 6 | the record cut to its first 0–1 535 rows (the 2 s minimum on both sides) |
//! | 7 | a single sample spiked in one column |
//!
//! Asserted: `diagnose` returns a report (never an error: the model is the default one,
//! which is physical), its report.json round-trips with the same verdict, and report.md
//! states that verdict. A panic anywhere is the failure libFuzzer reports.

use std::sync::OnceLock;

use paragyro_diagnose::diagnose::{Answer, Options, Report, diagnose, to_json_sorted};
use paragyro_simulator::lockin::LockinExt;
use paragyro_simulator::record::{
    Record, RecordOptions, parse_record, simulate_record_ext, write_record_to,
};
use paragyro_simulator::scenario::Scenario;

use crate::Bytes;

/// The base record's scenario: `characterise`'s device and dither, 3 s, its two
/// pump-amplitude steps moved inside the run.
const BASE_TOML: &str = r#"
name = "fuzz-diagnosis"
duration_s = 3.0
seed = 31

[plant]
wy2 = 1.0265

[estimator]
forgetting = 0.999
pump_centre_hz = 21883.9526
dither_pump_hz = 21.6
dither_freq_hz = 5.0
dither_scale_frac = 0.1
dither_scale_freq_hz = 1.3
dither_start_s = 1.0
gate_startup_s = 0.5
retune = true
retune_track_hz = 0.0

[[event]]
t_s = 1.5
kind = "pump_scale"
s = 0.85
ramp_s = 0.2

[[event]]
t_s = 2.3
kind = "pump_scale"
s = 1.15
ramp_s = 0.2
"#;

/// The base record (simulated once per process): a rate table and a die temperature.
pub fn base_record() -> &'static Record {
    static BASE: OnceLock<Record> = OnceLock::new();
    BASE.get_or_init(|| {
        let sc = Scenario::from_toml_str(BASE_TOML, "fuzz-diagnosis.toml")
            .expect("the base scenario parses");
        let opts = RecordOptions {
            seed: Some(31),
            effects: Vec::new(),
            rate_table: true,
            temp: Some((25.0, 1.0)),
        };
        simulate_record_ext(&sc, &opts, None, &mut |_| {})
            .expect("the base record simulates")
            .0
    })
}

/// Columns an edit can address: the 18 data columns, then `temp_c`, `rate_ref_dps`.
const COLUMNS: usize = 20;

/// The value of column `c` of a row (`None` for an absent optional column).
fn get(r: &paragyro_simulator::record::RecordRow, c: usize) -> Option<f64> {
    match c {
        0 => Some(r.pump_hz),
        1 => Some(r.pump_amp_v),
        2 => Some(r.ax_mps2),
        3 => Some(r.ay_mps2),
        4..=17 => Some(r.lockin.to_channels()[c - 4]),
        18 => r.temp_c,
        _ => r.rate_ref_dps,
    }
}

/// Sets column `c` of a row.
fn set(r: &mut paragyro_simulator::record::RecordRow, c: usize, v: f64) {
    match c {
        0 => r.pump_hz = v,
        1 => r.pump_amp_v = v,
        2 => r.ax_mps2 = v,
        3 => r.ay_mps2 = v,
        4..=17 => {
            let mut ch = r.lockin.to_channels();
            ch[c - 4] = v;
            r.lockin = LockinExt::from_channels(&ch);
        }
        18 => r.temp_c = Some(v),
        _ => r.rate_ref_dps = Some(v),
    }
}

/// A span `[k0, k0 + len)` of the record's rows from the input.
fn span(b: &mut Bytes, n: usize) -> std::ops::Range<usize> {
    let k0 = usize::from(u16::from_le_bytes(b.take())) % n.max(1);
    let len = usize::from(u16::from_le_bytes(b.take()));
    k0..(k0 + len).min(n)
}

/// Applies the input's edits to `rec` (see the module docs).
pub fn edit(rec: &mut Record, data: &[u8]) {
    let mut b = Bytes(data);
    while !b.0.is_empty() {
        let op = b.u8() % 8;
        let c = usize::from(b.u8()) % COLUMNS;
        let n = rec.rows.len();
        if n == 0 {
            return;
        }
        match op {
            0..=2 => {
                let s = span(&mut b, n);
                let v = b.f64();
                for r in &mut rec.rows[s] {
                    if let Some(x) = get(r, c) {
                        set(r, c, [x * v, x + v, v][usize::from(op)]);
                    }
                }
            }
            3 => {
                let s = span(&mut b, n);
                if let Some(x) = rec.rows.get(s.start).and_then(|r| get(r, c)) {
                    for r in &mut rec.rows[s] {
                        set(r, c, x);
                    }
                }
            }
            4 => {
                let s = span(&mut b, n);
                let ramp = f64::from(b.u8());
                for (j, r) in rec.rows[s].iter_mut().enumerate() {
                    r.rate_ref_dps = if c.is_multiple_of(2) {
                        // from +R to −R through a half cosine of `ramp` samples
                        let f = if ramp == 0.0 {
                            -1.0
                        } else {
                            (std::f64::consts::PI * (j as f64 / ramp).min(1.0)).cos()
                        };
                        r.rate_ref_dps.map(|v| v * f)
                    } else {
                        None
                    };
                }
            }
            5 => {
                let s = span(&mut b, n);
                let k_per_s = f64::from(b.u8() as i8) * 0.05;
                for (j, r) in rec.rows[s].iter_mut().enumerate() {
                    r.temp_c = if c.is_multiple_of(4) {
                        None
                    } else {
                        Some(r.temp_c.unwrap_or(25.0) + k_per_s * j as f64 / 500.0)
                    };
                }
            }
            6 => {
                let keep = usize::from(u16::from_le_bytes(b.take())) % 1536;
                rec.rows.truncate(keep.max(1));
            }
            _ => {
                let k = usize::from(u16::from_le_bytes(b.take())) % n;
                let v = b.f64();
                if let Some(x) = get(&rec.rows[k], c) {
                    set(&mut rec.rows[k], c, x + v);
                }
            }
        }
    }
}

/// The harness: the base record edited by `data`, written and read back (a record the
/// reader refuses is not diagnosed), then diagnosed on the cheap path.
pub fn diagnosis(data: &[u8]) {
    let mut rec = base_record().clone();
    edit(&mut rec, data);
    let mut csv = Vec::new();
    if write_record_to(&mut csv, &rec).is_err() {
        return;
    }
    let Ok(text) = String::from_utf8(csv) else {
        return;
    };
    let Ok(rec) = parse_record(&text, "fuzz.csv") else {
        return;
    };
    let opts = Options {
        resimulate: false,
        confirm_runs: Some(0),
        ..Options::default()
    };
    let d = match diagnose(&rec, &opts) {
        Ok(d) => d,
        Err(e) => panic!("no report on a record the reader accepts: {e:#}"),
    };
    let json = to_json_sorted(&d.report).expect("report.json serialises");
    let back: Report = match serde_json::from_str(&json) {
        Ok(r) => r,
        Err(e) => panic!(
            "report.json does not read back: {e} (its line: {:?})",
            json.lines().nth(e.line().saturating_sub(1)).unwrap_or("")
        ),
    };
    let answer: Answer = d.report.verdict.answer();
    assert_eq!(back.verdict.answer(), answer, "the verdict reads back");
    assert!(
        d.report
            .markdown("fuzz.csv")
            .contains(&format!("**Verdict: `{answer}`**")),
        "report.md states the verdict"
    );
}
