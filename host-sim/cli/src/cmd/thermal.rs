//! `paragyro-sim thermal [SCENARIO] --out DIR`: a run through a temperature profile and its
//! thermal report (thermal.md, thermal.json, thermal.png, and the run's own outputs).

use std::path::PathBuf;

use super::{
    Ctx, EXIT_LOAD, EXIT_RUN, Failure, PrecisionArg, fail, file_list, load, run_with_progress,
    write_run,
};
use paragyro_simulator::runner::RunOptions;
use paragyro_simulator::scenario::Scenario;
use paragyro_simulator::thermal::{ThermalReport, oracle_sense_amp};

/// `host-sim/scenarios/warm-up.toml`, the default.
const WARM_UP: &str = include_str!("../../../scenarios/warm-up.toml");

/// Run a scenario with a `[temperature]` profile; write its thermal report.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scenario with a `[temperature]` profile (built-in name or TOML file); default: the
    /// 10 K warm-up of host-sim/scenarios/warm-up.toml.
    pub scenario: Option<String>,
    /// Output directory (created if needed).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Override the scenario's noise seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Precision of the core.
    #[arg(long, value_enum, default_value_t = PrecisionArg::F32)]
    pub precision: PrecisionArg,
    /// Drift tracking's κ (core `rls.drift_kappa`; 0 turns it off), instead of the
    /// scenario's or the core's.
    #[arg(long, value_name = "KAPPA")]
    pub drift_kappa: Option<f64>,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Runs the scenario, writes its outputs and the thermal report, prints the report.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    let mut sc =
        match &a.scenario {
            Some(s) => load(s)?,
            None => Scenario::from_toml_str(WARM_UP, "host-sim/scenarios/warm-up.toml").map_err(
                |e| Failure {
                    code: EXIT_LOAD,
                    error: anyhow::Error::new(e),
                },
            )?,
        };
    if let Some(k) = a.drift_kappa {
        if !(k.is_finite() && k >= 0.0) {
            return Err(Failure {
                code: EXIT_LOAD,
                error: anyhow::anyhow!("--drift-kappa must be finite and >= 0 (got {k})"),
            });
        }
        sc.estimator.drift_kappa = Some(k);
    }
    if sc.temperature.is_none() {
        return Err(Failure {
            code: EXIT_LOAD,
            error: anyhow::anyhow!(
                "scenario '{}' has no [temperature] profile (host-sim/scenarios/README.md, `[temperature]`)",
                sc.name
            ),
        });
    }
    let opts = RunOptions {
        precision: a.precision.into(),
        seed: a.seed,
    };
    let result = run_with_progress(&sc, &opts, ctx.progress_ok && !a.quiet)?;
    let oracle = oracle_sense_amp(&sc, a.seed.unwrap_or(sc.seed)).map_err(fail(EXIT_RUN))?;
    let report = ThermalReport::of(&sc, &result.trace)
        .map_err(fail(EXIT_RUN))?
        .with_oracle(&result.trace, &oracle);
    let mut files = write_run(&a.out, &result)?;
    let md = report.markdown();
    let write = |name: &str, text: &str| -> Result<PathBuf, Failure> {
        let p = a.out.join(name);
        std::fs::write(&p, text)
            .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", p.display()))
            .map_err(fail(EXIT_RUN))?;
        Ok(p)
    };
    files.push(write("thermal.md", &md)?);
    let json = serde_json::to_string_pretty(&report)
        .map_err(anyhow::Error::from)
        .map_err(fail(EXIT_RUN))?;
    files.push(write("thermal.json", &json)?);
    let png = a.out.join("thermal.png");
    report
        .plot(&sc, &result.trace, &png)
        .map_err(fail(EXIT_RUN))?;
    files.push(png);
    let mut text = md;
    text.push_str(&format!(
        "\nWrote {} files to {}:\n",
        files.len(),
        a.out.display()
    ));
    text.push_str(&file_list(&files));
    ctx.say(&text)
}
