//! The slow-time state-variable filter bank (DERIVATION §4).
//!
//! Every signal `u` of a regression row is replaced by `(1/Λ)u`, `(D/Λ)u`, `(D²/Λ)u`
//! with `Λ(D) = (D + w)²` (ζ = 1, w = 2π·10 Hz in τ units), and the rows are scaled by
//! `w²` so that `1/Λ` has unit DC gain. The paper's `Λ = D² + 3D + 2` has its poles at
//! the carrier and is meaningless for 500 Hz envelope data.
//!
//! **Realisation.** With a double real pole the filter is a cascade of two identical
//! first-order low-passes `p1 = w/(D+w)·u`, `p2 = w/(D+w)·p1`, and
//!
//! ```text
//!   F0 = w²(1/Λ)u  = p2
//!   F1 = w²(D/Λ)u  = w (p1 − p2)
//!   F2 = w²(D²/Λ)u = w² (u − 2 p1 + p2)
//! ```
//!
//! Both states stay of the size of the input, and the two outputs that are differences
//! come multiplied by `w ≈ 9e-4` or `w² ≈ 9e-7`, so their rounding errors in `f32` are
//! ~1e-10 of the row: far below the 1e-7 the drive rows need. (The usual `(y, y')`
//! realisation carries a state of size `u/w²` and loses that precision in `f32`.) Only
//! `F0` of a large signal is sensitive, which is why the estimator filters the *nominal
//! combination* of the large terms (small by construction) rather than each term alone.
//!
//! **Discretisation.** FOH-exact at the sample period `T` (input linear between samples):
//!
//! ```text
//!   a = e^{−wT}, h = wT
//!   p1[k+1] = a p1 + (1−a) u[k] + g1 (u[k+1] − u[k]),          g1 = 1 − (1−a)/h
//!   p2[k+1] = a p2 + h a p1 + (1−a−ha) u[k] + g2 (u[k+1] − u[k]), g2 = (h − 2 + a(2+h))/h
//! ```

use crate::complex::Cplx;
use crate::real::Real;

/// FOH-exact coefficients of the ζ = 1 state-variable filter (`Default`: all zero, the
/// placeholder of a design not built yet, whose outputs are zero).
#[derive(Clone, Copy, Debug, Default)]
pub struct SvfCoeffs<T> {
    a: T,
    one_minus_a: T,
    ha: T,
    c2: T,
    g1: T,
    g2: T,
    /// Filter corner `w` (rad per τ).
    pub w: T,
    /// `w²`.
    pub w2: T,
}

impl<T: Real> SvfCoeffs<T> {
    /// Coefficients for corner `w` (rad per time unit) sampled every `ts` time units.
    #[inline(never)] // set-up only: its own frame, not inlined into App::new (flash, stack)
    pub fn new(w: f64, ts: f64) -> Self {
        let h = w * ts;
        let a = T::design_exp_f64(-h);
        let g1 = 1.0 - (1.0 - a) / h;
        let g2 = (h - 2.0 + a * (2.0 + h)) / h;
        SvfCoeffs {
            a: T::from_f64(a),
            one_minus_a: T::from_f64(1.0 - a),
            ha: T::from_f64(h * a),
            c2: T::from_f64(1.0 - a - h * a),
            g1: T::from_f64(g1),
            g2: T::from_f64(g2),
            w: T::from_f64(w),
            w2: T::from_f64(w * w),
        }
    }
}

