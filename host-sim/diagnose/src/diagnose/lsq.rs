//! Least squares on a column bank: Gram sums over the fit blocks and the held-out span,
//! the SPD solve, fits with cluster-robust (jackknife) standard errors, partial correlations.

use std::ops::Range;

use super::NR;

/// Gram sums of a column bank over a set of samples: `G = Σ CᵀC`, `b = Σ Cᵀy`, `yy`.
#[derive(Clone, Debug)]
pub(crate) struct Gram {
    g: Vec<f64>,
    b: Vec<f64>,
    yy: f64,
    /// Rows summed.
    pub rows: usize,
    m: usize,
}

impl Gram {
    fn new(m: usize) -> Self {
        Gram {
            g: vec![0.0; m * m],
            b: vec![0.0; m],
            yy: 0.0,
            rows: 0,
            m,
        }
    }

    fn add(&mut self, o: &Gram) {
        for (a, b) in self.g.iter_mut().zip(&o.g) {
            *a += b;
        }
        for (a, b) in self.b.iter_mut().zip(&o.b) {
            *a += b;
        }
        self.yy += o.yy;
        self.rows += o.rows;
    }

    fn accumulate(
        &mut self,
        cols: &[&[[f64; NR]]],
        y: &[[f64; NR]],
        range: Range<usize>,
        ok: &[bool],
    ) {
        let m = self.m;
        let mut row = vec![0.0; m];
        for k in range {
            if !ok[k] {
                continue;
            }
            for r in 0..NR {
                for (j, c) in cols.iter().enumerate() {
                    row[j] = c[k][r];
                }
                let yv = y[k][r];
                self.yy += yv * yv;
                for i in 0..m {
                    let ri = row[i];
                    if ri == 0.0 {
                        continue;
                    }
                    self.b[i] += ri * yv;
                    let gi = &mut self.g[i * m..(i + 1) * m];
                    for j in i..m {
                        gi[j] += ri * row[j];
                    }
                }
                self.rows += 1;
            }
        }
        // mirror
        for i in 0..m {
            for j in 0..i {
                self.g[i * m + j] = self.g[j * m + i];
            }
        }
    }

    /// Energy of `y − C_S β` for the subset `s` and coefficients `beta`.
    fn energy(&self, s: &[usize], beta: &[f64]) -> f64 {
        let m = self.m;
        let mut e = self.yy;
        for (a, &i) in s.iter().enumerate() {
            e -= 2.0 * beta[a] * self.b[i];
            for (c, &j) in s.iter().enumerate() {
                e += beta[a] * beta[c] * self.g[i * m + j];
            }
        }
        e
    }

    fn sub(&self, s: &[usize]) -> (Vec<f64>, Vec<f64>) {
        let p = s.len();
        let mut g = vec![0.0; p * p];
        let mut b = vec![0.0; p];
        for (a, &i) in s.iter().enumerate() {
            b[a] = self.b[i];
            for (c, &j) in s.iter().enumerate() {
                g[a * p + c] = self.g[i * self.m + j];
            }
        }
        (g, b)
    }
}

/// A fitted subset: coefficients, cluster-robust standard errors, energies.
#[derive(Clone, Debug)]
pub(crate) struct Fit {
    /// The bank columns fitted.
    pub cols: Vec<usize>,
    pub beta: Vec<f64>,
    pub sigma: Vec<f64>,
    /// The cluster-robust covariance of `beta` (row-major; jackknife, [`Bank::fit`]).
    pub cov: Vec<f64>,
    /// Fit-span energy.
    pub e_fit: f64,
    /// Held-out energy.
    pub e_hold: f64,
}

impl Fit {
    /// The residual `y − C β` of sample `k` (`cols`: the bank's columns).
    pub(crate) fn resid(&self, y: &[[f64; NR]], cols: &[&[[f64; NR]]], k: usize) -> [f64; NR] {
        let mut r = y[k];
        for (a, &c) in self.cols.iter().enumerate() {
            for i in 0..NR {
                r[i] -= self.beta[a] * cols[c][k][i];
            }
        }
        r
    }
}

