//! report.md: the report in words and tables, from the typed [`Report`].

use super::calibrate::{percent_pm, value_to_sigma};
use super::report::Report;
use super::verdict::Answer;
use super::{GAP_MIN, GUARD_S, NONE_NOISE_MAX, SHARE_MIN, T_SIG, UNEXPLAINED_MAX, VIB_NOISE_T};

/// A number with 4 significant digits (scientific when small or large).
fn g4(v: f64) -> String {
    if v == 0.0 || (1e-3..1e5).contains(&v.abs()) {
        format!("{v:.4}")
    } else {
        format!("{v:.3e}")
    }
}

/// The parameter face: the calibrated device against the model, and the hypotheses.
fn parameter_face(s: &mut String, r: &Report) {
    let f = &r.parameter_face;
    s.push_str(&format!(
        "\n## Parameter face (the device calibrated on the record)\n\nRecord noise: {:.3} × the energy of 1 pm/√Hz (estimated from the record); held-out residual of the calibrated model {:.3} × that noise per row.\n\n| parameter | model | device | ± 1σ | deviation | t |\n|---|---|---|---|---|---|\n",
        f.noise_energy_ratio, r.residual_over_noise
    ));
    for p in &f.parameters {
        let dev = match (p.relative, p.relative_sigma) {
            (Some(a), Some(b)) => percent_pm(a, b),
            _ => format!("{:+.3e}", p.device - p.model),
        };
        s.push_str(&format!(
            "| {} | {} | {} | {:.2e} | {dev} | {:+.1} |\n",
            p.name,
            value_to_sigma(p.model, p.sigma),
            value_to_sigma(p.device, p.sigma),
            p.sigma,
            p.t
        ));
    }
    s.push('\n');
    for h in &f.hypotheses {
        s.push_str(&format!("- **{}** ({}): {}\n", h.name, h.status, h.detail));
    }
}

/// The candidates re-simulated when the linear test left the verdict `unknown`.
fn confirmation(s: &mut String, r: &Report) {
    if r.confirmation.is_empty() {
        return;
    }
    s.push_str(&format!(
        "\n\nThe linear test left the verdict `unknown`; re-simulated at their fitted sizes (at most {:.0} % of the gap above the noise may be left, or the residual at most {:.1} × the record's noise, each row at its own noise level):\n\n| effect | gap above the noise left | rows left | residual / noise | runs | steps ended | confirmed |\n|---|---|---|---|---|---|---|\n",
        100.0 * UNEXPLAINED_MAX,
        NONE_NOISE_MAX
    ));
    for c in &r.confirmation {
        let rows: Vec<&str> = c
            .unexplained_rows
            .iter()
            .filter_map(|&i| super::ROW_LABELS.get(i).copied())
            .collect();
        s.push_str(&format!(
            "| `{}` | {:.1} % | {} | {} | {} | {} | {} |\n",
            c.effect,
            100.0 * c.unexplained,
            if rows.is_empty() {
                "–".into()
            } else {
                rows.join(", ")
            },
            g4(c.residual_over_noise),
            c.runs.len(),
            stop_text(c),
            if c.confirmed { "yes" } else { "no" }
        ));
        if let Some(w) = &c.with {
            s.push_str(&format!(
                "| `{}` + `{}` (fitted together about its run{}) | {:.1} % | – | {} | – | – | as a pair |\n",
                w.first.as_deref().unwrap_or(&c.effect),
                w.effect,
                if w.outside_regrowths.is_some() {
                    "; outside the drive's regrowths"
                } else {
                    ""
                },
                100.0 * w.unexplained,
                g4(w.residual_over_noise)
            ));
        }
    }
}

/// Why a candidate's Gauss–Newton steps ended, with the step not taken.
fn stop_text(c: &super::confirm::Confirmation) -> String {
    match (c.stopped, c.next_step) {
        (Some(st), Some(d)) => format!("{st} (next step {:+.2} %)", 100.0 * d),
        (Some(st), None) => st.to_string(),
        (None, _) => "–".into(),
    }
}

