//! The thermal report of a run through a temperature profile (`paragyro-sim thermal`):
//! how the core holds while the device's frequencies move with its die temperature.
//!
//! From a run of a scenario with a `[temperature]` profile: the covariance resets after
//! start-up, the rate's validity and error before and during the temperature's change, the
//! identified ω̂y² against the truth, the pump centre against twice the sense resonance, the
//! drift the core followed, the sense amplitude against an oracle twin whose pump centre
//! sits at twice the true sense resonance, and the same per kelvin of die temperature (a
//! table and `thermal.png`).

mod scale;
pub use scale::{ScaleBin, scale_bins};

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Result, bail};
use plotters::prelude::{BLACK, BLUE, RED};
use serde::Serialize;

use paragyro_core::{Estimator, Sample, StepOutput};

use crate::lockin::LockinExt;
use crate::plot::{Line, Panel, draw_panel, figure, grid};
use crate::runner::{Device, LoopHooks, closed_loop_hooked, core_config};
use crate::scenario::Scenario;
use crate::trace::TraceRow;

/// The oracle's pump: the core's command with its centre replaced by twice the true sense
/// resonance at the next sample (the dither and the scale kept).
struct OraclePump<'a> {
    sc: &'a Scenario,
    fs_hz: f64,
}

impl LoopHooks<f32> for OraclePump<'_> {
    fn step(
        &mut self,
        k: u64,
        est: &mut Estimator<f32>,
        sample: &mut Sample<f32>,
        _last: &StepOutput,
    ) -> StepOutput {
        let mut out = est.step(sample);
        let t_next = (k + 1) as f64 / self.fs_hz;
        let target = 2.0 * self.sc.sim.f0_hz * self.sc.plant_at(t_next).phys[4].sqrt();
        out.pump_hz_next += target - est.pump_centre_hz();
        out
    }
}

/// The sense amplitude |B1| of every sample of the oracle twin: the same scenario (seed
/// `seed`, f32 core) with the pump centre held at twice the true sense resonance.
pub fn oracle_sense_amp(sc: &Scenario, seed: u64) -> Result<Vec<(f64, f64)>> {
    let cfg = core_config(sc);
    let mut est: Estimator<f32> = cfg
        .build()
        .map_err(|e| anyhow::anyhow!("core configuration: {e}"))?;
    let mut hook = OraclePump {
        sc,
        fs_hz: cfg.fs_hz,
    };
    let mut amp = Vec::new();
    closed_loop_hooked(
        sc,
        seed,
        &Device::default(),
        &mut est,
        &mut hook,
        |_| {},
        |ls| amp.push((ls.t_s, ls.lockin.y_abs(1))),
    )?;
    Ok(amp)
}

/// The modes' frequency TCFs, drive and sense, ppm/K, set to `tcf` (two finite values)
/// (`paragyro-sim thermal --tcf-ppm-k`, `paragyro-fil warm-up --tcf-ppm-k`).
pub fn set_tcf_ppm_k(sc: &mut Scenario, tcf: &[f64]) -> Result<()> {
    let Some(t) = sc.temperature.as_mut() else {
        bail!("scenario '{}' has no [temperature] profile", sc.name);
    };
    match tcf {
        [wx, wy] if wx.is_finite() && wy.is_finite() => {
            (t.tcf_wx_ppm_k, t.tcf_wy_ppm_k) = (*wx, *wy);
            Ok(())
        }
        _ => bail!("--tcf-ppm-k takes two finite values (got {tcf:?})"),
    }
}

/// The profile's one ramp (points: held, ramp start, ramp end) stretched to `ramp_s` and
/// `rise_k`; the run ends 2 s after it (`paragyro-sim thermal --ramp-s/--rise-k`,
/// `paragyro-fil warm-up --ramp-s/--rise-k`).
pub fn reshape_ramp(sc: &mut Scenario, ramp_s: Option<f64>, rise_k: Option<f64>) -> Result<()> {
    let Some(t) = sc.temperature.as_mut() else {
        bail!("scenario '{}' has no [temperature] profile", sc.name);
    };
    let moves = t.points.windows(2).filter(|w| w[1][1] != w[0][1]).count();
    let Some(&[t0, c0]) = t.points.iter().rev().nth(1) else {
        bail!("--ramp-s/--rise-k need a profile of one ramp");
    };
    if moves != 1 || t.points.last().is_none_or(|l| l[1] == c0) {
        bail!(
            "--ramp-s/--rise-k need a profile of one ramp ending at its last point (scenario '{}' has {moves} moves)",
            sc.name
        );
    }
    let last = t.points.last().copied().unwrap_or([t0, c0]);
    let dur = ramp_s.unwrap_or(last[0] - t0);
    let rise = rise_k.unwrap_or(last[1] - c0);
    if !(dur.is_finite() && dur > 0.0 && rise.is_finite() && rise.abs() <= 200.0) {
        bail!("--ramp-s must be > 0 and --rise-k within ±200 K (got {dur} s, {rise} K)");
    }
    if let Some(l) = t.points.last_mut() {
        *l = [t0 + dur, c0 + rise];
    }
    sc.duration_s = t0 + dur + 2.0;
    Ok(())
}

