//! The part of eq. (6)'s right-hand side that depends on the instant but not on the
//! state ([`Forcing`]).

use super::{Drive, Theta};

/// The part of the right-hand side of eq. (6) that depends on the instant but not on the
/// state: the pumped linear and cubic drive stiffnesses and the two acceleration forces,
/// for one θ and one [`Drive`]. [`super::rhs`] takes it ready-made, so the integrator computes it
/// once per instant of its half-step grid rather than once per RK4 stage (k2 and k3 share
/// the mid-step instant, and a step's end is the next step's start).
#[derive(Clone, Copy, Debug)]
pub(super) struct Forcing {
    /// θ12 + pm·θ16, pm = (s − 1) + s·cos2ψ.
    pub(super) kx: f64,
    /// θ15 + pm·θ17.
    pub(super) kx3: f64,
    /// θ18·ãx.
    pub(super) accel_x: f64,
    /// θ26·ãy.
    pub(super) accel_y: f64,
}

impl Forcing {
    /// The forcing of the parameters `th` at the pump/input values `d`.
    #[inline(always)]
    pub(super) fn of(th: &Theta, d: &Drive) -> Self {
        let t1 = &th.drive;
        // pump modulation: the (s−1) shift of the nominal θ12/θ15 plus the s·cos2ψ term
        let pm = (d.s - 1.0) + d.s * d.cos2psi;
        Self {
            kx: t1[1] + pm * t1[5],  // linear stiffness incl. pump
            kx3: t1[4] + pm * t1[6], // cubic stiffness incl. pump
            accel_x: t1[7] * d.ax,
            accel_y: th.sense[5] * d.ay,
        }
    }
}
