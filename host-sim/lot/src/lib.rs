//! paragyro-lot: the diagnosis of a lot of records (host-sim/lot/README.md).
//!
//! Each record (host-sim/sim/record-format.md) is read with the CLI's reader and diagnosed
//! with [`paragyro_diagnose::diagnose::diagnose`]; the result is one flat [`LotRow`] per
//! device, its values report.json's own. A record that cannot be read or diagnosed (or
//! whose diagnosis panics) is a row with its `error`, never dropped. The rows go to a
//! Parquet file ([`write_parquet`], [`read_parquet`]) and to the lot report against a
//! [`Spec`] ([`report()`]: yield, the deviations' distributions, outliers, errors).
//!
//! ```no_run
//! use paragyro_lot::{LotOptions, Spec, diagnose_lot, find_records, report, write_parquet};
//! # fn main() -> anyhow::Result<()> {
//! let paths = find_records("lot-42".as_ref())?;
//! let opts = LotOptions { reports: Some("out/reports".into()), ..LotOptions::default() };
//! let rows = diagnose_lot(&paths, &opts, &|done, total, _row| eprintln!("{done}/{total}"))?;
//! write_parquet("out/lot.parquet".as_ref(), &rows)?;
//! report(&rows, &Spec::load("spec.toml".as_ref())?, "out/report".as_ref())?;
//! # Ok(())
//! # }
//! ```

pub mod parquet_io;
mod plot;
pub mod report;
pub mod row;
pub mod spec;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{Context, Result};
use paragyro_diagnose::diagnose::{Options, diagnose, write_report};
use paragyro_simulator::record::read_record;
use rayon::prelude::*;

pub use parquet_io::{read_parquet, write_parquet};
pub use report::{LotSummary, report};
pub use row::{Column, Kind, LotRow, ParamValues, columns};
pub use spec::{Deviation, Judgement, Limit, Spec, Yield};

/// How to diagnose a lot (default: the diagnosis's defaults, no reports, one thread per
/// core).
#[derive(Clone, Debug, Default)]
pub struct LotOptions {
    /// The diagnosis's options (model, re-simulation, confirmation runs).
    pub diagnose: Options,
    /// Write each device's report (report.md, report.json, plots) into `DIR/<record stem>/`.
    pub reports: Option<PathBuf>,
    /// Records diagnosed at once (rayon threads); 0: rayon's default (the cores).
    pub threads: usize,
}

/// The record files of a lot folder, sorted by name: every `*.csv` (any case) directly in
/// `dir`, not its subfolders; a simulated record's truth (`FILE.truth.json`) and any other
/// `*.truth.*` file is skipped.
pub fn find_records(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).with_context(|| format!("cannot list {}", dir.display()))? {
        let p = e
            .with_context(|| format!("cannot list {}", dir.display()))?
            .path();
        let name = p
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned());
        let csv = p.extension().is_some_and(|x| x.eq_ignore_ascii_case("csv"));
        if csv && !name.contains(".truth.") && p.is_file() {
            out.push(p);
        }
    }
    out.sort();
    Ok(out)
}

/// The folder of a record's report under `reports`: its file stem (`dev-007.csv` →
/// `reports/dev-007`).
pub fn report_dir_of(reports: &Path, record: &Path) -> PathBuf {
    let stem = record
        .file_stem()
        .map_or("record".into(), |s| s.to_string_lossy().into_owned());
    reports.join(stem)
}

/// Reads and diagnoses one record (and writes its report when `opts.reports` is set). Never
/// fails: a record that cannot be read or diagnosed, a report that cannot be written or a
/// panic of the diagnosis is the row's `error` (with the path).
pub fn diagnose_path(path: &Path, opts: &LotOptions) -> LotRow {
    let name = path
        .file_name()
        .map_or(String::new(), |n| n.to_string_lossy().into_owned());
    let shown = path.display().to_string();
    match caught(|| diagnose_inner(path, &name, opts)) {
        Ok(Ok(row)) => row,
        Ok(Err(e)) => LotRow::failed(&name, &shown, format!("{e:#}")),
        Err(what) => LotRow::failed(
            &name,
            &shown,
            format!("internal error diagnosing {shown}: {what}"),
        ),
    }
}

/// `f()`, or its panic's message (a `&str` or `String` payload; "unknown panic" else).
fn caught<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|panic| {
        panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into())
    })
}

fn diagnose_inner(path: &Path, name: &str, opts: &LotOptions) -> Result<LotRow> {
    let shown = path.display().to_string();
    let rec = read_record(path).map_err(anyhow::Error::new)?;
    let d = diagnose(&rec, &opts.diagnose).with_context(|| format!("cannot diagnose {shown}"))?;
    let mut row = LotRow::from_report(
        name,
        &shown,
        &d.report,
        rec.duration_s(),
        rec.warnings.len(),
    );
    if let Some(reports) = &opts.reports {
        let dir = report_dir_of(reports, path);
        match write_report(&dir, &d, name) {
            Ok(_) => row.report_dir = Some(dir.display().to_string()),
            Err(e) => {
                row.error = Some(format!(
                    "{shown}: diagnosed, but its report was not written: {e:#}"
                ))
            }
        }
    }
    Ok(row)
}

/// Diagnoses `paths` on `opts.threads` threads; the rows in the order of `paths`.
/// `progress(done, total, row)` is called as each record finishes (from the worker
/// threads, in completion order). Fails only when the thread pool cannot be made.
pub fn diagnose_lot(
    paths: &[PathBuf],
    opts: &LotOptions,
    progress: &(dyn Fn(usize, usize, &LotRow) + Sync),
) -> Result<Vec<LotRow>> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads)
        .build()
        .context("cannot start the diagnosis threads")?;
    let done = AtomicUsize::new(0);
    let total = paths.len();
    Ok(pool.install(|| {
        paths
            .par_iter()
            .with_max_len(1)
            .map(|p| {
                let row = diagnose_path(p, opts);
                progress(done.fetch_add(1, Ordering::Relaxed) + 1, total, &row);
                row
            })
            .collect()
    }))
}

#[cfg(test)]
mod tests {
    use super::caught;

    /// A panic is its message, whatever its payload; the panic does not escape.
    #[test]
    fn a_panic_becomes_its_message() {
        assert_eq!(caught(|| 7), Ok(7));
        assert_eq!(caught(|| -> u8 { panic!("boom") }), Err("boom".into()));
        let n = 3;
        assert_eq!(
            caught(|| -> u8 { panic!("boom {n}") }),
            Err("boom 3".into())
        );
        assert_eq!(
            caught(|| -> u8 { std::panic::panic_any(5u32) }),
            Err("unknown panic".into())
        );
    }
}
