//! The analog lock-in front end of the simulated gyro: mixers, Butterworth low-pass,
//! 500 Hz sampling.
//!
//! # What is modelled
//!
//! A real lock-in multiplies the measured displacement `Xm` (and `Ym`) by the
//! reference `2·e^{−ikψ}` (k = 1, 2, 3) and by 1 (DC), filters every product with the
//! same analog Butterworth low-pass and lets the firmware sample the filter outputs at
//! 500 Hz. That gives 14 real channels ([`CHANNEL_NAMES`]):
//! `X0 = LP[Xm]`, `A_k = LP[2·Xm·e^{−ikψ}]`, and the same for `Y` (`Y0`, `B_k`), so that
//! `X ≈ X0 + Σ Re(A_k e^{ikψ})` (DERIVATION.md §1, §5).
//!
//! # How the analog filter is integrated (block moments)
//!
//! The mixer products are known only at the fine RK4 grid `s_j = j·h` of the plant
//! (about 128 points per carrier period). Updating an exactly discretised 4-state filter
//! for 14 channels at every fine step would cost more than the plant itself, so the
//! filter is advanced once per *block* of `m` fine steps (`T = m·h`; the plant uses
//! `m` = 32, a quarter of a carrier period, while the filter time constant is ~70 τ):
//!
//! ```text
//! x(T) = e^{AT} x(0) + ∫₀ᵀ e^{A(T−s)} B u(s) ds
//! ```
//!
//! The kernel `e^{A(T−s)}B` is smooth on the block (`‖A‖T ≈ 0.04`), so it is replaced by
//! a polynomial of degree `NMOM − 1` = 3 in `s`. Then the integral only needs four
//! weighted sums of the samples, and those are accumulated with **running sums only**
//! (no multiplications): `S0 += u; S1 += S0; S2 += S1; S3 += S2`, with the two samples
//! at the block edges weighted by ½ (trapezoid). Once per block the state is updated
//! with `x ← Φ x + G·S` (`Φ = e^{AT}`).
//!
//! `G` is not a truncated Taylor series: it is *fitted* at build time so that the block
//! update reproduces the trapezoid rule applied to the **exact** kernel for every
//! polynomial input of degree ≤ 3 (a discrete least-squares projection of the kernel
//! onto cubics). Why the trapezoid rule and not the exact integral: the composite
//! trapezoid error of the convolution telescopes to end terms `h²/12·C·(d/ds)[e^{A(t−s)}Bu]`
//! which vanish at the output because `C·B = C·A·B = 0` (relative degree ≥ 2), leaving
//! `O(h⁴)`; matching the exact integral instead would bend the weights of the
//! `B`-direction by `O(h²/T²)` across the block, and an input at the block rate `2π/T`
//! (4ω here, present in the 3rd-harmonic mixer) would then leak straight to DC (1e-3!).
//! Measured by the tests (4th order, 150 Hz, 128 steps/period, m = 4, 8, 16 and 32):
//!
//! * slowly varying inputs (DC … 120 Hz) match the true continuous filter to ≲ 4e-13
//!   of their amplitude;
//! * carrier components (ω/2 … 9ω, and exactly the block rate and twice it) pass with
//!   the true filter's attenuation to within ≲ 2e-11 of their amplitude, far below the
//!   filter's own stop-band rejection (3.7e-8 at ω, 2.3e-9 at 2ω).
//!
//! Cost per fine step: 4 adds per channel; per block: `n² + 4n` multiply-adds per
//! channel.
//!
//! # Realisation
//!
//! [`butterworth_ss`] builds a cascade of second-order sections (and one first-order
//! section for odd orders) with the states scaled to the signal (`q`, `q'/w_c`), so that
//! every state is of the order of the input and the DC gain is exactly 1.

/// Number of real lock-in channels (X0, A1..A3 re/im, Y0, B1..B3 re/im).
pub const NCH: usize = 14;

/// Largest supported low-pass order.
pub const MAX_LPF_ORDER: usize = 8;

/// Number of block moments (polynomial degree of the block kernel + 1).
const NMOM: usize = 4;

/// Channel names in the order of [`LockinExt::to_channels`] (same as the prototype's
/// `CH_NAMES[0..14]`).
pub const CHANNEL_NAMES: [&str; NCH] = [
    "X0", "A1r", "A1i", "A2r", "A2i", "A3r", "A3i", "Y0", "B1r", "B1i", "B2r", "B2i", "B3r", "B3i",
];

