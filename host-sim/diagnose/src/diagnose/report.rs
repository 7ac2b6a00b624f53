//! The typed result of a diagnosis: [`Report`] is report.json (serde derive; keys in
//! alphabetical order, as the file has always had them), [`PlotData`] what the plots need;
//! [`write_report`] writes report.json, report.md and the plots.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Context;
use paragyro_core::physics::rate_dps_from_gamma;
use paragyro_simulator::effects::Effect;
use paragyro_simulator::record::Record;
use serde::{Deserialize, Serialize};

pub use super::calibrate::ParameterFace;
use super::columns::Columns;
pub use super::confirm::Confirmation;
use super::howfar::Far;
pub use super::howfar::HowFar;
pub use super::locate::{AxisShare, Regime, Tercile, TimeSpan};
use super::locate::{LocatePlots, Located, RowEnergy, Where};
use super::rank::Fits;
use super::rows::{Rows, Spans};
use super::verdict::{Answer, Decision, Verdict};
use super::{
    COHERENT, CONFIRM_NOISE_MAX, GAP_MIN, GUARD_S, NOISE_ROW_ENERGY, NONE_NOISE_MAX, Options,
    ROW_GAP_MIN, ROW_GAP_SHARE, ROW_LABELS, ROW_UNEXPLAINED_MAX, SECOND_MIN, SHARE_MIN, T_SIG,
    UNEXPLAINED_MAX, VIB_BEAT_CYCLES, VIB_BEAT_MAX_HZ, VIB_NOISE_T,
};

/// The format tag of report.json (3: format 2's keys and `confirmation`).
pub const FORMAT: &str = "paragyro-diagnosis 3";

/// One candidate's result.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// The effect.
    pub effect: Effect,
    /// Fitted size in the effect's unit (see [`paragyro_simulator::effects`]); `None` when
    /// the record cannot test it.
    pub size: Option<f64>,
    /// Its 1σ uncertainty (cluster-robust).
    pub size_sigma: Option<f64>,
    /// Held-out gap closure (E0 − E_c)/(E0 − E_floor).
    pub gap_closure: f64,
    /// Whether it is significant (|size|/σ ≥ T_SIG and closes ≥ GAP_MIN of E0).
    pub significant: bool,
    /// Fraction of the held-out baseline energy it removes.
    pub energy_fraction: f64,
    /// ΔBIC against the baseline on the fit span (negative favours the effect).
    pub delta_bic: f64,
    /// What remains explainable after it (catch-all on its residual), as a share of the
    /// explainable gap (the residual check; small is good).
    pub residual_explainable: f64,
    /// Candidates this record cannot tell it apart from.
    pub coherent_with: Vec<Effect>,
    /// Why the candidate could not be tested, if so.
    pub untestable: Option<String>,
    /// Angular vibration: the beat frequency found, Hz.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beat_hz: Option<f64>,
}

/// Held-out energies (report.json's `energies`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Energies {
    /// What the numbers are.
    pub note: String,
    /// The baseline's (E0).
    pub baseline: f64,
    /// The catch-all's.
    pub catch_all: f64,
    /// The floor (the best of any model).
    pub floor: f64,
    /// After the verdict's effect(s).
    pub after: f64,
    /// Weighted rows in the held-out span.
    pub rows: usize,
}

/// Where the rate came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "source")]
pub enum Rate {
    /// The record's rate table fixes it.
    #[serde(rename = "rate_ref_dps (rate table)")]
    Table,
    /// Fitted on the rows.
    #[serde(rename = "fitted")]
    Fitted {
        /// The rate, °/s.
        rate_dps: Option<f64>,
    },
}

impl Rate {
    /// The source as report.json names it.
    pub fn source(&self) -> &'static str {
        match self {
            Rate::Table => "rate_ref_dps (rate table)",
            Rate::Fitted { .. } => "fitted",
        }
    }
}

/// The spans, s.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpansReport {
    /// The fit span.
    pub fit: [f64; 2],
    /// The guard between them.
    pub guard_s: f64,
    /// The held-out span.
    pub held_out: [f64; 2],
}

