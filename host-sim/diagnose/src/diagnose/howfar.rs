//! Stage 6, how far the gap closes: the simulator re-run on the record's inputs with the
//! verdict's effect(s) at their fitted sizes over the held-out span, its output error
//! against the model's, and the envelopes for the plot.

use paragyro_core::Cplx;
use paragyro_core::physics::rate_dps_from_gamma;
use paragyro_simulator::effects::{Effect, EffectSpec, Signature};
use serde::{Deserialize, Serialize};

use super::columns::Columns;
use super::lsq::Fit;
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
fn verdict_specs(cols: &Columns, rows: &Rows, decision: &Decision) -> (Vec<EffectSpec>, f64) {
    if decision.verdict_cols.is_empty() {
        return (Vec::new(), 0.0);
    }
    specs_of(cols, rows, &decision.verdict.effects(), &decision.after_fit)
}

/// `effects` at their sizes in `f`, a fit of the baseline columns followed by exactly
/// theirs in that order, and the vibration's phase.
pub(crate) fn specs_of(
    cols: &Columns,
    rows: &Rows,
    effects: &[Effect],
    f: &Fit,
) -> (Vec<EffectSpec>, f64) {
    let mut specs = Vec::new();
    let mut vib_phase = 0.0;
    let mut k = cols.base_cols.len();
    for &effect in effects {
        if effect.signature() == Some(Signature::Vibration) {
            let (gr, gi) = (f.beta[k], f.beta[k + 1]);
            vib_phase = gi.atan2(gr);
            specs.push(EffectSpec {
                effect,
                size: gr.hypot(gi) / rows.gpd,
                param: Some(cols.beat),
            });
            k += 2;
        } else {
            specs.push(EffectSpec {
                effect,
                size: f.beta[k],
                // the structural face tests the softening driven by the pump
                param: (effect == Effect::ElectrostaticSoftening).then_some(1.0),
            });
            k += 1;
        }
    }
    (specs, vib_phase)
}

/// Re-runs the simulator with the verdict's effect(s) on the held-out span: the calibrated
/// model with its θ refitted jointly with the effect (`model_after`; the calibration alone
/// absorbed part of the effect), against the calibrated model alone.
pub(crate) fn how_far(
    st: &Stage<'_>,
    decision: &Decision,
    model_after: &Model,
    timing: &mut Timing,
) -> anyhow::Result<Far> {
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
    let (specs, vib_phase) = verdict_specs(cols, rows, decision);
    timing.tick("ranking_and_where");
    let Some(before) = &rows.before_sim else {
        return Ok(Far {
            report: None,
            gamma_fit,
            envelopes: Vec::new(),
        });
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
    if !specs.is_empty() {
        // (no effect added: the run would be the calibrated model's again)
        let after_h = resim.run(hold_start..last + 1)?;
        after[hold_start..last + 1].clone_from_slice(&after_h);
    }
    let ratio = lockin_noise_diff_ratio(rec)?;
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
        added: specs.iter().map(|s| s.to_string()).collect(),
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
    Ok(Far {
        report: Some(report),
        gamma_fit,
        envelopes,
    })
}
