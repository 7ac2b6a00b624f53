//! Stage 6, how far the gap closes: the simulator re-run on the record's inputs with the
//! verdict's effect(s) at their fitted sizes over the held-out span, its output error
//! against the model's, and the envelopes for the plot.

use paragyro_core::Cplx;
use paragyro_core::physics::rate_dps_from_gamma;
use paragyro_simulator::effects::{Effect, EffectSpec, Signature};
use serde::{Deserialize, Serialize};

use super::columns::Columns;
use super::lsq::Fit;
use super::report::Limitation;
use super::resim::{OutputError, Resim, lockin_noise_diff_ratio, output_error};
use super::rows::Rows;
use super::verdict::Decision;
use super::{Model, Stage, Timing};

/// What the re-simulation with the verdict's effect(s) does to the output error
/// (report.json's `output_error`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HowFar {
    /// The held-out span, s.
    pub held_out_span_s: [f64; 2],
    /// The model's output error.
    pub before: OutputError,
    /// With the verdict's effect(s).
    pub after: OutputError,
    /// 1 − after/before of the error above the record's noise.
    pub closure: f64,
    /// 1 − after/before of the raw error.
    pub closure_raw: f64,
    /// The lock-in noise's `E|Δn|²/E|n|²` ([`lockin_noise_diff_ratio`]).
    pub noise_diff_ratio: f64,
    /// The effects added (`NAME=SIZE[@PARAM]`).
    pub added: Vec<String>,
    /// The rate the simulator ran with (none with a rate table), °/s.
    pub rate_dps: Option<f64>,
    /// What the numbers are.
    pub note: String,
}

const NOTE: &str = "rms of the lock-in channel errors (DC, 1st, 3rd harmonics of each axis) relative to the rms of the record's channels, on the held-out span; above_noise removes the record's own noise (estimated from the error's sample-to-sample differences); closure uses above_noise; simulator re-run open-loop on the record's pump, amplitude, accelerations and temperature";

/// The result of this stage.
pub(crate) struct Far {
    /// The output error before and after (with the re-simulation).
    pub report: Option<HowFar>,
    /// The rate fitted (none with a rate table).
    pub gamma_fit: Option<f64>,
    /// Envelopes on the held-out span (see [`super::PlotData::envelopes`]).
    pub envelopes: Vec<[f64; 11]>,
}

/// The verdict's effects at their fitted sizes (from the fit of exactly their columns) and
/// the vibration's phase.
fn verdict_specs(cols: &Columns, rows: &Rows, decision: &Decision) -> Specs {
    if decision.verdict_cols.is_empty() {
        return Specs::default();
    }
    specs_of(
        cols,
        rows.gpd,
        &decision.verdict.effects(),
        &decision.after_fit,
    )
}

/// Effects at their fitted sizes ([`specs_of`]).
#[derive(Debug, Default)]
pub(crate) struct Specs {
    /// The effects whose columns the fit holds, at their sizes.
    pub specs: Vec<EffectSpec>,
    /// The angular vibration's phase (0 without it).
    pub vib_phase: f64,
    /// The effects left out, each with why (`NAME: reason`).
    pub skipped: Vec<String>,
}

/// The coefficient of the bank column `c` in the fit `f` (by the column's identity, not
/// its position: the fit may hold fewer columns than the effects asked about).
fn coef(f: &Fit, c: usize) -> Option<f64> {
    f.cols
        .iter()
        .position(|&j| j == c)
        .and_then(|a| f.beta.get(a).copied())
}

/// `effects` at their sizes in `f` (the vibration's γ over `gpd`, γ per °/s), each effect's columns looked up in the fit by their
/// bank index, and the vibration's phase. An effect is left out, with the reason in
/// [`Specs::skipped`], when it has no column of its own on this record (a parameter-face
/// effect such as the anisodamping the calibration names against a rate table: the
/// calibrated model carries it already; or an effect the record cannot test), when the fit
/// does not hold its columns, or when its fitted size is not finite.
pub(crate) fn specs_of(cols: &Columns, gpd: f64, effects: &[Effect], f: &Fit) -> Specs {
    let mut out = Specs::default();
    for &effect in effects {
        let ec = cols.of(effect);
        if ec.is_empty() {
            out.skipped.push(format!(
                "{effect}: no column of its own on this record (a parameter-face effect is carried by the calibrated model; an untestable one cannot be sized)"
            ));
            continue;
        }
        let betas: Option<Vec<f64>> = ec.iter().map(|&c| coef(f, c)).collect();
        let Some(betas) = betas else {
            out.skipped.push(format!(
                "{effect}: its columns are not in the fit it was to be sized from"
            ));
            continue;
        };
        let (spec, phase) = match spec_of(effect, &betas, cols.beat, gpd) {
            Ok(v) => v,
            Err(why) => {
                out.skipped.push(format!("{effect}: {why}"));
                continue;
            }
        };
        if let Some(p) = phase {
            out.vib_phase = p;
        }
        out.specs.push(spec);
    }
    out
}