/// The decision thresholds in force.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Thresholds {
    pub t_sig: f64,
    pub gap_min: f64,
    pub share_min: f64,
    pub second_min: f64,
    pub coherent: f64,
    pub noise_row_energy: f64,
    pub none_noise_max: f64,
    pub unexplained_max: f64,
    pub row_gap_share: f64,
    pub row_gap_min: f64,
    pub row_unexplained_max: f64,
    pub confirm_noise_max: f64,
    pub vib_noise_t: f64,
    pub vib_beat_cycles: f64,
}

impl Thresholds {
    /// The constants of this module.
    pub fn current() -> Self {
        Thresholds {
            t_sig: T_SIG,
            gap_min: GAP_MIN,
            share_min: SHARE_MIN,
            second_min: SECOND_MIN,
            coherent: COHERENT,
            noise_row_energy: NOISE_ROW_ENERGY,
            none_noise_max: NONE_NOISE_MAX,
            unexplained_max: UNEXPLAINED_MAX,
            row_gap_share: ROW_GAP_SHARE,
            row_gap_min: ROW_GAP_MIN,
            row_unexplained_max: ROW_UNEXPLAINED_MAX,
            confirm_noise_max: CONFIRM_NOISE_MAX,
            vib_noise_t: VIB_NOISE_T,
            vib_beat_cycles: VIB_BEAT_CYCLES,
        }
    }
}

/// The vibration's beat scan.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BeatScan {
    /// |beat| ≤ this, Hz.
    pub range_hz: f64,
    /// The beat found, Hz.
    pub best_hz: f64,
    /// The record's dither lines, Hz (pump frequency, pump amplitude; where each moves):
    /// a beat on one or its harmonics is not named at the noise.
    #[serde(default)]
    pub dither_hz: Vec<f64>,
}

/// Candidates this record cannot separate (or test), and the excitation that would.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Separation {
    /// Two coherent candidates, or one untestable.
    pub pair: Vec<Effect>,
    /// The excitation.
    pub excitation: String,
}

/// A stage of the diagnosis that could not run as designed on this record, and what was
/// done instead (report.json's `limitations`, absent when there is none): the diagnosis
/// is total over the records the reader accepts, and an internal inconsistency or an
/// estimate that is not physical becomes one of these, never an abort.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Limitation {
    /// The stage (`calibration`, `confirmation`, `joint_calibration`, `output_error`, …).
    pub stage: String,
    /// What happened and what the diagnosis did instead.
    pub detail: String,
}

impl Limitation {
    /// A limitation of `stage`.
    pub fn new(stage: &str, detail: impl Into<String>) -> Self {
        Limitation {
            stage: stage.into(),
            detail: detail.into(),
        }
    }
}

/// report.json.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// [`FORMAT`].
    pub format: String,
    /// The verdict (`verdict` and `secondary` in the file).
    #[serde(flatten)]
    pub verdict: Verdict,
    /// The candidates, best first, the untestable last.
    pub ranking: Vec<Candidate>,
    /// Held-out gap (row energy above the floor) before and after the verdict's effect(s).
    pub gap_before: f64,
    pub gap_after: f64,
    /// 1 − after/before.
    pub gap_closure: f64,
    /// Explainable share of the held-out baseline energy.
    pub gap_fraction_of_baseline: f64,
    /// Share of the gap above the noise the closest library effect leaves unexplained.
    pub unexplained_above_noise: f64,
    /// Rows ([`ROW_LABELS`]) holding a share of the gap it leaves mostly unexplained.
    pub unexplained_rows: Vec<String>,
    /// The verdict before the residual checks.
    pub closest_library_effect: Answer,
    /// Held-out energy per row.
    pub held_out_by_row: Vec<RowEnergy>,
    pub energies: Energies,
    /// The re-simulation's output error (none without it).
    pub output_error: Option<HowFar>,
    /// The parameter face: the calibrated device against the model, and its hypotheses.
    pub parameter_face: ParameterFace,
    /// The library effects re-simulated when the linear test left the verdict `unknown`
    /// ([`super::confirm`]), in the order tested; empty when that test did not run.
    #[serde(default)]
    pub confirmation: Vec<Confirmation>,
    /// Held-out baseline energy per row over the record's own noise per row (the mean of
    /// [`Report::noise_per_row`] × the record's noise energy ratio): about 1 at the noise.
    pub residual_over_noise: f64,
    /// Each row's noise energy per sample at the reference density (1 pm/√Hz) for this
    /// record, `ROW_LABELS` order: lock-in noise carried through the record's rows and the
    /// calibrated θ (× the noise energy ratio for the record's own; about
    /// `NOISE_ROW_ENERGY` × `NOISE_ROW_PROFILE` on an average device).
    #[serde(default)]
    pub noise_per_row: Vec<f64>,
    #[serde(rename = "where")]
    pub location: Where,
    /// The simulator configuration compared with.
    pub model: String,
    pub rate: Rate,
    pub spans_s: SpansReport,
    pub thresholds: Thresholds,
    pub vibration_beat_scan: BeatScan,
    pub separating_excitation: Vec<Separation>,
    /// Samples in the record.
    pub samples: usize,
    /// Wall time of the diagnosis, s.
    pub seconds: f64,
    /// Wall time per stage, s.
    pub timing_s: BTreeMap<String, f64>,
    /// The stages that could not run as designed on this record ([`Limitation`]); absent
    /// from report.json when there is none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub limitations: Vec<Limitation>,
}

