//! Stability of the rest state: Floquet exponents of the full linear time-periodic system
//! and the instability intervals of a growth rate.

use std::f64::consts::PI;

use super::model::AveragedModel;
use crate::complex::CplxExt;
use crate::numerics::eig4;

impl AveragedModel {
    /// Largest Floquet exponent (1/τ) of the rest state: the linear part of eq. (6) about
    /// 0 (as the prototype's `task1.floquet`), monodromy over one pump period π/ω by RK4
    /// with 512 steps, `max ln|multiplier| / period`.
    pub fn floquet_exponent(&self, omega: f64) -> f64 {
        let (t1, t2) = (&self.theta.drive, &self.theta.sense);
        let (t12, s) = (self.t12(), self.s);
        let period = PI / omega;
        let n = 512;
        let h = period / n as f64;
        let mat = |t: f64| -> [[f64; 4]; 4] {
            let k = t12 + s * t1[5] * (2.0 * omega * t).cos();
            [
                [0.0, 1.0, 0.0, 0.0],
                [k, t1[0], t1[2], t1[3]],
                [0.0, 0.0, 0.0, 1.0],
                [t2[2], t2[3], t2[1], t2[0]],
            ]
        };
        let mv = |m: &[[f64; 4]; 4], z: &[f64; 4]| -> [f64; 4] {
            std::array::from_fn(|i| (0..4).map(|k| m[i][k] * z[k]).sum())
        };
        // columns of the fundamental matrix
        let mut cols: [[f64; 4]; 4] =
            std::array::from_fn(|c| std::array::from_fn(|r| f64::from(u8::from(r == c))));
        for i in 0..n {
            let t = i as f64 * h;
            let (ma, mh, me) = (mat(t), mat(t + 0.5 * h), mat(t + h));
            for z in cols.iter_mut() {
                let k1 = mv(&ma, z);
                let z2: [f64; 4] = std::array::from_fn(|q| z[q] + 0.5 * h * k1[q]);
                let k2 = mv(&mh, &z2);
                let z3: [f64; 4] = std::array::from_fn(|q| z[q] + 0.5 * h * k2[q]);
                let k3 = mv(&mh, &z3);
                let z4: [f64; 4] = std::array::from_fn(|q| z[q] + h * k3[q]);
                let k4 = mv(&me, &z4);
                for q in 0..4 {
                    z[q] += h / 6.0 * (k1[q] + 2.0 * (k2[q] + k3[q]) + k4[q]);
                }
            }
        }
        let m: [[f64; 4]; 4] = std::array::from_fn(|r| std::array::from_fn(|c| cols[c][r]));
        eig4(&m)
            .iter()
            .map(|z| z.modulus().ln() / period)
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// The rest-state instability band from Floquet exponents of the full linear
    /// time-periodic system, see [`unstable_interval`] (scan `[lo, hi]` with `step`).
    pub fn floquet_band(&self, lo: f64, hi: f64, step: f64) -> Option<(f64, f64)> {
        unstable_interval(&|w| self.floquet_exponent(w), lo, hi, step)
    }

    /// The band where the rest state of the averaged flow itself (drive and sense coupled)
    /// is unstable, from its Jacobian's eigenvalues, see [`unstable_interval`]. The
    /// closed-form [`Self::trivial_band`] neglects the coupling to the sense mode.
    pub fn rest_band(&self, lo: f64, hi: f64, step: f64) -> Option<(f64, f64)> {
        unstable_interval(&|w| self.trivial(w).max_re, lo, hi, step)
    }
}

/// The outermost interval of `[lo, hi]` where the growth rate `g(ω)` is positive: scanned
/// with `step`, both edges refined by bisection to 1e-7. `None` if `g ≤ 0` on the grid.
pub fn unstable_interval(
    g: &dyn Fn(f64) -> f64,
    lo: f64,
    hi: f64,
    step: f64,
) -> Option<(f64, f64)> {
    let n = ((hi - lo) / step).round() as usize;
    let grid: Vec<f64> = (0..=n).map(|i| lo + i as f64 * step).collect();
    let ex: Vec<f64> = grid.iter().map(|&w| g(w)).collect();
    let first = ex.iter().position(|&e| e > 0.0)?;
    let last = ex.iter().rposition(|&e| e > 0.0)?;
    let bisect = |mut a: f64, mut b: f64| {
        let fa = g(a) > 0.0;
        while (b - a).abs() > 1e-7 {
            let m = 0.5 * (a + b);
            if (g(m) > 0.0) == fa {
                a = m;
            } else {
                b = m;
            }
        }
        0.5 * (a + b)
    };
    let l = if first > 0 {
        bisect(grid[first - 1], grid[first])
    } else {
        grid[0]
    };
    let h = if last + 1 < grid.len() {
        bisect(grid[last], grid[last + 1])
    } else {
        grid[last]
    };
    Some((l, h))
}
