//! Small dense linear algebra and root finding for the 4-dimensional slow flows: linear
//! solves (nalgebra's LU), the eigenvalues of a 4×4 Jacobian (hand-written, see [`eig4`]
//! for why), finite-difference Jacobians and a damped Newton iteration.

use std::f64::consts::TAU;

use nalgebra::{Const, DimMin, SMatrix, SVector};
use paragyro_core::Cplx;

use crate::complex::CplxExt;

/// Solves `a·x = b` by LU decomposition with partial pivoting (nalgebra); `None` if `a` is
/// singular or the solution is not finite.
pub fn solve<const N: usize>(a: [[f64; N]; N], b: [f64; N]) -> Option<[f64; N]>
where
    Const<N>: DimMin<Const<N>, Output = Const<N>>,
{
    let m = SMatrix::<f64, N, N>::from_fn(|r, c| a[r][c]);
    let x = m.lu().solve(&SVector::<f64, N>::from_column_slice(&b))?;
    let x: [f64; N] = std::array::from_fn(|i| x[i]);
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Roots of the monic quartic `z⁴ + c[0]z³ + c[1]z² + c[2]z + c[3]` (Aberth–Ehrlich
/// simultaneous iteration).
pub fn quartic_roots(c: [f64; 4]) -> [Cplx<f64>; 4] {
    let coef = [1.0, c[0], c[1], c[2], c[3]];
    let eval = |z: Cplx<f64>| {
        let mut p = Cplx::new(1.0, 0.0);
        let mut dp = Cplx::ZERO;
        for &ck in &coef[1..] {
            dp = dp * z + p;
            p = p * z + Cplx::new(ck, 0.0);
        }
        (p, dp)
    };
    let bound = 1.0 + c.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let r0 = 0.5 * bound;
    let mut z = [Cplx::ZERO; 4];
    for (k, zk) in z.iter_mut().enumerate() {
        let a = 0.4 + TAU * k as f64 / 4.0;
        *zk = Cplx::new(r0 * a.cos(), r0 * a.sin());
    }
    for _ in 0..800 {
        let mut worst = 0.0f64;
        for k in 0..4 {
            let (p, dp) = eval(z[k]);
            if p.norm_sqr() == 0.0 {
                continue;
            }
            let mut s = Cplx::ZERO;
            for j in 0..4 {
                if j != k {
                    let d = z[k] - z[j];
                    if d.norm_sqr() > 0.0 {
                        s += Cplx::new(1.0, 0.0).div(d);
                    }
                }
            }
            let step = if dp.norm_sqr() > 0.0 {
                let w = p.div(dp);
                w.div(Cplx::new(1.0, 0.0) - w * s)
            } else {
                Cplx::new(1e-8 * bound, 1e-8 * bound)
            };
            if step.re.is_finite() && step.im.is_finite() {
                z[k] = z[k] - step;
                worst = worst.max(step.modulus() / (1.0 + z[k].modulus()));
            }
        }
        if worst < 1e-16 {
            break;
        }
    }
    z
}

/// Eigenvalues of a real 4×4 matrix, sorted by decreasing real part: characteristic
/// polynomial by Faddeev–LeVerrier on the max-entry-scaled matrix, roots by
/// [`quartic_roots`]. Accurate to ~1e-14 of the largest entry for simple eigenvalues
/// (√ of that for a double one); more than enough to classify stability.
///
/// Hand-written rather than nalgebra's real Schur form: on seed 001's Hamiltonian slow
/// flow (purely imaginary spectra) nalgebra 0.33's Francis QR did not converge within
/// 10 000 iterations for 28 of the branch points of Figs 3–4 (`complex_eigenvalues()`
/// iterates without a bound), which would turn them unstable. The characteristic
/// polynomial of such a Jacobian is even, so these roots come out on the axis. On the
/// averaged flow both agree to 3e-11.
pub fn eig4(m: &[[f64; 4]; 4]) -> [Cplx<f64>; 4] {
    let s = m.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
    if s == 0.0 || !s.is_finite() {
        let v = if s == 0.0 { 0.0 } else { f64::NAN };
        return [Cplx::new(v, 0.0); 4];
    }
    let a: [[f64; 4]; 4] = std::array::from_fn(|i| std::array::from_fn(|k| m[i][k] / s));
    let mut mk = [[0.0; 4]; 4];
    for (i, row) in mk.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    let mut c = [0.0; 4];
    for k in 1..=4 {
        let am: [[f64; 4]; 4] = std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..4).map(|l| a[i][l] * mk[l][j]).sum())
        });
        let ck = -(0..4).map(|i| am[i][i]).sum::<f64>() / k as f64;
        c[k - 1] = ck;
        mk = am;
        for i in 0..4 {
            mk[i][i] += ck;
        }
    }
    let mut r = quartic_roots(c).map(|z| z.scale(s));
    r.sort_by(|x, y| y.re.total_cmp(&x.re));
    r
}