impl Report {
    /// report.md (without the plots, which it links) for the record `record_name`.
    pub fn markdown(&self, record_name: &str) -> String {
        super::markdown::markdown(self, record_name)
    }
}

/// The full result.
#[derive(Clone, Debug)]
pub struct Diagnosis {
    /// report.json.
    pub report: Report,
    /// Data for the plots.
    pub plots: PlotData,
}

/// What the plots need.
#[derive(Clone, Debug, Default)]
pub struct PlotData {
    /// Time of each usable sample, s.
    pub t: Vec<f64>,
    /// Baseline residual energy per sample (weighted, all rows).
    pub e_base: Vec<f64>,
    /// Residual energy per sample after the verdict's effect (or the floor).
    pub e_after: Vec<f64>,
    /// Fit span and held-out span, s.
    pub fit_span: (f64, f64),
    /// Held-out span, s.
    pub hold_span: (f64, f64),
    /// Explainable gap share by axis × channel: (label, share).
    pub shares: Vec<(String, f64)>,
    /// Ranking (effect, gap closure, significant).
    pub ranking: Vec<(Effect, f64, bool)>,
    /// Envelopes on the held-out span: (t, |x1| rec, |y1| rec, |x1| sim before, |y1| sim
    /// before, |x1| after, |y1| after, then |x1 rec − x1 sim| and |y1 rec − y1 sim| before
    /// and after), µm.
    pub envelopes: Vec<[f64; 11]>,
    /// Windowed gap energy over time: (t, baseline − floor).
    pub windows: Vec<(f64, f64)>,
    /// CUSUM of the windowed gap.
    pub cusum: Vec<(f64, f64)>,
}

/// Everything the report is made of.
pub(crate) struct Parts<'a> {
    pub opts: &'a Options,
    pub rows: &'a Rows,
    pub spans: &'a Spans,
    pub cols: &'a Columns,
    pub fits: &'a Fits,
    pub ranking: Vec<Candidate>,
    pub decision: Decision,
    pub face: ParameterFace,
    pub place: Located,
    pub far: &'a Far,
    pub confirmation: Vec<Confirmation>,
    /// Each row's noise energy at the reference density for this record.
    pub row_noise: [f64; super::NR],
    pub seconds: f64,
    pub timing: BTreeMap<String, f64>,
    /// The stages that could not run as designed.
    pub limitations: Vec<Limitation>,
}

