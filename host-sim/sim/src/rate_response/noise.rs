//! Rate noise against the Cramér–Rao bound, and the static Allan runs.

use std::f64::consts::{PI, TAU};

use anyhow::{Result, ensure};

use super::{AllanFigures, AllanResult, BASE_DPS, NoiseResult, Options, T0_S, scenario, trace};
use crate::runner::{LoopSample, Precision, closed_loop, core_config};
use crate::scenario::Scenario;
use crate::trace::TraceRow;
use paragyro_core::persist::Start;
use paragyro_core::{Estimator, Real};

/// Noise: the same static run with and without front-end noise (same seed, same dither),
/// over 4 s from `T0_S`; the bound for the channel's own transfer and for a brick wall
/// at `bandwidth_hz`.
pub fn noise(o: &Options, bandwidth_hz: Option<f64>) -> Result<NoiseResult> {
    let sc = scenario("", T0_S + 4.0)?;
    let noisy = trace(&sc, o.precision, o.seed)?;
    let mut clean_sc = sc.clone();
    clean_sc.sim.noise_pm_rthz = 0.0;
    let clean = trace(&clean_sc, o.precision, o.seed)?;
    let pick = |tr: &[TraceRow]| -> Vec<(f64, f64)> {
        tr.iter()
            .filter(|r| r.t_s >= T0_S)
            .map(|r| (r.rate_dps_est, r.rate_dps_true))
            .collect()
    };
    let (a, b) = (pick(&noisy), pick(&clean));
    ensure!(
        a.len() == b.len() && a.len() > 100,
        "noise runs differ in length"
    );
    let d: Vec<f64> = a.iter().zip(&b).map(|(x, y)| x.0 - y.0).collect();
    let m = d.iter().sum::<f64>() / d.len() as f64;
    let noise_std = (d.iter().map(|v| (v - m).powi(2)).sum::<f64>() / d.len() as f64).sqrt();
    let model = (b.iter().map(|v| (v.0 - v.1).powi(2)).sum::<f64>() / b.len() as f64).sqrt();
    let cfg = core_config(&sc);
    let amp = noisy
        .iter()
        .filter(|r| r.t_s >= T0_S)
        .map(|r| r.drive_amp_um)
        .sum::<f64>()
        / a.len() as f64;
    let mu_y = noisy.last().map_or(1e-3, |r| r.phys_true[1]);
    let b = Bound {
        omega0: TAU * cfg.f0_hz,
        // one-sided displacement PSD (L0²/Hz; L0 = 1 µm), ×2 for the mixing with 2e^{−iψ}
        s_b: 2.0 * (sc.sim.noise_pm_rthz * 1e-6 / cfg.l0_um).powi(2),
        amp,
        mu_y,
        fc: cfg.rate.svf_hz,
        post_hz: paragyro_core::rate::POST_HZ,
        post_zeta: paragyro_core::rate::POST_ZETA,
        fs: cfg.fs_hz,
        lpf_hz: cfg.lockin_lpf_hz,
        lpf_order: cfg.lockin_lpf_order as i32,
        nyquist: cfg.fs_hz / 2.0,
    };
    let to_dps = b.omega0 * 180.0 / PI;
    let density = b.s_b.sqrt() * (mu_y / 2.0) / amp * to_dps;
    let same = b.std_dps(|f| b.design_gain(f));
    let wall = b.std_dps(|f| match bandwidth_hz {
        Some(bw) if f <= bw => 1.0,
        Some(_) => 0.0,
        None => b.design_gain(f),
    });
    Ok(NoiseResult {
        noise_pm_rthz: sc.sim.noise_pm_rthz,
        noise_std_dps: noise_std,
        model_err_rms_dps: model,
        crlb_density_dps_rthz: density,
        // °/s/√Hz → °/√h: × √(3600 s/h)… a white rate density N (°/s/√Hz, one-sided)
        // integrates to an angle random walk N/√2 · 60 °/√h
        crlb_arw_deg_rth: density / 2f64.sqrt() * 60.0,
        crlb_std_same_g_dps: same,
        crlb_std_brickwall_dps: wall,
        ratio_same_g: noise_std / same,
        ratio_brickwall: noise_std / wall,
    })
}

/// The model of the bound (module docs of `rate_response`).
struct Bound {
    omega0: f64,
    s_b: f64,
    amp: f64,
    mu_y: f64,
    fc: f64,
    post_hz: f64,
    post_zeta: f64,
    fs: f64,
    lpf_hz: f64,
    lpf_order: i32,
    nyquist: f64,
}

impl Bound {
    /// |G| of the channel's design: F0 (double pole at fc) × the output's section (its
    /// bilinear transform: the analog prototype at `2fs·tan(πf/fs)`) × Butterworth
    /// lock-in.
    fn design_gain(&self, f: f64) -> f64 {
        let x = f / self.fc;
        let xp = self.fs / PI * (PI * f / self.fs).tan() / self.post_hz;
        let post = 1.0 / ((1.0 - xp * xp).powi(2) + (2.0 * self.post_zeta * xp).powi(2)).sqrt();
        post / (1.0 + x * x) / (1.0 + (f / self.lpf_hz).powi(2 * self.lpf_order)).sqrt()
    }

