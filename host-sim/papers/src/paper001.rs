//! Seed 001 (Giap, "The geometrical non-linearity influence of the suspension of
//! micromechanical gyroscope under the conditions of angular vibration"): its RR-type gyro
//! near the main parametric resonance — eq. (19), the Krylov–Bogolyubov slow flow eq. (22),
//! the stationary regimes eq. (23), their Lyapunov stability and the amplitude–frequency
//! characteristics A(λ), B(λ) of Figs 3–4.
//!
//! # Model
//!
//! Eq. (19), non-dimensional time τ = ωt, small parameter ε, base rate
//! `v = v0 + v1 sin 2μτ`, forcing `m0 sin μτ` at μ = ω0/ω with `μ − 1 = ελ` (eq. 20):
//!
//! ```text
//! x'' + x = ε(−γx' + v y' + (1−ξ) v' y + j y(σ·x y + 2x'y') − m0 sin μτ)
//! y'' + y = ε(−γy' − v x' − ξ v' x − j y x'²),        v' = 2μ v1 cos 2μτ
//! ```
//!
//! Slow variables (eq. 21): `x = q1 cos μτ + p1 sin μτ`, `y = q2 cos μτ + p2 sin μτ`,
//! `A = √(q1² + p1²)`, `B = √(q2² + p2²)`. The averaged system is eq. (22),
//! `d(q1, p1, q2, p2)/dτ = (ε/8)·G(q, p)`, implemented as printed in [`eq22`]; its
//! stationary points with γ = v0 = 0 are the regimes of eq. (23).
//!
//! # What the paper leaves open, and what is chosen here (also in the JSON)
//!
//! * **j = 1, m0 = 0.05, γ = 0, v0 = 0** for Figs 3–4 (the paper states only v1 = 0 and
//!   v1 = 0.1, and γ = v0 = 0 for eq. 23). j > 0 (hardening) sets the scale: amplitudes ~
//!   √(8λ/j). m0 is in eq. (22)'s units (`−4m0` in the q1 equation); eq. (23) prints `−m0`
//!   where eq. (22)·8/ε with γ = v0 = 0 gives `−4m0` — an inconsistency of the paper, which
//!   only rescales m0.
//! * **ξ = 3/2.** Averaging eq. (19) gives the v1 coupling coefficient `2 − 4ξ` in every
//!   line of (22) (e.g. `q1' ∋ (2−4ξ)v1 p2`); eq. (22) prints −4, i.e. ξ = 3/2. With that
//!   value (22) is exactly the first-order average of (19).
//! * **σ = −1 (sign of the `xy` term).** Eq. (19) prints `j y(xy + 2x'y')`, but the
//!   Lagrange equations (9) give `(J_z − J_x)(α''β² + 2βα'β')` with α'' ≈ −α, i.e.
//!   `j y(−xy + 2x'y')`, and only that sign averages to the j-terms of (22) (and makes the
//!   averaged system Hamiltonian, as it must be for γ = 0). [`Params::xy_sign`] = −1 is the
//!   corrected sign; +1 reproduces the printed one (the RK4 check shows it does not match 22).
//! * **Forcing sign / phase origin.** Averaging (19) with (21) literally gives `+4m0` in the
//!   q1 equation; (22) prints `−4m0`. Both describe the same motion with the time origin
//!   shifted by half a forcing period, i.e. (22)'s slow variables belong to
//!   `x = −(q1 cos μτ + p1 sin μτ)`, `y = −(q2 cos μτ + p2 sin μτ)` (v, v' are unchanged by
//!   that shift). [`state_from_slow`] / [`slow_from_state`] use this; A and B are unaffected.
//! * ε = 0.005 is needed only for the direct integration of (19).
//! * Stability is Lyapunov stability of the linearisation of (22): with γ = 0 the averaged
//!   system is Hamiltonian, so "stable" means all eigenvalues on the imaginary axis (to
//!   1e-6 of their size); with γ > 0 it means all real parts negative.
//!
//! [`write_paper001_report`] writes `paper001_fig3.png`, `paper001_fig4.png` and
//! `paper001.json`.

use std::f64::consts::TAU;
use std::fs;
use std::path::Path;

use anyhow::{Context, Result};
use serde_json::{Value, json};

use crate::averaged::{
    BranchPoint, C64, ContinuationSettings, eig4, find_branches, newton4, split_by,
};

/// Parameters of eq. (19)/(22).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// Geometric-nonlinearity coefficient j (eq. 13).
    pub j: f64,
    /// Damping γ (γ1 = γ2).
    pub gamma: f64,
    /// Constant base rate v0.
    pub v0: f64,
    /// Amplitude of the angular-vibration rate v1 (`v = v0 + v1 sin 2μτ`).
    pub v1: f64,
    /// Forcing amplitude m0 (eq. 22 units).
    pub m0: f64,
    /// ξ = 1/j2 (eq. 13); 3/2 makes (22) the average of (19).
    pub xi: f64,
    /// ε (only for the direct integration of eq. 19).
    pub eps: f64,
    /// Sign σ of the `xy` term in eq. (19): −1 corrected (consistent with eqs. 9 and 22),
    /// +1 as printed.
    pub xy_sign: f64,
}

impl Params {
    /// Fig. 3: v1 = 0 (with j = 1, m0 = 0.05, γ = v0 = 0, ξ = 3/2, ε = 0.005).
    pub fn fig3() -> Self {
        Self {
            j: 1.0,
            gamma: 0.0,
            v0: 0.0,
            v1: 0.0,
            m0: 0.05,
            xi: 1.5,
            eps: 0.005,
            xy_sign: -1.0,
        }
    }