pub use paragyro_core::Lockin;
use paragyro_core::{Cplx, Real};

/// The host's one lock-in channel type: the core's [`Lockin`] in `f64`, the 14 outputs at
/// one sampling instant in µm (the simulator's length unit L0 is 1 µm): `x0_um = X0 =
/// LP[Xm]`, `x_um[k−1] = A_k = LP[2·Xm·e^{−ikψ}]` (k = 1, 2, 3), the same for Y. The
/// simulated plant produces it, a record row holds it, the core takes it in its own
/// precision ([`LockinExt::to_precision`]); the conversions to and from the 14 real
/// channels ([`CHANNEL_NAMES`] order, which is also the record's column order) are here.
pub type LockinOut = Lockin<f64>;

/// The conversions of the host lock-in type ([`LockinOut`]), in one place.
pub trait LockinExt: Sized {
    /// Builds the output from the 14 channels in [`CHANNEL_NAMES`] order.
    fn from_channels(ch: &[f64; NCH]) -> Self;
    /// The 14 channels in [`CHANNEL_NAMES`] order.
    fn to_channels(&self) -> [f64; NCH];
    /// Magnitude `|A_k|` of the drive harmonic `k` (1..=3; `NaN` otherwise).
    fn x_abs(&self, k: usize) -> f64;
    /// Magnitude `|B_k|` of the sense harmonic `k` (1..=3; `NaN` otherwise).
    fn y_abs(&self, k: usize) -> f64;
    /// The core's input in precision `T` (each channel rounded once from `f64`).
    fn to_precision<T: Real>(&self) -> Lockin<T>;
}

/// `|z|` as `hypot` (the simulator's amplitudes; `Cplx::abs` squares first).
fn harmonic_abs(h: &[Cplx<f64>; 3], k: usize) -> f64 {
    match k.checked_sub(1).and_then(|i| h.get(i)) {
        Some(z) => z.re.hypot(z.im),
        None => f64::NAN,
    }
}

impl LockinExt for Lockin<f64> {
    fn from_channels(ch: &[f64; NCH]) -> Self {
        let c = |i: usize| Cplx::new(ch[i], ch[i + 1]);
        Lockin {
            x0_um: ch[0],
            x_um: [c(1), c(3), c(5)],
            y0_um: ch[7],
            y_um: [c(8), c(10), c(12)],
        }
    }

    fn to_channels(&self) -> [f64; NCH] {
        let (x, y) = (&self.x_um, &self.y_um);
        [
            self.x0_um, x[0].re, x[0].im, x[1].re, x[1].im, x[2].re, x[2].im, self.y0_um, y[0].re,
            y[0].im, y[1].re, y[1].im, y[2].re, y[2].im,
        ]
    }

    fn x_abs(&self, k: usize) -> f64 {
        harmonic_abs(&self.x_um, k)
    }

    fn y_abs(&self, k: usize) -> f64 {
        harmonic_abs(&self.y_um, k)
    }

    fn to_precision<T: Real>(&self) -> Lockin<T> {
        let c = |z: Cplx<f64>| Cplx::new(T::from_f64(z.re), T::from_f64(z.im));
        Lockin {
            x0_um: T::from_f64(self.x0_um),
            x_um: self.x_um.map(c),
            y0_um: T::from_f64(self.y0_um),
            y_um: self.y_um.map(c),
        }
    }
}

/// The 14 mixer products (the low-pass inputs) of the measured displacements `xm`, `ym`
/// for the reference phasor `e^{iψ} = c1 + i·s1`, in [`CHANNEL_NAMES`] order:
/// `[Xm, 2Xm cosψ, −2Xm sinψ, 2Xm cos2ψ, −2Xm sin2ψ, 2Xm cos3ψ, −2Xm sin3ψ, Ym, …]`.
///
/// `c1² + s1²` is assumed to be 1 (the harmonics are formed by complex products).
#[inline(always)]
pub fn mixer_products(xm: f64, ym: f64, c1: f64, s1: f64) -> [f64; NCH] {
    let c2 = c1 * c1 - s1 * s1;
    let s2 = 2.0 * c1 * s1;
    let c3 = c2 * c1 - s2 * s1;
    let s3 = s2 * c1 + c2 * s1;
    let tx = 2.0 * xm;
    let ty = 2.0 * ym;
    [
        xm,
        tx * c1,
        -tx * s1,
        tx * c2,
        -tx * s2,
        tx * c3,
        -tx * s3,
        ym,
        ty * c1,
        -ty * s1,
        ty * c2,
        -ty * s2,
        ty * c3,
        -ty * s3,
    ]
}

