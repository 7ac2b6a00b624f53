//! The lot report: `lot.md` (read first), `lot.json` ([`LotSummary`]) and one histogram per
//! parameter (`dev_<name>.png`): verdict counts, the yield against the [`Spec`], each
//! parameter's deviations over the lot against its tolerance band, the outlier devices
//! (outside the spec, or a verdict the spec does not accept) with relative links to their
//! own report.md, and the records that could not be read or diagnosed.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Component, Path, PathBuf};

use anyhow::{Context, Result};
use paragyro_diagnose::diagnose::calibrate::PARAM_NAMES;
use serde::{Deserialize, Serialize};

use crate::plot::{Hist, histogram};
use crate::row::LotRow;
use crate::spec::{Deviation, Limit, Spec, Yield};

/// The format tag of lot.json.
pub const FORMAT: &str = "paragyro-lot 1";

/// One parameter's deviations over the lot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParamStats {
    /// The parameter (report.json's name).
    pub name: String,
    /// The deviation shown: the spec's, else `relative` (`absolute` when no device has a
    /// relative one: a model value of 0).
    pub deviation: Deviation,
    /// The spec's limits (none: the parameter is not in the spec).
    pub lo: Option<f64>,
    pub hi: Option<f64>,
    /// Diagnosed devices with a value of this deviation.
    pub with_value: usize,
    /// Of those, within the limits, below, above (all within without limits).
    pub within: usize,
    pub below: usize,
    pub above: usize,
    /// The distribution: median, 5th and 95th percentiles, extremes (null without values).
    pub median: Option<f64>,
    pub p05: Option<f64>,
    pub p95: Option<f64>,
    pub min: Option<f64>,
    pub max: Option<f64>,
    /// The histogram (file name in the report folder), if drawn.
    pub plot: Option<String>,
}

/// A device outside the spec or with a verdict the spec does not accept.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Outlier {
    /// The record's file name.
    pub record: String,
    /// Its verdict.
    pub verdict: Option<String>,
    /// Why it fails ([`crate::spec::Judgement::reasons`]).
    pub reasons: Vec<String>,
    /// Its report.md relative to the lot report's folder (when its report was written and
    /// exists).
    pub report: Option<String>,
}

/// A record that could not be read or diagnosed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorEntry {
    /// The record's file name and path.
    pub record: String,
    pub path: String,
    /// The error.
    pub error: String,
}

/// lot.json.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LotSummary {
    /// [`FORMAT`].
    pub format: String,
    /// The spec the lot was judged against.
    pub spec: Spec,
    /// Verdict counts over the diagnosed devices (`none`, `unknown`, effect names).
    pub verdicts: BTreeMap<String, usize>,
    /// The yield.
    #[serde(rename = "yield")]
    pub yield_: Yield,
    /// Every parameter ([`PARAM_NAMES`] order).
    pub parameters: Vec<ParamStats>,
    /// The failing devices in lot order (errors are in `errors`).
    pub outliers: Vec<Outlier>,
    /// The records that could not be read or diagnosed.
    pub errors: Vec<ErrorEntry>,
    /// Sum and median of the diagnoses' wall times, s.
    pub diagnosis_seconds_total: f64,
    pub diagnosis_seconds_median: Option<f64>,
}

/// The `q` quantile of sorted `v` (linear between order statistics).
fn quantile(v: &[f64], q: f64) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let x = q * (v.len() - 1) as f64;
    let (i, f) = (x.floor() as usize, x - x.floor());
    let j = (i + 1).min(v.len() - 1);
    Some(v[i] + f * (v[j] - v[i]))
}

/// The limit a parameter is shown against: the spec's, else none on the relative deviation
/// (absolute when no row has a relative one).
fn limit_for(spec: &Spec, rows: &[LotRow], name: &str) -> (Limit, bool) {
    if let Some(l) = spec.parameters.get(name) {
        return (l.clone(), true);
    }
    let any_rel = rows
        .iter()
        .any(|r| r.param(name).is_some_and(|p| p.rel.is_some()));
    let deviation = if any_rel {
        Deviation::Relative
    } else {
        Deviation::Absolute
    };
    (
        Limit {
            deviation,
            lo: None,
            hi: None,
        },
        false,
    )
}

