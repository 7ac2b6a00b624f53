//! `paragyro-sim blind --n N --seed S --out DIR`: the blind benchmark of the diagnosis.

use std::path::PathBuf;

use super::{Ctx, EXIT_RUN, Failure, fail, note};

/// Blind benchmark of the diagnosis: draw N records with withheld effects, seal the
/// labels, diagnose each, score (score.md, score.json).
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Number of records.
    #[arg(long, default_value_t = 100)]
    pub n: usize,
    /// Seed of the draw (the development seeds were 1 and 2; score on others).
    #[arg(long)]
    pub seed: u64,
    /// Output directory (created if needed).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

/// Runs the benchmark (progress on stderr) and prints the headline scores.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    let s =
        paragyro_diagnose::blind::run(a.n, a.seed, &a.out, &|m| note(m)).map_err(fail(EXIT_RUN))?;
    let p = |v: Option<f64>| v.map_or("–".into(), |x| format!("{:.0} %", 100.0 * x));
    ctx.say(&format!(
        "Blind benchmark, N = {}, seed {}:\n  top-1 (single, above limit) {}\n  unknown on out-of-library {} (outside the diagnosis's span, above limit: {} of {})\n  false alarms on clean {}\n  parameters within 1σ {}\n  median closure / oracle {}\nWrote {}/score.md and score.json\n",
        a.n,
        a.seed,
        p(s.top1_single_above_limit),
        p(s.unknown_on_outside),
        p(s.unknown_on_outside_span_above_limit),
        s.outside_span_above_limit_records,
        p(s.false_alarms_on_clean),
        p(s.parameter_coverage_1sigma),
        p(s.median_closure_over_oracle),
        a.out.display()
    ))
}
