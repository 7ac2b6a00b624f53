//! Physical parameters ↔ regression parameters θ1 (drive, 8) / θ2 (sense, 6), and the
//! rate ↔ Coriolis coefficient γ conversion.
//!
//! # Model (paper eq. 6, non-dimensional time τ = ω0·t, θ in the eq. (25) order)
//!
//! ```text
//! X'' = θ11 X' + θ12 X + θ13 Y + θ14 Y' + θ15 X³ + θ16 X cos2ψ + θ17 X³ cos2ψ + θ18 ãx
//! Y'' = θ21 Y' + θ22 Y + θ23 X + θ24 X' + θ25 Y³ + θ26 ãy
//!
//! θ1 = [−μx, −(ωx²−γ²+2β1), −(ωxy²−γ'), −(μxy−2γ), −(2β3+αx), −2β1, −2β3, c_ax]
//! θ2 = [−μy, −(ωy²−γ²),     −(ωxy²+γ'), −(μxy+2γ), −αy,                 c_ay]
//! ```
//!
//! (pump-voltage scale `s = 1`; `c_ax = c_ay = 1` in the paper's model, kept as free
//! parameters θ18/θ26 so that accelerometer gain errors are identified too).
//!
//! [`physical_from_theta`] is the *corrected* Table 3 for this order
//! (DERIVATION.md §0):
//!
//! | quantity | eq. (25) order (implemented) |
//! |---|---|
//! | γ | (θ14 − θ24)/4 |
//! | μxy | −(θ14 + θ24)/2 |
//! | ωxy² | −(θ13 + θ23)/2 |
//! | γ' | +(θ13 − θ23)/2 |
//! | β1, β3 | −θ16/2, −θ17/2 |
//! | αx | θ17 − θ15 |
//! | ωx² | −θ12 + θ16 + γ² |
//! | ωy² | −θ22 + γ² |
//! | μx, μy, αy | −θ11, −θ21, −θ25 |
//!
//! # Errata of the paper (verified in FINDINGS.md §0; the code follows the corrections)
//!
//! 1. **Order.** The numbers of eq. (25) use the order above, in which components 3 and
//!    4 of θ1 and of θ2 are *swapped* relative to eq. (8)/(12): here θ13 = −(ωxy²−γ')
//!    multiplies `Y` and θ14 = −(μxy−2γ) multiplies `Y'`. The paper's Table 3 is
//!    written for the eq. (8) order.
//! 2. **θ2, 4th entry.** Eq. (25) prints −0.0000177; the model gives
//!    −(μxy+2γ) = −1.77e-4 (factor-10 typo, carried into eqs. 26–27).
//! 3. **θ2, 5th entry.** Eq. (25) prints −0.001537, but −αy = −0.001264 with Table 2.
//!    It is consistent through eqs. (25)–(27), so the paper probably simulated with
//!    αy = 0.001537. [`TABLE2`] keeps Table 2's value.
//! 4. **Table 3, γ'.** The paper has γ' = −(θ14−θ24)/2 (its order); the correct sign is
//!    + (as in the Fig. 14 caption): γ' = +(θ13 − θ23)/2 in the eq. (25) order.
//! 5. **Table 3, αx.** The paper writes αx = −θ15 + θ16 (index error); correct is
//!    αx = θ17 − θ15 (as in the Fig. 13 caption).
//!
//! # Rate
//!
//! γ is the Coriolis coefficient in units of ω0: Ω = γ·ω0 rad/s, so
//! [`rate_dps_from_gamma`] is `γ·ω0·180/π`. Table 2's γ = 3.8581e-5 with
//! ω0 = 2.618/3.8581e-5 rad/s ([`OMEGA0_TABLE2_RAD_S`], 67 858 rad/s, 10.80 kHz) is
//! 2.618 rad/s = 150 °/s.
//!
//! These are slow-path helpers in `f64` (called after the RLS, not per row).

