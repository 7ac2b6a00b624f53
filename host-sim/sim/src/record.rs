//! The record: one CSV format at 500 Hz for real devices and simulations
//! (`paragyro-record 1`, specified in `docs/record-format.md`).
//!
//! ```text
//! # format: paragyro-record 1
//! # f0_hz: 10799.814…            drive natural frequency that defines ω0 = 2π·f0
//! # l0_um: 1                     length unit of the lock-in columns, µm
//! # fs_hz: 500
//! # lockin_lpf_order: 4
//! # lockin_lpf_hz: 150
//! # pump_amp_ref_v: 1            V_A0: s = (pump_amp_v / pump_amp_ref_v)²
//! t_s,pump_hz,pump_amp_v,ax_mps2,ay_mps2,x0_um,x1_re_um,…,y3_im_um[,temp_c][,rate_ref_dps]
//! 0,21883.9526,1,98.0665,98.0665,0.01,…
//! ```
//!
//! * [`write_record`] / [`write_record_to`] write it (shortest round-trip numbers);
//!   [`read_record`] / [`parse_record`] / [`read_record_from`] read it line by line with
//!   errors that name the file, the line, the column (number and name)
//!   (`file.csv:123:7: column 'x1_re_um': expected a number, found 'abc'`).
//! * [`simulate_record`] produces one from a scenario (the closed loop of
//!   [`runner::simulate`] with the `f64` core) plus its truth (a JSON value that goes to
//!   `FILE.truth.json`, never into the record).
//! * [`replay`] runs the core open-loop on a record; [`config_for`] is the core
//!   configuration for a record of an unknown device.

use std::fmt::{self, Write as _};
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::effects::Effects;
use crate::runner::Device;
use anyhow::Context;
use paragyro_core::physics::{physical_from_theta, rate_dps_from_gamma};
use paragyro_core::{Config, Counters, Cplx, Estimator, Lockin, Real, Sample};
use serde_json::{Map, Value, json};

use crate::runner::{self, Precision};
use crate::scenario::{L0_M, PlantAt, Scenario};
use crate::summary::{PhysicalValues, ThetaPair};
use crate::trace::{HEALTH_NAMES, PHYS_NAMES, THETA_DRIVE_NAMES, THETA_SENSE_NAMES};
use serde::Serialize;

// ---------------------------------------------------------------------------------------------
// The format
// ---------------------------------------------------------------------------------------------

/// Name of the format in the `# format:` line.
pub const FORMAT_NAME: &str = "paragyro-record";
/// Version this module reads and writes.
pub const FORMAT_VERSION: u32 = 1;
/// The whole `# format:` value.
pub const FORMAT: &str = "paragyro-record 1";

/// The required header keys, in the order they are written.
pub const HEADER_KEYS: [&str; 7] = [
    "format",
    "f0_hz",
    "l0_um",
    "fs_hz",
    "lockin_lpf_order",
    "lockin_lpf_hz",
    "pump_amp_ref_v",
];

/// Number of required columns.
pub const N_REQUIRED: usize = 19;

/// The required columns, in the order they are written.
pub const REQUIRED_COLUMNS: [&str; N_REQUIRED] = [
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
];

/// The optional columns (written after the required ones, only when some row has a value;
/// an empty field means "unknown").
pub const OPTIONAL_COLUMNS: [&str; 2] = ["temp_c", "rate_ref_dps"];

/// Largest relative deviation of a `t_s` step from 1/fs_hz.
pub const SAMPLING_TOLERANCE: f64 = 0.01;

/// Index of a column among the known ones (required then optional).
const N_KNOWN: usize = N_REQUIRED + OPTIONAL_COLUMNS.len();
const COL_T: usize = 0;
const COL_TEMP: usize = N_REQUIRED;
const COL_RATE: usize = N_REQUIRED + 1;

fn known_name(i: usize) -> &'static str {
    if i < N_REQUIRED {
        REQUIRED_COLUMNS[i]
    } else {
        OPTIONAL_COLUMNS[i - N_REQUIRED]
    }
}

/// The `# key: value` lines of a record.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordHeader {
    /// Drive natural frequency f0 that defines ω0 = 2π·f0 (the model's time unit), Hz.
    pub f0_hz: f64,
    /// Length unit L0 of the lock-in columns, µm (1).
    pub l0_um: f64,
    /// Sample rate, Hz (500).
    pub fs_hz: f64,
    /// Order of the lock-in's Butterworth low-pass.
    pub lockin_lpf_order: usize,
    /// Cut-off of the lock-in low-pass, Hz.
    pub lockin_lpf_hz: f64,
    /// Pump voltage amplitude V_A0 at which s = 1, V.
    pub pump_amp_ref_v: f64,
    /// Further `# key: value` lines, in file order (kept, not interpreted).
    pub extra: Vec<(String, String)>,
}

impl RecordHeader {
    /// A header with the settings of a core configuration (no extra keys).
    pub fn from_config(cfg: &Config) -> Self {
        RecordHeader {
            f0_hz: cfg.f0_hz,
            l0_um: cfg.l0_um,
            fs_hz: cfg.fs_hz,
            lockin_lpf_order: cfg.lockin_lpf_order,
            lockin_lpf_hz: cfg.lockin_lpf_hz,
            pump_amp_ref_v: cfg.pump_amp_ref_v,
            extra: Vec::new(),
        }
    }

    /// The value of an extra key, if present (the first one).
    pub fn extra_value(&self, key: &str) -> Option<&str> {
        self.extra
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

/// One 500 Hz sample of a record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecordRow {
    /// Time, s.
    pub t_s: f64,
    /// Pump frequency 2Ω/2π in effect at the sample instant, Hz.
    pub pump_hz: f64,
    /// Pump voltage amplitude V_A, V.
    pub pump_amp_v: f64,
    /// Acceleration along the drive axis x, m/s².
    pub ax_mps2: f64,
    /// Acceleration along the sense axis y, m/s².
    pub ay_mps2: f64,
    /// Low-passed DC level of the drive displacement, µm.
    pub x0_um: f64,
    /// Drive harmonics k = 1, 2, 3: peak complex amplitude (re, im) against e^{−ikψ}, µm.
    pub x_um: [(f64, f64); 3],
    /// Low-passed DC level of the sense displacement, µm.
    pub y0_um: f64,
    /// Sense harmonics k = 1, 2, 3, µm.
    pub y_um: [(f64, f64); 3],
    /// Temperature, °C (optional column).
    pub temp_c: Option<f64>,
    /// Known reference rate (rate table), °/s (optional column).
    pub rate_ref_dps: Option<f64>,
}

impl RecordRow {
    /// The required columns in [`REQUIRED_COLUMNS`] order.
    pub fn required(&self) -> [f64; N_REQUIRED] {
        let (x, y) = (&self.x_um, &self.y_um);
        [
            self.t_s,
            self.pump_hz,
            self.pump_amp_v,
            self.ax_mps2,
            self.ay_mps2,
            self.x0_um,
            x[0].0,
            x[0].1,
            x[1].0,
            x[1].1,
            x[2].0,
            x[2].1,
            self.y0_um,
            y[0].0,
            y[0].1,
            y[1].0,
            y[1].1,
            y[2].0,
            y[2].1,
        ]
    }

