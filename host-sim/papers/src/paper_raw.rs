//! The paper's own estimator, exactly as the paper states it, on the raw fast signals.
//!
//! This is the *other* estimator: not the product's 500 Hz lock-in RLS (paragyro-core), but
//! sections 3–4 of the seed paper taken literally, to answer "does the code implement the
//! paper, and does the paper hold?".
//!
//! # What is integrated (one ODE, one fixed-step classic RK4)
//!
//! * **The plant**, eq. (6) with θ in the eq. (25) order (pump scale s = 1, no dither):
//!
//!   ```text
//!   X'' = θ11 X' + θ12 X + θ13 Y + θ14 Y' + θ15 X³ + θ16 X cos2ψ + θ17 X³ cos2ψ + θ18 ãx
//!   Y'' = θ21 Y' + θ22 Y + θ23 X + θ24 X' + θ25 Y³ + θ26 ãy,        ψ' = ω (constant)
//!   ```
//!
//! * **The state variables x5 … of eqs. (17)–(19)**: every regressor signal u goes through
//!   the paper's Λ(D) = D² + 3D + 2, realised as `s'' + 3 s' + 2 s = u` from rest, which
//!   delivers both `u/Λ = s` and `D u/Λ = s'` (the paper's eq. (19) feeds the plant state
//!   x2 = X' into a second filter to get D X/Λ; with a *measured* X only, `s'` of the X
//!   filter is the same signal up to a transient X(0)·e^{−τ}). Eight filtered signals:
//!   X, Y, X³, X cos2ψ, X³ cos2ψ, ãx, Y³, ãy, all built from the *measured* X, Y.
//!   The regressors (eq. (17), in the eq. (25) order, i.e. components 3↔4 swapped
//!   relative to eq. (17)/(12) as printed):
//!
//!   ```text
//!   Φ1 = [DX/Λ, X/Λ, Y/Λ, DY/Λ, X³/Λ, X cos2ψ/Λ, X³ cos2ψ/Λ, ãx/Λ]
//!   Φ2 = [DY/Λ, Y/Λ, X/Λ, DX/Λ, Y³/Λ, ãy/Λ]
//!   ```
//!
//! * **The continuous-time least squares of eq. (10)**, for each axis:
//!
//!   ```text
//!   θ̂' = P Φ e,   e = Z − Φᵀ θ̂,   P' = λ P − P Φ Φᵀ P,   P(0) = 1e4·I,  θ̂(0) = 0 (eq. 28)
//!   ```
//!
//!   The full 8×8 and 6×6 matrices P are state variables (as the paper says), integrated
//!   by the same RK4 step as the plant ("discretised faithfully at the integration step").
//!
//! # The measurement Z and the "3, 2" shift (eq. 11, 13, 15)
//!
//! Λ X = X'' + 3X' + 2X gives `X = (3 + θ11) DX/Λ + (2 + θ12) X/Λ + Σ_{i≥3} θ1i Φ1i`, so
//! with the paper's literal measurement Z = X (eqs. 11, 13) the estimated vector is
//! θ1 + [3, 2, 0, …] (exactly what eq. (15) prints: "3 − μx", "2 − (ωx² …)"), and likewise
//! θ2 + [3, 2, 0, …]. The paper's figures and eq. (25) show the unshifted θ, so the shift
//! is removed when θ̂ is reported. [`ZForm::Literal`] (default) is that reading, with
//! θ̂(0) = 0 for the shifted vector (eq. 28) — the reported θ̂ starts at [−3, −2, 0, …].
//! [`ZForm::D2`] uses the equivalent measurement Z = D²X/Λ = X − 3 DX/Λ − 2 X/Λ, for
//! which the unshifted θ̂ itself starts at 0. The two give identical dynamics of the
//! error θ̂ − θ; only the initial error differs.
//!
//! # Forgetting factor
//!
//! eq. (10) with λ = 0.2 — but in which time unit? The model is written in τ = ω0 t, so
//! λ = 0.2 per τ ([`LambdaReading::PaperPerTau`]) is a 5 τ = 74 µs memory (less than one
//! carrier period; FINDINGS §4). Read per second ([`LambdaReading::PerSecond`]) it is a
//! 5 s memory (0.2/ω0 = 2.95e-6 per τ). The product's λ_d = 0.999 per 500 Hz sample is a
//! 2 s memory ([`LambdaReading::Product2s`], −ln(0.999)·500/ω0 = 7.37e-6 per τ). With
//! P' = λP − PΦΦᵀP the information matrix obeys (P⁻¹)' = −λP⁻¹ + ΦΦᵀ, so 1/λ is the
//! memory in τ.
//!
//! # The discretised identity is exact
//!
//! The residual r = Z − Φᵀθ (true θ) is a *linear* function of the combined state whose
//! derivatives obey r'' + 3r' + 2r = 0 identically (the nonlinear terms X³, X cos2ψ, …
//! cancel between the plant and the filters). RK4 integrates such a linear invariant as its
//! own linear ODE, so on noise-free data the regression of eq. (15)–(17) holds at the
//! integration step to rounding (≈ 1e-16 relative) once the e^{−τ} start transient
//! (X(0) ≠ 0 with the filters at rest) has died. The plant's RK4 error (7e-6 at 128
//! steps/period, FINDINGS §1) therefore never biases this estimator: in the paper's own
//! noise-free world every error comes from excitation and conditioning.
//!
//! # What it shows (measured; `write_paper_raw_report`, tests/paper_raw.rs)
//!
//! * Noise-free, λ = 0.2/τ, estimation from the start-up: all 14 θ within 1 % in ≤ 1 ms and
//!   1e-12…1e-6 after, rate 150.000 °/s. With 50 ms per parameter set (the paper's figures
//!   have a time axis in ms) it tracks eqs. 25 → 26 → 27 to ≤ 1e-7 within 2 ms of each
//!   switch, even with the literal pump. This is what Figs 9–14 show, and only the per-τ
//!   reading of λ can produce it.
//! * With 0.2–0.5 s per set, P winds up in the directions the steady state does not excite
//!   (trace P ≈ 4e11 drive, 3e13 sense), the regressor leaves that subspace at the switch,
//!   2h·ΦᵀPΦ jumps past RK4's stability limit and the explicit step overflows within
//!   microseconds. A 4× finer step (512/period) survives and tracks the re-centred sets to
//!   ≤ 2e-6; with the
//!   literal pump the drive dies (< 1 % of nominal 85 ms after the +50 % switch), the sense
//!   loses all excitation and P overflows at 0.73 s even with the fine step.
//! * The paper's P0 = 1e4·I on an already running gyro gives h·ΦᵀP0Φ ≈ 670: immediate
//!   divergence. The paper's set-up works only from a small-amplitude start-up.
//! * With 1 pm/√Hz of displacement noise, λ = 0.2/τ (5 τ of memory) is useless (errors
//!   10…1e4, rate off by 1e5 °/s). With seconds of memory (0.2/s or 2 s) the steady state
//!   leaves θ14 (the rate-carrying Y' coefficient) and, more weakly, θ17, θ24 poorly
//!   determined: the pump-only steady state has no information on θ14 at all (scaled
//!   condition number ≈ 7e17), and these estimators cannot follow any parameter change.
//!
//! # Noise and time grid
//!
//! Optional white displacement noise on the measured X and Y, one independent normal per
//! RK4 step and axis with σ = density·√(1/(2 h_sec)) (as in [`paragyro_simulator::plant`]), held over
//! the step. The step is `h = ω0·record_every_s / n` with n the smallest integer that gives
//! ≥ `steps_per_period` steps per carrier period 2π/ω at the largest ω of the run, so the
//! records fall exactly on the step grid. Parameter sets and pump frequencies switch at step
//! boundaries; ψ is continuous.

use std::f64::consts::TAU;
use std::fmt::Write as _;
use std::path::Path;
use std::sync::Once;
use std::time::Instant;

use anyhow::{Context, Result};
use paragyro_core::physics::{
    OMEGA0_TABLE2_RAD_S, Physical, TABLE2, physical_from_theta, rate_dps_from_gamma,
    theta_from_physical,
};
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::Serialize;
use serde_json::{Value, json};

use paragyro_simulator::plant::{ACCEL_TABLE2, Theta};
use paragyro_simulator::runner::{self, Precision, RunOptions};
use paragyro_simulator::scenario::Scenario;
use paragyro_simulator::trace::{RunResult, THETA_DRIVE_NAMES, THETA_SENSE_NAMES};

// =============================================================================================
// Configuration
// =============================================================================================

/// The paper's forgetting factor (eq. 10, section 4).
pub const PAPER_LAMBDA: f64 = 0.2;
/// The paper's initial covariance P(0) = 1e4·I (section 4).
pub const PAPER_P0: f64 = 1e4;
/// The paper's Λ(D) = D² + 3D + 2: coefficients (a1, a0) of D and 1.
const LAMBDA_A1: f64 = 3.0;
const LAMBDA_A0: f64 = 2.0;

/// How the measurement Z of eq. (10) is formed (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum ZForm {
    /// Z = X (eqs. 11, 13): the estimated vector is θ + [3, 2, 0, …], starting at 0.
    Literal,
    /// Z = D²X/Λ = X − 3 DX/Λ − 2 X/Λ: the estimated vector is θ itself, starting at 0.
    D2,
}

/// Readings of the paper's λ = 0.2 (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub enum LambdaReading {
    /// λ = 0.2 per τ (the model's time unit): 5 τ = 74 µs memory.
    PaperPerTau,
    /// λ = 0.2 per second: 5 s memory.
    PerSecond,
    /// 2 s memory, the product's λ_d = 0.999 per 500 Hz sample.
    Product2s,
    /// Any λ, per τ.
    PerTau(f64),
}