/// Analog Butterworth low-pass of order `order` (1..=[`MAX_LPF_ORDER`]) and cut-off
/// `wc` (rad per time unit; in this crate rad/τ) as a state-space model `(A, B, C)`:
/// `x' = A x + B u`, `y = C x`, with unit DC gain.
///
/// Realisation: cascade of second-order sections `q' = wc·r`,
/// `r' = wc·(v − q − 2ζ_k r)` with `ζ_k = sin(π(2k−1)/(2n))` (plus `q' = wc·(v − q)` for
/// odd orders), where `v` is the previous section's `q` (the input `u` for the first
/// section) and the output is the last section's `q`. `A` is returned as rows.
///
/// # Panics
/// If `order` is 0 or larger than [`MAX_LPF_ORDER`], or `wc` is not positive and finite.
pub fn butterworth_ss(order: usize, wc: f64) -> (Vec<Vec<f64>>, Vec<f64>, Vec<f64>) {
    assert!(
        (1..=MAX_LPF_ORDER).contains(&order),
        "butterworth_ss: order {order} not in 1..={MAX_LPF_ORDER}"
    );
    assert!(
        wc.is_finite() && wc > 0.0,
        "butterworth_ss: wc = {wc} must be > 0"
    );
    let n = order;
    let mut a = vec![vec![0.0; n]; n];
    let mut b = vec![0.0; n];
    let mut c = vec![0.0; n];
    let mut prev: Option<usize> = None; // state index of the previous section's output
    let mut idx = 0;
    for k in 1..=n / 2 {
        let zeta = (std::f64::consts::PI * (2 * k - 1) as f64 / (2 * n) as f64).sin();
        let (q, r) = (idx, idx + 1);
        idx += 2;
        a[q][r] = wc;
        a[r][q] = -wc;
        a[r][r] = -2.0 * zeta * wc;
        match prev {
            None => b[r] = wc,
            Some(p) => a[r][p] = wc,
        }
        prev = Some(q);
    }
    if n % 2 == 1 {
        let q = idx;
        a[q][q] = -wc;
        match prev {
            None => b[q] = wc,
            Some(p) => a[q][p] = wc,
        }
        prev = Some(q);
    }
    c[prev.expect("order >= 1")] = 1.0;
    (a, b, c)
}

/// Frequency response `H(iw) = C (iw·I − A)⁻¹ B` of a single-input single-output
/// state-space model, as (re, im). `A` is given as rows (as returned by
/// [`butterworth_ss`]). Used to check a realisation against the analytic filter.
///
/// # Panics
/// If the dimensions of `a`, `b`, `c` disagree or `iw·I − A` is singular.
pub fn ss_freq_response(a: &[Vec<f64>], b: &[f64], c: &[f64], w: f64) -> (f64, f64) {
    let n = a.len();
    assert!(b.len() == n && c.len() == n && a.iter().all(|r| r.len() == n));
    // complex Gaussian elimination on [iwI − A | B], (re, im) pairs
    let mut m: Vec<Vec<(f64, f64)>> = (0..n)
        .map(|i| {
            let mut row: Vec<(f64, f64)> = (0..n)
                .map(|j| (-a[i][j], if i == j { w } else { 0.0 }))
                .collect();
            row.push((b[i], 0.0));
            row
        })
        .collect();
    let cmul = |x: (f64, f64), y: (f64, f64)| (x.0 * y.0 - x.1 * y.1, x.0 * y.1 + x.1 * y.0);
    let cdiv = |x: (f64, f64), y: (f64, f64)| {
        let d = y.0 * y.0 + y.1 * y.1;
        ((x.0 * y.0 + x.1 * y.1) / d, (x.1 * y.0 - x.0 * y.1) / d)
    };
    for col in 0..n {
        let piv = (col..n)
            .max_by(|&i, &j| {
                m[i][col]
                    .0
                    .hypot(m[i][col].1)
                    .total_cmp(&m[j][col].0.hypot(m[j][col].1))
            })
            .expect("non-empty");
        m.swap(col, piv);
        let p = m[col][col];
        assert!(
            p.0.hypot(p.1) > 0.0,
            "ss_freq_response: singular at w = {w}"
        );
        let pivot = m[col].clone();
        for (i, row) in m.iter_mut().enumerate() {
            if i != col {
                let f = cdiv(row[col], p);
                for (dst, src) in row[col..].iter_mut().zip(&pivot[col..]) {
                    let t = cmul(f, *src);
                    dst.0 -= t.0;
                    dst.1 -= t.1;
                }
            }
        }
    }
    let mut h = (0.0, 0.0);
    for i in 0..n {
        let xi = cdiv(m[i][n], m[i][i]);
        h.0 += c[i] * xi.0;
        h.1 += c[i] * xi.1;
    }
    h
}

