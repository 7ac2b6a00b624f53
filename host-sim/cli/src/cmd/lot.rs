//! `paragyro-sim lot DIR --out lot.parquet`: diagnose a lot of records, one row per device
//! (Parquet), their reports and the lot report; `paragyro-sim lot-report lot.parquet --out
//! DIR`: the lot report again from the Parquet (host-sim/lot/README.md).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use paragyro_lot::{LotOptions, LotRow, LotSummary, Spec};

use super::{Ctx, EXIT_LOAD, EXIT_RUN, Failure, fail, note};

/// Diagnose every record of a folder (one row per device in a Parquet file), with the
/// devices' reports and the lot report against a spec.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The lot's folder: every `*.csv` directly in it is a record (`*.truth.*` skipped).
    pub dir: PathBuf,
    /// The rows, one per device (Parquet).
    #[arg(long, value_name = "FILE.parquet")]
    pub out: PathBuf,
    /// Write each device's report into DIR/STEM/ (report.md, report.json, plots), STEM the
    /// record's file name without its extension.
    #[arg(long, value_name = "DIR")]
    pub reports: Option<PathBuf>,
    /// The spec (TOML: per-parameter limits, accepted verdicts); default: no limits, the
    /// verdict `none` passes.
    #[arg(long, value_name = "spec.toml")]
    pub spec: Option<PathBuf>,
    /// Write the lot report (lot.md, lot.json, plots) into this folder.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// Records diagnosed at once (threads); 0: one per core.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub jobs: usize,
    #[command(flatten)]
    pub opts: super::diagnose::DiagnoseOpts,
}

/// Redraw the lot report from a lot's Parquet file.
#[derive(clap::Args, Debug)]
pub struct ReportArgs {
    /// The rows written by `paragyro-sim lot`.
    pub parquet: PathBuf,
    /// The spec (TOML); default: no limits, the verdict `none` passes.
    #[arg(long, value_name = "spec.toml")]
    pub spec: Option<PathBuf>,
    /// The report's folder (lot.md, lot.json, plots).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

fn load_spec(path: Option<&Path>) -> Result<Spec, Failure> {
    match path {
        Some(p) => Spec::load(p).map_err(fail(EXIT_LOAD)),
        None => Ok(Spec::default()),
    }
}

fn bar(ctx: &Ctx, n: usize) -> ProgressBar {
    if !ctx.progress_ok {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::with_draw_target(Some(n as u64), ProgressDrawTarget::stderr());
    let style = ProgressStyle::with_template(
        "{msg} [{bar:40.cyan/blue}] {pos}/{len}  {elapsed_precise} (eta {eta})",
    )
    .map(|s| s.progress_chars("=> "))
    .unwrap_or_else(|_| ProgressStyle::default_bar());
    bar.set_style(style);
    bar.set_message("diagnosing");
    bar
}

/// Diagnoses the lot, writes the Parquet, the reports and the lot report, prints counts.
/// Fails (exit 2) only when the folder cannot be listed, holds no record, the spec cannot
/// be read, or no record could be read; errors of single records are rows.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    let spec = load_spec(a.spec.as_deref())?;
    let diag = a.opts.options()?;
    let paths = paragyro_lot::find_records(&a.dir).map_err(fail(EXIT_LOAD))?;
    if paths.is_empty() {
        return Err(Failure {
            code: EXIT_LOAD,
            error: anyhow::anyhow!("no record (*.csv) in {}", a.dir.display()),
        });
    }
    let opts = LotOptions {
        diagnose: diag,
        reports: a.reports.clone(),
        threads: a.jobs,
    };
    let threads = if a.jobs == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        a.jobs
    };
    note(&format!(
        "diagnosing {} records of {} on {threads} thread(s){}",
        paths.len(),
        a.dir.display(),
        if opts.diagnose.resimulate {
            ", with the re-simulation"
        } else {
            ""
        }
    ));
    let pb = bar(ctx, paths.len());
    let wall = Instant::now();
    let progress = |_done: usize, _total: usize, row: &LotRow| {
        pb.inc(1);
        if let Some(e) = &row.error {
            pb.suspend(|| note(&format!("error: {e}")));
        }
    };
    let rows = paragyro_lot::diagnose_lot(&paths, &opts, &progress).map_err(fail(EXIT_RUN))?;
    pb.finish_and_clear();
    let secs = wall.elapsed().as_secs_f64();
    paragyro_lot::write_parquet(&a.out, &rows).map_err(fail(EXIT_RUN))?;
    let summary = match &a.report {
        Some(dir) => Some(paragyro_lot::report(&rows, &spec, dir).map_err(fail(EXIT_RUN))?),
        None => None,
    };
    let y = spec.yield_of(&rows);
    let mut text = format!(
        "{} records in {secs:.1} s ({:.3} records/s on {threads} thread(s)): {} diagnosed, {} errors\n",
        rows.len(),
        rows.len() as f64 / secs.max(1e-9),
        y.diagnosed,
        rows.len() - y.diagnosed
    );
    text.push_str(&counts(&rows, &spec, summary.as_ref()));
    text.push_str(&format!("Wrote {}", a.out.display()));
    if let Some(d) = &a.reports {
        text.push_str(&format!(", the devices' reports in {}", d.display()));
    }
    if let Some(d) = &a.report {
        text.push_str(&format!(", the lot report {}", d.join("lot.md").display()));
    }
    text.push('\n');
    ctx.say(&text)?;
    if y.diagnosed == 0 {
        return Err(Failure {
            code: EXIT_LOAD,
            error: anyhow::anyhow!(
                "none of the {} records of {} could be read and diagnosed",
                rows.len(),
                a.dir.display()
            ),
        });
    }
    Ok(())
}

/// The verdict counts and the yield, one line each.
fn counts(rows: &[LotRow], spec: &Spec, summary: Option<&LotSummary>) -> String {
    let mut verdicts = std::collections::BTreeMap::new();
    for v in rows
        .iter()
        .filter(|r| r.diagnosed())
        .filter_map(|r| r.verdict.as_ref())
    {
        *verdicts.entry(v.as_str()).or_insert(0usize) += 1;
    }
    let list: Vec<String> = verdicts.iter().map(|(v, n)| format!("{v} {n}")).collect();
    let y = summary.map_or_else(|| spec.yield_of(rows), |s| s.yield_.clone());
    format!(
        "Verdicts: {}\nYield {} ({} of {} pass; parametric {} of {} diagnosed)\n",
        if list.is_empty() {
            "–".into()
        } else {
            list.join(", ")
        },
        y.yield_all
            .map_or("–".into(), |x| format!("{:.1} %", 100.0 * x)),
        y.passed,
        y.devices,
        y.parametric_passed,
        y.diagnosed
    )
}

/// Reads the rows back and writes the lot report.
pub fn exec_report(a: ReportArgs, ctx: &mut Ctx) -> Result<(), Failure> {
    let spec = load_spec(a.spec.as_deref())?;
    let rows = paragyro_lot::read_parquet(&a.parquet)
        .with_context(|| format!("cannot read the lot {}", a.parquet.display()))
        .map_err(fail(EXIT_LOAD))?;
    let s = paragyro_lot::report(&rows, &spec, &a.out).map_err(fail(EXIT_RUN))?;
    let mut text = format!("{} devices read from {}\n", rows.len(), a.parquet.display());
    text.push_str(&counts(&rows, &spec, Some(&s)));
    text.push_str(&format!("Wrote {}\n", a.out.join("lot.md").display()));
    ctx.say(&text)
}
