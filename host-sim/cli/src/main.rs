//! `paragyro-sim`: the command line of the simulator.
//!
//! ```text
//! paragyro-sim list                                   built-in scenarios
//! paragyro-sim check <scenario|file.toml>             load and validate, print the resolved settings
//! paragyro-sim run <scenario|file.toml> --out DIR     run, write summary.json, trace.csv, plots
//!              [--seed N] [--precision f32|f64] [--quiet]
//! paragyro-sim demo [--out DIR] [--precision ...]     the built-in drift-retune, with a summary
//! paragyro-sim results                                every built-in, f32 and f64: host-sim/README.md "Results"
//! paragyro-sim calibrate <scenario|file.toml>         row noise (weights) with the true θ
//!              [--from S] [--steps-per-period N]
//! paragyro-sim averaged [--out DIR]                   seed 000's averaged model, band, sweeps
//! paragyro-sim paper-001 [--out DIR]                  seed 001's stationary regimes, Figs 3–4
//! paragyro-sim paper-claims                           the "20 %" claim, reading by reading
//! paragyro-sim paper-raw [--out DIR]                  the paper's own estimator on the raw signals
//! paragyro-sim record <scenario|file.toml>            a simulated record (host-sim/sim/record-format.md)
//!              --out FILE.csv [--seed N]               and its truth, FILE.truth.json
//! paragyro-sim replay FILE.csv --out DIR              the core open-loop on a record:
//!              [--precision f32|f64]                   estimates.csv, summary.json
//! paragyro-sim faults --ticks N --out DIR             the fault campaign: faults.json, faults.md
//!              [--seed N] [--class a,b]
//! paragyro-sim soak [--hours H] --out DIR             the soak benchmark: soak.json, soak.md
//! paragyro-sim lot DIR --out lot.parquet              a lot of records diagnosed: one row per
//!              [--reports DIR] [--spec spec.toml]      device, the devices' reports, the lot
//!              [--report DIR] [--jobs N]               report (lot.md); `lot-report` redraws it
//! ```
//!
//! Exit codes: 0 success; 1 the run or the outputs failed; 2 the scenario could not be loaded
//! (or the command line is wrong). Errors are printed as `error: <message>` with their causes;
//! no panic traces.

mod cmd;

use std::io::{IsTerminal, Write};
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use cmd::{Ctx, Failure};

/// Simulated parametrically excited MEMS gyroscope driving the paragyro core.
#[derive(Parser, Debug)]
#[command(name = "paragyro-sim", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The subcommands; each lives in its own file under `cmd/`.
#[derive(Subcommand, Debug)]
enum Command {
    /// List the built-in scenarios.
    List,
    /// Load and validate a scenario (built-in name or TOML file) without running it.
    Check(cmd::check::Args),
    /// Run a scenario; write summary.json, trace.csv and the plots.
    Run(cmd::run::Args),
    /// Run every built-in scenario with the f32 and the f64 core; print a Markdown table.
    Results,
    /// Measure the residual std of each regression row with the true θ (the row weights
    /// `row_sigma_*` of the core's configuration) on a scenario.
    Calibrate(cmd::calibrate::Args),
    /// Seed 000, averaged slow flow: steady states, stability, rest-state band, sweeps with hysteresis.
    Averaged(cmd::averaged::Args),
    /// Seed 001: stationary regimes and stability, Figs 3–4, RK4 checks of eq. (19), the paper's claims.
    #[command(name = "paper-001")]
    Paper001(cmd::paper001::Args),
    /// The paper's own estimator (eqs. 10–19) on the raw signals: the ±50 % test with three
    /// λ readings and a side by side with the 500 Hz estimator; plots and paper_raw_summary.json.
    PaperRaw(cmd::paper_raw::Args),
    /// Seed 000's "sense amplitude drops to 20 %" claim, reading by reading (full-rate plant).
    #[command(name = "paper-claims")]
    PaperClaims,
    /// Simulate a scenario as a record (CSV at 500 Hz, host-sim/sim/record-format.md); its truth
    /// goes to FILE.truth.json beside it.
    Record(cmd::record::Args),
    /// List the effects the simulator can add (names, units, what they add).
    Effects,
    /// Blind benchmark of the diagnosis: draw N records with withheld effects, seal the
    /// labels, diagnose each, score (score.md, score.json).
    Blind(cmd::blind::Args),
    /// Diagnose the gap between a record and the simulator: where it lies, which effect
    /// causes it, how far it shrinks once that effect is added (report.md, report.json, PNGs).
    Diagnose(cmd::diagnose::Args),
    /// Diagnose every record of a folder (a lot): one row per device in a Parquet file,
    /// the devices' reports and the lot report against a spec (yield, outliers).
    Lot(cmd::lot::Args),
    /// Redraw the lot report (lot.md, lot.json, plots) from a lot's Parquet file.
    #[command(name = "lot-report")]
    LotReport(cmd::lot::ReportArgs),
    /// Run the core open-loop on a record; write estimates.csv and summary.json.
    Replay(cmd::replay::Args),
    /// Run the built-in `drift-retune` scenario, print its summary and write the plots.
    Demo(cmd::demo::Args),
    /// Fault campaign: every fault class injected into the f32 core's closed loop, scored;
    /// writes DIR/faults.json and DIR/faults.md.
    Faults(cmd::faults::Args),
    /// Soak benchmark: hours of the f32 core with the dither off after convergence, and
    /// on; writes DIR/soak.json and DIR/soak.md.
    Soak(cmd::soak::Args),
    /// The rate channel's datasheet: step, chirp (bandwidth), sines, ±300 °/s ramp, g-sensitivity, noise vs CRLB.
    RateResponse(cmd::rate_response::Args),
    /// A run through a temperature profile (default: a 10 K warm-up) and its thermal report:
    /// resets, the rate's validity and error, the pump against 2·f_y, per kelvin.
    Thermal(cmd::thermal::Args),
}