    /// A row from the required columns in [`REQUIRED_COLUMNS`] order and the optional ones.
    pub fn from_required(
        v: &[f64; N_REQUIRED],
        temp_c: Option<f64>,
        rate_ref_dps: Option<f64>,
    ) -> Self {
        RecordRow {
            t_s: v[0],
            pump_hz: v[1],
            pump_amp_v: v[2],
            ax_mps2: v[3],
            ay_mps2: v[4],
            x0_um: v[5],
            x_um: [(v[6], v[7]), (v[8], v[9]), (v[10], v[11])],
            y0_um: v[12],
            y_um: [(v[13], v[14]), (v[15], v[16]), (v[17], v[18])],
            temp_c,
            rate_ref_dps,
        }
    }

    /// The core's input for this sample: s = (pump_amp_v / pump_amp_ref_v)², lock-in in µm
    /// as recorded (the core's [`Lockin`] is in µm), accelerations in m/s². NaN passes
    /// through (the core flags and skips such a sample).
    pub fn to_sample<T: Real>(&self, header: &RecordHeader) -> Sample<T> {
        let c = |p: (f64, f64)| Cplx::new(T::from_f64(p.0), T::from_f64(p.1));
        Sample {
            lockin: Lockin {
                x0_um: T::from_f64(self.x0_um),
                x_um: [c(self.x_um[0]), c(self.x_um[1]), c(self.x_um[2])],
                y0_um: T::from_f64(self.y0_um),
                y_um: [c(self.y_um[0]), c(self.y_um[1]), c(self.y_um[2])],
            },
            accel_mps2: [T::from_f64(self.ax_mps2), T::from_f64(self.ay_mps2)],
            pump_hz: self.pump_hz,
            pump_scale: Sample::<T>::pump_scale_from_volts(self.pump_amp_v, header.pump_amp_ref_v),
        }
    }

    /// |x_k| (k = 1..=3), µm.
    pub fn x_abs(&self, k: usize) -> f64 {
        let (re, im) = self.x_um[k - 1];
        re.hypot(im)
    }

    /// |y_k| (k = 1..=3), µm.
    pub fn y_abs(&self, k: usize) -> f64 {
        let (re, im) = self.y_um[k - 1];
        re.hypot(im)
    }
}

/// A whole record.
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    /// The header lines.
    pub header: RecordHeader,
    /// One row per sample.
    pub rows: Vec<RecordRow>,
    /// What the reader ignored or noticed (unknown columns, NaN rows); empty when written.
    pub warnings: Vec<String>,
}

impl Record {
    /// Duration from the first to the last sample, s.
    pub fn duration_s(&self) -> f64 {
        match (self.rows.first(), self.rows.last()) {
            (Some(a), Some(b)) => b.t_s - a.t_s,
            _ => 0.0,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

/// What went wrong when reading a record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordErrorKind {
    /// The file could not be read (or is not UTF-8 text).
    Io,
    /// The file is empty.
    Empty,
    /// The `# format:` line is missing or names another format or version.
    Format,
    /// A required header key is missing, repeated or has a bad value.
    Header,
    /// The header row lacks a required column, repeats one, or is missing.
    Columns,
    /// A row has the wrong number of fields, or there are no rows.
    Row,
    /// A field is not a number.
    Number,
    /// `t_s` does not increase or is not sampled at fs_hz (±1 %).
    Time,
}

/// A record error naming the file, the line, the column (1-based field number, or the
/// character position on `#` lines) and the column or header key.
///
/// Displayed as `file:line:col: context: message`, e.g.
/// `file.csv:123:7: column 'x1_re_um': expected a number, found 'abc'`.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordError {
    /// The kind of error.
    pub kind: RecordErrorKind,
    /// The file (the `source` given to the parser).
    pub file: String,
    /// 1-based line, where known.
    pub line: Option<usize>,
    /// 1-based column: the field number on the header row and data rows, the character
    /// position of the value on `#` header lines.
    pub column: Option<usize>,
    /// The column or header key, e.g. `column 'x1_re_um'` or `header 'f0_hz'`.
    pub context: Option<String>,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for RecordError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.file)?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
            if let Some(col) = self.column {
                write!(f, ":{col}")?;
            }
        }
        f.write_str(": ")?;
        if let Some(ctx) = &self.context {
            write!(f, "{ctx}: ")?;
        }
        f.write_str(&self.message)
    }
}

impl std::error::Error for RecordError {}

/// A field as quoted in messages (at most 40 characters).
fn quoted(s: &str) -> String {
    if s.is_empty() {
        return "an empty field".to_string();
    }
    let mut q: String = s.chars().take(40).collect();
    if q.len() < s.len() {
        q.push('…');
    }
    format!("'{q}'")
}

// ---------------------------------------------------------------------------------------------
// Reader
// ---------------------------------------------------------------------------------------------

/// Reads a record file (line by line). The error names `path` as the file.
pub fn read_record(path: &Path) -> Result<Record, RecordError> {
    let source = path.display().to_string();
    let file = File::open(path).map_err(|e| RecordError {
        kind: RecordErrorKind::Io,
        file: source.clone(),
        line: None,
        column: None,
        context: None,
        message: format!("cannot read the record: {e}"),
    })?;
    read_record_from(BufReader::with_capacity(1 << 16, file), &source)
}

/// Parses a record held in memory; `source` names the file in messages.
pub fn parse_record(text: &str, source: &str) -> Result<Record, RecordError> {
    read_record_from(text.as_bytes(), source)
}

/// One `# key: value` line.
struct KeyLine {
    value: String,
    line: usize,
    /// 1-based character position of the value.
    value_col: usize,
}