use core::f64::consts::PI;

/// Drive natural frequency implied by Table 2: ω0 = 2.618/3.8581e-5 ≈ 67 858 rad/s
/// (10.80 kHz), chosen so that γ = 3.8581e-5 is 150 °/s. The one definition of ω0 in
/// the workspace: the configuration ([`crate::Config::table2`]) and the simulator
/// derive from it.
pub const OMEGA0_TABLE2_RAD_S: f64 = 2.618 / 3.8581e-5;

/// ω0/2π of Table 2 (≈ 10 799.8 Hz): the configuration's `f0_hz`.
pub const F0_TABLE2_HZ: f64 = OMEGA0_TABLE2_RAD_S / (2.0 * PI);

/// The length unit L0 of the non-dimensional model (the paper's 1 µm), in µm: the
/// configuration's `l0_um`.
pub const L0_TABLE2_UM: f64 = 1.0;

/// The length unit L0 in metres (1e-6 m), for SI conversions such as
/// `a = ã · L0 · ω0²`.
pub const L0_TABLE2_M: f64 = 1e-6;

/// Physical parameters of eq. (6), non-dimensional (units of ω0 and L0).
///
/// Field order of [`Physical::as_array`] / [`Physical::from_array`]:
/// `[mu_x, mu_y, mu_xy, wx2, wy2, wxy2, alpha_x, alpha_y, beta1, beta3, gamma,
/// gamma_p]` (names in [`PHYSICAL_NAMES`]); the accelerometer gains `c_ax`, `c_ay`
/// are separate.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Physical {
    /// μx: drive damping (1/Q_x).
    pub mu_x: f64,
    /// μy: sense damping (1/Q_y).
    pub mu_y: f64,
    /// μxy: anisodamping (damping cross-coupling).
    pub mu_xy: f64,
    /// ωx²: drive stiffness (squared natural frequency, units of ω0²).
    pub wx2: f64,
    /// ωy²: sense stiffness (squared natural frequency, units of ω0²).
    pub wy2: f64,
    /// ωxy²: quadrature (stiffness cross-coupling).
    pub wxy2: f64,
    /// αx: drive cubic (Duffing) stiffness.
    pub alpha_x: f64,
    /// αy: sense cubic (Duffing) stiffness.
    pub alpha_y: f64,
    /// β1: linear parametric pump depth.
    pub beta1: f64,
    /// β3: cubic parametric pump depth.
    pub beta3: f64,
    /// γ: Coriolis coefficient = Ω/ω0 (see [`rate_dps_from_gamma`]).
    pub gamma: f64,
    /// γ': angular acceleration Ω'/ω0² (0 at constant rate).
    pub gamma_p: f64,
    /// θ18: gain of the drive-axis acceleration input ãx (1 in the model).
    pub c_ax: f64,
    /// θ26: gain of the sense-axis acceleration input ãy (1 in the model).
    pub c_ay: f64,
}

/// Names of the entries of [`Physical::as_array`], in order (for reports).
pub const PHYSICAL_NAMES: [&str; 12] = [
    "mu_x", "mu_y", "mu_xy", "wx2", "wy2", "wxy2", "alpha_x", "alpha_y", "beta1", "beta3", "gamma",
    "gamma_p",
];

/// Table 2 of the paper (150 °/s, γ' = 0, unit accelerometer gains).
pub const TABLE2: Physical = Physical {
    mu_x: 1e-3,
    mu_y: 1e-3,
    mu_xy: 1e-4,
    wx2: 1.0,
    wy2: 1.0265,
    wxy2: 2e-3,
    alpha_x: 0.002303,
    alpha_y: 0.001264,
    beta1: 0.0226,
    beta3: 6.33e-5,
    gamma: 3.8581e-5,
    gamma_p: 0.0,
    c_ax: 1.0,
    c_ay: 1.0,
};

impl Physical {
    /// Same as the module-level [`TABLE2`].
    pub const TABLE2: Physical = TABLE2;

