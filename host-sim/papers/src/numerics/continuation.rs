//! Pseudo-arclength continuation of a 4-dimensional slow flow in one parameter: branches
//! of steady states traced through their folds, deduplicated, and their folds.

use super::linalg::{inf_norm, solve};

/// Settings of [`trace_branch`] / [`find_branches`].
#[derive(Clone, Debug)]
pub struct ContinuationSettings {
    /// Parameter window; tracing stops at the first point outside.
    pub p_min: f64,
    /// Upper end of the parameter window.
    pub p_max: f64,
    /// The parameter enters the arclength metric as `p·p_scale` (makes it commensurate
    /// with the state).
    pub p_scale: f64,
    /// Initial arclength step (in the scaled metric).
    pub h_init: f64,
    /// Smallest step before giving up.
    pub h_min: f64,
    /// Largest step (also the spacing of the branch points).
    pub h_max: f64,
    /// Points per direction at most.
    pub max_points: usize,
    /// Stop when `‖v‖∞` exceeds this.
    pub amp_max: f64,
    /// Stop when `‖v‖∞` falls below this or the branch passes through `v = 0` onto its
    /// mirror image (it reached the trivial state); `≤ 0` disables both checks.
    pub trivial_tol: f64,
    /// Residual tolerance `‖f‖∞` of the corrector.
    pub res_tol: f64,
}

/// One point of a traced branch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BranchPoint {
    /// Parameter value.
    pub p: f64,
    /// Slow-flow state.
    pub v: [f64; 4],
    /// Largest real part of the Jacobian's eigenvalues.
    pub max_re: f64,
    /// Lyapunov (linear) stability.
    pub stable: bool,
}

type Flow<'a> = &'a dyn Fn(&[f64; 4], f64) -> [f64; 4];

/// Stability of a point `(v, p)`: `(max Re λ, stable)`.
type Stability<'a> = &'a dyn Fn(&[f64; 4], f64) -> (f64, bool);

fn jac5(f: Flow<'_>, u: &[f64; 5], ps: f64) -> [[f64; 5]; 4] {
    let mut j = [[0.0; 5]; 4];
    for c in 0..5 {
        let h = 1e-7 * u[c].abs().max(1.0);
        let mut up = *u;
        let mut um = *u;
        up[c] += h;
        um[c] -= h;
        let fp = f(&[up[0], up[1], up[2], up[3]], up[4] / ps);
        let fm = f(&[um[0], um[1], um[2], um[3]], um[4] / ps);
        for r in 0..4 {
            j[r][c] = (fp[r] - fm[r]) / (2.0 * h);
        }
    }
    j
}

fn tangent(j: &[[f64; 5]; 4], t_prev: &[f64; 5]) -> Option<[f64; 5]> {
    let m: [[f64; 5]; 5] = std::array::from_fn(|r| if r < 4 { j[r] } else { *t_prev });
    let t = solve(m, [0.0, 0.0, 0.0, 0.0, 1.0])?;
    let n = t.iter().map(|x| x * x).sum::<f64>().sqrt();
    Some(t.map(|x| x / n))
}

/// Traces the solution curve of `f(v, p) = 0` from the solution `(v0, p0)` in the direction
/// of increasing (`dir > 0`) or decreasing `p` by pseudo-arclength continuation
/// (secant-free: tangent from the bordered Jacobian, Newton corrector on the arclength
/// hyperplane, step halving on failure or on turns sharper than ~18°). Passes folds.
/// Stops outside the parameter window, beyond `amp_max`, at the trivial state (see
/// [`ContinuationSettings::trivial_tol`]), after `max_points` or when the step falls
/// below `h_min`. Returns the points (the seed first) and whether the curve closed on
/// itself.
pub fn trace_branch(
    f: Flow<'_>,
    v0: [f64; 4],
    p0: f64,
    dir: f64,
    cs: &ContinuationSettings,
) -> (Vec<([f64; 4], f64)>, bool) {
    let ps = cs.p_scale;
    let to_u = |v: &[f64; 4], p: f64| [v[0], v[1], v[2], v[3], p * ps];
    let res = |u: &[f64; 5]| f(&[u[0], u[1], u[2], u[3]], u[4] / ps);
    let u0 = to_u(&v0, p0);
    let mut pts = vec![(v0, p0)];
    let Some(mut t) = tangent(&jac5(f, &u0, ps), &[0.0, 0.0, 0.0, 0.0, dir.signum()]) else {
        return (pts, false);
    };
    let mut u = u0;
    let mut h = cs.h_init;
    while pts.len() < cs.max_points {
        let up: [f64; 5] = std::array::from_fn(|i| u[i] + h * t[i]);
        let mut uc = up;
        let mut ok = false;
        let mut its = 0;
        for it in 0..12 {
            its = it + 1;
            let r = res(&uc);
            let j = jac5(f, &uc, ps);
            let m: [[f64; 5]; 5] = std::array::from_fn(|k| if k < 4 { j[k] } else { t });
            let arc: f64 = (0..5).map(|i| t[i] * (uc[i] - up[i])).sum();
            let Some(du) = solve(m, [-r[0], -r[1], -r[2], -r[3], -arc]) else {
                break;
            };
            for i in 0..5 {
                uc[i] += du[i];
            }
            let small = inf_norm(&du) <= 1e-12 * (1.0 + inf_norm(&uc));
            if inf_norm(&res(&uc)) <= cs.res_tol && (small || it >= 1) {
                ok = true;
                break;
            }
        }
        let tn = if ok {
            tangent(&jac5(f, &uc, ps), &t)
        } else {
            None
        };
        let turn_ok = tn.is_some_and(|tn| (0..5).map(|i| tn[i] * t[i]).sum::<f64>() > 0.95);
        if !ok || !turn_ok {
            h *= 0.5;
            if h < cs.h_min {
                break;
            }
            continue;
        }
        let v = [uc[0], uc[1], uc[2], uc[3]];
        let vp = [u[0], u[1], u[2], u[3]];
        if cs.trivial_tol > 0.0 && (0..4).map(|i| v[i] * vp[i]).sum::<f64>() <= 0.0 {
            // passed through the trivial state onto the mirrored branch
            break;
        }
        u = uc;
        t = tn.unwrap_or(t);
        let p = u[4] / ps;
        pts.push((v, p));
        if its <= 3 {
            h = (h * 1.4).min(cs.h_max);
        }
        let vn = inf_norm(&v);
        if p < cs.p_min || p > cs.p_max || vn > cs.amp_max || vn < cs.trivial_tol {
            break;
        }
        let d0 = (0..5).map(|i| (u[i] - u0[i]).powi(2)).sum::<f64>().sqrt();
        if pts.len() > 20 && d0 < 1.5 * cs.h_max {
            pts.push((v0, p0));
            return (pts, true);
        }
    }
    (pts, false)
}

