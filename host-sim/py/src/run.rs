//! Simulation, the core on a record and the rate-response datasheet: what
//! `paragyro-sim record`, `replay` and `rate-response` compute, through the same library
//! functions.

use std::path::PathBuf;

use anyhow::Context;
use paragyro_simulator::effects::{Effect, EffectSpec};
use paragyro_simulator::rate_response;
use paragyro_simulator::record::{
    self, RecordOptions, config_for, replay, replay_csv_header, simulate_record_with,
    write_simulated_record,
};
use paragyro_simulator::runner::Precision;
use paragyro_simulator::scenario::Scenario;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};

use crate::errors::{Fail, guarded};
use crate::record::{RecordParts, bytearray, to_python};

/// `"f32"` / `"f64"` as the CLI's `--precision`.
pub(crate) fn precision(p: &str) -> Result<Precision, Fail> {
    match p {
        "f32" => Ok(Precision::F32),
        "f64" => Ok(Precision::F64),
        other => Err(Fail::Argument(format!(
            "precision: expected 'f32' or 'f64', found '{other}'"
        ))),
    }
}

/// The names of the effects the simulator can add, with their units and whether the
/// diagnosis's library knows them: `[(name, unit, in_library)]`.
#[pyfunction]
pub fn effect_names() -> Vec<(&'static str, &'static str, bool)> {
    Effect::ALL
        .iter()
        .map(|e| (e.name(), e.unit(), e.in_library()))
        .collect()
}

/// A simulated record of `scenario` (a built-in name or a TOML path), as
/// `paragyro-sim record SCENARIO [--seed N] [--effect NAME=SIZE]… [--temp START:RISE]
/// [--rate-table]`, with the scenario's duration replaced by `duration_s` when given.
/// With `out`, the record and its truth are written there as the CLI writes them.
/// Returns `(record parts, truth JSON, files written)`.
#[pyfunction]
#[pyo3(signature = (scenario, seed=None, effects=Vec::new(), temp=None, rate_table=false, duration_s=None, out=None))]
#[allow(clippy::too_many_arguments)]
pub fn simulate<'py>(
    py: Python<'py>,
    scenario: String,
    seed: Option<u64>,
    effects: Vec<String>,
    temp: Option<(f64, f64)>,
    rate_table: bool,
    duration_s: Option<f64>,
    out: Option<PathBuf>,
) -> PyResult<Bound<'py, PyTuple>> {
    let (rec, truth, files) = guarded(py, || {
        let mut sc = Scenario::load(&scenario)?;
        if let Some(d) = duration_s {
            if !(d.is_finite() && d > 0.0) {
                return Err(Fail::Argument(format!(
                    "duration_s must be finite and > 0 (got {d})"
                )));
            }
            sc.duration_s = d;
        }
        if let Some((a, b)) = temp
            && !(a.is_finite() && b.is_finite())
        {
            return Err(Fail::Argument(format!(
                "temperature ({a}, {b}): START_C and RISE_K must be finite"
            )));
        }
        let effects = effects
            .iter()
            .map(|e| e.parse::<EffectSpec>())
            .collect::<Result<Vec<_>, _>>()
            .map_err(Fail::Argument)?;
        let opts = RecordOptions {
            seed,
            effects,
            temp,
            rate_table,
        };
        let failed = |e: anyhow::Error| {
            Fail::run(
                "SimulationError",
                e.context(format!("cannot record scenario '{}'", sc.name)),
            )
        };
        match &out {
            Some(path) => {
                let (files, rec) =
                    write_simulated_record(&sc, path, &opts, &mut |_| {}).map_err(failed)?;
                let truth = std::fs::read_to_string(&files.truth)
                    .with_context(|| format!("cannot read back {}", files.truth.display()))
                    .map_err(failed)?;
                Ok((rec, truth, vec![files.csv, files.truth]))
            }
            None => {
                let (rec, truth) = simulate_record_with(&sc, &opts, &mut |_| {}).map_err(failed)?;
                let truth = paragyro_simulator::summary::to_json_pretty(&truth)
                    .map_err(|e| failed(e.into()))?;
                Ok((rec, truth, Vec::new()))
            }
        }
    })?;
    let files: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    PyTuple::new(
        py,
        [
            to_python(py, &rec)?.into_any(),
            truth.into_pyobject(py)?.into_any(),
            files.into_pyobject(py)?.into_any(),
        ],
    )
}