/// report.md of a report of the record `record_name`.
pub(crate) fn markdown(r: &Report, record_name: &str) -> String {
    let mut s = format!("# Sim-to-real diagnosis of `{record_name}`\n\n");
    s.push_str(&format!(
        "**Verdict: `{}`**{}\n\nModel: {}. Rate: {}.\n\n",
        r.verdict,
        r.verdict
            .secondary()
            .map(|e| format!(" (and `{}`)", e.effect))
            .unwrap_or_default(),
        r.model,
        r.rate.source()
    ));
    s.push_str(&verdict_text(r));
    limitations(&mut s, r);
    confirmation(&mut s, r);
    parameter_face(&mut s, r);
    how_far(&mut s, r);
    which(&mut s, r);
    place(&mut s, r);
    s.push_str(&format!(
        "\n## Method\n\nThe device's θ calibrated on the fit span (batch least squares, the simulator re-run with them, refined); the record's rows about the calibrated model (the core's estimator, never re-linearised, rows weighted to unit noise) minus the rows of the simulator re-run on the record's inputs; each library effect fitted with the rate on the fit span {:.1}–{:.1} s and scored on the held-out span {:.1}–{:.1} s (guard {GUARD_S} s). The floor is the best held-out energy of any model: each effect, the catch-all (14 θ free plus the quadratic and cubic force monomials), and both together. Thresholds: size/σ ≥ {T_SIG}, gap ≥ {:.0} % of the baseline, verdict share ≥ {:.0} % of the explainable gap, at most {:.0} % of the gap above the noise left unexplained. See host-sim/diagnose/README.md.\n",
        r.spans_s.fit[0],
        r.spans_s.fit[1],
        r.spans_s.held_out[0],
        r.spans_s.held_out[1],
        100.0 * GAP_MIN,
        100.0 * SHARE_MIN,
        100.0 * UNEXPLAINED_MAX
    ));
    s
}

/// The stages that could not run as designed on this record.
fn limitations(s: &mut String, r: &Report) {
    if r.limitations.is_empty() {
        return;
    }
    s.push_str("\n\n## Limitations\n\nStages that could not run as designed on this record, and what was done instead:\n\n");
    for l in &r.limitations {
        s.push_str(&format!("- **{}**: {}\n", l.stage, l.detail));
    }
}

/// What the verdict means, in one sentence.
fn verdict_text(r: &Report) -> String {
    match r.verdict.answer() {
        Answer::None => format!(
            "No significant gap: the best model closes {:.1} % of the held-out baseline row energy (threshold {:.0} %).",
            100.0 * r.gap_fraction_of_baseline,
            100.0 * GAP_MIN
        ),
        Answer::Unknown => format!(
            "A gap exists but no library effect explains it: the closest, `{}`, leaves {:.0} % of the held-out gap above the noise unexplained (at most {:.0} % allowed) or is not significant. An effect outside the library.",
            r.closest_library_effect,
            100.0 * r.unexplained_above_noise,
            100.0 * UNEXPLAINED_MAX
        ),
        Answer::Effect(v) if r.gap_fraction_of_baseline < GAP_MIN => {
            match r
                .ranking
                .iter()
                .find(|c| c.effect == v && c.beat_hz.is_some())
            {
                Some(c) => format!(
                    "`{v}` at the record's noise: the best model closes {:.1} % of the held-out baseline row energy (under the {:.0} % gap), but the vibration stands at {:.1} σ (at least {VIB_NOISE_T}) at a beat of {:+.3} Hz and closes held-out energy it was not fitted on.",
                    100.0 * r.gap_fraction_of_baseline,
                    100.0 * GAP_MIN,
                    c.size.unwrap_or(0.0).abs() / c.size_sigma.unwrap_or(f64::INFINITY),
                    c.beat_hz.unwrap_or(0.0),
                ),
                None => format!(
                    "`{v}` at the record's noise: the best model closes {:.1} % of the held-out baseline row energy (under the {:.0} % gap); the parameter face names it (below).",
                    100.0 * r.gap_fraction_of_baseline,
                    100.0 * GAP_MIN,
                ),
            }
        }
        Answer::Effect(v) => format!(
            "`{v}` is significant and closes {:.0} % of the explainable held-out gap{}.",
            100.0
                * r.ranking
                    .iter()
                    .find(|c| c.effect == v)
                    .map_or(0.0, |c| c.gap_closure),
            if r.confirmation.iter().any(|c| c.confirmed) {
                format!(
                    " (linearly); re-simulated with it, it leaves at most {:.0} % of the gap above the noise (below)",
                    100.0 * UNEXPLAINED_MAX
                )
            } else {
                String::new()
            }
        ),
    }
}

