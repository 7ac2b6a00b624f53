//! The Markdown tables of the report.

use std::fmt::Write as _;

use paragyro_simulator::trace::{THETA_DRIVE_NAMES, THETA_SENSE_NAMES};

use super::compare::{CompareRow, Comparison};
use super::records::rel_err;
use super::report::COMPARE_RAW_S;
use super::switch::SwitchResult;

fn fe(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.1e}")
    } else {
        format!("{v}")
    }
}

fn ft(v: Option<f64>) -> String {
    v.map_or("never".into(), |t| format!("{t:.3}"))
}

/// Column label of a comparison row.
fn short_label(r: &CompareRow) -> String {
    let n = if r.noise_density > 0.0 { "1 pm" } else { "0" };
    if r.estimator.starts_with("product") {
        format!("product, {n}")
    } else if r.label.contains("0.2/τ") {
        format!("paper 0.2/τ, {n}")
    } else if r.label.contains("0.2/s") {
        format!("paper 0.2/s, {n}")
    } else {
        format!("paper 2 s, {n}")
    }
}

/// The Markdown tables of the report: the comparison with the product, then the ±50 %
/// runs (`long` then `short`).
pub(super) fn tables_md(
    cmp: &Comparison,
    long: &[&SwitchResult],
    short: &[&SwitchResult],
) -> String {
    let mut md = comparison_md(cmp);
    md += &switch_md(long, short);
    md
}

/// The side-by-side tables: final errors, settling times, data and cost.
fn comparison_md(cmp: &Comparison) -> String {
    let mut md = String::new();
    let rows = &cmp.rows;
    let head: Vec<String> = rows.iter().map(short_label).collect();
    let sep = |n: usize| format!("|{}|\n", vec!["---"; n + 1].join("|"));
    let _ = writeln!(
        md,
        "### Side by side on the `identify` plant (Table 2, 150 °/s, 10 g, pump 2·√1.0265·f0)\n\n\
         paper = the raw estimator of eqs. (10)–(19) (P0 = 1e4·I, θ̂(0) = 0, no dither, \
         {COMPARE_RAW_S} s from start-up); product = `identify` (f64 core, 10 s, gate 0.5 s, \
         dither from 1 s). 0 = noise-free, 1 pm = 1 pm/√Hz.\n\n\
         **Final relative error**\n"
    );
    let _ = writeln!(md, "| θ | {} |", head.join(" | "));
    md += &sep(rows.len());
    let names: Vec<String> = THETA_DRIVE_NAMES
        .iter()
        .chain(THETA_SENSE_NAMES.iter())
        .map(|n| n.replace("th", "θ"))
        .collect();
    for j in 0..14 {
        let cells: Vec<String> = rows.iter().map(|r| fe(r.final_rel_err[j])).collect();
        let _ = writeln!(md, "| {} | {} |", names[j], cells.join(" | "));
    }
    let cells: Vec<String> = rows
        .iter()
        .map(|r| {
            format!(
                "{:.3} ({})",
                r.rate_dps_est,
                fe(rel_err(r.rate_dps_est, r.rate_dps_true))
            )
        })
        .collect();
    let _ = writeln!(md, "| rate °/s (rel. err) | {} |", cells.join(" | "));
    let _ = writeln!(
        md,
        "\n**Time from t = 0 after which the error stays within 10 % / 1 % (s; product: dither starts at 1 s)**\n"
    );
    let _ = writeln!(md, "| θ | {} |", head.join(" | "));
    md += &sep(rows.len());
    for j in 0..14 {
        let cells: Vec<String> = rows
            .iter()
            .map(|r| format!("{} / {}", ft(r.within_10pct_s[j]), ft(r.within_1pct_s[j])))
            .collect();
        let _ = writeln!(md, "| {} | {} |", names[j], cells.join(" | "));
    }
    let _ = writeln!(md, "\n**Data and cost**\n");
    let _ = writeln!(md, "| | {} |", head.join(" | "));
    md += &sep(rows.len());
    let line = |name: &str, f: &dyn Fn(&CompareRow) -> String| {
        let cells: Vec<String> = rows.iter().map(f).collect();
        format!("| {name} | {} |\n", cells.join(" | "))
    };
    md += &line("consumes", &|r| r.data.clone());
    md += &line("sample instants / s", &|r| {
        format!("{:.0}", r.samples_per_s)
    });
    md += &line("real values / s", &|r| format!("{:.0}", r.values_per_s));
    md += &line("simulated s", &|r| format!("{:.1}", r.sim_s));
    md += &line("wall s (2 jobs on 2 cores)", &|r| {
        format!("{:.2}", r.wall_s)
    });
    md += &line("estimator blow-up", &|r| {
        r.blowup_s.map_or("no".into(), |t| format!("{t:.4} s"))
    });
    md
}

/// The ±50 % table: one row per run.
fn switch_md(long: &[&SwitchResult], short: &[&SwitchResult]) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "\n### The paper's ±50 % test (eqs. 25 → 26 → 27), raw estimator, noise-free\n\n\
         Per set: drive amplitude at its end / nominal, worst θ error at its end (θ14, θ17 in \
         brackets), all θ within 10 % after the switch (s).\n"
    );
    let _ = writeln!(
        md,
        "| run | λ | steps/period | per set | eq. 25 | eq. 26 (+50 %) | eq. 27 (−50 %) | blow-up | wall s / sim s |"
    );
    md += "|---|---|---|---|---|---|---|---|---|\n";
    for r in long.iter().chain(short) {
        let cells: Vec<String> = r
            .segments
            .iter()
            .map(|s| {
                let worst = s.final_rel_err.iter().copied().fold(0.0, f64::max);
                let all10 = if s.within_10pct_s.iter().all(Option::is_some) {
                    format!(
                        "{:.4}",
                        s.within_10pct_s
                            .iter()
                            .flatten()
                            .copied()
                            .fold(0.0, f64::max)
                    )
                } else {
                    "never".into()
                };
                format!(
                    "A {:.2e} · err {} ({}, {}) · {all10}",
                    s.drive_amp_end / r.drive_amp_nominal,
                    fe(worst),
                    fe(s.final_rel_err[3]),
                    fe(s.final_rel_err[6]),
                )
            })
            .collect();
        let sim = r.run.records.last().map_or(0.0, |x| x.t_s);
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} s | {} | {} | {:.2} / {:.2} |",
            r.name,
            r.lambda.label(),
            r.steps_per_period,
            r.segment_s,
            cells.join(" | "),
            r.run
                .estimator_blowup_s
                .map_or("no".into(), |t| format!("{t:.4} s")),
            r.run.wall_s,
            sim
        );
    }
    md
}
