//! RK4's dispersion, pre-warped away.
//!
//! Classic RK4 advances an oscillation `e^{λτ}` by `R(hλ) = 1 + z + z²/2 + z³/6 + z⁴/24`
//! per step instead of `e^{z}`: at `z = iωh` it is slow by `(ωh)⁴/120` in frequency and
//! loses `(ωh)⁶/144` of amplitude per step. At 128 steps per carrier period that is an
//! ω² low by 8e-8, which the diagnosis's calibration absorbs as a stiffness shift (and
//! reports as the device's); at 64 steps it is 16× more.
//!
//! [`prewarp`] moves eq. (6)'s coefficients so that RK4 at step `h` advances an
//! oscillation at the reference frequency ω (both modes ring at ω = ψ′, half the pump)
//! as the exact flow would, or as RK4 at another step `h_target` would (a simulated
//! record's own grid, whose dispersion then cancels). It is a time scale of the
//! oscillator: with `hλ̃` the root of `R(hλ̃) = e^{hλ_target}` nearest `iωh`,
//! `1 + ε = Im(hλ̃)/(ωh)` and `r = Re(hλ̃)/h`, every position term of both equations
//! (stiffness, coupling, cubic, pump, acceleration: θ·2, θ·3, θ·5…) is scaled by
//! `(1 + ε)²`, every velocity term (damping, Coriolis: θ·1, θ·4) by `1 + ε`, and the
//! damping θ11, θ21 gets `+2r`, RK4's amplitude loss given back. An oscillation at ω
//! (the pumped drive and the Coriolis-driven sense in their steady state) then advances
//! as the target's to below 1e-2 of RK4's own error with a device's damping (its decay
//! rate within 3e-6 of itself at 64 steps; 1e-8 of the error undamped; tests); a
//! mode ringing freely at its own ωn keeps `4·|ωn/ω − 1|` of its frequency error and
//! `6·|ωn/ω − 1|` of its decay's (5 % and 9 % at 1.3 % off: the errors' ω⁴ and ω⁶).

use super::Theta;
use paragyro_core::Cplx;

type C = Cplx<f64>;

/// A real number as a complex one.
fn re(v: f64) -> C {
    C::new(v, 0.0)
}

/// RK4's growth factor `R(z)` and its derivative `R′(z)` (Horner).
fn rk4_factor(z: C) -> (C, C) {
    // R′(z) = 1 + z(1 + z(1/2 + z/6))
    let d = re(1.0) + z * (re(1.0) + z * (re(0.5) + z * re(1.0 / 6.0)));
    // R(z) = 1 + z(1 + z(1/2 + z(1/6 + z/24)))
    let r = re(1.0) + z * (re(1.0) + z * (re(0.5) + z * (re(1.0 / 6.0) + z * re(1.0 / 24.0))));
    (r, d)
}

/// The per-step factor RK4 at step `h` would need to advance `e^{iωτ}` as the target
/// does: the exact `e^{iωh}` (`h_target = 0`), or RK4's own at `h_target`, continued to
/// the step `h` (`e^{(h/h_target)·log R(iωh_target)}`).
fn target_factor(omega: f64, h: f64, h_target: f64) -> C {
    let (ln_abs, arg) = if h_target > 0.0 {
        let (r, _) = rk4_factor(C::new(0.0, omega * h_target));
        let k = h / h_target;
        (k * 0.5 * r.norm_sqr().ln(), k * r.im.atan2(r.re))
    } else {
        (0.0, omega * h)
    };
    C::new(arg.cos(), arg.sin()).scale(ln_abs.exp())
}

/// The time scale `1 + ε` and the amplitude rate `r` (per τ) that make RK4 at step `h`
/// advance an oscillation at ω as the target does (the exact flow, or RK4 at `h_target`).
pub fn prewarp_factors(omega: f64, h: f64, h_target: f64) -> (f64, f64) {
    let t = target_factor(omega, h, h_target);
    let mut z = C::new(0.0, omega * h);
    for _ in 0..4 {
        // Newton on R(z) = t: z −= (R − t)/R′
        let (r, d) = rk4_factor(z);
        z = z - ((r - t) * d.conj()).scale(1.0 / d.norm_sqr());
    }
    (z.im / (omega * h), z.re / h)
}

