//! The diagnosis, as `paragyro-sim diagnose FILE.csv [--model M] [--no-resim]
//! [--confirm-runs N]`: [`NativeDiagnosis`] holds the typed result (report.json and the
//! plots' data), so that `write_report` writes exactly what the CLI writes.

use std::path::PathBuf;

use anyhow::Context;
use paragyro_diagnose::diagnose::{
    Diagnosis, Model, Options, diagnose, to_json_sorted, write_report,
};
use paragyro_simulator::record::{self, Record};
use paragyro_simulator::scenario::Scenario;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::{Fail, guarded};
use crate::record::RecordParts;

/// A finished diagnosis (Python's `paragyro.Diagnosis` wraps it).
#[pyclass(frozen, module = "paragyro._native")]
pub struct NativeDiagnosis {
    d: Diagnosis,
    /// The record's file name (report.md's title).
    name: String,
}

#[pymethods]
impl NativeDiagnosis {
    /// report.json's text (serde, keys sorted, as `paragyro-sim diagnose` writes it).
    fn report_json(&self, py: Python<'_>) -> PyResult<String> {
        guarded(py, || {
            to_json_sorted(&self.d.report)
                .map_err(|e| Fail::run("DiagnosisError", anyhow::Error::new(e)))
        })
    }

    /// report.md's text.
    fn report_markdown(&self) -> String {
        self.d.report.markdown(&self.name)
    }

    /// Writes report.json, report.md and the plots into `dir` (created if needed); returns
    /// the files written.
    fn write_report(&self, py: Python<'_>, dir: PathBuf) -> PyResult<Vec<String>> {
        guarded(py, || {
            let files = write_report(&dir, &self.d, &self.name)
                .map_err(|e| Fail::run("DiagnosisError", e))?;
            Ok(files.iter().map(|f| f.display().to_string()).collect())
        })
    }
}

/// The diagnosis options of the CLI's flags (`model`: a built-in scenario or a TOML).
pub(crate) fn options(
    model: Option<&str>,
    resimulate: bool,
    confirm_runs: Option<usize>,
) -> Result<Options, Fail> {
    let mut opts = Options {
        resimulate,
        confirm_runs,
        ..Default::default()
    };
    if let Some(m) = model {
        opts.model = Model::from_scenario(&Scenario::load(m)?);
    }
    Ok(opts)
}

/// Diagnoses `rec` (named `source` in errors) with `opts`.
fn run(rec: &Record, source: &str, opts: &Options, name: String) -> Result<NativeDiagnosis, Fail> {
    let d = diagnose(rec, opts)
        .with_context(|| format!("cannot diagnose {source}"))
        .map_err(|e| Fail::Run {
            class: "DiagnosisError",
            path: Some(source.to_string()),
            error: e,
        })?;
    Ok(NativeDiagnosis { d, name })
}

/// Diagnoses a record file, as `paragyro-sim diagnose PATH`; returns the diagnosis and the
/// reader's warnings.
#[pyfunction]
#[pyo3(signature = (path, model=None, resimulate=true, confirm_runs=None))]
pub fn diagnose_path(
    py: Python<'_>,
    path: PathBuf,
    model: Option<String>,
    resimulate: bool,
    confirm_runs: Option<usize>,
) -> PyResult<(NativeDiagnosis, Vec<String>)> {
    guarded(py, || {
        let opts = options(model.as_deref(), resimulate, confirm_runs)?;
        let rec = record::read_record(&path)?;
        let name = path
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned());
        let d = run(&rec, &path.display().to_string(), &opts, name)?;
        Ok((d, rec.warnings))
    })
}

/// Diagnoses a record handed over by Python (`paragyro.Record`), named `name`.
#[pyfunction]
#[pyo3(signature = (header, columns, name, model=None, resimulate=true, confirm_runs=None))]
pub fn diagnose_record(
    py: Python<'_>,
    header: &Bound<'_, PyDict>,
    columns: &Bound<'_, PyDict>,
    name: String,
    model: Option<String>,
    resimulate: bool,
    confirm_runs: Option<usize>,
) -> PyResult<NativeDiagnosis> {
    let parts = RecordParts::extract(header, columns).map_err(|e| e.into_pyerr(py))?;
    guarded(py, || {
        let opts = options(model.as_deref(), resimulate, confirm_runs)?;
        let rec = parts.to_record(&name)?;
        run(&rec, &name, &opts, name.clone())
    })
}
