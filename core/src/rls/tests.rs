//! Host tests of the Bierman-UD RLS: batch least squares, a-priori innovation, f32 on
//! ill-conditioned rows against the covariance form, windup, guards; property tests
//! against a nalgebra oracle (`props`).
#![allow(clippy::needless_range_loop)] // dense matrix algebra in the test oracles

extern crate std;
use super::*;
use std::vec::Vec;

/// xorshift64* — tiny deterministic RNG for the tests.
struct Rng(u64);
impl Rng {
    fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in [−1, 1).
    fn uni(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
    /// Standard normal (Box–Muller).
    fn gauss(&mut self) -> f64 {
        let u1 = ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
        let u2 = (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        libm::sqrt(-2.0 * libm::log(u1)) * libm::cos(2.0 * core::f64::consts::PI * u2)
    }
}

/// Lower Cholesky factor, `None` unless the matrix is symmetric positive definite
/// (every pivot > 0 and finite).
fn cholesky<const N: usize>(a: &[[f64; N]; N]) -> Option<[[f64; N]; N]> {
    let mut l = [[0.0; N]; N];
    for j in 0..N {
        let mut d = a[j][j];
        for k in 0..j {
            d -= l[j][k] * l[j][k];
        }
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        let djj = libm::sqrt(d);
        l[j][j] = djj;
        for i in j + 1..N {
            let mut s = a[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            l[i][j] = s / djj;
        }
    }
    Some(l)
}

fn chol_solve<const N: usize>(l: &[[f64; N]; N], b: &[f64; N]) -> [f64; N] {
    let mut z = [0.0; N];
    for i in 0..N {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i][k] * z[k];
        }
        z[i] = s / l[i][i];
    }
    let mut x = [0.0; N];
    for i in (0..N).rev() {
        let mut s = z[i];
        for k in i + 1..N {
            s -= l[k][i] * x[k];
        }
        x[i] = s / l[i][i];
    }
    x
}

fn inverse_spd<const N: usize>(a: &[[f64; N]; N]) -> [[f64; N]; N] {
    let l = cholesky(a).expect("information matrix must be SPD");
    let mut inv = [[0.0; N]; N];
    for j in 0..N {
        let mut e = [0.0; N];
        e[j] = 1.0;
        let c = chol_solve(&l, &e);
        for i in 0..N {
            inv[i][j] = c[i];
        }
    }
    inv
}

fn to_f64_mat<T: Real, const N: usize>(p: &[[T; N]; N]) -> [[f64; N]; N] {
    let mut out = [[0.0; N]; N];
    for i in 0..N {
        for j in 0..N {
            out[i][j] = p[i][j].to_f64();
        }
    }
    out
}

fn cast_vec<T: Real, const N: usize>(v: &[f64; N]) -> [T; N] {
    let mut out = [T::ZERO; N];
    for (o, x) in out.iter_mut().zip(v) {
        *o = T::from_f64(*x);
    }
    out
}

fn norm<const N: usize>(v: &[f64; N]) -> f64 {
    libm::sqrt(v.iter().map(|x| x * x).sum())
}

fn max_abs<const N: usize>(a: &[[f64; N]; N]) -> f64 {
    a.iter().flatten().fold(0.0, |m: f64, x| m.max(x.abs()))
}

fn unbounded<T: Real>(lambda: f64, p0: f64) -> RlsSettings<T> {
    RlsSettings::new(
        T::from_f64(lambda),
        T::from_f64(p0),
        T::from_f64(f64::INFINITY),
    )
    .unwrap()
}

/// f64 RLS vs the exact minimiser of
/// Σ_k λ^(n−k) Σ_rows (y − φᵀx)² + λ^n xᵀ(p0·I)⁻¹x and its inverse Hessian.
fn batch_case<const N: usize>(lambda: f64, seed: u64) -> (f64, f64) {
    const SAMPLES: usize = 400;
    const ROWS: usize = 2;
    let p0 = 1e6;
    let mut rng = Rng::new(seed);
    let mut x_true = [0.0; N];
    for x in x_true.iter_mut() {
        *x = 2.0 * rng.uni();
    }
    let mut rls: Rls<f64, N> = Rls::new(unbounded(lambda, p0));
    // information matrix and vector, recursively weighted
    let mut a = [[0.0; N]; N];
    for (i, row) in a.iter_mut().enumerate() {
        row[i] = 1.0 / p0;
    }
    let mut b = [0.0; N];
    for _ in 0..SAMPLES {
        assert!(rls.begin_sample());
        for row in a.iter_mut() {
            for v in row.iter_mut() {
                *v *= lambda;
            }
        }
        for v in b.iter_mut() {
            *v *= lambda;
        }
        for _ in 0..ROWS {
            let mut phi = [0.0; N];
            for p in phi.iter_mut() {
                *p = rng.uni();
            }
            let y = phi.iter().zip(&x_true).map(|(p, x)| p * x).sum::<f64>() + 0.1 * rng.gauss();
            let inn = rls.update(&phi, y);
            assert!(inn.is_applied());
            for i in 0..N {
                b[i] += phi[i] * y;
                for j in 0..N {
                    a[i][j] += phi[i] * phi[j];
                }
            }
        }
    }
    let l = cholesky(&a).unwrap();
    let x_ref = chol_solve(&l, &b);
    let p_ref = inverse_spd(&a);
    let x = rls.estimate();
    let mut dx = [0.0; N];
    for i in 0..N {
        dx[i] = x[i] - x_ref[i];
    }
    let p = rls.covariance();
    let mut dp = [[0.0; N]; N];
    for i in 0..N {
        for j in 0..N {
            dp[i][j] = p[i][j] - p_ref[i][j];
        }
    }
    assert_eq!(rls.stats().updates, (SAMPLES * ROWS) as u64);
    assert_eq!(rls.stats().forgetting_skipped, 0);
    (norm(&dx) / norm(&x_ref), max_abs(&dp) / max_abs(&p_ref))
}

#[test]
fn f64_rls_equals_batch_weighted_least_squares() {
    for (k, lambda) in [0.999, 1.0].into_iter().enumerate() {
        let (ex8, ep8) = batch_case::<8>(lambda, 11 + k as u64);
        let (ex6, ep6) = batch_case::<6>(lambda, 23 + k as u64);
        std::println!(
            "λ={lambda}: N=8 x rel {ex8:.2e} P rel {ep8:.2e}; N=6 x rel {ex6:.2e} P rel {ep6:.2e}"
        );
        assert!(ex8 < 1e-9 && ex6 < 1e-9, "estimate differs from batch LS");
        assert!(
            ep8 < 1e-8 && ep6 < 1e-8,
            "P differs from inverse information"
        );
    }
}

#[test]
fn innovation_and_variance_factor_are_a_priori() {
    let mut rng = Rng::new(5);
    let mut rls: Rls<f64, 6> = Rls::new(RlsSettings::default());
    for n in 0..200 {
        rls.begin_sample();
        let mut phi = [0.0; 6];
        for p in phi.iter_mut() {
            *p = rng.uni();
        }
        let y = phi[0] - 0.5 * phi[3] + 0.01 * rng.gauss();
        let x = rls.estimate();
        let p = rls.covariance();
        let e_ref = y - phi.iter().zip(&x).map(|(a, b)| a * b).sum::<f64>();
        let mut s_ref = 1.0;
        for i in 0..6 {
            for j in 0..6 {
                s_ref += phi[i] * p[i][j] * phi[j];
            }
        }
        let inn = rls.update(&phi, y);
        assert!(inn.is_applied());
        assert!(
            (inn.e - e_ref).abs() <= 1e-12 * (1.0 + e_ref.abs()),
            "n={n}"
        );
        assert!(
            (inn.s - s_ref).abs() <= 1e-10 * s_ref,
            "n={n}: {} vs {s_ref}",
            inn.s
        );
        assert!(
            (inn.normalized_sq() - e_ref * e_ref / s_ref).abs()
                <= 1e-9 * (1.0 + inn.normalized_sq())
        );
    }
}

/// Ill-conditioned rows: column scales 1e-6 … 1e3 (log-spaced) and strongly
/// correlated columns (99.9 % common component), like the drive rows.
fn ill_row(rng: &mut Rng) -> [f64; 8] {
    let common = rng.gauss();
    let mut phi = [0.0; 8];
    for (i, p) in phi.iter_mut().enumerate() {
        let scale = libm::pow(10.0, -6.0 + 9.0 * i as f64 / 7.0);
        *p = scale * (0.999 * common + 0.001 * rng.gauss());
    }
    phi
}

/// Plain covariance-form RLS in f32 (the textbook form, symmetrised each update).
struct CovRls {
    x: [f32; 8],
    p: [[f32; 8]; 8],
}
impl CovRls {
    fn new(p0: f32) -> Self {
        let mut p = [[0.0; 8]; 8];
        for (i, row) in p.iter_mut().enumerate() {
            row[i] = p0;
        }
        CovRls { x: [0.0; 8], p }
    }
    fn step(&mut self, lambda: f32, phi: &[f32; 8], y: f32) {
        for row in self.p.iter_mut() {
            for v in row.iter_mut() {
                *v /= lambda;
            }
        }
        let mut pphi = [0.0f32; 8];
        for i in 0..8 {
            for j in 0..8 {
                pphi[i] += self.p[i][j] * phi[j];
            }
        }
        let den = 1.0 + phi.iter().zip(&pphi).map(|(a, b)| a * b).sum::<f32>();
        let e = y - phi.iter().zip(&self.x).map(|(a, b)| a * b).sum::<f32>();
        for i in 0..8 {
            let k = pphi[i] / den;
            self.x[i] += k * e;
            for j in 0..8 {
                self.p[i][j] -= k * pphi[j];
            }
        }
        for i in 0..8 {
            for j in i + 1..8 {
                let s = 0.5 * (self.p[i][j] + self.p[j][i]);
                self.p[i][j] = s;
                self.p[j][i] = s;
            }
        }
    }
}

/// UD in f32 on ill-conditioned rows: D > 0, P symmetric and positive definite (f64
/// Cholesky of the f32 P after every sample), estimate finite and close to the f64 UD
/// filter on the identifiable columns. The textbook covariance form in f32 on the
/// same data loses definiteness (negative diagonal) — measured, then asserted.
#[test]
fn ud_f32_stays_positive_definite_on_ill_conditioned_rows() {
    const SAMPLES: usize = 5000;
    let lambda = 0.999;
    let p0 = 1e4;
    let mut rng = Rng::new(77);
    let x_true = [0.3, -0.2, 0.1, 0.05, -0.4, 0.25, -0.15, 0.2];
    let mut ud32: Rls<f32, 8> = Rls::new(unbounded(lambda, p0));
    let mut ud64: Rls<f64, 8> = Rls::new(unbounded(lambda, p0));
    let mut cov = CovRls::new(p0 as f32);
    let mut ud_chol_failures = 0usize;
    let mut cov_chol_failures = 0usize;
    let mut cov_first_failure: Option<usize> = None;
    let mut cov_min_diag = f64::INFINITY;
    for n in 0..SAMPLES {
        let phi = ill_row(&mut rng);
        let y = phi.iter().zip(&x_true).map(|(a, b)| a * b).sum::<f64>() + rng.gauss();
        let phi32: [f32; 8] = cast_vec(&phi);
        ud32.begin_sample();
        ud64.begin_sample();
        assert!(ud32.update(&phi32, y as f32).is_applied(), "n={n}");
        assert!(ud64.update(&phi, y).is_applied());
        cov.step(lambda as f32, &phi32, y as f32);

        let (_, d) = ud32.factors();
        assert!(
            d.iter().all(|&v| v > 0.0 && v.is_finite()),
            "n={n}: D = {d:?}"
        );
        assert!(ud32.estimate().iter().all(|v| v.is_finite()));
        let p = ud32.covariance();
        for i in 0..8 {
            for j in 0..8 {
                assert_eq!(p[i][j].to_bits(), p[j][i].to_bits(), "P not symmetric");
            }
        }
        if cholesky(&to_f64_mat(&p)).is_none() {
            ud_chol_failures += 1;
        }
        let pc = to_f64_mat(&cov.p);
        for (i, row) in pc.iter().enumerate() {
            cov_min_diag = cov_min_diag.min(row[i]);
        }
        if cholesky(&pc).is_none() || !cov.x.iter().all(|v| v.is_finite()) {
            cov_chol_failures += 1;
            cov_first_failure.get_or_insert(n);
        }
    }
    let x32 = ud32.estimate();
    let x64 = ud64.estimate();
    let xc = cov.x;
    std::println!(
        "UD f32: min D {:.3e}, trace {:.3e}, Cholesky failures {ud_chol_failures}; \
         cov-form f32: not PD in {cov_chol_failures}/{SAMPLES} samples (first {:?}), \
         min diag {:.3e}",
        ud32.min_d(),
        ud32.trace(),
        cov_first_failure,
        cov_min_diag
    );
    let (mut ud_err, mut cov_err) = (0.0f64, 0.0f64);
    for i in 0..8 {
        std::println!(
            "  x[{i}] true {:+.4} ud64 {:+.6e} ud32 {:+.6e} cov32 {:+.6e}",
            x_true[i],
            x64[i],
            x32[i],
            xc[i]
        );
        if i >= 5 {
            // best-determined columns (scale ≥ 1e1): compare with the f64 UD filter
            ud_err = ud_err.max((x32[i] as f64 - x64[i]).abs() / x64[i].abs());
            cov_err = cov_err.max((xc[i] as f64 - x64[i]).abs() / x64[i].abs());
        }
    }
    std::println!(
        "  best-determined columns, rel. deviation from f64 UD: ud32 {ud_err:.2e}, cov32 {cov_err:.2e}"
    );
    assert_eq!(ud_chol_failures, 0, "UD f32 covariance failed a Cholesky");
    assert_eq!(ud32.stats().d_floor_hits, 0);
    assert_eq!(ud32.stats().skipped_non_finite, 0);
    assert!(ud_err < 1e-3, "UD f32 drifted from f64: {ud_err:e}");
    // Measured: the covariance form goes indefinite (negative diagonal entries).
    assert!(
        cov_chol_failures > 0 && cov_min_diag < 0.0,
        "covariance form stayed PD"
    );
    // ... and its estimate is much further from the f64 solution (measured ~160×).
    assert!(
        cov_err > 10.0 * ud_err,
        "cov form not worse: {cov_err:e} vs {ud_err:e}"
    );
}

/// f32 and f64 instantiations agree on a well-conditioned problem.
fn f32_vs_f64<const N: usize>(seed: u64) -> (f64, f64) {
    let mut rng = Rng::new(seed);
    let settings = RlsSettings::<f64>::default();
    let mut a: Rls<f64, N> = Rls::new(settings);
    let mut b: Rls<f32, N> = Rls::new(settings.cast());
    let mut x_true = [0.0; N];
    for x in x_true.iter_mut() {
        *x = rng.uni();
    }
    for _ in 0..3000 {
        a.begin_sample();
        b.begin_sample();
        for _ in 0..2 {
            let mut phi = [0.0; N];
            for p in phi.iter_mut() {
                *p = rng.uni();
            }
            // round the inputs first so both filters see identical data
            let phi32: [f32; N] = cast_vec(&phi);
            let phi: [f64; N] = cast_vec(&phi32.map(f64::from));
            let y = (phi.iter().zip(&x_true).map(|(p, x)| p * x).sum::<f64>() + 0.1 * rng.gauss())
                as f32;
            assert!(a.update(&phi, y as f64).is_applied());
            assert!(b.update(&phi32, y).is_applied());
        }
    }
    let xa = a.estimate();
    let xb = b.estimate().map(f64::from);
    let mut d = [0.0; N];
    for i in 0..N {
        d[i] = xa[i] - xb[i];
    }
    let tr_rel = (a.trace() - b.trace().to_f64()).abs() / a.trace();
    (norm(&d) / norm(&xa), tr_rel)
}

#[test]
fn f32_and_f64_agree_on_well_conditioned_data() {
    let (e8, t8) = f32_vs_f64::<8>(3);
    let (e6, t6) = f32_vs_f64::<6>(4);
    std::println!("f32 vs f64: N=8 x {e8:.2e} trace {t8:.2e}; N=6 x {e6:.2e} trace {t6:.2e}");
    assert!(e8 < 1e-4 && e6 < 1e-4);
    assert!(t8 < 1e-4 && t6 < 1e-4);
}

/// Excite for 2000 samples, then idle for 10 000 samples (20 s). `idle_row` makes the
/// idle rows. Returns (converged trace, max trace during idle, final trace, stats).
fn windup_run<T: Real>(
    trace_max: f64,
    idle_row: fn(&mut Rng) -> [f64; 6],
) -> (f64, f64, f64, RlsStats) {
    let lambda = 0.999;
    let mut rng = Rng::new(99);
    let settings = RlsSettings::new(
        T::from_f64(lambda),
        T::from_f64(1.0),
        T::from_f64(trace_max),
    )
    .unwrap();
    let mut rls: Rls<T, 6> = Rls::new(settings);
    let x_true = [0.1, -0.2, 0.3, -0.1, 0.05, 0.2];
    let step = |rls: &mut Rls<T, 6>, phi: [f64; 6], rng: &mut Rng| {
        let y = phi.iter().zip(&x_true).map(|(a, b)| a * b).sum::<f64>() + 0.01 * rng.gauss();
        rls.begin_sample();
        assert!(rls.update(&cast_vec(&phi), T::from_f64(y)).is_applied());
    };
    for _ in 0..2000 {
        let mut phi = [0.0; 6];
        for p in phi.iter_mut() {
            *p = rng.uni();
        }
        step(&mut rls, phi, &mut rng);
    }
    let tr_conv = rls.trace().to_f64();
    let mut tr_idle_max: f64 = 0.0;
    for _ in 0..10_000 {
        let phi = idle_row(&mut rng);
        step(&mut rls, phi, &mut rng);
        tr_idle_max = tr_idle_max.max(rls.trace().to_f64());
    }
    (tr_conv, tr_idle_max, rls.trace().to_f64(), rls.stats())
}

fn zero_row(_: &mut Rng) -> [f64; 6] {
    [0.0; 6]
}

fn one_dim_row(rng: &mut Rng) -> [f64; 6] {
    let c = rng.gauss();
    [0.5 * c, -0.3 * c, 0.2 * c, 0.1 * c, -0.6 * c, 0.4 * c]
}

fn check_trace_bound<T: Real>() {
    for (name, idle) in [
        ("zero rows", zero_row as fn(&mut Rng) -> [f64; 6]),
        ("1-D rows", one_dim_row),
    ] {
        let (tr_conv, _, tr_free_end, free_stats) = windup_run::<T>(f64::INFINITY, idle);
        let trace_max = 10.0 * tr_conv;
        let (_, tr_idle_max, tr_end, stats) = windup_run::<T>(trace_max, idle);
        std::println!(
            "{} {name}: converged {tr_conv:.3e}; unbounded end {tr_free_end:.3e} (×{:.1e}); \
             bounded max {tr_idle_max:.3e} (bound/λ {:.3e}), end {tr_end:.3e}, skipped {}",
            T::NAME,
            tr_free_end / tr_conv,
            trace_max / 0.999,
            stats.forgetting_skipped
        );
        assert_eq!(free_stats.forgetting_skipped, 0);
        assert!(
            tr_free_end > 1e3 * tr_conv,
            "{name}: unbounded trace did not wind up"
        );
        assert!(
            tr_idle_max <= trace_max / 0.999 * (1.0 + 1e-5),
            "{name}: bound violated"
        );
        assert!(stats.forgetting_skipped > 1000);
    }
}

#[test]
fn trace_bound_prevents_windup_f64() {
    check_trace_bound::<f64>();
}

#[test]
fn trace_bound_prevents_windup_f32() {
    check_trace_bound::<f32>();
}

#[test]
fn forgetting_skipped_when_trace_would_overflow() {
    let s = RlsSettings::new(0.5f32, 1e37, f32::INFINITY).unwrap();
    let mut rls: Rls<f32, 2> = Rls::new(s);
    // trace 2e37 → 4e37 → 8e37 → 1.6e38 → 3.2e38 (all finite: 4 applications); the
    // next doubling (6.4e38) would overflow f32 and must be skipped.
    let mut applied = 0;
    for _ in 0..10 {
        if rls.begin_sample() {
            applied += 1;
        }
        assert!(rls.trace().is_finite() && rls.min_d().is_finite());
    }
    assert_eq!(applied, 4);
    assert_eq!(rls.stats().forgetting_skipped, 6);
}

fn sample_filter() -> Rls<f32, 4> {
    let mut rls: Rls<f32, 4> = Rls::new(RlsSettings::default());
    let mut rng = Rng::new(1);
    for _ in 0..50 {
        rls.begin_sample();
        let phi = [
            rng.uni() as f32,
            rng.uni() as f32,
            rng.uni() as f32,
            rng.uni() as f32,
        ];
        rls.update(&phi, rng.uni() as f32);
    }
    rls
}

#[test]
fn non_finite_input_leaves_state_untouched() {
    let mut rls = sample_filter();
    let before = rls.clone();
    let mut rejected = 0;
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        for i in 0..4 {
            let mut phi = [0.1f32, 0.2, -0.3, 0.4];
            phi[i] = bad;
            let inn = rls.update(&phi, 1.0);
            assert_eq!(inn.status, UpdateStatus::NonFiniteInput);
            assert!(!inn.is_applied());
            assert_eq!((inn.e, inn.s, inn.normalized_sq()), (0.0, 1.0, 0.0));
            rejected += 1;
        }
        let inn = rls.update(&[0.1, 0.2, -0.3, 0.4], bad);
        assert_eq!(inn.status, UpdateStatus::NonFiniteInput);
        rejected += 1;
    }
    // the input is classified after the innovation: with x = 0, ±∞·0 = NaN still flags it
    let mut zero = rls.clone();
    assert!(zero.set_estimate([0.0; 4]));
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let inn = zero.update(&[bad, 0.2, -0.3, 0.4], 1.0);
        assert_eq!(inn.status, UpdateStatus::NonFiniteInput);
    }
    // finite but overflowing: s = 1 + φᵀPφ = +∞ in f32
    let inn = rls.update(&[1e30, 0.0, 0.0, 0.0], 1.0);
    assert_eq!(inn.status, UpdateStatus::NumericalFault);
    rejected += 1;
    assert!(!rls.set_estimate([0.0, f32::NAN, 0.0, 0.0]));
    assert!(!rls.set_estimate([0.0, 0.0, f32::INFINITY, 0.0]));

    let (u0, d0) = before.factors();
    let (u1, d1) = rls.factors();
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&before.estimate()), bits(&rls.estimate()));
    assert_eq!(bits(&d0), bits(&d1));
    assert_eq!(bits(u0.as_flattened()), bits(u1.as_flattened()));
    let st = rls.stats();
    assert_eq!(st.skipped_non_finite, rejected);
    assert_eq!(st.updates, before.stats().updates);
    assert_eq!(
        RlsStats {
            skipped_non_finite: 0,
            ..st
        },
        before.stats()
    );
}