/// Central finite-difference Jacobian of `f` at `v` (step `1e-6·max(1, |v_i|)`).
pub fn fd_jacobian(f: &dyn Fn(&[f64; 4]) -> [f64; 4], v: &[f64; 4]) -> [[f64; 4]; 4] {
    let mut j = [[0.0; 4]; 4];
    for c in 0..4 {
        let h = 1e-6 * v[c].abs().max(1.0);
        let mut vp = *v;
        let mut vm = *v;
        vp[c] += h;
        vm[c] -= h;
        let (fp, fm) = (f(&vp), f(&vm));
        for r in 0..4 {
            j[r][c] = (fp[r] - fm[r]) / (2.0 * h);
        }
    }
    j
}

pub(crate) fn inf_norm<const N: usize>(v: &[f64; N]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// Damped Newton for `f(v) = 0` from `guess`: full steps, halved until `‖f‖∞` decreases.
/// Returns the root once `‖f‖∞ ≤ res_tol` (after one more polishing step), `None` if it
/// stalls, diverges beyond `‖v‖∞ > max_norm` or needs more than 100 iterations.
pub fn newton4(
    f: &dyn Fn(&[f64; 4]) -> [f64; 4],
    jac: &dyn Fn(&[f64; 4]) -> [[f64; 4]; 4],
    guess: [f64; 4],
    res_tol: f64,
    max_norm: f64,
) -> Option<[f64; 4]> {
    let mut v = guess;
    let mut r = f(&v);
    let mut rn = inf_norm(&r);
    let mut polished = false;
    for _ in 0..100 {
        if !rn.is_finite() {
            return None;
        }
        if rn <= res_tol {
            if polished {
                return Some(v);
            }
            polished = true;
        }
        let dx = solve(jac(&v), r.map(|x| -x))?;
        let mut t = 1.0;
        let mut moved = false;
        for _ in 0..40 {
            let cand: [f64; 4] = std::array::from_fn(|i| v[i] + t * dx[i]);
            let rc = f(&cand);
            let rcn = inf_norm(&rc);
            if rcn.is_finite() && rcn < rn {
                (v, r, rn, moved) = (cand, rc, rcn, true);
                break;
            }
            t *= 0.5;
        }
        if !moved {
            // no decrease possible: at the rounding floor (accept if small) or stalled
            return (rn <= res_tol).then_some(v);
        }
        if inf_norm(&v) > max_norm {
            return None;
        }
    }
    (rn <= res_tol).then_some(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eig4_matches_known_spectra() {
        // block diagonal: eigenvalues −1 ± 2i, 3, −0.5
        let m = [
            [-1.0, 2.0, 0.0, 0.0],
            [-2.0, -1.0, 0.0, 0.0],
            [0.0, 0.0, 3.0, 1.0],
            [0.0, 0.0, 0.0, -0.5],
        ];
        let e = eig4(&m);
        let want = [
            Cplx::new(3.0, 0.0),
            Cplx::new(-0.5, 0.0),
            Cplx::new(-1.0, 2.0),
            Cplx::new(-1.0, -2.0),
        ];
        for w in want {
            assert!(
                e.iter().any(|z| (*z - w).abs() < 1e-12),
                "{w:?} not in {e:?}"
            );
        }
        assert!((e[0].re - 3.0).abs() < 1e-12);
        // a similarity transform keeps the spectrum (small scale as in the slow flow)
        let p = [
            [1.0, 0.2, -0.3, 0.1],
            [0.0, 1.0, 0.5, -0.2],
            [0.3, 0.0, 1.0, 0.4],
            [0.1, -0.1, 0.0, 1.0],
        ];
        // m2 = P·diag(d)·P⁻¹ with d = 1e-3·[−0.5, −2, 1, −4]
        let d = [-0.5e-3, -2e-3, 1e-3, -4e-3];
        let mut pinv = [[0.0; 4]; 4];
        for c in 0..4 {
            let mut e = [0.0; 4];
            e[c] = 1.0;
            let col = solve(p, e).unwrap();
            for r in 0..4 {
                pinv[r][c] = col[r];
            }
        }
        let m2: [[f64; 4]; 4] = std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..4).map(|k| p[i][k] * d[k] * pinv[k][j]).sum())
        });
        let mut got: Vec<f64> = eig4(&m2).iter().map(|z| z.re).collect();
        got.sort_by(f64::total_cmp);
        let mut dd = d.to_vec();
        dd.sort_by(f64::total_cmp);
        for (g, w) in got.iter().zip(&dd) {
            assert!((g - w).abs() < 1e-14, "{got:?} vs {dd:?}");
        }
    }

    #[test]
    fn solve_and_newton() {
        let a = [[4.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 2.0]];
        let x = solve(a, [1.0, 2.0, 3.0]).unwrap();
        for r in 0..3 {
            let s: f64 = (0..3).map(|k| a[r][k] * x[k]).sum();
            assert!((s - [1.0, 2.0, 3.0][r]).abs() < 1e-14);
        }
        assert!(solve([[1.0, 2.0], [2.0, 4.0]], [1.0, 1.0]).is_none());
        // x_i³ = i+1
        let f = |v: &[f64; 4]| std::array::from_fn(|i| v[i].powi(3) - (i + 1) as f64);
        let r = newton4(&f, &|v| fd_jacobian(&f, v), [1.0; 4], 1e-13, 1e3).unwrap();
        for i in 0..4 {
            assert!((r[i] - ((i + 1) as f64).cbrt()).abs() < 1e-12);
        }
    }
}
