//! `paragyro._native`: the Rust half of the Python package `paragyro` (host-sim/py/README.md).
//!
//! Thin bindings over the workspace's library crates, so that Python gets what the CLI
//! computes, bit for bit:
//!
//! * records: `paragyro_simulator::record` (read, write, the reader's checks and errors);
//! * simulation: `write_simulated_record` / `simulate_record_with`, as `paragyro-sim record`;
//! * the core open-loop on a record: `record::replay` with `config_for`, as `paragyro-sim replay`;
//! * the diagnosis: `paragyro_diagnose::diagnose`, as `paragyro-sim diagnose`;
//! * the rate-response datasheet: `rate_response::report` / `run_all`, as `paragyro-sim rate-response`;
//! * a lot's row: `paragyro_lot::diagnose_path`, as the CLI's lot (one task of `paragyro.lot`).
//!
//! Columns cross the boundary as native-endian `f64` bytes (numpy's `frombuffer` on the
//! Python side), reports as their serde JSON (report.json's exact text, parsed by Python).
//! Every call runs with the interpreter detached and under `catch_unwind`: an error is a
//! Python exception of `paragyro._errors` (`RecordError`, `ScenarioError`, … with the file,
//! line and column the CLI prints), a panic is a `paragyro.InternalError`, never an abort.

mod diag;
mod errors;
mod lot;
mod record;
mod run;

use pyo3::prelude::*;

/// The native module of the `paragyro` package (use `paragyro`, not this module).
#[pymodule(name = "_native")]
mod native {
    #[pymodule_export]
    use super::diag::{NativeDiagnosis, diagnose_path, diagnose_record};
    #[pymodule_export]
    use super::errors::_panic_inside_the_guard;
    #[pymodule_export]
    use super::lot::{check_scenario, lot_columns, lot_row};
    #[pymodule_export]
    use super::record::{parse_record_text, read_record, write_record};
    #[pymodule_export]
    use super::run::{datasheet, effect_names, run_core, simulate};

    /// The version of the workspace crates this module was built from.
    #[pymodule_export]
    const VERSION: &str = env!("CARGO_PKG_VERSION");
}