#[test]
fn reset_sets_p_identity_and_keeps_estimate() {
    let mut rls = sample_filter();
    let x = rls.estimate();
    let off_diag_before = rls.covariance()[0][1];
    assert!(off_diag_before != 0.0);
    rls.reset_covariance(2.5);
    let p = rls.covariance();
    for i in 0..4 {
        for j in 0..4 {
            assert_eq!(p[i][j], if i == j { 2.5 } else { 0.0 });
        }
    }
    assert_eq!(rls.estimate(), x);
    assert_eq!(rls.trace(), 10.0);
    assert_eq!(rls.stats().resets, 1);
    // invalid p falls back to p0
    for bad in [f32::NAN, 0.0, -1.0, f32::INFINITY] {
        rls.reset_covariance(bad);
        assert_eq!(rls.min_d(), 1e4);
    }
    assert_eq!(rls.stats().resets, 5);
    assert!(rls.set_estimate([1.0, 2.0, 3.0, 4.0]));
    assert_eq!(rls.estimate(), [1.0, 2.0, 3.0, 4.0]);
    assert_eq!(rls.min_d(), 1e4);
}

#[test]
fn d_floor_clamps_underflow_and_counts() {
    let mut rls: Rls<f32, 3> = Rls::new(RlsSettings::default());
    // D0 = 1e4, f0 = 1e16: α = 1 + 1e36, new D0 = 1e4/1e36 = 1e-32 < D_FLOOR
    let inn = rls.update(&[1e16, 0.0, 0.0], 1.0);
    assert!(inn.is_applied());
    assert_eq!(rls.stats().d_floor_hits, 1);
    assert_eq!(rls.min_d(), D_FLOOR as f32);
    assert!(rls.estimate().iter().all(|v| v.is_finite()));
    // the filter keeps working afterwards
    let inn = rls.update(&[0.0, 1.0, 0.0], 1.0);
    assert!(inn.is_applied() && rls.min_d() > 0.0);
}