/// A `# key: value` line split up; the columns are 1-based character positions.
struct KeyValue<'l> {
    key: &'l str,
    key_col: usize,
    value: &'l str,
    value_col: usize,
}

/// Splits `# key: value`; `None` for a comment (no colon, or a key with spaces).
fn key_value(line: &str) -> Option<KeyValue<'_>> {
    let rest = line.strip_prefix('#')?;
    let colon = rest.find(':')?;
    let before = &rest[..colon];
    let key = before.trim();
    if key.is_empty() || key.contains(char::is_whitespace) {
        return None;
    }
    let key_lead = before.len() - before.trim_start().len();
    let after = &rest[colon + 1..];
    let lead = after.len() - after.trim_start().len();
    Some(KeyValue {
        key,
        // '#', the spaces before the key, then 1-based
        key_col: 1 + before[..key_lead].chars().count() + 1,
        value: after.trim(),
        // '#', the text up to the colon, ':', the spaces before the value, then 1-based
        value_col: 1 + before.chars().count() + 1 + after[..lead].chars().count() + 1,
    })
}

/// Where the known columns sit in the header row.
struct Columns {
    /// For each field of the header row, the known column it is (None: ignored).
    field_known: Vec<Option<usize>>,
    /// For each known column, its field index (None: absent; only optional ones).
    known_field: [Option<usize>; N_KNOWN],
    /// The names of the header row.
    names: Vec<String>,
    /// Line of the header row.
    line: usize,
}

/// The streaming parser: one line at a time.
struct Parser<'a> {
    source: &'a str,
    /// Seen the format line.
    format_ok: bool,
    keys: Vec<(&'static str, KeyLine)>,
    extra: Vec<(String, String)>,
    header: Option<RecordHeader>,
    columns: Option<Columns>,
    rows: Vec<RecordRow>,
    warnings: Vec<String>,
    /// (t_s, line) of the previous row.
    prev: Option<(f64, usize)>,
    /// Rows with a non-finite data value, and the first one's line.
    nan_rows: (usize, usize),
    /// Lines seen.
    lines: usize,
}

impl<'a> Parser<'a> {
    fn new(source: &'a str) -> Self {
        Parser {
            source,
            format_ok: false,
            keys: Vec::new(),
            extra: Vec::new(),
            header: None,
            columns: None,
            rows: Vec::new(),
            warnings: Vec::new(),
            prev: None,
            nan_rows: (0, 0),
            lines: 0,
        }
    }

    fn err(
        &self,
        kind: RecordErrorKind,
        line: usize,
        column: Option<usize>,
        context: Option<String>,
        message: String,
    ) -> RecordError {
        RecordError {
            kind,
            file: self.source.to_string(),
            line: Some(line),
            column,
            context,
            message,
        }
    }

    fn line(&mut self, no: usize, line: &str) -> Result<(), RecordError> {
        self.lines = no;
        if self.columns.is_some() {
            if line.trim().is_empty() || line.starts_with('#') {
                return Ok(()); // blank lines and comments between rows are allowed
            }
            return self.row(no, line);
        }
        if line.trim().is_empty() {
            return Ok(());
        }
        if !self.format_ok {
            return self.format_line(no, line);
        }
        if line.starts_with('#') {
            return self.header_line(no, line);
        }
        self.header_row(no, line)
    }

    fn format_line(&mut self, no: usize, line: &str) -> Result<(), RecordError> {
        let ctx = Some("header 'format'".to_string());
        match key_value(line) {
            Some(KeyValue {
                key: "format",
                value,
                value_col: col,
                ..
            }) => {
                let mut words = value.split_whitespace();
                let (name, version) = (words.next(), words.next());
                if name != Some(FORMAT_NAME) || words.next().is_some() {
                    return Err(self.err(
                        RecordErrorKind::Format,
                        no,
                        Some(col),
                        ctx,
                        format!("expected '{FORMAT}', found {}", quoted(value)),
                    ));
                }
                if version != Some("1") {
                    return Err(self.err(
                        RecordErrorKind::Format,
                        no,
                        Some(col),
                        ctx,
                        format!(
                            "unsupported version {}: this reader reads '{FORMAT}'",
                            quoted(version.unwrap_or(""))
                        ),
                    ));
                }
                self.format_ok = true;
                self.keys.push((
                    "format",
                    KeyLine {
                        value: value.to_string(),
                        line: no,
                        value_col: col,
                    },
                ));
                Ok(())
            }
            _ => Err(self.err(
                RecordErrorKind::Format,
                no,
                Some(1),
                ctx,
                format!(
                    "the first line must be '# format: {FORMAT}' (not a paragyro record?), found {}",
                    quoted(line)
                ),
            )),
        }
    }

    fn header_line(&mut self, no: usize, line: &str) -> Result<(), RecordError> {
        let Some(KeyValue {
            key,
            key_col,
            value,
            value_col,
        }) = key_value(line)
        else {
            return Ok(()); // a comment
        };
        match HEADER_KEYS.iter().find(|k| **k == key) {
            Some(&k) => {
                if let Some((_, first)) = self.keys.iter().find(|(n, _)| *n == k) {
                    return Err(self.err(
                        RecordErrorKind::Header,
                        no,
                        Some(key_col),
                        Some(format!("header '{k}'")),
                        format!("repeated (first on line {})", first.line),
                    ));
                }
                self.keys.push((
                    k,
                    KeyLine {
                        value: value.to_string(),
                        line: no,
                        value_col,
                    },
                ));
            }
            None => self.extra.push((key.to_string(), value.to_string())),
        }
        Ok(())
    }

