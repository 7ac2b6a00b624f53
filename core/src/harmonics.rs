//! Fourier projections of the nonlinear terms (DERIVATION §3).
//!
//! The lock-in delivers `X = X0 + Σ_k Re(A_k e^{ikψ})` (k = 1..3). The regression
//! needs the harmonic content of `X³`, `X·cos2ψ`, `X³·cos2ψ` and `Y³` at k = 0, 1, 3.
//! The DC + fundamental closed forms alone are off by 2.5e-3 in `[X³]₁`, which biases
//! θ17 by −9…−20 % (FINDINGS §2), so the truncated series with the 2nd and 3rd
//! harmonics is synthesised on N = 16 points per period, cubed and projected. That is
//! exact: on N points `[f]_k` also collects the harmonics m ≡ k (mod N), and a cube of a
//! 3rd-order series reaches harmonic 9, a further `cos2ψ` harmonic 11, so for k = 0, 1, 3
//! the nearest intruders (m = ±16, 17 and −15, 19 and −13) are absent; 16 = the smallest
//! power of two above 11 + 3. (32 points until the firmware's tick budget needed the
//! 600 instructions; the results are the same to rounding, unit test
//! `synthesis_matches_fine_quadrature`.)
//!
//! `[f]₀ = ⟨f⟩`, `[f]_k = 2⟨f e^{−ikψ}⟩`. The linear `X·cos2ψ` is written in closed
//! form (exact for the truncated series): `[Xc]₀ = Re A₂/2`, `[Xc]₁ = (A₁* + A₃)/2`,
//! `[Xc]₃ = A₁/2` (A₅ is not measured).

use crate::complex::Cplx;
use crate::real::Real;

/// Synthesis points per period.
pub const NSYN: usize = 16;

/// Precomputed trigonometric tables for the synthesis (built by [`SynthTables::new`];
/// `Default` is all zero, the placeholder of a design not built yet).
#[derive(Clone, Copy, Debug, Default)]
pub struct SynthTables<T> {
    c1: [T; NSYN],
    s1: [T; NSYN],
    c2: [T; NSYN],
    s2: [T; NSYN],
    c3: [T; NSYN],
    s3: [T; NSYN],
}

impl<T: Real> SynthTables<T> {
    /// Builds the tables (design time).
    #[inline(never)] // set-up only: its own frame, not inlined into App::new (flash, stack)
    pub fn new() -> Self {
        let mut t = SynthTables {
            c1: [T::ZERO; NSYN],
            s1: [T::ZERO; NSYN],
            c2: [T::ZERO; NSYN],
            s2: [T::ZERO; NSYN],
            c3: [T::ZERO; NSYN],
            s3: [T::ZERO; NSYN],
        };
        for j in 0..NSYN {
            let ph = 2.0 * core::f64::consts::PI * j as f64 / NSYN as f64;
            (t.c1[j], t.s1[j]) = T::design_cos_sin(ph);
            (t.c2[j], t.s2[j]) = T::design_cos_sin(2.0 * ph);
            (t.c3[j], t.s3[j]) = T::design_cos_sin(3.0 * ph);
        }
        t
    }
}

/// Harmonic content (k = 0, 1, 3) of one nonlinear term.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Proj<T> {
    /// `[f]₀` (real).
    pub h0: T,
    /// `[f]₁`.
    pub h1: Cplx<T>,
    /// `[f]₃`.
    pub h3: Cplx<T>,
}

/// The projections of one axis.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AxisProj<T> {
    /// `[X³]` (or `[Y³]`).
    pub cube: Proj<T>,
    /// `[X³ cos2ψ]` (drive only; zero for the sense axis).
    pub cube_cos: Proj<T>,
    /// `[X cos2ψ]` (closed form; drive only).
    pub lin_cos: Proj<T>,
}