impl LambdaReading {
    /// λ in 1/τ for the time scale `omega0_rad_s`.
    pub fn per_tau(self, omega0_rad_s: f64) -> f64 {
        match self {
            LambdaReading::PaperPerTau => PAPER_LAMBDA,
            LambdaReading::PerSecond => PAPER_LAMBDA / omega0_rad_s,
            LambdaReading::Product2s => -(0.999f64.ln()) * 500.0 / omega0_rad_s,
            LambdaReading::PerTau(l) => l,
        }
    }

    /// Memory 1/λ in seconds.
    pub fn memory_s(self, omega0_rad_s: f64) -> f64 {
        1.0 / (self.per_tau(omega0_rad_s) * omega0_rad_s)
    }

    /// Short label for tables and legends.
    pub fn label(self) -> String {
        match self {
            LambdaReading::PaperPerTau => "λ = 0.2/τ (74 µs)".into(),
            LambdaReading::PerSecond => "λ = 0.2/s (5 s)".into(),
            LambdaReading::Product2s => "λ = 0.5/s (2 s, product)".into(),
            LambdaReading::PerTau(l) => format!("λ = {l:.3e}/τ"),
        }
    }

    /// Machine-friendly key.
    pub fn key(self) -> String {
        match self {
            LambdaReading::PaperPerTau => "per_tau".into(),
            LambdaReading::PerSecond => "per_second".into(),
            LambdaReading::Product2s => "memory_2s".into(),
            LambdaReading::PerTau(l) => format!("per_tau_{l:e}"),
        }
    }
}

/// Settings of one run of the raw paper estimator.
#[derive(Clone, Debug)]
pub struct RawConfig {
    /// Time scale ω0, rad/s (τ = ω0 t).
    pub omega0_rad_s: f64,
    /// Minimum RK4 steps per carrier period 2π/ω at the largest ω of the run (≥ 128).
    pub steps_per_period: usize,
    /// One-sided white displacement noise density on the measured X and Y, L0/√Hz.
    pub noise_density: f64,
    /// Seed of the noise generator.
    pub seed: u64,
    /// Forgetting factor λ of eq. (10), per τ.
    pub lambda_per_tau: f64,
    /// Initial covariance P(0) = p0·I.
    pub p0: f64,
    /// Measurement form.
    pub z_form: ZForm,
    /// Record interval, s (the step grid is aligned to it).
    pub record_every_s: f64,
    /// Initial plant state [X, X', Y, Y'].
    pub x0: [f64; 4],
    /// Constant accelerations [ãx, ãy].
    pub accel: [f64; 2],
    /// The estimator (θ̂, P) is held at its initial value until this time, s (the plant and
    /// the Λ filters run from 0). 0 = the paper (estimation from the start).
    pub estimator_start_s: f64,
    /// θ with which the equation error [`RawRecord::e_true_rms`] is evaluated, if not the
    /// plant's own (to check that the identity is sensitive to θ).
    pub model_theta: Option<Theta>,
    /// Window `[from, to)` in s over which the information matrices ∫ΦΦᵀdτ are accumulated
    /// (for identifiability diagnostics), if any.
    pub info_window_s: Option<(f64, f64)>,
}

impl Default for RawConfig {
    /// Table 2 time scale, 128 steps/period, no noise, the paper's λ = 0.2/τ, P0 = 1e4·I,
    /// literal Z = X, 1 ms records, X(0) = 0.01, ãx = ãy = 0.0213 (10 g).
    fn default() -> Self {
        Self {
            omega0_rad_s: OMEGA0_TABLE2_RAD_S,
            steps_per_period: 128,
            noise_density: 0.0,
            seed: 1,
            lambda_per_tau: PAPER_LAMBDA,
            p0: PAPER_P0,
            z_form: ZForm::Literal,
            record_every_s: 1e-3,
            x0: [0.01, 0.0, 0.0, 0.0],
            accel: [ACCEL_TABLE2, ACCEL_TABLE2],
            estimator_start_s: 0.0,
            model_theta: None,
            info_window_s: None,
        }
    }
}

/// One segment of a run: the plant's θ and the pump's ω (half the pump frequency, units of
/// ω0) held for `duration_s`.
#[derive(Clone, Copy, Debug)]
pub struct Segment {
    /// Length, s (rounded to the step grid).
    pub duration_s: f64,
    /// The plant's θ during the segment (eq. 25 order).
    pub theta: Theta,
    /// Pump ω = ψ' during the segment.
    pub omega: f64,
}

// =============================================================================================
// The combined ODE: plant (4) + Λ filters (8 × 2) + θ1 (8) + P1 (64) + θ2 (6) + P2 (36)
// =============================================================================================

/// Classic RK4 is stable for y' = −a·y, a > 0, only while h·a ≲ 2.785. Along Φ, θ̂' = PΦe
/// has the rate ΦᵀPΦ and the linearised Riccati equation P' = λP − PΦΦᵀP up to 2ΦᵀPΦ.
pub const RK4_STABILITY_LIMIT: f64 = 2.785;

/// Filtered signals, in this order.
const F_X: usize = 0;
const F_Y: usize = 1;
const F_X3: usize = 2;
const F_XC: usize = 3;
const F_X3C: usize = 4;
const F_AX: usize = 5;
const F_Y3: usize = 6;
const F_AY: usize = 7;
const NF: usize = 8;

const I_Z: usize = 0;
const I_F: usize = 4;
const I_T1: usize = I_F + 2 * NF;
const I_P1: usize = I_T1 + 8;
const I_T2: usize = I_P1 + 64;
const I_P2: usize = I_T2 + 6;
/// Size of the combined state.
const NS: usize = I_P2 + 36;

type State = [f64; NS];

/// What the right-hand side needs besides the state, at one stage.
#[derive(Clone, Copy)]
struct Stage<'a> {
    theta: &'a Theta,
    /// θ of the equation-error diagnostic.
    model: &'a Theta,
    cos2psi: f64,
    noise: [f64; 2],
    accel: [f64; 2],
    lambda: f64,
    z_form: ZForm,
}

/// Diagnostics of one evaluation of the right-hand side.
#[derive(Clone, Copy, Default)]
struct Diag {
    /// Estimator errors e1, e2 (eq. 13).
    e: [f64; 2],
    /// Equation errors with the true θ: Z − Φᵀθ_true (shifted as the estimator's θ).
    e_true: [f64; 2],
    /// The measurements Z1, Z2.
    z: [f64; 2],
    /// Φᵀ P Φ (the stiffness of the Riccati equation along Φ).
    phi_p_phi: [f64; 2],
}

/// Regressors Φ1, Φ2 (eq. 25 order) from the filter states.
#[inline(always)]
fn regressors(y: &State) -> ([f64; 8], [f64; 6]) {
    let s = |j: usize| y[I_F + 2 * j];
    let ds = |j: usize| y[I_F + 2 * j + 1];
    (
        [
            ds(F_X),
            s(F_X),
            s(F_Y),
            ds(F_Y),
            s(F_X3),
            s(F_XC),
            s(F_X3C),
            s(F_AX),
        ],
        [ds(F_Y), s(F_Y), s(F_X), ds(F_X), s(F_Y3), s(F_AY)],
    )
}

/// The shift between the estimator's vector and the eq. (25) θ ([3, 2, 0, …] for
/// [`ZForm::Literal`], 0 for [`ZForm::D2`]).
fn shift(z_form: ZForm) -> f64 {
    match z_form {
        ZForm::Literal => 1.0,
        ZForm::D2 => 0.0,
    }
}

/// One axis of eq. (10): writes θ̂' and P' into `dth`, `dp`; returns (e, ΦᵀPΦ).
#[inline(always)]
fn ls_axis<const N: usize>(
    th: &[f64],
    p: &[f64],
    phi: &[f64; N],
    z: f64,
    lambda: f64,
    dth: &mut [f64],
    dp: &mut [f64],
) -> (f64, f64) {
    let mut e = z;
    for i in 0..N {
        e -= phi[i] * th[i];
    }
    let mut v = [0.0; N];
    for i in 0..N {
        let row = &p[i * N..(i + 1) * N];
        let mut acc = 0.0;
        for j in 0..N {
            acc += row[j] * phi[j];
        }
        v[i] = acc;
    }
    let mut pp = 0.0;
    for i in 0..N {
        pp += phi[i] * v[i];
        dth[i] = v[i] * e;
        let row = &p[i * N..(i + 1) * N];
        let drow = &mut dp[i * N..(i + 1) * N];
        for j in 0..N {
            drow[j] = lambda * row[j] - v[i] * v[j];
        }
    }
    (e, pp)
}

