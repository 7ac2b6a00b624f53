//! The averaged slow flow of seed 000's gyro (DERIVATION.md §6): steady states, their
//! stability, the parametric band of the rest state and the response-vs-pump-frequency
//! characteristic with its hysteresis.
//!
//! # Model
//!
//! First-order Krylov–Bogolyubov averaging of eq. (6) (the method of seed 001), written with
//! complex envelopes: `X = X0 + Re(A e^{iψ})`, `Y = Y0 + Re(B e^{iψ})`, pump `cos 2ψ`,
//! `ψ' = ω` (half the pump frequency). Dropping `A''` and the small `θ11 A'`, `θ14 B'`
//! terms,
//!
//! ```text
//! 2iω A' = F_A = ω²A + iωθ11 A + θ12' A + θ13 B + iωθ14 B + θ15'((3/4)|A|²A + 3X0²A)
//!              + sθ16 A*/2 + sθ17((3/8)|A|²A* + A³/8 + (3/2)X0²A*)
//! 2iω B' = F_B = ω²B + iωθ21 B + θ22 B + θ23 A + iωθ24 A + θ25((3/4)|B|²B + 3Y0²B)
//! ```
//!
//! with `θ12' = θ12 + (s−1)θ16`, `θ15' = θ15 + (s−1)θ17` and the DC levels `X0`, `Y0`
//! solved from the DC balance at every evaluation ([`AveragedModel::dc_solve`], as the
//! prototype's `hb.dc_solve`). θ is in the eq. (25) order of [`paragyro_simulator::plant::Theta`]. The
//! slow-flow state is `v = [Re A, Im A, Re B, Im B]`; the flow is odd in `v` (`v ↦ −v` is a
//! symmetry), so steady states are reported with the canonical sign `Re A ≥ 0`.
//!
//! # Numerics ([`crate::numerics`])
//!
//! * steady states: damped Newton with central finite-difference Jacobians from a fixed
//!   multi-start grid (the prototype's 480 guesses), deduplicated;
//! * stability: eigenvalues of the 4×4 Jacobian ([`crate::numerics::eig4`]: Faddeev–LeVerrier
//!   characteristic polynomial + Aberth–Ehrlich roots);
//! * branches: pseudo-arclength continuation in `(v, ω)`
//!   ([`crate::numerics::trace_branch`]), seeded by the
//!   multi-start, so folds and unstable branches are followed;
//! * quasi-static sweeps: at each frequency the state follows the previous one (Newton); when
//!   that state is lost (fold) or unstable, the slow flow is integrated in time (RK4) to the
//!   attractor it falls into, which is where a slow physical sweep jumps;
//! * the rest-state band both from the averaged formula and from Floquet multipliers of the
//!   full linear time-periodic system (RK4 monodromy).
//!
//! [`write_averaged_report`] writes `averaged_sweep.png` and `averaged.json`.
//!
//! # Modules
//!
//! [`model`] (the flow, steady states), [`stability`] (Floquet, instability bands),
//! [`sweeps`] (quasi-static sweeps, branches, hysteresis), `report` (full-rate check,
//! typed `averaged.json`), `plots` (the figure).

pub mod model;
mod plots;
mod report;
pub mod stability;
pub mod sweeps;

pub use model::{AveragedModel, StateRecord, SteadyState, SweepPoint, canonical, pump_khz};
pub use report::{
    AveragedReport, Band, Claim20, Fold, FullSimCheck, Grid, OperatingPoint, Parameters, SWEEP_HI,
    SWEEP_LO, SWEEP_STEP, SweepMax, SweepReport, SweepSeries, full_sim_envelopes, nearest_stable,
    write_averaged_report,
};
pub use stability::unstable_interval;
pub use sweeps::hysteresis_intervals;

#[cfg(test)]
mod tests;