/// The FOH discretisation's bias on a curved input, per unit `u″`: `[ε0, ε1, ε2]` such
/// that a slowly curving input's discrete outputs are the continuous filter's plus
/// `ε_j u″(t)`, less the part every input shares.
///
/// FOH-exact means exact for an input linear between samples. A smooth input differs
/// from its chords by a scallop (`u″(t−t_k)(t_{k+1}−t)/2`): its mean, `u″T²/12`, reaches
/// `F0` as it reaches any filter of any input, so it cancels in every constant-coefficient
/// relation between filtered signals (a row) and is left out of `ε0`; its ripple at the
/// sample rate does not cancel: a filter passes it with a gain that depends on its own
/// corner and output, and sampled at the sample instants it leaves `ε_j u″`. `ε2 ≈
/// −(wT)²/12` for small `wT` (−0.13 % of `F2` at the slow bank's 10 Hz); at the fast rate
/// channel's 150 Hz (`wT` = 1.88) it is ≈ −25 %, and ε1 moves `F1` by a comparable share
/// of `u″/w`. On the pump dither's 5 Hz modulation of the envelopes this was the fast
/// channel's ≈ 0.65 °/s tone (`crate::rate`, which removes the bias).
///
/// Design time, `f64`: the discrete filter run on samples of `t²/2` from `t = −KT` to `0`
/// (the start-up transient decays as `e^{−wKT}`, `wKT` ≥ 80) and compared there with the
/// exact outputs `3/w²`, `−2/w` and `1` (and the shared `T²/12` taken from `F0`'s).
#[inline(never)] // set-up only
pub fn parabola_bias<T: Real>(w: f64, ts: f64) -> [f64; 3] {
    let h = w * ts;
    if !(h > 0.0 && h.is_finite()) {
        return [0.0; 3];
    }
    // in `T`: the `f32` design links no `f64` filter (flash); the states shrink from
    // ~1e7 to ~1/w² over the run, so its rounding stays ~1e-3 of `ε0` and below (test)
    let c = SvfCoeffs::<T>::new(w, ts);
    let n = libm::round(80.0 / h + 0.5).clamp(8.0, 4000.0) as u32;
    // the samples t²/2 in `T` too (FPU operations on the chip: flash)
    let (tt, nn) = (T::from_f64(ts), T::ratio(u64::from(n), 1));
    let u = |k: u32| {
        let t = (T::ratio(u64::from(k), 1) - nn) * tt;
        T::from_f64(0.5) * t * t
    };
    let mut st = SvfState::at_rest(u(0));
    let mut out = st.outputs(&c);
    for k in 1..=n {
        out = st.update(&c, u(k));
    }
    let wt = T::from_f64(w);
    [
        (out.f0 - T::from_f64(3.0) / (wt * wt) - tt * tt / T::from_f64(12.0)).to_f64(),
        (out.f1 + T::from_f64(2.0) / wt).to_f64(),
        (out.f2 - T::ONE).to_f64(),
    ]
}

/// The fast rate channel's default wide filter, Hz, and sample rate, Hz: the design
/// [`BAND_TAPS`] holds for (`rate.svf_hz`, `fs_hz`).
pub const BAND_SVF_HZ: f64 = 150.0;
/// See [`BAND_SVF_HZ`].
pub const BAND_FS_HZ: f64 = 500.0;
/// `wT` of that design.
pub const BAND_WT: f64 = 2.0 * core::f64::consts::PI * BAND_SVF_HZ / BAND_FS_HZ;

/// [`band_taps`] at [`BAND_WT`], designed on the host and shipped (the design runs ≈ 10⁵
/// filter updates: not on the chip; test `the_shipped_band_taps_are_the_design`).
pub const BAND_TAPS: [f64; 2] = [2.1532246804870003, 7.862743680729376];