/// d/dτ of the combined state. With `EST = false` the estimator (θ̂, P) is frozen.
#[inline(always)]
fn rhs<const EST: bool>(y: &State, st: &Stage<'_>, dy: &mut State) -> Diag {
    let [x, xd, yv, yd] = [y[0], y[1], y[2], y[3]];
    let t1 = &st.theta.drive;
    let t2 = &st.theta.sense;
    let c = st.cos2psi;
    let [ax, ay] = st.accel;
    // ---- plant, eq. (6) (s = 1)
    let x3 = x * x * x;
    dy[I_Z] = xd;
    dy[I_Z + 1] = (t1[0] * xd + t1[3] * yd)
        + (t1[2] * yv + t1[7] * ax)
        + x * (t1[1] + t1[5] * c)
        + x3 * (t1[4] + t1[6] * c);
    dy[I_Z + 2] = yd;
    dy[I_Z + 3] =
        (t2[0] * yd + t2[3] * xd) + (t2[2] * x + t2[5] * ay) + yv * (t2[1] + t2[4] * (yv * yv));
    // ---- the measurement and the filter inputs (eq. 17)
    let xm = x + st.noise[0];
    let ym = yv + st.noise[1];
    let xm3 = xm * xm * xm;
    let u: [f64; NF] = [xm, ym, xm3, xm * c, xm3 * c, ax, ym * ym * ym, ay];
    for j in 0..NF {
        let s = y[I_F + 2 * j];
        let ds = y[I_F + 2 * j + 1];
        dy[I_F + 2 * j] = ds;
        dy[I_F + 2 * j + 1] = u[j] - LAMBDA_A1 * ds - LAMBDA_A0 * s;
    }
    // ---- measurements Z (module docs)
    let (phi1, phi2) = regressors(y);
    let sh = shift(st.z_form);
    let (z1, z2) = match st.z_form {
        ZForm::Literal => (xm, ym),
        ZForm::D2 => (
            xm - LAMBDA_A1 * phi1[0] - LAMBDA_A0 * phi1[1],
            ym - LAMBDA_A1 * phi2[0] - LAMBDA_A0 * phi2[1],
        ),
    };
    // equation errors with the model θ (shifted like the estimator's vector)
    let (m1, m2) = (&st.model.drive, &st.model.sense);
    let mut et1 = z1 - sh * (LAMBDA_A1 * phi1[0] + LAMBDA_A0 * phi1[1]);
    for i in 0..8 {
        et1 -= phi1[i] * m1[i];
    }
    let mut et2 = z2 - sh * (LAMBDA_A1 * phi2[0] + LAMBDA_A0 * phi2[1]);
    for i in 0..6 {
        et2 -= phi2[i] * m2[i];
    }
    let mut d = Diag {
        e_true: [et1, et2],
        z: [z1, z2],
        ..Diag::default()
    };
    // ---- eq. (10), both axes
    if EST {
        let (a, b) = dy.split_at_mut(I_P1);
        let (e1, pp1) = ls_axis::<8>(
            &y[I_T1..I_T1 + 8],
            &y[I_P1..I_P1 + 64],
            &phi1,
            z1,
            st.lambda,
            &mut a[I_T1..I_T1 + 8],
            &mut b[..64],
        );
        let (a, b) = dy.split_at_mut(I_P2);
        let (e2, pp2) = ls_axis::<6>(
            &y[I_T2..I_T2 + 6],
            &y[I_P2..I_P2 + 36],
            &phi2,
            z2,
            st.lambda,
            &mut a[I_T2..I_T2 + 6],
            &mut b[..36],
        );
        d.e = [e1, e2];
        d.phi_p_phi = [pp1, pp2];
    } else {
        dy[I_T1..].fill(0.0);
    }
    d
}

/// One classic RK4 step of the combined state; returns the diagnostics at the step start.
#[inline(always)]
fn rk4<const EST: bool>(
    y: &mut State,
    h: f64,
    sa: &Stage<'_>,
    sm: &Stage<'_>,
    se: &Stage<'_>,
) -> Diag {
    let mut k1 = [0.0; NS];
    let mut k2 = [0.0; NS];
    let mut k3 = [0.0; NS];
    let mut k4 = [0.0; NS];
    let mut yt = [0.0; NS];
    let hh = 0.5 * h;
    let d = rhs::<EST>(y, sa, &mut k1);
    for i in 0..NS {
        yt[i] = y[i] + hh * k1[i];
    }
    rhs::<EST>(&yt, sm, &mut k2);
    for i in 0..NS {
        yt[i] = y[i] + hh * k2[i];
    }
    rhs::<EST>(&yt, sm, &mut k3);
    for i in 0..NS {
        yt[i] = y[i] + h * k3[i];
    }
    rhs::<EST>(&yt, se, &mut k4);
    let h6 = h / 6.0;
    for i in 0..NS {
        y[i] += h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
    }
    d
}

// =============================================================================================
// Runs
// =============================================================================================

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
    let w0 = cfg.omega0_rad_s;
    let t_rec = w0 * cfg.record_every_s; // τ per record
    let h_max = TAU / (omega_max(segments) * cfg.steps_per_period as f64);
    let n_rec = (t_rec / h_max).ceil().max(1.0) as u64;
    if n_rec > 100_000_000 {
        return Err("too many steps per record".into());
    }
    let h = t_rec / n_rec as f64;
    let h_sec = h / w0;
    let sigma = cfg.noise_density * (1.0 / (2.0 * h_sec)).sqrt();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(cfg.seed);
    let lambda = cfg.lambda_per_tau;
    let sh = shift(cfg.z_form);

    let mut y: State = [0.0; NS];
    y[..4].copy_from_slice(&cfg.x0);
    for i in 0..8 {
        y[I_P1 + 9 * i] = cfg.p0;
    }
    for i in 0..6 {
        y[I_P2 + 7 * i] = cfg.p0;
    }
    let est_theta = |y: &State| {
        let mut a = [0.0; 8];
        let mut b = [0.0; 6];
        a.copy_from_slice(&y[I_T1..I_T1 + 8]);
        b.copy_from_slice(&y[I_T2..I_T2 + 6]);
        a[0] -= sh * LAMBDA_A1;
        a[1] -= sh * LAMBDA_A0;
        b[0] -= sh * LAMBDA_A1;
        b[1] -= sh * LAMBDA_A0;
        (a, b)
    };
    let trace_p = |y: &State| {
        let t1: f64 = (0..8).map(|i| y[I_P1 + 9 * i]).sum();
        let t2: f64 = (0..6).map(|i| y[I_P2 + 7 * i]).sum();
        [t1, t2]
    };

    let mut records = Vec::new();
    let mut segment_starts_s = Vec::new();
    {
        let (a, b) = est_theta(&y);
        records.push(RawRecord {
            t_s: 0.0,
            omega: segments[0].omega,
            theta_drive_est: a,
            theta_sense_est: b,
            theta_drive_true: segments[0].theta.drive,
            theta_sense_true: segments[0].theta.sense,
            drive_amp: cfg.x0[0].abs(),
            sense_amp: cfg.x0[2].abs(),
            trace_p: trace_p(&y),
            h_phi_p_phi_max: [0.0; 2],
            e_rms: [0.0; 2],
            e_true_rms: [0.0; 2],
            z_rms: [0.0; 2],
        });
    }
    let mut step: u64 = 0;
    let mut psi_seg = 0.0f64; // ψ at the start of the segment
    let mut blowup: Option<f64> = None;
    let mut blowup_pp: Option<[f64; 2]> = None;
    let mut rk4_exceeded: Option<f64> = None;
    let mut saved = [0.0; NS - I_T1];
    let n_start = (cfg.estimator_start_s * w0 / h).round().max(0.0) as u64;
    let (n_info0, n_info1) = match cfg.info_window_s {
        Some((a, b)) => ((a * w0 / h).round() as u64, (b * w0 / h).round() as u64),
        None => (u64::MAX, u64::MAX),
    };
    let mut info1 = [0.0; 64];
    let mut info2 = [0.0; 36];
    for seg in segments {
        segment_starts_s.push(step as f64 * h / w0);
        let n_seg = ((seg.duration_s * w0 / t_rec).round().max(1.0) as u64) * n_rec;
        let th = seg.theta;
        let model = cfg.model_theta.unwrap_or(th);
        let om = seg.omega;
        let mk = |j: u64, noise: [f64; 2]| Stage {
            theta: &th,
            model: &model,
            // ψ = ψ_seg + ω·(j h/2), j counting half steps in the segment
            cos2psi: (2.0 * (psi_seg + om * (j as f64 * 0.5 * h))).cos(),
            noise,
            accel: cfg.accel,
            lambda,
            z_form: cfg.z_form,
        };
        let mut acc = Acc::new();
        let mut c_start = (2.0 * psi_seg).cos();
        for i in 0..n_seg {
            let noise = if sigma > 0.0 {
                let a: f64 = StandardNormal.sample(&mut rng);
                let b: f64 = StandardNormal.sample(&mut rng);
                [sigma * a, sigma * b]
            } else {
                [0.0; 2]
            };
            let mut sa = mk(2 * i, noise);
            sa.cos2psi = c_start;
            let sm = mk(2 * i + 1, noise);
            let se = mk(2 * i + 2, noise);
            c_start = se.cos2psi;
            if step >= n_info0 && step < n_info1 {
                // rectangle rule at the step start (the window is many periods long)
                let (p1, p2) = regressors(&y);
                for a in 0..8 {
                    for b in 0..8 {
                        info1[8 * a + b] += h * p1[a] * p1[b];
                    }
                }
                for a in 0..6 {
                    for b in 0..6 {
                        info2[6 * a + b] += h * p2[a] * p2[b];
                    }
                }
            }
            let d = if blowup.is_none() && step >= n_start {
                saved.copy_from_slice(&y[I_T1..]);
                let d = rk4::<true>(&mut y, h, &sa, &sm, &se);
                let chk: f64 = y[I_T1..I_T1 + 8].iter().sum::<f64>()
                    + y[I_T2..I_T2 + 6].iter().sum::<f64>()
                    + trace_p(&y).iter().sum::<f64>();
                let pp_max = d.phi_p_phi[0].max(d.phi_p_phi[1]);
                let pp_min = d.phi_p_phi[0].min(d.phi_p_phi[1]);
                if rk4_exceeded.is_none()
                    && (2.0 * h * pp_max > RK4_STABILITY_LIMIT || pp_min < 0.0)
                {
                    rk4_exceeded = Some(step as f64 * h / w0);
                }
                if !chk.is_finite() {
                    y[I_T1..].copy_from_slice(&saved);
                    blowup = Some((step + 1) as f64 * h / w0);
                    blowup_pp = Some([h * d.phi_p_phi[0], h * d.phi_p_phi[1]]);
                }
                d
            } else {
                rk4::<false>(&mut y, h, &sa, &sm, &se)
            };
            acc.add(&y, &d, h);
            step += 1;
            if (i + 1) % n_rec == 0 {
                let (a, b) = est_theta(&y);
                let n = acc.n as f64;
                let rms = |s: [f64; 2]| [(s[0] / n).sqrt(), (s[1] / n).sqrt()];
                records.push(RawRecord {
                    t_s: step as f64 * h / w0,
                    omega: om,
                    theta_drive_est: a,
                    theta_sense_est: b,
                    theta_drive_true: th.drive,
                    theta_sense_true: th.sense,
                    drive_amp: 0.5 * (acc.xmax - acc.xmin),
                    sense_amp: 0.5 * (acc.ymax - acc.ymin),
                    trace_p: trace_p(&y),
                    h_phi_p_phi_max: acc.pp_max,
                    e_rms: rms(acc.e2),
                    e_true_rms: rms(acc.et2),
                    z_rms: rms(acc.z2),
                });
                acc = Acc::new();
            }
        }
        psi_seg = (psi_seg + om * (n_seg as f64 * h)) % TAU;
    }
    Ok(RawRun {
        records,
        segment_starts_s,
        h_tau: h,
        steps_per_s: w0 / h,
        steps: step,
        lambda_per_tau: lambda,
        estimator_blowup_s: blowup,
        blowup_h_phi_p_phi: blowup_pp,
        rk4_limit_exceeded_s: rk4_exceeded,
        info_drive: cfg.info_window_s.map(|_| info1.to_vec()),
        info_sense: cfg.info_window_s.map(|_| info2.to_vec()),
        wall_s: wall.elapsed().as_secs_f64(),
    })
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

