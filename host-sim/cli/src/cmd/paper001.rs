//! `paragyro-sim paper-001`: seed 001's stationary regimes and their stability (Figs 3–4),
//! RK4 checks of eq. (19), the paper's claims.

use std::path::PathBuf;

use super::{Ctx, EXIT_RUN, Failure, fail};

/// Seed 001: stationary regimes and stability, Figs 3–4, RK4 checks of eq. (19), the paper's claims.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output directory (created if needed).
    #[arg(long, value_name = "DIR", default_value = "out")]
    pub out: PathBuf,
}

/// Writes the report and says where.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    paragyro_papers::paper001::write_paper001_report(&a.out).map_err(fail(EXIT_RUN))?;
    ctx.say(&format!(
        "Wrote paper001_fig3.png, paper001_fig4.png and paper001.json to {}\n",
        a.out.display()
    ))
}