/// The band taps of `F0`, in units of the curvature correction's `e0`: `[a, b]` such that
/// `F0 − (1 + a)·e0·F2[k] − b·e0·(F2[k] − F2[k−1])` has, for a sampled sinusoid at Ω, the
/// same ratio to the continuous filter's output as `F1 − e1·F2` has to its own, in the least
/// squares over Ω from w/30 to 2w/3 (5–100 Hz at the default 150 Hz), `e0`, `e1` the
/// curvature correction of [`parabola_bias`] (`ε_j/(1+ε2)`).
///
/// Why: a row relation between filtered signals holds when every output's ratio to the
/// continuous filter is the same. FOH-exact, the ratios drift apart above a few % of the
/// sample rate (the interpolant's images pass `F1`'s band-pass more than `F0`'s low-pass),
/// and the curvature correction evens them only to second order: at 100 Hz at the default
/// `wT` `F1`'s ratio is 6 % from `F0`'s (`cargo run -p paragyro-core --example svf_band`).
/// The fast rate row balances `2iω·F1(B)` against the quadrature's `θ23·F0(A)`, so a drive
/// ringing at 60–150 Hz (every DDS word step kicks its ≈ 100 Hz envelope mode) was read as
/// a rate in proportion.
///
/// Design time, `f64`, `w = 1`: the discrete filter's steady state on a sampled `e^{iΩt}`
/// ([`sine_response`]).
pub fn band_taps(wt: f64) -> [f64; 2] {
    if !(wt > 0.0 && wt.is_finite()) {
        return [0.0; 2];
    }
    let (w, ts) = (1.0, wt);
    let eps = parabola_bias::<f64>(w, ts);
    let g = 1.0 / (1.0 + eps[2]);
    let (e0, e1) = (eps[0] * g, eps[1] * g);
    type C = (f64, f64);
    let mul = |a: C, b: C| (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0);
    let div = |a: C, b: C| {
        let d = b.0 * b.0 + b.1 * b.1;
        ((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
    };
    let (mut ata, mut atb) = ([[0.0f64; 2]; 2], [0.0f64; 2]);
    for q in 1..=20 {
        let om = w * f64::from(q) / 30.0;
        let x = om * ts;
        let d = sine_response(w, ts, x);
        let h0 = div((w * w, 0.0), mul((w, om), (w, om)));
        let h1 = mul(h0, (0.0, om));
        let r0 = div((d[0].0 - e0 * d[2].0, d[0].1 - e0 * d[2].1), h0);
        let r1 = div((d[1].0 - e1 * d[2].0, d[1].1 - e1 * d[2].1), h1);
        // −a·F2[k] and −b·(F2[k] − F2[k−1]) move F0's ratio by these
        let col_a = div((-d[2].0, -d[2].1), h0);
        let col_b = mul(col_a, (1.0 - libm::cos(x), libm::sin(x)));
        let t = (r1.0 - r0.0, r1.1 - r0.1);
        let cols = [col_a, col_b];
        for i in 0..2 {
            for j in 0..2 {
                ata[i][j] += cols[i].0 * cols[j].0 + cols[i].1 * cols[j].1;
            }
            atb[i] += cols[i].0 * t.0 + cols[i].1 * t.1;
        }
    }
    let det = ata[0][0] * ata[1][1] - ata[0][1] * ata[1][0];
    [
        (atb[0] * ata[1][1] - atb[1] * ata[0][1]) / det / e0,
        (ata[0][0] * atb[1] - ata[1][0] * atb[0]) / det / e0,
    ]
}

/// The FOH-exact filter's outputs `[F0, F1, F2]` (complex, as `(re, im)`) in the steady
/// state of the sampled `e^{iΩt}`, divided by the input: `x = ΩT` per sample, `w`, `ts` as in
/// [`SvfCoeffs::new`]. Design time, `f64` (the band taps, `examples/svf_band.rs`).
pub fn sine_response(w: f64, ts: f64, x: f64) -> [(f64, f64); 3] {
    let c = SvfCoeffs::<f64>::new(w, ts);
    let (mut re, mut im) = (SvfState::at_rest(1.0), SvfState::at_rest(0.0));
    // long enough for the start's transient, e^{−wT·k}, to vanish
    let n = libm::ceil(60.0 / (w * ts)) as u32 + 200;
    let mut d = [(0.0, 0.0); 3];
    for k in 1..=n {
        let (sn, cs) = libm::sincos(x * f64::from(k));
        let (r, i) = (re.update(&c, cs), im.update(&c, sn));
        if k == n {
            // divided by the last input, e^{i x n}
            let back = |a: f64, b: f64| (a * cs + b * sn, b * cs - a * sn);
            d = [back(r.f0, i.f0), back(r.f1, i.f1), back(r.f2, i.f2)];
        }
    }
    d
}

/// The three scaled outputs of one filtered signal.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Svf3<T> {
    /// `w²(1/Λ)u`
    pub f0: T,
    /// `w²(D/Λ)u`
    pub f1: T,
    /// `w²(D²/Λ)u`
    pub f2: T,
}

/// State of one real filtered signal.
#[derive(Clone, Copy, Debug, Default)]
pub struct SvfState<T> {
    p1: T,
    p2: T,
    u: T,
}

impl<T: Real> SvfState<T> {
    /// At rest at constant input `u` (no start-up transient in the filter itself).
    pub fn at_rest(u: T) -> Self {
        SvfState { p1: u, p2: u, u }
    }

    /// Advances one sample to the new input `u`; returns the outputs at the new time.
    #[inline]
    pub fn update(&mut self, c: &SvfCoeffs<T>, u: T) -> Svf3<T> {
        let du = u - self.u;
        let p1 = c.a * self.p1 + c.one_minus_a * self.u + c.g1 * du;
        let p2 = c.a * self.p2 + c.ha * self.p1 + c.c2 * self.u + c.g2 * du;
        self.p1 = p1;
        self.p2 = p2;
        self.u = u;
        self.outputs(c)
    }

    /// `self += alpha · other`: the filter is linear, so this is the state of the
    /// filtered combination of the two inputs (used to re-linearise the rows).
    pub fn axpy(&mut self, alpha: T, other: &SvfState<T>) {
        self.p1 += alpha * other.p1;
        self.p2 += alpha * other.p2;
        self.u += alpha * other.u;
    }

    /// Outputs at the current time.
    #[inline]
    pub fn outputs(&self, c: &SvfCoeffs<T>) -> Svf3<T> {
        Svf3 {
            f0: self.p2,
            f1: c.w * (self.p1 - self.p2),
            f2: c.w2 * ((self.u - self.p1) - (self.p1 - self.p2)),
        }
    }
}

/// The filter's first stage alone, `w/(s + w)` (FOH-exact, the same coefficients): a
/// one-pole low-pass at the corner.
#[derive(Clone, Copy, Debug, Default)]
pub struct PoleState<T> {
    y: Cplx<T>,
    u: Cplx<T>,
}

impl<T: Real> PoleState<T> {
    /// Advances one sample to the new (complex) input `u`; returns the output.
    #[inline]
    pub fn update(&mut self, c: &SvfCoeffs<T>, u: Cplx<T>) -> Cplx<T> {
        let du = u - self.u;
        self.y = self.y.scale(c.a) + self.u.scale(c.one_minus_a) + du.scale(c.g1);
        self.u = u;
        self.y
    }
}

/// Outputs of one filtered complex signal.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CSvf3<T> {
    /// `w²(1/Λ)u`
    pub f0: Cplx<T>,
    /// `w²(D/Λ)u`
    pub f1: Cplx<T>,
    /// `w²(D²/Λ)u`
    pub f2: Cplx<T>,
}