// =============================================================================================
// Helpers on records
// =============================================================================================

/// |est − true| / |true| (absolute error where the truth is 0; NaN stays NaN).
pub fn rel_err(est: f64, truth: f64) -> f64 {
    if truth != 0.0 {
        ((est - truth) / truth).abs()
    } else {
        (est - truth).abs()
    }
}

/// Relative errors of the 14 θ components of a record (θ11…θ18, θ21…θ26).
pub fn theta_rel_errors(r: &RawRecord) -> [f64; 14] {
    let mut out = [0.0; 14];
    for j in 0..8 {
        out[j] = rel_err(r.theta_drive_est[j], r.theta_drive_true[j]);
    }
    for j in 0..6 {
        out[8 + j] = rel_err(r.theta_sense_est[j], r.theta_sense_true[j]);
    }
    out
}

/// Time from `t0` after which the relative error of θ component `j` (0..14) stays below
/// `tol` up to and including `t1` (`Some(0)` if it always does, `None` if it is not below at
/// `t1`). Only records with `t0 < t ≤ t1` count.
pub fn settle_time(records: &[RawRecord], j: usize, tol: f64, t0: f64, t1: f64) -> Option<f64> {
    let win: Vec<&RawRecord> = records
        .iter()
        .filter(|r| r.t_s > t0 && r.t_s <= t1 + 1e-12)
        .collect();
    let bad = |r: &RawRecord| {
        let e = theta_rel_errors(r)[j];
        e.is_nan() || e >= tol
    };
    match win.iter().rposition(|r| bad(r)) {
        None => Some(0.0),
        Some(i) if i + 1 == win.len() => None,
        Some(i) => Some(win[i].t_s - t0),
    }
}

/// Physical parameters (corrected Table 3) of the estimate and of the truth of a record.
pub fn physical_of(r: &RawRecord) -> (Physical, Physical) {
    (
        physical_from_theta(&r.theta_drive_est, &r.theta_sense_est),
        physical_from_theta(&r.theta_drive_true, &r.theta_sense_true),
    )
}

// =============================================================================================
// Scenario 1/2: the paper's ±50 % test, literal and with the pump re-centred
// =============================================================================================

/// The paper's three parameter sets from physical parameters `p`: eq. (25) (nominal),
/// eq. (26) (every component ×1.5 except the input gains θ18, θ26) and eq. (27) (×0.5).
/// From Table 2 these are eqs. (25)–(27) with the errata of DERIVATION.md §0 (θ24 =
/// −1.77e-4, θ25 = −αy = −0.001264).
pub fn paper_sets(p: &Physical) -> [Theta; 3] {
    let (d, s) = theta_from_physical(p);
    let scaled = |f: f64| {
        let mut t = Theta { drive: d, sense: s };
        for v in &mut t.drive[..7] {
            *v *= f;
        }
        for v in &mut t.sense[..5] {
            *v *= f;
        }
        t
    };
    [scaled(1.0), scaled(1.5), scaled(0.5)]
}

/// The pump in the ±50 % test.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Pump {
    /// Left at ω = √1.0265 for all three sets (the paper as written).
    Literal,
    /// Re-centred to ω = √(−θ22) of each set (keeps the drive inside its parametric band).
    Recentred,
}

/// Options of the ±50 % test.
#[derive(Clone, Copy, Debug)]
pub struct SwitchOptions {
    /// Pump policy.
    pub pump: Pump,
    /// Forgetting factor reading.
    pub lambda: LambdaReading,
    /// Length of each of the three segments, s.
    pub segment_s: f64,
    /// White displacement noise density, L0/√Hz (the paper: none).
    pub noise_density: f64,
    /// Noise seed.
    pub seed: u64,
    /// Measurement form.
    pub z_form: ZForm,
    /// Record interval, s.
    pub record_every_s: f64,
    /// Minimum RK4 steps per carrier period (128 = the plant's step).
    pub steps_per_period: usize,
}

impl SwitchOptions {
    /// Noise-free, literal Z, 0.5 s per set, 1 ms records.
    pub fn new(pump: Pump, lambda: LambdaReading) -> Self {
        Self {
            pump,
            lambda,
            segment_s: 0.5,
            noise_density: 0.0,
            seed: 1,
            z_form: ZForm::Literal,
            record_every_s: 1e-3,
            steps_per_period: 128,
        }
    }

    /// The paper's time scale: 50 ms per set (its Figs 9–14 have a time axis in ms),
    /// 0.1 ms records.
    pub fn ms_scale(pump: Pump, lambda: LambdaReading) -> Self {
        Self {
            segment_s: 0.05,
            record_every_s: 1e-4,
            ..Self::new(pump, lambda)
        }
    }
}

/// Outcome of one parameter set (segment) of a run.
#[derive(Clone, Debug, Serialize)]
pub struct SegmentSummary {
    /// "eq. 25", "eq. 26 (+50 %)", "eq. 27 (−50 %)".
    pub label: String,
    /// Start and end, s.
    pub start_s: f64,
    /// End, s.
    pub end_s: f64,
    /// Pump ω.
    pub omega: f64,
    /// Relative θ errors at the end of the segment (θ11…θ18, θ21…θ26).
    pub final_rel_err: [f64; 14],
    /// Time from the segment start after which each θ stays within 10 %.
    pub within_10pct_s: [Option<f64>; 14],
    /// … within 1 %.
    pub within_1pct_s: [Option<f64>; 14],
    /// Drive amplitude at the end of the segment, L0.
    pub drive_amp_end: f64,
    /// Sense amplitude at the end of the segment, L0.
    pub sense_amp_end: f64,
    /// Estimated and true rate at the end, °/s.
    pub rate_dps_est: f64,
    /// True rate, °/s.
    pub rate_dps_true: f64,
}

/// Summaries of the segments of a run.
pub fn segment_summaries(run: &RawRun, labels: &[&str], omega0_rad_s: f64) -> Vec<SegmentSummary> {
    let t_end = run.records.last().map_or(0.0, |r| r.t_s);
    (0..run.segment_starts_s.len())
        .map(|k| {
            let t0 = run.segment_starts_s[k];
            let t1 = run.segment_starts_s.get(k + 1).copied().unwrap_or(t_end);
            let last = run
                .records
                .iter()
                .rev()
                .find(|r| r.t_s <= t1 + 1e-12)
                .expect("records");
            let (pe, pt) = physical_of(last);
            SegmentSummary {
                label: labels
                    .get(k)
                    .map_or_else(|| format!("segment {k}"), |s| s.to_string()),
                start_s: t0,
                end_s: t1,
                omega: last.omega,
                final_rel_err: theta_rel_errors(last),
                within_10pct_s: std::array::from_fn(|j| settle_time(&run.records, j, 0.1, t0, t1)),
                within_1pct_s: std::array::from_fn(|j| settle_time(&run.records, j, 0.01, t0, t1)),
                drive_amp_end: last.drive_amp,
                sense_amp_end: last.sense_amp,
                rate_dps_est: rate_dps_from_gamma(pe.gamma, omega0_rad_s),
                rate_dps_true: rate_dps_from_gamma(pt.gamma, omega0_rad_s),
            }
        })
        .collect()
}

/// Labels of the three sets.
pub const SET_LABELS: [&str; 3] = ["eq. 25", "eq. 26 (+50 %)", "eq. 27 (−50 %)"];

/// Result of the ±50 % test.
#[derive(Clone, Debug, Serialize)]
pub struct SwitchResult {
    /// "paper-raw literal" or "paper-raw variant".
    pub name: String,
    /// Pump policy.
    pub pump: Pump,
    /// λ reading.
    pub lambda: LambdaReading,
    /// λ per τ.
    pub lambda_per_tau: f64,
    /// Noise density, L0/√Hz.
    pub noise_density: f64,
    /// Length of each set, s.
    pub segment_s: f64,
    /// Minimum RK4 steps per carrier period.
    pub steps_per_period: usize,
    /// The run (records not serialised; see [`run_summary`]).
    #[serde(skip)]
    pub run: RawRun,
    /// One summary per set.
    pub segments: Vec<SegmentSummary>,
    /// Drive amplitude at the end of the nominal set, L0.
    pub drive_amp_nominal: f64,
    /// Time after the +50 % switch at which the drive amplitude first falls below 1 % of
    /// `drive_amp_nominal`, s.
    pub drive_below_1pct_after_s: Option<f64>,
    /// Smallest drive amplitude in the last 10 % of each of the +50 % and −50 % sets,
    /// relative to `drive_amp_nominal`.
    pub drive_amp_rel_end: [f64; 2],
}

