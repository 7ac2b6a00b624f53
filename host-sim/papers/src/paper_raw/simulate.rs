//! A run through a list of segments: the step grid, noise, the estimator's blow-up guard,
//! the information matrices and the records.

use std::f64::consts::TAU;
use std::time::Instant;

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::Serialize;

use super::config::{LAMBDA_A0, LAMBDA_A1, RawConfig, Segment};
use super::ode::{
    Diag, I_P1, I_P2, I_T1, I_T2, NS, RK4_STABILITY_LIMIT, Stage, State, regressors, rk4, shift,
};

/// One record (every `record_every_s`).
#[derive(Clone, Debug, Serialize)]
pub struct RawRecord {
    /// Time at the end of the record interval, s.
    pub t_s: f64,
    /// Pump ω in effect.
    pub omega: f64,
    /// θ̂1 in the eq. (25) convention (the "3, 2" shift removed).
    pub theta_drive_est: [f64; 8],
    /// θ̂2 in the eq. (25) convention.
    pub theta_sense_est: [f64; 6],
    /// The plant's θ1.
    pub theta_drive_true: [f64; 8],
    /// The plant's θ2.
    pub theta_sense_true: [f64; 6],
    /// Drive amplitude (max X − min X)/2 over the interval (true X), L0.
    pub drive_amp: f64,
    /// Sense amplitude (max Y − min Y)/2 over the interval, L0.
    pub sense_amp: f64,
    /// trace P1, trace P2 at the record instant.
    pub trace_p: [f64; 2],
    /// Largest h·ΦᵀPΦ over the interval (RK4 is stable along Φ for ≲ 2.78), per axis.
    pub h_phi_p_phi_max: [f64; 2],
    /// rms of the estimator error e over the interval, per axis.
    pub e_rms: [f64; 2],
    /// rms of the equation error Z − Φᵀθ with the plant's θ (or [`RawConfig::model_theta`])
    /// over the interval, per axis: the regression identity of eqs. (15)–(17).
    pub e_true_rms: [f64; 2],
    /// rms of the measurement Z over the interval, per axis.
    pub z_rms: [f64; 2],
}

/// A whole run.
#[derive(Clone, Debug, Serialize)]
pub struct RawRun {
    /// Records, the first at t = 0 (initial state), then every `record_every_s`.
    pub records: Vec<RawRecord>,
    /// Segment start times, s.
    pub segment_starts_s: Vec<f64>,
    /// Integration step, τ.
    pub h_tau: f64,
    /// RK4 steps per simulated second (the sampling rate of X, Y the estimator consumes).
    pub steps_per_s: f64,
    /// Total RK4 steps.
    pub steps: u64,
    /// λ, per τ.
    pub lambda_per_tau: f64,
    /// First time the estimator state became non-finite (θ̂, P then frozen at the last
    /// finite values), s.
    pub estimator_blowup_s: Option<f64>,
    /// h·ΦᵀPΦ (drive, sense) at the start of the step that blew up: RK4 is stable along Φ
    /// only below ≈ 2.785, so a large value means the Riccati equation became too stiff for
    /// the explicit step.
    pub blowup_h_phi_p_phi: Option<[f64; 2]>,
    /// First step start (either axis) at which 2h·ΦᵀPΦ exceeded [`RK4_STABILITY_LIMIT`] or
    /// ΦᵀPΦ < 0 (P no longer positive definite), s: from there the explicit step is no
    /// longer a faithful discretisation of eq. (10).
    pub rk4_limit_exceeded_s: Option<f64>,
    /// ∫Φ1Φ1ᵀ dτ over `info_window_s` (8×8, row-major), if requested.
    pub info_drive: Option<Vec<f64>>,
    /// ∫Φ2Φ2ᵀ dτ over `info_window_s` (6×6, row-major), if requested.
    pub info_sense: Option<Vec<f64>>,
    /// Wall time, s.
    pub wall_s: f64,
}

/// The largest ω of a list of segments.
fn omega_max(segments: &[Segment]) -> f64 {
    segments.iter().map(|s| s.omega).fold(0.0, f64::max)
}

/// Runs the plant, the Λ filters and eq. (10) through `segments` (module docs).
///
/// Errors name a bad setting. Never panics on a diverging estimator: the first non-finite
/// estimator state freezes θ̂ and P (reported in [`RawRun::estimator_blowup_s`]).
pub fn simulate(cfg: &RawConfig, segments: &[Segment]) -> Result<RawRun, String> {
    let wall = Instant::now();
    validate(cfg, segments)?;
    let mut run = Integrator::new(cfg, segments)?;
    for seg in segments {
        run.segment(seg);
    }
    Ok(run.finish(wall))
}

