//! The lock-in's low-pass, realised as a **doubly terminated LC ladder** (Cauer topology)
//! whose element values are the Butterworth prototype's, `g_k = 2·sin((2k − 1)π/(2n))`,
//! between a 1 Ω source and a 1 Ω load. Its states are the capacitor voltages and the
//! inductor currents; its transfer function from the source to twice the load voltage is
//! the n-th order Butterworth low-pass `1/B_n(s/ωc)`: DC gain 1, −3 dB at ωc.
//!
//! The ladder's state equations are tridiagonal and well scaled (every state is of the
//! order of the input), so the lock-in integrates them **as part of the plant's ODE**
//! ([`crate::sim`]): the mixer products drive the ladders at every stage of the adaptive
//! integrator, and the filter outputs at the sample instants are the record's columns.
//!
//! The pick-off noise is white and enters the lock-in linearly, so its contribution is a
//! separate linear stochastic process per channel, discretised **exactly** at the sample
//! period ([`NoiseDiscretisation`], Van Loan's matrix exponential): `ξ ← Φξ + L·N(0, I)`
//! with `L·Lᵀ = ∫₀^Ts e^{Aτ} B S Bᵀ e^{Aᵀτ} dτ`.

// dense small-matrix and stage arithmetic reads best with indices
#![allow(clippy::needless_range_loop)]

/// Largest order.
pub const MAX_ORDER: usize = 8;

/// The ladder of order `n` at cut-off `wc` (rad/s): `ẋ = wc·(A x + B u)`, `y = C x`.
#[derive(Clone, Debug, PartialEq)]
pub struct Ladder {
    /// Order.
    pub n: usize,
    /// Cut-off, rad/s.
    pub wc: f64,
    /// Row k of the tridiagonal `wc·A`: the coefficients of x[k−1], x[k], x[k+1]. A
    /// shunt capacitor (k even) sees the current in minus the current out of its node
    /// (from the source through 1 Ω at k = 0, into the 1 Ω load at the end); a series
    /// inductor (k odd) the voltage across it (onto the load at the end).
    tri: [[f64; 3]; MAX_ORDER],
    /// The source's gain into x[0], wc/g_1.
    b0: f64,
}

impl Ladder {
    /// The Butterworth ladder of order `n` (1..=8) and cut-off `hz`.
    pub fn new(n: usize, hz: f64) -> Result<Self, String> {
        if !(1..=MAX_ORDER).contains(&n) {
            return Err(format!("low-pass order {n} must be 1..={MAX_ORDER}"));
        }
        if !(hz.is_finite() && hz > 0.0) {
            return Err(format!("low-pass cut-off {hz} Hz must be positive"));
        }
        let wc = std::f64::consts::TAU * hz;
        let mut tri = [[0.0; 3]; MAX_ORDER];
        let mut b0 = 0.0;
        for (k, row) in tri.iter_mut().enumerate().take(n) {
            let g = 2.0 * ((2 * k + 1) as f64 * std::f64::consts::PI / (2 * n) as f64).sin();
            let w = wc / g;
            let first = k == 0;
            let last = k + 1 == n;
            if first {
                b0 = w; // (u − x0)/R_s
            }
            row[0] = if first { 0.0 } else { w };
            row[1] = -w * (f64::from(u8::from(first)) + f64::from(u8::from(last)));
            row[2] = if last { 0.0 } else { -w };
        }
        Ok(Self { n, wc, tri, b0 })
    }

    /// `dx/dt` of one channel's ladder with input `u` (the source voltage).
    #[inline(always)]
    pub fn deriv(&self, x: &[f64], u: f64, dx: &mut [f64]) {
        let n = self.n;
        for k in 0..n {
            let mut v = self.tri[k][1] * x[k];
            if k > 0 {
                v += self.tri[k][0] * x[k - 1];
            }
            if k + 1 < n {
                v += self.tri[k][2] * x[k + 1];
            }
            dx[k] = v;
        }
        dx[0] += self.b0 * u;
    }

    /// `dx/dt` of a bank of `C` ladders stored state-major (`x[k·C + c]`: state k of
    /// channel c), with the inputs `u`: the same tridiagonal equations, each state row a
    /// loop over the channels.
    #[inline(always)]
    pub fn deriv_bank<const C: usize>(&self, x: &[f64], u: &[f64; C], dx: &mut [f64]) {
        let n = self.n;
        for k in 0..n {
            let [lo, di, up] = self.tri[k];
            let row = &mut dx[k * C..(k + 1) * C];
            let xk = &x[k * C..(k + 1) * C];
            for c in 0..C {
                row[c] = di * xk[c];
            }
            if k > 0 {
                let xl = &x[(k - 1) * C..k * C];
                for c in 0..C {
                    row[c] += lo * xl[c];
                }
            }
            if k + 1 < n {
                let xu = &x[(k + 1) * C..(k + 2) * C];
                for c in 0..C {
                    row[c] += up * xu[c];
                }
            }
        }
        for c in 0..C {
            dx[c] += self.b0 * u[c];
        }
    }