/// The paper's ±50 % test (sets of [`paper_sets`] from Table 2, `segment_s` each) on the
/// raw estimator: `Pump::Literal` is "paper-raw literal", `Pump::Recentred` is
/// "paper-raw variant". The plant starts from X(0) = 0.01 at rest.
pub fn paper_switch(opts: &SwitchOptions) -> Result<SwitchResult, String> {
    let w0 = OMEGA0_TABLE2_RAD_S;
    let sets = paper_sets(&TABLE2);
    let lit = 1.0265f64.sqrt();
    let segs: Vec<Segment> = sets
        .iter()
        .map(|th| Segment {
            duration_s: opts.segment_s,
            theta: *th,
            omega: match opts.pump {
                Pump::Literal => lit,
                Pump::Recentred => (-th.sense[1]).sqrt(),
            },
        })
        .collect();
    let cfg = RawConfig {
        omega0_rad_s: w0,
        noise_density: opts.noise_density,
        seed: opts.seed,
        lambda_per_tau: opts.lambda.per_tau(w0),
        z_form: opts.z_form,
        record_every_s: opts.record_every_s,
        steps_per_period: opts.steps_per_period,
        ..RawConfig::default()
    };
    let run = simulate(&cfg, &segs)?;
    let segments = segment_summaries(&run, &SET_LABELS, w0);
    let nominal = segments[0].drive_amp_end;
    let t_switch = run.segment_starts_s[1];
    let below = run
        .records
        .iter()
        .find(|r| r.t_s > t_switch && r.drive_amp < 0.01 * nominal)
        .map(|r| r.t_s - t_switch);
    let tail_min = |k: usize| {
        let (a, b) = (segments[k].start_s, segments[k].end_s);
        let from = b - 0.1 * (b - a);
        run.records
            .iter()
            .filter(|r| r.t_s > from && r.t_s <= b + 1e-12)
            .map(|r| r.drive_amp)
            .fold(f64::INFINITY, f64::min)
            / nominal
    };
    Ok(SwitchResult {
        name: match opts.pump {
            Pump::Literal => "paper-raw literal".into(),
            Pump::Recentred => "paper-raw variant".into(),
        },
        pump: opts.pump,
        lambda: opts.lambda,
        lambda_per_tau: cfg.lambda_per_tau,
        noise_density: opts.noise_density,
        segment_s: opts.segment_s,
        steps_per_period: opts.steps_per_period,
        drive_amp_rel_end: [tail_min(1), tail_min(2)],
        run,
        segments,
        drive_amp_nominal: nominal,
        drive_below_1pct_after_s: below,
    })
}

// =============================================================================================
// Scenario 3: side by side with the product's estimator
// =============================================================================================

/// One estimator configuration in the comparison.
#[derive(Clone, Debug, Serialize)]
pub struct CompareRow {
    /// Short label.
    pub label: String,
    /// "paper (raw)" or "product (lock-in)".
    pub estimator: String,
    /// Noise density, L0/√Hz.
    pub noise_density: f64,
    /// Relative θ errors at the end (θ11…θ18, θ21…θ26).
    pub final_rel_err: [f64; 14],
    /// Time from t = 0 after which each θ stays within 10 % to the end.
    pub within_10pct_s: [Option<f64>; 14],
    /// … within 1 %.
    pub within_1pct_s: [Option<f64>; 14],
    /// Recovered rate at the end, °/s (γ̂ via the corrected Table 3).
    pub rate_dps_est: f64,
    /// True rate, °/s.
    pub rate_dps_true: f64,
    /// What the estimator consumes.
    pub data: String,
    /// Sample instants per second the estimator consumes.
    pub samples_per_s: f64,
    /// Real values per second it consumes (all channels).
    pub values_per_s: f64,
    /// Simulated time, s.
    pub sim_s: f64,
    /// Wall time, s.
    pub wall_s: f64,
    /// Estimator blow-up time (raw runs), s.
    pub blowup_s: Option<f64>,
}

/// The side-by-side comparison.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    /// Rows: the raw paper estimator for each λ reading and noise level, then the product.
    pub rows: Vec<CompareRow>,
    /// The raw runs (same order as the first rows).
    #[serde(skip)]
    pub raw_runs: Vec<RawRun>,
    /// The product runs.
    #[serde(skip)]
    pub product_runs: Vec<RunResult>,
}

/// The product's `identify` scenario (the plant of the comparison).
fn identify_scenario() -> Result<Scenario> {
    Scenario::builtin("identify").context("built-in scenario 'identify' is missing")
}

/// The raw estimator on the plant of the product's `identify` scenario (Table 2, 150 °/s,
/// 10 g, X(0) from the scenario), pump fixed at the scenario's centre (√1.0265, no dither),
/// for `sim_s` seconds.
pub fn raw_on_identify_plant(
    lambda: LambdaReading,
    noise_density: f64,
    sim_s: f64,
) -> Result<RawRun> {
    let sc = identify_scenario()?;
    let pa = sc.plant_at(0.0);
    let w0 = sc.omega0_rad_s();
    let omega = sc.pump_centre_hz() / (2.0 * sc.sim.f0_hz);
    let cfg = RawConfig {
        omega0_rad_s: w0,
        noise_density,
        seed: sc.seed,
        lambda_per_tau: lambda.per_tau(w0),
        x0: [sc.plant.initial_x_um, 0.0, sc.plant.initial_y_um, 0.0],
        accel: [pa.accel_x, pa.accel_y],
        ..RawConfig::default()
    };
    let seg = Segment {
        duration_s: sim_s,
        theta: Theta {
            drive: pa.theta_drive,
            sense: pa.theta_sense,
        },
        omega,
    };
    simulate(&cfg, &[seg]).map_err(|e| anyhow::anyhow!("raw estimator: {e}"))
}

fn raw_row(label: String, noise: f64, run: &RawRun, w0: f64) -> CompareRow {
    let seg = &segment_summaries(run, &["nominal"], w0)[0];
    CompareRow {
        label,
        estimator: "paper (raw)".into(),
        noise_density: noise,
        final_rel_err: seg.final_rel_err,
        within_10pct_s: seg.within_10pct_s,
        within_1pct_s: seg.within_1pct_s,
        rate_dps_est: seg.rate_dps_est,
        rate_dps_true: seg.rate_dps_true,
        data: format!(
            "raw X, Y at the integration rate ({:.2} MS/s) + ãx, ãy + pump phase",
            run.steps_per_s / 1e6
        ),
        samples_per_s: run.steps_per_s,
        values_per_s: 4.0 * run.steps_per_s,
        sim_s: seg.end_s,
        wall_s: run.wall_s,
        blowup_s: run.estimator_blowup_s,
    }
}

fn product_row(label: String, noise: f64, res: &RunResult) -> CompareRow {
    let tr = &res.trace;
    let last = tr.last().expect("a run has samples");
    let mut fe = [0.0; 14];
    for j in 0..8 {
        fe[j] = rel_err(last.theta_drive_est[j], last.theta_drive_true[j]);
    }
    for j in 0..6 {
        fe[8 + j] = rel_err(last.theta_sense_est[j], last.theta_sense_true[j]);
    }
    let fs = if tr.len() > 1 {
        1.0 / (tr[1].t_s - tr[0].t_s)
    } else {
        500.0
    };
    CompareRow {
        label,
        estimator: "product (lock-in)".into(),
        noise_density: noise,
        final_rel_err: fe,
        within_10pct_s: std::array::from_fn(|j| runner::settle_time(tr, j, 0.1, 0.0)),
        within_1pct_s: std::array::from_fn(|j| runner::settle_time(tr, j, 0.01, 0.0)),
        rate_dps_est: last.rate_dps_est,
        rate_dps_true: last.rate_dps_true,
        data: format!(
            "14 lock-in channels + 2 accelerometer + pump at {fs:.0} Hz (dither from 1 s)"
        ),
        samples_per_s: fs,
        values_per_s: 17.0 * fs,
        sim_s: last.t_s,
        wall_s: res
            .summary
            .get("wall_seconds")
            .and_then(Value::as_f64)
            .unwrap_or(f64::NAN),
        blowup_s: None,
    }
}

/// λ readings compared everywhere.
pub const LAMBDAS: [LambdaReading; 3] = [
    LambdaReading::PaperPerTau,
    LambdaReading::PerSecond,
    LambdaReading::Product2s,
];

/// Runs `jobs` on up to `threads` threads, results in order.
fn par_map<T: Send, R: Send>(jobs: Vec<T>, threads: usize, f: impl Fn(T) -> R + Sync) -> Vec<R> {
    let n = jobs.len();
    // a stack, first job on top: jobs start in their order
    let queue = std::sync::Mutex::new(jobs.into_iter().enumerate().rev().collect::<Vec<_>>());
    let out = std::sync::Mutex::new((0..n).map(|_| None).collect::<Vec<Option<R>>>());
    std::thread::scope(|s| {
        for _ in 0..threads.max(1) {
            s.spawn(|| {
                loop {
                    let job = queue.lock().expect("queue").pop();
                    let Some((i, j)) = job else { break };
                    let r = f(j);
                    out.lock().expect("results")[i] = Some(r);
                }
            });
        }
    });
    out.into_inner()
        .expect("results")
        .into_iter()
        .map(|r| r.expect("every job ran"))
        .collect()
}