    /// `[mu_x, mu_y, mu_xy, wx2, wy2, wxy2, alpha_x, alpha_y, beta1, beta3, gamma,
    /// gamma_p]` (without `c_ax`, `c_ay`).
    pub const fn as_array(&self) -> [f64; 12] {
        [
            self.mu_x,
            self.mu_y,
            self.mu_xy,
            self.wx2,
            self.wy2,
            self.wxy2,
            self.alpha_x,
            self.alpha_y,
            self.beta1,
            self.beta3,
            self.gamma,
            self.gamma_p,
        ]
    }

    /// Inverse of [`Physical::as_array`]; `c_ax` and `c_ay` are set to their model
    /// value 1.
    pub const fn from_array(a: [f64; 12]) -> Self {
        let [
            mu_x,
            mu_y,
            mu_xy,
            wx2,
            wy2,
            wxy2,
            alpha_x,
            alpha_y,
            beta1,
            beta3,
            gamma,
            gamma_p,
        ] = a;
        Physical {
            mu_x,
            mu_y,
            mu_xy,
            wx2,
            wy2,
            wxy2,
            alpha_x,
            alpha_y,
            beta1,
            beta3,
            gamma,
            gamma_p,
            c_ax: 1.0,
            c_ay: 1.0,
        }
    }
}

/// Physical parameters → `(θ1, θ2)` in the eq. (25) order (see the module docs):
///
/// ```text
/// θ1 = [−μx, −(ωx²−γ²+2β1), −(ωxy²−γ'), −(μxy−2γ), −(2β3+αx), −2β1, −2β3, c_ax]
/// θ2 = [−μy, −(ωy²−γ²),     −(ωxy²+γ'), −(μxy+2γ), −αy,                 c_ay]
/// ```
///
/// ```
/// use paragyro_core::physics::{theta_from_physical, TABLE2};
/// let (th1, th2) = theta_from_physical(&TABLE2);
/// assert!((th1[1] + 1.0452).abs() < 5e-5); // eq. (25): −1.0452
/// assert!((th2[3] + 1.77e-4).abs() < 5e-7); // eq. (25) prints −0.0000177 (typo)
/// ```
pub fn theta_from_physical(p: &Physical) -> ([f64; 8], [f64; 6]) {
    let g2 = p.gamma * p.gamma;
    let th1 = [
        -p.mu_x,
        -(p.wx2 - g2 + 2.0 * p.beta1),
        -(p.wxy2 - p.gamma_p),
        -(p.mu_xy - 2.0 * p.gamma),
        -(2.0 * p.beta3 + p.alpha_x),
        -2.0 * p.beta1,
        -2.0 * p.beta3,
        p.c_ax,
    ];
    let th2 = [
        -p.mu_y,
        -(p.wy2 - g2),
        -(p.wxy2 + p.gamma_p),
        -(p.mu_xy + 2.0 * p.gamma),
        -p.alpha_y,
        p.c_ay,
    ];
    (th1, th2)
}

/// ω_y² from θ1, θ2 (its three components: −θ22 + γ², γ = (θ14 − θ24)/4), without the
/// rest of [`physical_from_theta`].
pub fn wy2_from_theta(th1: &[f64; 8], th2: &[f64; 6]) -> f64 {
    let g = (th1[3] - th2[3]) / 4.0;
    -th2[1] + g * g
}

