//! Scores the project's diagnosis on a directory written by `paragyro-refsim gen`: each
//! record diagnosed from its CSV alone (`paragyro_diagnose::diagnose::diagnose`, default
//! options), then its verdict judged against labels.json (read as the blind benchmark's
//! `Labels`) with the blind benchmark's own rule (`blind::correct_for`). Writes
//! DIR/score.md and prints it.
//!
//! ```sh
//! cargo run --profile test -p paragyro-refsim --example score -- DIR
//! ```
//!
//! An example, not the library: it uses the dev-dependencies (the diagnosis, the
//! simulator's reader), which the generator itself never depends on.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use paragyro_diagnose::blind::{Category, Labels, correct_for};
use paragyro_diagnose::diagnose::{Answer, Options, diagnose};
use rayon::prelude::*;

struct Scored {
    id: String,
    category: Category,
    truth: String,
    above: bool,
    /// An out-of-library type outside the diagnosis's span (`Outside::outside_span`).
    span_out: bool,
    verdict: Answer,
    correct: bool,
    seconds: f64,
}

fn share(v: &[&Scored], f: impl Fn(&Scored) -> bool) -> String {
    if v.is_empty() {
        return "–".into();
    }
    let k = v.iter().filter(|s| f(s)).count();
    format!(
        "{k}/{} ({:.0} %)",
        v.len(),
        100.0 * k as f64 / v.len() as f64
    )
}

fn main() -> anyhow::Result<()> {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .context("usage: score DIR (a directory written by paragyro-refsim gen)")?,
    );
    let path = dir.join("labels.json");
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("cannot read {}", path.display()))?;
    let labels: Labels = serde_json::from_str(&text)
        .with_context(|| format!("{} is not a blind benchmark's labels", path.display()))?;
    let n = labels.records.len();
    let scored: Vec<Scored> = labels
        .records
        .par_iter()
        .map(|d| -> anyhow::Result<Scored> {
            let t = Instant::now();
            let csv = dir.join(format!("{}.csv", d.id));
            let rec = paragyro_simulator::record::read_record(&csv)?;
            let r = diagnose(&rec, &Options::default())
                .with_context(|| format!("diagnosing {}", csv.display()))?;
            let verdict = r.report.verdict.answer();
            let effects: Vec<_> = d.effects.iter().map(|e| e.effect).collect();
            let mut truth: Vec<String> = d.effects.iter().map(|e| e.to_string()).collect();
            truth.extend(d.outside.map(|o| format!("{}={:e}", o.kind, o.size)));
            let s = Scored {
                id: d.id.clone(),
                category: d.category,
                truth: truth.join(", "),
                above: d.size_over_limit() >= 1.0,
                span_out: d.outside.is_some_and(|o| o.kind.outside_span()),
                verdict,
                correct: correct_for(d.category, &effects, verdict),
                seconds: t.elapsed().as_secs_f64(),
            };
            eprintln!("{} → {} ({:.1} s)", s.id, s.verdict, s.seconds);
            Ok(s)
        })
        .collect::<anyhow::Result<_>>()?;
    let of = |c: Category, above: Option<bool>| -> Vec<&Scored> {
        scored
            .iter()
            .filter(|s| s.category == c && above.is_none_or(|a| s.above == a))
            .collect()
    };
    let span_out: Vec<&Scored> = of(Category::Outside, Some(true))
        .into_iter()
        .filter(|s| s.span_out)
        .collect();
    let mut m = format!(
        "# The diagnosis on refsim records ({n} records, seed {})\n\n| measure | result |\n|---|---|\n",
        labels.seed
    );
    let rows = [
        (
            "top-1 on single library effects above the detection limit",
            share(&of(Category::Single, Some(true)), |s| s.correct),
        ),
        (
            "top-1 on single library effects, all sizes",
            share(&of(Category::Single, None), |s| s.correct),
        ),
        (
            "`none` on clean records",
            share(&of(Category::None, None), |s| s.correct),
        ),
        (
            "`unknown` on out-of-library records above their limit",
            share(&of(Category::Outside, Some(true)), |s| s.correct),
        ),
        (
            "`unknown` on out-of-library records, all sizes",
            share(&of(Category::Outside, None), |s| s.correct),
        ),
        (
            "`unknown` on out-of-library types outside the span, above their limit",
            share(&span_out, |s| s.verdict == Answer::Unknown),
        ),
        (
            "a library effect named on out-of-library types outside the span, above their limit",
            share(&span_out, |s| matches!(s.verdict, Answer::Effect(_))),
        ),
        (
            "two effects: one named",
            share(&of(Category::Double, None), |s| s.correct),
        ),
    ];
    for (k, v) in rows {
        let _ = writeln!(m, "| {k} | {v} |");
    }
    m.push_str("\n| id | category | truth | above limit | verdict | right | s |\n|---|---|---|---|---|---|---|\n");
    for s in &scored {
        let _ = writeln!(
            m,
            "| {} | {} | {} | {} | {} | {} | {:.1} |",
            s.id,
            s.category,
            s.truth,
            if s.above { "yes" } else { "no" },
            s.verdict,
            if s.correct { "yes" } else { "**no**" },
            s.seconds
        );
    }
    std::fs::write(dir.join("score.md"), &m)?;
    print!("{m}");
    Ok(())
}