fn threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// The side-by-side comparison on the `identify` plant: the raw paper estimator for each λ
/// reading of [`LAMBDAS`], noise-free and at 1 pm/√Hz, `raw_sim_s` seconds each, against the
/// product's `identify` scenario (f64 core, 10 s, 1 pm/√Hz, and the same noise-free).
pub fn compare(raw_sim_s: f64) -> Result<Comparison> {
    let sc = identify_scenario()?;
    let w0 = sc.omega0_rad_s();
    let noise = sc.sim.noise_pm_rthz * 1e-6;
    enum Job {
        Raw(LambdaReading, f64),
        Product(f64),
    }
    let mut jobs = Vec::new();
    for &n in &[0.0, noise] {
        for &l in &LAMBDAS {
            jobs.push(Job::Raw(l, n));
        }
    }
    jobs.push(Job::Product(noise));
    jobs.push(Job::Product(0.0));
    enum Out {
        Raw(RawRun),
        Product(Box<RunResult>),
    }
    let outs = par_map(jobs, threads(), |j| -> Result<Out> {
        match j {
            Job::Raw(l, n) => Ok(Out::Raw(raw_on_identify_plant(l, n, raw_sim_s)?)),
            Job::Product(n) => {
                let mut s = sc.clone();
                s.sim.noise_pm_rthz = n * 1e6;
                let opts = RunOptions {
                    precision: Precision::F64,
                    seed: None,
                };
                Ok(Out::Product(Box::new(runner::run(&s, &opts, &mut |_| {})?)))
            }
        }
    });
    let mut rows = Vec::new();
    let mut raw_runs = Vec::new();
    let mut product_runs = Vec::new();
    let mut k = 0;
    for o in outs {
        match o? {
            Out::Raw(r) => {
                let (l, n) = (LAMBDAS[k % 3], if k < 3 { 0.0 } else { noise });
                let nl = if n > 0.0 { "1 pm/√Hz" } else { "noise-free" };
                rows.push(raw_row(format!("paper, {}, {nl}", l.label()), n, &r, w0));
                raw_runs.push(r);
                k += 1;
            }
            Out::Product(r) => {
                let n = if product_runs.is_empty() { noise } else { 0.0 };
                let nl = if n > 0.0 { "1 pm/√Hz" } else { "noise-free" };
                rows.push(product_row(
                    format!("product (identify, f64, λd = 0.999), {nl}"),
                    n,
                    &r,
                ));
                product_runs.push(*r);
            }
        }
    }
    Ok(Comparison {
        rows,
        raw_runs,
        product_runs,
    })
}

// =============================================================================================
// Identifiability: the information matrix of the raw regressors
// =============================================================================================

/// Eigen-decomposition of a symmetric `n×n` matrix (row-major) by cyclic Jacobi rotations:
/// eigenvalues in descending order and the matching unit eigenvectors (as rows).
pub fn symmetric_eigen(a: &[f64], n: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    let mut m = a.to_vec();
    let mut v = vec![0.0; n * n];
    for i in 0..n {
        v[i * n + i] = 1.0;
    }
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| m[i * n + j] * m[i * n + j])
            .sum();
        let diag: f64 = (0..n).map(|i| m[i * n + i] * m[i * n + i]).sum();
        if off <= 1e-32 * diag || off == 0.0 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = m[p * n + q];
                if apq == 0.0 {
                    continue;
                }
                let (app, aqq) = (m[p * n + p], m[q * n + q]);
                let theta = (aqq - app) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (mkp, mkq) = (m[k * n + p], m[k * n + q]);
                    m[k * n + p] = c * mkp - s * mkq;
                    m[k * n + q] = s * mkp + c * mkq;
                }
                for k in 0..n {
                    let (mpk, mqk) = (m[p * n + k], m[q * n + k]);
                    m[p * n + k] = c * mpk - s * mqk;
                    m[q * n + k] = s * mpk + c * mqk;
                }
                for k in 0..n {
                    let (vkp, vkq) = (v[k * n + p], v[k * n + q]);
                    v[k * n + p] = c * vkp - s * vkq;
                    v[k * n + q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut idx: Vec<usize> = (0..n).collect();
    idx.sort_by(|&a, &b| m[b * n + b].total_cmp(&m[a * n + a]));
    let vals = idx.iter().map(|&i| m[i * n + i]).collect();
    let vecs = idx
        .iter()
        .map(|&i| (0..n).map(|k| v[k * n + i]).collect())
        .collect();
    (vals, vecs)
}

/// Identifiability of one axis from an information matrix ∫ΦΦᵀdτ.
#[derive(Clone, Debug, Serialize)]
pub struct Identifiability {
    /// Eigenvalues of D·M·D (D = diag|θ|, i.e. relative parameters), descending.
    pub scaled_eigenvalues: Vec<f64>,
    /// Largest / smallest scaled eigenvalue.
    pub condition: f64,
    /// √diag((D M D)⁻¹): relative error of each θ component per unit equation-error
    /// amplitude density (multiply by σ·√h for white noise of std σ per step h).
    pub rel_sensitivity: Vec<f64>,
    /// The component that dominates each of the three weakest directions (1-based θ index
    /// within the axis, weakest first).
    pub weakest_components: Vec<usize>,
    /// The three weakest unit eigenvectors (relative-parameter coordinates), weakest first.
    pub weakest_directions: Vec<Vec<f64>>,
}

/// [`Identifiability`] of the information matrix `info` (n×n, row-major) for the parameter
/// magnitudes `theta`.
pub fn identifiability(info: &[f64], theta: &[f64]) -> Identifiability {
    let n = theta.len();
    let d: Vec<f64> = theta.iter().map(|t| t.abs()).collect();
    let scaled: Vec<f64> = (0..n * n).map(|k| info[k] * d[k / n] * d[k % n]).collect();
    let (vals, vecs) = symmetric_eigen(&scaled, n);
    let rel_sensitivity = (0..n)
        .map(|i| {
            vals.iter()
                .zip(&vecs)
                .map(|(l, v)| v[i] * v[i] / l)
                .sum::<f64>()
                .sqrt()
        })
        .collect();
    let weakest_components = vecs
        .iter()
        .rev()
        .take(3)
        .map(|v| {
            (0..n)
                .max_by(|&a, &b| v[a].abs().total_cmp(&v[b].abs()))
                .unwrap_or(0)
                + 1
        })
        .collect();
    let weakest_directions = vecs.iter().rev().take(3).cloned().collect();
    Identifiability {
        weakest_directions,
        condition: vals[0] / vals[n - 1],
        scaled_eigenvalues: vals,
        rel_sensitivity,
        weakest_components,
    }
}

/// Steady-state (or any window) identifiability of the paper's regressors on Table 2 with
/// the pump at √1.0265: information matrices over `window_s` of a noise-free run (the
/// estimator plays no part), scaled by |θ| (drive, sense).
pub fn window_identifiability(window_s: (f64, f64)) -> Result<(Identifiability, Identifiability)> {
    let sets = paper_sets(&TABLE2);
    let cfg = RawConfig {
        info_window_s: Some(window_s),
        lambda_per_tau: LambdaReading::Product2s.per_tau(OMEGA0_TABLE2_RAD_S),
        ..RawConfig::default()
    };
    let seg = Segment {
        duration_s: window_s.1,
        theta: sets[0],
        omega: 1.0265f64.sqrt(),
    };
    let run = simulate(&cfg, &[seg]).map_err(|e| anyhow::anyhow!(e))?;
    let (Some(i1), Some(i2)) = (&run.info_drive, &run.info_sense) else {
        anyhow::bail!("no information matrix");
    };
    Ok((
        identifiability(i1, &sets[0].drive),
        identifiability(i2, &sets[0].sense),
    ))
}

/// Numbers of a run without its records.
pub fn run_summary(run: &RawRun) -> Value {
    let sim_s = run.records.last().map_or(0.0, |r| r.t_s);
    let max2 = |f: &dyn Fn(&RawRecord) -> [f64; 2]| {
        run.records.iter().fold([0.0f64; 2], |m, r| {
            let v = f(r);
            [m[0].max(v[0]), m[1].max(v[1])]
        })
    };
    json!({
        "h_tau": run.h_tau,
        "steps_per_s": run.steps_per_s,
        "steps": run.steps,
        "sim_s": sim_s,
        "wall_s": run.wall_s,
        "wall_per_sim_s": run.wall_s / sim_s.max(1e-12),
        "lambda_per_tau": run.lambda_per_tau,
        "estimator_blowup_s": run.estimator_blowup_s,
        "blowup_h_phi_p_phi": run.blowup_h_phi_p_phi,
        "rk4_limit_exceeded_s": run.rk4_limit_exceeded_s,
        "max_trace_p": max2(&|r| r.trace_p),
        "max_h_phi_p_phi": max2(&|r| r.h_phi_p_phi_max),
    })
}

// =============================================================================================
// The report: plots (paper Figs 9–14 style) and numbers
// =============================================================================================

/// The finer step of the extra ±50 % runs (4× the plant's): enough for the explicit RK4 to
/// survive the switches with λ = 0.2/τ.
pub const FINE_STEPS_PER_PERIOD: usize = 512;

/// Simulated seconds of each raw run in the comparison.
pub const COMPARE_RAW_S: f64 = 3.0;

/// Font family the embedded DejaVu Sans is registered under (as in [`paragyro_simulator::report`]).
const FONT: &str = "sans-serif";

fn ensure_fonts() {
    static FONTS: Once = Once::new();
    FONTS.call_once(|| {
        // A failure shows up later as a drawing error, which is reported.
        let _ = register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
        let _ = register_font(FONT, FontStyle::Bold, dejavu::sans::bold());
    });
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

const TRUE_COLOR: RGBColor = RGBColor(20, 20, 20);
const LAMBDA_COLORS: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
];
/// 14 distinct colours: the shared tab10 palette and four dark ones.
const TAB14: [RGBColor; 14] = {
    let t = paragyro_simulator::plot::TAB10;
    [
        t[0],
        t[1],
        t[2],
        t[3],
        t[4],
        t[5],
        t[6],
        t[7],
        t[8],
        t[9],
        RGBColor(0, 0, 128),
        RGBColor(128, 0, 0),
        RGBColor(0, 100, 0),
        RGBColor(0, 0, 0),
    ]
};

/// One polyline.
struct Series {
    pts: Vec<(f64, f64)>,
    color: RGBColor,
    dashed: bool,
    label: String,
}

/// One panel.
struct PanelSpec {
    caption: String,
    x: (f64, f64),
    y: (f64, f64),
    x_desc: String,
    y_desc: String,
    log_y: bool,
    series: Vec<Series>,
    vlines: Vec<f64>,
    hlines: Vec<(f64, RGBColor, String)>,
    legend: bool,
}

fn tick(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".into()
    } else if (1e-2..1e4).contains(&a) {
        let s = format!("{v:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.2e}")
    }
}

