//! The rate channel's datasheet on the simulated device (`paragyro-sim rate-response`):
//! step response, frequency response from a chirp, sines, a ±300 °/s ramp (scale factor,
//! nonlinearity), acceleration steps (g-sensitivity), the rate noise against the
//! Cramér–Rao bound at the same bandwidth, and optionally a long static run (Allan
//! deviation). Every number comes from a closed-loop run of the core on the simulated
//! gyro ([`crate::runner`]), seeded.
//!
//! **CRLB.** The rate reaches the lock-in through the sense mode: for a small rate change
//! δγ the sense envelope moves by `δB = −A δγ / (s + μy/2)` along the drive displacement A
//! (the averaged slow flow, DERIVATION §6, tuned pump). The lock-in's sense component
//! along A carries white noise of one-sided PSD `S_B = 2 S_w` (`S_w` the front end's
//! displacement noise density², mixing with `2e^{−iψ}`), so any unbiased estimator of the
//! rate seen through a transfer `G(f)` has a variance of at least
//! `∫ |G(f)|² S_B (ν² + (μy/2)²)/|A|² df`, `ν = 2πf/ω0` (in ω0 units of γ). Two `G`: the
//! channel's own design (`F0` of its filter times the lock-in low-pass) and an ideal
//! brick wall at the measured −3 dB bandwidth. The measured noise is the difference of
//! the same run with and without front-end noise (the deterministic model errors cancel).

use std::f64::consts::TAU;
use std::path::Path;

use anyhow::{Context, Result, ensure};
use serde::{Deserialize, Serialize};

use crate::runner::{self, Precision, RunOptions};
use crate::scenario::Scenario;
use crate::trace::TraceRow;

/// The base of every run: `host-sim/scenarios/rate-response.toml`.
const BASE: &str = include_str!("../../scenarios/rate-response.toml");

/// When the base has settled and the tests start, s.
pub const T0_S: f64 = 3.0;
/// The base rate, °/s.
pub const BASE_DPS: f64 = 150.0;

/// Options of the report.
#[derive(Clone, Debug)]
pub struct Options {
    /// Core precision.
    pub precision: Precision,
    /// Noise seed of every run.
    pub seed: u64,
    /// Length of the static Allan runs (0 and 150 °/s), s; `None`: not run.
    pub allan_s: Option<f64>,
    /// The Allan runs' memory of the rate's zero (scenario `rate_zero_memory_s`, core
    /// `rate.zero_memory_s`; 0: the slow RLS's μ̂xy every sample); `None`: the core's.
    pub allan_zero_memory_s: Option<f64>,
    /// The Allan runs' slow RLS forgetting factor (scenario `estimator.forgetting`, core
    /// `rls.forgetting`); `None`: the base scenario's 0.999 (a 2 s memory).
    pub allan_forgetting: Option<f64>,
    /// The Allan record starts this long after the start-up (`T0_S`), s: the device at
    /// its operating point, the rate's zero settled (IEEE Std 952's stabilised gyro; a
    /// warm start does not carry the zero's mean). The figures from the start-up over the
    /// same length are reported beside them ([`AllanResult::from_start_up`]).
    pub allan_settle_s: f64,
    /// Also the record of the same length after a warm start: the snapshot taken at the
    /// settle's end, a second boot of the device (another noise seed) started from it
    /// ([`AllanResult::after_warm_start`]).
    pub allan_warm_start: bool,
}

/// A slow RLS forgetting factor the Allan runs take ([`Options::allan_forgetting`]): in
/// (0, 1].
pub fn forgetting_ok(l: f64) -> bool {
    l > 0.0 && l <= 1.0
}

/// The default of [`Options::allan_settle_s`], s: one memory of the core's rate zero
/// (`rate.zero_memory_s`) is not needed, ten minutes of it are (the zero's error falls as
/// 1/√t from a reset).
pub const ALLAN_SETTLE_S: f64 = 600.0;

/// The whole report (`report.json`).
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Precision and seed.
    pub precision: Precision,
    pub seed: u64,
    pub step: StepResult,
    pub frequency: FreqResult,
    pub sines: Vec<SineResult>,
    pub ramp: RampResult,
    pub g_sensitivity: GResult,
    pub noise: NoiseResult,
    pub allan: Vec<AllanResult>,
}

