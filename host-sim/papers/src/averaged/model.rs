//! The averaged model itself: the DC balance, the slow-flow forces, steady states by
//! multi-start Newton and their classification, and the rest state's closed-form band.

use std::f64::consts::{PI, TAU};

use paragyro_core::Cplx;
use paragyro_core::physics::OMEGA0_TABLE2_RAD_S;
use paragyro_simulator::plant::{ACCEL_TABLE2, Theta};
use serde::Serialize;

use crate::complex::CplxExt;
use crate::numerics::{eig4, fd_jacobian, newton4};

/// Newton residual tolerance on the slow flow `‖v'‖∞` (the prototype's 1e-11, tighter).
pub(super) const RES_TOL: f64 = 1e-12;
/// A state with `|A|` below this is the trivial (rest) state.
pub(super) const TRIVIAL_A: f64 = 1e-3;
/// In a sweep, a change of the state by more than this (`‖Δv‖∞`) from one frequency to
/// the next is a jump.
pub(super) const JUMP: f64 = 0.3;
/// Seed amplitude of the drive when the sweep leaves an unstable rest state (the
/// full simulation's `X(0) = 0.01`).
pub(super) const SEED_A: f64 = 0.01;

/// The averaged slow flow of eq. (6) for one parameter set and constant inputs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AveragedModel {
    /// θ1, θ2 (eq. 25 order).
    pub theta: Theta,
    /// Pump voltage scale s.
    pub s: f64,
    /// Drive-axis acceleration ãx.
    pub ax: f64,
    /// Sense-axis acceleration ãy.
    pub ay: f64,
}

/// A steady state of the slow flow at one pump half-frequency ω.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SteadyState {
    /// ω (half the pump frequency, units of ω0).
    pub omega: f64,
    /// Drive envelope A (canonical sign Re A ≥ 0).
    pub a: Cplx<f64>,
    /// Sense envelope B.
    pub b: Cplx<f64>,
    /// DC level of X.
    pub x0: f64,
    /// DC level of Y.
    pub y0: f64,
    /// Eigenvalues of the slow-flow Jacobian, decreasing real part (1/τ).
    pub eigenvalues: [Cplx<f64>; 4],
    /// Largest real part.
    pub max_re: f64,
    /// `max_re < 0`.
    pub stable: bool,
}

impl SteadyState {
    /// The slow-flow state `[Re A, Im A, Re B, Im B]`.
    pub fn v(&self) -> [f64; 4] {
        [self.a.re, self.a.im, self.b.re, self.b.im]
    }

    /// The record written to `averaged.json` (amplitudes, envelopes, DC levels,
    /// eigenvalues, stability).
    pub fn record(&self) -> StateRecord {
        StateRecord {
            omega: self.omega,
            pump_khz: pump_khz(self.omega),
            abs_a: self.a.modulus(),
            abs_b: self.b.modulus(),
            a: [self.a.re, self.a.im],
            b: [self.b.re, self.b.im],
            x0: self.x0,
            y0: self.y0,
            eigenvalues: self.eigenvalues.iter().map(|z| [z.re, z.im]).collect(),
            max_re_eig: self.max_re,
            stable: self.stable,
        }
    }
}

/// A [`SteadyState`] as written to `averaged.json`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StateRecord {
    /// ω.
    pub omega: f64,
    /// Pump frequency, kHz.
    pub pump_khz: f64,
    /// |A|.
    #[serde(rename = "abs_A")]
    pub abs_a: f64,
    /// |B|.
    #[serde(rename = "abs_B")]
    pub abs_b: f64,
    /// A as [Re, Im].
    #[serde(rename = "A")]
    pub a: [f64; 2],
    /// B as [Re, Im].
    #[serde(rename = "B")]
    pub b: [f64; 2],
    /// DC level of X.
    #[serde(rename = "X0")]
    pub x0: f64,
    /// DC level of Y.
    #[serde(rename = "Y0")]
    pub y0: f64,
    /// Eigenvalues as [Re, Im], decreasing real part.
    pub eigenvalues: Vec<[f64; 2]>,
    /// Largest real part.
    pub max_re_eig: f64,
    /// Linearly stable.
    pub stable: bool,
}

/// One frequency of a quasi-static sweep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SweepPoint {
    /// ω.
    pub omega: f64,
    /// The state the sweep is in.
    pub v: [f64; 4],
    /// |A|.
    pub abs_a: f64,
    /// |B|.
    pub abs_b: f64,
    /// Stability of that state (always true unless the integration did not settle).
    pub stable: bool,
    /// The state jumped (left its branch) on arriving at this frequency.
    pub jump: bool,
}

/// Pump frequency in kHz for the half-frequency `omega` (units of ω0 = 67 858 rad/s).
pub fn pump_khz(omega: f64) -> f64 {
    2.0 * omega * OMEGA0_TABLE2_RAD_S / TAU / 1e3
}