/// The report from the stages' results.
pub(crate) fn assemble(p: Parts<'_>) -> Report {
    let (t, d) = (&p.rows.t, &p.decision);
    let rate = match &p.rows.rate_ref {
        Some(_) => Rate::Table,
        None => Rate::Fitted {
            rate_dps: p
                .far
                .gamma_fit
                .map(|g| rate_dps_from_gamma(g, p.rows.omega0)),
        },
    };
    Report {
        format: FORMAT.into(),
        separating_excitation: separating(&p.ranking),
        verdict: d.verdict.clone(),
        ranking: p.ranking,
        gap_before: d.gap_before,
        gap_after: d.gap_after,
        gap_closure: if d.gap_before > 0.0 {
            1.0 - d.gap_after / d.gap_before
        } else {
            0.0
        },
        gap_fraction_of_baseline: d.gap_fraction,
        unexplained_above_noise: d.unexplained,
        unexplained_rows: d.unexplained_rows.iter().map(|&i| ROW_LABELS[i].into()).collect(),
        closest_library_effect: d.closest,
        held_out_by_row: p.place.by_row,
        energies: Energies {
            note: "weighted row energy on the held-out span (unit-noise rows: noise alone gives about one per row)".into(),
            baseline: p.fits.e0,
            catch_all: p.fits.ca_fit.e_hold,
            floor: p.fits.e_floor,
            after: d.after_fit.e_hold,
            rows: p.fits.bank.hold.rows,
        },
        output_error: p.far.report.clone(),
        residual_over_noise: d.residual_over_noise,
        noise_per_row: p.row_noise.to_vec(),
        parameter_face: p.face,
        confirmation: p.confirmation,
        location: p.place.location,
        model: p.opts.model.source.clone(),
        rate,
        spans_s: SpansReport {
            fit: [t[p.spans.first], t[p.spans.fit_end]],
            guard_s: GUARD_S,
            held_out: [t[p.spans.hold_start], t[p.spans.last]],
        },
        thresholds: Thresholds::current(),
        vibration_beat_scan: BeatScan {
            range_hz: VIB_BEAT_MAX_HZ,
            best_hz: p.cols.beat,
            dither_hz: p.cols.dither_hz.clone(),
        },
        samples: t.len(),
        seconds: p.seconds,
        timing_s: p.timing,
        limitations: p.limitations,
    }
}

/// The report of a record no stage of the diagnosis can take (`why`): verdict `unknown`,
/// nothing ranked, fitted or located, and the reason as the one limitation (stage
/// `record`). report.md and the (empty) plots are written from it as from any other.
pub fn not_diagnosed(rec: &Record, opts: &Options, why: &str, seconds: f64) -> Diagnosis {
    let t0 = rec.rows.first().map_or(0.0, |r| r.t_s);
    let t1 = rec.rows.last().map_or(0.0, |r| r.t_s);
    let table = !rec.rows.is_empty()
        && rec
            .rows
            .iter()
            .all(|r| r.rate_ref_dps.is_some_and(f64::is_finite));
    let report = Report {
        format: FORMAT.into(),
        verdict: Verdict::Unknown,
        ranking: Vec::new(),
        gap_before: 0.0,
        gap_after: 0.0,
        gap_closure: 0.0,
        gap_fraction_of_baseline: 0.0,
        unexplained_above_noise: 0.0,
        unexplained_rows: Vec::new(),
        closest_library_effect: Answer::Unknown,
        held_out_by_row: Vec::new(),
        energies: Energies {
            note: "not computed: the record could not be diagnosed (limitations)".into(),
            baseline: 0.0,
            catch_all: 0.0,
            floor: 0.0,
            after: 0.0,
            rows: 0,
        },
        output_error: None,
        parameter_face: ParameterFace {
            parameters: Vec::new(),
            hypotheses: Vec::new(),
            rate_offset_dps: None,
            noise_energy_ratio: 0.0,
            resimulations: 0,
        },
        confirmation: Vec::new(),
        residual_over_noise: 0.0,
        noise_per_row: Vec::new(),
        location: Where {
            axis: super::locate::AxisShare {
                drive: 0.0,
                sense: 0.0,
            },
            channel: BTreeMap::new(),
            regime: Vec::new(),
            time: TimeSpan {
                half_of_gap_within_s: [t0, t1],
                fraction_of_time_holding_half: 0.0,
                cusum_extreme_at_s: t0,
            },
        },
        model: opts.model.source.clone(),
        rate: if table {
            Rate::Table
        } else {
            Rate::Fitted { rate_dps: None }
        },
        spans_s: SpansReport {
            fit: [t0, t0],
            guard_s: GUARD_S,
            held_out: [t1, t1],
        },
        thresholds: Thresholds::current(),
        vibration_beat_scan: BeatScan {
            range_hz: VIB_BEAT_MAX_HZ,
            best_hz: 0.0,
            dither_hz: Vec::new(),
        },
        separating_excitation: Vec::new(),
        samples: rec.rows.len(),
        seconds,
        timing_s: BTreeMap::new(),
        limitations: vec![Limitation::new(
            "record",
            format!(
                "the record cannot be diagnosed: {why}; nothing was fitted, the verdict is `unknown`"
            ),
        )],
    };
    Diagnosis {
        report,
        plots: PlotData::default(),
    }
}