/// `(θ1, θ2)` in the eq. (25) order → physical parameters: the corrected Table 3
/// (module docs; the paper's γ' sign and αx index errors are fixed).
///
/// Exact inverse of [`theta_from_physical`] up to rounding (≤ a few ulp relative for
/// Table-2-like values). γ comes from the small difference θ14 − θ24 (θ14 ≈ 5e-5 of
/// its row), which is why γ is the most noise-sensitive output (FINDINGS.md §7).
///
/// ```
/// use paragyro_core::physics::{physical_from_theta, theta_from_physical, TABLE2};
/// let (th1, th2) = theta_from_physical(&TABLE2);
/// let p = physical_from_theta(&th1, &th2);
/// assert!((p.gamma - TABLE2.gamma).abs() < 1e-18);
/// ```
pub fn physical_from_theta(th1: &[f64; 8], th2: &[f64; 6]) -> Physical {
    let [t11, t12, t13, t14, t15, t16, t17, t18] = *th1;
    let [t21, t22, t23, t24, t25, t26] = *th2;
    let gamma = (t14 - t24) / 4.0;
    let g2 = gamma * gamma;
    Physical {
        mu_x: -t11,
        mu_y: -t21,
        mu_xy: -(t14 + t24) / 2.0,
        wx2: -t12 + t16 + g2,
        wy2: -t22 + g2,
        wxy2: -(t13 + t23) / 2.0,
        alpha_x: t17 - t15,
        alpha_y: -t25,
        beta1: -t16 / 2.0,
        beta3: -t17 / 2.0,
        gamma,
        gamma_p: (t13 - t23) / 2.0,
        c_ax: t18,
        c_ay: t26,
    }
}

/// Rate in °/s from the Coriolis coefficient: `γ·ω0·180/π` (`omega0_rad_s` = drive
/// natural frequency ω0 in rad/s, e.g. [`OMEGA0_TABLE2_RAD_S`]).
///
/// ```
/// use paragyro_core::physics::{rate_dps_from_gamma, OMEGA0_TABLE2_RAD_S};
/// let r = rate_dps_from_gamma(3.8581e-5, OMEGA0_TABLE2_RAD_S);
/// assert!((r - 150.0).abs() < 1e-3);
/// ```
pub fn rate_dps_from_gamma(gamma: f64, omega0_rad_s: f64) -> f64 {
    gamma * omega0_rad_s * (180.0 / PI)
}

