//! Digital replica of the analog lock-in low-pass, applied to every known signal.
//!
//! The lock-in front end filters the demodulated displacement with an analog
//! Butterworth low-pass (4th order, 150 Hz by default) before the 500 Hz ADC. The
//! regression multiplies those envelopes by known signals (pump frequency ω, ω², ω′,
//! voltage scale s, accelerations), so the known signals must see the same filter:
//! without it the 2 ms group delay on a ±1e-3 dither makes row errors about ten times
//! the Coriolis term (FINDINGS §3.1).
//!
//! The replica is the same analog filter discretised **FOH-exactly** at the sample
//! period: between two samples the commanded signals are linear in time (the DDS sweeps
//! linearly between updates), so the discrete filter reproduces the analog one exactly
//! for them. The design (pole placement, matrix exponential) runs once in `f64` at
//! build time; the per-tick update is `n²+3n` multiply-adds in `T` per channel.
//!
//! Realisation: a cascade of second-order sections (and one first-order section for odd
//! orders) with states scaled to the signal (q, q′/w), which keeps every state of the
//! order of the input, so `f32` storage loses nothing to scaling.

use crate::real::Real;

/// Largest supported filter order.
pub const MAX_ORDER: usize = 8;
const MAXAUG: usize = MAX_ORDER + 2;

/// A continuous-time single-input single-output state-space model (`f64`, design time).
#[derive(Clone, Copy, Debug)]
pub struct Analog {
    /// Order (number of states).
    pub n: usize,
    /// State matrix.
    pub a: [[f64; MAX_ORDER]; MAX_ORDER],
    /// Input vector.
    pub b: [f64; MAX_ORDER],
    /// Output vector.
    pub c: [f64; MAX_ORDER],
}

/// Analog Butterworth low-pass of order `n` (1..=8) and cut-off `wc` (rad per time
/// unit), unit DC gain, as a cascade of scaled sections.
#[inline(never)] // set-up only: its own frame, not inlined into App::new (flash, stack)
pub fn butterworth(n: usize, wc: f64) -> Analog {
    butterworth_with(n, wc, libm::sin)
}

/// [`butterworth`] with the sine of the pole angles from `sin` (the design precision's
/// [`Real::design_cos_sin_f64`], so that the `f32` design links no libm trigonometry).
#[inline(never)] // set-up only
pub fn butterworth_with(n: usize, wc: f64, sin: fn(f64) -> f64) -> Analog {
    let mut a = [[0.0; MAX_ORDER]; MAX_ORDER];
    let mut b = [0.0; MAX_ORDER];
    let mut c = [0.0; MAX_ORDER];
    let n = n.clamp(1, MAX_ORDER);
    // section inputs chain: the first section's input is u, each next section's input is
    // the previous section's output state q. Section k (1-based) holds the states
    // 2k − 2 (its output q) and 2k − 1 (r); an odd order ends with the state n − 1. The
    // indices are written from k and n (≤ MAX_ORDER) so that no bounds check is left.
    let pairs = n / 2;
    // checked writes (`get_mut`): the indices are < n by construction, but the compiler
    // cannot see it and its bounds checks kept `core::fmt` in the firmware image
    fn set(m: &mut [[f64; MAX_ORDER]; MAX_ORDER], i: usize, j: usize, v: f64, add: bool) {
        if let Some(x) = m.get_mut(i).and_then(|row| row.get_mut(j)) {
            *x = if add { *x + v } else { v };
        }
    }
    for k in 1..=pairs {
        // damping of the k-th conjugate pole pair
        let zeta = sin(core::f64::consts::PI * (2 * k - 1) as f64 / (2 * n) as f64);
        let (q, r) = (2 * k - 2, 2 * k - 1);
        // q' = wc r ; r' = wc (u_in - q - 2 zeta r)
        set(&mut a, q, r, wc, false);
        set(&mut a, r, q, -wc, false);
        set(&mut a, r, r, -2.0 * zeta * wc, false);
        if k == 1 {
            if let Some(br) = b.get_mut(r) {
                *br = wc;
            }
        } else {
            set(&mut a, r, q.saturating_sub(2), wc, true); // the previous section's output
        }
    }
    let out = if n % 2 == 1 {
        let q = n - 1;
        set(&mut a, q, q, -wc, false);
        if pairs == 0 {
            if let Some(bq) = b.get_mut(q) {
                *bq = wc;
            }
        } else {
            set(&mut a, q, q.saturating_sub(2), wc, true); // (pairs > 0)
        }
        q
    } else {
        n.saturating_sub(2) // (n ≥ 2 here)
    };
    if let Some(co) = c.get_mut(out) {
        *co = 1.0;
    }
    Analog { n, a, b, c }
}