/// The estimator's rows without the floor, then the floor once: the same state as the
/// floored updates where the floor is not reached; where a row drives a `D` below it, the
/// sample's later rows stay finite and the floor restores it.
#[test]
fn the_floor_once_per_sample_is_the_floor_per_update() {
    let rows: [([f32; 4], [f32; 4], f32); 5] = [
        ([1.0, 0.3, -0.2, 0.5], [1.0, 2.0, 0.5, 1.0], 0.7),
        ([0.1, -1.0, 0.4, 0.2], [1.0, 2.0, 0.5, 1.0], -0.2),
        ([0.6, 0.2, 1.0, -0.3], [1.0, 2.0, 0.5, 1.0], 1.1),
        ([-0.4, 0.5, 0.1, 1.0], [1.0, 2.0, 0.5, 1.0], 0.3),
        ([0.2, 0.2, -0.6, 0.4], [1.0, 2.0, 0.5, 1.0], -0.9),
    ];
    let mut a: Rls<f32, 4> = Rls::new(RlsSettings::default());
    let mut b = a.clone();
    for _ in 0..50 {
        a.begin_sample();
        b.begin_sample();
        for (phi, sc, y) in &rows {
            let ia = a.update_scaled(phi, sc, *y);
            let ib = b.update_scaled_unfloored(phi, sc, *y);
            assert_eq!(ia, ib);
        }
        b.floor_all();
        assert_eq!(a.factors(), b.factors());
        assert_eq!(a.estimate(), b.estimate());
    }
    // a row that underflows D0 (as `d_floor_clamps_underflow_and_counts`), then more rows
    let mut c: Rls<f32, 3> = Rls::new(RlsSettings::default());
    let ones = [1.0; 3];
    assert!(
        c.update_scaled_unfloored(&[1e16, 0.0, 0.0], &ones, 1.0)
            .is_applied()
    );
    assert!(c.factors().1[0] < D_FLOOR as f32);
    assert!(
        c.update_scaled_unfloored(&[0.5, 1.0, 0.0], &ones, 1.0)
            .is_applied()
    );
    assert!(c.estimate().iter().all(|v| v.is_finite()));
    c.floor_all();
    assert_eq!(c.min_d(), D_FLOOR as f32);
    assert_eq!(c.stats().d_floor_hits, 1);
}