    /// √∫₀^{fs/2} |G|² S_γ df in °/s.
    fn std_dps(&self, g: impl Fn(f64) -> f64) -> f64 {
        let n = 20_000;
        let df = self.nyquist / n as f64;
        let mut acc = 0.0;
        for i in 0..n {
            let f = (i as f64 + 0.5) * df;
            let nu = TAU * f / self.omega0;
            let s_g = self.s_b * (nu * nu + (self.mu_y / 2.0).powi(2)) / (self.amp * self.amp);
            acc += g(f).powi(2) * s_g * df;
        }
        acc.sqrt() * self.omega0 * 180.0 / PI
    }
}

/// A static run at `rate_dps`: overlapping Allan deviation of the fast rate over
/// `duration_s` from `o.allan_settle_s` after `T0_S`, ARW from the fit at τ = 1 s, bias
/// instability, and the rate's zero's share of the curve ([`AllanFigures`]); the same
/// figures over `duration_s` from `T0_S`, and after a warm start when asked.
pub fn allan(o: &Options, rate_dps: f64, duration_s: f64) -> Result<AllanResult> {
    ensure!(
        o.allan_settle_s.is_finite() && o.allan_settle_s >= 0.0,
        "the Allan settle must be finite and >= 0 (got {})",
        o.allan_settle_s
    );
    let ev = if rate_dps == BASE_DPS {
        String::new()
    } else {
        format!(
            "[[event]]\nt_s = 0.0\nkind = \"ramp\"\nparam = \"rate_dps\"\nto = {rate_dps}\nduration_s = 0.0\n"
        )
    };
    let settle = o.allan_settle_s;
    let mut sc = scenario(&ev, T0_S + settle + duration_s)?;
    sc.estimator.rate_zero_memory_s = o.allan_zero_memory_s;
    if let Some(l) = o.allan_forgetting {
        ensure!(
            super::forgetting_ok(l),
            "the Allan runs' forgetting must be in (0, 1] (got {l})"
        );
        sc.estimator.forgetting = l;
    }
    let run = match o.precision {
        Precision::F32 => cold_run::<f32>(&sc, o.seed)?,
        Precision::F64 => cold_run::<f64>(&sc, o.seed)?,
    };
    let c = curves(&run.from(T0_S + settle, duration_s))?;
    let from_start_up = if settle > 0.0 {
        Some(curves(&run.from(T0_S, duration_s))?.figures)
    } else {
        None
    };
    let after_warm_start = if o.allan_warm_start {
        let y = match o.precision {
            Precision::F32 => warm_run::<f32>(&sc, o.seed, settle, duration_s)?,
            Precision::F64 => warm_run::<f64>(&sc, o.seed, settle, duration_s)?,
        };
        Some(curves(&y.from(T0_S, duration_s))?.figures)
    } else {
        None
    };
    Ok(AllanResult {
        rate_dps,
        duration_s,
        settle_s: settle,
        forgetting: sc.estimator.forgetting,
        figures: c.figures,
        tau_s: c.tau_s,
        adev_dps: c.adev_dps,
        zero_adev_dps: c.zero_adev_dps,
        from_start_up,
        after_warm_start,
    })
}

/// A static run's fast rate and the rate's zero as a rate, every sample.
#[derive(Default)]
struct StaticRun {
    t_s: Vec<f64>,
    /// The fast rate, °/s.
    rate: Vec<f64>,
    /// The rate's zero as the rate it subtracts, −μxy·ω0/2 in °/s (`Estimator::rate_zero`).
    zero: Vec<f64>,
}

impl StaticRun {
    fn push<T: Real>(&mut self, ls: &LoopSample<'_, T>, zero_to_dps: f64) {
        self.t_s.push(ls.t_s);
        self.rate.push(ls.out.rate.rate_dps);
        self.zero.push(ls.est.rate_zero().0 * zero_to_dps);
    }

    fn span(&self, from: f64, duration_s: f64) -> std::ops::Range<usize> {
        let a = self.t_s.partition_point(|&t| t < from);
        let b = self.t_s.partition_point(|&t| t < from + duration_s);
        a..b
    }

    /// The two records over `duration_s` from `from` s.
    fn from(&self, from: f64, duration_s: f64) -> Record<'_> {
        let r = self.span(from, duration_s);
        Record {
            rate: &self.rate[r.clone()],
            zero: &self.zero[r],
        }
    }
}

/// A record of the fast rate and, beside it, the rate's zero as a rate (°/s).
struct Record<'a> {
    rate: &'a [f64],
    zero: &'a [f64],
}