/// Frequency response `H(iw)` of the analog Butterworth low-pass of order `order` and
/// cut-off `wc`, from its poles `p_k = wc·e^{iπ(2k+n−1)/(2n)}`: `H(s) = Π (−p_k)/(s − p_k)`.
/// Independent of any realisation; returns (re, im).
pub fn butterworth_response(order: usize, wc: f64, w: f64) -> (f64, f64) {
    let n = order as f64;
    let mut h = (1.0, 0.0);
    for k in 1..=order {
        let ang = std::f64::consts::PI * (2.0 * k as f64 + n - 1.0) / (2.0 * n);
        let p = (wc * ang.cos(), wc * ang.sin());
        // (−p) / (iw − p)
        let num = (-p.0, -p.1);
        let den = (-p.0, w - p.1);
        let d = den.0 * den.0 + den.1 * den.1;
        let q = (
            (num.0 * den.0 + num.1 * den.1) / d,
            (num.1 * den.0 - num.0 * den.1) / d,
        );
        h = (h.0 * q.0 - h.1 * q.1, h.0 * q.1 + h.1 * q.0);
    }
    h
}

// ---------------------------------------------------------------------------------------
// small dense linear algebra for the build-time design (f64, allocation is fine here)

type Mat = Vec<Vec<f64>>;

fn mat_mul(a: &Mat, b: &Mat) -> Mat {
    let (n, k, m) = (a.len(), b.len(), b[0].len());
    let mut c = vec![vec![0.0; m]; n];
    for i in 0..n {
        for p in 0..k {
            let aip = a[i][p];
            if aip != 0.0 {
                for j in 0..m {
                    c[i][j] += aip * b[p][j];
                }
            }
        }
    }
    c
}

fn norm_inf(a: &Mat) -> f64 {
    a.iter()
        .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// Matrix exponential by scaling and squaring with a Taylor series (‖A/2^s‖ ≤ 1/2,
/// terms until they no longer change the sum): relative accuracy ~1e-15 for the small
/// well-conditioned matrices of this module.
fn expm(a: &Mat) -> Mat {
    let n = a.len();
    let nrm = norm_inf(a);
    let s = if nrm > 0.5 {
        (nrm / 0.5).log2().ceil() as i32
    } else {
        0
    };
    let scale = 0.5f64.powi(s);
    let x: Mat = a
        .iter()
        .map(|r| r.iter().map(|v| v * scale).collect())
        .collect();
    let mut sum: Mat = (0..n)
        .map(|i| (0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
        .collect();
    let mut term = sum.clone();
    for k in 1..=40 {
        term = mat_mul(&term, &x);
        let inv = 1.0 / k as f64;
        term.iter_mut().flatten().for_each(|v| *v *= inv);
        for i in 0..n {
            for j in 0..n {
                sum[i][j] += term[i][j];
            }
        }
        if norm_inf(&term) <= 1e-20 * norm_inf(&sum) {
            break;
        }
    }
    for _ in 0..s {
        sum = mat_mul(&sum, &sum);
    }
    sum
}

/// Inverse of a small square matrix (Gauss–Jordan, partial pivoting).
fn mat_inv(a: &Mat) -> Result<Mat, String> {
    let n = a.len();
    let mut m: Mat = a
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let mut row = r.clone();
            row.extend((0..n).map(|j| if i == j { 1.0 } else { 0.0 }));
            row
        })
        .collect();
    for col in 0..n {
        let piv = (col..n)
            .max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))
            .expect("non-empty");
        if m[piv][col].abs() < 1e-300 {
            return Err("singular moment matrix".into());
        }
        m.swap(col, piv);
        let p = m[col][col];
        m[col].iter_mut().for_each(|v| *v /= p);
        let pivot = m[col].clone();
        for (i, row) in m.iter_mut().enumerate() {
            let f = row[col];
            if i != col && f != 0.0 {
                for (dst, src) in row.iter_mut().zip(&pivot) {
                    *dst -= f * src;
                }
            }
        }
    }
    Ok(m.into_iter().map(|r| r[n..].to_vec()).collect())
}

