//! The report's figures (the paper's Figs 9–14 style) drawn with the project's plotting kit
//! ([`paragyro_simulator::plot`]): estimates against the truth per θ or physical quantity,
//! and the literal run's amplitudes and θ errors on log axes.

use std::path::Path;

use anyhow::Result;
use paragyro_core::physics::{OMEGA0_TABLE2_RAD_S, Physical, rate_dps_from_gamma};
use paragyro_simulator::plot::{
    Line, Panel, TAB10, TRUE_COLOR, draw_panel, figure_sized, grid, log10_or_gap,
};
use plotters::prelude::{RGBColor, SeriesLabelPosition};

use super::records::{physical_of, theta_rel_errors};
use super::simulate::RawRecord;
use super::switch::SwitchResult;

/// One colour per λ reading.
const LAMBDA_COLORS: [RGBColor; 4] = [TAB10[0], TAB10[2], TAB10[1], TAB10[4]];

/// 14 distinct colours: the shared tab10 palette and four dark ones.
const TAB14: [RGBColor; 14] = [
    TAB10[0],
    TAB10[1],
    TAB10[2],
    TAB10[3],
    TAB10[4],
    TAB10[5],
    TAB10[6],
    TAB10[7],
    TAB10[8],
    TAB10[9],
    RGBColor(0, 0, 128),
    RGBColor(128, 0, 0),
    RGBColor(0, 100, 0),
    RGBColor(0, 0, 0),
];

/// The value of a quantity in a record: the estimate (`true`) or the truth.
type Value = Box<dyn Fn(&RawRecord, bool) -> f64>;

/// A quantity plotted against truth: its name and its value in a record.
pub(super) struct Quantity {
    name: String,
    value: Value,
}

/// Meaning of the 14 θ (eq. 25 order).
const THETA_MEANING: [&str; 14] = [
    "−μx",
    "−(ωx²−γ²+2β1)",
    "−(ωxy²−γ')",
    "−(μxy−2γ)",
    "−(2β3+αx)",
    "−2β1",
    "−2β3",
    "1 (ãx gain)",
    "−μy",
    "−(ωy²−γ²)",
    "−(ωxy²+γ')",
    "−(μxy+2γ)",
    "−αy",
    "1 (ãy gain)",
];

/// θ component `j` (0..14: θ11…θ18, θ21…θ26).
pub(super) fn theta_quantity(j: usize) -> Quantity {
    let name = if j < 8 {
        format!("θ1{} = {}", j + 1, THETA_MEANING[j])
    } else {
        format!("θ2{} = {}", j - 7, THETA_MEANING[j])
    };
    Quantity {
        name,
        value: Box::new(move |r: &RawRecord, est: bool| match (j < 8, est) {
            (true, true) => r.theta_drive_est[j],
            (true, false) => r.theta_drive_true[j],
            (false, true) => r.theta_sense_est[j - 8],
            (false, false) => r.theta_sense_true[j - 8],
        }),
    }
}

/// The physical quantities of the paper's Figs 12–14 (corrected Table 3), γ as the rate.
pub(super) fn physical_quantity(k: usize) -> Quantity {
    let (name, f): (&str, fn(&Physical) -> f64) = match k {
        0 => ("μxy = −(θ14+θ24)/2 (Fig. 12a)", |p| p.mu_xy),
        1 => ("rate from γ = (θ14−θ24)/4, °/s (Fig. 12b)", |p| {
            rate_dps_from_gamma(p.gamma, OMEGA0_TABLE2_RAD_S)
        }),
        2 => ("αx = θ17 − θ15 (Fig. 13a)", |p| p.alpha_x),
        3 => ("ωx² = −θ12 + θ16 + γ² (Fig. 13b)", |p| p.wx2),
        4 => ("ωxy² = −(θ13+θ23)/2 (Fig. 14a)", |p| p.wxy2),
        _ => ("γ' = (θ13−θ23)/2 (Fig. 14b)", |p| p.gamma_p),
    };
    Quantity {
        name: name.to_string(),
        value: Box::new(move |r: &RawRecord, est: bool| {
            let (pe, pt) = physical_of(r);
            f(if est { &pe } else { &pt })
        }),
    }
}

