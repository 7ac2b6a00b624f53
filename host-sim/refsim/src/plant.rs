//! The plant in SI units: a first-order state space in seconds and metres,
//! `q = [x, ẋ, y, ẏ, z, ż]` (z: the spurious mode, zero without it).
//!
//! ```text
//! ẍ = −bx ẋ − (kx(T) + kp·p − Ω²) x − (kxy − Ω̇) y − (bxy − 2Ω) ẏ − (cx + cp·p) x³ + ax + Fx
//! ÿ = −by ẏ − (ky(T) − Ω²) y − (kxy + Ω̇) x − (bxy + 2Ω) ẋ − cy y³ + ay + Fy
//! ```
//!
//! with the pump `p = s·(1 + cos 2ψ)` (the electrostatic force goes with the square of the
//! pump voltage V_A·cos ψ: V_A² cos²ψ = V_A²(1 + cos 2ψ)/2, so the pump phase is exactly
//! 2ψ and its mean is s), `s = (V_A/V_A0)²`, the rate Ω(t) in rad/s (a rate table and an
//! angular vibration move it, Ω̇ is its derivative), the die temperature T(t), and the
//! effect forces `Fx`, `Fy` of [`crate::effects`].

use crate::device::{L0_M, OMEGA0_RAD_S, SiDevice};
use crate::effects::EffectSizes;

/// Number of plant states.
pub const NQ: usize = 6;

/// Reference temperature of the thermal drift, °C.
pub const T_REF_C: f64 = 25.0;

/// Cubic-to-linear ratio of the electrostatic softening, per L0² (parallel plates, 3 µm
/// gap: F ∝ y + 2y³/g²).
const ES_CUBIC: f64 = 2.0 / 9.0;

/// The friction's smoothing velocity, in L0·ω0 (m/s after scaling).
const FRICTION_V: f64 = 1e-3;

/// The spurious mode: ωz² = ky·(1 + this), damping 1e-3·ω0.
const SPURIOUS_DETUNE: f64 = 4e-3;
const SPURIOUS_DAMPING: f64 = 1e-3;

/// The trapped charge's time constant, s.
const CHARGING_TAU_S: f64 = 5.0;

/// Known inputs of the plant at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inputs {
    /// cos 2ψ, the pump's phase.
    pub cos2psi: f64,
    /// Pump scale s = (V_A/V_A0)².
    pub s: f64,
    /// Accelerations along x and y, m/s².
    pub ax: f64,
    /// Sense axis acceleration, m/s².
    pub ay: f64,
    /// Rate (rate table), rad/s.
    pub rate: f64,
    /// Its derivative, rad/s².
    pub rate_dot: f64,
    /// Die temperature, °C.
    pub temp_c: f64,
}

/// The device and its effects, ready for the right-hand side.
#[derive(Clone, Debug)]
pub struct Plant {
    dev: SiDevice,
    fx: EffectSizes,
    /// Angular vibration amplitude, rad/s, and angular frequency, rad/s.
    vib: (f64, f64),
    /// Whether any term beyond the nominal model is active.
    any: bool,
}

impl Plant {
    /// The plant of `dev` with the effects `fx`; `first_pump_hz` places the angular
    /// vibration (its frequency is that plus the beat).
    pub fn new(dev: SiDevice, fx: EffectSizes, first_pump_hz: f64) -> Self {
        let vib = if fx.vib_dps != 0.0 {
            (
                fx.vib_dps.to_radians(),
                std::f64::consts::TAU * (first_pump_hz + fx.vib_beat_hz),
            )
        } else {
            (0.0, 0.0)
        };
        let z = EffectSizes {
            vib_beat_hz: fx.vib_beat_hz,
            es_pump: fx.es_pump,
            lockin_mismatch: fx.lockin_mismatch,
            tcf_ppm_k: fx.tcf_ppm_k,
            ..EffectSizes::default()
        };
        let any = fx != z;
        Self { dev, fx, vib, any }
    }

    /// The effect sizes.
    pub fn effects(&self) -> &EffectSizes {
        &self.fx
    }

    /// The angular vibration's rate and its derivative at `t_s`, rad/s and rad/s².
    #[inline]
    fn vibration(&self, t_s: f64) -> (f64, f64) {
        if self.vib.0 == 0.0 {
            return (0.0, 0.0);
        }
        let (sn, cs) = (self.vib.1 * t_s + self.fx.vib_phase).sin_cos();
        (self.vib.0 * sn, self.vib.0 * self.vib.1 * cs)
    }