fn param_stats(name: &str, rows: &[LotRow], spec: &Spec, out_dir: &Path) -> Result<ParamStats> {
    let (limit, in_spec) = limit_for(spec, rows, name);
    let mut v: Vec<f64> = rows
        .iter()
        .filter(|r| r.diagnosed())
        .filter_map(|r| limit.deviation_of(r, name))
        .filter(|x| x.is_finite())
        .collect();
    v.sort_by(f64::total_cmp);
    let below = v
        .iter()
        .filter(|&&x| limit.lo.is_some_and(|lo| x < lo))
        .count();
    let above = v
        .iter()
        .filter(|&&x| limit.hi.is_some_and(|hi| x > hi))
        .count();
    let mut s = ParamStats {
        name: name.into(),
        deviation: limit.deviation,
        lo: limit.lo,
        hi: limit.hi,
        with_value: v.len(),
        within: v.len() - below - above,
        below,
        above,
        median: quantile(&v, 0.5),
        p05: quantile(&v, 0.05),
        p95: quantile(&v, 0.95),
        min: v.first().copied(),
        max: v.last().copied(),
        plot: None,
    };
    if !v.is_empty() {
        let file = format!("dev_{name}.png");
        let (scale, unit) = match limit.deviation {
            Deviation::Relative => (
                100.0,
                format!("{name}: relative deviation from the model, %"),
            ),
            Deviation::Absolute => (
                1.0,
                format!("{name}: deviation from the model (device − model)"),
            ),
        };
        let scaled: Vec<f64> = v.iter().map(|x| x * scale).collect();
        let title = format!(
            "{name}: {} devices{}",
            v.len(),
            if in_spec {
                format!(", {} within the tolerance band", s.within)
            } else {
                " (no limits in the spec)".into()
            }
        );
        histogram(
            &out_dir.join(&file),
            &Hist {
                title: &title,
                x_desc: &unit,
                values: &scaled,
                lo: limit.lo.map(|x| x * scale),
                hi: limit.hi.map(|x| x * scale),
            },
        )
        .with_context(|| format!("cannot draw {}", out_dir.join(&file).display()))?;
        s.plot = Some(file);
    }
    Ok(s)
}

/// `to` relative to the folder `from` (both made absolute against the current folder),
/// `/`-separated, for a Markdown link.
pub fn relative_link(from: &Path, to: &Path) -> Option<String> {
    let norm = |p: &Path| -> Option<Vec<String>> {
        let abs = std::path::absolute(p).ok()?;
        let mut out: Vec<String> = Vec::new();
        for c in abs.components() {
            match c {
                Component::ParentDir => {
                    out.pop();
                }
                Component::CurDir => {}
                c => out.push(c.as_os_str().to_string_lossy().into_owned()),
            }
        }
        Some(out)
    };
    let (f, t) = (norm(from)?, norm(to)?);
    let common = f.iter().zip(&t).take_while(|(a, b)| a == b).count();
    if common == 0 {
        return None;
    }
    let mut parts: Vec<String> = vec!["..".into(); f.len() - common];
    parts.extend(t[common..].iter().cloned());
    Some(parts.join("/"))
}

/// Builds the summary of `rows` against `spec` and draws the plots into `out_dir`.
pub fn summarise(rows: &[LotRow], spec: &Spec, out_dir: &Path) -> Result<LotSummary> {
    let mut verdicts = BTreeMap::new();
    for r in rows.iter().filter(|r| r.diagnosed()) {
        if let Some(v) = &r.verdict {
            *verdicts.entry(v.clone()).or_insert(0) += 1;
        }
    }
    let parameters = PARAM_NAMES
        .iter()
        .map(|n| param_stats(n, rows, spec, out_dir))
        .collect::<Result<Vec<_>>>()?;
    let mut outliers = Vec::new();
    let mut errors = Vec::new();
    for r in rows {
        if let Some(e) = &r.error {
            errors.push(ErrorEntry {
                record: r.record.clone(),
                path: r.path.clone(),
                error: e.clone(),
            });
            continue;
        }
        let j = spec.judge(r);
        if !j.pass() {
            let report = r
                .report_dir
                .as_ref()
                .map(|d| PathBuf::from(d).join("report.md"))
                .filter(|p| p.is_file())
                .and_then(|p| relative_link(out_dir, &p));
            outliers.push(Outlier {
                record: r.record.clone(),
                verdict: r.verdict.clone(),
                reasons: j.reasons,
                report,
            });
        }
    }
    let mut secs: Vec<f64> = rows.iter().filter_map(|r| r.seconds).collect();
    secs.sort_by(f64::total_cmp);
    Ok(LotSummary {
        format: FORMAT.into(),
        spec: spec.clone(),
        verdicts,
        yield_: spec.yield_of(rows),
        parameters,
        outliers,
        errors,
        diagnosis_seconds_total: secs.iter().sum(),
        diagnosis_seconds_median: quantile(&secs, 0.5),
    })
}

/// Writes the lot report into `out_dir` (created if needed): lot.md, lot.json and the
/// histograms; returns the summary.
pub fn report(rows: &[LotRow], spec: &Spec, out_dir: &Path) -> Result<LotSummary> {
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("cannot create {}", out_dir.display()))?;
    let s = summarise(rows, spec, out_dir)?;
    let json = out_dir.join("lot.json");
    let text = serde_json::to_string_pretty(&s).context("cannot serialise lot.json")? + "\n";
    std::fs::write(&json, text).with_context(|| format!("cannot write {}", json.display()))?;
    let md = out_dir.join("lot.md");
    std::fs::write(&md, markdown(&s, rows))
        .with_context(|| format!("cannot write {}", md.display()))?;
    Ok(s)
}

