//! `paragyro-sim demo`: the main job. The built-in `drift-retune` scenario (simulated gyro
//! → estimator → drift → detection → retune), its summary, and its data and plots.

use std::path::PathBuf;

use super::{Ctx, Failure, PrecisionArg, file_list, load, run_with_progress, write_run};
use paragyro_simulator::report;
use paragyro_simulator::runner::RunOptions;

/// Run the built-in `drift-retune` scenario, print its summary and write the plots.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output directory (created if needed).
    #[arg(long, value_name = "DIR", default_value = "out")]
    pub out: PathBuf,
    /// Precision of the core.
    #[arg(long, value_enum, default_value_t = PrecisionArg::F32)]
    pub precision: PrecisionArg,
}

/// Runs the demo, prints its summary, writes its outputs.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    let sc = load("drift-retune")?;
    ctx.say(&format!(
        "Demo: built-in scenario 'drift-retune' ({}).\n",
        sc.description
    ))?;
    let opts = RunOptions {
        precision: a.precision.into(),
        seed: None,
    };
    let show = ctx.progress_ok;
    let result = run_with_progress(&sc, &opts, show)?;
    ctx.say(&report::print_summary(&result))?;
    let files = write_run(&a.out, &result)?;
    let mut text = format!("\nPlots and data in {}:\n", a.out.display());
    text.push_str(&file_list(&files));
    ctx.say(&text)
}