    /// The header keys, checked, when the header row arrives on line `no`.
    fn finish_header(&self, no: usize) -> Result<RecordHeader, RecordError> {
        let get = |k: &str| -> Result<&KeyLine, RecordError> {
            self.keys
                .iter()
                .find(|(n, _)| *n == k)
                .map(|(_, v)| v)
                .ok_or_else(|| {
                    self.err(
                        RecordErrorKind::Header,
                        no,
                        Some(1),
                        Some(format!("header '{k}'")),
                        format!(
                            "required header line '# {k}: <value>' is missing before the header row"
                        ),
                    )
                })
        };
        let bad = |k: &str, kl: &KeyLine, what: &str| {
            self.err(
                RecordErrorKind::Header,
                kl.line,
                Some(kl.value_col),
                Some(format!("header '{k}'")),
                format!("expected {what}, found {}", quoted(&kl.value)),
            )
        };
        let pos = |k: &str| -> Result<f64, RecordError> {
            let kl = get(k)?;
            match kl.value.parse::<f64>() {
                Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
                _ => Err(bad(k, kl, "a positive number")),
            }
        };
        let order_kl = get("lockin_lpf_order")?;
        let order = match order_kl.value.parse::<usize>() {
            Ok(n) if (1..=crate::lockin::MAX_LPF_ORDER).contains(&n) => n,
            _ => {
                return Err(bad(
                    "lockin_lpf_order",
                    order_kl,
                    &format!("an integer 1..={}", crate::lockin::MAX_LPF_ORDER),
                ));
            }
        };
        Ok(RecordHeader {
            f0_hz: pos("f0_hz")?,
            l0_um: pos("l0_um")?,
            fs_hz: pos("fs_hz")?,
            lockin_lpf_order: order,
            lockin_lpf_hz: pos("lockin_lpf_hz")?,
            pump_amp_ref_v: pos("pump_amp_ref_v")?,
            extra: self.extra.clone(),
        })
    }

    fn header_row(&mut self, no: usize, line: &str) -> Result<(), RecordError> {
        let header = self.finish_header(no)?;
        let names: Vec<String> = line.split(',').map(|s| s.trim().to_string()).collect();
        let mut field_known = vec![None; names.len()];
        let mut known_field = [None; N_KNOWN];
        for (i, name) in names.iter().enumerate() {
            if name.is_empty() {
                return Err(self.err(
                    RecordErrorKind::Columns,
                    no,
                    Some(i + 1),
                    Some("header row".into()),
                    format!("column {} has no name", i + 1),
                ));
            }
            if let Some(j) = names[..i].iter().position(|n| n == name) {
                return Err(self.err(
                    RecordErrorKind::Columns,
                    no,
                    Some(i + 1),
                    Some(format!("column '{name}'")),
                    format!("repeated (first as column {})", j + 1),
                ));
            }
            match (0..N_KNOWN).find(|&k| known_name(k) == name) {
                Some(k) => {
                    field_known[i] = Some(k);
                    known_field[k] = Some(i);
                }
                None => self.warnings.push(format!(
                    "{}:{no}:{}: column '{name}' is not part of {FORMAT}: ignored",
                    self.source,
                    i + 1
                )),
            }
        }
        let missing: Vec<usize> = (0..N_REQUIRED)
            .filter(|&k| known_field[k].is_none())
            .collect();
        if let Some(&first) = missing.first() {
            let all: Vec<String> = missing
                .iter()
                .map(|&k| format!("'{}'", REQUIRED_COLUMNS[k]))
                .collect();
            return Err(self.err(
                RecordErrorKind::Columns,
                no,
                Some(first + 1),
                Some(format!("column '{}'", REQUIRED_COLUMNS[first])),
                format!(
                    "required column is missing from the header row (column {} of the \
                     standard order); missing: {}",
                    first + 1,
                    all.join(", ")
                ),
            ));
        }
        self.header = Some(header);
        self.columns = Some(Columns {
            field_known,
            known_field,
            names,
            line: no,
        });
        Ok(())
    }

    fn row(&mut self, no: usize, line: &str) -> Result<(), RecordError> {
        let cols = self.columns.as_ref().expect("header row parsed");
        let n = cols.field_known.len();
        let mut vals = [""; N_KNOWN];
        let mut count = 0usize;
        for (i, field) in line.split(',').enumerate() {
            if let Some(Some(k)) = cols.field_known.get(i) {
                vals[*k] = field;
            }
            count = i + 1;
        }
        if count != n {
            let (col, ctx) = if count > n {
                (n + 1, "row".to_string())
            } else {
                (count + 1, format!("column '{}'", cols.names[count]))
            };
            return Err(self.err(
                RecordErrorKind::Row,
                no,
                Some(col),
                Some(ctx),
                format!(
                    "the row has {count} fields, expected {n} (as the header row on line {})",
                    cols.line
                ),
            ));
        }
        let number = |k: usize, s: &str| -> Result<f64, RecordError> {
            let t = s.trim();
            t.parse::<f64>().map_err(|_| {
                self.err(
                    RecordErrorKind::Number,
                    no,
                    cols.known_field[k].map(|i| i + 1),
                    Some(format!("column '{}'", known_name(k))),
                    format!("expected a number, found {}", quoted(t)),
                )
            })
        };
        let mut req = [0.0; N_REQUIRED];
        for k in 0..N_REQUIRED {
            req[k] = number(k, vals[k])?;
        }
        let optional = |k: usize| -> Result<Option<f64>, RecordError> {
            if cols.known_field[k].is_none() || vals[k].trim().is_empty() {
                Ok(None)
            } else {
                number(k, vals[k]).map(Some)
            }
        };
        let temp = optional(COL_TEMP)?;
        let rate = optional(COL_RATE)?;
        // time: finite, increasing, regular
        let t = req[COL_T];
        let t_col = cols.known_field[COL_T].map(|i| i + 1);
        let t_ctx = Some("column 't_s'".to_string());
        if !t.is_finite() {
            return Err(self.err(
                RecordErrorKind::Time,
                no,
                t_col,
                t_ctx,
                format!(
                    "expected a finite time, found {}",
                    quoted(vals[COL_T].trim())
                ),
            ));
        }
        if let Some((tp, lp)) = self.prev {
            let fs = self.header.as_ref().expect("header parsed").fs_hz;
            let dt = t - tp;
            if dt <= 0.0 {
                return Err(self.err(
                    RecordErrorKind::Time,
                    no,
                    t_col,
                    t_ctx,
                    format!("time does not increase: {t} s after {tp} s on line {lp}"),
                ));
            }
            if (dt * fs - 1.0).abs() > SAMPLING_TOLERANCE {
                return Err(self.err(
                    RecordErrorKind::Time,
                    no,
                    t_col,
                    t_ctx,
                    format!(
                        "irregular sampling: step of {dt} s from line {lp}, expected 1/fs_hz = {} s \
                         within {} %",
                        1.0 / fs,
                        SAMPLING_TOLERANCE * 100.0
                    ),
                ));
            }
        }
        self.prev = Some((t, no));
        if req[1..].iter().any(|v| !v.is_finite()) {
            if self.nan_rows.0 == 0 {
                self.nan_rows.1 = no;
            }
            self.nan_rows.0 += 1;
        }
        self.rows.push(RecordRow::from_required(&req, temp, rate));
        Ok(())
    }