/// Matrix exponential of an `m × m` block of `x` (m ≤ 10) by scaling and squaring
/// with a 20-term Taylor series. Design-time only (`f64`).
#[inline(never)] // set-up only: its own frame, not inlined into App::new (flash, stack)
pub fn expm(x: &[[f64; MAXAUG]; MAXAUG], m: usize) -> [[f64; MAXAUG]; MAXAUG] {
    let m = m.min(MAXAUG);
    // infinity norm
    let mut norm = 0.0f64;
    for row in x.iter().take(m) {
        let s: f64 = row.iter().take(m).map(|v| libm::fabs(*v)).sum();
        norm = norm.max(s);
    }
    let mut squarings = 0u32;
    let mut scale = 1.0;
    while norm * scale > 0.25 && squarings < 60 {
        scale *= 0.5;
        squarings += 1;
    }
    // Taylor: E = I + X + X²/2! + ... with X = x·scale, formed in place (the design runs
    // on the chip's stack): row i of term·X needs only row i of term, so each new row goes
    // through a one-row buffer; term·(x·scale) = (term·x)·scale exactly, scale being a
    // power of two, and every sum runs in the order of a plain product.
    let mut e = [[0.0; MAXAUG]; MAXAUG];
    let mut term = [[0.0; MAXAUG]; MAXAUG];
    for i in 0..m {
        e[i][i] = 1.0;
        term[i][i] = 1.0;
    }
    for k in 1..=20 {
        let inv = 1.0 / k as f64;
        for i in 0..m {
            let row = row_times(&term[i], x, m);
            for j in 0..m {
                term[i][j] = row[j] * scale * inv;
            }
        }
        for i in 0..m {
            for j in 0..m {
                e[i][j] += term[i][j];
            }
        }
    }
    // squarings: E·E needs every row of E, so through a copy (term is free now)
    for _ in 0..squarings {
        term = e;
        for i in 0..m {
            e[i] = row_times(&term[i], &term, m);
        }
    }
    e
}

/// Row `a` (first `m` entries) times the `m × m` block of `b`, summed in the order of a
/// plain matrix product (zero entries of `a` skipped).
#[inline(never)]
fn row_times(a: &[f64; MAXAUG], b: &[[f64; MAXAUG]; MAXAUG], m: usize) -> [f64; MAXAUG] {
    let mut row = [0.0; MAXAUG];
    let m = m.min(MAXAUG); // (≤ MAXAUG already: lets the compiler drop the bounds checks)
    for (aik, bk) in a.iter().zip(b.iter()).take(m) {
        if *aik == 0.0 {
            continue;
        }
        for j in 0..m {
            row[j] += aik * bk[j];
        }
    }
    row
}

/// FOH-exact discretisation of an analog SISO model at period `ts`:
/// `x[k+1] = Φ x[k] + Γ0 u[k] + Γ1 (u[k+1] − u[k])` (exact for piecewise-linear input).
#[derive(Clone, Copy, Debug)]
pub struct FohDiscrete {
    /// Order.
    pub n: usize,
    /// Φ = e^{A ts}.
    pub phi: [[f64; MAX_ORDER]; MAX_ORDER],
    /// Γ0 = ∫ e^{A s} B ds.
    pub g0: [f64; MAX_ORDER],
    /// Γ1 = ∫ e^{A s} B (ts − s)/ts ds.
    pub g1: [f64; MAX_ORDER],
}

