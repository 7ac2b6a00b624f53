//! Errors across the boundary: every failure becomes an exception of `paragyro._errors`
//! (defined in Python so that they pickle with their attributes and can be caught as
//! `paragyro.ParagyroError`), with the message the CLI prints and, for a scenario or a
//! record, the file, line, column and context of [`LocatedError`].

use std::fmt::Debug;
use std::panic::{AssertUnwindSafe, catch_unwind};

use paragyro_simulator::located::LocatedError;
use paragyro_simulator::record::RecordError;
use paragyro_simulator::scenario::ScenarioError;
use pyo3::prelude::*;

/// What went wrong, before it becomes a Python exception.
#[derive(Debug)]
pub(crate) enum Fail {
    /// A record that cannot be read (or written): `RecordError`.
    Record(RecordError),
    /// A scenario that cannot be loaded: `ScenarioError`.
    Scenario(ScenarioError),
    /// An argument the CLI's parser would refuse: `ArgumentError` (also a `ValueError`).
    Argument(String),
    /// A failed run: the exception class (`SimulationError`, `DiagnosisError`, …), the
    /// path it concerns, and the error with its causes (printed as the CLI does, `{:#}`).
    Run {
        class: &'static str,
        path: Option<String>,
        error: anyhow::Error,
    },
    /// A panic caught at the boundary: `InternalError`.
    Panic(String),
}

impl Fail {
    /// A failed run of `class`.
    pub(crate) fn run(class: &'static str, error: anyhow::Error) -> Self {
        Fail::Run {
            class,
            path: None,
            error,
        }
    }

    /// The Python exception.
    pub(crate) fn into_pyerr(self, py: Python<'_>) -> PyErr {
        match self {
            Fail::Record(e) => located(py, "RecordError", &e),
            Fail::Scenario(e) => located(py, "ScenarioError", &e),
            Fail::Argument(m) => exception(py, "ArgumentError", Fields::message(m)),
            Fail::Run { class, path, error } => exception(
                py,
                class,
                Fields {
                    path,
                    ..Fields::message(format!("{error:#}"))
                },
            ),
            Fail::Panic(m) => exception(
                py,
                "InternalError",
                Fields::message(format!("internal error (please report): {m}")),
            ),
        }
    }
}

impl From<RecordError> for Fail {
    fn from(e: RecordError) -> Self {
        Fail::Record(e)
    }
}

impl From<ScenarioError> for Fail {
    fn from(e: ScenarioError) -> Self {
        Fail::Scenario(e)
    }
}

/// The attributes of a `paragyro.ParagyroError`.
struct Fields {
    message: String,
    path: Option<String>,
    line: Option<usize>,
    column: Option<usize>,
    context: Option<String>,
    kind: Option<String>,
}

impl Fields {
    fn message(message: String) -> Self {
        Fields {
            message,
            path: None,
            line: None,
            column: None,
            context: None,
            kind: None,
        }
    }
}

/// A located error as `class`: the CLI's message, and its parts as attributes.
fn located<K: Debug>(py: Python<'_>, class: &str, e: &LocatedError<K>) -> PyErr {
    exception(
        py,
        class,
        Fields {
            message: e.to_string(),
            path: (!e.file.is_empty()).then(|| e.file.clone()),
            line: e.line,
            column: e.column,
            context: e.context.clone(),
            kind: Some(snake(&format!("{:?}", e.kind))),
        },
    )
}

/// `UnknownScenario` → `unknown_scenario`.
fn snake(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 4);
    for (i, c) in s.chars().enumerate() {
        if c.is_uppercase() {
            if i > 0 {
                out.push('_');
            }
            out.extend(c.to_lowercase());
        } else {
            out.push(c);
        }
    }
    out
}

/// An instance of `paragyro._errors.<class>` (a `RuntimeError` if that module cannot be
/// imported, which only a broken install does).
fn exception(py: Python<'_>, class: &str, f: Fields) -> PyErr {
    let made = py
        .import("paragyro._errors")
        .and_then(|m| m.getattr(class))
        .and_then(|c| {
            c.call1((
                f.message.clone(),
                f.path,
                f.line,
                f.column,
                f.context,
                f.kind,
            ))
        });
    match made {
        Ok(obj) => PyErr::from_value(obj),
        Err(e) => pyo3::exceptions::PyRuntimeError::new_err(format!(
            "{} (and paragyro._errors.{class} could not be raised: {e})",
            f.message
        )),
    }
}

/// Runs `f` with the interpreter detached (other Python threads run meanwhile), a panic
/// caught and turned into [`Fail::Panic`], and the failure into its exception.
pub(crate) fn guarded<T, F>(py: Python<'_>, f: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce() -> Result<T, Fail> + Send,
{
    py.detach(|| {
        catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|p| {
            let msg = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a panic without a message".into());
            Err(Fail::Panic(msg))
        })
    })
    .map_err(|e| e.into_pyerr(py))
}

/// Panics inside the guard (for the tests: a panic must reach Python as
/// `paragyro.InternalError`, never abort the interpreter).
#[pyfunction]
pub fn _panic_inside_the_guard(py: Python<'_>, message: String) -> PyResult<()> {
    guarded(py, || -> Result<(), Fail> { panic!("{message}") })
}