/// Moves a profile of one ramp (as [`reshape_ramp`] takes) to start at `start_s`, its
/// duration and rise kept, the temperature held before it; the run ends 2 s after it.
/// Whether a sudden onset sets the change detector off depends on the dithers' phases at
/// it, so the onset's time is a parameter of a warm-up.
pub fn move_ramp_start(sc: &mut Scenario, start_s: f64) -> Result<()> {
    reshape_ramp(sc, None, None)?;
    let Some(t) = sc.temperature.as_mut() else {
        bail!("scenario '{}' has no [temperature] profile", sc.name);
    };
    let n = t.points.len();
    let (Some(&[t0, c0]), Some(&[t1, c1])) = (t.points.get(n.wrapping_sub(2)), t.points.last())
    else {
        bail!("--start-s needs a profile of one ramp");
    };
    if !(start_s.is_finite() && start_s > 0.0) {
        bail!("--start-s must be > 0 (got {start_s} s)");
    }
    t.points = vec![[0.0, c0], [start_s, c0], [start_s + (t1 - t0), c1]];
    sc.duration_s = start_s + (t1 - t0) + 2.0;
    Ok(())
}

/// The lowest ratio of `amp`'s mean over a whole second of `span` (from its first whole
/// second on) to `oracle`'s mean over the same second; both `(t, value)`. `None` when no
/// second of the span has both.
pub fn lowest_second_ratio(
    amp: &[(f64, f64)],
    oracle: &[(f64, f64)],
    span: (f64, f64),
) -> Option<f64> {
    let mean = |v: &[(f64, f64)], t: f64| {
        let (s, n) = v
            .iter()
            .filter(|(ts, _)| (t..t + 1.0).contains(ts))
            .fold((0.0, 0usize), |(s, n), x| (s + x.1, n + 1));
        if n == 0 { f64::NAN } else { s / n as f64 }
    };
    let mut worst: Option<f64> = None;
    let mut t = span.0.ceil();
    while t + 1.0 <= span.1 {
        let r = mean(amp, t) / mean(oracle, t);
        if r.is_finite() {
            worst = Some(worst.map_or(r, |w: f64| w.min(r)));
        }
        t += 1.0;
    }
    worst
}

/// Start-up excluded from every figure, s (the identification converges, the dither starts).
pub const STARTUP_S: f64 = 2.5;

/// The change's first seconds, left out of [`ThermalReport::rate_err_rms_after_onset_dps`]:
/// a ramp that starts within a sample moves the rate by up to ≈ 1.5 °/s while the drift
/// tracker's lead catches up (host-sim/docs/benchmarks.md, "Through temperature").
pub const ONSET_S: f64 = 0.5;

/// One kelvin of die temperature during the change.
#[derive(Clone, Debug, Serialize)]
pub struct KelvinBin {
    /// The bin's centre, °C.
    pub temp_c: f64,
    /// Samples in it.
    pub samples: usize,
    /// Share of them with the rate flagged valid.
    pub valid: f64,
    /// Mean and rms of the rate error (fast channel − truth), °/s.
    pub rate_err_mean_dps: f64,
    pub rate_err_rms_dps: f64,
    /// Mean pump centre − 2·f_y (the sense resonance), Hz.
    pub pump_offset_mean_hz: f64,
}