    fn finish(mut self) -> Result<Record, RecordError> {
        let last = self.lines;
        if !self.format_ok {
            return Err(RecordError {
                kind: RecordErrorKind::Empty,
                file: self.source.to_string(),
                line: Some(1),
                column: Some(1),
                context: None,
                message: format!("the file is empty (expected '# format: {FORMAT}')"),
            });
        }
        let Some(cols) = &self.columns else {
            return Err(self.err(
                RecordErrorKind::Columns,
                last + 1,
                Some(1),
                Some("header row".into()),
                "missing: the file ends after the header lines (no column names, no rows)".into(),
            ));
        };
        if self.rows.is_empty() {
            return Err(self.err(
                RecordErrorKind::Row,
                cols.line + 1,
                Some(1),
                None,
                "no sample rows after the header row".into(),
            ));
        }
        if self.nan_rows.0 > 0 {
            self.warnings.push(format!(
                "{}:{}: {} row(s) have NaN or infinite values (first on this line); kept: the \
                 core flags and skips such samples",
                self.source, self.nan_rows.1, self.nan_rows.0
            ));
        }
        Ok(Record {
            header: self.header.expect("header parsed with the columns"),
            rows: self.rows,
            warnings: self.warnings,
        })
    }
}

/// Reads a record from any buffered reader, line by line; `source` names the file in
/// messages.
pub fn read_record_from<R: BufRead>(mut reader: R, source: &str) -> Result<Record, RecordError> {
    let mut p = Parser::new(source);
    let mut buf = String::new();
    let mut no = 0usize;
    loop {
        buf.clear();
        let n = reader.read_line(&mut buf).map_err(|e| RecordError {
            kind: RecordErrorKind::Io,
            file: source.to_string(),
            line: Some(no + 1),
            column: None,
            context: None,
            message: if e.kind() == std::io::ErrorKind::InvalidData {
                "not UTF-8 text".to_string()
            } else {
                format!("cannot read the record: {e}")
            },
        })?;
        if n == 0 {
            break;
        }
        no += 1;
        let mut line = buf.trim_end_matches(['\n', '\r']);
        if no == 1 {
            line = line.strip_prefix('\u{feff}').unwrap_or(line);
        }
        p.line(no, line)?;
    }
    p.finish()
}

// ---------------------------------------------------------------------------------------------
// Writer
// ---------------------------------------------------------------------------------------------

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

// ---------------------------------------------------------------------------------------------
// From a simulation
// ---------------------------------------------------------------------------------------------

/// Pump voltage amplitude V0 at which s = 1 in simulated records, V.
pub const SIM_PUMP_AMP_REF_V: f64 = 1.0;

pub use crate::effects::EffectSpec;

/// Options of a simulated record.
#[derive(Clone, Debug, Default)]
pub struct RecordOptions {
    /// Overrides the scenario's noise seed.
    pub seed: Option<u64>,
    /// Effects added to the simulated device ([`crate::effects`]).
    pub effects: Vec<EffectSpec>,
    /// Die temperature `(start °C, rise K over the run)`, written as `temp_c` (with a
    /// 0.01 K sensor resolution); `None`: no temperature column, unless the thermal drift
    /// is added, which then gets the default 25 °C + 5 K.
    /// A rate table is present: write the scenario's true rate as `rate_ref_dps`.
    pub rate_table: bool,
    /// Die temperature profile (see above).
    pub temp: Option<(f64, f64)>,
}

/// Temperature profile of a record with thermal drift but no profile given: 25 °C + 5 K.
pub const DEFAULT_TEMP_PROFILE: (f64, f64) = (25.0, 5.0);

/// A simulated record of a scenario (main run, no twin) and its truth; see
/// [`simulate_record_with`].
pub fn simulate_record(sc: &Scenario, seed: Option<u64>) -> anyhow::Result<(Record, Value)> {
    let opts = RecordOptions {
        seed,
        ..RecordOptions::default()
    };
    simulate_record_with(sc, &opts, &mut |_| {})
}

/// A simulated record and its truth (JSON).
///
/// The closed loop of [`runner::simulate`] with the `f64` core and [`runner::core_config`]:
/// at every 500 Hz sample the lock-in outputs, the accelerations and the pump in effect go
/// to the core, whose command sets the pump for the next sample; each sample becomes one
/// row (the pump frequency in effect, `pump_amp_v` = V0·√s with V0 = 1 V, accelerations in
/// m/s², the 14 lock-in channels in µm). Same seed, same rows as the runner sees.
/// `progress` gets the fraction done (at most every 100 ms).
pub fn simulate_record_with(
    sc: &Scenario,
    opts: &RecordOptions,
    progress: &mut dyn FnMut(f64),
) -> anyhow::Result<(Record, Value)> {
    let gamma_per_dps = paragyro_core::physics::gamma_from_rate_dps(1.0, sc.omega0_rad_s());
    let effects = Effects::from_specs(&opts.effects, gamma_per_dps).map_err(anyhow::Error::msg)?;
    let temp = opts
        .temp
        .or((effects.tcf_ppm_k != 0.0).then_some(DEFAULT_TEMP_PROFILE));
    let dev = Device { effects, temp };
    let cfg = runner::core_config(sc);
    let mut est: Estimator<f64> = cfg
        .build()
        .map_err(|e| anyhow::anyhow!("core configuration: {e}"))?;
    let seed = opts.seed.unwrap_or(sc.seed);
    let n = (sc.duration_s * cfg.fs_hz).round() as u64;
    let mut rows = Vec::with_capacity(n as usize + 1);
    let pump_centre_initial_hz = est.pump_centre_hz();
    let mut last_progress = Instant::now();
    // the runner's closed loop: the record holds exactly what the core was given
    runner::closed_loop_with(
        sc,
        seed,
        &dev,
        &mut est,
        |_| {},
        |ls| {
            let li = ls.lockin;
            rows.push(RecordRow {
                t_s: ls.t_s,
                pump_hz: ls.sample.pump_hz,
                pump_amp_v: SIM_PUMP_AMP_REF_V * ls.sample.pump_scale.sqrt(),
                ax_mps2: ls.sample.accel_mps2[0],
                ay_mps2: ls.sample.accel_mps2[1],
                x0_um: li.x0,
                x_um: li.x,
                y0_um: li.y0,
                y_um: li.y,
                temp_c: temp.map(|_| (dev.temp_c(ls.t_s, sc.duration_s) * 100.0).round() / 100.0),
                rate_ref_dps: opts.rate_table.then_some(ls.plant.rate_dps),
            });
            if ls.k % 50 == 0 && last_progress.elapsed().as_millis() >= 100 {
                progress(ls.k as f64 / n.max(1) as f64);
                last_progress = Instant::now();
            }
        },
    )?;
    progress(1.0);
    let mut header = RecordHeader::from_config(&cfg);
    header.pump_amp_ref_v = SIM_PUMP_AMP_REF_V;
    header.extra = vec![
        (
            "generator".into(),
            format!("paragyro-sim {}", env!("CARGO_PKG_VERSION")),
        ),
        ("device".into(), "simulated".into()),
    ];
    let t_end = rows.last().map_or(0.0, |r| r.t_s);
    let truth = truth_json(
        sc,
        opts,
        seed,
        t_end,
        rows.len(),
        pump_centre_initial_hz,
        est.pump_centre_hz(),
    );
    let rec = Record {
        header,
        rows,
        warnings: Vec::new(),
    };
    Ok((rec, truth))
}