/// The scoring machinery: Grams of the full column bank over the fit blocks and the
/// held-out span.
pub(crate) struct Bank {
    blocks: Vec<Gram>,
    /// Over the fit span.
    pub fit: Gram,
    /// Over the held-out span.
    pub hold: Gram,
}

impl Bank {
    pub(crate) fn build(
        cols: &[&[[f64; NR]]],
        y: &[[f64; NR]],
        ok: &[bool],
        fit: &[Range<usize>],
        hold: Range<usize>,
    ) -> Self {
        use rayon::prelude::*;
        let m = cols.len();
        // each block's sums on its own thread (the sums in each block and their order
        // over the blocks as on one thread: the same bits)
        let (blocks, hg) = rayon::join(
            || -> Vec<Gram> {
                fit.par_iter()
                    .map(|r| {
                        let mut g = Gram::new(m);
                        g.accumulate(cols, y, r.clone(), ok);
                        g
                    })
                    .collect()
            },
            || {
                let mut hg = Gram::new(m);
                hg.accumulate(cols, y, hold, ok);
                hg
            },
        );
        let mut fg = Gram::new(m);
        for b in &blocks {
            fg.add(b);
        }
        Bank {
            blocks,
            fit: fg,
            hold: hg,
        }
    }

    /// Fits the columns `s` on the fit span, with the cluster-robust covariance of the
    /// coefficients over the fit blocks in its jackknife form (CR3, MacKinnon & White 1985;
    /// Bell & McCaffrey 2002): `V = (B − 1)/B · Σ_b (G − G_b)⁻¹ ŝ_b ŝ_bᵀ (G − G_b)⁻¹`, the
    /// spread of the B leave-one-block-out fits. `ŝ_b = b_b − G_b β` is block b's score at
    /// the fit; the fit has already absorbed part of each block's noise (most where a block
    /// carries much of a column's information), which the plain sandwich
    /// `G⁻¹ (Σ ŝ_b ŝ_bᵀ) G⁻¹ · B/(B − 1)` (CR1, used up to issue 11) does not undo: on 48
    /// clean toleranced devices the calibration's σ against the spread of the estimates over
    /// noise realizations had a geometric mean of 0.951 with it on 16 blocks (0.967 expected
    /// of an unbiased variance from 15 sums), 0.977 in this form on 32 (0.984): docs/notes.md, "The
    /// parameter face's σ". With fewer than two blocks it is the plain sandwich.
    pub(crate) fn fit(&self, s: &[usize]) -> Fit {
        let p = s.len();
        let (g, b) = self.fit.sub(s);
        let (beta, inv) = solve_spd(&g, &b, p);
        let nb = self.blocks.iter().filter(|blk| blk.rows > 0).count();
        let mut cov = vec![0.0; p * p];
        if nb >= 2 {
            for blk in self.blocks.iter().filter(|blk| blk.rows > 0) {
                let (gb, bb) = blk.sub(s);
                let sc: Vec<f64> = (0..p)
                    .map(|i| bb[i] - (0..p).map(|j| gb[i * p + j] * beta[j]).sum::<f64>())
                    .collect();
                let rest: Vec<f64> = g.iter().zip(&gb).map(|(a, c)| a - c).collect();
                let d = solve_spd_x(&rest, &sc, p);
                for i in 0..p {
                    if d[i] != 0.0 {
                        for j in 0..p {
                            cov[i * p + j] += d[i] * d[j];
                        }
                    }
                }
            }
            let corr = (nb as f64 - 1.0) / nb as f64;
            cov.iter_mut().for_each(|v| *v *= corr);
        } else {
            // one block: G⁻¹ (ŝ ŝᵀ) G⁻¹ (ŝ is 0 at the fit: no spread to measure)
            self.add_sandwich(s, &beta, &inv, &mut cov);
        }
        let sigma = (0..p).map(|i| cov[i * p + i].max(0.0).sqrt()).collect();
        Fit {
            cov,
            cols: s.to_vec(),
            e_fit: self.fit.energy(s, &beta),
            e_hold: self.hold.energy(s, &beta),
            beta,
            sigma,
        }
    }