/// Projections of `X³`, `X³cos2ψ` (when `with_pump`) and `X cos2ψ` for the series
/// `X0 + Σ Re(A_k e^{ikψ})`.
#[inline(never)]
pub fn project<T: Real>(
    tb: &SynthTables<T>,
    x0: T,
    a: &[Cplx<T>; 3],
    with_pump: bool,
) -> AxisProj<T> {
    let [a1, a2, a3] = *a;
    let mut cube = [T::ZERO; 5]; // h0, h1 re, h1 im, h3 re, h3 im (sums)
    let mut cc = [T::ZERO; 5];
    // half-period symmetry: at ψ_j + π the odd harmonics change sign, the even ones do
    // not, so x = E ± O at the pair (j, j + N/2); the even sums (k = 0) take x₊³ + x₋³,
    // the odd ones (k = 1, 3) x₊³ − x₋³ — half the points to synthesise and project
    for j in 0..NSYN / 2 {
        let (c1, s1, c2, s2, c3, s3) = (tb.c1[j], tb.s1[j], tb.c2[j], tb.s2[j], tb.c3[j], tb.s3[j]);
        let even = x0 + (a2.re * c2 - a2.im * s2);
        let odd = (a1.re * c1 - a1.im * s1) + (a3.re * c3 - a3.im * s3);
        let (xp, xm) = (even + odd, even - odd);
        let (p3, m3) = (xp * xp * xp, xm * xm * xm);
        let (sum, dif) = (p3 + m3, p3 - m3);
        cube[0] += sum;
        cube[1] += dif * c1;
        cube[2] -= dif * s1;
        cube[3] += dif * c3;
        cube[4] -= dif * s3;
        if with_pump {
            let (fs, fd) = (sum * c2, dif * c2);
            cc[0] += fs;
            cc[1] += fd * c1;
            cc[2] -= fd * s1;
            cc[3] += fd * c3;
            cc[4] -= fd * s3;
        }
    }
    let inv = T::from_f64(1.0 / NSYN as f64);
    let inv2 = T::from_f64(2.0 / NSYN as f64);
    let mk = |s: &[T; 5]| Proj {
        h0: s[0] * inv,
        h1: Cplx::new(s[1] * inv2, s[2] * inv2),
        h3: Cplx::new(s[3] * inv2, s[4] * inv2),
    };
    let half = T::from_f64(0.5);
    let lin_cos = if with_pump {
        Proj {
            h0: a2.re * half,
            h1: (a1.conj() + a3).scale(half),
            h3: a1.scale(half),
        }
    } else {
        Proj::default()
    };
    AxisProj {
        cube: mk(&cube),
        cube_cos: mk(&cc),
        lin_cos,
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn c(re: f64, im: f64) -> Cplx<f64> {
        Cplx::new(re, im)
    }

    /// DC + fundamental only: the closed forms of DERIVATION §3 hold exactly.
    #[test]
    fn closed_forms_dc_plus_fundamental() {
        let tb = SynthTables::<f64>::new();
        let x0 = 0.02;
        let a = c(1.2, -1.27);
        let p = project(&tb, x0, &[a, Cplx::ZERO, Cplx::ZERO], true);
        let aa = a.norm_sqr();
        let close = |u: Cplx<f64>, v: Cplx<f64>| (u - v).abs() < 1e-13;
        assert!((p.cube.h0 - (x0 * x0 * x0 + 1.5 * x0 * aa)).abs() < 1e-13);
        assert!(close(p.cube.h1, a.scale(0.75 * aa + 3.0 * x0 * x0)));
        assert!(close(p.cube.h3, a * a * a * c(0.25, 0.0)));
        assert!((p.cube_cos.h0 - 0.75 * x0 * (a * a).re).abs() < 1e-13);
        let h1 = a.conj().scale(0.375 * aa + 1.5 * x0 * x0) + (a * a * a).scale(0.125);
        assert!(close(p.cube_cos.h1, h1));
        assert!(close(p.cube_cos.h3, a.scale(0.375 * aa + 1.5 * x0 * x0)));
        assert!(close(p.lin_cos.h1, a.conj().scale(0.5)));
        assert!(close(p.lin_cos.h3, a.scale(0.5)));
    }

    /// With A2, A3: compare against a brute-force projection on a fine grid (the
    /// estimator's sizes, and harmonics as large as the fundamental: the case where an
    /// alias of the 9th or 11th harmonic onto k ≤ 3 would show).
    #[test]
    fn synthesis_matches_fine_quadrature() {
        let x0 = -0.03;
        check_against_quadrature(x0, [c(1.1, 0.9), c(0.02, -0.01), c(-0.003, 0.004)]);
        check_against_quadrature(x0, [c(1.1, 0.9), c(-0.7, 0.5), c(0.8, -0.6)]);
    }

    fn check_against_quadrature(x0: f64, a: [Cplx<f64>; 3]) {
        let tb = SynthTables::<f64>::new();
        let p = project(&tb, x0, &a, true);
        let n = 4096;
        let (mut h1, mut h3, mut h0) = (c(0.0, 0.0), c(0.0, 0.0), 0.0);
        let (mut g1, mut g3, mut g0) = (c(0.0, 0.0), c(0.0, 0.0), 0.0);
        for j in 0..n {
            let ph = 2.0 * core::f64::consts::PI * j as f64 / n as f64;
            let mut x = x0;
            for (k, ak) in a.iter().enumerate() {
                let kk = (k + 1) as f64;
                x += ak.re * (kk * ph).cos() - ak.im * (kk * ph).sin();
            }
            let x3 = x * x * x;
            h0 += x3 / n as f64;
            h1 += c(ph.cos(), -ph.sin()).scale(2.0 * x3 / n as f64);
            h3 += c((3.0 * ph).cos(), -(3.0 * ph).sin()).scale(2.0 * x3 / n as f64);
            let f = x3 * (2.0 * ph).cos();
            g0 += f / n as f64;
            g1 += c(ph.cos(), -ph.sin()).scale(2.0 * f / n as f64);
            g3 += c((3.0 * ph).cos(), -(3.0 * ph).sin()).scale(2.0 * f / n as f64);
        }
        assert!((p.cube.h0 - h0).abs() < 1e-13);
        assert!((p.cube.h1 - h1).abs() < 1e-13);
        assert!((p.cube.h3 - h3).abs() < 1e-13);
        assert!((p.cube_cos.h0 - g0).abs() < 1e-13);
        assert!((p.cube_cos.h1 - g1).abs() < 1e-13);
        assert!((p.cube_cos.h3 - g3).abs() < 1e-13);
        // closed-form X cos2ψ vs quadrature of the truncated series
        let mut l1 = c(0.0, 0.0);
        for j in 0..n {
            let ph = 2.0 * core::f64::consts::PI * j as f64 / n as f64;
            let mut x = x0;
            for (k, ak) in a.iter().enumerate() {
                let kk = (k + 1) as f64;
                x += ak.re * (kk * ph).cos() - ak.im * (kk * ph).sin();
            }
            l1 += c(ph.cos(), -ph.sin()).scale(2.0 * x * (2.0 * ph).cos() / n as f64);
        }
        assert!((p.lin_cos.h1 - l1).abs() < 1e-13);
    }
}