/// State of one complex filtered signal (two real filters).
#[derive(Clone, Copy, Debug, Default)]
pub struct CSvfState<T> {
    re: SvfState<T>,
    im: SvfState<T>,
}

impl<T: Real> CSvfState<T> {
    /// At rest at constant input `u`.
    pub fn at_rest(u: Cplx<T>) -> Self {
        CSvfState {
            re: SvfState::at_rest(u.re),
            im: SvfState::at_rest(u.im),
        }
    }
    /// `self += alpha · other` for a complex `alpha` (linearity of the filter).
    pub fn caxpy(&mut self, alpha: Cplx<T>, other: &CSvfState<T>) {
        // (ar + i ai)(or + i oi) = (ar or − ai oi) + i (ar oi + ai or)
        self.re.axpy(alpha.re, &other.re);
        self.re.axpy(-alpha.im, &other.im);
        self.im.axpy(alpha.re, &other.im);
        self.im.axpy(alpha.im, &other.re);
    }

    /// Advances one sample.
    #[inline]
    pub fn update(&mut self, c: &SvfCoeffs<T>, u: Cplx<T>) -> CSvf3<T> {
        let r = self.re.update(c, u.re);
        let i = self.im.update(c, u.im);
        CSvf3 {
            f0: Cplx::new(r.f0, i.f0),
            f1: Cplx::new(r.f1, i.f1),
            f2: Cplx::new(r.f2, i.f2),
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// A drifting coefficient (rows.rs, "A drifting coefficient"): the filtered product
    /// of θ(t) = θ0 + θ′t with an envelope moving at the pump dither's 5 Hz is the
    /// delayed coefficient's `F0` plus `(2θ′/w²)·L[F1]`, `L` the first stage
    /// ([`PoleState`]) to 0.2 % of that term; with `F1` alone (the first-order term
    /// without `L`) the error is half the term (the 10 Hz stage's gain of 0.89 and phase
    /// of −27° at 5 Hz).
    #[test]
    fn a_drifting_coefficient_is_the_delayed_one_plus_the_first_stage_of_its_f1_term() {
        let (fs, w) = (500.0, 2.0 * core::f64::consts::PI * 10.0);
        let c = SvfCoeffs::<f64>::new(w, 1.0 / fs);
        let (th0, th1) = (1.0, 0.5);
        let theta = |t: f64| th0 + th1 * t;
        let b = |t: f64| 1.0 + 0.4 * (2.0 * core::f64::consts::PI * 5.0 * t).cos();
        let (mut prod, mut env) = (
            SvfState::at_rest(theta(0.0) * b(0.0)),
            SvfState::at_rest(b(0.0)),
        );
        let mut l = PoleState::default();
        let (mut err_l, mut err_f1, mut term) = (0.0f64, 0.0f64, 0.0f64);
        for k in 1..(4.0 * fs) as usize {
            let t = k as f64 / fs;
            let y = prod.update(&c, Cplx::new(theta(t) * b(t), 0.0).re);
            let e = env.update(&c, b(t));
            let lf1 = l.update(&c, Cplx::new(e.f1, 0.0)).re;
            let g = 2.0 * th1 / (w * w);
            let delayed = theta(t - 2.0 / w) * e.f0;
            if t > 1.0 {
                err_l = err_l.max((y.f0 - delayed - g * lf1).abs());
                err_f1 = err_f1.max((y.f0 - delayed - g * e.f1).abs());
                term = term.max((g * lf1).abs());
            }
        }
        assert!(
            err_l < 0.02 * term,
            "with L: {err_l:e} against the term {term:e}"
        );
        assert!(
            err_f1 > 0.3 * term,
            "without L: {err_f1:e} against the term {term:e}"
        );
    }

    /// The shipped taps are the design at the default `wT` (to 1e-9 relative).
    #[test]
    fn the_shipped_band_taps_are_the_design() {
        let t = band_taps(BAND_WT);
        for j in 0..2 {
            assert!(
                (BAND_TAPS[j] - t[j]).abs() <= 1e-9 * t[j].abs(),
                "{BAND_TAPS:?} against {t:?}"
            );
        }
    }
    use std::vec::Vec;

    #[test]
    fn parabola_bias_small_wt_is_the_scallop_ripple() {
        // wT = 0.01: ε2 → −(wT)²/12, ε1 and ε0 of higher order in wT
        let (w, ts) = (0.01, 1.0);
        let [e0, e1, e2] = parabola_bias::<f64>(w, ts);
        let want = -(w * ts) * (w * ts) / 12.0;
        assert!((e2 - want).abs() < 0.02 * want.abs(), "ε2 {e2} vs {want}");
        assert!(e1.abs() * w < 10.0 * want.abs(), "ε1 {e1}");
        assert!(e0.abs() * w * w < 10.0 * want.abs(), "ε0 {e0}");
        // no corner, no bias; a bad corner is refused with zeros
        assert_eq!(parabola_bias::<f64>(0.0, 1.0), [0.0; 3]);
        assert_eq!(parabola_bias::<f64>(f64::NAN, 1.0), [0.0; 3]);
    }

    /// At the fast channel's wT = 1.885 the FOH outputs of a slow sine (5 Hz at 500 Hz)
    /// are off by ε_j u″: removing it brings F1 and F2 to the continuous filter's
    /// steady-state response (F0 keeps the shared scallop mean u″T²/12).
    #[test]
    fn curvature_bias_removed_on_a_slow_sine() {
        let (w, ts) = (1.884_955_592_153_876, 1.0);
        let nu = 2.0 * core::f64::consts::PI * 5.0 / 500.0;
        let [e0, e1, e2] = parabola_bias::<f64>(w, ts);
        assert!((-0.3..-0.2).contains(&e2), "ε2 {e2}");
        // the chip's f32 design agrees (at the real scale of τ: T = 135.7, w = 0.0139)
        let (wr, tr) = (w / 135.716, 135.716);
        let e64 = parabola_bias::<f64>(wr, tr);
        let e32 = parabola_bias::<f32>(wr, tr);
        let scale = [tr * tr, tr, 1.0];
        for j in 0..3 {
            assert!(
                (e64[j] - e32[j]).abs() < 1e-4 * scale[j],
                "ε{j}: {e64:?} vs {e32:?}"
            );
            assert!(
                (e64[j] / scale[j] - [e0, e1, e2][j]).abs() < 1e-9,
                "scale-free"
            );
        }
        let c = SvfCoeffs::<f64>::new(w, ts);
        let mut st = SvfState::at_rest(0.0);
        let (mut raw, mut fixed) = ([0.0f64; 3], [0.0f64; 3]);
        for k in 1..=4000 {
            let t = k as f64 * ts;
            let o = st.update(&c, (nu * t).sin());
            if k < 2000 {
                continue;
            }
            // exact steady state: H_j(iν)·e^{iνt}, imaginary part; H_j = w²(iν)^j/(iν+w)²
            let z = |j: i32| {
                let (re, im) = (w, nu); // iν + w
                let d2 = (re * re - im * im, 2.0 * re * im);
                let num = match j {
                    0 => (w * w, 0.0),
                    1 => (0.0, w * w * nu),
                    _ => (-w * w * nu * nu, 0.0),
                };
                let den = d2.0 * d2.0 + d2.1 * d2.1;
                let h = (
                    (num.0 * d2.0 + num.1 * d2.1) / den,
                    (num.1 * d2.0 - num.0 * d2.1) / den,
                );
                h.0 * (nu * t).sin() + h.1 * (nu * t).cos()
            };
            let upp = o.f2 / (1.0 + e2); // u″ as filtered
            let scallop = -nu * nu * z(0) * ts * ts / 12.0; // the shared mean, through F0
            let got = [o.f0 - e0 * upp, o.f1 - e1 * upp, upp];
            let want = [z(0) + scallop, z(1), z(2)];
            for j in 0..3 {
                let unc = if j == 0 {
                    o.f0
                } else if j == 1 {
                    o.f1
                } else {
                    o.f2
                };
                raw[j] = raw[j].max((unc - want[j]).abs());
                fixed[j] = fixed[j].max((got[j] - want[j]).abs());
            }
        }
        std::println!("wT 1.885: ε = [{e0:.4}, {e1:.4}, {e2:.4}]; raw {raw:?}, fixed {fixed:?}");
        let u2 = nu * nu; // |u″| of the sine
        // uncorrected: F2 off by a quarter of u″ (measured: ε2 = −0.2501). Corrected, what
        // is left is mostly the lag of u″'s estimate (F2 lags by ≈ 2/w = 1.06 samples:
        // 6.7 % of the correction at 5 Hz): F2 within 3 % of u″ (1.9 % measured), F0 and
        // F1 at least 10× and 4× closer (17× and 4.9× measured)
        assert!(raw[2] > 0.2 * u2, "F2 raw {:e}", raw[2]);
        assert!(fixed[2] < 0.03 * u2, "F2 fixed {:e}", fixed[2]);
        assert!(
            fixed[0] < raw[0] / 10.0,
            "F0 raw {:e} fixed {:e}",
            raw[0],
            fixed[0]
        );
        assert!(
            fixed[1] < raw[1] / 4.0,
            "F1 raw {:e} fixed {:e}",
            raw[1],
            fixed[1]
        );
    }

    /// The continuous filter driven by u(t) = sin(νt) from rest, integrated finely, vs
    /// the discrete bank fed with the samples: F0, F1, F2 agree with w²(1/Λ)u,
    /// w²(D/Λ)u and w²(D²/Λ)u of the continuous filter (FOH is exact up to the
    /// linear-interpolation error of the input, which is O((νT)²)·small here).
    #[test]
    fn matches_continuous_filter() {
        let w = 2.0 * core::f64::consts::PI * 10.0 / 67858.0;
        let ts = 67858.0 / 500.0;
        let nu = 2.0 * core::f64::consts::PI * 2.0 / 67858.0; // 2 Hz input
        let c = SvfCoeffs::<f64>::new(w, ts);
        let mut st = SvfState::at_rest(0.0);
        // continuous reference, integrated finely in the well-scaled cascade states
        // q1' = w(u − q1), q2' = w(q1 − q2) (q2 = w²(1/Λ)u, w(q1−q2) = w²(D/Λ)u)
        let (mut q1, mut q2) = (0.0f64, 0.0f64);
        let m = 2000;
        let h = ts / m as f64;
        let mut maxerr = [0.0f64; 3];
        let u_of = |t: f64| (nu * t).sin();
        for k in 0..1500 {
            let t0 = k as f64 * ts;
            let (u0, u1) = (u_of(t0), u_of(t0 + ts));
            // input to the continuous filter: the linear interpolation (FOH assumption)
            let ui = |i: f64| u0 + (u1 - u0) * i / m as f64;
            for i in 0..m {
                let f = |q1: f64, q2: f64, uu: f64| (w * (uu - q1), w * (q1 - q2));
                let fi = i as f64;
                let (a1, b1) = f(q1, q2, ui(fi));
                let (a2, b2) = f(q1 + 0.5 * h * a1, q2 + 0.5 * h * b1, ui(fi + 0.5));
                let (a3, b3) = f(q1 + 0.5 * h * a2, q2 + 0.5 * h * b2, ui(fi + 0.5));
                let (a4, b4) = f(q1 + h * a3, q2 + h * b3, ui(fi + 1.0));
                q1 += h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4);
                q2 += h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4);
            }
            let o = st.update(&c, u1);
            let e = [
                (o.f0 - q2).abs(),
                (o.f1 - w * (q1 - q2)).abs(),
                (o.f2 - w * w * (u1 - 2.0 * q1 + q2)).abs(),
            ];
            for i in 0..3 {
                maxerr[i] = maxerr[i].max(e[i]);
            }
        }
        // relative to the size of each output (F0 ~ 1, F1 ~ nu, F2 ~ nu²)
        assert!(maxerr[0] < 1e-10, "{maxerr:?}");
        assert!(maxerr[1] < 1e-10 * nu / w + 1e-13, "{maxerr:?}");
        assert!(maxerr[2] < 1e-16, "{maxerr:?}");
    }