/// The 100 °/s step.
#[derive(Clone, Debug, Serialize)]
pub struct StepResult {
    pub from_dps: f64,
    pub to_dps: f64,
    /// Largest |error| from 25 ms to 500 ms after the step, % of the step.
    pub max_err_after_25ms_pct: f64,
    /// First time after which |error| stays below 1 % of the step (within 0.5 s), ms.
    pub settle_1pct_ms: Option<f64>,
    /// Covariance resets from the step to the end of the run.
    pub resets: u32,
    /// Largest relative change of the slow θ (all but θ14, θ24) over the run after the
    /// step, in units of its own steady-state standard deviation before the step.
    pub slow_theta_max_dev_sigma: f64,
}

/// The frequency response from the chirp.
#[derive(Clone, Debug, Serialize)]
pub struct FreqResult {
    pub amplitude_dps: f64,
    pub f_start_hz: f64,
    pub f_end_hz: f64,
    pub points: Vec<FreqPoint>,
    /// First −3 dB crossing, Hz (`None`: none below the chirp's end).
    pub bandwidth_3db_hz: Option<f64>,
    pub resets: u32,
}

/// One point of the frequency response.
#[derive(Clone, Debug, Serialize)]
pub struct FreqPoint {
    pub f_hz: f64,
    pub mag_db: f64,
    pub phase_deg: f64,
}

/// A sine of the rate.
#[derive(Clone, Debug, Serialize)]
pub struct SineResult {
    pub f_hz: f64,
    pub amplitude_dps: f64,
    pub gain: f64,
    pub phase_deg: f64,
    /// rms of (estimate − truth), °/s, over the sine (lag included).
    pub err_rms_dps: f64,
    pub resets: u32,
    pub slow_theta_max_dev_sigma: f64,
}

/// The ±300 °/s ramp.
#[derive(Clone, Debug, Serialize)]
pub struct RampResult {
    pub full_scale_dps: f64,
    /// Least-squares scale factor of the bin means, −1, ppm.
    pub scale_factor_err_ppm: f64,
    /// Largest |bin mean − fit| over the full scale, ppm of full scale.
    pub nonlinearity_ppm_fs: f64,
    pub bias_dps: f64,
    pub bins: usize,
    pub resets: u32,
}

/// g-sensitivity from acceleration steps of 10 g.
#[derive(Clone, Debug, Serialize)]
pub struct GResult {
    pub dps_per_g_x: f64,
    pub dps_per_g_y: f64,
}

/// Rate noise and the Cramér–Rao bound.
#[derive(Clone, Debug, Serialize)]
pub struct NoiseResult {
    /// Front-end noise, pm/√Hz.
    pub noise_pm_rthz: f64,
    /// std of (noisy − noise-free) fast rate, °/s.
    pub noise_std_dps: f64,
    /// rms of (noise-free estimate − truth): the deterministic error, °/s.
    pub model_err_rms_dps: f64,
    /// Low-frequency rate noise density of the bound, °/s/√Hz, and as angle random walk.
    pub crlb_density_dps_rthz: f64,
    pub crlb_arw_deg_rth: f64,
    /// The bound for the channel's own transfer (filter × lock-in), °/s.
    pub crlb_std_same_g_dps: f64,
    /// The bound for a brick wall at the measured bandwidth, °/s.
    pub crlb_std_brickwall_dps: f64,
    pub ratio_same_g: f64,
    pub ratio_brickwall: f64,
}

/// A static Allan run: the record of `duration_s` from `settle_s` after the start-up.
#[derive(Clone, Debug, Serialize)]
pub struct AllanResult {
    pub rate_dps: f64,
    pub duration_s: f64,
    /// How long after the start-up (`T0_S`) the record starts, s.
    pub settle_s: f64,
    /// The runs' slow RLS forgetting factor per sample ([`Options::allan_forgetting`]).
    pub forgetting: f64,
    /// ARW, bias instability, and the rate's zero alone at the minimum (flat in
    /// report.json).
    #[serde(flatten)]
    pub figures: AllanFigures,
    pub tau_s: Vec<f64>,
    pub adev_dps: Vec<f64>,
    /// The rate's zero's Allan deviation at `tau_s`, °/s.
    pub zero_adev_dps: Vec<f64>,
    /// The same figures for the record of the same length from the start-up (the rate's
    /// zero still converging); `None` when `settle_s` is 0 (they are the ones above).
    pub from_start_up: Option<AllanFigures>,
    /// The same figures for the record of the same length from a warm start's boot
    /// ([`Options::allan_warm_start`]; `None` when not run).
    pub after_warm_start: Option<AllanFigures>,
}

