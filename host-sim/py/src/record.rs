//! Records across the boundary. A record goes to Python as `(header, columns, warnings)`:
//! the header as `(key, value)` pairs in file order (the required keys as numbers, the
//! extra ones as text), the columns as `(name, bytearray)` pairs of native-endian `f64`
//! (the required ones, then `temp_c` and `rate_ref_dps` when present, `NaN` where the
//! field is empty). It comes back the same way ([`RecordParts`]) and is checked by the
//! record reader itself: a record Python hands over is the file it would write, or the
//! error reading that file would give.

use std::path::PathBuf;

use paragyro_simulator::record::{
    self, N_REQUIRED, OPTIONAL_COLUMNS, REQUIRED_COLUMNS, Record, RecordHeader, RecordRow,
};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes, PyDict, PyList, PyTuple};

use crate::errors::{Fail, guarded};

/// A record as Python hands it over (the fields of `paragyro.Record`).
pub(crate) struct RecordParts {
    /// `f0_hz`, `l0_um`, `fs_hz`, `lockin_lpf_order`, `lockin_lpf_hz`, `pump_amp_ref_v`.
    numbers: [f64; 6],
    /// The extra header keys, in order.
    extra: Vec<(String, String)>,
    /// Column name and values.
    columns: Vec<(String, Vec<f64>)>,
}

impl RecordParts {
    /// Reads the parts from `header` (a dict: the six numeric keys, `format`, extra keys
    /// as text) and `columns` (a dict of name → bytes of `f64`).
    pub(crate) fn extract(
        header: &Bound<'_, PyDict>,
        columns: &Bound<'_, PyDict>,
    ) -> Result<Self, Fail> {
        // the record format's numeric header keys, in its order (`format` first)
        let keys = &record::HEADER_KEYS[1..];
        let mut numbers = [f64::NAN; 6];
        let mut extra = Vec::new();
        for (k, v) in header.iter() {
            let key: String = k
                .extract()
                .map_err(|_| Fail::Argument("a header key is not a string".into()))?;
            if key == "format" {
                let f: String = v.extract().unwrap_or_default();
                if f != record::FORMAT {
                    return Err(Fail::Argument(format!(
                        "header 'format': expected '{}', found '{f}'",
                        record::FORMAT
                    )));
                }
            } else if let Some(i) = keys.iter().position(|n| *n == key) {
                numbers[i] = v.extract::<f64>().map_err(|_| {
                    Fail::Argument(format!("header '{key}': expected a number, found {v}"))
                })?;
            } else {
                extra.push((key, v.str().map(|s| s.to_string()).unwrap_or_default()));
            }
        }
        if let Some(i) = numbers.iter().position(|v| v.is_nan()) {
            return Err(Fail::Argument(format!(
                "header '{}': required key is missing",
                keys[i]
            )));
        }
        let mut cols = Vec::new();
        for (k, v) in columns.iter() {
            let name: String = k
                .extract()
                .map_err(|_| Fail::Argument("a column name is not a string".into()))?;
            let bytes = v.cast::<PyBytes>().map_err(|_| {
                Fail::Argument(format!("column '{name}': expected bytes of float64"))
            })?;
            cols.push((name, f64s(bytes.as_bytes())));
        }
        Ok(RecordParts {
            numbers,
            extra,
            columns: cols,
        })
    }

    /// The record these parts make, checked as the reader checks a file named `source`:
    /// the text the writer makes of it is parsed back (the same values: the writer's
    /// numbers round-trip), so every error names its line and column in that file.
    pub(crate) fn to_record(&self, source: &str) -> Result<Record, Fail> {
        let n = self.columns.first().map_or(0, |c| c.1.len());
        let arg = Fail::Argument;
        if let Some((name, c)) = self.columns.iter().find(|c| c.1.len() != n) {
            return Err(arg(format!(
                "column '{name}' has {} values, the first column {n}",
                c.len()
            )));
        }
        let find = |name: &str| self.columns.iter().find(|c| c.0 == name).map(|c| &c.1);
        for (name, _) in &self.columns {
            if !REQUIRED_COLUMNS.contains(&name.as_str())
                && !OPTIONAL_COLUMNS.contains(&name.as_str())
            {
                return Err(arg(format!(
                    "column '{name}' is not part of {} (its columns: host-sim/sim/record-format.md)",
                    record::FORMAT
                )));
            }
        }
        let mut req: Vec<&Vec<f64>> = Vec::with_capacity(N_REQUIRED);
        for name in REQUIRED_COLUMNS {
            req.push(
                find(name)
                    .ok_or_else(|| arg(format!("column '{name}': required column is missing")))?,
            );
        }
        let opt = |name: &str, i: usize| find(name).map(|c| c[i]).filter(|v| !v.is_nan());
        let rows = (0..n)
            .map(|i| {
                let mut v = [0.0; N_REQUIRED];
                for (x, c) in v.iter_mut().zip(&req) {
                    *x = c[i];
                }
                RecordRow::from_required(&v, opt("temp_c", i), opt("rate_ref_dps", i))
            })
            .collect();
        let [f0_hz, l0_um, fs_hz, order, lockin_lpf_hz, pump_amp_ref_v] = self.numbers;
        if !(order >= 0.0 && order.fract() == 0.0) {
            return Err(arg(format!(
                "header 'lockin_lpf_order': expected a whole number, found {order}"
            )));
        }
        let rec = Record {
            header: RecordHeader {
                f0_hz,
                l0_um,
                fs_hz,
                lockin_lpf_order: order as usize,
                lockin_lpf_hz,
                pump_amp_ref_v,
                extra: self.extra.clone(),
            },
            rows,
            warnings: Vec::new(),
        };
        let mut text = Vec::new();
        record::write_record_to(&mut text, &rec).map_err(|e| Fail::Run {
            class: "RecordError",
            path: Some(source.to_string()),
            error: e,
        })?;
        let text = String::from_utf8(text).map_err(|e| arg(e.to_string()))?;
        Ok(record::parse_record(&text, source)?)
    }
}