/// Discretises `sys` with a first-order hold (augmented matrix exponential, as in
/// `svf_discrete` of the prototype).
#[inline(never)] // set-up only: its own frame, not inlined into App::new (flash, stack)
pub fn foh_discretise(sys: &Analog, ts: f64) -> FohDiscrete {
    let n = sys.n.min(MAX_ORDER); // (≤ MAX_ORDER already: no bounds checks below)
    let mut m = [[0.0; MAXAUG]; MAXAUG];
    for i in 0..n {
        for j in 0..n {
            m[i][j] = sys.a[i][j] * ts;
        }
        m[i][n] = sys.b[i] * ts;
    }
    m[n][n + 1] = 1.0;
    let e = expm(&m, n + 2);
    // filled in the returned value (no second copy on the chip's stack)
    let mut d = FohDiscrete {
        n,
        phi: [[0.0; MAX_ORDER]; MAX_ORDER],
        g0: [0.0; MAX_ORDER],
        g1: [0.0; MAX_ORDER],
    };
    for i in 0..n {
        d.phi[i][..n].copy_from_slice(&e[i][..n]);
        d.g0[i] = e[i][n];
        d.g1[i] = e[i][n + 1];
    }
    d
}

/// Runtime coefficients of the replica filter in the estimator's precision (`Default`:
/// order 0, all zero, the placeholder of a design not built yet).
#[derive(Clone, Copy, Debug, Default)]
pub struct ReplicaCoeffs<T> {
    n: usize,
    phi: [[T; MAX_ORDER]; MAX_ORDER],
    g0: [T; MAX_ORDER],
    g1: [T; MAX_ORDER],
    /// Γ1 of the pump channels ([`ReplicaChannel::update_pump`]): `g1`, or with
    /// `pump_half_steps` the Γ1 of an input in two steps per interval, the linear
    /// sweep's means over its halves (`½·Γ0(ts/2) + ¼·Γ0(ts)`, exact for them).
    g1_pump: [T; MAX_ORDER],
    c: [T; MAX_ORDER],
    /// C·A: the output's time derivative is C·A·x + C·B·u (C·B = 0 for order ≥ 2).
    ca: [T; MAX_ORDER],
    cb: T,
    /// Steady state of a unit constant input (the filter is linear: the rest state at
    /// input u is u times this), computed at design time so that starting a channel
    /// costs O(n) on the tick path.
    rest_unit: [T; MAX_ORDER],
}

impl<T: Real> ReplicaCoeffs<T> {
    /// Designs the replica of an order-`order` Butterworth with cut-off `wc` (rad per
    /// time unit), sampled every `ts` time units. `pump_half_steps`: the pump channels
    /// move in two steps per interval (`PumpProfile::HalfSteps`), each the mean of the
    /// linear sweep over its half: between nodes u0 and u1 the input is u0 + ¼·du over
    /// the first half and u0 + ¾·du over the second, so their Γ1 is
    /// ¾·∫₀^{ts/2} e^{As}B ds + ¼·∫_{ts/2}^{ts} e^{As}B ds = ½·Γ0(ts/2) + ¼·Γ0(ts).
    #[inline(never)] // set-up only: its own frame, not inlined into App::new (flash, stack)
    pub fn butterworth(order: usize, wc: f64, ts: f64, pump_half_steps: bool) -> Self {
        let sys = butterworth_with(order, wc, |a| T::design_cos_sin_f64(a).1);
        let d = foh_discretise(&sys, ts);
        let dn = d.n.min(MAX_ORDER); // (≤ MAX_ORDER already: no bounds checks below)
        let mut r = ReplicaCoeffs {
            n: dn,
            phi: [[T::ZERO; MAX_ORDER]; MAX_ORDER],
            g0: [T::ZERO; MAX_ORDER],
            g1: [T::ZERO; MAX_ORDER],
            g1_pump: [T::ZERO; MAX_ORDER],
            c: [T::ZERO; MAX_ORDER],
            ca: [T::ZERO; MAX_ORDER],
            cb: T::ZERO,
            rest_unit: [T::ZERO; MAX_ORDER],
        };
        let mut cb = 0.0;
        for i in 0..dn {
            for j in 0..dn {
                r.phi[i][j] = T::from_f64(d.phi[i][j]);
            }
            r.g0[i] = T::from_f64(d.g0[i]);
            r.g1[i] = T::from_f64(d.g1[i]);
            r.c[i] = T::from_f64(sys.c[i]);
            let mut ca = 0.0;
            for k in 0..dn {
                ca += sys.c[k] * sys.a[k][i];
            }
            r.ca[i] = T::from_f64(ca);
            cb += sys.c[i] * sys.b[i];
        }
        r.cb = T::from_f64(cb);
        r.g1_pump = r.g1;
        if pump_half_steps {
            // Γ0 over the last half of the interval (in `T`: ½ and ¼ are exact)
            let h = foh_discretise(&sys, 0.5 * ts);
            for i in 0..dn {
                r.g1_pump[i] =
                    T::from_f64(h.g0[i]) * T::from_f64(0.5) + r.g0[i] * T::from_f64(0.25);
            }
        }
        // rest state for u = 1: iterate x = Φx + Γ0 (|eig Φ| < 1, converges
        // geometrically) in f64 at design time
        let mut x = [0.0f64; MAX_ORDER];
        for _ in 0..2000 {
            let mut nx = [0.0f64; MAX_ORDER];
            for i in 0..dn {
                let mut acc = d.g0[i];
                for j in 0..dn {
                    acc += d.phi[i][j] * x[j];
                }
                nx[i] = acc;
            }
            x = nx;
        }
        for i in 0..dn {
            r.rest_unit[i] = T::from_f64(x[i]);
        }
        r
    }
}