/// An Allan curve's figures.
#[derive(Clone, Debug, Serialize)]
pub struct AllanFigures {
    /// Angle random walk from the τ^−1/2 fit at τ = 1 s, °/√h.
    pub arw_deg_rth: f64,
    /// Bias instability: min of the Allan deviation / 0.664, °/h.
    pub bias_instability_deg_h: f64,
    /// τ of the curve's minimum, s.
    pub tau_min_s: f64,
    /// The rate's zero alone at `tau_min_s`: the Allan deviation of the rate it
    /// subtracts (−μxy·ω0/2, `Estimator::rate_zero`), °/s; how much of the minimum is the
    /// zero's mean still moving.
    pub zero_adev_at_min_dps: f64,
}

/// The base scenario with `extra` TOML appended (events) and its length.
pub fn scenario(extra: &str, duration_s: f64) -> Result<Scenario> {
    let text = BASE.replacen("duration_s = 6.0", &format!("duration_s = {duration_s}"), 1);
    Scenario::from_toml_str(&format!("{text}\n{extra}"), "rate-response.toml")
        .map_err(|e| anyhow::anyhow!("{e}"))
}

/// The rate channel's delay at low frequency, s: the group delay at DC of its transfer,
/// the wide filter's double real pole (`2/wf`), the output section
/// (`2ζ/w`, [`paragyro_core::rate::POST_HZ`]; the bilinear transform keeps it) and the
/// lock-in's Butterworth (`Σ 2 sin((2k−1)π/2n)/wc` over its sections, `1/wc` for an odd
/// order). A sine at 5 Hz lags the truth by about this (6.6 ms with the defaults).
pub fn design_delay_s(cfg: &paragyro_core::config::Config) -> f64 {
    let wf = TAU * cfg.rate.svf_hz;
    let wp = TAU * paragyro_core::rate::POST_HZ;
    let wc = TAU * cfg.lockin_lpf_hz;
    let n = cfg.lockin_lpf_order;
    let lockin: f64 = (1..=n / 2)
        .map(|k| 2.0 * ((2 * k - 1) as f64 * std::f64::consts::PI / (2 * n) as f64).sin() / wc)
        .sum::<f64>()
        + if n % 2 == 1 { 1.0 / wc } else { 0.0 };
    2.0 / wf + 2.0 * paragyro_core::rate::POST_ZETA / wp + lockin
}

/// One run's trace.
pub fn trace(sc: &Scenario, precision: Precision, seed: u64) -> Result<Vec<TraceRow>> {
    let opts = RunOptions {
        precision,
        seed: Some(seed),
    };
    let run = match precision {
        Precision::F32 => runner::simulate::<f32>(sc, &opts, &mut |_| {}),
        Precision::F64 => runner::simulate::<f64>(sc, &opts, &mut |_| {}),
    }?;
    Ok(run.trace)
}

fn ev_ramp(t: f64, param: &str, to: f64, dur: f64) -> String {
    format!(
        "[[event]]\nt_s = {t}\nkind = \"ramp\"\nparam = \"{param}\"\nto = {to}\nduration_s = {dur}\n"
    )
}

fn resets_from(tr: &[TraceRow], t: f64) -> u32 {
    let before = tr.iter().rfind(|r| r.t_s < t).map_or(0, |r| r.resets);
    tr.last().map_or(0, |r| r.resets) - before
}

