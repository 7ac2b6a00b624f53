//! `paragyro-sim rate-response --out DIR`: the rate channel's datasheet on the simulated
//! device — step, chirp (magnitude, phase, −3 dB bandwidth), sines at 10 and 50 Hz, a
//! ±300 °/s ramp (scale factor, nonlinearity), g-sensitivity, rate noise against the
//! Cramér–Rao bound; with `--allan-s` the static Allan runs (long: not for CI).

use std::path::PathBuf;

use super::{Ctx, EXIT_RUN, Failure, PrecisionArg, fail};
use paragyro_simulator::rate_response::{self, Options};

/// The rate channel's report (report.json, report.md, PNGs).
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output directory (created if needed).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Noise seed of every run.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Precision of the core.
    #[arg(long, value_enum, default_value_t = PrecisionArg::F32)]
    pub precision: PrecisionArg,
    /// Also run the static Allan runs (0 and 150 °/s) of this many seconds each.
    #[arg(long, value_name = "S")]
    pub allan_s: Option<f64>,
    /// The Allan runs' memory of the rate's zero μ̂xy, s (core `rate.zero_memory_s`; 0: the
    /// slow RLS's 2 s estimate every sample), instead of the core's.
    #[arg(long, value_name = "S")]
    pub allan_zero_memory_s: Option<f64>,
    /// The Allan runs' slow RLS forgetting factor per sample, in (0, 1] (scenario
    /// `estimator.forgetting`; the memory is 1/(1 − λ) samples), instead of the
    /// base scenario's 0.999.
    #[arg(long, value_name = "LAMBDA")]
    pub allan_forgetting: Option<f64>,
    /// The Allan record starts this long after the start-up, s (the rate's zero settled;
    /// the figures from the start-up are reported beside).
    #[arg(long, value_name = "S", default_value_t = rate_response::ALLAN_SETTLE_S)]
    pub allan_settle_s: f64,
    /// Also the hour after a warm start from the snapshot at the settle's end (a second
    /// boot of the device, another noise seed).
    #[arg(long)]
    pub allan_warm_start: bool,
}

/// Runs every measurement and writes the report.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    if let Some(s) = a.allan_s
        && !(s.is_finite() && s >= 10.0)
    {
        return Err(fail(EXIT_RUN)(anyhow::anyhow!(
            "--allan-s must be at least 10 s (got {s})"
        )));
    }
    if let Some(m) = a.allan_zero_memory_s
        && !(m.is_finite() && m >= 0.0)
    {
        return Err(fail(EXIT_RUN)(anyhow::anyhow!(
            "--allan-zero-memory-s must be finite and >= 0 (got {m})"
        )));
    }
    if let Some(l) = a.allan_forgetting
        && !rate_response::forgetting_ok(l)
    {
        return Err(fail(EXIT_RUN)(anyhow::anyhow!(
            "--allan-forgetting must be in (0, 1] (got {l})"
        )));
    }
    if !(a.allan_settle_s.is_finite() && a.allan_settle_s >= 0.0) {
        return Err(fail(EXIT_RUN)(anyhow::anyhow!(
            "--allan-settle-s must be finite and >= 0 (got {})",
            a.allan_settle_s
        )));
    }
    let o = Options {
        precision: a.precision.into(),
        seed: a.seed,
        allan_s: a.allan_s,
        allan_zero_memory_s: a.allan_zero_memory_s,
        allan_forgetting: a.allan_forgetting,
        allan_settle_s: a.allan_settle_s,
        allan_warm_start: a.allan_warm_start,
    };
    let (report, files) = rate_response::run_all(&o, &a.out).map_err(fail(EXIT_RUN))?;
    let mut text = format!(
        "Wrote {} files to {}: {}\n\n",
        files.len(),
        a.out.display(),
        files.join(", ")
    );
    text.push_str(&rate_response::markdown(&report));
    ctx.say(&text)
}