/// `effect` at the size its fitted coefficients `betas` give (its columns' order), with the
/// angular vibration's phase: the vibration's γ over `gpd` (γ per °/s) at the scanned
/// `beat`, the softening driven by the pump. Why not, when the coefficients are not the
/// effect's or its size is not finite.
pub(crate) fn spec_of(
    effect: Effect,
    betas: &[f64],
    beat: f64,
    gpd: f64,
) -> Result<(EffectSpec, Option<f64>), String> {
    let (spec, phase) = if effect.signature() == Some(Signature::Vibration) {
        match betas {
            &[gr, gi] => (
                EffectSpec {
                    effect,
                    size: gr.hypot(gi) / gpd,
                    param: Some(beat),
                },
                Some(gi.atan2(gr)),
            ),
            _ => return Err(format!("{} of its 2 columns on this record", betas.len())),
        }
    } else {
        let Some(&size) = betas.first() else {
            return Err("no column of its own on this record".into());
        };
        (
            EffectSpec {
                effect,
                size,
                // the structural face tests the softening driven by the pump
                param: (effect == Effect::ElectrostaticSoftening).then_some(1.0),
            },
            None,
        )
    };
    if !spec.size.is_finite() || phase.is_some_and(|p| !p.is_finite()) {
        return Err("its fitted size is not finite".into());
    }
    Ok((spec, phase))
}

/// Re-runs the simulator with the verdict's effect(s) on the held-out span: the calibrated
/// model with its θ refitted jointly with the effect (`model_after`; the calibration alone
/// absorbed part of the effect), against the calibrated model alone.
pub(crate) fn how_far(
    st: &Stage<'_>,
    decision: &Decision,
    model_after: &Model,
    timing: &mut Timing,
    limits: &mut Vec<Limitation>,
) -> Far {
    let Stage {
        rec,
        opts,
        rows,
        spans,
        cols,
        fits: _,
    } = *st;
    let gamma_fit = match (&rows.rate_ref, rows.gamma_sim) {
        (Some(_), _) => None,
        (None, Some(g)) => Some(g),
        (None, None) => Some(rows.gamma_nom),
    };
    let Specs {
        specs,
        vib_phase,
        skipped,
    } = verdict_specs(cols, rows, decision);
    for why in skipped {
        limits.push(Limitation::new(
            "output_error",
            format!("the re-simulation with the verdict's effects leaves out {why}"),
        ));
    }
    timing.tick("ranking_and_where");
    let Some(before) = &rows.before_sim else {
        return Far {
            report: None,
            gamma_fit,
            envelopes: Vec::new(),
        };
    };
    let (hold_start, last) = (spans.hold_start, spans.last);
    // the effect's run covers the held-out span (starting 0.5 s early from the record)
    let resim = Resim {
        rec,
        model: model_after,
        gamma: gamma_fit.map(|_| model_after.phys.gamma),
        rate_ref: rows.rate_ref.as_deref(),
        effects: &specs,
        vib_phase0: vib_phase,
        steps_per_period: opts.steps_per_period,
    };
    let mut after = before.clone();
    let mut added = specs.iter().map(|s| s.to_string()).collect();
    if !specs.is_empty() {
        // (no effect added: the run would be the calibrated model's again)
        match resim.run(hold_start..last + 1) {
            Ok(after_h) if after_h.len() == last + 1 - hold_start => {
                after[hold_start..last + 1].clone_from_slice(&after_h);
            }
            Ok(after_h) => {
                limits.push(Limitation::new(
                    "output_error",
                    format!(
                        "the re-simulation with the verdict's effects gave {} samples for the {} of the held-out span: 'after' is the calibrated model's",
                        after_h.len(),
                        last + 1 - hold_start
                    ),
                ));
                added = Vec::new();
            }
            Err(e) => {
                limits.push(Limitation::new(
                    "output_error",
                    format!(
                        "the re-simulation with the verdict's effects failed ({e:#}): 'after' is the calibrated model's"
                    ),
                ));
                added = Vec::new();
            }
        }
    }
    let ratio = match lockin_noise_diff_ratio(rec) {
        Ok(r) => r,
        Err(e) => {
            limits.push(Limitation::new(
                "output_error",
                format!(
                    "the lock-in noise's difference ratio could not be computed ({e:#}): 1 taken"
                ),
            ));
            1.0
        }
    };
    let b = output_error(rec, before, hold_start..last + 1, ratio);
    let a = output_error(rec, &after, hold_start..last + 1, ratio);
    let cl = |x: f64, y: f64| if x > 0.0 { 1.0 - y / x } else { 0.0 };
    let report = HowFar {
        held_out_span_s: [rows.t[hold_start], rows.t[last]],
        before: b,
        after: a,
        closure: cl(b.above_noise, a.above_noise),
        closure_raw: cl(b.combined, a.combined),
        noise_diff_ratio: ratio,
        added,
        rate_dps: gamma_fit.map(|g| rate_dps_from_gamma(g, rows.omega0)),
        note: NOTE.into(),
    };
    timing.tick("resimulate_with_effect");
    let stride = ((last + 1 - hold_start) / 2000).max(1);
    let l0 = rec.header.l0_um;
    let mut envelopes = Vec::new();
    for k in (hold_start..=last).step_by(stride) {
        let r = &rec.rows[k];
        let h = |v: Cplx<f64>| v.re.hypot(v.im);
        let d = |a: Cplx<f64>, b: Cplx<f64>| (a.re - b.re * l0).hypot(a.im - b.im * l0);
        envelopes.push([
            rows.t[k],
            h(r.lockin.x_um[0]),
            h(r.lockin.y_um[0]),
            h(before[k].x_um[0]) * l0,
            h(before[k].y_um[0]) * l0,
            h(after[k].x_um[0]) * l0,
            h(after[k].y_um[0]) * l0,
            d(r.lockin.x_um[0], before[k].x_um[0]),
            d(r.lockin.y_um[0], before[k].y_um[0]),
            d(r.lockin.x_um[0], after[k].x_um[0]),
            d(r.lockin.y_um[0], after[k].y_um[0]),
        ]);
    }
    Far {
        report: Some(report),
        gamma_fit,
        envelopes,
    }
}