fn main() -> ExitCode {
    // A bug must not print a backtrace at the user: one line, then exit 101.
    std::panic::set_hook(Box::new(|info| {
        eprintln!("error: internal error (please report): {info}");
    }));
    let cli = Cli::parse();
    let mut stdout = std::io::stdout().lock();
    let mut stderr = std::io::stderr();
    let tty = std::io::stderr().is_terminal();
    ExitCode::from(execute(cli, &mut stdout, &mut stderr, tty))
}

/// Runs a parsed command; prints errors on `err`; returns the exit code.
fn execute(cli: Cli, out: &mut dyn Write, err: &mut dyn Write, progress_ok: bool) -> u8 {
    let mut ctx = Ctx { out, progress_ok };
    match dispatch(cli.command, &mut ctx) {
        Ok(()) => 0,
        Err(f) if f.code == 0 => 0, // stdout closed: nothing left to say
        Err(f) => {
            let _ = writeln!(err, "error: {:#}", f.error);
            f.code
        }
    }
}

fn dispatch(command: Command, ctx: &mut Ctx) -> Result<(), Failure> {
    use cmd::*;
    match command {
        Command::List => list::exec(ctx),
        Command::Check(a) => check::exec(a, ctx),
        Command::Run(a) => run::exec(a, ctx),
        Command::Results => results::exec(ctx),
        Command::Calibrate(a) => calibrate::exec(a, ctx),
        Command::Averaged(a) => averaged::exec(a, ctx),
        Command::Paper001(a) => paper001::exec(a, ctx),
        Command::PaperRaw(a) => paper_raw::exec(a, ctx),
        Command::PaperClaims => paper_claims::exec(ctx),
        Command::Record(a) => record::exec(a, ctx),
        Command::Effects => effects::exec(ctx),
        Command::Blind(a) => blind::exec(a, ctx),
        Command::Diagnose(a) => diagnose::exec(a, ctx),
        Command::Lot(a) => lot::exec(a, ctx),
        Command::LotReport(a) => lot::exec_report(a, ctx),
        Command::Replay(a) => replay::exec(a, ctx),
        Command::Demo(a) => demo::exec(a, ctx),
        Command::Faults(a) => faults::exec(a, ctx),
        Command::Soak(a) => soak::exec(a, ctx),
        Command::RateResponse(a) => rate_response::exec(a, ctx),
        Command::Thermal(a) => thermal::exec(a, ctx),
    }
}

#[cfg(test)]
mod tests;