#[test]
fn set_trace_max_takes_effect_and_rejects_invalid() {
    let mut rls: Rls<f64, 2> = Rls::new(unbounded(0.5, 1.0));
    assert!(rls.begin_sample()); // trace 2 < ∞
    assert!(rls.set_trace_max(3.0));
    assert_eq!(rls.settings().trace_max, 3.0);
    assert!(!rls.begin_sample()); // trace 4 ≥ 3: skipped
    assert_eq!(rls.trace(), 4.0);
    for bad in [f64::NAN, 0.0, -1.0] {
        assert!(!rls.set_trace_max(bad));
        assert_eq!(rls.settings().trace_max, 3.0);
    }
    assert!(rls.set_trace_max(f64::INFINITY));
    assert!(rls.begin_sample());
    assert_eq!(rls.stats().forgetting_skipped, 1);
}

#[test]
fn lambda_one_is_growing_memory() {
    let mut rls: Rls<f64, 2> = Rls::new(unbounded(1.0, 3.0));
    assert!(rls.begin_sample());
    assert_eq!(rls.trace(), 6.0);
    assert_eq!(rls.stats().forgetting_skipped, 0);
}

#[test]
fn settings_validation_names_the_field() {
    assert_eq!(RlsSettings::<f32>::default().validate(), Ok(()));
    assert_eq!(RlsSettings::<f64>::default().validate(), Ok(()));
    let ok = RlsSettings::new(1.0f64, 1.0, f64::INFINITY);
    assert!(ok.is_ok());
    for lam in [0.0, -0.5, 1.0001, f64::NAN, f64::INFINITY] {
        let e = RlsSettings::new(lam, 1e4, 1e5).unwrap_err();
        assert_eq!(e, RlsSettingsError::Forgetting);
        assert_eq!(e.field(), "forgetting");
    }
    for p0 in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert_eq!(RlsSettings::new(0.999, p0, 1e5).unwrap_err().field(), "p0");
    }
    for tm in [0.0, -1.0, f64::NAN] {
        assert_eq!(
            RlsSettings::new(0.999, 1e4, tm).unwrap_err().field(),
            "trace_max"
        );
    }
    let msg = std::format!("{}", RlsSettings::new(0.999, f64::NAN, 1e5).unwrap_err());
    assert!(msg.contains("`p0`"), "{msg}");
    let bad = RlsSettings {
        forgetting: 2.0f32,
        ..RlsSettings::default()
    };
    assert_eq!(
        Rls::<f32, 8>::try_new(bad).unwrap_err(),
        RlsSettingsError::Forgetting
    );
}