/// y range around a truth curve: its span (at least 10 % of its magnitude) ± 30 %.
fn truth_range(truth: &[f64]) -> (f64, f64) {
    let (lo, hi) = truth
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    if lo > hi {
        return (-1.0, 1.0);
    }
    let mag = lo.abs().max(hi.abs());
    let span = (hi - lo).max(0.1 * mag).max(1e-12);
    (lo - 0.3 * span, hi + 0.3 * span)
}

/// Legend label of a ±50 % run: the λ reading, and the step if it is not the plant's.
fn run_label(r: &SwitchResult) -> String {
    if r.steps_per_period == 128 {
        r.lambda.label()
    } else {
        format!("{}, {} steps/period", r.lambda.label(), r.steps_per_period)
    }
}

/// Estimate-vs-truth panel of quantity `q` for the runs `runs` (one per λ reading, at least
/// one), time in ms (`ms = true`) or s.
fn est_truth_panel(q: &Quantity, runs: &[&SwitchResult], ms: bool, last_row: bool) -> Panel {
    let scale = if ms { 1e3 } else { 1.0 };
    let recs = &runs[0].run.records;
    let truth: Vec<(f64, f64)> = recs
        .iter()
        .map(|r| (r.t_s * scale, (q.value)(r, false)))
        .collect();
    let tv: Vec<f64> = truth.iter().map(|p| p.1).collect();
    let mut y = truth_range(&tv);
    if y.0 == y.1 || tv.iter().all(|v| *v == 0.0) {
        y = (-2e-4, 2e-4);
    }
    let t_end = recs.last().map_or(1.0, |r| r.t_s) * scale;
    let blown: Vec<String> = runs
        .iter()
        .filter_map(|r| {
            r.run
                .estimator_blowup_s
                .map(|t| format!("{} overflows at {:.1} ms", run_label(r), t * 1e3))
        })
        .collect();
    let caption = format!(
        "{}, {} per set{}",
        q.name,
        if ms { "50 ms" } else { "0.5 s" },
        if blown.is_empty() {
            String::new()
        } else {
            format!(" ({})", blown.join("; "))
        }
    );
    let mut p = Panel::new(caption, (0.0, t_end), y);
    p.lines.push(Line::new(truth, TRUE_COLOR, 1).label("true"));
    for (i, r) in runs.iter().enumerate() {
        let pts = r
            .run
            .records
            .iter()
            .map(|x| (x.t_s * scale, (q.value)(x, true)))
            .collect();
        p.lines.push(
            Line::new(pts, LAMBDA_COLORS[i % 4], 3)
                .dashed()
                .label(format!("estimate, {}", run_label(r))),
        );
    }
    if last_row {
        p.x_desc = Some((if ms { "time (ms)" } else { "time (s)" }).into());
    }
    p.vlines = runs[0]
        .run
        .segment_starts_s
        .iter()
        .skip(1)
        .map(|t| t * scale)
        .collect();
    p
}

/// Panels of `quantities` in two columns: the ms-scale runs (left) and the 0.5 s runs.
pub(super) fn plot_est_truth(
    path: &Path,
    title: &str,
    quantities: &[Quantity],
    ms_runs: &[&SwitchResult],
    long_runs: &[&SwitchResult],
) -> Result<()> {
    if ms_runs.is_empty() || long_runs.is_empty() {
        anyhow::bail!("no run to plot in {}", path.display());
    }
    let rows = quantities.len();
    let (root, body) = figure_sized(path, (1500, 260 * rows as u32 + 60), title)?;
    let areas = grid(&body, rows, 2);
    for (i, q) in quantities.iter().enumerate() {
        let last = i + 1 == rows;
        draw_panel(&areas[2 * i], &est_truth_panel(q, ms_runs, true, last))?;
        let mut right = est_truth_panel(q, long_runs, false, last);
        if i == 0 {
            right.legend = Some(SeriesLabelPosition::UpperRight);
        }
        draw_panel(&areas[2 * i + 1], &right)?;
    }
    root.present()?;
    Ok(())
}

