//! Property tests of the Bierman-UD RLS against a nalgebra oracle:
//!
//! * with λ = 1 the filter is the batch least-squares solution of all rows so far plus
//!   the prior `P₀ = p0·I` (solved by nalgebra's Cholesky), and `P` is the inverse of
//!   that normal matrix, on random well-conditioned data;
//! * under random rows (column scales over six decades), random forgetting and random
//!   covariance resets, `U` stays unit upper triangular, `D` positive and finite, and
//!   `P = U D Uᵀ` symmetric positive definite (nalgebra's Cholesky succeeds), in `f64`
//!   and in `f32`.

extern crate std;
use super::*;
use nalgebra::{SMatrix, SVector};
use proptest::prelude::*;
use std::vec::Vec;

/// One sample: its rows `(φ, y)`.
type Rows<const N: usize> = Vec<([f64; N], f64)>;

fn rows_strategy<const N: usize>(
    min_samples: usize,
    max_samples: usize,
) -> impl Strategy<Value = Vec<Rows<N>>> {
    let row = (prop::array::uniform::<_, N>(-1.0f64..1.0), -1.0f64..1.0);
    prop::collection::vec(prop::collection::vec(row, 1..3), min_samples..max_samples)
}

/// λ = 1, `P₀ = p0·I`: the RLS estimate and covariance equal the batch solution.
fn equals_batch<const N: usize>(
    samples: &[Rows<N>],
    x_true: [f64; N],
) -> Result<(), TestCaseError> {
    let p0 = 1e6;
    let mut rls: Rls<f64, N> = Rls::new(RlsSettings::new(1.0, p0, f64::INFINITY).unwrap());
    let mut a = SMatrix::<f64, N, N>::identity() / p0;
    let mut b = SVector::<f64, N>::zeros();
    for rows in samples {
        prop_assert!(rls.begin_sample());
        for (phi, noise) in rows {
            let phi_v = SVector::<f64, N>::from_column_slice(phi);
            let y = phi_v.dot(&SVector::from_column_slice(&x_true)) + 0.1 * noise;
            prop_assert!(rls.update(phi, y).is_applied());
            a += phi_v * phi_v.transpose();
            b += phi_v * y;
        }
    }
    let chol = a.cholesky().expect("normal matrix with a prior is SPD");
    let x_ref = chol.solve(&b);
    let p_ref = chol.inverse();
    let x = SVector::<f64, N>::from_column_slice(&rls.estimate());
    let p = SMatrix::<f64, N, N>::from_fn(|i, j| rls.covariance()[i][j]);
    let ex = (x - x_ref).norm() / x_ref.norm().max(1e-12);
    let ep = (p - p_ref).abs().max() / p_ref.abs().max();
    prop_assert!(ex < 1e-7, "estimate differs from batch LS: rel {ex:e}");
    prop_assert!(
        ep < 1e-7,
        "P differs from the inverse normal matrix: rel {ep:e}"
    );
    Ok(())
}

/// U unit upper triangular, D > 0 finite, P symmetric positive definite.
fn check_factors<T: Real, const N: usize>(rls: &Rls<T, N>) -> Result<(), TestCaseError> {
    let (u, d) = rls.factors();
    for i in 0..N {
        prop_assert!(d[i].is_finite() && d[i] > T::ZERO, "D[{i}] = {:?}", d[i]);
        prop_assert_eq!(u[i][i], T::ONE);
        for j in 0..i {
            prop_assert_eq!(u[i][j], T::ZERO);
        }
    }
    // the covariance the filter reports is exactly symmetric
    let p = rls.covariance();
    for i in 0..N {
        for j in 0..i {
            prop_assert_eq!(p[i][j].to_f64().to_bits(), p[j][i].to_f64().to_bits());
        }
    }
    // U D Uᵀ from the factors in f64, normalised to unit diagonal (the column scales
    // span six decades): a Cholesky factor exists
    let um = SMatrix::<f64, N, N>::from_fn(|i, j| u[i][j].to_f64());
    let dm = SMatrix::<f64, N, N>::from_diagonal(&SVector::from_fn(|i, _| d[i].to_f64()));
    let pm = um * dm * um.transpose();
    let s = SVector::<f64, N>::from_fn(|i, _| 1.0 / libm::sqrt(pm[(i, i)]));
    let corr = SMatrix::<f64, N, N>::from_fn(|i, j| pm[(i, j)] * s[i] * s[j]);
    prop_assert!(
        corr.cholesky().is_some(),
        "U D Uᵀ not positive definite: {pm}"
    );
    Ok(())
}

/// Random rows with column scales 10^[−3, 3], forgetting λ, and a covariance reset at
/// the samples marked in `resets`.
fn stays_spd<T: Real, const N: usize>(
    lambda: f64,
    scales_log10: [f64; N],
    samples: &[Rows<N>],
    resets: &[bool],
) -> Result<(), TestCaseError> {
    let settings = RlsSettings::new(T::from_f64(lambda), T::from_f64(1e4), T::from_f64(1e12));
    let mut rls: Rls<T, N> = Rls::new(settings.unwrap());
    for (n, rows) in samples.iter().enumerate() {
        rls.begin_sample();
        if resets.get(n).copied().unwrap_or(false) {
            rls.reset_covariance(T::ONE);
        }
        for (phi, y) in rows {
            let phi: [T; N] =
                core::array::from_fn(|j| T::from_f64(phi[j] * libm::pow(10.0, scales_log10[j])));
            let inn = rls.update(&phi, T::from_f64(*y));
            prop_assert!(inn.is_applied(), "{:?}", inn.status);
        }
        check_factors(&rls)?;
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn lambda_one_equals_batch_least_squares_8(
        samples in rows_strategy::<8>(40, 120),
        x_true in prop::array::uniform8(-2.0f64..2.0),
    ) {
        equals_batch(&samples, x_true)?;
    }

    #[test]
    fn lambda_one_equals_batch_least_squares_6(
        samples in rows_strategy::<6>(30, 100),
        x_true in prop::array::uniform6(-2.0f64..2.0),
    ) {
        equals_batch(&samples, x_true)?;
    }

    #[test]
    fn udu_stays_spd_under_forgetting_f64(
        lambda in 0.95f64..=1.0,
        scales in prop::array::uniform8(-3.0f64..3.0),
        samples in rows_strategy::<8>(1, 200),
        resets in prop::collection::vec(prop::bool::weighted(0.02), 200),
    ) {
        stays_spd::<f64, 8>(lambda, scales, &samples, &resets)?;
    }

    #[test]
    fn udu_stays_spd_under_forgetting_f32(
        lambda in 0.95f64..=1.0,
        scales in prop::array::uniform6(-3.0f64..3.0),
        samples in rows_strategy::<6>(1, 200),
        resets in prop::collection::vec(prop::bool::weighted(0.02), 200),
    ) {
        stays_spd::<f32, 6>(lambda, scales, &samples, &resets)?;
    }
}