#[cfg(test)]
mod tests {
    use paragyro_simulator::effects::Effect;

    use super::specs_of;
    use crate::diagnose::columns::{Column, ColumnId, Columns};
    use crate::diagnose::lsq::Fit;

    /// The bank of a record with a rate table: the 14 θ, a feedthrough column, the
    /// vibration's pair (no column for the anisodamping: the parameter face tests it).
    fn bank() -> Columns {
        let ids = (0..14)
            .map(ColumnId::Theta)
            .chain([
                ColumnId::Effect(Effect::Feedthrough),
                ColumnId::Vibration(false),
                ColumnId::Vibration(true),
            ])
            .map(|id| Column { id, v: Vec::new() });
        Columns {
            cols: ids.collect(),
            base_cols: (0..14).collect(),
            ca_idx: Vec::new(),
            untestable: vec![(Effect::Anisodamping, "parameter face".into())],
            beat: 2.5,
            dither_hz: Vec::new(),
        }
    }

    /// A fit of the bank columns `cols`, coefficient `100 + column` each.
    fn fit(cols: &[usize]) -> Fit {
        let p = cols.len();
        Fit {
            cols: cols.to_vec(),
            beta: cols.iter().map(|&c| 100.0 + c as f64).collect(),
            sigma: vec![1.0; p],
            cov: vec![0.0; p * p],
            e_fit: 0.0,
            e_hold: 0.0,
        }
    }

    /// Issue 31 (howfar.rs:86, "the len is 15 but the index is 15"): the parameter face
    /// names the anisodamping against a rate table and a second effect tops it; the fit of
    /// the verdict's columns holds the 14 θ and the second effect's column only. The
    /// anisodamping was read at the second effect's position and the second effect past
    /// the end. Now each is looked up by its columns: the second at its own coefficient,
    /// the anisodamping left out with its reason.
    #[test]
    fn a_parameter_face_effect_without_columns_is_left_out_with_its_reason() {
        let cols = bank();
        let base: Vec<usize> = (0..14).collect();
        let f = fit(&cols.with(&[14]));
        let s = specs_of(&cols, 1.0, &[Effect::Anisodamping, Effect::Feedthrough], &f);
        assert_eq!(s.specs.len(), 1, "{s:?}");
        assert_eq!(s.specs[0].effect, Effect::Feedthrough);
        assert_eq!(s.specs[0].size, 114.0);
        assert_eq!(s.skipped.len(), 1);
        assert!(s.skipped[0].starts_with("anisodamping: no column"), "{s:?}");
        // howfar.rs:75 ("the len is 16 but the index is 16"): the vibration as the second
        let f = fit(&cols.with(&[15, 16]));
        let s = specs_of(
            &cols,
            2.0,
            &[Effect::Anisodamping, Effect::AngularVibration],
            &f,
        );
        assert_eq!(s.specs.len(), 1, "{s:?}");
        assert_eq!(s.specs[0].effect, Effect::AngularVibration);
        assert!((s.specs[0].size - 115.0f64.hypot(116.0) / 2.0).abs() < 1e-12);
        assert_eq!(s.specs[0].param, Some(2.5));
        assert!((s.vib_phase - 116.0f64.atan2(115.0)).abs() < 1e-15);
        // a fit that does not hold an effect's columns at all (the baseline's alone)
        let s = specs_of(
            &cols,
            1.0,
            &[Effect::Feedthrough, Effect::AngularVibration],
            &fit(&base),
        );
        assert!(s.specs.is_empty(), "{s:?}");
        assert_eq!(s.skipped.len(), 2);
        assert!(
            s.skipped.iter().all(|w| w.contains("not in the fit")),
            "{s:?}"
        );
        // columns in another order than the effects': still each its own
        let f = fit(&cols.with(&[16, 14, 15]));
        let s = specs_of(
            &cols,
            1.0,
            &[Effect::Feedthrough, Effect::AngularVibration],
            &f,
        );
        assert_eq!(s.specs.len(), 2, "{s:?}");
        assert_eq!(s.specs[0].size, 114.0);
        assert!((s.specs[1].size - 115.0f64.hypot(116.0)).abs() < 1e-12);
    }