/// Largest change of the slow θ (all but θ14 and θ24, which carry the rate) after `t`,
/// in units of each component's standard deviation over [t − 1 s, t).
pub fn slow_theta_dev_sigma(tr: &[TraceRow], t: f64) -> f64 {
    let th = |r: &TraceRow, j: usize| {
        if j < 8 {
            r.theta_drive_est[j]
        } else {
            r.theta_sense_est[j - 8]
        }
    };
    let before: Vec<&TraceRow> = tr
        .iter()
        .filter(|r| r.t_s >= t - 1.0 && r.t_s < t)
        .collect();
    let mut worst: f64 = 0.0;
    for j in (0..14).filter(|&j| j != 3 && j != 11) {
        let n = before.len().max(1) as f64;
        let m = before.iter().map(|r| th(r, j)).sum::<f64>() / n;
        let sd = (before.iter().map(|r| (th(r, j) - m).powi(2)).sum::<f64>() / n).sqrt();
        for r in tr.iter().filter(|r| r.t_s >= t) {
            worst = worst.max((th(r, j) - m).abs() / sd.max(1e-300));
        }
    }
    worst
}

/// The 100 °/s step at `T0_S` (150 → 250 °/s in one sample).
pub fn step(o: &Options) -> Result<(StepResult, Vec<TraceRow>)> {
    let to = BASE_DPS + 100.0;
    let tr = trace(
        &scenario(&ev_ramp(T0_S, "rate_dps", to, 0.0), T0_S + 1.5)?,
        o.precision,
        o.seed,
    )?;
    let mut max_err: f64 = 0.0;
    let mut last_bad = None;
    for r in tr.iter().filter(|r| r.t_s > T0_S && r.t_s <= T0_S + 0.5) {
        let e = (r.rate_dps_est - r.rate_dps_true).abs();
        if r.t_s >= T0_S + 0.025 - 1e-9 {
            max_err = max_err.max(e);
        }
        if e.is_nan() || e > 1.0 {
            last_bad = Some(r.t_s);
        }
    }
    let settle = match last_bad {
        None => Some(0.0),
        Some(t) if t < T0_S + 0.5 - 1e-9 => Some((t - T0_S) * 1e3 + 2.0),
        Some(_) => None,
    };
    Ok((
        StepResult {
            from_dps: BASE_DPS,
            to_dps: to,
            max_err_after_25ms_pct: max_err,
            settle_1pct_ms: settle,
            resets: resets_from(&tr, T0_S),
            slow_theta_max_dev_sigma: slow_theta_dev_sigma(&tr, T0_S),
        },
        tr,
    ))
}

/// Complex ratio Σ est·z̄ / Σ true·z̄ of the rate deviations from `base` over `rows`, with
/// the reference phasor `z(t)`.
fn ratio(rows: &[&TraceRow], base: f64, phase: impl Fn(f64) -> f64) -> (f64, f64) {
    let (mut er, mut ei, mut tr_, mut ti) = (0.0, 0.0, 0.0, 0.0);
    for r in rows {
        let p = phase(r.t_s);
        let (c, s) = (p.cos(), p.sin());
        let (e, t) = (r.rate_dps_est - base, r.rate_dps_true - base);
        er += e * c;
        ei -= e * s;
        tr_ += t * c;
        ti -= t * s;
    }
    // (er + i ei)/(tr + i ti)
    let d = tr_ * tr_ + ti * ti;
    let (re, im) = ((er * tr_ + ei * ti) / d, (ei * tr_ - er * ti) / d);
    ((re * re + im * im).sqrt(), im.atan2(re))
}

/// A sine of `amp` °/s at `f` Hz from `T0_S` for `dur` s.
pub fn sine(o: &Options, f: f64, amp: f64, dur: f64) -> Result<(SineResult, Vec<TraceRow>)> {
    let ev = format!(
        "[[event]]\nt_s = {T0_S}\nkind = \"rate_sine\"\namplitude_dps = {amp}\nfreq_hz = {f}\nduration_s = {dur}\n"
    );
    let tr = trace(&scenario(&ev, T0_S + dur + 0.5)?, o.precision, o.seed)?;
    // whole periods after the first 0.2 s
    let t1 = T0_S + 0.2;
    let t2 = t1 + ((dur - 0.2) * f).floor() / f;
    let rows: Vec<&TraceRow> = tr.iter().filter(|r| r.t_s >= t1 && r.t_s < t2).collect();
    ensure!(rows.len() > 10, "sine window too short");
    let (gain, ph) = ratio(&rows, BASE_DPS, |t| TAU * f * (t - T0_S));
    let err = (rows
        .iter()
        .map(|r| (r.rate_dps_est - r.rate_dps_true).powi(2))
        .sum::<f64>()
        / rows.len() as f64)
        .sqrt();
    Ok((
        SineResult {
            f_hz: f,
            amplitude_dps: amp,
            gain,
            phase_deg: ph.to_degrees(),
            err_rms_dps: err,
            resets: resets_from(&tr, T0_S),
            slow_theta_max_dev_sigma: slow_theta_dev_sigma(&tr, T0_S),
        },
        tr,
    ))
}