    /// dq/dt at time `t_s` with the inputs `u`.
    #[inline]
    pub fn rhs(&self, t_s: f64, q: &[f64; NQ], u: &Inputs) -> [f64; NQ] {
        let d = &self.dev;
        let [x, xd, y, yd, z, zd] = *q;
        let (om_v, om_vd) = self.vibration(t_s);
        let om = u.rate + om_v;
        let om_d = u.rate_dot + om_vd;
        let om2 = om * om;
        let (kx, ky) = if self.fx.tcf_ppm_k != 0.0 {
            let f = 1.0 + self.fx.tcf_ppm_k * 1e-6 * (u.temp_c - T_REF_C);
            (d.kx * f * f, d.ky * f * f)
        } else {
            (d.kx, d.ky)
        };
        let p = u.s * (1.0 + u.cos2psi);
        let x2 = x * x;
        let y2 = y * y;
        let mut xdd = -d.bx * xd
            - (kx + d.kp * p - om2) * x
            - (d.kxy - om_d) * y
            - (d.bxy - 2.0 * om) * yd
            - (d.cx + d.cp * p) * x2 * x
            + u.ax;
        let mut ydd = -d.by * yd
            - (ky - om2) * y
            - (d.kxy + om_d) * x
            - (d.bxy + 2.0 * om) * xd
            - d.cy * y2 * y
            + u.ay;
        let mut zdd = 0.0;
        if self.any {
            let [fx_, fy_, fz] = self.effect_forces(t_s, q, u, p);
            xdd += fx_;
            ydd += fy_;
            zdd = fz - SPURIOUS_DAMPING * OMEGA0_RAD_S * zd - (1.0 + SPURIOUS_DETUNE) * ky * z;
        }
        [xd, xdd, yd, ydd, zd, zdd]
    }

    /// The effect forces (m/s²) on x, y and the spurious mode's coupling force.
    fn effect_forces(&self, t_s: f64, q: &[f64; NQ], u: &Inputs, p: f64) -> [f64; 3] {
        let e = &self.fx;
        let d = &self.dev;
        let [x, xd, y, yd, z, _] = *q;
        let w0 = OMEGA0_RAD_S;
        let w02 = w0 * w0;
        let il2 = 1.0 / (L0_M * L0_M);
        let mut fx = 0.0;
        let mut fy = 0.0;
        if e.geometric != 0.0 {
            fx -= e.geometric * y * (w02 * x * y + 2.0 * xd * yd) * il2;
            fy += e.geometric * y * xd * xd * il2;
        }
        if e.electrostatic != 0.0 {
            let k = if e.es_pump {
                e.electrostatic * u.s
            } else {
                e.electrostatic
            };
            fy -= k * w02 * y * (1.0 + ES_CUBIC * y * y * il2);
        }
        if e.nl_damping != 0.0 {
            fx -= e.nl_damping * w0 * x * x * xd * il2;
            fy -= e.nl_damping * w0 * y * y * yd * il2;
        }
        if e.anisodamping != 0.0 {
            fx -= 0.5 * e.anisodamping * w0 * yd;
            fy += 0.5 * e.anisodamping * w0 * xd;
        }
        if e.force_leak != 0.0 {
            fy -= e.force_leak * p * (d.kp * x + d.cp * x * x * x);
        }
        if e.quadratic != 0.0 {
            fx -= e.quadratic * w02 * x * x / L0_M;
            fy -= e.quadratic * w02 * y * y / L0_M;
        }
        if e.friction != 0.0 {
            fy -= e.friction * w02 * L0_M * (yd / (FRICTION_V * w0 * L0_M)).tanh();
        }
        if e.charging != 0.0 {
            let charge = -(-t_s / CHARGING_TAU_S).exp_m1();
            fy += e.charging * w02 * charge * (L0_M + y);
        }
        let mut fz = 0.0;
        if e.spurious != 0.0 {
            fy -= e.spurious * w02 * z;
            fz = -e.spurious * w02 * y;
        }
        [fx, fy, fz]
    }

    /// What the pick-offs read, m: `[x, (1 + g)y + C·s(1 + cos2ψ) − d·ẏ]`.
    #[inline]
    pub fn measure(&self, q: &[f64; NQ], u: &Inputs) -> [f64; 2] {
        if !self.any {
            return [q[0], q[2]];
        }
        let e = &self.fx;
        let lag_s = e.pickoff_lag_rad / self.dev.wy_rad_s();
        let ft = e.feedthrough_um * 1e-6 * u.s * (1.0 + u.cos2psi);
        [q[0], (1.0 + e.readout_gain) * q[2] + ft - lag_s * q[3]]
    }
}