// ---------------------------------------------------------------------------------------
// running-sum moment accumulators (one lane per channel); the same code computes the
// build-time functionals, so the fit and the hot path cannot disagree.

type Sums = [[f64; NCH]; NMOM];

/// Expands `$body` once per channel with `$c` bound to the literal channel index, so the
/// per-sample work is straight-line code at every optimisation level (no loop, no
/// bounds check; the compiler pairs neighbouring lanes into SIMD).
macro_rules! for_each_channel {
    ($c:ident => $body:block) => {
        for_each_channel!(@ $c $body [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13])
    };
    (@ $c:ident $body:block [$($i:literal),*]) => {
        $( { let $c: usize = $i; $body } )*
    };
}

/// First sample of a block (weight ½): the sums restart from `u/2`.
#[inline(always)]
fn sums_start(s: &mut Sums, u: &[f64; NCH]) {
    let [s0, s1, s2, s3] = s;
    for_each_channel!(c => {
        let half = 0.5 * u[c];
        s0[c] = half;
        s1[c] = half;
        s2[c] = half;
        s3[c] = half;
    });
}

/// An interior sample: `S0 += u; S1 += S0; S2 += S1; S3 += S2`.
#[inline(always)]
fn sums_push(s: &mut Sums, u: &[f64; NCH]) {
    let [s0, s1, s2, s3] = s;
    for_each_channel!(c => {
        s0[c] += u[c];
        s1[c] += s0[c];
        s2[c] += s1[c];
        s3[c] += s2[c];
    });
}

/// Last sample of a block (weight ½; its polynomial weight is 0 in S1..S3).
#[inline(always)]
fn sums_end(s: &mut Sums, u: &[f64; NCH]) {
    let s0 = &mut s[0];
    for_each_channel!(c => {
        s0[c] += 0.5 * u[c];
    });
}

/// Filter design of a [`BlockLpf`] (immutable after build).
#[derive(Clone, Debug)]
struct BlockDesign {
    n: usize,
    /// `e^{A T}` for the block length `T`.
    phi: [[f64; MAX_LPF_ORDER]; MAX_LPF_ORDER],
    /// Moment gains: `x ← Φx + Σ_k g[r][k]·S_k`.
    g: [[f64; NMOM]; MAX_LPF_ORDER],
    /// Output row.
    c: [f64; MAX_LPF_ORDER],
}

/// A bank of [`NCH`] identical analog low-pass filters driven by samples on a uniform
/// fine grid (step `h`) and advanced exactly once per block of `m` fine steps (see the
/// module documentation for the scheme and its accuracy).
///
/// Protocol per block of samples `u_0 … u_m` (`u_m` is the next block's `u_0`):
/// [`start`](Self::start)`(u_0)` once at the very beginning, then
/// [`push`](Self::push)`(u_j)` for `j = 1 … m−1`, then
/// [`finish_block`](Self::finish_block)`(u_m)`, which advances the filters by `T = m·h`
/// and starts the next block. [`output`](Self::output) is valid after `finish_block`
/// (and at the very start), i.e. at block boundaries.
#[derive(Clone, Debug)]
pub struct BlockLpf {
    d: BlockDesign,
    m: usize,
    /// Filter states, `x[r][channel]`.
    x: [[f64; NCH]; MAX_LPF_ORDER],
    sums: Sums,
}