/// °/s of rate per unit of the zero μxy: the rate is γ·ω0 with γ = −(θ24 + μxy)/2.
fn zero_to_dps(sc: &Scenario) -> f64 {
    -0.5 * core_config(sc).omega0_rad_s() * 180.0 / PI
}

/// The core of `sc`.
fn build<T: Real>(sc: &Scenario) -> Result<Estimator<T>> {
    core_config(sc)
        .build::<T>()
        .map_err(|e| anyhow::anyhow!("core configuration: {e}"))
}

/// The cold run of `sc`: the fast rate and the rate's zero every sample.
fn cold_run<T: Real>(sc: &Scenario, seed: u64) -> Result<StaticRun> {
    let mut est = build::<T>(sc)?;
    let k = zero_to_dps(sc);
    let mut run = StaticRun::default();
    closed_loop(sc, seed, &mut est, |_| {}, |ls| run.push(ls, k))?;
    Ok(run)
}

/// The run after a warm start, `T0_S + duration_s` long: the device run cold for
/// `T0_S + settle` s (seed `seed`), its snapshot, a second boot of it (seed `seed + 1`)
/// started from the snapshot; the fast rate and its zero every sample.
fn warm_run<T: Real>(sc: &Scenario, seed: u64, settle: f64, duration_s: f64) -> Result<StaticRun> {
    let mut cold_sc = sc.clone();
    cold_sc.duration_s = T0_S + settle;
    let mut cold = build::<T>(sc)?;
    closed_loop(&cold_sc, seed, &mut cold, |_| {}, |_| {})?;
    let record = cold.snapshot().encode();
    let mut warm = build::<T>(sc)?;
    match warm.boot_from(Some(&record)) {
        Start::Warm => {}
        Start::Cold(e) => anyhow::bail!("the snapshot at {settle} s was refused: {e:?}"),
    }
    let mut warm_sc = sc.clone();
    warm_sc.duration_s = T0_S + duration_s;
    let k = zero_to_dps(sc);
    let mut run = StaticRun::default();
    closed_loop(
        &warm_sc,
        seed.wrapping_add(1),
        &mut warm,
        |_| {},
        |ls| run.push(ls, k),
    )?;
    Ok(run)
}

/// A record's Allan curves: the fast rate's and its zero's, and the rate's figures.
struct Curves {
    tau_s: Vec<f64>,
    adev_dps: Vec<f64>,
    zero_adev_dps: Vec<f64>,
    figures: AllanFigures,
}

/// The Allan curves of a record ([`adev`]) and the figures of the rate's: its ARW (the
/// point nearest τ = 1 s, as white rate noise σ = N/√τ), its bias instability (the
/// curve's minimum / 0.664) and, at the minimum's τ, the zero's own deviation.
fn curves(rec: &Record) -> Result<Curves> {
    let (tau_s, adev_dps) = adev(rec.rate)?;
    let (_, zero_adev_dps) = adev(rec.zero)?;
    // white rate noise: σ(τ) = N/√τ; N from the point nearest τ = 1 s
    let i1 = tau_s
        .iter()
        .enumerate()
        .min_by(|a, b| (a.1.ln().abs()).total_cmp(&b.1.ln().abs()))
        .map_or(0, |x| x.0);
    let n = adev_dps[i1] * tau_s[i1].sqrt();
    let imin = adev_dps
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .map_or(0, |x| x.0);
    let figures = AllanFigures {
        arw_deg_rth: n * 60.0,
        bias_instability_deg_h: adev_dps[imin] / 0.664 * 3600.0,
        tau_min_s: tau_s[imin],
        zero_adev_at_min_dps: zero_adev_dps[imin],
    };
    Ok(Curves {
        tau_s,
        adev_dps,
        zero_adev_dps,
        figures,
    })
}

/// Overlapping Allan deviation of `y` (500 Hz) at τ growing by 1.25× up to a sixth of
/// the record.
fn adev(y: &[f64]) -> Result<(Vec<f64>, Vec<f64>)> {
    let fs = 500.0;
    let mut tau_s = Vec::new();
    let mut adev = Vec::new();
    let mut m = 1usize;
    // cumulative sum for O(N) per τ
    let mut c = vec![0.0; y.len() + 1];
    for (i, v) in y.iter().enumerate() {
        c[i + 1] = c[i] + v;
    }
    while 2 * m < y.len() / 3 {
        let n = y.len() - 2 * m;
        let mut s = 0.0;
        for k in 0..n {
            let a1 = (c[k + m] - c[k]) / m as f64;
            let a2 = (c[k + 2 * m] - c[k + m]) / m as f64;
            s += (a2 - a1).powi(2);
        }
        tau_s.push(m as f64 / fs);
        adev.push((s / (2.0 * n as f64)).sqrt());
        m = ((m as f64) * 1.25).ceil() as usize;
    }
    ensure!(!adev.is_empty(), "Allan run too short");
    Ok((tau_s, adev))
}