fn plant_json(pa: &PlantAt, t_s: f64, accel_si: f64) -> Value {
    let named = |names: &[&str], v: &[f64]| {
        let mut o = Map::new();
        for (n, x) in names.iter().zip(v) {
            o.insert((*n).into(), json!(x));
        }
        Value::Object(o)
    };
    json!({
        "t_s": t_s,
        "theta_drive": named(&THETA_DRIVE_NAMES, &pa.theta_drive),
        "theta_sense": named(&THETA_SENSE_NAMES, &pa.theta_sense),
        "physical": named(&PHYS_NAMES, &pa.phys),
        "rate_dps": pa.rate_dps,
        "accel_x_mps2": pa.accel_x * accel_si,
        "accel_y_mps2": pa.accel_y * accel_si,
    })
}

fn truth_json(
    sc: &Scenario,
    opts: &RecordOptions,
    seed: u64,
    t_end: f64,
    samples: usize,
    pump_centre_initial_hz: f64,
    pump_centre_final_hz: f64,
) -> Value {
    let w0 = sc.omega0_rad_s();
    let accel_si = L0_M * w0 * w0;
    let plant = |t: f64| plant_json(&sc.plant_at(t), t, accel_si);
    let events: Vec<Value> = sc
        .events
        .iter()
        .map(|e| {
            let mut v = serde_json::to_value(e).unwrap_or(Value::Null);
            if let Value::Object(m) = &mut v {
                m.insert("what".into(), json!(e.kind.to_string()));
                if let Some(c) = sc.pump_jump_centre_hz(e) {
                    m.insert("pump_centre_hz".into(), json!(c));
                }
            }
            v
        })
        .collect();
    json!({
        "format": "paragyro-record-truth 1",
        "scenario": sc.name,
        "scenario_source": sc.source,
        "description": sc.description,
        "seed": seed,
        "samples": samples,
        "duration_s": t_end,
        "f0_hz": sc.sim.f0_hz,
        "omega0_rad_s": w0,
        "noise_pm_rthz": sc.sim.noise_pm_rthz,
        "lockin": {
            "lpf_order": sc.sim.lockin_lpf_order,
            "lpf_hz": sc.sim.lockin_lpf_hz,
        },
        "steps_per_period": sc.sim.steps_per_period,
        "pump_amp_ref_v": SIM_PUMP_AMP_REF_V,
        "initial_state_um": {"x": sc.plant.initial_x_um, "y": sc.plant.initial_y_um},
        "plant_start": plant(0.0),
        "plant_end": plant(t_end),
        "events": events,
        "effects": opts.effects,
        "rate_table": opts.rate_table,
        "closed_loop": {
            "core": "f64",
            "pump_centre_initial_hz": pump_centre_initial_hz,
            "pump_centre_final_hz": pump_centre_final_hz,
        },
        "twin_ignored": sc.twin.is_some(),
        "scenario_spec": serde_json::to_value(sc).unwrap_or(Value::Null),
    })
}

/// Where the truth of a simulated record goes: `FILE.csv` → `FILE.truth.json`
/// (`FILE` → `FILE.truth.json` without a `.csv` extension).
pub fn truth_path(csv: &Path) -> PathBuf {
    let is_csv = csv
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    let base = if is_csv {
        csv.with_extension("")
    } else {
        csv.to_path_buf()
    };
    let mut name = base.file_name().unwrap_or_default().to_os_string();
    name.push(".truth.json");
    base.with_file_name(name)
}

/// The files of a simulated record.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordFiles {
    /// The record (CSV).
    pub csv: PathBuf,
    /// Its truth (JSON), beside it.
    pub truth: PathBuf,
}

/// Simulates a scenario and writes `out` (the record) and [`truth_path`]`(out)` (the
/// truth, with `"record"` set to the CSV's file name). Creates the parent directory.
pub fn write_simulated_record(
    sc: &Scenario,
    out: &Path,
    opts: &RecordOptions,
    progress: &mut dyn FnMut(f64),
) -> anyhow::Result<(RecordFiles, Record)> {
    let (rec, mut truth) = simulate_record_with(sc, opts, progress)
        .with_context(|| format!("simulating scenario '{}'", sc.name))?;
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the directory {}", dir.display()))?;
    }
    write_record(out, &rec)?;
    let tp = truth_path(out);
    if let Value::Object(m) = &mut truth {
        let name = out.file_name().map(|n| n.to_string_lossy().into_owned());
        m.insert("record".into(), json!(name));
    }
    let text = serde_json::to_string_pretty(&truth)?;
    std::fs::write(&tp, text + "\n").with_context(|| format!("cannot write {}", tp.display()))?;
    Ok((
        RecordFiles {
            csv: out.to_path_buf(),
            truth: tp,
        },
        rec,
    ))
}

// ---------------------------------------------------------------------------------------------
// Replay
// ---------------------------------------------------------------------------------------------