    /// The output (twice the load voltage, or twice the load current through 1 Ω).
    #[inline(always)]
    pub fn output(&self, x: &[f64]) -> f64 {
        2.0 * x[self.n - 1]
    }

    /// The dense `A` (n×n, row-major) and `B` of `ẋ = wc(Ax + Bu)` (for the noise and the
    /// tests).
    pub fn matrices(&self) -> (Vec<f64>, Vec<f64>) {
        let n = self.n;
        let mut a = vec![0.0; n * n];
        let mut b = vec![0.0; n];
        for j in 0..n {
            let mut e = vec![0.0; n];
            e[j] = 1.0;
            let mut d = vec![0.0; n];
            self.deriv(&e, 0.0, &mut d);
            for i in 0..n {
                a[i * n + j] = d[i] / self.wc;
            }
        }
        let mut d = vec![0.0; n];
        self.deriv(&vec![0.0; n], 1.0, &mut d);
        for i in 0..n {
            b[i] = d[i] / self.wc;
        }
        (a, b)
    }

    /// The complex gain at `f_hz` (re, im), from the state equations.
    pub fn gain(&self, f_hz: f64) -> (f64, f64) {
        let n = self.n;
        let (a, b) = self.matrices();
        // (jω I − wc A) x = wc B, complex, by Gaussian elimination on 2n real unknowns
        let w = std::f64::consts::TAU * f_hz;
        let m = 2 * n;
        let mut mat = vec![0.0; m * (m + 1)];
        for i in 0..n {
            for j in 0..n {
                let v = -self.wc * a[i * n + j];
                mat[i * (m + 1) + j] = v; // re rows: Re part
                mat[(i + n) * (m + 1) + (j + n)] = v;
            }
            mat[i * (m + 1) + (i + n)] = -w; // re: −ω·Im x
            mat[(i + n) * (m + 1) + i] = w; // im: +ω·Re x
            mat[i * (m + 1) + m] = self.wc * b[i];
        }
        let x = solve(&mut mat, m);
        (2.0 * x[n - 1], 2.0 * x[2 * n - 1])
    }
}

/// Solves the augmented system `mat` (m rows of m + 1) by elimination with pivoting.
fn solve(mat: &mut [f64], m: usize) -> Vec<f64> {
    let w = m + 1;
    for c in 0..m {
        let p = (c..m)
            .max_by(|&i, &j| mat[i * w + c].abs().total_cmp(&mat[j * w + c].abs()))
            .unwrap_or(c);
        for k in 0..w {
            mat.swap(c * w + k, p * w + k);
        }
        for r in 0..m {
            if r != c {
                let f = mat[r * w + c] / mat[c * w + c];
                for k in c..w {
                    mat[r * w + k] -= f * mat[c * w + k];
                }
            }
        }
    }
    (0..m).map(|i| mat[i * w + m] / mat[i * w + i]).collect()
}