/// The thermal figures of one run.
#[derive(Clone, Debug, Serialize)]
pub struct ThermalReport {
    /// The scenario's name.
    pub scenario: String,
    /// When the die temperature changes, s (first to last move of the profile).
    pub change_s: (f64, f64),
    /// The die temperature at its start and end, °C.
    pub temp_c: (f64, f64),
    /// Covariance resets after start-up ([`STARTUP_S`]).
    pub resets_after_startup: u32,
    /// Change alarms read as a drift after start-up (the drift column's walk opened
    /// instead of a reset).
    pub drift_alarms_after_startup: u32,
    /// Share of the samples with the rate flagged valid: during the change, and from
    /// start-up to the change.
    pub valid_during: f64,
    pub valid_before: f64,
    /// rms of the rate error before and during the change, and its largest magnitude
    /// during it (every sample, valid or not), °/s.
    pub rate_err_rms_before_dps: f64,
    pub rate_err_rms_during_dps: f64,
    pub rate_err_max_during_dps: f64,
    /// rms of the rate error during the change after its first [`ONSET_S`], and its mean
    /// over the whole change, °/s (every sample): what the onset takes, and how much of
    /// the rms is an offset.
    pub rate_err_rms_after_onset_dps: f64,
    pub rate_err_mean_during_dps: f64,
    /// Largest |ω̂y² − ωy²| during the change.
    pub wy2_err_max: f64,
    /// Largest |pump centre − 2·f_y| during the change, Hz.
    pub pump_offset_max_hz: f64,
    /// Largest drift of θ22 the core followed, ppm/s, and the truth's ωy² rate, ppm/s.
    pub drift_th22_max_ppm_s: f64,
    pub wy2_rate_max_ppm_s: f64,
    /// The lowest ratio, over the whole seconds of the change, of the mean sense amplitude
    /// to the oracle twin's (its pump centre at twice the true sense resonance); `None`
    /// without the twin.
    pub sense_amp_vs_oracle_min: Option<f64>,
    /// The samples carry the die temperature (the scenario's `sensor`).
    pub sensor: bool,
    /// The frequency TCFs (drive, sense) the core has learned by the end of the run, and
    /// the scenario's, ppm/K (NaN: not learned).
    pub tcf_learned_ppm_k: [f64; 2],
    pub tcf_truth_ppm_k: [f64; 2],
    /// Per kelvin of die temperature during the change.
    pub bins: Vec<KelvinBin>,
    /// The rate's scale factor and bias per 5 K, where the rate alternates between ±Ω
    /// (module `scale`; empty otherwise).
    pub scale: Vec<ScaleBin>,
}

fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        (s / n as f64).sqrt()
    }
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    if n == 0 { f64::NAN } else { s / n as f64 }
}

fn share(rows: &[&TraceRow]) -> f64 {
    if rows.is_empty() {
        return f64::NAN;
    }
    rows.iter().filter(|r| r.rate_valid).count() as f64 / rows.len() as f64
}

/// Twice the sense resonance, Hz: 2·f0·√ωy² (ωy² non-dimensional, f0 the drive's).
fn pump_target_hz(sc: &Scenario, r: &TraceRow) -> f64 {
    2.0 * sc.sim.f0_hz * r.phys_true[4].sqrt()
}