    /// Fig. 4: v1 = 0.1, otherwise as [`Params::fig3`].
    pub fn fig4() -> Self {
        Self {
            v1: 0.1,
            ..Self::fig3()
        }
    }

    /// JSON record of the parameters.
    pub fn to_json(&self) -> Value {
        json!({"j": self.j, "gamma": self.gamma, "v0": self.v0, "v1": self.v1, "m0": self.m0,
               "xi": self.xi, "eps": self.eps, "xy_sign": self.xy_sign})
    }

    /// The v1 coefficient of eq. (22): `2 − 4ξ` (−4 at ξ = 3/2, as printed).
    fn kv(&self) -> f64 {
        2.0 - 4.0 * self.xi
    }
}

/// The bracket `G` of eq. (22) (`d[q1, p1, q2, p2]/dτ = (ε/8)·G`), as printed for ξ = 3/2.
pub fn eq22(p: &Params, lambda: f64, s: &[f64; 4]) -> [f64; 4] {
    let [q1, p1, q2, p2] = *s;
    let (g, l, j, v0, kv1) = (p.gamma, lambda, p.j, p.v0, p.kv() * p.v1);
    let w = p2 * q1 - p1 * q2;
    let aa = q1 * q1 + p1 * p1;
    let bb = q2 * q2 + p2 * p2;
    [
        -4.0 * g * q1 - 8.0 * l * p1 + 4.0 * v0 * q2 + kv1 * p2 + j * p1 * bb
            - 2.0 * j * q2 * w
            - 4.0 * p.m0,
        -4.0 * g * p1 + 8.0 * l * q1 + 4.0 * v0 * p2 + kv1 * q2 - j * q1 * bb - 2.0 * j * p2 * w,
        -4.0 * g * q2 - 8.0 * l * p2 - 4.0 * v0 * q1 + kv1 * p1 + j * p2 * aa + 2.0 * j * q1 * w,
        -4.0 * g * p2 + 8.0 * l * q2 - 4.0 * v0 * p1 + kv1 * q1 - j * q2 * aa + 2.0 * j * p1 * w,
    ]
}

/// Analytic Jacobian of [`eq22`] with respect to `[q1, p1, q2, p2]`.
pub fn eq22_jacobian(p: &Params, lambda: f64, s: &[f64; 4]) -> [[f64; 4]; 4] {
    let [q1, p1, q2, p2] = *s;
    let (g, l, j, v0, kv1) = (p.gamma, lambda, p.j, p.v0, p.kv() * p.v1);
    let w = p2 * q1 - p1 * q2;
    let aa = q1 * q1 + p1 * p1;
    let bb = q2 * q2 + p2 * p2;
    [
        [
            -4.0 * g - 2.0 * j * q2 * p2,
            -8.0 * l + j * bb + 2.0 * j * q2 * q2,
            4.0 * v0 + 4.0 * j * p1 * q2 - 2.0 * j * w,
            kv1 + 2.0 * j * p1 * p2 - 2.0 * j * q1 * q2,
        ],
        [
            8.0 * l - j * bb - 2.0 * j * p2 * p2,
            -4.0 * g + 2.0 * j * p2 * q2,
            kv1 - 2.0 * j * q1 * q2 + 2.0 * j * p1 * p2,
            4.0 * v0 - 4.0 * j * q1 * p2 - 2.0 * j * w,
        ],
        [
            -4.0 * v0 + 4.0 * j * q1 * p2 + 2.0 * j * w,
            kv1 + 2.0 * j * p1 * p2 - 2.0 * j * q1 * q2,
            -4.0 * g - 2.0 * j * q1 * p1,
            -8.0 * l + j * aa + 2.0 * j * q1 * q1,
        ],
        [
            kv1 - 2.0 * j * q1 * q2 + 2.0 * j * p1 * p2,
            -4.0 * v0 - 4.0 * j * p1 * q2 + 2.0 * j * w,
            8.0 * l - j * aa - 2.0 * j * p1 * p1,
            -4.0 * g + 2.0 * j * p1 * q1,
        ],
    ]
}

/// Newton residual tolerance on `‖G‖∞`.
const RES_TOL: f64 = 1e-11;
/// Relative tolerance on the real parts for "on the imaginary axis" (γ = 0).
const STAB_TOL: f64 = 1e-6;

/// A stationary regime of eq. (22) at one detuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stationary {
    /// Detuning λ.
    pub lambda: f64,
    /// `[q1, p1, q2, p2]`.
    pub s: [f64; 4],
    /// Drive amplitude A = √(q1² + p1²).
    pub a: f64,
    /// Sense amplitude B = √(q2² + p2²).
    pub b: f64,
    /// Eigenvalues of the Jacobian of G (slow time T = ετ/8), decreasing real part.
    pub eigenvalues: [C64; 4],
    /// Largest real part.
    pub max_re: f64,
    /// Lyapunov stability of the linearisation.
    pub stable: bool,
}

impl Stationary {
    /// JSON record.
    pub fn to_json(&self) -> Value {
        json!({"lambda": self.lambda, "q1_p1_q2_p2": self.s, "A": self.a, "B": self.b,
               "eigenvalues": self.eigenvalues.iter().map(|z| [z.re, z.im]).collect::<Vec<_>>(),
               "max_re_eig": self.max_re, "stable": self.stable})
    }
}