/// The literal run: drive/sense amplitude and the θ̂ errors for each λ reading.
pub(super) fn plot_literal(path: &Path, runs: &[&SwitchResult]) -> Result<()> {
    let (root, body) = figure_sized(
        path,
        (1500, 1300),
        "paper-raw literal: eq. 25 → 26 (+50 %) → 27 (−50 %), pump left at ω = √1.0265, no noise",
    )?;
    let areas = grid(&body, 1 + runs.len(), 1);
    let r0 = runs
        .first()
        .ok_or_else(|| anyhow::anyhow!("no literal run to plot"))?;
    let t_end = r0.run.records.last().map_or(1.0, |r| r.t_s);
    let vlines: Vec<f64> = r0.run.segment_starts_s.iter().skip(1).copied().collect();
    draw_panel(&areas[0], &amplitude_panel(r0, t_end, &vlines))?;
    for (k, r) in runs.iter().enumerate() {
        let mut p = Panel::new(
            format!(
                "relative error of θ̂, {}{}",
                run_label(r),
                r.run.estimator_blowup_s.map_or(String::new(), |t| {
                    format!("; estimator overflowed at {t:.4} s")
                })
            ),
            (0.0, t_end),
            (-12.0, 4.0),
        )
        .log_y();
        p.y_desc = "|θ̂ − θ| / |θ|".into();
        if k + 1 == runs.len() {
            p.x_desc = Some("time (s)".into());
        }
        for j in 0..14 {
            let pts = r
                .run
                .records
                .iter()
                .map(|x| (x.t_s, log10_or_gap(theta_rel_errors(x)[j].max(1e-14))))
                .collect();
            let name = if j < 8 {
                format!("θ1{}", j + 1)
            } else {
                format!("θ2{}", j - 7)
            };
            p.lines.push(Line::new(pts, TAB14[j], 1).label(name));
        }
        p.vlines = vlines.clone();
        p.hlines = vec![
            (-2.0, RGBColor(230, 140, 0), "1 %".into()),
            (-1.0, RGBColor(200, 0, 0), "10 %".into()),
        ];
        p.legend = (k == 0).then_some(SeriesLabelPosition::UpperRight);
        p.legend_font_px = 11;
        draw_panel(&areas[1 + k], &p)?;
    }
    root.present()?;
    Ok(())
}

/// Drive and sense amplitude of the literal run on a log axis.
fn amplitude_panel(r0: &SwitchResult, t_end: f64, vlines: &[f64]) -> Panel {
    let mut p = Panel::new(
        format!(
            "drive and sense amplitude (max−min)/2 per ms; drive below 1 % of nominal {} after the +50 % switch",
            r0.drive_below_1pct_after_s
                .map_or("never".into(), |t| format!("{:.0} ms", t * 1e3))
        ),
        (0.0, t_end),
        (-8.0, 1.0),
    )
    .log_y();
    p.y_desc = "amplitude (L0 = 1 µm)".into();
    let recs = &r0.run.records;
    p.lines.push(
        Line::new(
            recs.iter()
                .map(|r| (r.t_s, log10_or_gap(r.drive_amp)))
                .collect(),
            LAMBDA_COLORS[0],
            1,
        )
        .label("drive |X|"),
    );
    p.lines.push(
        Line::new(
            recs.iter()
                .map(|r| (r.t_s, log10_or_gap(r.sense_amp)))
                .collect(),
            LAMBDA_COLORS[2],
            1,
        )
        .label("sense |Y|"),
    );
    p.vlines = vlines.to_vec();
    p.hlines = vec![(
        log10_or_gap(0.01 * r0.drive_amp_nominal),
        RGBColor(200, 0, 0),
        "1 % of the nominal drive".into(),
    )];
    p.legend = Some(SeriesLabelPosition::UpperRight);
    p
}