impl BlockLpf {
    /// Builds the bank for a Butterworth low-pass of order `order` and cut-off `wc`
    /// (rad per time unit), fine step `h` and block length `m` fine steps (≥ 4).
    /// The filters start at rest (zero state).
    ///
    /// Errors if an argument is out of range, or if `wc·m·h > 0.1` (the block would no
    /// longer be short against the filter time constant; the accuracy quoted in the
    /// module documentation holds at `wc·m·h ≈ 0.02` and degrades roughly as `(wc·m·h)⁴`).
    pub fn new(order: usize, wc: f64, h: f64, m: usize) -> Result<Self, String> {
        if !(1..=MAX_LPF_ORDER).contains(&order) {
            return Err(format!("lpf order {order} not in 1..={MAX_LPF_ORDER}"));
        }
        if !(wc.is_finite() && wc > 0.0) {
            return Err(format!(
                "lpf cut-off {wc} rad/τ must be positive and finite"
            ));
        }
        if !(h.is_finite() && h > 0.0) {
            return Err(format!("fine step h = {h} must be positive and finite"));
        }
        if m < NMOM {
            return Err(format!("block length {m} must be ≥ {NMOM}"));
        }
        let t = m as f64 * h;
        if wc * t > 0.1 {
            return Err(format!(
                "lpf cut-off too high for the block: wc·T = {:.3} > 0.1",
                wc * t
            ));
        }
        let (a, b, c) = butterworth_ss(order, wc);
        let n = order;
        let scaled = |k: f64| -> Mat {
            a.iter()
                .map(|r| r.iter().map(|v| v * k).collect())
                .collect()
        };
        let e = expm(&scaled(t)); // Φ = e^{AT}
        let phi_h = expm(&scaled(h));
        // exact kernel on the fine grid: E_j = e^{A(T − s_j)} B, s_j = j·h
        let mut kern = vec![vec![0.0; n]; m + 1];
        kern[m].copy_from_slice(&b);
        for j in (0..m).rev() {
            for r in 0..n {
                kern[j][r] = (0..n).map(|q| phi_h[r][q] * kern[j + 1][q]).sum();
            }
        }
        // target responses R[r][q] = Σ_j w_j E_j s_j^q/q! with trapezoid weights w_j: the
        // update reproduces the trapezoid rule on the exact kernel for every polynomial
        // input of degree ≤ 3. (Matching the exact integral instead would bend the
        // B-direction weights by O(h²/T²) inside the block, and an input at the block
        // rate 2π/T would then leak straight to DC; with the trapezoid the composite
        // error telescopes to O(h⁴) at the output, because C·B = C·A·B = 0.)
        let fact = |q: usize| (1..=q).map(|i| i as f64).product::<f64>();
        let mut resp = vec![vec![0.0; NMOM]; n];
        for (j, kj) in kern.iter().enumerate() {
            let wj = if j == 0 || j == m { 0.5 * h } else { h };
            let sj = j as f64 * h;
            for (r, row) in resp.iter_mut().enumerate() {
                for (q, v) in row.iter_mut().enumerate() {
                    *v += wj * kj[r] * sj.powi(q as i32) / fact(q);
                }
            }
        }
        // functionals F[k][j] of the hot-path accumulators, by feeding impulses
        let f: Vec<Vec<f64>> = {
            let cols: Vec<[f64; NMOM]> = (0..=m)
                .map(|j| {
                    let mut s: Sums = [[0.0; NCH]; NMOM];
                    let imp = |i: usize| {
                        let mut u = [0.0; NCH];
                        if i == j {
                            u[0] = 1.0;
                        }
                        u
                    };
                    sums_start(&mut s, &imp(0));
                    for i in 1..m {
                        sums_push(&mut s, &imp(i));
                    }
                    sums_end(&mut s, &imp(m));
                    std::array::from_fn(|k| s[k][0])
                })
                .collect();
            (0..NMOM)
                .map(|k| cols.iter().map(|c| c[k]).collect())
                .collect()
        };
        // L[k][q] = Σ_j F[k][j] s_j^q/q!, s_j = j·h (the same polynomials as `resp`)
        let mut l = vec![vec![0.0; NMOM]; NMOM];
        for (k, lrow) in l.iter_mut().enumerate() {
            for (q, v) in lrow.iter_mut().enumerate() {
                *v = (0..=m)
                    .map(|j| f[k][j] * (j as f64 * h).powi(q as i32) / fact(q))
                    .sum();
            }
        }
        // G L = R  ⇒  G = R L⁻¹
        let g = mat_mul(&resp, &mat_inv(&l)?);
        let mut d = BlockDesign {
            n,
            phi: [[0.0; MAX_LPF_ORDER]; MAX_LPF_ORDER],
            g: [[0.0; NMOM]; MAX_LPF_ORDER],
            c: [0.0; MAX_LPF_ORDER],
        };
        for r in 0..n {
            d.phi[r][..n].copy_from_slice(&e[r][..n]);
            d.g[r][..NMOM].copy_from_slice(&g[r][..NMOM]);
        }
        d.c[..n].copy_from_slice(&c);
        Ok(Self {
            d,
            m,
            x: [[0.0; NCH]; MAX_LPF_ORDER],
            sums: [[0.0; NCH]; NMOM],
        })
    }