fn pct(x: Option<f64>) -> String {
    x.map_or("–".into(), |v| format!("{:.1} %", 100.0 * v))
}

fn num(x: Option<f64>, dev: Deviation) -> String {
    match (x, dev) {
        (None, _) => "–".into(),
        (Some(v), Deviation::Relative) if v == 0.0 || (100.0 * v).abs() >= 0.01 => {
            format!("{:+.3} %", 100.0 * v)
        }
        (Some(v), Deviation::Relative) => format!("{:+.2e} %", 100.0 * v),
        (Some(v), Deviation::Absolute) => format!("{v:+.3e}"),
    }
}

/// A table cell: no `|` or line break.
fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

/// lot.md.
pub fn markdown(s: &LotSummary, rows: &[LotRow]) -> String {
    let mut m = String::new();
    let y = &s.yield_;
    let _ = writeln!(
        m,
        "# Lot report{}\n",
        s.spec
            .name
            .as_ref()
            .map_or(String::new(), |n| format!(": {n}"))
    );
    let _ = writeln!(
        m,
        "{} devices: {} diagnosed, {} could not be read or diagnosed.\n",
        y.devices,
        y.diagnosed,
        s.errors.len()
    );
    let _ = writeln!(
        m,
        "**Yield {}** ({} of {} devices pass: diagnosed, every parameter within its limits, verdict {}); \
         {} of the diagnosed devices; parametric yield (limits only) {} ({} of {}).\n",
        pct(y.yield_all),
        y.passed,
        y.devices,
        s.spec.accept_verdicts.join(" or "),
        pct(y.yield_diagnosed),
        pct(y.parametric_yield),
        y.parametric_passed,
        y.diagnosed
    );
    m.push_str("## Verdicts\n\n| verdict | devices |\n|---|---|\n");
    for (v, n) in &s.verdicts {
        let _ = writeln!(m, "| `{v}` | {n} |");
    }
    markdown_parameters(&mut m, s);
    markdown_outliers(&mut m, s);
    if !s.errors.is_empty() {
        m.push_str("\n## Errors\n\n| record | error |\n|---|---|\n");
        for e in &s.errors {
            let _ = writeln!(m, "| `{}` | {} |", cell(&e.record), cell(&e.error));
        }
    }
    let _ = writeln!(
        m,
        "\n## Time\n\n{} diagnoses took {:.1} s of wall time in all (median {} s each; with \
         several threads they overlap).\n\nlot.json has these numbers typed; the rows are in the Parquet file \
         (host-sim/lot/README.md, \"The row\").",
        rows.iter().filter(|r| r.seconds.is_some()).count(),
        s.diagnosis_seconds_total,
        s.diagnosis_seconds_median
            .map_or("–".into(), |x| format!("{x:.2}"))
    );
    m
}

fn markdown_parameters(m: &mut String, s: &LotSummary) {
    m.push_str(
        "\n## Parameters\n\nThe deviation of each calibrated parameter from the model over the \
         diagnosed devices (relative in %, absolute in the parameter's unit), against the spec's limits.\n\n\
         | parameter | deviation | lo | hi | devices | within | below | above | median | 5 % | 95 % | plot |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for p in &s.parameters {
        let d = p.deviation;
        let _ = writeln!(
            m,
            "| `{}` | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            p.name,
            match d {
                Deviation::Relative => "relative",
                Deviation::Absolute => "absolute",
            },
            num(p.lo, d),
            num(p.hi, d),
            p.with_value,
            p.within,
            p.below,
            p.above,
            num(p.median, d),
            num(p.p05, d),
            num(p.p95, d),
            p.plot
                .as_ref()
                .map_or("–".into(), |f| format!("[png]({f})"))
        );
    }
    let plotted: Vec<&ParamStats> = s
        .parameters
        .iter()
        .filter(|p| p.plot.is_some() && (p.lo.is_some() || p.hi.is_some()))
        .collect();
    for p in plotted {
        if let Some(f) = &p.plot {
            let _ = writeln!(m, "\n![{}]({f})", p.name);
        }
    }
}

fn markdown_outliers(m: &mut String, s: &LotSummary) {
    let _ = writeln!(
        m,
        "\n## Outliers\n\n{} diagnosed devices outside the spec or with a verdict it does not accept.\n",
        s.outliers.len()
    );
    if s.outliers.is_empty() {
        return;
    }
    m.push_str("| record | verdict | why | report |\n|---|---|---|---|\n");
    for o in &s.outliers {
        let _ = writeln!(
            m,
            "| `{}` | {} | {} | {} |",
            cell(&o.record),
            o.verdict
                .as_deref()
                .map_or("–".into(), |v| format!("`{v}`")),
            cell(&o.reasons.join("; ")),
            o.report
                .as_ref()
                .map_or("–".into(), |r| format!("[report.md](<{r}>)"))
        );
    }
}
