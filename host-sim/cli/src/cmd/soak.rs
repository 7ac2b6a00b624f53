//! `paragyro-sim soak --hours H --out DIR`: the soak benchmark
//! (paragyro_simulator::faults::soak): the f32 core for hours with the dither switched
//! off after convergence, and with it on; writes DIR/soak.json and DIR/soak.md.

use std::path::PathBuf;

use super::{Ctx, EXIT_RUN, Failure, fail, note, write_report};
use paragyro_simulator::faults::soak::{soak_both, table_md};

/// Soak benchmark: hours of the f32 core, dither off and on; soak.json, soak.md.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Soak length per run, hours (after the convergence).
    #[arg(long, default_value_t = 1.0)]
    pub hours: f64,
    /// Output directory (created if needed).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Convergence with the dither before the soak, s.
    #[arg(long, default_value_t = 20.0)]
    pub converge_s: f64,
    /// Window of the rate-error means at the start and the end, s.
    #[arg(long, default_value_t = 300.0)]
    pub window_s: f64,
    /// Noise seed.
    #[arg(long, default_value_t = 13)]
    pub seed: u64,
}

/// Runs both soaks and writes their figures.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    let soak_s = a.hours * 3600.0;
    if !(soak_s.is_finite() && soak_s > a.window_s && a.window_s > 0.0 && a.converge_s > 0.0) {
        return Err(Failure {
            code: super::EXIT_LOAD,
            error: anyhow::anyhow!(
                "--hours must give a soak longer than --window-s (> 0), --converge-s > 0"
            ),
        });
    }
    note(&format!(
        "soak: 2 runs of {:.0} s simulated (dither off, on) after {} s of convergence",
        soak_s, a.converge_s
    ));
    let reps = soak_both(a.converge_s, soak_s, a.window_s, a.seed).map_err(fail(EXIT_RUN))?;
    let table = table_md(&reps);
    write_report(ctx, &a.out, "soak", &reps, &table)
}