/// The core's estimates after one sample of a replayed record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReplayRow {
    /// Time, s (from the record).
    pub t_s: f64,
    /// Pump frequency of the record, Hz.
    pub pump_hz: f64,
    /// Pump scale s = (V_A/V_A0)² the core was given.
    pub pump_scale: f64,
    /// θ̂1 (drive, 8).
    pub theta_drive: [f64; 8],
    /// θ̂2 (sense, 6).
    pub theta_sense: [f64; 6],
    /// Estimated rate, °/s.
    pub rate_dps: f64,
    /// ω̂y² (non-dimensional).
    pub wy2: f64,
    /// Health bits (see [`HEALTH_NAMES`]).
    pub health: u32,
    /// Event bits of the step (`paragyro_core::estimator::event`).
    pub events: u8,
    /// The pump frequency the core would have commanded next (ignored in replay), Hz.
    pub pump_hz_cmd: f64,
    /// Counters after the step.
    pub counters: Counters,
}

/// The core configuration for a record of a device known only by its record: Table 2
/// design ([`Config::table2`]) with f0, fs, L0, the lock-in settings and V_A0 of the
/// header, the pump centre at the first finite positive `pump_hz` of the rows and the
/// Table 2 dither amplitude scaled to f0 (2e-3·f0).
pub fn config_for(rec: &Record) -> Config {
    let h = &rec.header;
    let mut c = Config::table2();
    c.f0_hz = h.f0_hz;
    c.fs_hz = h.fs_hz;
    c.l0_um = h.l0_um;
    c.lockin_lpf_order = h.lockin_lpf_order;
    c.lockin_lpf_hz = h.lockin_lpf_hz;
    c.pump_amp_ref_v = h.pump_amp_ref_v;
    c.dither.pump_hz = 2.0e-3 * h.f0_hz;
    if let Some(p) = rec
        .rows
        .iter()
        .map(|r| r.pump_hz)
        .find(|p| p.is_finite() && *p > 0.0)
    {
        c.pump_centre_hz = p;
    }
    c
}

/// Runs the core in precision `T` open-loop on a record: every row becomes a
/// [`Sample`] ([`RecordRow::to_sample`]), the pump is the record's (the core's own pump
/// command is reported in [`ReplayRow::pump_hz_cmd`] and otherwise ignored). Same data
/// and configuration as a closed-loop run ⇒ the same estimates. Errors when `cfg` is
/// invalid or its fs_hz is not the record's.
pub fn replay<T: Real>(rec: &Record, cfg: &Config) -> anyhow::Result<Vec<ReplayRow>> {
    anyhow::ensure!(
        cfg.fs_hz == rec.header.fs_hz,
        "the core runs at fs_hz = {} but the record is sampled at {} Hz",
        cfg.fs_hz,
        rec.header.fs_hz
    );
    let mut est: Estimator<T> = cfg
        .build()
        .map_err(|e| anyhow::anyhow!("core configuration: {e}"))?;
    let w0 = cfg.omega0_rad_s();
    let mut out = Vec::with_capacity(rec.rows.len());
    for r in &rec.rows {
        let s = r.to_sample::<T>(&rec.header);
        let o = est.step(&s);
        let (th1, th2) = est.theta();
        let phys = physical_from_theta(&th1, &th2);
        out.push(ReplayRow {
            t_s: r.t_s,
            pump_hz: r.pump_hz,
            pump_scale: s.pump_scale.to_f64(),
            theta_drive: th1,
            theta_sense: th2,
            rate_dps: rate_dps_from_gamma(phys.gamma, w0),
            wy2: est.wy2(),
            health: o.health.bits(),
            events: o.events,
            pump_hz_cmd: o.pump_hz_next,
            counters: est.counters(),
        });
    }
    Ok(out)
}

/// Column names of the replay CSV.
pub fn replay_csv_header() -> Vec<String> {
    let mut h: Vec<String> = ["t_s", "pump_hz", "pump_scale"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    h.extend(THETA_DRIVE_NAMES.iter().map(|n| format!("{n}_est")));
    h.extend(THETA_SENSE_NAMES.iter().map(|n| format!("{n}_est")));
    h.extend(
        [
            "rate_dps_est",
            "wy2_est",
            "health",
            "events",
            "pump_hz_cmd",
            "updates",
            "bad_samples",
            "resets_drive",
            "resets_sense",
        ]
        .iter()
        .map(|s| s.to_string()),
    );
    h
}

/// Writes the replay estimates as CSV (one row per sample, [`replay_csv_header`]).
pub fn write_replay_csv<W: Write>(mut w: W, rows: &[ReplayRow]) -> anyhow::Result<()> {
    let mut line = replay_csv_header().join(",");
    line.push('\n');
    w.write_all(line.as_bytes())?;
    for r in rows {
        line.clear();
        for v in [r.t_s, r.pump_hz, r.pump_scale]
            .iter()
            .chain(&r.theta_drive)
            .chain(&r.theta_sense)
            .chain(&[r.rate_dps, r.wy2])
        {
            push_number(&mut line, *v);
            line.push(',');
        }
        let c = &r.counters;
        let _ = write!(line, "{},{},", r.health, r.events);
        push_number(&mut line, r.pump_hz_cmd);
        let _ = writeln!(
            line,
            ",{},{},{},{}",
            c.updates, c.bad_samples, c.resets_drive, c.resets_sense
        );
        w.write_all(line.as_bytes())?;
    }
    w.flush()?;
    Ok(())
}

/// The core configuration a replay ran with (the part `summary.json` shows).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[allow(missing_docs)]
pub struct ReplayConfig {
    pub f0_hz: f64,
    pub fs_hz: f64,
    pub pump_centre_hz: f64,
    pub lockin_lpf_order: usize,
    pub lockin_lpf_hz: f64,
    pub noise_pm_rthz: f64,
}

/// The core's counters at the end of a replay.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[allow(missing_docs)]
pub struct ReplayCounters {
    pub samples: u32,
    pub updates: u32,
    pub bad_samples: u32,
    pub non_finite: u32,
    pub saturated: u32,
    pub stuck: u32,
    pub resets_drive: u32,
    pub resets_sense: u32,
    pub retunes: u32,
    pub retune_aborts: u32,
}

impl From<&Counters> for ReplayCounters {
    fn from(c: &Counters) -> Self {
        ReplayCounters {
            samples: c.samples,
            updates: c.updates,
            bad_samples: c.bad_samples,
            non_finite: c.non_finite,
            saturated: c.saturated,
            stuck: c.stuck,
            resets_drive: c.resets_drive,
            resets_sense: c.resets_sense,
            retunes: c.retunes,
            retune_aborts: c.retune_aborts,
        }
    }
}

/// The estimates at the end of a replay (absent when the record had no row).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReplayFinal {
    /// θ̂ after the last sample (`{"drive": {"th11": ..}, "sense": {..}}`).
    #[serde(serialize_with = "crate::summary::theta_named")]
    pub theta_est: ThetaPair<f64>,
    /// Physical parameters from θ̂.
    pub physical_est: PhysicalValues,
    /// Estimated rate after the last sample, °/s.
    pub rate_dps_est: f64,
    /// ω̂y² after the last sample.
    pub wy2_est: f64,
    /// Mean of the finite rate estimates over the last second, °/s.
    pub rate_dps_est_mean_last_1s: Option<f64>,
    /// Mean of the record's `rate_ref_dps` over the last second, °/s (when it has it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rate_ref_dps_mean_last_1s: Option<f64>,
    /// The difference of the two means, °/s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rate_err_dps_last_1s: Option<f64>,
    /// Health flags set after the last sample (names of [`HEALTH_NAMES`]).
    pub health_final: Vec<&'static str>,
    /// The core's counters at the end.
    pub counters: ReplayCounters,
}

