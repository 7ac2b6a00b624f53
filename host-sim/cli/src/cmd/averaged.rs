//! `paragyro-sim averaged`: seed 000's averaged slow flow (steady states, stability,
//! rest-state band, sweeps with hysteresis).

use std::path::PathBuf;

use super::{Ctx, EXIT_RUN, Failure, fail};

/// Seed 000, averaged slow flow: steady states, stability, rest-state band, sweeps with hysteresis.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output directory (created if needed).
    #[arg(long, value_name = "DIR", default_value = "out")]
    pub out: PathBuf,
}

/// Writes the report and says where.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    paragyro_papers::averaged::write_averaged_report(&a.out).map_err(fail(EXIT_RUN))?;
    ctx.say(&format!(
        "Wrote averaged_sweep.png and averaged.json to {}\n",
        a.out.display()
    ))
}