fn draw_panel(area: &Area<'_>, p: &PanelSpec) -> Result<()> {
    let (x0, x1) = p.x;
    let (y0, y1) = p.y;
    let mut chart = ChartBuilder::on(area)
        .caption(&p.caption, (FONT, 14))
        .margin(5)
        .margin_right(14)
        .x_label_area_size(if p.x_desc.is_empty() { 22 } else { 36 })
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    let log_y = p.log_y;
    let yf = move |v: &f64| {
        if log_y {
            if (v - v.round()).abs() < 1e-9 {
                format!("1e{}", v.round() as i64)
            } else {
                String::new()
            }
        } else {
            tick(*v)
        }
    };
    let mut mesh = chart.configure_mesh();
    mesh.bold_line_style(RGBColor(215, 215, 215))
        .light_line_style(RGBColor(242, 242, 242))
        .x_labels(8)
        .y_labels(6)
        .y_label_formatter(&yf)
        .x_label_formatter(&|v| tick(*v))
        .label_style((FONT, 11))
        .axis_desc_style((FONT, 12));
    if !p.x_desc.is_empty() {
        mesh.x_desc(p.x_desc.as_str());
    }
    if !p.y_desc.is_empty() {
        mesh.y_desc(p.y_desc.as_str());
    }
    mesh.draw()?;
    for &t in &p.vlines {
        if t > x0 && t < x1 {
            chart.draw_series(DashedLineSeries::new(
                vec![(t, y0), (t, y1)],
                5,
                4,
                RGBColor(150, 150, 150).stroke_width(1),
            ))?;
        }
    }
    for (v, c, label) in &p.hlines {
        if *v > y0 && *v < y1 {
            let style = c.stroke_width(2);
            chart
                .draw_series(DashedLineSeries::new(
                    vec![(x0, *v), (x1, *v)],
                    10,
                    6,
                    style,
                ))?
                .label(label.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], style));
        }
    }
    for s in &p.series {
        let style = s.color.stroke_width(if s.dashed { 2 } else { 1 });
        // split at non-finite points, clamp into the panel
        let mut segs: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
        for &(t, v) in &s.pts {
            if t.is_finite() && v.is_finite() {
                segs.last_mut().expect("one").push((t, v.clamp(y0, y1)));
            } else if !segs.last().expect("one").is_empty() {
                segs.push(Vec::new());
            }
        }
        let mut labelled = false;
        for seg in segs.into_iter().filter(|v| !v.is_empty()) {
            let anno = if s.dashed {
                chart.draw_series(DashedLineSeries::new(seg, 7, 5, style))?
            } else {
                chart.draw_series(LineSeries::new(seg, style))?
            };
            if !labelled && !s.label.is_empty() {
                labelled = true;
                anno.label(s.label.as_str())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], style));
            }
        }
    }
    if p.legend {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .label_font((FONT, 11))
            .draw()?;
    }
    Ok(())
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

fn figure<'a>(path: &'a Path, size: (u32, u32), title: &str) -> Result<(Area<'a>, Area<'a>)> {
    ensure_fonts();
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE)?;
    let body = root.titled(title, (FONT, 20).into_font().style(FontStyle::Bold))?;
    Ok((root, body))
}

/// A quantity plotted against truth: name and value from (record, estimate?) .
type Quantity = (String, Box<dyn Fn(&RawRecord, bool) -> f64>);