/// `f64` values from their native-endian bytes (a trailing partial value is dropped; the
/// Python side sends whole arrays).
fn f64s(b: &[u8]) -> Vec<f64> {
    b.chunks_exact(8)
        .map(|c| f64::from_ne_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
        .collect()
}

/// The native-endian bytes of `f64` values, as a `bytearray` (numpy reads it writable).
pub(crate) fn bytearray<'py>(
    py: Python<'py>,
    values: impl ExactSizeIterator<Item = f64>,
) -> Bound<'py, PyByteArray> {
    let mut b = Vec::with_capacity(values.len() * 8);
    for v in values {
        b.extend_from_slice(&v.to_ne_bytes());
    }
    PyByteArray::new(py, &b)
}

/// `(header pairs, column pairs, warnings)` of a record (the module's docs).
pub(crate) fn to_python<'py>(py: Python<'py>, rec: &Record) -> PyResult<Bound<'py, PyTuple>> {
    let h = &rec.header;
    let header = PyList::empty(py);
    header.append(("format", record::FORMAT))?;
    for (k, v) in [("f0_hz", h.f0_hz), ("l0_um", h.l0_um), ("fs_hz", h.fs_hz)] {
        header.append((k, v))?;
    }
    header.append(("lockin_lpf_order", h.lockin_lpf_order))?;
    header.append(("lockin_lpf_hz", h.lockin_lpf_hz))?;
    header.append(("pump_amp_ref_v", h.pump_amp_ref_v))?;
    for (k, v) in &h.extra {
        header.append((k, v))?;
    }
    let columns = PyList::empty(py);
    for (i, name) in REQUIRED_COLUMNS.iter().enumerate() {
        let col = bytearray(py, rec.rows.iter().map(|r| r.required()[i]));
        columns.append((*name, col))?;
    }
    type Get = fn(&RecordRow) -> Option<f64>;
    let optional: [(&str, Get); 2] = [
        ("temp_c", |r| r.temp_c),
        ("rate_ref_dps", |r| r.rate_ref_dps),
    ];
    for (name, get) in optional {
        if rec.rows.iter().any(|r| get(r).is_some()) {
            let col = bytearray(py, rec.rows.iter().map(|r| get(r).unwrap_or(f64::NAN)));
            columns.append((name, col))?;
        }
    }
    PyTuple::new(
        py,
        [
            header.into_any(),
            columns.into_any(),
            rec.warnings.clone().into_pyobject(py)?.into_any(),
        ],
    )
}

/// Reads a record file (host-sim/sim/record-format.md): `(header, columns, warnings)`.
#[pyfunction]
pub fn read_record<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyTuple>> {
    let rec = guarded(py, || Ok(record::read_record(&path)?))?;
    to_python(py, &rec)
}

/// Parses a record's text; `source` names it in errors and warnings.
#[pyfunction]
pub fn parse_record_text<'py>(
    py: Python<'py>,
    text: String,
    source: String,
) -> PyResult<Bound<'py, PyTuple>> {
    let rec = guarded(py, || Ok(record::parse_record(&text, &source)?))?;
    to_python(py, &rec)
}

/// Writes a record (header dict, columns dict of bytes) to `path`, after the reader's
/// checks.
#[pyfunction]
pub fn write_record(
    py: Python<'_>,
    header: &Bound<'_, PyDict>,
    columns: &Bound<'_, PyDict>,
    path: PathBuf,
) -> PyResult<()> {
    let parts = RecordParts::extract(header, columns).map_err(|e| e.into_pyerr(py))?;
    let source = path.display().to_string();
    guarded(py, || {
        let rec = parts.to_record(&source)?;
        record::write_record(&path, &rec).map_err(|e| Fail::Run {
            class: "RecordError",
            path: Some(source.clone()),
            error: e,
        })
    })
}