    /// A fitted size that is not finite is not handed to the simulator.
    #[test]
    fn a_size_that_is_not_finite_is_left_out() {
        let cols = bank();
        let mut f = fit(&cols.with(&[14]));
        f.beta[14] = f64::NAN;
        let s = specs_of(&cols, 1.0, &[Effect::Feedthrough], &f);
        assert!(s.specs.is_empty());
        assert!(s.skipped[0].contains("not finite"), "{s:?}");
    }

    /// The crash path itself, end to end on a record with a rate table: the stages run to
    /// the verdict, which is then set as the parameter face names it with a second effect
    /// on top (`anisodamping` and `feedthrough`, the feedthrough's columns fitted with the
    /// baseline's). `how_far` stays within the fit: the re-simulation adds the
    /// feedthrough alone and says why the anisodamping is left out.
    #[test]
    fn how_far_with_a_face_named_anisodamping_under_a_second_effect() {
        use crate::diagnose::verdict::{Answer, Decision, Secondary, Verdict};
        use crate::diagnose::{Options, Stage, Timing, calibration, columns, rank};
        use paragyro_simulator::record::{RecordOptions, simulate_record_with};
        use paragyro_simulator::scenario::Scenario;

        let mut sc = Scenario::load("characterise").unwrap();
        sc.duration_s = 4.0;
        let ro = RecordOptions {
            seed: Some(3),
            effects: vec!["feedthrough=3e-4".parse().unwrap()],
            rate_table: true,
            temp: None,
        };
        let (rec, _) = simulate_record_with(&sc, &ro, &mut |_| {}).unwrap();
        let mut timing = Timing::new();
        let mut limits = Vec::new();
        let (mut rows, spans, opts, fit1, _) =
            calibration(&rec, &Options::default(), &mut timing, &mut limits).unwrap();
        rows.remove_theta(&fit1.dtheta);
        let cols = columns::Columns::build(&rec, &opts, &rows, &spans)
            .unwrap()
            .with_catch_all_columns(columns::catch_all_columns(&rows.base, &rows.svf));
        let fits = rank::Fits::build(&cols, &rows, &spans);
        assert!(cols.of(Effect::Anisodamping).is_empty());
        let verdict_cols = cols.of(Effect::Feedthrough);
        let after_fit = fits.bank.fit(&cols.with(&verdict_cols));
        assert_eq!(after_fit.beta.len(), 15);
        let decision = Decision {
            verdict: Verdict::Effects {
                primary: Effect::Anisodamping,
                secondary: Some(Secondary {
                    effect: Effect::Feedthrough,
                    added_closure: 0.5,
                }),
            },
            closest: Answer::Effect(Effect::Anisodamping),
            verdict_cols,
            after_fit,
            unexplained: 0.0,
            unexplained_rows: Vec::new(),
            gap_fraction: 0.0,
            gap_before: 0.0,
            gap_after: 0.0,
            residual_over_noise: 1.0,
        };
        let st = Stage {
            rec: &rec,
            opts: &opts,
            rows: &rows,
            spans: &spans,
            cols: &cols,
            fits: &fits,
        };
        let far = super::how_far(&st, &decision, &opts.model, &mut timing, &mut limits);
        let report = far.report.expect("an output error");
        assert_eq!(report.added.len(), 1, "{:?}", report.added);
        assert!(
            report.added[0].starts_with("feedthrough="),
            "{:?}",
            report.added
        );
        assert!(report.after.combined.is_finite());
        assert!(
            limits
                .iter()
                .any(|l| l.stage == "output_error" && l.detail.contains("anisodamping: no column")),
            "{limits:?}"
        );
    }
}
