//! An adaptive embedded Runge–Kutta integrator: Dormand–Prince 5(4) (the seven-stage
//! FSAL pair of Dormand & Prince 1980, the coefficients of Hairer, Nørsett & Wanner,
//! *Solving ODEs I*, table 5.2), local extrapolation (the 5th-order solution is kept), a
//! mixed absolute/relative error norm per component and a PI step-size controller
//! (Gustafsson; β = 0.04). Steps end exactly on the caller's output instants.

// dense small-matrix and stage arithmetic reads best with indices
#![allow(clippy::needless_range_loop)]

/// Tolerances and limits of the integrator.
#[derive(Clone, Debug, PartialEq)]
pub struct Tolerances {
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance per component (same length as the state). The error norm runs
    /// over the leading components with a finite tolerance; components from the first
    /// infinite one on ride along uncontrolled (the lock-in's ladders).
    pub atol: Vec<f64>,
    /// Largest step, s.
    pub h_max: f64,
    /// `Some(ω)`: the controlled components are (position, velocity) pairs of oscillators
    /// near ω (rad/s), and the relative tolerance applies to each pair's amplitude
    /// `√(q² + (q'/ω)²)` (× ω for the velocity), so that a zero crossing does not demand
    /// a tiny step.
    pub pair_omega: Option<f64>,
}

/// Counters of the integrator.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Stats {
    /// Accepted steps.
    pub accepted: u64,
    /// Rejected steps.
    pub rejected: u64,
    /// Right-hand-side evaluations.
    pub evals: u64,
}

const C2: f64 = 1.0 / 5.0;
const C3: f64 = 3.0 / 10.0;
const C4: f64 = 4.0 / 5.0;
const C5: f64 = 8.0 / 9.0;
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const B1: f64 = 35.0 / 384.0;
const B3: f64 = 500.0 / 1113.0;
const B4: f64 = 125.0 / 192.0;
const B5: f64 = -2187.0 / 6784.0;
const B6: f64 = 11.0 / 84.0;
// error coefficients: b − b̂ (5th minus 4th order weights)
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;

/// The integrator's state: the solution, its derivative there (FSAL), the proposed step
/// and the work buffers.
#[derive(Clone, Debug)]
pub struct Dopri {
    /// Current time.
    pub t: f64,
    /// Current solution.
    pub y: Vec<f64>,
    tol: Tolerances,
    h: f64,
    f0: Vec<f64>,
    fresh: bool,
    k: [Vec<f64>; 6],
    tmp: Vec<f64>,
    y5: Vec<f64>,
    err_prev: f64,
    /// Number of leading components in the error norm.
    n_control: usize,
    /// Counters.
    pub stats: Stats,
}

impl Dopri {
    /// An integrator at `t0`, `y0` with the tolerances `tol` and a first step `h0`.
    pub fn new(t0: f64, y0: Vec<f64>, tol: Tolerances, h0: f64) -> Self {
        let n = y0.len();
        assert_eq!(tol.atol.len(), n, "one absolute tolerance per component");
        let z = || vec![0.0; n];
        let n_control = tol.atol.iter().take_while(|a| a.is_finite()).count();
        Self {
            t: t0,
            y: y0,
            tol,
            h: h0,
            f0: z(),
            fresh: false,
            k: [z(), z(), z(), z(), z(), z()],
            tmp: z(),
            y5: z(),
            err_prev: 1e-4,
            n_control,
            stats: Stats::default(),
        }
    }

    /// Forgets the derivative at the current point (the right-hand side changed there: a
    /// new input interval begins).
    pub fn invalidate(&mut self) {
        self.fresh = false;
    }