/// Stability from the eigenvalues: all real parts `< tol·max(1, max|eig|)` with
/// `tol = 1e-6` (marginal, Hamiltonian case γ = 0) or `< 0` when γ > 0.
fn stability(p: &Params, eig: &[C64; 4]) -> bool {
    if p.gamma > 0.0 {
        eig[0].re < 0.0
    } else {
        let scale = eig.iter().fold(1.0f64, |m, z| m.max(z.abs()));
        eig[0].re <= STAB_TOL * scale
    }
}

/// The point `s` classified (eigenvalues of the analytic Jacobian).
pub fn classify(p: &Params, lambda: f64, s: [f64; 4]) -> Stationary {
    let eigenvalues = eig4(&eq22_jacobian(p, lambda, &s));
    Stationary {
        lambda,
        s,
        a: s[0].hypot(s[1]),
        b: s[2].hypot(s[3]),
        eigenvalues,
        max_re: eigenvalues[0].re,
        stable: stability(p, &eigenvalues),
    }
}

/// Newton (analytic Jacobian) from `guess` to a root of eq. (22) at λ (`‖G‖∞ ≤ 1e-11`).
pub fn newton(p: &Params, lambda: f64, guess: [f64; 4]) -> Option<[f64; 4]> {
    newton4(
        &|s| eq22(p, lambda, s),
        &|s| eq22_jacobian(p, lambda, s),
        guess,
        RES_TOL,
        50.0,
    )
}

/// The multi-start grid: A, B ∈ {0.05, 0.3, 0.8, 1.5, 2.5, 3.6} × 6 phases each
/// (offset 0.1 rad) — 1296 guesses.
pub fn default_guesses() -> Vec<[f64; 4]> {
    let amps = [0.05, 0.3, 0.8, 1.5, 2.5, 3.6];
    let mut g = Vec::with_capacity(1296);
    for a in amps {
        for b in amps {
            for k in 0..6 {
                let pa = 0.1 + TAU * k as f64 / 6.0;
                for l in 0..6 {
                    let pb = 0.1 + TAU * l as f64 / 6.0;
                    g.push([a * pa.cos(), a * pa.sin(), b * pb.cos(), b * pb.sin()]);
                }
            }
        }
    }
    g
}

/// All distinct nontrivial (`‖s‖∞ > 1e-9`) stationary regimes at λ from
/// [`default_guesses`] plus `extra` guesses, sorted by (A, B).
pub fn stationary_points_with(p: &Params, lambda: f64, extra: &[[f64; 4]]) -> Vec<Stationary> {
    let mut found: Vec<[f64; 4]> = Vec::new();
    for g in extra.iter().copied().chain(default_guesses()) {
        let Some(s) = newton(p, lambda, g) else {
            continue;
        };
        if s.iter().all(|x| x.abs() < 1e-9) {
            continue;
        }
        if found
            .iter()
            .any(|w| (0..4).all(|i| (w[i] - s[i]).abs() < 1e-7))
        {
            continue;
        }
        found.push(s);
    }
    let mut out: Vec<Stationary> = found.into_iter().map(|s| classify(p, lambda, s)).collect();
    out.sort_by(|x, y| x.a.total_cmp(&y.a).then(x.b.total_cmp(&y.b)));
    out
}

/// As [`stationary_points_with`] without extra guesses.
pub fn stationary_points(p: &Params, lambda: f64) -> Vec<Stationary> {
    stationary_points_with(p, lambda, &[])
}

/// Distinct amplitude pairs (A, B) (to 1e-6) among `pts`: the points of the
/// amplitude–frequency characteristic at one λ (symmetric copies coincide there).
pub fn distinct_amplitudes(pts: &[Stationary]) -> Vec<(f64, f64, bool)> {
    let mut out: Vec<(f64, f64, bool)> = Vec::new();
    for s in pts {
        if !out
            .iter()
            .any(|o| (o.0 - s.a).abs() < 1e-6 && (o.1 - s.b).abs() < 1e-6)
        {
            out.push((s.a, s.b, s.stable));
        }
    }
    out
}

/// Detuning window of Figs 3–4.
pub const LAMBDA_LO: f64 = -0.5;
/// Upper end of the detuning window.
pub const LAMBDA_HI: f64 = 1.5;
/// Branches are followed up to this amplitude.
pub const AMP_MAX: f64 = 4.2;

/// All branches of stationary regimes for λ in `[lo, hi]`: multi-start seeds at 24
/// detunings, each new branch traced by pseudo-arclength continuation (step ≤ 0.01)
/// until it leaves the window or A or B exceeds [`AMP_MAX`].
pub fn branches(p: &Params, lo: f64, hi: f64) -> Vec<Vec<BranchPoint>> {
    let mut lams: Vec<f64> = (0..=20)
        .map(|i| lo + (hi - lo) * (i as f64 + 0.37) / 21.0)
        .collect();
    lams.extend([-0.02, 0.02, 0.06]);
    let mut seeds = Vec::new();
    for &l in &lams {
        for st in stationary_points(p, l) {
            if st.a.max(st.b) < AMP_MAX {
                seeds.push((st.s, l));
            }
        }
    }
    let cs = ContinuationSettings {
        p_min: lo,
        p_max: hi,
        p_scale: 1.0,
        h_init: 0.002,
        h_min: 1e-7,
        h_max: 0.01,
        max_points: 20_000,
        amp_max: AMP_MAX,
        trivial_tol: if p.m0 == 0.0 { 1e-3 } else { -1.0 },
        res_tol: 1e-10,
    };
    let flow = |s: &[f64; 4], l: f64| eq22(p, l, s);
    let stab = |s: &[f64; 4], l: f64| {
        let st = classify(p, l, *s);
        (st.max_re, st.stable)
    };
    let sig = |s: &[f64; 4]| [s[0].hypot(s[1]), s[2].hypot(s[3])];
    find_branches(&flow, &stab, &sig, &seeds, &cs)
}