/// One replica channel: filter state and the last input.
#[derive(Clone, Copy, Debug)]
pub struct ReplicaChannel<T> {
    x: [T; MAX_ORDER],
    u_prev: T,
}

impl<T: Real> ReplicaChannel<T> {
    /// A channel at rest at input `u` (steady state: every section output equals `u`).
    pub fn at_rest(coeffs: &ReplicaCoeffs<T>, u: T) -> Self {
        let mut ch = ReplicaChannel {
            x: [T::ZERO; MAX_ORDER],
            u_prev: u,
        };
        ch.settle(coeffs, u);
        ch
    }

    /// Sets the state to the steady state of a constant input `u` (O(n): the design
    /// holds the rest state of a unit input).
    pub fn settle(&mut self, coeffs: &ReplicaCoeffs<T>, u: T) {
        for (x, r) in self.x.iter_mut().zip(coeffs.rest_unit.iter()) {
            *x = *r * u;
        }
        self.u_prev = u;
    }

    /// Advances one sample with the new input `u` and returns the filtered value: FOH
    /// (the input ramps linearly from the previous sample to `u`) or, with `hold`, ZOH
    /// (the input is `u` over the whole interval, as a staircase that steps at the
    /// previous sample instant).
    #[inline]
    pub fn update_with(&mut self, coeffs: &ReplicaCoeffs<T>, u: T, hold: bool) -> T {
        if hold {
            self.u_prev = u;
        }
        self.update(coeffs, u)
    }

    /// The next update's interval starts at input `u` (instead of the last sample's).
    #[inline(always)]
    pub fn restart_from(&mut self, u: T) {
        self.u_prev = u;
    }

    /// [`ReplicaChannel::update_with`] for a pump channel: between samples the input
    /// moves as the pump generator does (`ReplicaCoeffs::butterworth`'s
    /// `pump_half_steps`: a linear sweep, or its two half-interval means), or with
    /// `hold` it steps at the previous sample instant.
    #[inline]
    pub fn update_pump(&mut self, coeffs: &ReplicaCoeffs<T>, u: T, hold: bool) -> T {
        if hold {
            self.u_prev = u;
        }
        self.update_g1(coeffs, &coeffs.g1_pump, u)
    }

    /// Advances one sample with the new input `u` (FOH) and returns the filtered value.
    ///
    /// The default order (4, `lockin_lpf_order`) runs a kernel written out for it (no
    /// loop, iterator or zeroing overhead on the tick path; the same operations in the
    /// same order); any other order the loop below.
    #[inline(always)]
    pub fn update(&mut self, coeffs: &ReplicaCoeffs<T>, u: T) -> T {
        self.update_g1(coeffs, &coeffs.g1, u)
    }

    /// One sample with the slope coefficients `g1` (`coeffs.g1` or `coeffs.g1_pump`).
    /// Not inlined: one copy for the five channels (the stm32f405 image's 128 KiB flash
    /// budget, firmware/README.md "Budgets").
    #[inline(never)]
    fn update_g1(&mut self, coeffs: &ReplicaCoeffs<T>, g1: &[T; MAX_ORDER], u: T) -> T {
        if coeffs.n == 4 {
            return self.update_4(coeffs, g1, u);
        }
        self.update_loop(coeffs, g1, u)
    }