#[test]
fn innovation_error_is_within_the_summation_bound() {
    // y − φᵀx summed in index order in f32: the error is within the textbook bound
    // γ_(N+1)·(|y| + Σ|φᵢxᵢ|), γ_n = nε/(1 − nε), against the exact f64 value (products
    // of 12-bit factors, exact in f32, and terms that cancel to a small innovation: the
    // case where the bound is all there is). The estimator's precision case: rls.rs,
    // "The innovation".
    let mut rng = Rng::new(2024);
    let eps = f32::EPSILON as f64 / 2.0;
    let gamma = 9.0 * eps / (1.0 - 9.0 * eps);
    let mut worst = 0.0f64;
    for _ in 0..2000 {
        let mut phi = [0.0f32; 8];
        let mut x = [0.0f32; 8];
        for i in 0..8 {
            let sign = if rng.uni() < 0.5 { -1.0 } else { 1.0 };
            phi[i] = sign * (1.0 + (4095.0 * rng.uni()).floor()) as f32;
            x[i] = ((4095.0 * rng.uni()).floor() / 4096.0) as f32;
        }
        let exact_dot: f64 = phi.iter().zip(&x).map(|(&a, &b)| a as f64 * b as f64).sum();
        let y = (exact_dot + 1e-3 * rng.uni()) as f32;
        let r_ref = y as f64 - exact_dot;
        let mag = (y as f64).abs()
            + phi
                .iter()
                .zip(&x)
                .map(|(&a, &b)| (a as f64 * b as f64).abs())
                .sum::<f64>();
        let err = (residual(y, &phi, &x) as f64 - r_ref).abs();
        assert!(
            err <= gamma * mag,
            "error {err:e} above the bound {:e}",
            gamma * mag
        );
        worst = worst.max(err / (gamma * mag));
    }
    // the bound is approached, not vacuous: this data does cancel
    assert!(worst > 1e-3, "worst error / bound {worst:e}");
}