// =======================================================================================
// Direct integration of eq. (19)
// =======================================================================================

/// RK4 steps per period 2π/μ of the direct integration.
pub const STEPS_PER_PERIOD: usize = 64;

/// Right-hand side `d/dτ [x, x', y, y']` of eq. (19) at detuning λ (μ = 1 + ελ).
pub fn eq19_rhs(p: &Params, lambda: f64, tau: f64, z: &[f64; 4]) -> [f64; 4] {
    let mu = 1.0 + p.eps * lambda;
    let (s1, c1) = (mu * tau).sin_cos();
    let (s2, c2) = (2.0 * s1 * c1, c1 * c1 - s1 * s1);
    let [x, xd, y, yd] = *z;
    let v = p.v0 + p.v1 * s2;
    let vd = 2.0 * mu * p.v1 * c2;
    let fx = -p.gamma * xd
        + v * yd
        + (1.0 - p.xi) * vd * y
        + p.j * y * (p.xy_sign * x * y + 2.0 * xd * yd)
        - p.m0 * s1;
    let fy = -p.gamma * yd - v * xd - p.xi * vd * x - p.j * y * xd * xd;
    [xd, -x + p.eps * fx, yd, -y + p.eps * fy]
}

/// The state `[x, x', y, y']` at τ for the slow variables `s` of eq. (22) (phase origin of
/// (22): `x = −(q1 cos μτ + p1 sin μτ)`, see the module docs).
pub fn state_from_slow(p: &Params, lambda: f64, tau: f64, s: &[f64; 4]) -> [f64; 4] {
    let mu = 1.0 + p.eps * lambda;
    let (sn, cs) = (mu * tau).sin_cos();
    let [q1, p1, q2, p2] = *s;
    [
        -(q1 * cs + p1 * sn),
        -mu * (-q1 * sn + p1 * cs),
        -(q2 * cs + p2 * sn),
        -mu * (-q2 * sn + p2 * cs),
    ]
}

/// The slow variables of eq. (22) for the state `z` at τ (inverse of [`state_from_slow`]).
pub fn slow_from_state(p: &Params, lambda: f64, tau: f64, z: &[f64; 4]) -> [f64; 4] {
    let mu = 1.0 + p.eps * lambda;
    let (sn, cs) = (mu * tau).sin_cos();
    let [x, xd, y, yd] = *z;
    [
        -(x * cs - xd / mu * sn),
        -(x * sn + xd / mu * cs),
        -(y * cs - yd / mu * sn),
        -(y * sn + yd / mu * cs),
    ]
}

/// Summary of a direct integration of eq. (19).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rk4Run {
    /// Length of the run, τ.
    pub t_end: f64,
    /// Mean A over the averaging window.
    pub mean_a: f64,
    /// Mean B over the averaging window.
    pub mean_b: f64,
    /// Largest relative distance `‖s(τ) − s*‖/‖s*‖` over the whole run.
    pub max_dev: f64,
    /// Mean relative distance over the averaging window.
    pub window_dev: f64,
    /// Slow variables at the end.
    pub final_s: [f64; 4],
}

impl Rk4Run {
    /// JSON record.
    pub fn to_json(&self) -> Value {
        json!({"t_end_tau": self.t_end, "mean_A": self.mean_a, "mean_B": self.mean_b,
               "max_rel_dev": self.max_dev, "window_rel_dev": self.window_dev,
               "final_q1_p1_q2_p2": self.final_s})
    }
}

/// Integrates eq. (19) at λ with classic RK4 ([`STEPS_PER_PERIOD`] steps per period) from
/// the slow state `start` (τ = 0) to `t_end`; the slow variables are extracted at every
/// step and compared with `target`; means over `τ ≥ avg_from`.
pub fn rk4_eq19(
    p: &Params,
    lambda: f64,
    start: &[f64; 4],
    target: &[f64; 4],
    t_end: f64,
    avg_from: f64,
) -> Rk4Run {
    let mu = 1.0 + p.eps * lambda;
    let h = TAU / mu / STEPS_PER_PERIOD as f64;
    let n = (t_end / h).ceil() as usize;
    let norm = |v: &[f64; 4]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let tn = norm(target).max(1e-300);
    let mut z = state_from_slow(p, lambda, 0.0, start);
    let (mut sa, mut sb, mut sd, mut cnt) = (0.0, 0.0, 0.0, 0usize);
    let mut max_dev = 0.0f64;
    let mut s = *start;
    for i in 0..n {
        let t = i as f64 * h;
        let k1 = eq19_rhs(p, lambda, t, &z);
        let k2 = eq19_rhs(
            p,
            lambda,
            t + 0.5 * h,
            &std::array::from_fn(|q| z[q] + 0.5 * h * k1[q]),
        );
        let k3 = eq19_rhs(
            p,
            lambda,
            t + 0.5 * h,
            &std::array::from_fn(|q| z[q] + 0.5 * h * k2[q]),
        );
        let k4 = eq19_rhs(p, lambda, t + h, &std::array::from_fn(|q| z[q] + h * k3[q]));
        for q in 0..4 {
            z[q] += h / 6.0 * (k1[q] + 2.0 * (k2[q] + k3[q]) + k4[q]);
        }
        let te = (i + 1) as f64 * h;
        s = slow_from_state(p, lambda, te, &z);
        let d = norm(&std::array::from_fn(|q| s[q] - target[q])) / tn;
        max_dev = max_dev.max(d);
        if te >= avg_from {
            sa += s[0].hypot(s[1]);
            sb += s[2].hypot(s[3]);
            sd += d;
            cnt += 1;
        }
    }
    let c = cnt.max(1) as f64;
    Rk4Run {
        t_end: n as f64 * h,
        mean_a: sa / c,
        mean_b: sb / c,
        max_dev,
        window_dev: sd / c,
        final_s: s,
    }
}