    /// [`ReplicaChannel::update`] for any order (the loop form).
    #[inline]
    fn update_loop(&mut self, coeffs: &ReplicaCoeffs<T>, g1: &[T; MAX_ORDER], u: T) -> T {
        let n = coeffs.n;
        let du = u - self.u_prev;
        let mut nx = [T::ZERO; MAX_ORDER];
        for (i, nxi) in nx.iter_mut().enumerate().take(n) {
            let mut acc = coeffs.g0[i] * self.u_prev + g1[i] * du;
            for (p, xj) in coeffs.phi[i].iter().zip(self.x.iter()).take(n) {
                acc += *p * *xj;
            }
            *nxi = acc;
        }
        self.x = nx;
        self.u_prev = u;
        self.output(coeffs)
    }

    /// [`ReplicaChannel::update`] for order 4, written out (the loop form's operations
    /// in its order: `acc = g0·u_prev + g1·du`, then `+= φ_ij·x_j` for j = 0..4; the
    /// output `0 + Σ c_i·x_i`). States above the order stay zero as in the loop form.
    #[inline(always)]
    fn update_4(&mut self, co: &ReplicaCoeffs<T>, g1: &[T; MAX_ORDER], u: T) -> T {
        let up = self.u_prev;
        let du = u - up;
        let [x0, x1, x2, x3] = [self.x[0], self.x[1], self.x[2], self.x[3]];
        let row = |i: usize| {
            let p = &co.phi[i];
            co.g0[i] * up + g1[i] * du + p[0] * x0 + p[1] * x1 + p[2] * x2 + p[3] * x3
        };
        let nx = [row(0), row(1), row(2), row(3)];
        self.x[..4].copy_from_slice(&nx);
        self.u_prev = u;
        T::ZERO + co.c[0] * nx[0] + co.c[1] * nx[1] + co.c[2] * nx[2] + co.c[3] * nx[3]
    }

    /// Current filtered value C·x.
    #[inline]
    pub fn output(&self, coeffs: &ReplicaCoeffs<T>) -> T {
        let mut y = T::ZERO;
        for (c, x) in coeffs.c.iter().zip(self.x.iter()).take(coeffs.n) {
            y += *c * *x;
        }
        y
    }