/// Checks the settings and the segments; the error names the bad one.
fn validate(cfg: &RawConfig, segments: &[Segment]) -> Result<(), String> {
    let pos = |v: f64, name: &str| {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(format!("{name} = {v} must be positive and finite"))
        }
    };
    pos(cfg.omega0_rad_s, "omega0_rad_s")?;
    pos(cfg.record_every_s, "record_every_s")?;
    pos(cfg.p0, "p0")?;
    if !(cfg.lambda_per_tau.is_finite() && cfg.lambda_per_tau >= 0.0) {
        return Err(format!(
            "lambda_per_tau = {} must be ≥ 0",
            cfg.lambda_per_tau
        ));
    }
    if !(cfg.noise_density.is_finite() && cfg.noise_density >= 0.0) {
        return Err(format!("noise_density = {} must be ≥ 0", cfg.noise_density));
    }
    if cfg.steps_per_period < 8 {
        return Err(format!(
            "steps_per_period = {} must be ≥ 8",
            cfg.steps_per_period
        ));
    }
    if segments.is_empty() {
        return Err("no segments".into());
    }
    for (i, s) in segments.iter().enumerate() {
        pos(s.omega, &format!("segment {i} omega"))?;
        pos(s.duration_s, &format!("segment {i} duration_s"))?;
    }
    Ok(())
}

/// The state of a run between steps: the combined ODE state, the step grid, the noise
/// generator, the guards' findings, the information matrices and the records so far.
struct Integrator<'a> {
    cfg: &'a RawConfig,
    /// ω0, rad/s.
    w0: f64,
    /// τ per record.
    t_rec: f64,
    /// Steps per record.
    n_rec: u64,
    /// Step, τ.
    h: f64,
    /// Noise std per step and axis.
    sigma: f64,
    rng: Xoshiro256PlusPlus,
    y: State,
    /// Steps done.
    step: u64,
    /// ψ at the start of the segment.
    psi_seg: f64,
    blowup: Option<f64>,
    blowup_pp: Option<[f64; 2]>,
    rk4_exceeded: Option<f64>,
    /// The estimator's part of the state before the step (restored on a blow-up).
    saved: [f64; NS - I_T1],
    /// The estimator runs from this step on.
    n_start: u64,
    /// Steps `[n_info0, n_info1)` accumulate the information matrices.
    n_info: (u64, u64),
    info1: [f64; 64],
    info2: [f64; 36],
    records: Vec<RawRecord>,
    segment_starts_s: Vec<f64>,
}

impl<'a> Integrator<'a> {
    /// The step grid (records on it, at least `steps_per_period` per carrier period at the
    /// largest ω), the initial state (P = p0·I) and the record at t = 0.
    fn new(cfg: &'a RawConfig, segments: &[Segment]) -> Result<Self, String> {
        let w0 = cfg.omega0_rad_s;
        let t_rec = w0 * cfg.record_every_s; // τ per record
        let h_max = TAU / (omega_max(segments) * cfg.steps_per_period as f64);
        let n_rec = (t_rec / h_max).ceil().max(1.0) as u64;
        if n_rec > 100_000_000 {
            return Err("too many steps per record".into());
        }
        let h = t_rec / n_rec as f64;
        let h_sec = h / w0;
        let mut y: State = [0.0; NS];
        y[..4].copy_from_slice(&cfg.x0);
        for i in 0..8 {
            y[I_P1 + 9 * i] = cfg.p0;
        }
        for i in 0..6 {
            y[I_P2 + 7 * i] = cfg.p0;
        }
        let n_info = match cfg.info_window_s {
            Some((a, b)) => ((a * w0 / h).round() as u64, (b * w0 / h).round() as u64),
            None => (u64::MAX, u64::MAX),
        };
        let mut run = Self {
            cfg,
            w0,
            t_rec,
            n_rec,
            h,
            sigma: cfg.noise_density * (1.0 / (2.0 * h_sec)).sqrt(),
            rng: Xoshiro256PlusPlus::seed_from_u64(cfg.seed),
            y,
            step: 0,
            psi_seg: 0.0,
            blowup: None,
            blowup_pp: None,
            rk4_exceeded: None,
            saved: [0.0; NS - I_T1],
            n_start: (cfg.estimator_start_s * w0 / h).round().max(0.0) as u64,
            n_info,
            info1: [0.0; 64],
            info2: [0.0; 36],
            records: Vec::new(),
            segment_starts_s: Vec::new(),
        };
        let (a, b) = run.est_theta();
        let first = &segments[0];
        run.records.push(RawRecord {
            t_s: 0.0,
            omega: first.omega,
            theta_drive_est: a,
            theta_sense_est: b,
            theta_drive_true: first.theta.drive,
            theta_sense_true: first.theta.sense,
            drive_amp: cfg.x0[0].abs(),
            sense_amp: cfg.x0[2].abs(),
            trace_p: run.trace_p(),
            h_phi_p_phi_max: [0.0; 2],
            e_rms: [0.0; 2],
            e_true_rms: [0.0; 2],
            z_rms: [0.0; 2],
        });
        Ok(run)
    }