// =======================================================================================
// Claims of the paper
// =======================================================================================

/// Family of a free (m0 = 0, γ = v0 = 0) stationary regime: `(c, sign)` with
/// `c·j·A² = 8λ + sign·4v1`, `c ∈ {1, 3}`, if A = B and the point lies on that parabola to
/// `tol`; `None` otherwise.
pub fn parabola_family(p: &Params, st: &Stationary, tol: f64) -> Option<(u8, i8)> {
    if (st.a - st.b).abs() > tol * st.a.max(1.0) {
        return None;
    }
    for c in [1u8, 3] {
        for sign in [1i8, -1] {
            let r =
                f64::from(c) * p.j * st.a * st.a - 8.0 * st.lambda - f64::from(sign) * 4.0 * p.v1;
            if r.abs() < tol * (1.0 + 8.0 * st.lambda.abs()) {
                return Some((c, sign));
            }
        }
    }
    None
}

fn check(
    name: &str,
    p: &Params,
    lambda: f64,
    st: &Stationary,
    start: [f64; 4],
    t_end: f64,
    avg_from: f64,
) -> (Value, Rk4Run) {
    let r = rk4_eq19(p, lambda, &start, &st.s, t_end, avg_from);
    let v = json!({
        "name": name,
        "params": p.to_json(),
        "lambda": lambda,
        "stationary": st.to_json(),
        "rk4": r.to_json(),
        "rel_err_A": r.mean_a / st.a - 1.0,
        "rel_err_B": r.mean_b / st.b - 1.0,
    });
    (v, r)
}

/// The stable stationary regime with the largest B (spatial oscillation) at λ.
pub fn stable_spatial(p: &Params, lambda: f64) -> Option<Stationary> {
    stationary_points(p, lambda)
        .into_iter()
        .filter(|s| s.stable && s.b > 0.5)
        .max_by(|x, y| x.b.total_cmp(&y.b))
}

/// The RK4 confirmations: stable regimes stay (γ = 0) or are reached (γ > 0), an unstable
/// one is left, and the printed `xy` sign of eq. (19) does not reproduce (22).
fn rk4_checks() -> Result<(Value, bool)> {
    let mut out = Vec::new();
    let mut all_ok = true;
    // (1) γ = 0: start on a stable regime; the slow variables stay near it
    for (fig, p, lam) in [
        ("fig4", Params::fig4(), 0.5),
        ("fig4", Params::fig4(), 1.0),
        ("fig3", Params::fig3(), 1.0),
    ] {
        let st = stable_spatial(&p, lam).context("no stable spatial regime")?;
        let (mut v, r) = check(
            &format!("{fig} stable, lambda={lam}"),
            &p,
            lam,
            &st,
            st.s,
            30_000.0,
            0.0,
        );
        let ok = (r.mean_a / st.a - 1.0).abs() < 0.03
            && (r.mean_b / st.b - 1.0).abs() < 0.03
            && r.max_dev < 0.1;
        v["pass"] = json!(ok);
        v["criterion"] = json!("|mean A, B / stationary − 1| < 3 %, max deviation < 10 %");
        all_ok &= ok;
        out.push(v);
    }
    // (2) damped (γ = 0.05): start 5 % off a stable regime, converge to it
    let pd = Params {
        gamma: 0.05,
        ..Params::fig4()
    };
    let st = stable_spatial(&pd, 1.0).context("no damped stable regime")?;
    let (mut v, r) = check(
        "fig4 with gamma=0.05, stable, lambda=1.0, start 5 % off",
        &pd,
        1.0,
        &st,
        st.s.map(|x| 1.05 * x),
        120_000.0,
        100_000.0,
    );
    let ok = (r.mean_a / st.a - 1.0).abs() < 0.02
        && (r.mean_b / st.b - 1.0).abs() < 0.02
        && r.window_dev < 0.02;
    v["pass"] = json!(ok);
    v["criterion"] =
        json!("last 20 000 τ: |mean A, B / stationary − 1| < 2 %, mean deviation < 2 %");
    all_ok &= ok;
    out.push(v);
    // (3) unstable regime: left
    let p = Params::fig4();
    let un = stationary_points(&p, 1.0)
        .into_iter()
        .filter(|s| !s.stable && s.b > 0.5)
        .max_by(|x, y| x.max_re.total_cmp(&y.max_re))
        .context("no unstable regime")?;
    let start = [un.s[0] * (1.0 + 1e-3), un.s[1], un.s[2], un.s[3]];
    let (mut v, r) = check(
        "fig4 unstable, lambda=1.0, start 1e-3 off",
        &p,
        1.0,
        &un,
        start,
        30_000.0,
        0.0,
    );
    let ok = r.max_dev > 0.2;
    v["pass"] = json!(ok);
    v["criterion"] = json!("max deviation > 20 %");
    all_ok &= ok;
    out.push(v);
    // (4) the printed sign of the xy term: the stable regime of (22) is not one of (19)
    let pp = Params {
        xy_sign: 1.0,
        ..Params::fig4()
    };
    let st = stable_spatial(&Params::fig4(), 1.0).context("no stable spatial regime")?;
    let (mut v, r) = check(
        "fig4 stable regime integrated with the printed +xy sign of eq. (19)",
        &pp,
        1.0,
        &st,
        st.s,
        30_000.0,
        0.0,
    );
    v["drifts_away"] = json!(r.max_dev > 0.1);
    v["note"] = json!(
        "informative: with the printed sign the regime of (22) is not kept (erratum, see docs)"
    );
    out.push(v);
    Ok((Value::Array(out), all_ok))
}