/// Excite for 20 000 samples (all six directions), then 50 000 samples (100 s at 500 Hz)
/// of weakly exciting rows: two strong directions plus a 3 % component in all six (the
/// soak with the dither off: the regression is nearly rank-deficient). Each idle sample
/// is opened by `begin_sample` (forgetting, trace bound 10× the converged trace) or by
/// `begin_sample_held`. Returns (largest |x − x_converged| over the idle time in the
/// weakly excited subspace, the trace after each idle sample, stats).
fn weak_run<T: Real>(held: bool) -> (f64, Vec<f64>, RlsStats) {
    let mut rng = Rng::new(7);
    let settings = RlsSettings::new(T::from_f64(0.999), T::from_f64(1.0), T::MAX).unwrap();
    let mut rls: Rls<T, 6> = Rls::new(settings);
    let x_true = [0.1, -0.2, 0.3, -0.1, 0.05, 0.2];
    let step = |rls: &mut Rls<T, 6>, phi: [f64; 6], rng: &mut Rng, held: bool| {
        let y = phi.iter().zip(&x_true).map(|(a, b)| a * b).sum::<f64>() + rng.gauss();
        if held {
            rls.begin_sample_held();
        } else {
            rls.begin_sample();
        }
        assert!(rls.update(&cast_vec(&phi), T::from_f64(y)).is_applied());
    };
    for _ in 0..20_000 {
        let phi: [f64; 6] = core::array::from_fn(|_| rng.uni());
        step(&mut rls, phi, &mut rng, false);
    }
    assert!(rls.set_trace_max(T::from_f64(10.0 * rls.trace().to_f64())));
    let x_conv = rls.estimate();
    let (a, b) = (
        [1.0, 0.5, -0.5, 0.0, 0.2, 0.1],
        [0.0, 0.3, 0.6, -0.4, 0.1, 0.5],
    );
    // orthonormal basis (qa, qb) of the strong plane: the deviation is measured in its
    // complement, the weakly excited directions
    let dot = |u: &[f64; 6], v: &[f64; 6]| u.iter().zip(v).map(|(p, q)| p * q).sum::<f64>();
    let qa: [f64; 6] = core::array::from_fn(|j| a[j] / dot(&a, &a).sqrt());
    let bp: [f64; 6] = core::array::from_fn(|j| b[j] - dot(&b, &qa) * qa[j]);
    let qb: [f64; 6] = core::array::from_fn(|j| bp[j] / dot(&bp, &bp).sqrt());
    let (mut dev, mut traces) = (0.0f64, Vec::new());
    for _ in 0..50_000 {
        let (c1, c2) = (rng.gauss(), rng.gauss());
        let phi: [f64; 6] = core::array::from_fn(|j| c1 * a[j] + c2 * b[j] + 0.03 * rng.gauss());
        step(&mut rls, phi, &mut rng, held);
        let x = rls.estimate();
        let d: [f64; 6] = core::array::from_fn(|j| (x[j] - x_conv[j]).to_f64());
        let (da, db) = (dot(&d, &qa), dot(&d, &qb));
        let perp: [f64; 6] = core::array::from_fn(|j| d[j] - da * qa[j] - db * qb[j]);
        dev = dev.max(dot(&perp, &perp).sqrt());
        traces.push(rls.trace().to_f64());
    }
    (dev, traces, rls.stats())
}

