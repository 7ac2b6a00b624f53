//! `paragyro-sim paper-raw` (also `run paper-raw`): the paper's own estimator (eqs. 10–19)
//! on the raw signals, the ±50 % test with three λ readings, side by side with the 500 Hz
//! estimator.

use std::path::PathBuf;

use super::{Ctx, EXIT_RUN, Failure, fail, note};

/// The paper's own estimator (eqs. 10–19) on the raw signals: the ±50 % test with three
/// λ readings and a side by side with the 500 Hz estimator; plots and paper_raw_summary.json.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output directory (created if needed).
    #[arg(long, value_name = "DIR", default_value = "out/paper-raw")]
    pub out: PathBuf,
}

/// Runs the reproduction, writes its plots and summary, prints its table.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    note("running the paper's raw-signal estimator (about 30 s) ...");
    let summary =
        paragyro_papers::paper_raw::write_paper_raw_summary(&a.out).map_err(fail(EXIT_RUN))?;
    let mut text = format!(
        "Wrote paper_raw_*.png and paper_raw_summary.json to {}\n\n",
        a.out.display()
    );
    text.push_str(&summary.table_md);
    ctx.say(&text)
}
