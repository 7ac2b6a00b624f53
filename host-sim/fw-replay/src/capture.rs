//! The firmware's capture log → a `paragyro-record 1` record.
//!
//! A firmware built with the `capture` feature prints, through defmt, one header line and
//! then one line per tick with the exact inputs the core was given (`Sample<f32>`: the
//! lock-in values after calibration in µm, the accelerations in m/s², the pump in effect):
//!
//! ```text
//! CAPHDR f0_hz=10799.81 fs_hz=500 l0_um=1 lpf_order=4 lpf_hz=150 vref=1
//! CAP k=0 pump_hz=21883.95 s=1 a=[39.2, 39.2] x=[x0, x1re, x1im, x2re, x2im, x3re, x3im] y=[…]
//! ```
//!
//! Anything else on a line (defmt-print's level, timestamp, location lines) and every other
//! line is ignored. The values are printed by defmt-print in Rust's shortest round-trip
//! form, so the record holds the very `f32`/`f64` values (the pump scale s becomes
//! `pump_amp_v = vref·√s`, which `RecordRow::to_sample` squares back).

use anyhow::{Context, bail, ensure};
use paragyro_simulator::lockin::{LockinExt, LockinOut};
use paragyro_simulator::record::{Record, RecordHeader, RecordRow};

/// `key=value` pairs after `marker` (arrays `[a, b]` are one value).
fn fields<'a>(line: &'a str, marker: &str) -> Option<Vec<(&'a str, &'a str)>> {
    let start = line.find(marker)? + marker.len();
    let mut rest = line[start..].trim();
    let mut out = Vec::new();
    while !rest.is_empty() {
        let eq = rest.find('=')?;
        let key = rest[..eq].trim();
        let after = &rest[eq + 1..];
        let (value, tail) = if after.starts_with('[') {
            let close = after.find(']')?;
            (&after[..=close], &after[close + 1..])
        } else {
            let end = after.find(char::is_whitespace).unwrap_or(after.len());
            (&after[..end], &after[end..])
        };
        out.push((key, value));
        rest = tail.trim_start();
    }
    Some(out)
}

fn get<'a>(f: &[(&str, &'a str)], key: &str, line: usize) -> anyhow::Result<&'a str> {
    f.iter()
        .find(|(k, _)| *k == key)
        .map(|(_, v)| *v)
        .with_context(|| format!("line {line}: no '{key}='"))
}

fn num(s: &str, what: &str, line: usize) -> anyhow::Result<f64> {
    s.trim()
        .parse::<f64>()
        .with_context(|| format!("line {line}: {what}: not a number: '{s}'"))
}

fn array(s: &str, n: usize, what: &str, line: usize) -> anyhow::Result<Vec<f64>> {
    let inner = s
        .strip_prefix('[')
        .and_then(|t| t.strip_suffix(']'))
        .with_context(|| format!("line {line}: {what}: not an array: '{s}'"))?;
    let v = inner
        .split(',')
        .map(|x| num(x, what, line))
        .collect::<anyhow::Result<Vec<_>>>()?;
    ensure!(
        v.len() == n,
        "line {line}: {what}: {} values, expected {n}",
        v.len()
    );
    Ok(v)
}

/// Parses a capture log (see the module documentation). `source` names it in errors.
pub fn parse_capture(text: &str, source: &str) -> anyhow::Result<Record> {
    let mut header: Option<RecordHeader> = None;
    let mut rows = Vec::new();
    let mut warnings = Vec::new();
    let mut next_k: Option<u64> = None;
    for (i, line) in text.lines().enumerate() {
        let ln = i + 1;
        if let Some(f) = fields(line, "CAPHDR ") {
            let g = |k| get(&f, k, ln).and_then(|v| num(v, k, ln));
            let h = RecordHeader {
                f0_hz: g("f0_hz")?,
                l0_um: g("l0_um")?,
                fs_hz: g("fs_hz")?,
                lockin_lpf_order: g("lpf_order")? as usize,
                lockin_lpf_hz: g("lpf_hz")?,
                pump_amp_ref_v: g("vref")?,
                extra: vec![
                    ("device".into(), "firmware capture".into()),
                    ("source".into(), source.into()),
                ],
            };
            if header.is_some() {
                bail!("{source}:{ln}: a second CAPHDR (one capture per log)");
            }
            header = Some(h);
            continue;
        }
        let Some(f) = fields(line, "CAP ") else {
            continue;
        };
        let Some(h) = header.as_ref() else {
            bail!("{source}:{ln}: CAP line before the CAPHDR line");
        };
        let k_text = get(&f, "k", ln)?;
        let k: u64 = k_text
            .parse()
            .with_context(|| format!("{source}:{ln}: bad tick number '{k_text}'"))?;
        if let Some(want) = next_k
            && k != want
        {
            warnings.push(format!(
                "{source}:{ln}: tick {k} where {want} was expected ({} ticks missing)",
                k.saturating_sub(want)
            ));
        }
        next_k = Some(k + 1);
        let pump_hz = num(get(&f, "pump_hz", ln)?, "pump_hz", ln)?;
        let s = num(get(&f, "s", ln)?, "s", ln)?;
        let a = array(get(&f, "a", ln)?, 2, "a", ln)?;
        let x = array(get(&f, "x", ln)?, 7, "x", ln)?;
        let y = array(get(&f, "y", ln)?, 7, "y", ln)?;
        rows.push(RecordRow {
            t_s: k as f64 / h.fs_hz,
            pump_hz,
            pump_amp_v: h.pump_amp_ref_v * s.sqrt(),
            ax_mps2: a[0],
            ay_mps2: a[1],
            lockin: LockinOut::from_channels(&[
                x[0], x[1], x[2], x[3], x[4], x[5], x[6], y[0], y[1], y[2], y[3], y[4], y[5], y[6],
            ]),
            temp_c: None,
            rate_ref_dps: None,
        });
    }
    let header = header.with_context(|| format!("{source}: no CAPHDR line (not a capture log)"))?;
    ensure!(!rows.is_empty(), "{source}: no CAP lines");
    Ok(Record {
        header,
        rows,
        warnings,
    })
}