/// Claim "a family of parabolas": free regimes (m0 = 0) lie exactly on
/// `c·j·A² = 8λ ± 4v1`, A = B (c = 1, 3); for the forced figures, the distance of the
/// spatial regimes from those parabolas.
fn parabola_claim(figs: &[(&str, Params, &[Vec<BranchPoint>])]) -> Value {
    let mut free = Vec::new();
    let mut all_on = true;
    for v1 in [0.0, 0.1] {
        let p = Params {
            m0: 0.0,
            v1,
            ..Params::fig3()
        };
        // v1 = 0 without forcing is rotation-invariant (a circle of regimes, singular
        // Jacobian); use it only through the forced figures
        if v1 == 0.0 {
            continue;
        }
        for lam in [0.2, 0.5, 1.0, 1.5] {
            let pts = stationary_points(&p, lam);
            let fam: Vec<Option<(u8, i8)>> =
                pts.iter().map(|s| parabola_family(&p, s, 1e-8)).collect();
            all_on &= fam.iter().all(Option::is_some);
            free.push(json!({"v1": v1, "lambda": lam, "regimes": pts.len(),
                             "on_parabolas": fam.iter().filter(|f| f.is_some()).count()}));
        }
    }
    let mut forced = Vec::new();
    for (name, p, br) in figs {
        // λ distance of the spatial points (B > 0.5) to the nearest parabola λ = (c j A² ∓ 4 v1)/8
        let mut worst = 0.0f64;
        for b in br.iter() {
            for pt in b {
                let a = pt.v[0].hypot(pt.v[1]);
                let bb = pt.v[2].hypot(pt.v[3]);
                if bb < 0.5 || a < 0.5 {
                    continue;
                }
                let d = [1.0, 3.0]
                    .iter()
                    .flat_map(|&c| {
                        [1.0, -1.0]
                            .map(|sg| (pt.p - (c * p.j * a * a - sg * 4.0 * p.v1) / 8.0).abs())
                    })
                    .fold(f64::INFINITY, f64::min);
                worst = worst.max(d);
            }
        }
        forced.push(
            json!({"figure": name, "max_lambda_distance_of_spatial_points_A_B_gt_0.5": worst}),
        );
    }
    json!({
        "claim": "the amplitude-frequency characteristics A(λ), B(λ) are a family of parabolas",
        "holds": all_on,
        "free_regimes_m0_0": free,
        "forced_figures": forced,
        "statement": "for m0 = 0 every regime has A = B on one of λ = (c·j·A² ∓ 4·v1)/8, c = 1, 3 (to 1e-8); with v1 = 0 and forcing, A² = 8λ/(c·j) holds exactly on the spatial branches (sense equation) and B is close to it; the plane branch A = m0/(2|λ|), B = 0 is a hyperbola",
    })
}

/// Claim "the doubled detuning must exceed v1": which free (m0 = 0) families exist vs λ.
pub fn existence_scan(v1: f64, lambdas: &[f64]) -> Vec<(f64, usize, usize, usize)> {
    let p = Params {
        m0: 0.0,
        v1,
        ..Params::fig3()
    };
    lambdas
        .iter()
        .map(|&lam| {
            let pts = stationary_points(&p, lam);
            let (mut minus, mut plus, mut other) = (0, 0, 0);
            for s in &pts {
                match parabola_family(&p, s, 1e-8) {
                    Some((_, -1)) => minus += 1,
                    Some((_, _)) => plus += 1,
                    None => other += 1,
                }
            }
            (lam, minus, plus, other)
        })
        .collect()
}

fn existence_claim() -> Value {
    let v1 = 0.1;
    let lams: Vec<f64> = (0..=30).map(|i| -0.149 + 0.01 * i as f64).collect();
    let scan = existence_scan(v1, &lams);
    let minus_from = scan.iter().find(|r| r.1 > 0).map(|r| r.0);
    let plus_from = scan.iter().find(|r| r.2 > 0).map(|r| r.0);
    let minus_ok = scan.iter().all(|r| (r.1 > 0) == (2.0 * r.0 > v1));
    let plus_ok = scan.iter().all(|r| (r.2 > 0) == (2.0 * r.0 > -v1));
    json!({
        "claim": "the doubled detuning 2λ must exceed v1",
        "v1": v1,
        "free_regimes_m0_0": scan.iter().map(|r| json!({"lambda": r.0, "minus_family": r.1, "plus_family": r.2, "other": r.3})).collect::<Vec<_>>(),
        "minus_family_first_lambda": minus_from,
        "plus_family_first_lambda": plus_from,
        "minus_family_exists_iff_2lambda_gt_v1": minus_ok,
        "plus_family_exists_iff_2lambda_gt_minus_v1": plus_ok,
        "holds": if minus_ok && plus_ok { "partly" } else { "no" },
        "statement": "for m0 = 0 the families c·j·A² = 8λ − 4v1 (c = 1, 3) exist only for 2λ > v1, as the paper says; the families c·j·A² = 8λ + 4v1 exist already for 2λ > −v1 (the rest state is parametrically unstable for |2λ| < v1); with forcing (the figures) a forced regime exists at every λ",
    })
}

