//! The device: the paper's Table 2 numbers (a protocol, copied as numbers), the drawn
//! manufacturing tolerances, and their conversion to the SI coefficients the plant
//! integrates ([`SiDevice`]).
//!
//! The non-dimensional parameters of the project's model (time unit 1/ω0, length unit
//! L0 = 1 µm) are only the *labels* of a device here; the plant never sees them. It sees
//! damping rates in 1/s, squared natural frequencies in rad²/s², cubic coefficients in
//! 1/(m²·s²), the pump depth in rad²/s² and the rate in rad/s.

use rand::Rng;
use serde::{Deserialize, Serialize};

/// ω0 of Table 2, rad/s: the drive frequency for which γ = 3.8581e-5 is 150 °/s.
pub const OMEGA0_RAD_S: f64 = 2.618 / 3.8581e-5;

/// The length unit of the labels (and of the record's lock-in columns), m.
pub const L0_M: f64 = 1e-6;

/// Standard gravity, m/s².
pub const G_MPS2: f64 = 9.80665;

/// Names of the ten device parameters, in the order of the labels' `deviations`.
pub const PARAM_NAMES: [&str; 10] = [
    "mu_x", "mu_y", "mu_xy", "wx2", "wy2", "wxy2", "alpha_x", "alpha_y", "beta1", "beta3",
];

/// Table 2 of the paper in that order (non-dimensional: μ in units of ω0, ω² of ω0²,
/// α of ω0²/L0², β of ω0²).
pub const TABLE2: [f64; 10] = [
    1e-3, 1e-3, 1e-4, 1.0, 1.0265, 2e-3, 0.002303, 0.001264, 0.0226, 6.33e-5,
];

/// Relative tolerances (uniform ±) of the drawn parameters, in [`PARAM_NAMES`] order:
/// damping 10 %, stiffness 0.2 %, couplings 30 %, cubic stiffness 10 %, pump depth 5 %.
pub const TOLERANCES: [f64; 10] = [0.10, 0.10, 0.30, 0.002, 0.002, 0.30, 0.10, 0.10, 0.05, 0.05];

/// One drawn device (labels.json's `device`, the blind benchmark's `DeviceDraw` format).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeviceDraw {
    /// Relative deviations from Table 2, in [`PARAM_NAMES`] order.
    pub deviations: [f64; 10],
    /// The rate before any rate-table reversal, °/s.
    pub rate_dps: f64,
    /// Mean accelerations along x and y, m/s².
    pub accel_mps2: [f64; 2],
    /// Displacement noise density at the pick-off (one-sided), pm/√Hz.
    pub noise_pm_rthz: f64,
}

impl DeviceDraw {
    /// Table 2 itself at `rate_dps`, 10 g on both axes, 1 pm/√Hz.
    pub fn nominal(rate_dps: f64) -> Self {
        Self {
            deviations: [0.0; 10],
            rate_dps,
            accel_mps2: [10.0 * G_MPS2; 2],
            noise_pm_rthz: 1.0,
        }
    }

    /// A device within the tolerances, a rate of ±30–300 °/s, 0–10 g per axis and
    /// 0.7–1.5 pm/√Hz.
    pub fn draw(rng: &mut impl Rng) -> Self {
        let deviations = TOLERANCES.map(|t| t * (2.0 * rng.random::<f64>() - 1.0));
        let rate = 30.0 + 270.0 * rng.random::<f64>();
        let rate_dps = if rng.random::<bool>() { rate } else { -rate };
        let accel_mps2 = [
            10.0 * G_MPS2 * rng.random::<f64>(),
            10.0 * G_MPS2 * rng.random::<f64>(),
        ];
        let noise_pm_rthz = 0.7 + 0.8 * rng.random::<f64>();
        Self {
            deviations,
            rate_dps,
            accel_mps2,
            noise_pm_rthz,
        }
    }

    /// The non-dimensional parameters (Table 2 × (1 + deviation)), [`PARAM_NAMES`] order.
    pub fn params(&self) -> [f64; 10] {
        let mut p = TABLE2;
        for (v, d) in p.iter_mut().zip(&self.deviations) {
            *v *= 1.0 + d;
        }
        p
    }

    /// The device in SI units.
    pub fn si(&self) -> SiDevice {
        SiDevice::from_params(&self.params())
    }

    /// The pump frequency at the sense resonance (twice the sense natural frequency), Hz.
    pub fn pump_centre_hz(&self) -> f64 {
        2.0 * self.si().wy_rad_s() / std::f64::consts::TAU
    }
}

/// The device's coefficients in SI units (time in s, displacement in m).
///
/// ```text
/// ẍ = −bx ẋ − (kx + kp·s(1 + cos2ψ) − Ω²) x − (kxy − Ω̇) y − (bxy − 2Ω) ẏ
///     − (cx + cp·s(1 + cos2ψ)) x³ + ax
/// ÿ = −by ẏ − (ky − Ω²) y − (kxy + Ω̇) x − (bxy + 2Ω) ẋ − cy y³ + ay
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SiDevice {
    /// Drive damping rate bx = μx·ω0, 1/s.
    pub bx: f64,
    /// Sense damping rate by, 1/s.
    pub by: f64,
    /// Damping coupling bxy, 1/s.
    pub bxy: f64,
    /// Drive stiffness kx = ωx² (rad/s)², at 25 °C.
    pub kx: f64,
    /// Sense stiffness ky, (rad/s)², at 25 °C.
    pub ky: f64,
    /// Stiffness coupling (quadrature) kxy, (rad/s)².
    pub kxy: f64,
    /// Drive cubic stiffness, 1/(m²s²).
    pub cx: f64,
    /// Sense cubic stiffness, 1/(m²s²).
    pub cy: f64,
    /// Linear pump depth 2β1·ω0², (rad/s)² per unit s(1 + cos2ψ).
    pub kp: f64,
    /// Cubic pump depth 2β3·ω0²/L0², 1/(m²s²).
    pub cp: f64,
}

impl SiDevice {
    /// From the non-dimensional parameters in [`PARAM_NAMES`] order.
    pub fn from_params(p: &[f64; 10]) -> Self {
        let w0 = OMEGA0_RAD_S;
        let w02 = w0 * w0;
        let l2 = L0_M * L0_M;
        Self {
            bx: p[0] * w0,
            by: p[1] * w0,
            bxy: p[2] * w0,
            kx: p[3] * w02,
            ky: p[4] * w02,
            kxy: p[5] * w02,
            cx: p[6] * w02 / l2,
            cy: p[7] * w02 / l2,
            kp: 2.0 * p[8] * w02,
            cp: 2.0 * p[9] * w02 / l2,
        }
    }

    /// The sense natural frequency, rad/s.
    pub fn wy_rad_s(&self) -> f64 {
        self.ky.sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn draws_stay_within_their_tolerances() {
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(5);
        for _ in 0..200 {
            let d = DeviceDraw::draw(&mut rng);
            for (v, t) in d.deviations.iter().zip(TOLERANCES) {
                assert!(v.abs() <= t);
            }
            assert!((30.0..=300.0).contains(&d.rate_dps.abs()));
            assert!(
                d.accel_mps2
                    .iter()
                    .all(|a| (0.0..=10.0 * G_MPS2).contains(a))
            );
            assert!((0.7..=1.5).contains(&d.noise_pm_rthz));
        }
        let c = DeviceDraw::nominal(150.0).pump_centre_hz();
        assert!((c - 21883.9526).abs() < 1e-3, "{c}");
    }
}