/// The chirp `f0 → f1` Hz of `amp` °/s over `dur` s, analysed on 1/6-octave windows.
pub fn chirp(o: &Options, f0: f64, f1: f64, amp: f64, dur: f64) -> Result<FreqResult> {
    let ev = format!(
        "[[event]]\nt_s = {T0_S}\nkind = \"rate_chirp\"\namplitude_dps = {amp}\nfreq_hz = {f0}\nfreq_end_hz = {f1}\nduration_s = {dur}\n"
    );
    let tr = trace(&scenario(&ev, T0_S + dur + 0.3)?, o.precision, o.seed)?;
    let phase = |t: f64| crate::scenario::chirp_phase(f0, f1, dur, t - T0_S);
    let mut points = Vec::new();
    let octaves = (f1 / f0).log2();
    let n = (octaves * 6.0).floor() as usize;
    for i in 0..n {
        let (fa, fb) = (
            f0 * 2f64.powf(i as f64 / 6.0),
            f0 * 2f64.powf((i + 1) as f64 / 6.0),
        );
        let rows: Vec<&TraceRow> = tr
            .iter()
            .filter(|r| r.t_s >= T0_S && r.t_s < T0_S + dur)
            .filter(|r| {
                let f = phase(r.t_s).1;
                f >= fa && f < fb
            })
            .collect();
        if rows.len() < 20 {
            continue;
        }
        let (g, ph) = ratio(&rows, BASE_DPS, |t| phase(t).0);
        // unwrapped against the previous point (the lag grows with frequency)
        let mut deg = ph.to_degrees();
        if let Some(prev) = points.last().map(|p: &FreqPoint| p.phase_deg) {
            deg -= 360.0 * ((deg - prev) / 360.0).round();
        }
        points.push(FreqPoint {
            f_hz: (fa * fb).sqrt(),
            mag_db: 20.0 * g.log10(),
            phase_deg: deg,
        });
    }
    let bw = points.windows(2).find_map(|w| {
        (w[0].mag_db > -3.0 && w[1].mag_db <= -3.0).then(|| {
            let x = (-3.0 - w[0].mag_db) / (w[1].mag_db - w[0].mag_db);
            (w[0].f_hz.ln() + x * (w[1].f_hz / w[0].f_hz).ln()).exp()
        })
    });
    Ok(FreqResult {
        amplitude_dps: amp,
        f_start_hz: f0,
        f_end_hz: f1,
        points,
        bandwidth_3db_hz: bw,
        resets: resets_from(&tr, T0_S),
    })
}

/// The ramp 150 → 300 → −300 → 0 °/s; bins of 20 °/s on the down-going leg (−300..300).
pub fn ramp(o: &Options) -> Result<(RampResult, Vec<TraceRow>)> {
    let fs = 300.0;
    let ev = ev_ramp(T0_S, "rate_dps", fs, 1.0)
        + &ev_ramp(T0_S + 1.5, "rate_dps", -fs, 12.0)
        + &ev_ramp(T0_S + 14.0, "rate_dps", 0.0, 1.0);
    let tr = trace(&scenario(&ev, T0_S + 15.5)?, o.precision, o.seed)?;
    let leg = tr
        .iter()
        .filter(|r| r.t_s >= T0_S + 1.5 && r.t_s < T0_S + 13.5)
        .map(|r| (r.rate_dps_true, r.rate_dps_est));
    let fit = ramp_fit(leg, fs)?;
    Ok((
        RampResult {
            full_scale_dps: fs,
            scale_factor_err_ppm: fit.scale_factor_err_ppm,
            nonlinearity_ppm_fs: fit.nonlinearity_ppm_fs,
            bias_dps: fit.bias_dps,
            bins: fit.bins,
            resets: resets_from(&tr, T0_S),
        },
        tr,
    ))
}