/// The plots' data.
pub(crate) fn plot_data(
    report: &Report,
    rows: &Rows,
    spans: &Spans,
    lp: LocatePlots,
    envelopes: Vec<[f64; 11]>,
) -> PlotData {
    let t = &rows.t;
    PlotData {
        t: lp.t,
        e_base: lp.e_base,
        e_after: lp.e_after,
        fit_span: (t[spans.first], t[spans.fit_end]),
        hold_span: (t[spans.hold_start], t[spans.last]),
        shares: lp.shares,
        ranking: report
            .ranking
            .iter()
            .filter(|c| c.untestable.is_none())
            .map(|c| (c.effect, c.gap_closure, c.significant))
            .collect(),
        envelopes,
        windows: lp.windows,
        cusum: lp.cusum,
    }
}

/// The excitation that separates coherent candidates (and untestable ones).
fn separating(ranking: &[Candidate]) -> Vec<Separation> {
    use Effect::*;
    let how = |a: Effect, b: Effect| -> &'static str {
        let pair = |x: Effect, y: Effect| (a == x && b == y) || (a == y && b == x);
        if pair(ElectrostaticSoftening, ThermalDrift) {
            "a temperature step at constant bias, or a bias-voltage step at constant temperature"
        } else if pair(ElectrostaticSoftening, GeometricNonlinearity) {
            "drive-amplitude steps (geometric shifts ω_y² ∝ |A|², electrostatic does not)"
        } else if pair(NonlinearDamping, GeometricNonlinearity) {
            "ring-down segments (decay rate versus frequency shift)"
        } else if a == Anisodamping || b == Anisodamping {
            "a known rate: a rate table or zero-rate segments"
        } else {
            "amplitude and pump-frequency steps that move the two terms differently"
        }
    };
    let mut out = Vec::new();
    for c in ranking {
        for &o in &c.coherent_with {
            // each pair once, in the order of the names
            if c.effect.name() < o.name() {
                out.push(Separation {
                    pair: vec![c.effect, o],
                    excitation: how(c.effect, o).into(),
                });
            }
        }
        if let Some(u) = &c.untestable {
            out.push(Separation {
                pair: vec![c.effect],
                excitation: u.clone(),
            });
        }
    }
    out
}

/// Pretty JSON of `v` with the keys of every object in alphabetical order (the order
/// report.json, labels.json and score.json have always had).
pub fn to_json_sorted<T: Serialize>(v: &T) -> serde_json::Result<String> {
    Ok(serde_json::to_string_pretty(&serde_json::to_value(v)?)? + "\n")
}

/// Writes report.json, report.md and the plots into `dir`.
pub fn write_report(dir: &Path, d: &Diagnosis, record_name: &str) -> anyhow::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut files = Vec::new();
    let jp = dir.join("report.json");
    std::fs::write(&jp, to_json_sorted(&d.report)?)
        .with_context(|| format!("cannot write {}", jp.display()))?;
    files.push(jp);
    files.extend(crate::diagplot::plots(dir, d)?);
    let mp = dir.join("report.md");
    std::fs::write(&mp, d.report.markdown(record_name))
        .with_context(|| format!("cannot write {}", mp.display()))?;
    files.push(mp);
    Ok(files)
}