    /// Integrates `dy/dt = f(t, y)` up to `t_end` exactly. `f(t, y, dy)` writes `dy`.
    pub fn advance_to(&mut self, t_end: f64, f: &mut impl FnMut(f64, &[f64], &mut [f64])) {
        if !self.fresh {
            f(self.t, &self.y, &mut self.f0);
            self.stats.evals += 1;
            self.fresh = true;
        }
        while self.t < t_end {
            let remaining = t_end - self.t;
            let mut h = self.h.min(self.tol.h_max);
            let last = h >= remaining * (1.0 - 1e-12);
            if last {
                h = remaining;
            }
            let err = self.try_step(h, f);
            if err <= 1.0 {
                self.stats.accepted += 1;
                self.t = if last { t_end } else { self.t + h };
                std::mem::swap(&mut self.y, &mut self.y5);
                // FSAL: the 7th stage is f at the new point
                std::mem::swap(&mut self.f0, &mut self.k[5]);
                let fac = 0.9 * err.max(1e-10).powf(-0.7 / 5.0) * self.err_prev.powf(0.04);
                let grown = h * fac.clamp(0.2, 5.0);
                // a step shortened to land on t_end does not shrink the next proposal
                self.h = if last { self.h.max(grown) } else { grown };
                self.err_prev = err.max(1e-4);
            } else {
                self.stats.rejected += 1;
                let fac = 0.9 * err.powf(-1.0 / 5.0);
                self.h = h * fac.clamp(0.1, 0.9);
                assert!(
                    self.h > 1e-14 * self.t.abs().max(1e-6),
                    "step size underflow at t = {} s",
                    self.t
                );
            }
        }
    }

    /// One trial step of length `h` from (t, y): the 5th-order solution into `y5`, the 7th
    /// stage into `k[5]`; returns the scaled error norm.
    fn try_step(&mut self, h: f64, f: &mut impl FnMut(f64, &[f64], &mut [f64])) -> f64 {
        let t = self.t;
        let n = self.y.len();
        let (y, f0, tmp) = (&self.y, &self.f0, &mut self.tmp);
        let [k2, k3, k4, k5, k6, k7] = &mut self.k;
        for i in 0..n {
            tmp[i] = y[i] + h * A21 * f0[i];
        }
        f(t + C2 * h, tmp, k2);
        for i in 0..n {
            tmp[i] = y[i] + h * (A31 * f0[i] + A32 * k2[i]);
        }
        f(t + C3 * h, tmp, k3);
        for i in 0..n {
            tmp[i] = y[i] + h * (A41 * f0[i] + A42 * k2[i] + A43 * k3[i]);
        }
        f(t + C4 * h, tmp, k4);
        for i in 0..n {
            tmp[i] = y[i] + h * (A51 * f0[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
        }
        f(t + C5 * h, tmp, k5);
        for i in 0..n {
            tmp[i] =
                y[i] + h * (A61 * f0[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
        }
        f(t + h, tmp, k6);
        let y5 = &mut self.y5;
        for i in 0..n {
            y5[i] = y[i] + h * (B1 * f0[i] + B3 * k3[i] + B4 * k4[i] + B5 * k5[i] + B6 * k6[i]);
        }
        f(t + h, y5, k7);
        self.stats.evals += 6;
        let mut acc = 0.0;
        let nc = self.n_control;
        let amp = |v: &[f64], i: usize| match self.tol.pair_omega {
            // an oscillator's (position, velocity): its amplitude, not the phase's |value|
            Some(w) => {
                let j = i & !1;
                (v[j] * v[j] + (v[j + 1] / w) * (v[j + 1] / w)).sqrt()
                    * if i % 2 == 1 { w } else { 1.0 }
            }
            None => v[i].abs(),
        };
        for i in 0..nc {
            let e =
                h * (E1 * f0[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
            let sc = self.tol.atol[i] + self.tol.rtol * amp(y, i).max(amp(y5, i));
            acc += (e / sc) * (e / sc);
        }
        (acc / nc.max(1) as f64).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A harmonic oscillator over many periods: error at the tolerance's level, steps
    /// landing on the output instants.
    #[test]
    fn oscillator_is_accurate() {
        let w = std::f64::consts::TAU * 1000.0;
        let tol = Tolerances {
            rtol: 1e-10,
            atol: vec![1e-12; 2],
            h_max: 1.0,
            pair_omega: None,
        };
        let mut d = Dopri::new(0.0, vec![1.0, 0.0], tol, 1e-5);
        let mut f = |_t: f64, y: &[f64], dy: &mut [f64]| {
            dy[0] = y[1];
            dy[1] = -w * w * y[0];
        };
        for k in 1..=100 {
            d.advance_to(k as f64 * 1e-3, &mut f);
            assert_eq!(d.t, k as f64 * 1e-3);
        }
        let t = d.t;
        assert!((d.y[0] - (w * t).cos()).abs() < 1e-6, "{}", d.y[0]);
        assert!(d.stats.rejected < d.stats.accepted / 10);
    }
}
