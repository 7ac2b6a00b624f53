//! Devices that are not the model: the `characterise` scenario with every parameter drawn
//! within a manufacturing tolerance, its own rate, accelerations and noise, and the pump
//! centred on that device's resonance.

use rand::Rng;
use serde::{Deserialize, Serialize};

use paragyro_simulator::scenario::Scenario;

/// Relative tolerances (uniform ±) of the drawn devices.
pub const TOL_DAMPING: f64 = 0.10;
/// ωx², ωy².
pub const TOL_STIFFNESS: f64 = 0.002;
/// μxy, ωxy² (the couplings).
pub const TOL_COUPLING: f64 = 0.30;
/// αx, αy (cubic stiffness).
pub const TOL_CUBIC: f64 = 0.10;
/// β1, β3 (the pump's depth).
pub const TOL_PUMP: f64 = 0.05;

/// What was drawn for one device (labels.json).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeviceDraw {
    /// Relative deviations from Table 2, in [`paragyro_core::physics::PHYSICAL_NAMES`]
    /// order for the ten device parameters (mu_x … beta3).
    pub deviations: [f64; 10],
    /// The rate, °/s.
    pub rate_dps: f64,
    /// Accelerations along x and y, m/s².
    pub accel_mps2: [f64; 2],
    /// Noise density, pm/√Hz.
    pub noise_pm_rthz: f64,
}

impl DeviceDraw {
    /// Draws a device: every parameter within its tolerance, a rate of ±30–300 °/s,
    /// accelerations of 0–10 g on each axis, noise 0.7–1.5 pm/√Hz.
    pub fn draw(rng: &mut impl Rng) -> Self {
        let tol = [
            TOL_DAMPING,
            TOL_DAMPING,
            TOL_COUPLING,
            TOL_STIFFNESS,
            TOL_STIFFNESS,
            TOL_COUPLING,
            TOL_CUBIC,
            TOL_CUBIC,
            TOL_PUMP,
            TOL_PUMP,
        ];
        let deviations = tol.map(|t| t * (2.0 * rng.random::<f64>() - 1.0));
        let rate = 30.0 + 270.0 * rng.random::<f64>();
        let rate_dps = if rng.random::<bool>() { rate } else { -rate };
        let g = 9.80665;
        let accel_mps2 = [
            10.0 * g * rng.random::<f64>(),
            10.0 * g * rng.random::<f64>(),
        ];
        let noise_pm_rthz = 0.7 + 0.8 * rng.random::<f64>();
        DeviceDraw {
            deviations,
            rate_dps,
            accel_mps2,
            noise_pm_rthz,
        }
    }

    /// The model itself (no deviation; Table 2's rate, accelerations and noise).
    pub fn nominal(sc: &Scenario) -> Self {
        DeviceDraw {
            deviations: [0.0; 10],
            rate_dps: sc.plant.rate_dps,
            accel_mps2: [sc.plant.accel_x_mps2, sc.plant.accel_y_mps2],
            noise_pm_rthz: sc.sim.noise_pm_rthz,
        }
    }

    /// The scenario of this device: `sc` with its parameters, rate, accelerations and
    /// noise, and the pump centred on its resonance (2·√ωy²·f0, as `characterise` is on
    /// Table 2's).
    pub fn apply(&self, sc: &Scenario) -> Scenario {
        let mut s = sc.clone();
        let p = &mut s.plant;
        let d = &self.deviations;
        p.mu_x *= 1.0 + d[0];
        p.mu_y *= 1.0 + d[1];
        p.mu_xy *= 1.0 + d[2];
        p.wx2 *= 1.0 + d[3];
        p.wy2 *= 1.0 + d[4];
        p.wxy2 *= 1.0 + d[5];
        p.alpha_x *= 1.0 + d[6];
        p.alpha_y *= 1.0 + d[7];
        p.beta1 *= 1.0 + d[8];
        p.beta3 *= 1.0 + d[9];
        p.rate_dps = self.rate_dps;
        p.accel_x_mps2 = self.accel_mps2[0];
        p.accel_y_mps2 = self.accel_mps2[1];
        s.sim.noise_pm_rthz = self.noise_pm_rthz;
        s.estimator.pump_centre_hz = Some(2.0 * s.plant.wy2.sqrt() * s.sim.f0_hz);
        s
    }

    /// The device's physical parameters (γ at its rate, unit accelerometer gains).
    pub fn physical(&self, sc: &Scenario) -> paragyro_core::Physical {
        let s = self.apply(sc);
        let p = &s.plant;
        let mut ph = paragyro_core::physics::TABLE2;
        ph.mu_x = p.mu_x;
        ph.mu_y = p.mu_y;
        ph.mu_xy = p.mu_xy;
        ph.wx2 = p.wx2;
        ph.wy2 = p.wy2;
        ph.wxy2 = p.wxy2;
        ph.alpha_x = p.alpha_x;
        ph.alpha_y = p.alpha_y;
        ph.beta1 = p.beta1;
        ph.beta3 = p.beta3;
        ph.gamma = paragyro_core::physics::gamma_from_rate_dps(p.rate_dps, s.omega0_rad_s());
        ph.gamma_p = 0.0;
        ph
    }
}
