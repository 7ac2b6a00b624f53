//! The writer: shortest round-trip numbers, the optional columns only when some row has a
//! value.

use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::Context;

use super::{FORMAT, HEADER_KEYS, REQUIRED_COLUMNS, Record, RecordHeader};

/// Appends `v` in its shortest round-trip form: the shorter of `{}` and `{:e}` (Rust
/// prints the fewest digits that parse back to the same bits in both), `nan`, `inf`, `-inf`.
pub fn push_number(out: &mut String, v: f64) {
    if v.is_nan() {
        out.push_str("nan");
    } else if v.is_infinite() {
        out.push_str(if v > 0.0 { "inf" } else { "-inf" });
    } else {
        let start = out.len();
        let _ = write!(out, "{v}");
        let plain = out.len() - start;
        if plain > 6 {
            // e.g. 0.000047083139822321306 → 4.7083139822321306e-5, 1000000000000000 → 1e15
            let _ = write!(out, "{v:e}");
            if out.len() - start - plain < plain {
                out.replace_range(start..start + plain, "");
            } else {
                out.truncate(start + plain);
            }
        }
    }
}

fn check_header(h: &RecordHeader) -> anyhow::Result<()> {
    for (k, v) in [
        ("f0_hz", h.f0_hz),
        ("l0_um", h.l0_um),
        ("fs_hz", h.fs_hz),
        ("lockin_lpf_hz", h.lockin_lpf_hz),
        ("pump_amp_ref_v", h.pump_amp_ref_v),
    ] {
        anyhow::ensure!(
            v.is_finite() && v > 0.0,
            "header '{k}' = {v} must be positive"
        );
    }
    anyhow::ensure!(
        (1..=crate::lockin::MAX_LPF_ORDER).contains(&h.lockin_lpf_order),
        "header 'lockin_lpf_order' = {} must be 1..={}",
        h.lockin_lpf_order,
        crate::lockin::MAX_LPF_ORDER
    );
    for (k, v) in &h.extra {
        anyhow::ensure!(
            !k.is_empty() && !k.contains(|c: char| c.is_whitespace() || c == ':'),
            "extra header key '{k}' must be one word without ':'"
        );
        anyhow::ensure!(
            !HEADER_KEYS.contains(&k.as_str()),
            "extra header key '{k}' is a standard key"
        );
        anyhow::ensure!(
            !v.contains(['\n', '\r']),
            "extra header '{k}': the value must be one line"
        );
    }
    Ok(())
}

/// Writes a record to any writer (buffer it: one `write_all` per line).
pub fn write_record_to<W: Write>(mut w: W, rec: &Record) -> anyhow::Result<()> {
    let h = &rec.header;
    check_header(h)?;
    let mut line = String::with_capacity(512);
    let _ = writeln!(line, "# format: {FORMAT}");
    for (k, v) in [
        ("f0_hz", h.f0_hz),
        ("l0_um", h.l0_um),
        ("fs_hz", h.fs_hz),
        ("lockin_lpf_order", h.lockin_lpf_order as f64),
        ("lockin_lpf_hz", h.lockin_lpf_hz),
        ("pump_amp_ref_v", h.pump_amp_ref_v),
    ] {
        let _ = write!(line, "# {k}: ");
        push_number(&mut line, v);
        line.push('\n');
    }
    for (k, v) in &h.extra {
        let _ = writeln!(line, "# {k}: {v}");
    }
    let temp = rec.rows.iter().any(|r| r.temp_c.is_some());
    let rate = rec.rows.iter().any(|r| r.rate_ref_dps.is_some());
    line.push_str(&REQUIRED_COLUMNS.join(","));
    if temp {
        line.push_str(",temp_c");
    }
    if rate {
        line.push_str(",rate_ref_dps");
    }
    line.push('\n');
    w.write_all(line.as_bytes())?;
    for r in &rec.rows {
        line.clear();
        for (i, v) in r.required().iter().enumerate() {
            if i > 0 {
                line.push(',');
            }
            push_number(&mut line, *v);
        }
        for (on, v) in [(temp, r.temp_c), (rate, r.rate_ref_dps)] {
            if on {
                line.push(',');
                if let Some(v) = v {
                    push_number(&mut line, v);
                }
            }
        }
        line.push('\n');
        w.write_all(line.as_bytes())?;
    }
    w.flush()?;
    Ok(())
}

/// Writes a record file (creating or truncating it).
pub fn write_record(path: &Path, rec: &Record) -> anyhow::Result<()> {
    let f = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    write_record_to(BufWriter::with_capacity(1 << 16, f), rec)
        .with_context(|| format!("cannot write the record {}", path.display()))
}
