//! A lot's row: `paragyro_lot::diagnose_path`, the function behind the CLI's lot, so that
//! the Python lot (`paragyro.lot`, on Dask) and the Rust one give the same rows.

use std::path::PathBuf;

use paragyro_lot::{Kind, LotOptions, columns, diagnose_path};
use pyo3::prelude::*;

use crate::errors::{Fail, guarded};

/// The row's columns in file order, with their type (`str`, `f64`, `i64`).
#[pyfunction]
pub fn lot_columns() -> Vec<(String, &'static str)> {
    columns()
        .into_iter()
        .map(|c| {
            let kind = match c.kind {
                Kind::Str => "str",
                Kind::F64 => "f64",
                Kind::I64 => "i64",
            };
            (c.name, kind)
        })
        .collect()
}

/// One device's row (`paragyro_lot::LotRow`) as its JSON object: the record read and
/// diagnosed with the CLI's options (`model`, `resimulate`, `confirm_runs`), its report
/// written into `reports/<stem>/` when `reports` is given. A record that cannot be read or
/// diagnosed is a row with its `error`; only a model that cannot be loaded raises.
#[pyfunction]
#[pyo3(signature = (path, model=None, resimulate=true, confirm_runs=None, reports=None))]
pub fn lot_row(
    py: Python<'_>,
    path: PathBuf,
    model: Option<String>,
    resimulate: bool,
    confirm_runs: Option<usize>,
    reports: Option<PathBuf>,
) -> PyResult<String> {
    guarded(py, || {
        let opts = LotOptions {
            diagnose: crate::diag::options(model.as_deref(), resimulate, confirm_runs)?,
            reports,
            threads: 1,
        };
        let row = diagnose_path(&path, &opts);
        serde_json::to_string(&row).map_err(|e| Fail::run("DiagnosisError", e.into()))
    })
}

/// Loads a scenario (a built-in name or a TOML path) and drops it: a `ScenarioError` now,
/// not in every task of a lot.
#[pyfunction]
pub fn check_scenario(py: Python<'_>, name: String) -> PyResult<()> {
    guarded(py, || {
        paragyro_simulator::scenario::Scenario::load(&name)?;
        Ok(())
    })
}