fn v0_claim() -> Value {
    let lams = [0.02, 0.1, 0.3, 0.5, 1.0];
    let mut rows = Vec::new();
    let mut adds = false;
    for (name, base) in [("fig3", Params::fig3()), ("fig4", Params::fig4())] {
        for &lam in &lams {
            let n0 = distinct_amplitudes(&stationary_points(&base, lam)).len();
            let p1 = Params { v0: 0.1, ..base };
            let n1 = distinct_amplitudes(&stationary_points(&p1, lam)).len();
            adds |= n1 > n0;
            rows.push(json!({"figure": name, "lambda": lam, "distinct_AB_v0_0": n0, "distinct_AB_v0_0.1": n1}));
        }
    }
    json!({
        "claim": "v0 ≠ 0 adds a branch to the amplitude-frequency characteristic",
        "v0": 0.1,
        "holds": adds,
        "counts": rows,
        "statement": "with v0 = 0 the regimes come in symmetric pairs with equal (A, B) (e.g. (q2, p2) → −(q2, p2) for v1 = 0); v0 couples x and y linearly, breaks that symmetry and splits such pairs into distinct (A, B) branches",
    })
}

/// Computes seed 001's Figs 3–4 (branches with stability), the RK4 confirmations and the
/// claims; writes `paper001_fig3.png`, `paper001_fig4.png` and `paper001.json` to `dir`;
/// returns the JSON.
pub fn write_paper001_report(dir: &Path) -> Result<Value> {
    fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let p3 = Params::fig3();
    let p4 = Params::fig4();
    let b3 = branches(&p3, LAMBDA_LO, LAMBDA_HI);
    let b4 = branches(&p4, LAMBDA_LO, LAMBDA_HI);
    plot_fig(
        &dir.join("paper001_fig3.png"),
        "Seed 001 Fig. 3: amplitude–frequency characteristics, v1 = 0",
        &p3,
        &b3,
    )?;
    plot_fig(
        &dir.join("paper001_fig4.png"),
        "Seed 001 Fig. 4: amplitude–frequency characteristics, v1 = 0.1",
        &p4,
        &b4,
    )?;
    let (rk4, rk4_ok) = rk4_checks()?;
    let branch_json =
        |br: &[Vec<BranchPoint>]| -> Value {
            br.iter()
            .map(|b| {
                // sampled every 5th point
                let pts: Vec<Value> = b
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| k % 5 == 0 || *k + 1 == b.len())
                    .map(|(_, pt)| {
                        json!([pt.p, pt.v[0].hypot(pt.v[1]), pt.v[2].hypot(pt.v[3]), pt.stable])
                    })
                    .collect();
                json!({"points": b.len(), "stable_points": b.iter().filter(|p| p.stable).count(),
                       "samples_lambda_A_B_stable": pts})
            })
            .collect::<Vec<_>>()
            .into()
        };
    let table = |p: &Params| -> Value {
        [-0.3, 0.1, 0.5, 1.0]
            .iter()
            .map(|&l| {
                json!({"lambda": l, "regimes": stationary_points(p, l).iter().map(Stationary::to_json).collect::<Vec<_>>()})
            })
            .collect::<Vec<_>>()
            .into()
    };
    let out = json!({
        "paper": "seed 001 (Giap): eq. (19), slow flow eq. (22), stationary regimes eq. (23), Figs 3-4",
        "parameters": {
            "fig3": p3.to_json(),
            "fig4": p4.to_json(),
            "stated_by_paper": "v1 = 0 (Fig. 3), v1 = 0.1 (Fig. 4); γ = 0 and v0 = 0 for the stationary regimes (eq. 23)",
            "chosen_here": "j = 1, m0 = 0.05 (eq. 22 units; eq. 23 prints m0 where 4·m0 is consistent), ξ = 3/2 (makes eq. 22 the average of eq. 19), ε = 0.005 (direct integration only), σ = −1 for the xy term of eq. 19 (erratum, from eq. 9)",
            "lambda_window": [LAMBDA_LO, LAMBDA_HI],
            "amplitude_cap": AMP_MAX,
            "stability": "eigenvalues of the Jacobian of (22); γ = 0: stable = all on the imaginary axis (|Re| ≤ 1e-6·|λ|max)",
        },
        "errata": [
            "eq. (19)/(14)/(15): j·y(x·y + 2x'y') should be j·y(−x·y + 2x'y') (eq. 9 with α'' ≈ −α; only this sign averages to eq. 22)",
            "eq. (22) vs (19): the v1 coefficient −4 corresponds to ξ = 3/2 (general: 2 − 4ξ)",
            "eq. (22) vs (19): −4m0 corresponds to the phase origin shifted by half a forcing period (x = −(q1 cos μτ + p1 sin μτ)); literal averaging gives +4m0",
            "eq. (23) prints −m0 where eq. (22) gives −4m0",
        ],
        "fig3": {"branches": branch_json(&b3), "regimes_at": table(&p3)},
        "fig4": {"branches": branch_json(&b4), "regimes_at": table(&p4)},
        "rk4_checks": rk4,
        "rk4_checks_pass": rk4_ok,
        "claims": {
            "family_of_parabolas": parabola_claim(&[("fig3", p3, &b3), ("fig4", p4, &b4)]),
            "doubled_detuning_exceeds_v1": existence_claim(),
            "v0_adds_a_branch": v0_claim(),
        },
        "files": ["paper001_fig3.png", "paper001_fig4.png", "paper001.json"],
    });
    fs::write(
        dir.join("paper001.json"),
        serde_json::to_string_pretty(&out)?,
    )
    .with_context(|| format!("writing {}", dir.join("paper001.json").display()))?;
    Ok(out)
}