/// Canonical representative of `±v`: `Re A ≥ 0` (then `Im A ≥ 0` if `Re A = 0`).
pub fn canonical(v: [f64; 4]) -> [f64; 4] {
    if v[0] < 0.0 || (v[0] == 0.0 && v[1] < 0.0) {
        v.map(|x| -x)
    } else {
        v
    }
}

pub(super) fn dist(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    (0..4).fold(0.0f64, |m, i| m.max((a[i] - b[i]).abs()))
}

impl AveragedModel {
    /// A model for `theta` with pump scale `s` and accelerations `ax`, `ay`.
    pub fn new(theta: Theta, s: f64, ax: f64, ay: f64) -> Self {
        Self { theta, s, ax, ay }
    }

    /// Table 2: θ of [`Theta::table2`], s = 1, ãx = ãy = 0.0213 (10 g).
    pub fn table2() -> Self {
        Self::new(Theta::table2(), 1.0, ACCEL_TABLE2, ACCEL_TABLE2)
    }

    /// The same model with the sense natural frequency ωy² = `wy2`.
    pub fn with_wy2(self, wy2: f64) -> Self {
        Self {
            theta: self.theta.with_wy2(wy2),
            ..self
        }
    }

    pub(super) fn t12(&self) -> f64 {
        self.theta.drive[1] + (self.s - 1.0) * self.theta.drive[5]
    }
    pub(super) fn t15(&self) -> f64 {
        self.theta.drive[4] + (self.s - 1.0) * self.theta.drive[6]
    }

    /// DC levels `(X0, Y0)` for the envelopes `a`, `b` (DC rows of DERIVATION §2–3 with
    /// only the fundamental present), by alternating Newton to the rounding level.
    pub fn dc_solve(&self, a: Cplx<f64>, b: Cplx<f64>) -> (f64, f64) {
        let (t1, t2) = (&self.theta.drive, &self.theta.sense);
        let (t12, t15) = (self.t12(), self.t15());
        let (aa, bb) = (a.norm_sqr(), b.norm_sqr());
        let re_a2 = (a * a).re;
        let mut x0 = -t1[7] * self.ax / t12;
        let mut y0 = -t2[5] * self.ay / t2[1];
        for _ in 0..30 {
            let fx = t12 * x0
                + t1[2] * y0
                + t15 * (x0 * x0 * x0 + 1.5 * x0 * aa)
                + self.s * t1[6] * 0.75 * x0 * re_a2
                + t1[7] * self.ax;
            let dfx = t12 + t15 * (3.0 * x0 * x0 + 1.5 * aa) + self.s * t1[6] * 0.75 * re_a2;
            let dx = fx / dfx;
            x0 -= dx;
            let fy =
                t2[1] * y0 + t2[2] * x0 + t2[4] * (y0 * y0 * y0 + 1.5 * y0 * bb) + t2[5] * self.ay;
            let dfy = t2[1] + t2[4] * (3.0 * y0 * y0 + 1.5 * bb);
            let dy = fy / dfy;
            y0 -= dy;
            if dx.abs() <= 1e-17 * x0.abs().max(1e-30) && dy.abs() <= 1e-17 * y0.abs().max(1e-30)
                || (dx == 0.0 && dy == 0.0)
            {
                break;
            }
            if !(dx.is_finite() && dy.is_finite()) {
                break;
            }
        }
        (x0, y0)
    }

    /// `(F_A, F_B)` of DERIVATION §6 at ω for the envelopes and DC levels given.
    pub fn forces(
        &self,
        omega: f64,
        a: Cplx<f64>,
        b: Cplx<f64>,
        x0: f64,
        y0: f64,
    ) -> (Cplx<f64>, Cplx<f64>) {
        let (t1, t2) = (&self.theta.drive, &self.theta.sense);
        let (t12, t15, s) = (self.t12(), self.t15(), self.s);
        let (aa, bb) = (a.norm_sqr(), b.norm_sqr());
        let w2 = omega * omega;
        let ac = a.conj();
        let fa = a.scale(w2 + t12)
            + a.mul_i().scale(omega * t1[0])
            + b.scale(t1[2])
            + b.mul_i().scale(omega * t1[3])
            + a.scale(t15 * (0.75 * aa + 3.0 * x0 * x0))
            + ac.scale(0.5 * s * t1[5])
            + (ac.scale(0.375 * aa + 1.5 * x0 * x0) + (a * a * a).scale(0.125)).scale(s * t1[6]);
        let fb = b.scale(w2 + t2[1])
            + b.mul_i().scale(omega * t2[0])
            + a.scale(t2[2])
            + a.mul_i().scale(omega * t2[3])
            + b.scale(t2[4] * (0.75 * bb + 3.0 * y0 * y0));
        (fa, fb)
    }

