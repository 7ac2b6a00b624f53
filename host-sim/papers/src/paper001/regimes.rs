//! The stationary regimes of eq. (22): multi-start Newton, Lyapunov stability from the
//! Jacobian's eigenvalues, and the branches A(λ), B(λ) by continuation.

use std::f64::consts::TAU;

use paragyro_core::Cplx;
use serde::Serialize;

use super::model::{Params, eq22, eq22_jacobian};
use crate::complex::CplxExt;
use crate::numerics::{BranchPoint, ContinuationSettings, eig4, find_branches, newton4};

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
    pub eigenvalues: [Cplx<f64>; 4],
    /// Largest real part.
    pub max_re: f64,
    /// Lyapunov stability of the linearisation.
    pub stable: bool,
}

impl Stationary {
    /// The record written to `paper001.json`.
    pub fn record(&self) -> StationaryRecord {
        StationaryRecord {
            lambda: self.lambda,
            q1_p1_q2_p2: self.s,
            a: self.a,
            b: self.b,
            eigenvalues: self.eigenvalues.iter().map(|z| [z.re, z.im]).collect(),
            max_re_eig: self.max_re,
            stable: self.stable,
        }
    }
}

/// A [`Stationary`] as written to `paper001.json`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StationaryRecord {
    /// Detuning λ.
    pub lambda: f64,
    /// `[q1, p1, q2, p2]`.
    pub q1_p1_q2_p2: [f64; 4],
    /// A.
    #[serde(rename = "A")]
    pub a: f64,
    /// B.
    #[serde(rename = "B")]
    pub b: f64,
    /// Eigenvalues as [Re, Im], decreasing real part.
    pub eigenvalues: Vec<[f64; 2]>,
    /// Largest real part.
    pub max_re_eig: f64,
    /// Lyapunov stability.
    pub stable: bool,
}

/// Stability from the eigenvalues: all real parts `< tol·max(1, max|eig|)` with
/// `tol = 1e-6` (marginal, Hamiltonian case γ = 0) or `< 0` when γ > 0.
fn stability(p: &Params, eig: &[Cplx<f64>; 4]) -> bool {
    if p.gamma > 0.0 {
        eig[0].re < 0.0
    } else {
        let scale = eig.iter().fold(1.0f64, |m, z| m.max(z.modulus()));
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