    /// θ̂ in the eq. (25) convention (the "3, 2" shift removed).
    fn est_theta(&self) -> ([f64; 8], [f64; 6]) {
        let sh = shift(self.cfg.z_form);
        let mut a = [0.0; 8];
        let mut b = [0.0; 6];
        a.copy_from_slice(&self.y[I_T1..I_T1 + 8]);
        b.copy_from_slice(&self.y[I_T2..I_T2 + 6]);
        a[0] -= sh * LAMBDA_A1;
        a[1] -= sh * LAMBDA_A0;
        b[0] -= sh * LAMBDA_A1;
        b[1] -= sh * LAMBDA_A0;
        (a, b)
    }

    fn trace_p(&self) -> [f64; 2] {
        let t1: f64 = (0..8).map(|i| self.y[I_P1 + 9 * i]).sum();
        let t2: f64 = (0..6).map(|i| self.y[I_P2 + 7 * i]).sum();
        [t1, t2]
    }

    /// One normal draw per axis (none without noise, so the generator's sequence is the
    /// same for every noise-free run).
    fn noise(&mut self) -> [f64; 2] {
        if self.sigma > 0.0 {
            let a: f64 = StandardNormal.sample(&mut self.rng);
            let b: f64 = StandardNormal.sample(&mut self.rng);
            [self.sigma * a, self.sigma * b]
        } else {
            [0.0; 2]
        }
    }

    /// Adds h·ΦΦᵀ at the step start to the information matrices (rectangle rule: the
    /// window is many periods long).
    fn accumulate_info(&mut self) {
        let h = self.h;
        let (p1, p2) = regressors(&self.y);
        for a in 0..8 {
            for b in 0..8 {
                self.info1[8 * a + b] += h * p1[a] * p1[b];
            }
        }
        for a in 0..6 {
            for b in 0..6 {
                self.info2[6 * a + b] += h * p2[a] * p2[b];
            }
        }
    }

    /// One RK4 step with the estimator running: records the first step past RK4's
    /// stability limit, and on a non-finite estimator state restores it and freezes it.
    fn estimator_step(&mut self, sa: &Stage<'_>, sm: &Stage<'_>, se: &Stage<'_>) -> Diag {
        let (h, w0, step) = (self.h, self.w0, self.step);
        self.saved.copy_from_slice(&self.y[I_T1..]);
        let d = rk4::<true>(&mut self.y, h, sa, sm, se);
        let chk: f64 = self.y[I_T1..I_T1 + 8].iter().sum::<f64>()
            + self.y[I_T2..I_T2 + 6].iter().sum::<f64>()
            + self.trace_p().iter().sum::<f64>();
        let pp_max = d.phi_p_phi[0].max(d.phi_p_phi[1]);
        let pp_min = d.phi_p_phi[0].min(d.phi_p_phi[1]);
        if self.rk4_exceeded.is_none() && (2.0 * h * pp_max > RK4_STABILITY_LIMIT || pp_min < 0.0) {
            self.rk4_exceeded = Some(step as f64 * h / w0);
        }
        if !chk.is_finite() {
            self.y[I_T1..].copy_from_slice(&self.saved);
            self.blowup = Some((step + 1) as f64 * h / w0);
            self.blowup_pp = Some([h * d.phi_p_phi[0], h * d.phi_p_phi[1]]);
        }
        d
    }