    /// The slow flow `v' = [A', B']` with `A' = F_A/(2iω)`, `B' = F_B/(2iω)` (1/τ).
    pub fn slow_flow(&self, omega: f64, v: &[f64; 4]) -> [f64; 4] {
        let a = Cplx::new(v[0], v[1]);
        let b = Cplx::new(v[2], v[3]);
        let (x0, y0) = self.dc_solve(a, b);
        let (fa, fb) = self.forces(omega, a, b, x0, y0);
        // F/(2iω) = −i·F/(2ω)
        let k = 0.5 / omega;
        [k * fa.im, -k * fa.re, k * fb.im, -k * fb.re]
    }

    /// Jacobian of [`Self::slow_flow`] with respect to `v` (central differences).
    pub fn jacobian(&self, omega: f64, v: &[f64; 4]) -> [[f64; 4]; 4] {
        fd_jacobian(&|x| self.slow_flow(omega, x), v)
    }

    /// Newton from `guess` to a fixed point of the slow flow at ω (`‖v'‖∞ ≤ 1e-12`).
    pub fn newton(&self, omega: f64, guess: [f64; 4]) -> Option<[f64; 4]> {
        newton4(
            &|x| self.slow_flow(omega, x),
            &|x| self.jacobian(omega, x),
            guess,
            RES_TOL,
            100.0,
        )
    }

    /// The fixed point `v` (any sign) as a classified, canonical [`SteadyState`].
    pub fn classify(&self, omega: f64, v: [f64; 4]) -> SteadyState {
        let v = canonical(v);
        let a = Cplx::new(v[0], v[1]);
        let b = Cplx::new(v[2], v[3]);
        let (x0, y0) = self.dc_solve(a, b);
        let eigenvalues = eig4(&self.jacobian(omega, &v));
        let max_re = eigenvalues[0].re;
        SteadyState {
            omega,
            a,
            b,
            x0,
            y0,
            eigenvalues,
            max_re,
            stable: max_re < 0.0,
        }
    }

    /// The rest state (A = B = 0, DC levels from the accelerations) at ω, classified.
    pub fn trivial(&self, omega: f64) -> SteadyState {
        self.classify(omega, [0.0; 4])
    }

    /// The prototype's multi-start grid (`hb.steady_states`): |A| ∈ {0.3, 1, 2, 3.5, 5} ×
    /// 6 phases in [0, π) × |B| ∈ {0.1, 1, 3, 6} × 4 phases — 480 guesses.
    pub fn default_guesses() -> Vec<[f64; 4]> {
        let mut g = Vec::with_capacity(480);
        for a in [0.3, 1.0, 2.0, 3.5, 5.0] {
            for k in 0..6 {
                let ph = PI * k as f64 / 6.0;
                for b in [0.1, 1.0, 3.0, 6.0] {
                    for l in 0..4 {
                        let pb = TAU * l as f64 / 4.0;
                        g.push([a * ph.cos(), a * ph.sin(), b * pb.cos(), b * pb.sin()]);
                    }
                }
            }
        }
        g
    }

    /// All distinct nontrivial steady states at ω found by Newton from
    /// [`Self::default_guesses`], canonical sign, sorted by |B|.
    pub fn steady_states(&self, omega: f64) -> Vec<SteadyState> {
        self.steady_states_with(omega, &Self::default_guesses())
    }

    /// As [`Self::steady_states`] from the given guesses.
    pub fn steady_states_with(&self, omega: f64, guesses: &[[f64; 4]]) -> Vec<SteadyState> {
        let mut found: Vec<[f64; 4]> = Vec::new();
        for g in guesses {
            let Some(v) = self.newton(omega, *g) else {
                continue;
            };
            if v[0].hypot(v[1]) < TRIVIAL_A {
                continue;
            }
            let v = canonical(v);
            if found.iter().any(|w| dist(w, &v) < 1e-6) {
                continue;
            }
            found.push(v);
        }
        let mut out: Vec<SteadyState> =
            found.into_iter().map(|v| self.classify(omega, v)).collect();
        out.sort_by(|x, y| x.b.modulus().total_cmp(&y.b.modulus()));
        out
    }

    /// The band of ω where the rest state is unstable, from the averaged (damped Mathieu)
    /// formula `ω² ∈ K ± √((sβ)² − μ²K)`, `K = −θ12'`, `β = |θ16|/2`, `μ = −θ11`
    /// (DERIVATION §6, `hb.trivial_band`). `None` if the pump is below threshold.
    pub fn trivial_band(&self) -> Option<(f64, f64)> {
        let k = -self.t12();
        let b = (self.s * self.theta.drive[5]).abs() / 2.0;
        let mu = -self.theta.drive[0];
        let d = b * b - mu * mu * k;
        if d <= 0.0 {
            return None;
        }
        let r = d.sqrt();
        Some(((k - r).sqrt(), (k + r).sqrt()))
    }
}
