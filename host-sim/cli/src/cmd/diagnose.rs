//! `paragyro-sim diagnose FILE.csv --out DIR`: where a record departs from the simulator,
//! which effect causes it, how far the gap shrinks once it is added (host-sim/diagnose/README.md).

use std::path::PathBuf;

use anyhow::Context;

use super::{Ctx, EXIT_RUN, Failure, fail, load, note, read_record_warn};
use paragyro_diagnose::diagnose::{Model, Options, diagnose, write_report};

/// Diagnose the gap between a record and the simulator: where it lies, which effect
/// causes it, how far it shrinks once that effect is added (report.md, report.json, PNGs).
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The record (CSV, host-sim/sim/record-format.md). Its truth file is never read.
    pub record: PathBuf,
    /// Output directory (created if needed).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    #[command(flatten)]
    pub opts: DiagnoseOpts,
}

/// The diagnosis's options on the command line (`diagnose` and `lot`).
#[derive(clap::Args, Debug)]
pub struct DiagnoseOpts {
    /// The simulator configuration to compare with: a built-in scenario name or a
    /// scenario TOML (its plant at t = 0); default Table 2.
    #[arg(long, value_name = "SCENARIO")]
    pub model: Option<String>,
    /// Skip the re-simulation (no output error, faster).
    #[arg(long)]
    pub no_resim: bool,
    /// Whole-record re-simulations beyond the calibration's first two (each about a
    /// fifth of the time of a 60 s record's diagnosis): a calibration that has not
    /// converged takes further steps from them first, the confirmation of large effects
    /// has the rest (more lets a candidate take more Gauss–Newton steps; 0 turns both
    /// off). Default: as many as 120 s of record hold, at least 2 (2 on a 60 s record,
    /// 6 on a 20 s one).
    #[arg(long, value_name = "N")]
    pub confirm_runs: Option<usize>,
    /// Leave the drive's excursions the re-simulation does not reproduce (a regrowth after
    /// a collapse, set by the drive's noise floor) out of the rows and the noise estimate;
    /// by default they are kept and named in the report's limitations.
    #[arg(long)]
    pub leave_out_excursions: bool,
}

impl DiagnoseOpts {
    /// The diagnosis's [`Options`] (the model loaded from its scenario).
    pub fn options(&self) -> Result<Options, Failure> {
        let mut opts = Options {
            resimulate: !self.no_resim,
            confirm_runs: self.confirm_runs,
            leave_out_excursions: self.leave_out_excursions,
            ..Default::default()
        };
        if let Some(m) = &self.model {
            opts.model = Model::from_scenario(&load(m)?);
        }
        Ok(opts)
    }
}

/// Diagnoses the record, writes the report, prints the verdict and the top candidates.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    let file = &a.record;
    let rec = read_record_warn(file)?;
    let opts = a.opts.options()?;
    note(&format!(
        "diagnosing {} ({} samples, {:.1} s){}",
        file.display(),
        rec.rows.len(),
        rec.duration_s(),
        if opts.resimulate {
            ", with the re-simulation"
        } else {
            ""
        }
    ));
    let d = diagnose(&rec, &opts)
        .with_context(|| format!("cannot diagnose {}", file.display()))
        .map_err(fail(EXIT_RUN))?;
    let name = file
        .file_name()
        .map_or(String::new(), |n| n.to_string_lossy().into_owned());
    let files = write_report(&a.out, &d, &name).map_err(fail(EXIT_RUN))?;
    let r = &d.report;
    let mut text = format!(
        "Verdict: {}{}\n",
        r.verdict,
        r.verdict
            .secondary()
            .map(|s| format!(" (and {})", s.effect))
            .unwrap_or_default()
    );
    for c in r.ranking.iter().filter(|c| c.untestable.is_none()).take(3) {
        text.push_str(&format!(
            "  {:<24} size {:.4e} ± {:.1e} {}  gap closure {:5.1} %{}\n",
            c.effect,
            c.size.unwrap_or(f64::NAN),
            c.size_sigma.unwrap_or(f64::NAN),
            c.effect.unit(),
            100.0 * c.gap_closure,
            if c.significant { "  significant" } else { "" }
        ));
    }
    text.push_str(&format!(
        "Held-out gap: {:.4e} → {:.4e} ({:.1} % closed); output error closure {}\n",
        r.gap_before,
        r.gap_after,
        100.0 * r.gap_closure,
        r.output_error
            .as_ref()
            .map_or("not computed".into(), |o| format!(
                "{:.1} %",
                100.0 * o.closure
            ))
    ));
    let face = &r.parameter_face;
    let sig: Vec<String> = face
        .parameters
        .iter()
        .filter(|p| p.t.abs() >= paragyro_diagnose::diagnose::calibrate::T_PARAM)
        .map(paragyro_diagnose::diagnose::calibrate::describe)
        .collect();
    text.push_str(&format!(
        "Parameter face: {}; record noise {:.3} × 1 pm/√Hz (energy), held-out residual {:.3} × it\n",
        if sig.is_empty() {
            "no deviation at 3σ".into()
        } else {
            sig.join(", ")
        },
        face.noise_energy_ratio,
        r.residual_over_noise
    ));
    for h in face.hypotheses.iter().filter(|h| h.status == "named") {
        text.push_str(&format!("  {} named: {}\n", h.name, h.detail));
    }
    text.push_str(&format!(
        "Took {:.2} s. Wrote {} files to {}\n",
        r.seconds,
        files.len(),
        a.out.display()
    ));
    ctx.say(&text)
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    /// The options as `diagnose` and `lot` take them.
    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        opts: super::DiagnoseOpts,
    }

    fn options(args: &[&str]) -> paragyro_diagnose::diagnose::Options {
        let cli = Cli::parse_from(std::iter::once("paragyro-sim").chain(args.iter().copied()));
        match cli.opts.options() {
            Ok(o) => o,
            Err(_) => panic!("options of {args:?}"),
        }
    }

    #[test]
    fn excursions_are_left_out_only_with_the_flag() {
        assert!(!options(&[]).leave_out_excursions);
        assert!(options(&["--leave-out-excursions"]).leave_out_excursions);
        // the flag leaves the rest as it was
        let o = options(&[
            "--leave-out-excursions",
            "--confirm-runs",
            "3",
            "--no-resim",
        ]);
        assert!(o.leave_out_excursions && o.confirm_runs == Some(3) && !o.resimulate);
    }
}