/// `th` pre-warped for RK4 at step `h` (τ) at the reference frequency `omega` (ψ′, units
/// of ω0) towards the target step `h_target` (0: the exact flow; the module's text).
/// Returns `th` unchanged when the steps are equal or an input is not finite and positive.
pub fn prewarp(th: &Theta, omega: f64, h: f64, h_target: f64) -> Theta {
    let ok = |v: f64| v.is_finite() && v > 0.0;
    if h == h_target || !ok(omega) || !ok(h) || !(h_target == 0.0 || ok(h_target)) {
        return *th;
    }
    let (a, r) = prewarp_factors(omega, h, h_target);
    if !(a.is_finite() && r.is_finite()) {
        return *th;
    }
    let a2 = a * a;
    let mut out = *th;
    for (i, v) in out.drive.iter_mut().enumerate() {
        *v *= if i == 0 || i == 3 { a } else { a2 };
    }
    for (i, v) in out.sense.iter_mut().enumerate() {
        *v *= if i == 0 || i == 3 { a } else { a2 };
    }
    out.drive[0] += 2.0 * r;
    out.sense[0] += 2.0 * r;
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// RK4 on a damped harmonic oscillator `x″ = −μx′ − ω²x`, `n` steps of `h`:
    /// the oscillation's frequency and decay rate fitted from the complex eigenvalue of
    /// the step map (its 2×2 matrix applied to the unit vectors).
    fn rk4_eig(mu: f64, w2: f64, h: f64) -> (f64, f64) {
        let f = |z: [f64; 2]| [z[1], -mu * z[1] - w2 * z[0]];
        let step = |z: [f64; 2]| {
            let k1 = f(z);
            let k2 = f([z[0] + 0.5 * h * k1[0], z[1] + 0.5 * h * k1[1]]);
            let k3 = f([z[0] + 0.5 * h * k2[0], z[1] + 0.5 * h * k2[1]]);
            let k4 = f([z[0] + h * k3[0], z[1] + h * k3[1]]);
            [
                z[0] + h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
                z[1] + h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
            ]
        };
        let (c0, c1) = (step([1.0, 0.0]), step([0.0, 1.0]));
        // eigenvalues of [[c0[0], c1[0]], [c0[1], c1[1]]]
        let tr = c0[0] + c1[1];
        let det = c0[0] * c1[1] - c1[0] * c0[1];
        let im = (det - 0.25 * tr * tr).sqrt();
        let (re, im) = (0.5 * tr, im);
        ((im.atan2(re)) / h, -0.5 * (re * re + im * im).ln() / h)
    }

    /// The continuous oscillator's frequency and decay rate.
    fn exact(mu: f64, w2: f64) -> (f64, f64) {
        ((w2 - 0.25 * mu * mu).sqrt(), 0.5 * mu)
    }

    fn oscillator(th: &Theta) -> (f64, f64) {
        (-th.drive[0], -th.drive[1])
    }

    fn theta(mu: f64, w2: f64) -> Theta {
        let mut th = Theta::table2();
        th.drive[0] = -mu;
        th.drive[1] = -w2;
        th
    }

    #[test]
    fn raw_rk4_is_slow_by_its_known_dispersion() {
        let h = TAU / 64.0;
        let (w, _) = rk4_eig(0.0, 1.0, h);
        let expect = 1.0 - h.powi(4) / 120.0;
        assert!(
            (w - expect).abs() < 1e-2 * h.powi(4) / 120.0,
            "{w} {expect}"
        );
    }

    /// At 64 steps per period the pre-warped step is the exact flow's to far below the
    /// raw error (6.7e-7 in frequency), with the damping of a device; a mode 1.3 % off
    /// the reference frequency keeps about 4 × 1.3 % of it (6 × 1.3 % of the decay's).
    #[test]
    fn prewarped_rk4_matches_the_exact_flow() {
        let omega = 1.0132;
        let h = TAU / (64.0 * 1.05);
        // (μ, ω², the share of RK4's frequency and decay errors that may be left)
        for (mu, w2, kw, kd) in [
            (0.0, omega * omega, 3e-3, 3e-3),
            (2e-4, omega * omega, 1e-2, 1e-2),
            (2e-4, 0.9994, 0.07, 0.1),
        ] {
            let th = prewarp(&theta(mu, w2), omega, h, 0.0);
            let (mu_p, w2_p) = oscillator(&th);
            let (w, d) = rk4_eig(mu_p, w2_p, h);
            let (we, de) = exact(mu, w2);
            let (w_raw, d_raw) = rk4_eig(mu, w2, h);
            println!(
                "μ {mu:e} ω² {w2}: raw {:.2e} / {:.2e}, pre-warped {:.2e} / {:.2e}",
                w_raw / we - 1.0,
                d_raw - de,
                w / we - 1.0,
                d - de
            );
            assert!((w_raw / we - 1.0).abs() > 5e-7);
            assert!((w / we - 1.0).abs() < kw * (w_raw / we - 1.0).abs());
            assert!((d - de).abs() < kd * (d_raw - de).abs());
        }
    }

    /// Towards another RK4 grid (a simulated record's 128 steps) the 64-step pre-warped
    /// oscillation has that grid's frequency and decay.
    #[test]
    fn prewarped_rk4_matches_another_grid() {
        let omega = 1.0132;
        let h0 = TAU / (128.0 * 1.03);
        let h = TAU / (64.0 * 1.05);
        let (mu, w2) = (1e-4, 1.0265);
        let (w0, d0) = rk4_eig(mu, w2, h0);
        let th = prewarp(&theta(mu, w2), omega, h, h0);
        let (mu_p, w2_p) = oscillator(&th);
        let (w, d) = rk4_eig(mu_p, w2_p, h);
        let (w_raw, d_raw) = rk4_eig(mu, w2, h);
        assert!(
            (w / w0 - 1.0).abs() < 3e-3 * (w_raw / w0 - 1.0).abs(),
            "{w} {w0}"
        );
        assert!((d - d0).abs() < 3e-3 * (d_raw - d0).abs(), "{d} {d0}");
    }

    #[test]
    fn equal_steps_and_bad_inputs_leave_theta_unchanged() {
        let th = Theta::table2();
        assert_eq!(prewarp(&th, 1.0, 0.1, 0.1), th);
        assert_eq!(prewarp(&th, f64::NAN, 0.1, 0.0), th);
        assert_eq!(prewarp(&th, 1.0, 0.0, 0.0), th);
        assert_eq!(prewarp(&th, 1.0, 0.1, -1.0), th);
    }
}
