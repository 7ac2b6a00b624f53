//! Quasi-static sweeps with their jumps, the branches of steady states by continuation,
//! and the hysteresis between the up- and the down-sweep.

use super::model::{AveragedModel, JUMP, RES_TOL, SEED_A, SweepPoint, dist};
use crate::numerics::linalg::inf_norm;
use crate::numerics::{BranchPoint, ContinuationSettings, find_branches};

impl AveragedModel {
    /// Integrates the slow flow at ω from `v0` (RK4, step 4 τ) until `‖v'‖∞ < 1e-8` or
    /// `t_max`; then polishes with Newton. Returns the attractor reached.
    pub fn settle(&self, omega: f64, v0: [f64; 4], t_max: f64) -> [f64; 4] {
        let dt = 4.0;
        let f = |v: &[f64; 4]| self.slow_flow(omega, v);
        let mut v = v0;
        let steps = (t_max / dt) as usize;
        let mut k = 0;
        while k < steps {
            for _ in 0..25 {
                let k1 = f(&v);
                let k2 = f(&std::array::from_fn(|i| v[i] + 0.5 * dt * k1[i]));
                let k3 = f(&std::array::from_fn(|i| v[i] + 0.5 * dt * k2[i]));
                let k4 = f(&std::array::from_fn(|i| v[i] + dt * k3[i]));
                for i in 0..4 {
                    v[i] += dt / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
                }
            }
            k += 25;
            if inf_norm(&f(&v)) < 1e-8 {
                if let Some(w) = self.newton(omega, v)
                    && dist(&w, &v) < 1e-2
                    && self.classify(omega, w).stable
                {
                    return w;
                }
                // a saddle's neighbourhood: keep integrating
                if inf_norm(&f(&v)) < 1e-13 && k > steps / 2 {
                    break;
                }
            }
        }
        self.newton(omega, v).unwrap_or(v)
    }

    /// Quasi-static sweep over `grid` (in order) starting from `start` at `grid[0]`: at
    /// each ω the state follows the previous one (Newton) if that stays a stable fixed
    /// point nearby; otherwise the slow flow is integrated to the attractor it falls into
    /// (a jump). An unstable rest state is left from the seed `A = 0.01`.
    pub fn sweep(&self, grid: &[f64], start: [f64; 4]) -> Vec<SweepPoint> {
        let mut out: Vec<SweepPoint> = Vec::with_capacity(grid.len());
        let mut v = start;
        for (k, &om) in grid.iter().enumerate() {
            let prev = v;
            let follow = (k > 0)
                .then(|| self.newton(om, prev))
                .flatten()
                .filter(|w| dist(w, &prev) < JUMP && self.classify(om, *w).stable);
            v = follow.unwrap_or_else(|| {
                let mut s = prev;
                if inf_norm(&s) < 1e-6 {
                    s = [SEED_A, 0.0, 0.0, 0.0];
                }
                self.settle(om, s, 4e5)
            });
            let st = self.classify(om, v);
            out.push(SweepPoint {
                omega: om,
                v,
                abs_a: v[0].hypot(v[1]),
                abs_b: v[2].hypot(v[3]),
                stable: st.stable,
                jump: k > 0 && dist(&v, &prev) > JUMP,
            });
        }
        out
    }

    /// All branches of nontrivial steady states for ω in `[lo, hi]`: multi-start at every
    /// `seed_step` of ω, each new branch traced by pseudo-arclength continuation (ω scaled
    /// by 200) until it leaves the window, reaches the rest state or |A|, |B| > 30.
    pub fn branches(&self, lo: f64, hi: f64, seed_step: f64) -> Vec<Vec<BranchPoint>> {
        let n = ((hi - lo) / seed_step).round() as usize;
        let mut seeds = Vec::new();
        for i in 0..=n {
            let om = lo + i as f64 * seed_step;
            for st in self.steady_states(om) {
                seeds.push((st.v(), om));
            }
        }
        let cs = ContinuationSettings {
            p_min: lo,
            p_max: hi,
            p_scale: 200.0,
            h_init: 0.005,
            h_min: 1e-6,
            h_max: 0.03,
            max_points: 20_000,
            amp_max: 30.0,
            trivial_tol: 2e-3,
            res_tol: RES_TOL,
        };
        let flow = |v: &[f64; 4], om: f64| self.slow_flow(om, v);
        let stab = |v: &[f64; 4], om: f64| {
            let st = self.classify(om, *v);
            (st.max_re, st.stable)
        };
        let sig = |v: &[f64; 4]| [v[0].hypot(v[1]), v[2].hypot(v[3])];
        find_branches(&flow, &stab, &sig, &seeds, &cs)
    }
}

/// ω intervals (first and last grid frequency) where the up- and the down-sweep end in
/// different states (`||A↑|−|A↓|| + ||B↑|−|B↓|| > tol`). `down` may be in either order.
pub fn hysteresis_intervals(up: &[SweepPoint], down: &[SweepPoint], tol: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let mut cur: Option<(f64, f64)> = None;
    for p in up {
        let Some(q) = down.iter().find(|q| (q.omega - p.omega).abs() < 1e-12) else {
            continue;
        };
        let differ = (p.abs_a - q.abs_a).abs() + (p.abs_b - q.abs_b).abs() > tol;
        cur = match (cur, differ) {
            (None, true) => Some((p.omega, p.omega)),
            (Some((a, _)), true) => Some((a, p.omega)),
            (Some(iv), false) => {
                out.push(iv);
                None
            }
            (None, false) => None,
        };
    }
    out.extend(cur);
    out
}