    /// Block length in fine steps.
    pub fn block_len(&self) -> usize {
        self.m
    }

    /// Filter order.
    pub fn order(&self) -> usize {
        self.d.n
    }

    /// Starts the very first block with its first sample `u_0`.
    #[inline]
    pub fn start(&mut self, u: &[f64; NCH]) {
        sums_start(&mut self.sums, u);
    }

    /// Adds the [`mixer_products`] of `xm`, `ym` at the reference phasor `c1 + i·s1` as an
    /// interior sample of the current block: [`Self::push`] of them, bit for bit.
    ///
    /// Out of line on purpose (the plant's loop calls it once per RK4 step): inlined into
    /// the loop, the 56 running sums were kept in registers across the block and spilled,
    /// each stored twice per step, and the step took ~40 % longer (`release`, opt-level
    /// "s"); behind a call they stay in memory, one add and one store each.
    #[inline(never)]
    pub fn push_mixed(&mut self, xm: f64, ym: f64, c1: f64, s1: f64) {
        sums_push(&mut self.sums, &mixer_products(xm, ym, c1, s1));
    }

    /// [`Self::push_mixed`], its AVX2 build inside the plant's AVX2 loop (`SIMD`,
    /// [`crate::simd`]).
    #[inline(always)]
    pub(crate) fn push_mixed_in<const SIMD: bool>(&mut self, xm: f64, ym: f64, c1: f64, s1: f64) {
        #[cfg(target_arch = "x86_64")]
        if SIMD {
            // SAFETY: `SIMD` only inside the plant's AVX2 loop, which runs where the CPU
            // has AVX2 and FMA
            #[allow(unsafe_code)]
            unsafe {
                self.push_mixed_avx2(xm, ym, c1, s1)
            };
            return;
        }
        self.push_mixed(xm, ym, c1, s1);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline(never)]
    fn push_mixed_avx2(&mut self, xm: f64, ym: f64, c1: f64, s1: f64) {
        sums_push(&mut self.sums, &mixer_products(xm, ym, c1, s1));
    }

    /// Adds an interior sample of the current block.
    #[inline(always)]
    pub fn push(&mut self, u: &[f64; NCH]) {
        sums_push(&mut self.sums, u);
    }

    /// Adds the last sample `u_m` of the block, advances all filters by one block and
    /// starts the next block with the same sample.
    #[inline]
    pub fn finish_block(&mut self, u: &[f64; NCH]) {
        sums_end(&mut self.sums, u);
        let d = &self.d;
        let n = d.n;
        let mut xn = [[0.0; NCH]; MAX_LPF_ORDER];
        for (r, out) in xn[..n].iter_mut().enumerate() {
            let [g0, g1, g2, g3] = d.g[r];
            let [s0, s1, s2, s3] = &self.sums;
            for_each_channel!(c => {
                out[c] = (g0 * s0[c] + g1 * s1[c]) + (g2 * s2[c] + g3 * s3[c]);
            });
            for q in 0..n {
                let p = d.phi[r][q];
                let xq = &self.x[q];
                for_each_channel!(c => {
                    out[c] += p * xq[c];
                });
            }
        }
        self.x = xn;
        sums_start(&mut self.sums, u);
    }

    /// Filter outputs `y = C x` of all channels (valid at block boundaries).
    pub fn output(&self) -> [f64; NCH] {
        let mut y = [0.0; NCH];
        for (r, xr) in self.x.iter().enumerate().take(self.d.n) {
            let c = self.d.c[r];
            if c != 0.0 {
                for ch in 0..NCH {
                    y[ch] += c * xr[ch];
                }
            }
        }
        y
    }

    /// Resets all filter states to rest and clears the current block.
    pub fn reset(&mut self) {
        self.x = [[0.0; NCH]; MAX_LPF_ORDER];
        self.sums = [[0.0; NCH]; NMOM];
    }
}

#[cfg(test)]
mod tests;
