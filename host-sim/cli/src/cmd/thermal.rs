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
    if let (Some(tcf), Some(t)) = (&a.tcf_ppm_k, sc.temperature.as_mut()) {
        if let [wx, wy] = tcf[..]
            && wx.is_finite()
            && wy.is_finite()
        {
            (t.tcf_wx_ppm_k, t.tcf_wy_ppm_k) = (wx, wy);
        } else {
            return Err(Failure {
                code: EXIT_LOAD,
                error: anyhow::anyhow!("--tcf-ppm-k takes two finite values (got {tcf:?})"),
            });
        }
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

/// The profile's one ramp (points: held, ramp start, ramp end) stretched to `ramp_s` and
/// `rise_k`; the run ends 2 s after it.
fn reshape_ramp(sc: &mut Scenario, ramp_s: Option<f64>, rise_k: Option<f64>) -> anyhow::Result<()> {
    let Some(t) = sc.temperature.as_mut() else {
        anyhow::bail!("scenario '{}' has no [temperature] profile", sc.name);
    };
    let moves = t.points.windows(2).filter(|w| w[1][1] != w[0][1]).count();
    let Some(&[t0, c0]) = t.points.iter().rev().nth(1) else {
        anyhow::bail!("--ramp-s/--rise-k need a profile of one ramp");
    };
    if moves != 1 || t.points.last().is_none_or(|l| l[1] == c0) {
        anyhow::bail!(
            "--ramp-s/--rise-k need a profile of one ramp ending at its last point (scenario '{}' has {moves} moves)",
            sc.name
        );
    }
    let last = t.points.last().copied().unwrap_or([t0, c0]);
    let dur = ramp_s.unwrap_or(last[0] - t0);
    let rise = rise_k.unwrap_or(last[1] - c0);
    if !(dur.is_finite() && dur > 0.0 && rise.is_finite() && rise.abs() <= 200.0) {
        anyhow::bail!("--ramp-s must be > 0 and --rise-k within ±200 K (got {dur} s, {rise} K)");
    }
    if let Some(l) = t.points.last_mut() {
        *l = [t0 + dur, c0 + rise];
    }
    sc.duration_s = t0 + dur + 2.0;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_warm_up_ramp_is_stretched_and_other_profiles_are_refused() {
        let warm = || Scenario::from_toml_str(WARM_UP, "warm-up.toml").unwrap();
        let mut sc = warm();
        reshape_ramp(&mut sc, Some(300.0), Some(2.0)).unwrap();
        let t = sc.temperature.as_ref().unwrap();
        assert_eq!(t.points.last(), Some(&[305.0, 27.0]));
        assert_eq!(sc.duration_s, 307.0);
        let mut sc = warm();
        reshape_ramp(&mut sc, Some(40.0), None).unwrap();
        assert_eq!(
            sc.temperature.as_ref().unwrap().points.last(),
            Some(&[45.0, 35.0])
        );
        // a cycle is not one ramp; a zero duration is not a ramp
        let mut sc = warm();
        sc.temperature.as_mut().unwrap().points.push([40.0, 25.0]);
        assert!(reshape_ramp(&mut sc, Some(300.0), None).is_err());
        assert!(reshape_ramp(&mut warm(), Some(0.0), None).is_err());
    }
}