/// `summary.json` of a replay.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReplaySummary {
    /// The record (as named by the caller).
    pub record: String,
    /// Core precision.
    pub precision: Precision,
    /// Rows replayed.
    pub samples: usize,
    /// Duration of the record, s.
    pub duration_s: f64,
    /// The reader's warnings.
    pub warnings: Vec<String>,
    /// The core configuration.
    pub config: ReplayConfig,
    /// The final estimates (its fields are top-level keys of `summary.json`).
    #[serde(flatten)]
    pub last: Option<ReplayFinal>,
}

/// The summary of a replay: final θ̂ and physical parameters, rate (and its error against
/// `rate_ref_dps` over the last second, when the record has it), health, counters.
pub fn replay_summary(
    rec: &Record,
    source: &str,
    cfg: &Config,
    precision: Precision,
    rows: &[ReplayRow],
) -> ReplaySummary {
    let config = ReplayConfig {
        f0_hz: cfg.f0_hz,
        fs_hz: cfg.fs_hz,
        pump_centre_hz: cfg.pump_centre_hz,
        lockin_lpf_order: cfg.lockin_lpf_order,
        lockin_lpf_hz: cfg.lockin_lpf_hz,
        noise_pm_rthz: cfg.noise_pm_rthz,
    };
    ReplaySummary {
        record: source.to_string(),
        precision,
        samples: rows.len(),
        duration_s: rec.duration_s(),
        warnings: rec.warnings.clone(),
        config,
        last: rows.last().map(|last| replay_final(rec, rows, last)),
    }
}

fn replay_final(rec: &Record, rows: &[ReplayRow], last: &ReplayRow) -> ReplayFinal {
    let phys = physical_from_theta(&last.theta_drive, &last.theta_sense).as_array();
    let tail: Vec<&ReplayRow> = rows
        .iter()
        .filter(|r| r.t_s >= last.t_s - 1.0 && r.rate_dps.is_finite())
        .collect();
    let mean_rate = (!tail.is_empty())
        .then(|| tail.iter().map(|r| r.rate_dps).sum::<f64>() / tail.len() as f64);
    let refs: Vec<f64> = rec
        .rows
        .iter()
        .filter(|r| r.t_s >= last.t_s - 1.0)
        .filter_map(|r| r.rate_ref_dps)
        .filter(|v| v.is_finite())
        .collect();
    let ref_mean = (!refs.is_empty()).then(|| refs.iter().sum::<f64>() / refs.len() as f64);
    ReplayFinal {
        theta_est: ThetaPair {
            drive: last.theta_drive,
            sense: last.theta_sense,
        },
        physical_est: PhysicalValues::from_array(phys),
        rate_dps_est: last.rate_dps,
        wy2_est: last.wy2,
        rate_dps_est_mean_last_1s: mean_rate,
        rate_ref_dps_mean_last_1s: ref_mean,
        rate_err_dps_last_1s: ref_mean.and_then(|rr| Some(mean_rate? - rr)),
        health_final: HEALTH_NAMES
            .iter()
            .enumerate()
            .filter(|(i, _)| last.health & (1 << i) != 0)
            .map(|(_, n)| *n)
            .collect(),
        counters: ReplayCounters::from(&last.counters),
    }
}

/// What [`write_replay`] produced.
#[derive(Clone, Debug)]
pub struct ReplayOutputs {
    /// The files written (`estimates.csv`, `summary.json`).
    pub files: Vec<PathBuf>,
    /// The summary (as written to `summary.json`).
    pub summary: ReplaySummary,
    /// A few lines for people.
    pub text: String,
}

/// Replays a record with [`config_for`] in `precision` and writes `dir/estimates.csv` and
/// `dir/summary.json` (creating `dir`); `source` names the record in the summary.
pub fn write_replay(
    rec: &Record,
    source: &str,
    dir: &Path,
    precision: Precision,
) -> anyhow::Result<ReplayOutputs> {
    let cfg = config_for(rec);
    let rows = match precision {
        Precision::F32 => replay::<f32>(rec, &cfg),
        Precision::F64 => replay::<f64>(rec, &cfg),
    }
    .with_context(|| format!("replaying {source}"))?;
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the directory {}", dir.display()))?;
    let csv = dir.join("estimates.csv");
    let f = File::create(&csv).with_context(|| format!("cannot create {}", csv.display()))?;
    write_replay_csv(BufWriter::with_capacity(1 << 16, f), &rows)
        .with_context(|| format!("cannot write {}", csv.display()))?;
    let summary = replay_summary(rec, source, &cfg, precision, &rows);
    let sj = dir.join("summary.json");
    std::fs::write(&sj, crate::summary::to_json_pretty(&summary)?)
        .with_context(|| format!("cannot write {}", sj.display()))?;
    let mut text = format!(
        "Replayed {source}: {} samples ({:.3} s) with the {} core (pump centre {:.3} Hz from the record)\n",
        rows.len(),
        rec.duration_s(),
        precision.name(),
        cfg.pump_centre_hz
    );
    if let Some(last) = rows.last() {
        let _ = writeln!(
            text,
            "  final: rate {:.4} °/s, ωy² {:.6}, health [{}], {} bad samples, {} resets",
            last.rate_dps,
            last.wy2,
            summary
                .last
                .as_ref()
                .map(|f| f.health_final.join(", "))
                .unwrap_or_default(),
            last.counters.bad_samples,
            last.counters.resets_drive + last.counters.resets_sense
        );
    }
    Ok(ReplayOutputs {
        files: vec![csv, sj],
        summary,
        text,
    })
}