/// The scale factor and nonlinearity of a ramp leg over ±`fs`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RampFit {
    /// Least-squares scale factor of the bin means, −1, ppm.
    pub scale_factor_err_ppm: f64,
    /// Largest |bin mean − fit| over the full scale, ppm of full scale.
    pub nonlinearity_ppm_fs: f64,
    /// The fit's offset, °/s.
    pub bias_dps: f64,
    /// Bins with samples (of 30 over ±`fs`).
    pub bins: usize,
}

/// The fit of [`ramp`] (and of the firmware loop's `rate-ramp`) on `(true, estimate)`
/// rates of one leg: 30 bins of `2·fs/30` over ±`fs`, each bin's mean estimate against its
/// mean truth, a least-squares line through the bin means (so each rate counts once,
/// however long the ramp dwells there); the scale-factor error is its slope − 1 and the
/// nonlinearity the largest bin mean off the line, over the full scale.
pub fn ramp_fit(leg: impl Iterator<Item = (f64, f64)>, fs: f64) -> Result<RampFit> {
    let nb = 30usize;
    let mut bins = vec![(0.0, 0.0, 0usize); nb];
    for (truth, est) in leg {
        let b = (((truth + fs) / (2.0 * fs)) * nb as f64).floor();
        if (0.0..nb as f64).contains(&b) {
            let e = &mut bins[b as usize];
            e.0 += truth;
            e.1 += est;
            e.2 += 1;
        }
    }
    let pts: Vec<(f64, f64)> = bins
        .iter()
        .filter(|b| b.2 > 0)
        .map(|b| (b.0 / b.2 as f64, b.1 / b.2 as f64))
        .collect();
    ensure!(pts.len() > 5, "ramp: too few bins");
    let n = pts.len() as f64;
    let (sx, sy) = pts.iter().fold((0.0, 0.0), |a, p| (a.0 + p.0, a.1 + p.1));
    let (mx, my) = (sx / n, sy / n);
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let k = sxy / sxx;
    let b = my - k * mx;
    let nl = pts
        .iter()
        .map(|p| (p.1 - (k * p.0 + b)).abs())
        .fold(0.0, f64::max);
    Ok(RampFit {
        scale_factor_err_ppm: (k - 1.0) * 1e6,
        nonlinearity_ppm_fs: nl / fs * 1e6,
        bias_dps: b,
        bins: pts.len(),
    })
}