fn plot_fig(path: &Path, title: &str, p: &Params, br: &[Vec<BranchPoint>]) -> Result<()> {
    use crate::averaged::plot::*;
    use plotters::prelude::*;
    let (root, body) = figure(path, (1400, 700), title)?;
    let panels = body.split_evenly((1, 2));
    let dark = RGBColor(20, 30, 100);
    let light = RGBColor(160, 185, 235);
    let grey = RGBColor(150, 150, 150);
    for (ip, area) in panels.iter().enumerate() {
        let amp = |v: &[f64; 4]| {
            if ip == 0 {
                v[0].hypot(v[1])
            } else {
                v[2].hypot(v[3])
            }
        };
        let what = if ip == 0 { "A" } else { "B" };
        let mut panel = Panel::new(
            format!(
                "{what}(λ)   (j = {}, m0 = {}, γ = {}, v0 = {}, v1 = {})",
                p.j, p.m0, p.gamma, p.v0, p.v1
            ),
            (LAMBDA_LO, LAMBDA_HI),
            (0.0, 4.0),
        );
        panel.x_desc = "detuning λ = (μ − 1)/ε".into();
        panel.y_desc = what.to_string();
        // backbone parabolas of the free system: c j A² = 8λ ± 4 v1
        let mut first = true;
        for c in [1.0, 3.0] {
            let signs: &[f64] = if p.v1 == 0.0 { &[1.0] } else { &[1.0, -1.0] };
            for &sg in signs {
                let pts: Vec<(f64, f64)> = (0..=200)
                    .map(|k| {
                        let a = 4.0 * k as f64 / 200.0;
                        ((c * p.j * a * a - sg * 4.0 * p.v1) / 8.0, a)
                    })
                    .collect();
                let mut cv = Curve::new(pts, grey, 1).dashed();
                if first {
                    cv = cv.label("free regimes (m0 = 0): c·j·A² = 8λ ± 4v1, c = 1, 3");
                    first = false;
                }
                panel.curves.push(cv);
            }
        }
        let (mut ls, mut lu) = (Some("Lyapunov stable"), Some("unstable"));
        for b in br {
            for (stable, seg) in split_by(b, |q| q.stable) {
                let pts: Vec<(f64, f64)> = seg.iter().map(|q| (q.p, amp(&q.v))).collect();
                let mut cv = Curve::new(
                    pts,
                    if stable { dark } else { light },
                    if stable { 3 } else { 2 },
                );
                if let Some(l) = if stable { ls.take() } else { lu.take() } {
                    cv = cv.label(l);
                }
                panel.curves.push(cv);
            }
        }
        // unstable drawn first so the stable branches stay on top
        panel
            .curves
            .sort_by_key(|c| (c.color == dark) as u8 + 2 * (c.color != grey) as u8);
        panel.legend = Some(SeriesLabelPosition::UpperLeft);
        draw_panel(area, &panel)?;
    }
    root.present()
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::averaged::fd_jacobian;

    #[test]
    fn analytic_jacobian_matches_finite_differences() {
        let p = Params {
            gamma: 0.3,
            v0: 0.2,
            ..Params::fig4()
        };
        for s in [[0.3, -1.2, 0.7, 0.4], [1.5, 0.2, -0.9, 2.0]] {
            let ja = eq22_jacobian(&p, 0.7, &s);
            let jf = fd_jacobian(&|x| eq22(&p, 0.7, x), &s);
            for r in 0..4 {
                for c in 0..4 {
                    assert!(
                        (ja[r][c] - jf[r][c]).abs() < 1e-7,
                        "{r},{c}: {} vs {}",
                        ja[r][c],
                        jf[r][c]
                    );
                }
            }
            // trace = −16γ
            let tr: f64 = (0..4).map(|i| ja[i][i]).sum();
            assert!((tr + 16.0 * p.gamma).abs() < 1e-12);
        }
    }

    #[test]
    fn plane_regime_and_backbone_of_fig3() {
        // v1 = v0 = γ = 0: the plane regime B = 0, A = m0/(2|λ|), and spatial regimes with
        // A² = 8λ/(c j)
        let p = Params::fig3();
        for lam in [-0.4, 0.3, 1.0] {
            let pts = stationary_points(&p, lam);
            assert!(
                pts.iter()
                    .any(|s| s.b < 1e-9 && (s.a - p.m0 / (2.0 * lam.abs())).abs() < 1e-10),
                "plane regime at {lam}: {pts:?}"
            );
            for s in pts.iter().filter(|s| s.b > 1e-6) {
                let c = p.j * s.a * s.a / (8.0 * lam);
                assert!(
                    (c - 1.0).abs() < 1e-9 || (3.0 * c - 1.0).abs() < 1e-9,
                    "{lam}: {s:?}"
                );
            }
        }
        // λ < 0: only the plane regime
        assert_eq!(stationary_points(&p, -0.4).len(), 1);
    }

    #[test]
    fn slow_state_round_trip() {
        let p = Params::fig4();
        let s = [0.3, -1.1, 0.8, 0.25];
        for tau in [0.0, 1.3, 1234.5] {
            let z = state_from_slow(&p, 0.7, tau, &s);
            let b = slow_from_state(&p, 0.7, tau, &z);
            for i in 0..4 {
                assert!((b[i] - s[i]).abs() < 1e-12);
            }
        }
    }
}
