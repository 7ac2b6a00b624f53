//! Eq. (19) (the full equations of motion in τ) and eq. (22) (their Krylov–Bogolyubov
//! slow flow) with the parameters the paper leaves open (module docs of [`super`]).

use serde::Serialize;

/// Parameters of eq. (19)/(22).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
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

    /// The v1 coefficient of eq. (22): `2 − 4ξ` (−4 at ξ = 3/2, as printed).
    pub(super) fn kv(&self) -> f64 {
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
