//! The reader: line by line, with errors that name the file, the line, the column (number
//! and name).

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::Path;

use super::error::quoted;
use super::{
    COL_RATE, COL_T, COL_TEMP, FORMAT, FORMAT_NAME, HEADER_KEYS, N_KNOWN, N_REQUIRED,
    REQUIRED_COLUMNS, Record, RecordError, RecordErrorKind, RecordHeader, RecordRow,
    SAMPLING_TOLERANCE, known_name,
};

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