    /// Integrates one segment (its length rounded to whole records), recording every
    /// `n_rec` steps; ψ runs on continuously.
    fn segment(&mut self, seg: &Segment) {
        let (h, w0) = (self.h, self.w0);
        self.segment_starts_s.push(self.step as f64 * h / w0);
        let n_seg = ((seg.duration_s * w0 / self.t_rec).round().max(1.0) as u64) * self.n_rec;
        let th = seg.theta;
        let model = self.cfg.model_theta.unwrap_or(th);
        let om = seg.omega;
        let psi_seg = self.psi_seg;
        let (accel, lambda, z_form) = (self.cfg.accel, self.cfg.lambda_per_tau, self.cfg.z_form);
        let mk = |j: u64, noise: [f64; 2]| Stage {
            theta: &th,
            model: &model,
            // ψ = ψ_seg + ω·(j h/2), j counting half steps in the segment
            cos2psi: (2.0 * (psi_seg + om * (j as f64 * 0.5 * h))).cos(),
            noise,
            accel,
            lambda,
            z_form,
        };
        let mut acc = Acc::new();
        let mut c_start = (2.0 * psi_seg).cos();
        for i in 0..n_seg {
            let noise = self.noise();
            let mut sa = mk(2 * i, noise);
            sa.cos2psi = c_start;
            let sm = mk(2 * i + 1, noise);
            let se = mk(2 * i + 2, noise);
            c_start = se.cos2psi;
            if self.step >= self.n_info.0 && self.step < self.n_info.1 {
                self.accumulate_info();
            }
            let d = if self.blowup.is_none() && self.step >= self.n_start {
                self.estimator_step(&sa, &sm, &se)
            } else {
                rk4::<false>(&mut self.y, h, &sa, &sm, &se)
            };
            acc.add(&self.y, &d, h);
            self.step += 1;
            if (i + 1) % self.n_rec == 0 {
                self.record(&acc, om, &th);
                acc = Acc::new();
            }
        }
        self.psi_seg = (psi_seg + om * (n_seg as f64 * h)) % TAU;
    }

    /// The record at the end of an interval.
    fn record(&mut self, acc: &Acc, om: f64, th: &paragyro_simulator::plant::Theta) {
        let (a, b) = self.est_theta();
        let n = acc.n as f64;
        let rms = |s: [f64; 2]| [(s[0] / n).sqrt(), (s[1] / n).sqrt()];
        let trace_p = self.trace_p();
        self.records.push(RawRecord {
            t_s: self.step as f64 * self.h / self.w0,
            omega: om,
            theta_drive_est: a,
            theta_sense_est: b,
            theta_drive_true: th.drive,
            theta_sense_true: th.sense,
            drive_amp: 0.5 * (acc.xmax - acc.xmin),
            sense_amp: 0.5 * (acc.ymax - acc.ymin),
            trace_p,
            h_phi_p_phi_max: acc.pp_max,
            e_rms: rms(acc.e2),
            e_true_rms: rms(acc.et2),
            z_rms: rms(acc.z2),
        });
    }

    fn finish(self, wall: Instant) -> RawRun {
        let info = self.cfg.info_window_s.is_some();
        RawRun {
            records: self.records,
            segment_starts_s: self.segment_starts_s,
            h_tau: self.h,
            steps_per_s: self.w0 / self.h,
            steps: self.step,
            lambda_per_tau: self.cfg.lambda_per_tau,
            estimator_blowup_s: self.blowup,
            blowup_h_phi_p_phi: self.blowup_pp,
            rk4_limit_exceeded_s: self.rk4_exceeded,
            info_drive: info.then(|| self.info1.to_vec()),
            info_sense: info.then(|| self.info2.to_vec()),
            wall_s: wall.elapsed().as_secs_f64(),
        }
    }
}

/// Per-record accumulators.
struct Acc {
    n: u64,
    xmin: f64,
    xmax: f64,
    ymin: f64,
    ymax: f64,
    pp_max: [f64; 2],
    e2: [f64; 2],
    et2: [f64; 2],
    z2: [f64; 2],
}

impl Acc {
    fn new() -> Self {
        Self {
            n: 0,
            xmin: f64::INFINITY,
            xmax: f64::NEG_INFINITY,
            ymin: f64::INFINITY,
            ymax: f64::NEG_INFINITY,
            pp_max: [0.0; 2],
            e2: [0.0; 2],
            et2: [0.0; 2],
            z2: [0.0; 2],
        }
    }

    #[inline(always)]
    fn add(&mut self, y: &State, d: &Diag, h: f64) {
        self.n += 1;
        self.xmin = self.xmin.min(y[0]);
        self.xmax = self.xmax.max(y[0]);
        self.ymin = self.ymin.min(y[2]);
        self.ymax = self.ymax.max(y[2]);
        for a in 0..2 {
            self.pp_max[a] = self.pp_max[a].max(h * d.phi_p_phi[a]);
            self.e2[a] += d.e[a] * d.e[a];
            self.et2[a] += d.e_true[a] * d.e_true[a];
            self.z2[a] += d.z[a] * d.z[a];
        }
    }
}
