//! One file per subcommand: its arguments (`Args`, clap derive) and its `exec`. What they
//! share is here: the exit codes, the error-with-exit-code type, writing to stdout, loading
//! scenarios and records, and the progress bar of long runs.

pub mod averaged;
pub mod blind;
pub mod calibrate;
pub mod check;
pub mod demo;
pub mod diagnose;
pub mod effects;
pub mod faults;
pub mod list;
pub mod lot;
pub mod paper001;
pub mod paper_claims;
pub mod paper_raw;
pub mod rate_response;
pub mod record;
pub mod replay;
pub mod results;
pub mod run;
pub mod soak;
pub mod thermal;

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use paragyro_simulator::record::{Record, read_record};
use paragyro_simulator::report;
use paragyro_simulator::runner::{self, Precision, RunOptions};
use paragyro_simulator::scenario::Scenario;
use paragyro_simulator::trace::RunResult;

/// Exit code of a failed run or output.
pub const EXIT_RUN: u8 = 1;
/// Exit code of a scenario or record that cannot be loaded.
pub const EXIT_LOAD: u8 = 2;
/// Runs shorter than this (simulated seconds, main + twin) get no progress bar.
const PROGRESS_MIN_SIM_S: f64 = 2.0;

/// Where a command writes and whether it may draw a progress bar.
pub struct Ctx<'a> {
    /// Standard output (a `Vec<u8>` in the tests).
    pub out: &'a mut dyn Write,
    /// stderr is a terminal: progress bars may be drawn there.
    pub progress_ok: bool,
}

impl Ctx<'_> {
    /// Writes to stdout. A closed pipe (`paragyro-sim demo | head`) ends the command
    /// quietly; other write errors are errors (exit 1); never a panic.
    pub fn say(&mut self, text: &str) -> Result<(), Failure> {
        match self
            .out
            .write_all(text.as_bytes())
            .and_then(|()| self.out.flush())
        {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Err(Failure {
                code: 0,
                error: anyhow::Error::new(e),
            }),
            Err(e) => Err(Failure {
                code: EXIT_RUN,
                error: anyhow::Error::new(e).context("cannot write to stdout"),
            }),
        }
    }
}

/// A line on stderr (progress and warnings; never fails the command).
pub fn note(text: &str) {
    let _ = writeln!(std::io::stderr(), "{text}");
}

/// An error with its exit code.
pub struct Failure {
    /// The process exit code (0: stdout was closed, nothing left to say).
    pub code: u8,
    /// What went wrong, with its causes.
    pub error: anyhow::Error,
}

/// `map_err(fail(EXIT_RUN))`: an error with that exit code.
pub fn fail(code: u8) -> impl FnOnce(anyhow::Error) -> Failure {
    move |error| Failure { code, error }
}

/// Precision of the core, as the command line spells it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PrecisionArg {
    /// `Estimator<f32>`, as on the chip.
    F32,
    /// `Estimator<f64>`, the host reference.
    F64,
}

impl From<PrecisionArg> for Precision {
    fn from(p: PrecisionArg) -> Self {
        match p {
            PrecisionArg::F32 => Precision::F32,
            PrecisionArg::F64 => Precision::F64,
        }
    }
}

/// Loads a built-in scenario or a scenario file (exit 2 on error).
pub fn load(name_or_path: &str) -> Result<Scenario, Failure> {
    Scenario::load(name_or_path).map_err(|e| Failure {
        code: EXIT_LOAD,
        error: anyhow::Error::new(e),
    })
}

/// Reads a record; its warnings go to stderr, its error exits with EXIT_LOAD.
pub fn read_record_warn(file: &Path) -> Result<Record, Failure> {
    let rec = read_record(file).map_err(|e| Failure {
        code: EXIT_LOAD,
        error: anyhow::Error::new(e),
    })?;
    for w in &rec.warnings {
        note(&format!("warning: {w}"));
    }
    Ok(rec)
}

/// Writes a run's outputs (summary, traces, plots) into `dir`.
pub fn write_run(dir: &Path, result: &RunResult) -> Result<Vec<PathBuf>, Failure> {
    report::write_outputs(dir, result)
        .with_context(|| format!("cannot write the outputs to {}", dir.display()))
        .map_err(fail(EXIT_RUN))
}

/// Writes a report as `DIR/STEM.json` (pretty, serde) and its Markdown table as
/// `DIR/STEM.md`, creating `dir`; says where, with the table (`faults`, `soak`).
pub fn write_report<T: serde::Serialize>(
    ctx: &mut Ctx,
    dir: &Path,
    stem: &str,
    rep: &T,
    table: &str,
) -> Result<(), Failure> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create {}", dir.display()))
        .map_err(fail(EXIT_RUN))?;
    let json = dir.join(format!("{stem}.json"));
    let md = dir.join(format!("{stem}.md"));
    let text = serde_json::to_string_pretty(rep)
        .context("cannot serialise the report")
        .map_err(fail(EXIT_RUN))?;
    std::fs::write(&json, text + "\n")
        .with_context(|| format!("cannot write {}", json.display()))
        .map_err(fail(EXIT_RUN))?;
    std::fs::write(&md, table)
        .with_context(|| format!("cannot write {}", md.display()))
        .map_err(fail(EXIT_RUN))?;
    ctx.say(&format!(
        "Wrote {} and {}\n{table}",
        json.display(),
        md.display()
    ))
}

/// "  path\n" per file.
pub fn file_list(files: &[PathBuf]) -> String {
    files
        .iter()
        .map(|f| format!("  {}\n", f.display()))
        .collect()
}

/// Runs with an indicatif bar on stderr (only when `show` and the run is long enough).
pub fn run_with_progress(
    sc: &Scenario,
    opts: &RunOptions,
    show: bool,
) -> Result<RunResult, Failure> {
    let sim_s = sc.duration_s * if sc.twin.is_some() { 2.0 } else { 1.0 };
    let bar = if show && sim_s >= PROGRESS_MIN_SIM_S {
        let bar = ProgressBar::with_draw_target(Some(1000), ProgressDrawTarget::stderr());
        let style = ProgressStyle::with_template(
            "{msg} [{bar:40.cyan/blue}] {percent:>3}%  {elapsed_precise} (eta {eta})",
        )
        .map(|s| s.progress_chars("=> "))
        .unwrap_or_else(|_| ProgressStyle::default_bar());
        bar.set_style(style);
        bar.set_message(format!(
            "{} ({})",
            sc.name,
            match opts.precision {
                Precision::F32 => "f32",
                Precision::F64 => "f64",
            }
        ));
        bar
    } else {
        ProgressBar::hidden()
    };
    let mut progress = |f: f64| {
        if f.is_finite() {
            bar.set_position((f.clamp(0.0, 1.0) * 1000.0).round() as u64);
        }
    };
    let result = runner::run(sc, opts, &mut progress);
    bar.finish_and_clear();
    result
        .with_context(|| format!("the run of scenario '{}' failed", sc.name))
        .map_err(fail(EXIT_RUN))
}
