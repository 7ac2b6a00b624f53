//! The writer of `paragyro-record 1` (host-sim/sim/record-format.md), written from the
//! specification: the header lines, the column names, one row per sample, every number
//! in Rust's shortest round-trip form (`{}` or `{:e}`, whichever is shorter).

use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;

use anyhow::Context;

use crate::device::OMEGA0_RAD_S;
use crate::sim::Row;

/// The columns, in the specification's order (`temp_c` and `rate_ref_dps` optional, last).
pub const COLUMNS: [&str; 21] = [
    "t_s",
    "pump_hz",
    "pump_amp_v",
    "ax_mps2",
    "ay_mps2",
    "x0_um",
    "x1_re_um",
    "x1_im_um",
    "x2_re_um",
    "x2_im_um",
    "x3_re_um",
    "x3_im_um",
    "y0_um",
    "y1_re_um",
    "y1_im_um",
    "y2_re_um",
    "y2_im_um",
    "y3_re_um",
    "y3_im_um",
    "temp_c",
    "rate_ref_dps",
];

/// The header of a record.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    /// Low-pass order.
    pub lpf_order: usize,
    /// Low-pass cut-off, Hz.
    pub lpf_hz: f64,
    /// Sample rate, Hz.
    pub fs_hz: f64,
    /// V_A0, V.
    pub pump_amp_ref_v: f64,
    /// Extra `key: value` lines (one-word keys).
    pub extra: Vec<(String, String)>,
}

/// A number in its shortest round-trip form.
pub fn number(out: &mut String, v: f64) {
    if v.is_nan() {
        out.push_str("nan");
        return;
    }
    let plain = format!("{v}");
    let sci = format!("{v:e}");
    out.push_str(if sci.len() < plain.len() {
        &sci
    } else {
        &plain
    });
}

/// The record as text.
pub fn to_text(h: &Header, rows: &[Row]) -> String {
    let mut s = String::with_capacity(rows.len() * 330 + 400);
    s.push_str("# format: paragyro-record 1\n");
    let _ = writeln!(s, "# f0_hz: {}", OMEGA0_RAD_S / std::f64::consts::TAU);
    s.push_str("# l0_um: 1\n");
    let _ = writeln!(s, "# fs_hz: {}", h.fs_hz);
    let _ = writeln!(s, "# lockin_lpf_order: {}", h.lpf_order);
    let _ = writeln!(s, "# lockin_lpf_hz: {}", h.lpf_hz);
    let _ = writeln!(s, "# pump_amp_ref_v: {}", h.pump_amp_ref_v);
    for (k, v) in &h.extra {
        let _ = writeln!(s, "# {k}: {v}");
    }
    s.push_str(&COLUMNS.join(","));
    s.push('\n');
    for r in rows {
        let head = [
            r.t_s,
            r.pump_hz,
            r.pump_amp_v,
            r.accel_mps2[0],
            r.accel_mps2[1],
        ];
        let tail = [r.temp_c, r.rate_ref_dps];
        for (i, v) in head.iter().chain(&r.lockin_um).chain(&tail).enumerate() {
            if i > 0 {
                s.push(',');
            }
            number(&mut s, *v);
        }
        s.push('\n');
    }
    s
}

/// Writes the record to `path` (through a temporary file renamed into place, so that a
/// record file exists only complete).
pub fn write(path: &Path, h: &Header, rows: &[Row]) -> anyhow::Result<()> {
    let text = to_text(h, rows);
    let tmp = path.with_extension("csv.part");
    let mut f =
        std::fs::File::create(&tmp).with_context(|| format!("cannot create {}", tmp.display()))?;
    f.write_all(text.as_bytes())
        .with_context(|| format!("cannot write {}", tmp.display()))?;
    drop(f);
    std::fs::rename(&tmp, path)
        .with_context(|| format!("cannot rename {} to {}", tmp.display(), path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_round_trip_and_stay_short() {
        for v in [
            0.0,
            1.0,
            -0.5,
            2.5e-7,
            4.7083139822321306e-5,
            21883.9526,
            1e15,
        ] {
            let mut s = String::new();
            number(&mut s, v);
            assert_eq!(s.parse::<f64>().unwrap(), v, "{s}");
            assert!(s.len() <= format!("{v}").len(), "{s}");
        }
        let mut s = String::new();
        number(&mut s, f64::NAN);
        assert_eq!(s, "nan");
    }
}