    /// In f32, F1 and F2 of a large slowly varying signal keep the precision the drive
    /// rows need (absolute error ≪ 1e-7 of the row), unlike a (y, y′) realisation.
    #[test]
    fn f32_precision_of_derivative_outputs() {
        let w = 2.0 * core::f64::consts::PI * 10.0 / 67858.0;
        let ts = 67858.0 / 500.0;
        let c64 = SvfCoeffs::<f64>::new(w, ts);
        let c32 = SvfCoeffs::<f32>::new(w, ts);
        let mut s64 = SvfState::at_rest(1.75f64);
        let mut s32 = SvfState::at_rest(1.75f32);
        let mut err = [0.0f64; 3];
        let mut rng = 1u64;
        let mut vals = Vec::new();
        for k in 0..5000 {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            let noise = (rng % 1000) as f64 * 1e-8;
            let u = 1.75 + 0.3 * (k as f64 * 0.025).sin() + noise;
            let u32v = u as f32;
            let o64 = s64.update(&c64, u32v as f64);
            let o32 = s32.update(&c32, u32v);
            vals.push(o64.f0);
            err[0] = err[0].max((o32.f0 as f64 - o64.f0).abs());
            err[1] = err[1].max((o32.f1 as f64 - o64.f1).abs());
            err[2] = err[2].max((o32.f2 as f64 - o64.f2).abs());
        }
        assert!(err[1] < 2e-9, "F1 error {:e}", err[1]);
        assert!(err[2] < 2e-12, "F2 error {:e}", err[2]);
        // F0 carries the f32 relative precision of the signal itself (~1e-7)
        assert!(err[0] < 2e-6, "F0 error {:e}", err[0]);
    }

    #[test]
    fn at_rest_outputs() {
        let c = SvfCoeffs::<f64>::new(0.01, 100.0);
        let mut s = SvfState::at_rest(2.0);
        let o = s.update(&c, 2.0);
        assert!((o.f0 - 2.0).abs() < 1e-14 && o.f1.abs() < 1e-14 && o.f2.abs() < 1e-14);
    }
}