    /// The plain cluster-robust sandwich `G⁻¹ (Σ ŝ_b ŝ_bᵀ) G⁻¹ · B/(B − 1)` (CR1) of the
    /// columns `s`: [`Bank::fit`]'s covariance up to issue 11, kept for the tests that
    /// compare the two.
    #[cfg(test)]
    pub(crate) fn cov_cr1(&self, s: &[usize]) -> Vec<f64> {
        let p = s.len();
        let (g, b) = self.fit.sub(s);
        let (beta, inv) = solve_spd(&g, &b, p);
        let mut cov = vec![0.0; p * p];
        self.add_sandwich(s, &beta, &inv, &mut cov);
        let nb = self.blocks.len() as f64;
        let corr = if nb > 1.0 { nb / (nb - 1.0) } else { 1.0 };
        cov.iter_mut().for_each(|v| *v *= corr);
        cov
    }

    /// Adds the plain sandwich `G⁻¹ (Σ_b ŝ_b ŝ_bᵀ) G⁻¹` over every block to `cov`
    /// (`ŝ_b = b_b − G_b β`, the block's score at the fit `beta`; `inv` = `G⁻¹`).
    fn add_sandwich(&self, s: &[usize], beta: &[f64], inv: &[f64], cov: &mut [f64]) {
        let p = s.len();
        for blk in &self.blocks {
            let (gb, bb) = blk.sub(s);
            let sc: Vec<f64> = (0..p)
                .map(|i| bb[i] - (0..p).map(|j| gb[i * p + j] * beta[j]).sum::<f64>())
                .collect();
            let d: Vec<f64> = (0..p)
                .map(|i| (0..p).map(|j| inv[i * p + j] * sc[j]).sum())
                .collect();
            for i in 0..p {
                for j in 0..p {
                    cov[i * p + j] += d[i] * d[j];
                }
            }
        }
    }

    /// Correlation of two columns after projecting out `base` (fit span).
    pub(crate) fn partial_corr(&self, a: usize, b: usize, base: &[usize]) -> f64 {
        let m = self.fit.m;
        let g = &self.fit.g;
        let resid = |i: usize, j: usize| -> f64 {
            // (c_i − P c_i)·(c_j − P c_j) = G_ij − G_iB G_BB⁻¹ G_Bj
            if base.is_empty() {
                return g[i * m + j];
            }
            let (gbb, _) = self.fit.sub(base);
            let gbj: Vec<f64> = base.iter().map(|&k| g[k * m + j]).collect();
            let (x, _) = solve_spd(&gbb, &gbj, base.len());
            g[i * m + j]
                - base
                    .iter()
                    .zip(&x)
                    .map(|(&k, v)| g[i * m + k] * v)
                    .sum::<f64>()
        };
        let (aa, bb, ab) = (resid(a, a), resid(b, b), resid(a, b));
        if aa > 0.0 && bb > 0.0 {
            ab / (aa * bb).sqrt()
        } else {
            0.0
        }
    }
}

/// Held-out energy per row (per sample) of the residual of a fit.
pub(crate) fn row_energy(
    f: &Fit,
    y: &[[f64; NR]],
    cols: &[&[[f64; NR]]],
    ok: &[bool],
    span: Range<usize>,
) -> [f64; NR] {
    let mut acc = [0.0; NR];
    let mut n = 0usize;
    for k in span.filter(|&k| ok[k]) {
        n += 1;
        let r = f.resid(y, cols, k);
        for i in 0..NR {
            acc[i] += r[i] * r[i];
        }
    }
    acc.map(|v| v / n.max(1) as f64)
}