impl ThermalReport {
    /// The figures of a run of `sc` (which must have a `[temperature]` profile that moves).
    pub fn of(sc: &Scenario, trace: &[TraceRow]) -> Result<Self> {
        let Some(tp) = &sc.temperature else {
            bail!(
                "scenario '{}' has no [temperature] profile: a thermal report needs one (host-sim/scenarios/README.md)",
                sc.name
            );
        };
        let Some((t0, t1)) = tp.moving_s() else {
            bail!("scenario '{}': its die temperature never changes", sc.name);
        };
        let t0 = t0.max(STARTUP_S);
        let t1 = t1.min(sc.duration_s);
        if t1 <= t0 {
            bail!(
                "scenario '{}': the temperature changes only before start-up ends ({STARTUP_S} s) or after the run",
                sc.name
            );
        }
        let during: Vec<&TraceRow> = trace.iter().filter(|r| (t0..t1).contains(&r.t_s)).collect();
        let before: Vec<&TraceRow> = trace
            .iter()
            .filter(|r| (STARTUP_S..t0).contains(&r.t_s))
            .collect();
        let err = |r: &&TraceRow| r.rate_dps_est - r.rate_dps_true;
        let resets_at = |t: f64| trace.iter().find(|r| r.t_s >= t).map_or(0, |r| r.resets);
        let last = trace.last().map_or(0, |r| r.resets);
        let alarms_at = |t: f64| {
            trace
                .iter()
                .find(|r| r.t_s >= t)
                .map_or(0, |r| r.drift_alarms)
        };
        let last_alarms = trace.last().map_or(0, |r| r.drift_alarms);
        let wy2_rate = during
            .windows(2)
            .map(|w| {
                let dt = w[1].t_s - w[0].t_s;
                ((w[1].phys_true[4] / w[0].phys_true[4] - 1.0) / dt * 1e6).abs()
            })
            .fold(0.0, f64::max);
        let mut bins: Vec<KelvinBin> = Vec::new();
        let (lo, hi) = during
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), r| {
                (l.min(r.temp_c), h.max(r.temp_c))
            });
        if lo.is_finite() && hi.is_finite() {
            let mut k = lo.floor();
            while k < hi {
                let rows: Vec<&TraceRow> = during
                    .iter()
                    .copied()
                    .filter(|r| r.temp_c >= k && r.temp_c < k + 1.0)
                    .collect();
                if !rows.is_empty() {
                    bins.push(KelvinBin {
                        temp_c: k + 0.5,
                        samples: rows.len(),
                        valid: share(&rows),
                        rate_err_mean_dps: mean(rows.iter().map(err)),
                        rate_err_rms_dps: rms(rows.iter().map(err)),
                        pump_offset_mean_hz: mean(
                            rows.iter()
                                .map(|r| r.pump_centre_hz - pump_target_hz(sc, r)),
                        ),
                    });
                }
                k += 1.0;
            }
        }
        Ok(ThermalReport {
            scenario: sc.name.clone(),
            change_s: (t0, t1),
            temp_c: (tp.temp_c(t0), tp.temp_c(t1)),
            resets_after_startup: last - resets_at(STARTUP_S),
            drift_alarms_after_startup: last_alarms - alarms_at(STARTUP_S),
            valid_during: share(&during),
            valid_before: share(&before),
            rate_err_rms_before_dps: rms(before.iter().map(err)),
            rate_err_rms_during_dps: rms(during.iter().map(err)),
            rate_err_max_during_dps: during.iter().map(|r| err(r).abs()).fold(0.0, f64::max),
            rate_err_rms_after_onset_dps: rms(during
                .iter()
                .filter(|r| r.t_s >= t0 + ONSET_S)
                .map(err)),
            rate_err_mean_during_dps: mean(during.iter().map(err)),
            wy2_err_max: during
                .iter()
                .map(|r| (r.phys_est[4] - r.phys_true[4]).abs())
                .fold(0.0, f64::max),
            pump_offset_max_hz: during
                .iter()
                .map(|r| (r.pump_centre_hz - pump_target_hz(sc, r)).abs())
                .fold(0.0, f64::max),
            drift_th22_max_ppm_s: during
                .iter()
                .map(|r| r.drift_ppm_s[1].abs())
                .fold(0.0, f64::max),
            wy2_rate_max_ppm_s: wy2_rate,
            sense_amp_vs_oracle_min: None,
            sensor: tp.sensor,
            tcf_learned_ppm_k: trace.last().map_or([f64::NAN; 2], |r| r.tcf_ppm_k),
            tcf_truth_ppm_k: [tp.tcf_wx_ppm_k, tp.tcf_wy_ppm_k],
            scale: scale_bins(&during, 5.0),
            bins,
        })
    }

    /// Adds the comparison with the oracle twin ([`oracle_sense_amp`]): the mean sense
    /// amplitude of each whole second of the change against the twin's.
    pub fn with_oracle(mut self, trace: &[TraceRow], oracle: &[(f64, f64)]) -> Self {
        let amp: Vec<(f64, f64)> = trace.iter().map(|r| (r.t_s, r.sense_amp_um)).collect();
        self.sense_amp_vs_oracle_min = lowest_second_ratio(&amp, oracle, self.change_s);
        self
    }

    /// The report as Markdown: the figures, then the per-kelvin table.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let pct = |x: f64| 100.0 * x;
        let _ = writeln!(
            s,
            "# Thermal report: {}\n\nThe die temperature moves {:.2} → {:.2} °C from {:.1} s to {:.1} s \
             (ωy² moving up to {:.1} ppm/s). Start-up ({STARTUP_S} s) excluded.\n",
            self.scenario,
            self.temp_c.0,
            self.temp_c.1,
            self.change_s.0,
            self.change_s.1,
            self.wy2_rate_max_ppm_s
        );
        let _ = writeln!(s, "| figure | value |\n|---|---|");
        let [lx, ly] = self.tcf_learned_ppm_k;
        let [tx, ty] = self.tcf_truth_ppm_k;
        let onset = format!("rate error during the change: rms after its first {ONSET_S} s / mean");
        let rows = [
            (
                "die temperature in the samples",
                if self.sensor {
                    "yes"
                } else {
                    "no (the walk alone)"
                }
                .to_string(),
            ),
            (
                "frequency TCFs learned by the end, drive / sense (the truth's)",
                format!("{lx:.2} / {ly:.2} ppm/K ({tx:.2} / {ty:.2})"),
            ),
            (
                "covariance resets after start-up",
                format!("{}", self.resets_after_startup),
            ),
            (
                "change alarms read as a drift after start-up (the walk opened, no reset)",
                format!("{}", self.drift_alarms_after_startup),
            ),
            (
                "rate valid: before the change / during it",
                format!(
                    "{:.1} % / {:.1} %",
                    pct(self.valid_before),
                    pct(self.valid_during)
                ),
            ),
            (
                "rate error rms: before the change / during it (every sample)",
                format!(
                    "{:.3} / {:.3} °/s ({:.2}×)",
                    self.rate_err_rms_before_dps,
                    self.rate_err_rms_during_dps,
                    self.rate_err_rms_during_dps / self.rate_err_rms_before_dps
                ),
            ),
            (
                onset.as_str(),
                format!(
                    "{:.3} °/s ({:.2}× the rms before) / {:+.3} °/s",
                    self.rate_err_rms_after_onset_dps,
                    self.rate_err_rms_after_onset_dps / self.rate_err_rms_before_dps,
                    self.rate_err_mean_during_dps
                ),
            ),
            (
                "largest rate error during the change",
                format!("{:.3} °/s", self.rate_err_max_during_dps),
            ),
            (
                "largest |ω̂y² − ωy²| during the change",
                format!("{:.2e}", self.wy2_err_max),
            ),
            (
                "largest |pump centre − 2·f_y| during the change",
                format!("{:.2} Hz", self.pump_offset_max_hz),
            ),
            (
                "largest θ22 drift followed (the truth's ωy² rate)",
                format!(
                    "{:.1} ppm/s ({:.1} ppm/s)",
                    self.drift_th22_max_ppm_s, self.wy2_rate_max_ppm_s
                ),
            ),
        ];
        for (k, v) in rows {
            let _ = writeln!(s, "| {k} | {v} |");
        }
        if let Some(r) = self.sense_amp_vs_oracle_min {
            let _ = writeln!(
                s,
                "| lowest 1 s mean sense amplitude during the change, against the oracle twin's (pump at 2·f_y) | {:.1} % |",
                pct(r)
            );
        }
        let _ = writeln!(
            s,
            "\n| die °C | samples | rate valid | rate error mean / rms, °/s | pump − 2·f_y, Hz |\n|---|---|---|---|---|"
        );
        for b in &self.bins {
            let _ = writeln!(
                s,
                "| {:.1} | {} | {:.1} % | {:+.3} / {:.3} | {:+.2} |",
                b.temp_c,
                b.samples,
                pct(b.valid),
                b.rate_err_mean_dps,
                b.rate_err_rms_dps,
                b.pump_offset_mean_hz
            );
        }
        if !self.scale.is_empty() {
            let worst =
                |f: fn(&ScaleBin) -> f64| self.scale.iter().map(|b| f(b).abs()).fold(0.0, f64::max);
            let _ = writeln!(
                s,
                "\nThe rate alternates between ±Ω: its scale factor and bias per 5 K (each side's \
                 first {} s after a step left out). Largest |scale factor error| {:.0} ppm, \
                 largest |bias| {:.3} °/s.\n\n| die °C | samples +Ω / −Ω | scale factor error, ppm | bias, °/s |\n|---|---|---|---|",
                scale::SETTLE_S,
                worst(|b| b.scale_err_ppm),
                worst(|b| b.bias_dps)
            );
            for b in &self.scale {
                let _ = writeln!(
                    s,
                    "| {:.1} | {} / {} | {:+.0} | {:+.3} |",
                    b.temp_c, b.samples.0, b.samples.1, b.scale_err_ppm, b.bias_dps
                );
            }
        }
        s
    }

    /// `thermal.png`: the rate error, the pump's offset from twice the sense resonance and
    /// the drift followed, against the die temperature; where the rate alternates, its
    /// scale factor error and bias per 5 K.
    pub fn plot(&self, sc: &Scenario, trace: &[TraceRow], path: &Path) -> Result<()> {
        let rows: Vec<&TraceRow> = trace
            .iter()
            .filter(|r| (self.change_s.0..self.change_s.1).contains(&r.t_s))
            .step_by(5)
            .collect();
        let x = (
            self.temp_c.0.min(self.temp_c.1),
            self.temp_c.0.max(self.temp_c.1),
        );
        let x = if x.1 > x.0 { x } else { (x.0 - 0.5, x.1 + 0.5) };
        let span = |v: &[f64]| {
            let (l, h) = v
                .iter()
                .filter(|x| x.is_finite())
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
                    (l.min(x), h.max(x))
                });
            if l.is_finite() && h > l {
                let p = 0.05 * (h - l);
                (l - p, h + p)
            } else {
                (-1.0, 1.0)
            }
        };
        let panel = |cap: &str, ydesc: &str, pts: Vec<(f64, f64)>, color| {
            let ys: Vec<f64> = pts.iter().map(|p| p.1).collect();
            let mut p = Panel::new(cap.into(), x, span(&ys));
            p.x_desc = Some("die temperature, °C".into());
            p.y_desc = ydesc.into();
            p.lines.push(Line::new(pts, color, 1));
            p.hlines.push((0.0, BLACK, String::new()));
            p
        };
        let (root, body) = figure(path, &format!("{}: through temperature", self.scenario))?;
        let areas = grid(&body, if self.scale.is_empty() { 3 } else { 5 }, 1);
        draw_panel(
            &areas[0],
            &panel(
                "rate error (fast channel − truth)",
                "°/s",
                rows.iter()
                    .map(|r| (r.temp_c, r.rate_dps_est - r.rate_dps_true))
                    .collect(),
                RED,
            ),
        )?;
        draw_panel(
            &areas[1],
            &panel(
                "pump centre − 2·f_y",
                "Hz",
                rows.iter()
                    .map(|r| (r.temp_c, r.pump_centre_hz - pump_target_hz(sc, r)))
                    .collect(),
                BLUE,
            ),
        )?;
        let p = panel(
            "θ22 drift followed by the core",
            "ppm/s",
            rows.iter().map(|r| (r.temp_c, r.drift_ppm_s[1])).collect(),
            BLUE,
        );
        draw_panel(&areas[2], &p)?;
        if let [_, _, _, a3, a4] = &areas[..] {
            let sf = self.scale.iter().map(|b| (b.temp_c, b.scale_err_ppm));
            draw_panel(
                a3,
                &panel("scale factor error (±Ω)", "ppm", sf.collect(), RED),
            )?;
            let bias = self.scale.iter().map(|b| (b.temp_c, b.bias_dps));
            draw_panel(a4, &panel("bias (±Ω)", "°/s", bias.collect(), RED))?;
        }
        root.present()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_warm_up_ramp_is_stretched_and_other_profiles_are_refused() {
        let warm = || {
            Scenario::from_toml_str(include_str!("../../scenarios/warm-up.toml"), "warm-up.toml")
                .unwrap()
        };
        let mut sc = warm();
        reshape_ramp(&mut sc, Some(300.0), Some(2.0)).unwrap();
        let t = sc.temperature.as_ref().unwrap();
        assert_eq!(t.points.last(), Some(&[305.0, 27.0]));
        assert_eq!(sc.duration_s, 307.0);
        let mut sc = warm();
        reshape_ramp(&mut sc, Some(40.0), None).unwrap();
        assert_eq!(
            sc.temperature.as_ref().unwrap().points.last(),
            Some(&[45.0, 35.0])
        );
        // a cycle is not one ramp; a zero duration is not a ramp
        let mut sc = warm();
        sc.temperature.as_mut().unwrap().points.push([40.0, 25.0]);
        assert!(reshape_ramp(&mut sc, Some(300.0), None).is_err());
        assert!(move_ramp_start(&mut sc, 10.0).is_err());
        assert!(reshape_ramp(&mut warm(), Some(0.0), None).is_err());
        // the onset moved: the ramp's length and rise kept, held before it
        let mut sc = warm();
        move_ramp_start(&mut sc, 30.4).unwrap();
        let t = sc.temperature.as_ref().unwrap();
        assert_eq!(t.points, vec![[0.0, 25.0], [30.4, 25.0], [50.4, 35.0]]);
        assert_eq!(sc.duration_s, 52.4);
        assert!(move_ramp_start(&mut warm(), f64::NAN).is_err());
    }
}