fn check_held_without_excitation<T: Real>() {
    let (dev_forget, tr_forget, st_forget) = weak_run::<T>(false);
    let (dev_held, tr_held, st_held) = weak_run::<T>(true);
    let max = |v: &[f64]| v.iter().cloned().fold(0.0, f64::max);
    std::println!(
        "{} weak rows, 100 s: |x − x_conv| (weak subspace) max forgetting {dev_forget:.3e} (trace max {:.3e}, \
         skipped {}), held {dev_held:.3e} (trace max {:.3e}, held {})",
        T::NAME,
        max(&tr_forget),
        st_forget.forgetting_skipped,
        max(&tr_held),
        st_held.forgetting_held
    );
    // with forgetting the weak directions wind up to the trace bound and the estimate
    // wanders along them; held, P only shrinks and the estimate stays put
    assert!(st_forget.forgetting_skipped > 1000 && st_forget.forgetting_held == 0);
    assert_eq!(st_held.forgetting_held, 50_000);
    assert_eq!(st_held.forgetting_skipped, 0);
    for w in tr_held.windows(2) {
        assert!(
            w[1] <= w[0] * (1.0 + 1e-6),
            "held trace grew {} → {}",
            w[0],
            w[1]
        );
    }
    assert!(max(&tr_held) < 0.5 * max(&tr_forget));
    assert!(
        dev_held < 0.2 * dev_forget,
        "held {dev_held:e}, forgetting {dev_forget:e}"
    );
}

