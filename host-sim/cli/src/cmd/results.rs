//! `paragyro-sim results`: every built-in scenario with the f32 and the f64 core, as the
//! Markdown table of host-sim/README.md "Results".

use super::{Ctx, EXIT_RUN, Failure, fail, note};

/// Runs the table; progress lines on stderr.
pub fn exec(ctx: &mut Ctx) -> Result<(), Failure> {
    let md = paragyro_simulator::results::results_table(&mut |what| {
        note(&format!("running {what} ..."));
    })
    .map_err(fail(EXIT_RUN))?;
    ctx.say(&md)
}