/// Coriolis coefficient from a rate in °/s: `rate·(π/180)/ω0`, the inverse of
/// [`rate_dps_from_gamma`]. Returns ±∞/NaN for `omega0_rad_s = 0` (caller validates ω0).
pub fn gamma_from_rate_dps(rate_dps: f64, omega0_rad_s: f64) -> f64 {
    rate_dps * (PI / 180.0) / omega0_rad_s
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    struct Rng(u64);
    impl Rng {
        /// Uniform in [−1, 1) (xorshift64*).
        fn uni(&mut self) -> f64 {
            let mut x = self.0;
            x ^= x >> 12;
            x ^= x << 25;
            x ^= x >> 27;
            self.0 = x;
            (x.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        }
    }

    /// Largest per-component relative difference.
    fn max_rel(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).fold(0.0, |m: f64, (x, y)| {
            let scale = x.abs().max(y.abs());
            if scale == 0.0 {
                m
            } else {
                m.max((x - y).abs() / scale)
            }
        })
    }

    /// Round-trip error of each θ component relative to the largest θ entry its
    /// Table-3 path combines (e.g. θ14 is rebuilt from (θ14 ± θ24)/2, so its error
    /// scale is max(|θ14|, |θ24|)); plain per-component relative error otherwise.
    fn operand_rel(t1: &[f64; 8], t2: &[f64; 6], u1: &[f64; 8], u2: &[f64; 6]) -> f64 {
        let m = |a: f64, b: f64| a.abs().max(b.abs());
        let s1 = [
            t1[0].abs(),
            m(t1[1], t1[5]),
            m(t1[2], t2[2]),
            m(t1[3], t2[3]),
            m(t1[4], t1[6]),
            t1[5].abs(),
            t1[6].abs(),
            t1[7].abs(),
        ];
        let s2 = [
            t2[0].abs(),
            t2[1].abs(),
            m(t1[2], t2[2]),
            m(t1[3], t2[3]),
            t2[4].abs(),
            t2[5].abs(),
        ];
        let mut worst: f64 = 0.0;
        for k in 0..8 {
            worst = worst.max((t1[k] - u1[k]).abs() / s1[k]);
        }
        for k in 0..6 {
            worst = worst.max((t2[k] - u2[k]).abs() / s2[k]);
        }
        worst
    }

    fn perturbed(rng: &mut Rng) -> Physical {
        let mut a = TABLE2.as_array();
        for v in a.iter_mut() {
            *v *= 1.0 + 0.5 * rng.uni();
        }
        a[11] = 1e-4 * rng.uni(); // γ' (0 in Table 2)
        let mut p = Physical::from_array(a);
        p.c_ax = 1.0 + 0.1 * rng.uni();
        p.c_ay = 1.0 + 0.1 * rng.uni();
        p
    }

    #[test]
    fn theta_round_trip_is_exact_to_rounding() {
        // Table 2: every component to 1e-15 relative.
        let (t1, t2) = theta_from_physical(&TABLE2);
        let (u1, u2) = theta_from_physical(&physical_from_theta(&t1, &t2));
        let table2_rel = max_rel(&t1, &u1).max(max_rel(&t2, &u2));
        std::println!("Table 2 θ→phys→θ per-component rel {table2_rel:.2e}");
        assert!(table2_rel <= 1e-15, "Table 2 round trip {table2_rel:e}");

        // Random perturbations (±50 % on every parameter, γ' ±1e-4, gains ±10 %).
        let mut rng = Rng(0x1234_5678_9abc_def1);
        let (mut worst_theta, mut worst_plain, mut worst_phys) = (0.0f64, 0.0f64, 0.0f64);
        for _ in 0..10_000 {
            let p = perturbed(&mut rng);
            let (t1, t2) = theta_from_physical(&p);
            let q = physical_from_theta(&t1, &t2);
            let (u1, u2) = theta_from_physical(&q);
            worst_theta = worst_theta.max(operand_rel(&t1, &t2, &u1, &u2));
            worst_plain = worst_plain.max(max_rel(&t1, &u1)).max(max_rel(&t2, &u2));
            // physical → θ → physical; γ' is absolute (true value may be 0)
            let (pa, qa) = (p.as_array(), q.as_array());
            worst_phys = worst_phys.max(max_rel(&pa[..11], &qa[..11]));
            assert!(
                (pa[11] - qa[11]).abs() < 1e-18,
                "γ' {} vs {}",
                pa[11],
                qa[11]
            );
            assert_eq!((q.c_ax, q.c_ay), (p.c_ax, p.c_ay));
        }
        std::println!(
            "random: θ→phys→θ {worst_theta:.2e} (operand-relative), {worst_plain:.2e} \
             (per-component, θ14 = −(μxy−2γ) can cancel); phys→θ→phys {worst_phys:.2e}"
        );
        assert!(worst_theta <= 1e-15, "θ round trip {worst_theta:e}");
        assert!(worst_phys <= 1e-15, "physical round trip {worst_phys:e}");
    }

    #[test]
    fn eq25_printed_values_reproduced() {
        let (t1, t2) = theta_from_physical(&TABLE2);
        // (printed value, half a unit of its last printed digit)
        let th1_printed = [
            (-0.001, 5e-7),
            (-1.0452, 5e-5),
            (-0.002, 5e-7),
            (-0.000023, 5e-7),
            (-0.00243, 5e-6),
            (-0.0452, 5e-5),
            (-1.266e-4, 5e-8),
            (1.0, 0.0),
        ];
        // 4th: printed −0.0000177 is a typo for −0.000177 (erratum 2);
        // 5th: printed −0.001537 ≠ −αy, Table 2's αy is used (erratum 3).
        let th2_printed = [
            (-0.001, 5e-7),
            (-1.0265, 5e-5),
            (-0.002, 5e-7),
            (-0.000177, 5e-7),
            (-0.001264, 0.0),
            (1.0, 0.0),
        ];
        for (i, (v, (pr, tol))) in t1.iter().zip(th1_printed).enumerate() {
            assert!((v - pr).abs() <= tol, "θ1{} = {v} vs printed {pr}", i + 1);
        }
        for (i, (v, (pr, tol))) in t2.iter().zip(th2_printed).enumerate() {
            assert!((v - pr).abs() <= tol, "θ2{} = {v} vs printed {pr}", i + 1);
        }
        // the errata really are errata: the paper's printed θ24, θ25 do not follow from Table 2
        assert!((t2[3] - -0.0000177).abs() > 1e-4);
        assert!((t2[4] - -0.001537).abs() > 2e-4);
    }

    #[test]
    fn paper_table3_as_printed_is_wrong_in_this_order() {
        // Table 3 as printed, applied to eq. (25)-ordered θ with γ' ≠ 0, must NOT recover
        // γ' and αx; the corrected formulas must.
        let mut p = TABLE2;
        p.gamma_p = 3e-5;
        let (t1, t2) = theta_from_physical(&p);
        let q = physical_from_theta(&t1, &t2);
        assert!((q.gamma_p - p.gamma_p).abs() < 1e-18);
        assert!((q.alpha_x - p.alpha_x).abs() < 1e-18);
        // printed γ' = −(θ14−θ24)/2 in the paper's eq.(8) order = −(θ13−θ23)/2 here
        let gp_printed = -(t1[2] - t2[2]) / 2.0;
        assert!((gp_printed - p.gamma_p).abs() > 1e-5);
        // printed αx = −θ15 + θ16
        let ax_printed = -t1[4] + t1[5];
        assert!((ax_printed - p.alpha_x).abs() > 1e-2);
    }

    #[test]
    fn rate_150_dps_is_table2_gamma() {
        assert_eq!(OMEGA0_TABLE2_RAD_S, 2.618 / 3.8581e-5);
        // the constants are the runtime expressions, bit for bit
        let (w0, two_pi) = (std::hint::black_box(OMEGA0_TABLE2_RAD_S), 2.0 * PI);
        assert_eq!(F0_TABLE2_HZ.to_bits(), (w0 / two_pi).to_bits());
        assert_eq!(L0_TABLE2_M, L0_TABLE2_UM * 1e-6);
        let r = rate_dps_from_gamma(3.8581e-5, OMEGA0_TABLE2_RAD_S);
        // 2.618 rad/s = 150.0002 °/s (2.618 is 150 °/s to the 4 printed digits)
        assert!((r - 2.618 * 180.0 / PI).abs() < 1e-12, "{r}");
        assert!((r - 150.0).abs() < 1e-3, "{r}");
        let g = gamma_from_rate_dps(150.0, OMEGA0_TABLE2_RAD_S);
        assert!((g - 3.8581e-5).abs() / 3.8581e-5 < 1e-5, "{g}");
        let back = gamma_from_rate_dps(rate_dps_from_gamma(1.234e-5, 6.0e4), 6.0e4);
        assert!((back - 1.234e-5).abs() < 1e-20);
        assert_eq!(rate_dps_from_gamma(-3.8581e-5, OMEGA0_TABLE2_RAD_S), -r);
    }

    #[test]
    fn array_order_and_names() {
        let a = TABLE2.as_array();
        assert_eq!(a[0], TABLE2.mu_x);
        assert_eq!(a[3], 1.0);
        assert_eq!(a[4], 1.0265);
        assert_eq!(a[10], 3.8581e-5);
        assert_eq!(Physical::from_array(a), TABLE2);
        assert_eq!(Physical::TABLE2, TABLE2);
        assert_eq!(PHYSICAL_NAMES[4], "wy2");
        assert_eq!(PHYSICAL_NAMES[10], "gamma");
        assert_eq!(PHYSICAL_NAMES[11], "gamma_p");
    }
}