#[test]
fn held_sample_keeps_estimate_without_excitation_f64() {
    check_held_without_excitation::<f64>();
}

#[test]
fn held_sample_keeps_estimate_without_excitation_f32() {
    check_held_without_excitation::<f32>();
}

#[test]
fn held_sample_on_zero_rows_changes_nothing_but_the_count() {
    let mut rls = sample_filter();
    let before = rls.clone();
    for _ in 0..1000 {
        rls.begin_sample_held();
        assert!(rls.update(&[0.0; 4], 0.0).is_applied());
    }
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let ((u0, d0), (u1, d1)) = (before.factors(), rls.factors());
    assert_eq!(bits(&before.estimate()), bits(&rls.estimate()));
    assert_eq!(bits(&d0), bits(&d1));
    assert_eq!(bits(u0.as_flattened()), bits(u1.as_flattened()));
    assert_eq!(rls.last_trace(), rls.trace());
    assert_eq!(rls.stats().forgetting_held, 1000);
    // `begin_sample` on the same rows forgets: P grows by 1/λ per sample
    let mut forgetting = before.clone();
    for _ in 0..1000 {
        forgetting.begin_sample();
        forgetting.update(&[0.0; 4], 0.0);
    }
    assert!(forgetting.trace() > 2.0 * rls.trace());
}

/// `add_walk` is `P + q·e_j e_jᵀ` exactly (against the dense covariance, after updates
/// that fill U), leaves the estimate alone, and does nothing at or above its cap or for a
/// bad `q` or `j` (beyond [`WALK_J_MAX`] or `N`).
#[test]
fn add_walk_adds_q_on_one_diagonal_entry_below_its_cap() {
    let mut rng = Rng::new(17);
    let mut rls: Rls<f64, 6> = Rls::new(unbounded(0.999, 10.0));
    for _ in 0..40 {
        rls.begin_sample();
        let phi: [f64; 6] = core::array::from_fn(|_| rng.uni());
        rls.update(&phi, rng.gauss());
    }
    for j in [0, 1, 2, 3] {
        let (p, x) = (rls.covariance(), rls.estimate());
        let q = 0.25 * p[j][j];
        assert!(rls.add_walk(j, q, f64::INFINITY));
        let p2 = rls.covariance();
        let mut err = 0.0_f64;
        for r in 0..6 {
            for c in 0..6 {
                let want = p[r][c] + if r == j && c == j { q } else { 0.0 };
                err = err.max((p2[r][c] - want).abs() / p[j][j]);
            }
        }
        assert!(err < 1e-12, "j = {j}: relative error {err:e}");
        assert_eq!(rls.estimate(), x);
    }
    let before = rls.covariance();
    let pjj = before[3][3];
    assert!(!rls.add_walk(3, 1.0, pjj), "at its cap");
    assert!(!rls.add_walk(3, f64::NAN, f64::INFINITY));
    assert!(!rls.add_walk(3, -1.0, f64::INFINITY));
    assert!(!rls.add_walk(3, 0.0, f64::INFINITY));
    assert!(!rls.add_walk(WALK_J_MAX + 1, 1.0, f64::INFINITY));
    assert!(!rls.add_walk(6, 1.0, f64::INFINITY));
    assert_eq!(rls.covariance(), before);
    assert!(rls.add_walk(3, 1.0, pjj * 1.01), "below its cap");
}

/// `shift` moves one entry of the estimate by `delta` and nothing else (the covariance is
/// kept), and a non-finite `delta` or `j ≥ N` changes nothing.
#[test]
fn shift_moves_one_estimate_entry_and_keeps_the_covariance() {
    let mut rng = Rng::new(23);
    let mut rls: Rls<f64, 6> = Rls::new(unbounded(0.999, 10.0));
    for _ in 0..40 {
        rls.begin_sample();
        let phi: [f64; 6] = core::array::from_fn(|_| rng.uni());
        rls.update(&phi, rng.gauss());
    }
    let (p, x) = (rls.covariance(), rls.estimate());
    rls.shift(3, 0.5);
    let x2 = rls.estimate();
    for j in 0..6 {
        let want = if j == 3 { x[j] + 0.5 } else { x[j] };
        assert_eq!(x2[j], want, "entry {j}");
    }
    assert_eq!(rls.covariance(), p);
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        rls.shift(3, bad);
    }
    rls.shift(6, 1.0);
    assert_eq!(rls.estimate(), x2);
    assert_eq!(rls.covariance(), p);
}
