//! `paragyro-sim run <scenario|file.toml> --out DIR`: run a scenario, write summary.json,
//! trace.csv and the plots. `run paper-raw` is the paper's own estimator (not a scenario of
//! the simulated gyro), kept under this name because the docs use it.

use std::path::PathBuf;

use super::{Ctx, Failure, PrecisionArg, file_list, load, run_with_progress, write_run};
use paragyro_simulator::report;
use paragyro_simulator::runner::RunOptions;

/// Run a scenario; write summary.json, trace.csv and the plots.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Built-in scenario name or path to a scenario TOML file.
    pub scenario: String,
    /// Output directory (created if needed).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Override the scenario's noise seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Precision of the core.
    #[arg(long, value_enum, default_value_t = PrecisionArg::F32)]
    pub precision: PrecisionArg,
    /// Override the scenario's `[estimator] rate_walk_dps`: the slow RLS's rate as a random
    /// walk of this standard deviation per sample, °/s (0: a constant rate).
    #[arg(long, value_name = "DPS", value_parser = non_negative)]
    pub rate_walk_dps: Option<f64>,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Runs the scenario and writes its outputs.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    if a.scenario == "paper-raw" {
        return super::paper_raw::exec(super::paper_raw::Args { out: a.out }, ctx);
    }
    let mut sc = load(&a.scenario)?;
    if let Some(w) = a.rate_walk_dps {
        sc.estimator.rate_walk_dps = Some(w);
    }
    let opts = RunOptions {
        precision: a.precision.into(),
        seed: a.seed,
    };
    let result = run_with_progress(&sc, &opts, ctx.progress_ok && !a.quiet)?;
    let files = write_run(&a.out, &result)?;
    let mut text = format!("Wrote {} files to {}:\n", files.len(), a.out.display());
    text.push_str(&file_list(&files));
    text.push_str(&report::short_summary(&result));
    ctx.say(&text)
}

/// A finite number ≥ 0.
fn non_negative(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        Ok(v) => Err(format!("must be finite and ≥ 0 (got {v})")),
        Err(e) => Err(e.to_string()),
    }
}