/// The core open-loop on a record, as `paragyro-sim replay` (its configuration
/// `record::config_for`, precision `f32` or `f64`): the columns of its `estimates.csv`, in
/// order, as `(name, bytearray of f64)` (the counters and bits are whole numbers).
#[pyfunction]
#[pyo3(signature = (header, columns, source, precision="f32"))]
pub fn run_core<'py>(
    py: Python<'py>,
    header: &Bound<'_, PyDict>,
    columns: &Bound<'_, PyDict>,
    source: String,
    precision: &str,
) -> PyResult<Bound<'py, PyList>> {
    let parts = RecordParts::extract(header, columns).map_err(|e| e.into_pyerr(py))?;
    let p = self::precision(precision).map_err(|e| e.into_pyerr(py))?;
    let rows = guarded(py, || {
        let rec = parts.to_record(&source)?;
        let cfg = config_for(&rec);
        match p {
            Precision::F32 => replay::<f32>(&rec, &cfg),
            Precision::F64 => replay::<f64>(&rec, &cfg),
        }
        .with_context(|| format!("replaying {source}"))
        .map_err(|e| Fail::run("RunError", e))
    })?;
    let out = PyList::empty(py);
    let col = |f: &dyn Fn(&record::ReplayRow) -> f64| bytearray(py, rows.iter().map(f));
    for (i, name) in replay_csv_header().iter().enumerate() {
        let values = match i {
            0 => col(&|r| r.t_s),
            1 => col(&|r| r.pump_hz),
            2 => col(&|r| r.pump_scale),
            3..=10 => col(&|r| r.theta_drive[i - 3]),
            11..=16 => col(&|r| r.theta_sense[i - 11]),
            17 => col(&|r| r.rate_dps),
            18 => col(&|r| r.wy2),
            19 => col(&|r| f64::from(r.health)),
            20 => col(&|r| f64::from(r.events)),
            21 => col(&|r| r.pump_hz_cmd),
            22 => col(&|r| f64::from(r.counters.updates)),
            23 => col(&|r| f64::from(r.counters.bad_samples)),
            24 => col(&|r| f64::from(r.counters.resets_drive)),
            25 => col(&|r| f64::from(r.counters.resets_sense)),
            _ => {
                return Err(
                    Fail::Panic(format!("replay column {name} has no value")).into_pyerr(py)
                );
            }
        };
        out.append((name, values))?;
    }
    Ok(out)
}

/// The rate channel's datasheet on the simulated device, as `paragyro-sim rate-response
/// [--seed N] [--precision P] [--allan-s S] [--allan-zero-memory-s S] [--allan-settle-s S] [--allan-warm-start]`: `(report.json's
/// text, report.md's table, files written)`; with `out`, report.json, report.md and the
/// PNGs are written there as the CLI writes them.
#[pyfunction]
// the Python signature's keyword arguments, one each (the CLI's flags)
#[allow(clippy::too_many_arguments)]
#[pyo3(name = "rate_response", signature = (seed=1, precision="f32", allan_s=None, allan_zero_memory_s=None, allan_forgetting=None, allan_settle_s=rate_response::ALLAN_SETTLE_S, allan_warm_start=false, out=None))]
pub fn datasheet(
    py: Python<'_>,
    seed: u64,
    precision: &str,
    allan_s: Option<f64>,
    allan_zero_memory_s: Option<f64>,
    allan_forgetting: Option<f64>,
    allan_settle_s: f64,
    allan_warm_start: bool,
    out: Option<PathBuf>,
) -> PyResult<(String, String, Vec<String>)> {
    let p = self::precision(precision).map_err(|e| e.into_pyerr(py))?;
    guarded(py, || {
        if let Some(s) = allan_s
            && !(s.is_finite() && s >= 10.0)
        {
            return Err(Fail::Argument(format!(
                "allan_s must be at least 10 s (got {s})"
            )));
        }
        if let Some(m) = allan_zero_memory_s
            && !(m.is_finite() && m >= 0.0)
        {
            return Err(Fail::Argument(format!(
                "allan_zero_memory_s must be finite and >= 0 (got {m})"
            )));
        }
        if let Some(l) = allan_forgetting
            && !rate_response::forgetting_ok(l)
        {
            return Err(Fail::Argument(format!(
                "allan_forgetting must be in (0, 1] (got {l})"
            )));
        }
        if !(allan_settle_s.is_finite() && allan_settle_s >= 0.0) {
            return Err(Fail::Argument(format!(
                "allan_settle_s must be finite and >= 0 (got {allan_settle_s})"
            )));
        }
        let o = rate_response::Options {
            precision: p,
            seed,
            allan_s,
            allan_zero_memory_s,
            allan_forgetting,
            allan_settle_s,
            allan_warm_start,
        };
        let failed = |e: anyhow::Error| Fail::run("RunError", e);
        let (report, files) = match &out {
            Some(dir) => rate_response::run_all(&o, dir).map_err(failed)?,
            None => (rate_response::report(&o).map_err(failed)?, Vec::new()),
        };
        let json = serde_json::to_string(&report).map_err(|e| failed(e.into()))?;
        Ok((json, rate_response::markdown(&report), files))
    })
}