/// ## How far: the regression gap and the output error, before and after.
fn how_far(s: &mut String, r: &Report) {
    s.push_str("\n\n## How far (held-out span)\n\n");
    s.push_str(&format!(
        "| measure | before | after | closure |\n|---|---|---|---|\n| regression gap (row energy above the floor) | {} | {} | {:.1} % |\n",
        g4(r.gap_before),
        g4(r.gap_after),
        100.0 * r.gap_closure
    ));
    if let Some(o) = &r.output_error {
        s.push_str(&format!(
            "| simulator output error above the record's noise (relative rms) | {:.3e} | {:.3e} | {:.1} % |\n| simulator output error, raw (noise included) | {:.3e} | {:.3e} | {:.1} % |\n",
            o.before.above_noise,
            o.after.above_noise,
            100.0 * o.closure,
            o.before.combined,
            o.after.combined,
            100.0 * o.closure_raw
        ));
        s.push_str(&format!(
            "\nRe-run with: {}.\n\n![envelopes](envelopes.png)\n",
            if o.added.is_empty() {
                "nothing added".into()
            } else {
                o.added.join(", ")
            }
        ));
    }
}

/// ## Which: the ranking and what this record cannot separate.
fn which(s: &mut String, r: &Report) {
    s.push_str("\n## Which\n\n| effect | size | ±1σ | gap closure | significant | ΔBIC | left explainable | coherent with |\n|---|---|---|---|---|---|---|---|\n");
    for c in &r.ranking {
        if let Some(u) = &c.untestable {
            s.push_str(&format!(
                "| {} | – | – | – | not testable: {u} | | | |\n",
                c.effect
            ));
            continue;
        }
        let coherent: Vec<&str> = c.coherent_with.iter().map(|e| e.name()).collect();
        s.push_str(&format!(
            "| {} | {} {} | {} | {:.1} % | {} | {:.1} | {:.1} % | {} |\n",
            c.effect,
            g4(c.size.unwrap_or(f64::NAN)),
            c.effect.unit(),
            g4(c.size_sigma.unwrap_or(f64::NAN)),
            100.0 * c.gap_closure,
            if c.significant { "yes" } else { "no" },
            c.delta_bic,
            100.0 * c.residual_explainable,
            coherent.join(", ")
        ));
    }
    if !r.separating_excitation.is_empty() {
        s.push_str("\nWhat this record cannot separate, and the excitation that would:\n\n");
        for v in &r.separating_excitation {
            let pair: Vec<&str> = v.pair.iter().map(|e| e.name()).collect();
            s.push_str(&format!("- {}: {}\n", pair.join(" vs "), v.excitation));
        }
    }
}

/// ## Where: by axis and channel, by regime, in time.
fn place(s: &mut String, r: &Report) {
    let w = &r.location;
    s.push_str("\n![ranking](ranking.png)\n\n## Where\n\n");
    s.push_str(&format!(
        "Axis: drive {:.0} %, sense {:.0} % of the explainable gap energy.\n\n| channel | share |\n|---|---|\n",
        100.0 * w.axis.drive,
        100.0 * w.axis.sense
    ));
    for (k, v) in &w.channel {
        s.push_str(&format!("| {k} | {:.1} % |\n", 100.0 * v));
    }
    s.push_str("\nRegimes (gap density per tercile relative to the mean; correlation of the per-sample gap with the quantity):\n\n| quantity | low | mid | high | correlation |\n|---|---|---|---|---|\n");
    for g in &w.regime {
        let b = |i: usize| {
            g.terciles
                .get(i)
                .map_or(f64::NAN, |t| t.relative_gap_density)
        };
        s.push_str(&format!(
            "| {} | {:.2} | {:.2} | {:.2} | {:+.2} |\n",
            g.quantity,
            b(0),
            b(1),
            b(2),
            g.correlation
        ));
    }
    let tm = &w.time;
    s.push_str(&format!(
        "\nTime: half of the gap energy lies within {:.1}–{:.1} s ({:.0} % of the time); the CUSUM of the windowed gap peaks at {:.1} s.\n\n![where](where.png)\n![time](time.png)\n",
        tm.half_of_gap_within_s[0],
        tm.half_of_gap_within_s[1],
        100.0 * tm.fraction_of_time_holding_half,
        tm.cusum_extreme_at_s
    ));
}
