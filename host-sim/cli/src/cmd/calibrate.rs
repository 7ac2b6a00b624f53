//! `paragyro-sim calibrate <scenario>`: the residual std of each regression row with the
//! true θ, i.e. the row weights `row_sigma_*` of the core's configuration.

use super::{Ctx, EXIT_RUN, Failure, fail, load};
use paragyro_simulator::runner;

/// Measure the residual std of each regression row with the true θ (the row weights
/// `row_sigma_*` of the core's configuration) on a scenario.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Built-in scenario name or path to a scenario TOML file.
    pub scenario: String,
    /// Start of the measurement window, s (after start-up and the dither onset).
    #[arg(long, default_value_t = 2.0)]
    pub from: f64,
    /// RK4 steps per carrier period (high, so the integrator's error is not counted as noise).
    #[arg(long, default_value_t = 512)]
    pub steps_per_period: usize,
}

/// Measures and prints the two weight vectors.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    let mut sc = load(&a.scenario)?;
    sc.sim.steps_per_period = a.steps_per_period;
    let (d, s) = runner::calibrate_rows(&sc, a.from).map_err(fail(EXIT_RUN))?;
    let f = |v: [f64; 5]| {
        v.iter()
            .map(|x| format!("{x:.3e}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    ctx.say(&format!(
        "Residual std per row with the true θ, per 1 pm/√Hz (rows: DC, h1 Re, h1 Im, h3 Re, h3 Im),\n\
         scenario '{}', from {} s, {} steps/period:\n\
         row_sigma_drive = [{}]\nrow_sigma_sense = [{}]\n",
        sc.name,
        a.from,
        a.steps_per_period,
        f(d),
        f(s)
    ))
}