/// Mean fast rate over [t0, t1).
fn mean_rate(tr: &[TraceRow], t0: f64, t1: f64) -> f64 {
    let v: Vec<f64> = tr
        .iter()
        .filter(|r| r.t_s >= t0 && r.t_s < t1)
        .map(|r| r.rate_dps_est)
        .collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Steps of 10 g (to 0) on each axis at `T0_S`; the rate shift over 1 s windows.
pub fn g_sensitivity(o: &Options) -> Result<GResult> {
    let g = 9.80665;
    // the change of the 1 s mean rate across the step, less the same change in a twin run
    // without it (same seed): what the slow estimate's own wander and convergence move
    // between the two windows is not the acceleration's
    let change =
        |tr: &[TraceRow]| mean_rate(tr, T0_S + 1.0, T0_S + 2.0) - mean_rate(tr, T0_S - 1.0, T0_S);
    let twin = trace(&scenario("", T0_S + 2.5)?, o.precision, o.seed)?;
    let base = change(&twin);
    let mut out = [0.0; 2];
    for (i, key) in ["accel_x_mps2", "accel_y_mps2"].iter().enumerate() {
        let tr = trace(
            &scenario(&ev_ramp(T0_S, key, 0.0, 0.0), T0_S + 2.5)?,
            o.precision,
            o.seed,
        )?;
        out[i] = (change(&tr) - base) / (-10.0 * g / g);
    }
    Ok(GResult {
        dps_per_g_x: out[0],
        dps_per_g_y: out[1],
    })
}

mod noise;
mod output;

pub use noise::{allan, noise};
pub use output::{markdown, write_plots, write_text};

/// Every measurement of the report (the slow part: several closed-loop runs in parallel),
/// written to `dir`: report.json, report.md and the plots (`paragyro-sim rate-response`).
pub fn run_all(o: &Options, dir: &Path) -> Result<(Report, Vec<String>)> {
    let m = measure(o)?;
    let mut files = write_text(dir, &m.report)?;
    files.extend(write_plots(
        dir,
        &m.report,
        &m.step_trace,
        &m.sine_traces,
        &m.ramp_trace,
    )?);
    Ok((m.report, files))
}

/// Every measurement of the report, written nowhere (the Python package's
/// `paragyro.rate_response`); the same figures as [`run_all`]'s.
pub fn report(o: &Options) -> Result<Report> {
    measure(o).map(|m| m.report)
}

/// The report and the traces its plots draw.
struct Measured {
    report: Report,
    step_trace: Vec<TraceRow>,
    sine_traces: Vec<Vec<TraceRow>>,
    ramp_trace: Vec<TraceRow>,
}

/// Runs every measurement (several closed-loop runs in parallel).
fn measure(o: &Options) -> Result<Measured> {
    type Job<'a> = Box<dyn Fn() -> Result<Part> + Send + Sync + 'a>;
    let jobs: Vec<Job<'_>> = vec![
        Box::new(|| step(o).map(|(r, t)| Part::Step(r, t))),
        Box::new(|| chirp(o, 0.1, 200.0, 20.0, 24.0).map(Part::Freq)),
        Box::new(|| sine(o, 10.0, 50.0, 2.0).map(|(r, t)| Part::Sine(r, t))),
        Box::new(|| sine(o, 50.0, 50.0, 2.0).map(|(r, t)| Part::Sine(r, t))),
        Box::new(|| ramp(o).map(|(r, t)| Part::Ramp(r, t))),
        Box::new(|| g_sensitivity(o).map(Part::G)),
    ];
    let parts = crate::par::try_map(&jobs, |_| "a rate-response run".to_string(), |j| j())?;
    let (mut st, mut fr, mut sn, mut rp, mut gs) = (None, None, Vec::new(), None, None);
    for p in parts {
        match p {
            Part::Step(r, t) => st = Some((r, t)),
            Part::Freq(r) => fr = Some(r),
            Part::Sine(r, t) => sn.push((r, t)),
            Part::Ramp(r, t) => rp = Some((r, t)),
            Part::G(r) => gs = Some(r),
        }
    }
    let (step_r, step_t) = st.context("step")?;
    let frequency = fr.context("chirp")?;
    let (ramp_r, ramp_t) = rp.context("ramp")?;
    let noise_r = noise(o, frequency.bandwidth_3db_hz)?;
    let mut allan_r = Vec::new();
    if let Some(d) = o.allan_s {
        // the two static runs are independent and long: one thread each
        let (a0, a1) = std::thread::scope(|s| {
            let h = s.spawn(|| allan(o, BASE_DPS, d));
            let a0 = allan(o, 0.0, d);
            let a1 = h
                .join()
                .map_err(|_| anyhow::anyhow!("the Allan run at {BASE_DPS} °/s panicked"));
            (a0, a1)
        });
        allan_r.push(a0?);
        allan_r.push(a1??);
    }
    let report = Report {
        precision: o.precision,
        seed: o.seed,
        step: step_r,
        frequency,
        sines: sn.iter().map(|x| x.0.clone()).collect(),
        ramp: ramp_r,
        g_sensitivity: gs.context("g-sensitivity")?,
        noise: noise_r,
        allan: allan_r,
    };
    let sine_traces: Vec<Vec<TraceRow>> = sn.into_iter().map(|x| x.1).collect();
    Ok(Measured {
        report,
        step_trace: step_t,
        sine_traces,
        ramp_trace: ramp_t,
    })
}

enum Part {
    Step(StepResult, Vec<TraceRow>),
    Freq(FreqResult),
    Sine(SineResult, Vec<TraceRow>),
    Ramp(RampResult, Vec<TraceRow>),
    G(GResult),
}