    /// Time derivative of the filtered value (per time unit): C·A·x + C·B·u. Exactly
    /// the filtered derivative of the input, since the filter commutes with d/dt.
    #[inline]
    pub fn derivative(&self, coeffs: &ReplicaCoeffs<T>) -> T {
        let mut y = coeffs.cb * self.u_prev;
        for (c, x) in coeffs.ca.iter().zip(self.x.iter()).take(coeffs.n) {
            y += *c * *x;
        }
        y
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// The written-out order-4 kernel gives the loop form's values bit for bit.
    #[test]
    fn order_4_kernel_equals_the_loop() {
        let co = ReplicaCoeffs::<f32>::butterworth(4, 0.3, 0.05, false);
        let mut fast = ReplicaChannel::at_rest(&co, 0.25);
        let mut slow = fast;
        for k in 0..2000 {
            let u = libm::sinf(k as f32 * 0.037) + if k % 97 == 0 { 3.0 } else { 0.0 };
            let (a, b) = (fast.update(&co, u), slow.update_loop(&co, &co.g1, u));
            assert_eq!(a.to_bits(), b.to_bits(), "k = {k}");
            assert_eq!(fast.x.map(f32::to_bits), slow.x.map(f32::to_bits));
        }
    }

    /// |H(jw)| of the analog model at angular frequency w.
    fn mag(sys: &Analog, w: f64) -> f64 {
        // solve (jwI - A) x = B by complex Gaussian elimination
        let n = sys.n;
        let mut mr = [[0.0; MAX_ORDER + 1]; MAX_ORDER];
        let mut mi = [[0.0; MAX_ORDER + 1]; MAX_ORDER];
        for i in 0..n {
            for j in 0..n {
                mr[i][j] = -sys.a[i][j];
            }
            mi[i][i] = w;
            mr[i][n] = sys.b[i];
        }
        for col in 0..n {
            // pivot
            let mut p = col;
            for r in col..n {
                if mr[r][col].hypot(mi[r][col]) > mr[p][col].hypot(mi[p][col]) {
                    p = r;
                }
            }
            mr.swap(col, p);
            mi.swap(col, p);
            let (pr, pi) = (mr[col][col], mi[col][col]);
            let d = pr * pr + pi * pi;
            for r in 0..n {
                if r == col {
                    continue;
                }
                let (ar, ai) = (mr[r][col], mi[r][col]);
                // f = a / p
                let fr = (ar * pr + ai * pi) / d;
                let fi = (ai * pr - ar * pi) / d;
                for j in col..=n {
                    let (br, bi) = (mr[col][j], mi[col][j]);
                    mr[r][j] -= fr * br - fi * bi;
                    mi[r][j] -= fr * bi + fi * br;
                }
            }
        }
        let mut yr = 0.0;
        let mut yi = 0.0;
        for i in 0..n {
            let (pr, pi) = (mr[i][i], mi[i][i]);
            let d = pr * pr + pi * pi;
            let xr = (mr[i][n] * pr + mi[i][n] * pi) / d;
            let xi = (mi[i][n] * pr - mr[i][n] * pi) / d;
            yr += sys.c[i] * xr;
            yi += sys.c[i] * xi;
        }
        yr.hypot(yi)
    }

    #[test]
    fn butterworth_magnitude_matches_findings() {
        // FINDINGS §3.1: |H| = 0.98 at 100 Hz and 0.13 at 250 Hz for 4th order 150 Hz
        let sys = butterworth(4, 2.0 * core::f64::consts::PI * 150.0);
        let m100 = mag(&sys, 2.0 * core::f64::consts::PI * 100.0);
        let m250 = mag(&sys, 2.0 * core::f64::consts::PI * 250.0);
        let m0 = mag(&sys, 1e-9);
        assert!((m0 - 1.0).abs() < 1e-9, "DC gain {m0}");
        // exact Butterworth: 1/sqrt(1+(f/fc)^8)
        let ex = |f: f64| 1.0 / (1.0 + (f / 150.0f64).powi(8)).sqrt();
        assert!((m100 - ex(100.0)).abs() < 1e-12, "{m100}");
        assert!((m250 - ex(250.0)).abs() < 1e-12, "{m250}");
        assert!((m100 - 0.98).abs() < 0.01 && (m250 - 0.13).abs() < 0.01);
        for n in 1..=8 {
            let s = butterworth(n, 1.0);
            assert!(
                (mag(&s, 1.0) - core::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12,
                "order {n}"
            );
        }
    }

    /// The matrix exponential as first written (four matrices, products by value).
    fn expm_reference(x: &[[f64; MAXAUG]; MAXAUG], m: usize) -> [[f64; MAXAUG]; MAXAUG] {
        fn matmul(
            a: &[[f64; MAXAUG]; MAXAUG],
            b: &[[f64; MAXAUG]; MAXAUG],
            m: usize,
        ) -> [[f64; MAXAUG]; MAXAUG] {
            let mut r = [[0.0; MAXAUG]; MAXAUG];
            for i in 0..m {
                for k in 0..m {
                    let aik = a[i][k];
                    if aik == 0.0 {
                        continue;
                    }
                    for j in 0..m {
                        r[i][j] += aik * b[k][j];
                    }
                }
            }
            r
        }
        let m = m.min(MAXAUG);
        let mut norm = 0.0f64;
        for row in x.iter().take(m) {
            let s: f64 = row.iter().take(m).map(|v| libm::fabs(*v)).sum();
            norm = norm.max(s);
        }
        let mut squarings = 0u32;
        let mut scale = 1.0;
        while norm * scale > 0.25 && squarings < 60 {
            scale *= 0.5;
            squarings += 1;
        }
        let mut xs = [[0.0; MAXAUG]; MAXAUG];
        for i in 0..m {
            for j in 0..m {
                xs[i][j] = x[i][j] * scale;
            }
        }
        let mut e = [[0.0; MAXAUG]; MAXAUG];
        let mut term = [[0.0; MAXAUG]; MAXAUG];
        for i in 0..m {
            e[i][i] = 1.0;
            term[i][i] = 1.0;
        }
        for k in 1..=20 {
            term = matmul(&term, &xs, m);
            let inv = 1.0 / k as f64;
            for row in term.iter_mut().take(m) {
                for v in row.iter_mut().take(m) {
                    *v *= inv;
                }
            }
            for i in 0..m {
                for j in 0..m {
                    e[i][j] += term[i][j];
                }
            }
        }
        for _ in 0..squarings {
            e = matmul(&e, &e, m);
        }
        e
    }

    #[test]
    fn expm_in_place_equals_the_reference_bit_for_bit() {
        // the FOH augmented matrices of every order at several corners, and dense ones
        for order in 1..=MAX_ORDER {
            for &(wc, ts) in &[(0.02, 0.5), (0.2, 1.3), (3.0, 0.9), (40.0, 2.0)] {
                let sys = butterworth(order, wc);
                let n = sys.n;
                let mut m = [[0.0; MAXAUG]; MAXAUG];
                for i in 0..n {
                    for j in 0..n {
                        m[i][j] = sys.a[i][j] * ts;
                    }
                    m[i][n] = sys.b[i] * ts;
                }
                m[n][n + 1] = 1.0;
                assert_eq!(expm(&m, n + 2), expm_reference(&m, n + 2), "order {order}");
            }
        }
        let mut s: u64 = 7;
        for size in 1..=MAXAUG {
            let mut x = [[0.0; MAXAUG]; MAXAUG];
            for row in x.iter_mut().take(size) {
                for v in row.iter_mut().take(size) {
                    s = s
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    *v = ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 6.0;
                }
            }
            assert_eq!(expm(&x, size), expm_reference(&x, size), "size {size}");
        }
    }

    #[test]
    fn expm_of_rotation_is_exact() {
        let mut x = [[0.0; MAXAUG]; MAXAUG];
        x[0][1] = 2.0;
        x[1][0] = -2.0;
        let e = expm(&x, 2);
        assert!((e[0][0] - 2.0f64.cos()).abs() < 1e-14);
        assert!((e[0][1] - 2.0f64.sin()).abs() < 1e-14);
    }

    #[test]
    fn foh_replica_is_exact_for_ramps_and_tracks_derivative() {
        // a ramp u = r t through a 4th-order filter: analog steady-state output is
        // r (t - τg) with group delay τg = -d(phase)/dw at 0 = sum of 2 zeta_k / wc.
        let wc = 2.0 * core::f64::consts::PI * 150.0;
        let ts = 1.0 / 500.0;
        let co = ReplicaCoeffs::<f64>::butterworth(4, wc, ts, false);
        let mut ch = ReplicaChannel::at_rest(&co, 0.0);
        let r = 3.0;
        let mut y = 0.0;
        let mut t = 0.0;
        for k in 1..=200 {
            t = k as f64 * ts;
            y = ch.update(&co, r * t);
        }
        let tg: f64 = (1..=2)
            .map(|k| 2.0 * (core::f64::consts::PI * (2 * k - 1) as f64 / 8.0).sin() / wc)
            .sum();
        assert!(
            (y - r * (t - tg)).abs() < 1e-9,
            "y {y} expected {}",
            r * (t - tg)
        );
        assert!(
            (ch.derivative(&co) - r).abs() < 1e-9,
            "derivative {}",
            ch.derivative(&co)
        );
        // at rest: output equals the input
        let ch2 = ReplicaChannel::at_rest(&co, 0.7);
        assert!((ch2.output(&co) - 0.7).abs() < 1e-12);
        assert!(ch2.derivative(&co).abs() < 1e-9);
    }

    /// Fine RK4 of `sys` over one interval `ts` in `m` sub-steps with the input `ui(a)`,
    /// a ∈ [0, 1] the fraction of the interval: at each RK4 stage, or (`held`) at each
    /// sub-step's midpoint for all its stages (an input that steps on the sub-step grid).
    fn rk4_interval(
        sys: &Analog,
        x: &mut [f64; MAX_ORDER],
        ts: f64,
        m: usize,
        held: bool,
        ui: &dyn Fn(f64) -> f64,
    ) {
        let n = sys.n;
        let f = |x: &[f64; MAX_ORDER], uu: f64| {
            let mut d = [0.0; MAX_ORDER];
            for i in 0..n {
                d[i] = sys.b[i] * uu;
                for j in 0..n {
                    d[i] += sys.a[i][j] * x[j];
                }
            }
            d
        };
        let h = ts / m as f64;
        for i in 0..m {
            let ah = (i as f64 + 0.5) / m as f64;
            let (a0, a1) = if held {
                (ah, ah)
            } else {
                (i as f64 / m as f64, (i as f64 + 1.0) / m as f64)
            };
            let k1 = f(x, ui(a0));
            let mut xt = *x;
            (0..n).for_each(|q| xt[q] = x[q] + 0.5 * h * k1[q]);
            let k2 = f(&xt, ui(ah));
            (0..n).for_each(|q| xt[q] = x[q] + 0.5 * h * k2[q]);
            let k3 = f(&xt, ui(ah));
            (0..n).for_each(|q| xt[q] = x[q] + h * k3[q]);
            let k4 = f(&xt, ui(a1));
            (0..n).for_each(|q| x[q] += h / 6.0 * (k1[q] + 2.0 * k2[q] + 2.0 * k3[q] + k4[q]));
        }
    }

    #[test]
    fn the_pump_channel_is_exact_for_two_steps_per_interval() {
        // the lock-in's 150 Hz 4th order at 500 Hz; a 5 Hz sine of nodes, the input between
        // two nodes u0, u1 at u0 + du/4 over the first half and u0 + 3du/4 over the second
        let wc = 2.0 * core::f64::consts::PI * 150.0;
        let ts = 1.0 / 500.0;
        let sys = butterworth(4, wc);
        // (an even number of sub-steps: the step falls between two of them)
        let half = ReplicaCoeffs::<f64>::butterworth(4, wc, ts, true);
        let foh = ReplicaCoeffs::<f64>::butterworth(4, wc, ts, false);
        let (mut ch, mut ch_foh) = (
            ReplicaChannel::at_rest(&half, 0.0),
            ReplicaChannel::at_rest(&foh, 0.0),
        );
        let mut x = [0.0f64; MAX_ORDER];
        let u = |k: usize| (2.0 * core::f64::consts::PI * 5.0 * k as f64 * ts).sin();
        let (mut worst, mut worst_foh, mut peak) = (0.0f64, 0.0f64, 0.0f64);
        for k in 0..100 {
            let (u0, u1) = (u(k), u(k + 1));
            let step = |a: f64| u0 + (u1 - u0) * if a < 0.5 { 0.25 } else { 0.75 };
            rk4_interval(&sys, &mut x, ts, 400, true, &step);
            let yref: f64 = (0..4).map(|i| sys.c[i] * x[i]).sum();
            worst = worst.max((ch.update_pump(&half, u1, false) - yref).abs());
            worst_foh = worst_foh.max((ch_foh.update_pump(&foh, u1, false) - yref).abs());
            peak = peak.max(yref.abs());
        }
        // exact up to the fine integration's own error; the sweep's (FOH) replica is not
        assert!(worst < 1e-10 * peak, "half-step replica off by {worst:e}");
        assert!(worst_foh > 1e3 * worst, "FOH off by {worst_foh:e} only");
        // the other channels keep the FOH slope coefficients
        assert_eq!(half.g1, foh.g1);
        assert_eq!(foh.g1_pump, foh.g1);
    }

    #[test]
    fn foh_matches_fine_integration_for_a_sine() {
        // compare against a fine RK4 integration of the analog model with a sinusoidal
        // input linearly interpolated between the samples (the FOH assumption).
        let wc = 1.3;
        let ts = 0.7;
        let sys = butterworth(3, wc);
        let co = ReplicaCoeffs::<f64>::butterworth(3, wc, ts, false);
        let mut ch = ReplicaChannel::at_rest(&co, 0.0);
        let mut x = [0.0f64; MAX_ORDER];
        let u = |k: usize| (0.4 * k as f64).sin();
        for k in 0..40 {
            let (u0, u1) = (u(k), u(k + 1));
            rk4_interval(&sys, &mut x, ts, 400, false, &|s| u0 + (u1 - u0) * s);
            let y = ch.update(&co, u1);
            let yref: f64 = (0..3).map(|i| sys.c[i] * x[i]).sum();
            assert!((y - yref).abs() < 1e-11, "k {k}: {y} vs {yref}");
        }
    }
}