fn theta_quantity(j: usize) -> Quantity {
    let name = if j < 8 {
        format!("θ1{} = {}", j + 1, THETA_MEANING[j])
    } else {
        format!("θ2{} = {}", j - 7, THETA_MEANING[j])
    };
    (
        name,
        Box::new(move |r: &RawRecord, est: bool| match (j < 8, est) {
            (true, true) => r.theta_drive_est[j],
            (true, false) => r.theta_drive_true[j],
            (false, true) => r.theta_sense_est[j - 8],
            (false, false) => r.theta_sense_true[j - 8],
        }),
    )
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

/// The physical quantities of the paper's Figs 12–14 (corrected Table 3), γ as the rate.
fn physical_quantity(k: usize) -> Quantity {
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
    (
        name.to_string(),
        Box::new(move |r: &RawRecord, est: bool| {
            let (pe, pt) = physical_of(r);
            f(if est { &pe } else { &pt })
        }),
    )
}

/// Legend label of a ±50 % run: the λ reading, and the step if it is not the plant's.
fn run_label(r: &SwitchResult) -> String {
    if r.steps_per_period == 128 {
        r.lambda.label()
    } else {
        format!("{}, {} steps/period", r.lambda.label(), r.steps_per_period)
    }
}

/// Estimate-vs-truth panel of quantity `q` for the runs `runs` (one per λ reading), time in
/// ms (`ms = true`) or s.
fn est_truth_panel(q: &Quantity, runs: &[&SwitchResult], ms: bool, last_row: bool) -> PanelSpec {
    let scale = if ms { 1e3 } else { 1.0 };
    let recs = &runs[0].run.records;
    let truth: Vec<(f64, f64)> = recs
        .iter()
        .map(|r| (r.t_s * scale, (q.1)(r, false)))
        .collect();
    let tv: Vec<f64> = truth.iter().map(|p| p.1).collect();
    let mut y = truth_range(&tv);
    if y.0 == y.1 || tv.iter().all(|v| *v == 0.0) {
        y = (-2e-4, 2e-4);
    }
    let t_end = recs.last().map_or(1.0, |r| r.t_s) * scale;
    let mut series = vec![Series {
        pts: truth,
        color: TRUE_COLOR,
        dashed: false,
        label: "true".into(),
    }];
    for (i, r) in runs.iter().enumerate() {
        series.push(Series {
            pts: r
                .run
                .records
                .iter()
                .map(|x| (x.t_s * scale, (q.1)(x, true)))
                .collect(),
            color: LAMBDA_COLORS[i % 4],
            dashed: true,
            label: format!("estimate, {}", run_label(r)),
        });
    }
    let blown: Vec<String> = runs
        .iter()
        .filter_map(|r| {
            r.run
                .estimator_blowup_s
                .map(|t| format!("{} overflows at {:.1} ms", run_label(r), t * 1e3))
        })
        .collect();
    PanelSpec {
        caption: format!(
            "{}, {} per set{}",
            q.0,
            if ms { "50 ms" } else { "0.5 s" },
            if blown.is_empty() {
                String::new()
            } else {
                format!(" ({})", blown.join("; "))
            }
        ),
        x: (0.0, t_end),
        y,
        x_desc: if last_row {
            (if ms { "time (ms)" } else { "time (s)" }).into()
        } else {
            String::new()
        },
        y_desc: String::new(),
        log_y: false,
        series,
        vlines: runs[0]
            .run
            .segment_starts_s
            .iter()
            .skip(1)
            .map(|t| t * scale)
            .collect(),
        hlines: Vec::new(),
        legend: false,
    }
}

/// Panels of `quantities` in two columns: the ms-scale runs (left) and the 0.5 s runs.
fn plot_est_truth(
    path: &Path,
    title: &str,
    quantities: &[Quantity],
    ms_runs: &[&SwitchResult],
    long_runs: &[&SwitchResult],
) -> Result<()> {
    let rows = quantities.len();
    let (root, body) = figure(path, (1500, 260 * rows as u32 + 60), title)?;
    let areas = body.split_evenly((rows, 2));
    for (i, q) in quantities.iter().enumerate() {
        let last = i + 1 == rows;
        draw_panel(&areas[2 * i], &est_truth_panel(q, ms_runs, true, last))?;
        let mut right = est_truth_panel(q, long_runs, false, last);
        right.legend = i == 0;
        draw_panel(&areas[2 * i + 1], &right)?;
    }
    root.present()?;
    Ok(())
}

/// The literal run: drive/sense amplitude and the θ̂ errors for each λ reading.
fn plot_literal(path: &Path, runs: &[&SwitchResult]) -> Result<()> {
    let (root, body) = figure(
        path,
        (1500, 1300),
        "paper-raw literal: eq. 25 → 26 (+50 %) → 27 (−50 %), pump left at ω = √1.0265, no noise",
    )?;
    let areas = body.split_evenly((1 + runs.len(), 1));
    let r0 = &runs[0];
    let t_end = r0.run.records.last().map_or(1.0, |r| r.t_s);
    let vlines: Vec<f64> = r0.run.segment_starts_s.iter().skip(1).copied().collect();
    let log = |v: f64| if v > 0.0 { v.log10() } else { f64::NAN };
    let amp = PanelSpec {
        caption: format!(
            "drive and sense amplitude (max−min)/2 per ms; drive below 1 % of nominal {} after the +50 % switch",
            r0.drive_below_1pct_after_s
                .map_or("never".into(), |t| format!("{:.0} ms", t * 1e3))
        ),
        x: (0.0, t_end),
        y: (-8.0, 1.0),
        x_desc: String::new(),
        y_desc: "amplitude (L0 = 1 µm)".into(),
        log_y: true,
        series: vec![
            Series {
                pts: r0
                    .run
                    .records
                    .iter()
                    .map(|r| (r.t_s, log(r.drive_amp)))
                    .collect(),
                color: LAMBDA_COLORS[0],
                dashed: false,
                label: "drive |X|".into(),
            },
            Series {
                pts: r0
                    .run
                    .records
                    .iter()
                    .map(|r| (r.t_s, log(r.sense_amp)))
                    .collect(),
                color: LAMBDA_COLORS[2],
                dashed: false,
                label: "sense |Y|".into(),
            },
        ],
        vlines: vlines.clone(),
        hlines: vec![(
            log(0.01 * r0.drive_amp_nominal),
            RGBColor(200, 0, 0),
            "1 % of the nominal drive".into(),
        )],
        legend: true,
    };
    draw_panel(&areas[0], &amp)?;
    for (k, r) in runs.iter().enumerate() {
        let series = (0..14)
            .map(|j| Series {
                pts: r
                    .run
                    .records
                    .iter()
                    .map(|x| (x.t_s, log(theta_rel_errors(x)[j].max(1e-14))))
                    .collect(),
                color: TAB14[j],
                dashed: false,
                label: if j < 8 {
                    format!("θ1{}", j + 1)
                } else {
                    format!("θ2{}", j - 7)
                },
            })
            .collect();
        let blow = r.run.estimator_blowup_s.map_or(String::new(), |t| {
            format!("; estimator overflowed at {t:.4} s")
        });
        let p = PanelSpec {
            caption: format!("relative error of θ̂, {}{blow}", run_label(r)),
            x: (0.0, t_end),
            y: (-12.0, 4.0),
            x_desc: if k + 1 == runs.len() {
                "time (s)".into()
            } else {
                String::new()
            },
            y_desc: "|θ̂ − θ| / |θ|".into(),
            log_y: true,
            series,
            vlines: vlines.clone(),
            hlines: vec![
                (-2.0, RGBColor(230, 140, 0), "1 %".into()),
                (-1.0, RGBColor(200, 0, 0), "10 %".into()),
            ],
            legend: k == 0,
        };
        draw_panel(&areas[1 + k], &p)?;
    }
    root.present()?;
    Ok(())
}

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

/// The Markdown tables of the report.
fn tables_md(cmp: &Comparison, long: &[&SwitchResult], short: &[&SwitchResult]) -> String {
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

/// Runs every scenario of this module, writes `paper_raw_theta1a.png`,
/// `paper_raw_theta1b.png`, `paper_raw_theta2.png` (Figs 9–11 style), `paper_raw_physical.png`
/// (Figs 12–14), `paper_raw_literal.png` and `paper_raw_summary.json` into `dir` (created if
/// needed), and returns the JSON (all numbers, plus `"table_md"`: the Markdown tables).
///
/// About 20 s wall on 2 cores (≈ 30 simulated seconds of the raw estimator at 1.4–1.7 M
/// RK4 steps per simulated second, plus two 10 s product runs).
pub fn write_paper_raw_report(dir: &Path) -> Result<Value> {
    let wall = Instant::now();
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the output directory {}", dir.display()))?;
    let w0 = OMEGA0_TABLE2_RAD_S;

    // ±50 % runs: both pumps × λ readings × (0.5 s, 50 ms per set)
    let mut jobs = Vec::new();
    for pump in [Pump::Literal, Pump::Recentred] {
        // the longest first (load balance)
        jobs.push(SwitchOptions {
            steps_per_period: FINE_STEPS_PER_PERIOD,
            ..SwitchOptions::new(pump, LambdaReading::PaperPerTau)
        });
    }
    for pump in [Pump::Literal, Pump::Recentred] {
        for l in LAMBDAS {
            jobs.push(SwitchOptions::new(pump, l));
            jobs.push(SwitchOptions::ms_scale(pump, l));
        }
    }
    let switch: Vec<SwitchResult> = par_map(jobs, threads(), |o| paper_switch(&o))
        .into_iter()
        .collect::<Result<_, String>>()
        .map_err(|e| anyhow::anyhow!("±50 % runs: {e}"))?;
    let pick = |pump: Pump, long: bool| -> Vec<&SwitchResult> {
        let mut v: Vec<&SwitchResult> = switch
            .iter()
            .filter(|r| r.pump == pump && (r.segment_s > 0.1) == long)
            .collect();
        // the plant's step first, the fine step last
        v.sort_by_key(|r| r.steps_per_period);
        v
    };
    let (lit_long, lit_ms) = (pick(Pump::Literal, true), pick(Pump::Literal, false));
    let (var_long, var_ms) = (pick(Pump::Recentred, true), pick(Pump::Recentred, false));

    // side by side with the product
    let cmp = compare(COMPARE_RAW_S)?;

    // identifiability and the P0 = 1e4·I start on a running gyro
    let (ss1, ss2) = window_identifiability((0.3, 0.5))?;
    let (su1, su2) = window_identifiability((0.0, 0.03))?;
    let late = {
        let cfg = RawConfig {
            estimator_start_s: 0.3,
            ..RawConfig::default()
        };
        let seg = Segment {
            duration_s: 0.32,
            theta: paper_sets(&TABLE2)[0],
            omega: 1.0265f64.sqrt(),
        };
        simulate(&cfg, &[seg]).map_err(|e| anyhow::anyhow!(e))?
    };

    // plots
    let mut files = Vec::new();
    let fig = |name: &str| dir.join(name);
    let qs = |r: std::ops::Range<usize>| r.map(theta_quantity).collect::<Vec<_>>();
    let title = |what: &str| {
        format!(
            "paper-raw variant (pump re-centred to √(−θ22)), no noise: {what}; solid = true, dashed = estimates"
        )
    };
    for (name, what, range) in [
        ("paper_raw_theta1a.png", "θ11…θ14 (Fig. 9)", 0..4),
        ("paper_raw_theta1b.png", "θ15…θ18 (Fig. 10)", 4..8),
        ("paper_raw_theta2.png", "θ21…θ26 (Fig. 11)", 8..14),
    ] {
        let p = fig(name);
        plot_est_truth(&p, &title(what), &qs(range), &var_ms, &var_long)
            .with_context(|| format!("cannot draw {}", p.display()))?;
        files.push(p);
    }
    let p = fig("paper_raw_physical.png");
    let phys: Vec<Quantity> = (0..6).map(physical_quantity).collect();
    plot_est_truth(
        &p,
        &title("physical parameters by the corrected Table 3 (Figs 12–14)"),
        &phys,
        &var_ms,
        &var_long,
    )
    .with_context(|| format!("cannot draw {}", p.display()))?;
    files.push(p);
    let p = fig("paper_raw_literal.png");
    let lit_plot: Vec<&SwitchResult> = lit_long
        .iter()
        .filter(|r| r.lambda != LambdaReading::PerSecond)
        .copied()
        .collect();
    plot_literal(&p, &lit_plot).with_context(|| format!("cannot draw {}", p.display()))?;
    files.push(p);

    // numbers
    let sw = |v: &[&SwitchResult]| -> Vec<Value> {
        v.iter()
            .map(|r| {
                let mut o = json!(r);
                o["run"] = run_summary(&r.run);
                o["lambda_label"] = json!(r.lambda.label());
                o
            })
            .collect()
    };
    let lambdas: Vec<Value> = LAMBDAS
        .iter()
        .map(|l| {
            json!({
                "key": l.key(), "label": l.label(), "per_tau": l.per_tau(w0),
                "per_s": l.per_tau(w0) * w0, "memory_s": l.memory_s(w0),
                "memory_tau": 1.0 / l.per_tau(w0),
                "discrete_per_500hz_sample": (-l.per_tau(w0) * w0 / 500.0).exp(),
            })
        })
        .collect();
    let table_md = tables_md(
        &cmp,
        &[lit_long.clone(), var_long.clone()].concat(),
        &[lit_ms.clone(), var_ms.clone()].concat(),
    );
    let late_first = late
        .records
        .iter()
        .find(|r| r.t_s > 0.3 + 1e-9)
        .map(|r| r.h_phi_p_phi_max);
    let out = json!({
        "omega0_rad_s": w0,
        "steps_per_period": RawConfig::default().steps_per_period,
        "p0": PAPER_P0,
        "lambda_readings": lambdas,
        "literal": sw(&lit_long),
        "variant": sw(&var_long),
        "literal_ms_scale": sw(&lit_ms),
        "variant_ms_scale": sw(&var_ms),
        "comparison": cmp.rows,
        "product_summaries": cmp.product_runs.iter().map(|r| r.summary.clone()).collect::<Vec<_>>(),
        "identifiability": {
            "steady_state_0.3_0.5s": {"drive": ss1, "sense": ss2},
            "startup_0_0.03s": {"drive": su1, "sense": su2},
        },
        "estimator_started_on_running_gyro": {
            "start_s": 0.3,
            "lambda_per_tau": late.lambda_per_tau,
            "first_ms_max_h_phi_p_phi": late_first,
            "rk4_limit_exceeded_s": late.rk4_limit_exceeded_s,
            "estimator_blowup_s": late.estimator_blowup_s,
        },
        "files": files.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
        "wall_s": wall.elapsed().as_secs_f64(),
        "table_md": table_md,
    });
    let path = dir.join("paper_raw_summary.json");
    std::fs::write(&path, serde_json::to_string_pretty(&out)? + "\n")
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(out)
}