/// Integrated correlation length (in rows) of the residual of a fit on `span`:
/// 1 + 2Σρ(lag) over sample lags up to 250 (0.5 s), per row, averaged; at least 1.
pub(crate) fn corr_length(
    y: &[[f64; NR]],
    ok: &[bool],
    cols: &[&[[f64; NR]]],
    f: &Fit,
    span: Range<usize>,
) -> f64 {
    let r: Vec<[f64; NR]> = span
        .filter(|&k| ok[k])
        .map(|k| f.resid(y, cols, k))
        .collect();
    let m = r.len();
    if m < 500 {
        return 1.0;
    }
    let mut tau = 0.0;
    for i in 0..NR {
        let var: f64 = r.iter().map(|v| v[i] * v[i]).sum::<f64>() / m as f64;
        if var <= 0.0 {
            continue;
        }
        let mut s = 1.0;
        for lag in 1..250 {
            let c: f64 =
                (0..m - lag).map(|k| r[k][i] * r[k + lag][i]).sum::<f64>() / (m - lag) as f64 / var;
            if c <= 0.0 {
                break;
            }
            s += 2.0 * c;
        }
        tau += s;
    }
    (tau / NR as f64).max(1.0)
}

/// Solves the symmetric positive semi-definite system `g x = b` (p×p, row-major) by
/// nalgebra's Cholesky with Jacobi scaling and a tiny ridge (1e-12 of the diagonal) for
/// collinear columns; a non-positive pivot (rounding on collinear columns) is replaced by
/// 1e-300. Also returns the inverse (for covariances), row-major.
///
/// (It replaced a hand-written Cholesky of the same scaling, ridge and guard: on the blind
/// benchmark's 20 reports of seed 5055 every verdict, ranking and score is the same and no
/// reported number moves by more than 1.2e-9 relative (the catch-all's 80-column fits
/// amplify the reordered sums of the back substitution); the solve is 1.1–1.8× faster for
/// p = 2…90.)
pub(crate) fn solve_spd(g: &[f64], b: &[f64], p: usize) -> (Vec<f64>, Vec<f64>) {
    spd(g, b, p, true)
}

/// [`solve_spd`]'s solution alone (no inverse).
pub(crate) fn solve_spd_x(g: &[f64], b: &[f64], p: usize) -> Vec<f64> {
    spd(g, b, p, false).0
}

fn spd(g: &[f64], b: &[f64], p: usize, with_inverse: bool) -> (Vec<f64>, Vec<f64>) {
    use nalgebra::{Cholesky, DMatrix, DVector};
    if p == 0 {
        return (Vec::new(), Vec::new());
    }
    let d: Vec<f64> = (0..p)
        .map(|i| {
            let v = g[i * p + i];
            if v > 0.0 { 1.0 / v.sqrt() } else { 0.0 }
        })
        .collect();
    let a = DMatrix::from_fn(p, p, |i, j| {
        let v = g[i * p + j] * d[i] * d[j];
        if i == j {
            v + (1e-12 + if d[i] == 0.0 { 1.0 } else { 0.0 })
        } else {
            v
        }
    });
    let Some(ch) = Cholesky::new_with_substitute(a, 1e-300) else {
        return (vec![0.0; p], vec![0.0; p * p]);
    };
    let x = ch.solve(&DVector::from_fn(p, |i, _| b[i] * d[i]));
    let xs = (0..p).map(|i| x[i] * d[i]).collect();
    if !with_inverse {
        return (xs, Vec::new());
    }
    let inv = ch.inverse();
    let mut iv = vec![0.0; p * p];
    for r in 0..p {
        for c in 0..p {
            iv[r * p + c] = inv[(r, c)] * d[r] * d[c];
        }
    }
    (xs, iv)
}
