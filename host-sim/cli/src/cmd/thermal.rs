//! `paragyro-sim thermal [SCENARIO] --out DIR`: a run through a temperature profile and its
//! thermal report (thermal.md, thermal.json, thermal.png, and the run's own outputs).

use std::path::PathBuf;

use super::{
    Ctx, EXIT_LOAD, EXIT_RUN, Failure, PrecisionArg, fail, file_list, load, run_with_progress,
    write_run,
};
use paragyro_simulator::runner::RunOptions;
use paragyro_simulator::scenario::Scenario;
use paragyro_simulator::thermal::{
    ThermalReport, move_ramp_start, oracle_sense_amp, reshape_ramp, set_tcf_ppm_k,
};

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
    /// The retune supervisor's tracking step, Hz (core `retune.track_hz`; 0: the pump moves
    /// only by retunes, through the 2 Hz dead band), instead of the scenario's or the core's.
    #[arg(long, value_name = "HZ")]
    pub track_hz: Option<f64>,
    /// The modes' frequency TCFs, drive and sense, ppm/K, instead of the scenario's.
    #[arg(
        long,
        value_name = "DRIVE,SENSE",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub tcf_ppm_k: Option<Vec<f64>>,
    /// Withhold the die temperature from the core (the scenario's `sensor = false`): the
    /// drift followed by the walk alone.
    #[arg(long)]
    pub no_sensor: bool,
    /// Stretch the profile's ramp to this many seconds (a profile of one ramp, such as
    /// the default warm-up's 20 s), the run ending 2 s after it.
    #[arg(long, value_name = "S")]
    pub ramp_s: Option<f64>,
    /// The ramp's rise instead of the profile's, K (a profile of one ramp).
    #[arg(long, value_name = "K")]
    pub rise_k: Option<f64>,
    /// Start the ramp at this time, s, its length and rise kept (a profile of one ramp;
    /// whether a sudden onset sets the change detector off depends on the dithers' phases
    /// at it).
    #[arg(long, value_name = "S")]
    pub start_s: Option<f64>,
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
        sc.estimator.drift_kappa = Some(non_negative("--drift-kappa", k)?);
    }
    if let Some(t) = a.track_hz {
        sc.estimator.retune_track_hz = Some(non_negative("--track-hz", t)?);
    }
    if let Some(tcf) = &a.tcf_ppm_k {
        set_tcf_ppm_k(&mut sc, tcf).map_err(|error| Failure {
            code: EXIT_LOAD,
            error,
        })?;
    }
    if let (true, Some(t)) = (a.no_sensor, sc.temperature.as_mut()) {
        t.sensor = false;
    }
    if a.ramp_s.is_some() || a.rise_k.is_some() {
        reshape_ramp(&mut sc, a.ramp_s, a.rise_k).map_err(|error| Failure {
            code: EXIT_LOAD,
            error,
        })?;
    }
    if let Some(t0) = a.start_s {
        move_ramp_start(&mut sc, t0).map_err(|error| Failure {
            code: EXIT_LOAD,
            error,
        })?;
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

/// A flag's value that must be finite and ≥ 0, or the load error naming it.
fn non_negative(flag: &str, v: f64) -> Result<f64, Failure> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(Failure {
            code: EXIT_LOAD,
            error: anyhow::anyhow!("{flag} must be finite and >= 0 (got {v})"),
        })
    }
}