/// All distinct branches through the `seeds`: each seed not already on a traced branch
/// (distance in `(p·p_scale, sig(v))` below `0.75·h_max`, so symmetric copies with the
/// same signature count as the same branch) is traced both ways and joined. Every point
/// gets its stability from `stab` (returns `(max Re λ, stable)`).
pub fn find_branches(
    f: Flow<'_>,
    stab: Stability<'_>,
    sig: &dyn Fn(&[f64; 4]) -> [f64; 2],
    seeds: &[([f64; 4], f64)],
    cs: &ContinuationSettings,
) -> Vec<Vec<BranchPoint>> {
    let key = |v: &[f64; 4], p: f64| {
        let s = sig(v);
        [p * cs.p_scale, s[0], s[1]]
    };
    let mut keys: Vec<[f64; 3]> = Vec::new();
    let mut out = Vec::new();
    let tol2 = (0.75 * cs.h_max).powi(2);
    for &(v, p) in seeds {
        let k = key(&v, p);
        let near = keys
            .iter()
            .any(|q| (0..3).map(|i| (q[i] - k[i]).powi(2)).sum::<f64>() < tol2);
        if near {
            continue;
        }
        let (fwd, closed) = trace_branch(f, v, p, 1.0, cs);
        let mut pts: Vec<([f64; 4], f64)> = if closed {
            fwd
        } else {
            let (bwd, _) = trace_branch(f, v, p, -1.0, cs);
            bwd.into_iter().skip(1).rev().chain(fwd).collect()
        };
        // densify the dedupe keys between points (the spacing can reach h_max)
        for w in pts.windows(2) {
            let (a, b) = (key(&w[0].0, w[0].1), key(&w[1].0, w[1].1));
            for s in 0..4 {
                let x = s as f64 / 4.0;
                keys.push(std::array::from_fn(|i| a[i] + x * (b[i] - a[i])));
            }
        }
        if let Some(l) = pts.last() {
            keys.push(key(&l.0, l.1));
        }
        let branch = pts
            .drain(..)
            .map(|(v, p)| {
                let (max_re, stable) = stab(&v, p);
                BranchPoint {
                    p,
                    v,
                    max_re,
                    stable,
                }
            })
            .collect();
        out.push(branch);
    }
    out
}

/// Parameter values where a branch turns back (folds / saddle-nodes), with the point.
pub fn folds(branch: &[BranchPoint]) -> Vec<BranchPoint> {
    let mut out = Vec::new();
    for w in branch.windows(3) {
        let (d1, d2) = (w[1].p - w[0].p, w[2].p - w[1].p);
        if d1 * d2 < 0.0 {
            out.push(w[1]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn continuation_follows_a_circle_through_its_folds() {
        // f(v, p) = [v0² + p² − 1, v1, v2, v3]: the unit circle in (v0, p), folds at p = ±1
        let f = |v: &[f64; 4], p: f64| [v[0] * v[0] + p * p - 1.0, v[1], v[2], v[3] - 0.0];
        let cs = ContinuationSettings {
            p_min: -2.0,
            p_max: 2.0,
            p_scale: 1.0,
            h_init: 0.01,
            h_min: 1e-8,
            h_max: 0.05,
            max_points: 10_000,
            amp_max: 10.0,
            trivial_tol: -1.0,
            res_tol: 1e-13,
        };
        let (pts, closed) = trace_branch(&f, [1.0, 0.0, 0.0, 0.0], 0.0, 1.0, &cs);
        assert!(closed, "circle must close ({} points)", pts.len());
        for (v, p) in &pts {
            assert!((v[0].hypot(*p) - 1.0).abs() < 1e-12);
        }
        let bp: Vec<BranchPoint> = pts
            .iter()
            .map(|(v, p)| BranchPoint {
                p: *p,
                v: *v,
                max_re: 0.0,
                stable: true,
            })
            .collect();
        let fl = folds(&bp);
        assert_eq!(fl.len(), 2, "{fl:?}");
        let mut ps: Vec<f64> = fl.iter().map(|b| b.p).collect();
        ps.sort_by(f64::total_cmp);
        assert!(
            (ps[0] + 1.0).abs() < 2e-3 && (ps[1] - 1.0).abs() < 2e-3,
            "{ps:?}"
        );
    }
}
