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
//!
//! # Modules
//!
//! [`model`] (eqs. 19 and 22), [`regimes`] (stationary regimes, stability, branches),
//! [`rk4`] (direct integration of eq. 19), [`claims`] (the paper's claims), `report`
//! (typed `paper001.json`), `plots` (Figs 3–4).

pub mod claims;
pub mod model;
mod plots;
pub mod regimes;
mod report;
pub mod rk4;

pub use claims::{existence_scan, parabola_family};
pub use model::{Params, eq19_rhs, eq22, eq22_jacobian, slow_from_state, state_from_slow};
pub use regimes::{
    AMP_MAX, LAMBDA_HI, LAMBDA_LO, Stationary, StationaryRecord, branches, classify,
    default_guesses, distinct_amplitudes, newton, stationary_points, stationary_points_with,
};
pub use report::{
    BranchSummary, FigureReport, Paper001Claims, Paper001Report, RegimesAt, ReportParameters,
    write_paper001_report,
};
pub use rk4::{Rk4Check, Rk4Run, STEPS_PER_PERIOD, rk4_eq19, stable_spatial};

#[cfg(test)]
mod tests;