/// `e^M` of a square matrix (row-major, dimension `n`): scaling and squaring with a
/// degree-24 Taylor series.
pub fn expm(m: &[f64], n: usize) -> Vec<f64> {
    let norm = (0..n)
        .map(|i| (0..n).map(|j| m[i * n + j].abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let sq = if norm > 0.25 {
        (norm / 0.25).log2().ceil() as i32
    } else {
        0
    };
    let scale = 0.5f64.powi(sq);
    let a: Vec<f64> = m.iter().map(|v| v * scale).collect();
    let mut result = identity(n);
    let mut term = identity(n);
    for k in 1..=24 {
        term = matmul(&term, &a, n);
        for v in &mut term {
            *v /= k as f64;
        }
        for (r, t) in result.iter_mut().zip(&term) {
            *r += t;
        }
    }
    for _ in 0..sq {
        result = matmul(&result, &result, n);
    }
    result
}

fn identity(n: usize) -> Vec<f64> {
    let mut i = vec![0.0; n * n];
    for k in 0..n {
        i[k * n + k] = 1.0;
    }
    i
}

fn matmul(a: &[f64], b: &[f64], n: usize) -> Vec<f64> {
    let mut c = vec![0.0; n * n];
    for i in 0..n {
        for k in 0..n {
            let aik = a[i * n + k];
            if aik != 0.0 {
                for j in 0..n {
                    c[i * n + j] += aik * b[k * n + j];
                }
            }
        }
    }
    c
}

/// The exact sample-period discretisation of a ladder driven by white noise of unit
/// two-sided density: `ξ_{k+1} = Φ ξ_k + L w_k`, `w_k ~ N(0, I)`.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseDiscretisation {
    /// Order.
    pub n: usize,
    /// Φ = e^{wc·A·Ts}, row-major.
    pub phi: Vec<f64>,
    /// Lower-triangular L with L·Lᵀ = Q (unit density), row-major.
    pub chol: Vec<f64>,
}

impl NoiseDiscretisation {
    /// For `ladder` at the sample period `ts` (Van Loan: e^{[[−F, GGᵀ], [0, Fᵀ]]·Ts}).
    pub fn new(ladder: &Ladder, ts: f64) -> Self {
        let n = ladder.n;
        let (a, b) = ladder.matrices();
        let f: Vec<f64> = a.iter().map(|v| v * ladder.wc).collect();
        let g: Vec<f64> = b.iter().map(|v| v * ladder.wc).collect();
        let m = 2 * n;
        let mut vl = vec![0.0; m * m];
        for i in 0..n {
            for j in 0..n {
                vl[i * m + j] = -f[i * n + j] * ts;
                vl[i * m + n + j] = g[i] * g[j] * ts;
                vl[(n + i) * m + n + j] = f[j * n + i] * ts;
            }
        }
        let e = expm(&vl, m);
        let mut phi = vec![0.0; n * n];
        let mut g12 = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                phi[i * n + j] = e[(n + j) * m + n + i]; // Φ = G22ᵀ
                g12[i * n + j] = e[i * m + n + j];
            }
        }
        let mut q = matmul(&phi, &g12, n);
        // symmetrise against rounding
        for i in 0..n {
            for j in 0..i {
                let v = 0.5 * (q[i * n + j] + q[j * n + i]);
                q[i * n + j] = v;
                q[j * n + i] = v;
            }
        }
        let chol = cholesky(&q, n);
        Self { n, phi, chol }
    }

    /// The stationary-free step: `ξ ← Φξ + σ·L·w` for the standard normals `w`.
    pub fn step(&self, xi: &mut [f64], sigma: f64, w: &[f64]) {
        let n = self.n;
        let mut out = [0.0; MAX_ORDER];
        for i in 0..n {
            let mut v = 0.0;
            for j in 0..n {
                v += self.phi[i * n + j] * xi[j];
            }
            for (j, wj) in w.iter().enumerate().take(i + 1) {
                v += sigma * self.chol[i * n + j] * wj;
            }
            out[i] = v;
        }
        xi[..n].copy_from_slice(&out[..n]);
    }
}

/// The Cholesky factor of a symmetric positive semi-definite matrix (pivots below a
/// relative 1e-300 are taken as zero).
fn cholesky(q: &[f64], n: usize) -> Vec<f64> {
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut s = q[i * n + j];
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                l[i * n + i] = s.max(0.0).sqrt();
            } else if l[j * n + j] > 0.0 {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    l
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The ladder is the Butterworth low-pass: |H| = 1/√(1 + (f/fc)^{2n}).
    #[test]
    fn ladder_is_butterworth() {
        for n in 1..=8 {
            let l = Ladder::new(n, 150.0).unwrap();
            for f in [0.0, 10.0, 75.0, 150.0, 300.0, 2000.0] {
                let (re, im) = l.gain(f);
                let want = 1.0 / (1.0 + (f / 150.0f64).powi(2 * n as i32)).sqrt();
                let got = (re * re + im * im).sqrt();
                assert!((got - want).abs() < 1e-12, "n {n} f {f}: {got} vs {want}");
            }
        }
    }

    /// The discretised noise has the continuous filter's variance: σ²·ENBW, where the
    /// stationary output variance of white noise of two-sided density 1 through the
    /// Butterworth filter is ∫|H|² df over ±∞ = wc/(2n·sin(π/2n)) ... checked here by
    /// iterating the discretisation to its stationary state.
    #[test]
    fn stationary_noise_variance_is_the_filters() {
        for n in [1usize, 2, 4, 5] {
            let l = Ladder::new(n, 150.0).unwrap();
            let d = NoiseDiscretisation::new(&l, 1.0 / 500.0);
            // P ← ΦPΦᵀ + LLᵀ to convergence
            let mut p = vec![0.0; n * n];
            let q = matmul(&d.chol, &transpose(&d.chol, n), n);
            for _ in 0..2000 {
                let t = matmul(&matmul(&d.phi, &p, n), &transpose(&d.phi, n), n);
                p = t.iter().zip(&q).map(|(a, b)| a + b).collect();
            }
            let var = 4.0 * p[(n - 1) * n + n - 1];
            // ∫_{−∞}^{∞} df / (1 + (f/fc)^{2n}) = 2 fc · (π/2n)/sin(π/2n)
            let x = std::f64::consts::PI / (2 * n) as f64;
            let want = 2.0 * 150.0 * x / x.sin();
            assert!((var / want - 1.0).abs() < 1e-9, "n {n}: {var} vs {want}");
        }
    }

    fn transpose(a: &[f64], n: usize) -> Vec<f64> {
        let mut t = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                t[j * n + i] = a[i * n + j];
            }
        }
        t
    }
}
