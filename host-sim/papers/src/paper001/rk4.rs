//! Direct RK4 integration of eq. (19) against the stationary regimes of eq. (22).

use std::f64::consts::TAU;

use anyhow::{Context, Result};
use serde::Serialize;

use super::model::{Params, eq19_rhs, slow_from_state, state_from_slow};
use super::regimes::{Stationary, StationaryRecord, stationary_points};
use paragyro_simulator::par::try_par_map;

/// RK4 steps per period 2π/μ of the direct integration.
pub const STEPS_PER_PERIOD: usize = 64;

/// Summary of a direct integration of eq. (19).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Rk4Run {
    /// Length of the run, τ.
    #[serde(rename = "t_end_tau")]
    pub t_end: f64,
    /// Mean A over the averaging window.
    #[serde(rename = "mean_A")]
    pub mean_a: f64,
    /// Mean B over the averaging window.
    #[serde(rename = "mean_B")]
    pub mean_b: f64,
    /// Largest relative distance `‖s(τ) − s*‖/‖s*‖` over the whole run.
    #[serde(rename = "max_rel_dev")]
    pub max_dev: f64,
    /// Mean relative distance over the averaging window.
    #[serde(rename = "window_rel_dev")]
    pub window_dev: f64,
    /// Slow variables at the end.
    #[serde(rename = "final_q1_p1_q2_p2")]
    pub final_s: [f64; 4],
}

/// Integrates eq. (19) at λ with classic RK4 ([`STEPS_PER_PERIOD`] steps per period) from
/// the slow state `start` (τ = 0) to `t_end`; the slow variables are extracted at every
/// step and compared with `target`; means over `τ ≥ avg_from`.
pub fn rk4_eq19(
    p: &Params,
    lambda: f64,
    start: &[f64; 4],
    target: &[f64; 4],
    t_end: f64,
    avg_from: f64,
) -> Rk4Run {
    let mu = 1.0 + p.eps * lambda;
    let h = TAU / mu / STEPS_PER_PERIOD as f64;
    let n = (t_end / h).ceil() as usize;
    let norm = |v: &[f64; 4]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let tn = norm(target).max(1e-300);
    let mut z = state_from_slow(p, lambda, 0.0, start);
    let (mut sa, mut sb, mut sd, mut cnt) = (0.0, 0.0, 0.0, 0usize);
    let mut max_dev = 0.0f64;
    let mut s = *start;
    for i in 0..n {
        let t = i as f64 * h;
        let k1 = eq19_rhs(p, lambda, t, &z);
        let k2 = eq19_rhs(
            p,
            lambda,
            t + 0.5 * h,
            &std::array::from_fn(|q| z[q] + 0.5 * h * k1[q]),
        );
        let k3 = eq19_rhs(
            p,
            lambda,
            t + 0.5 * h,
            &std::array::from_fn(|q| z[q] + 0.5 * h * k2[q]),
        );
        let k4 = eq19_rhs(p, lambda, t + h, &std::array::from_fn(|q| z[q] + h * k3[q]));
        for q in 0..4 {
            z[q] += h / 6.0 * (k1[q] + 2.0 * (k2[q] + k3[q]) + k4[q]);
        }
        let te = (i + 1) as f64 * h;
        s = slow_from_state(p, lambda, te, &z);
        let d = norm(&std::array::from_fn(|q| s[q] - target[q])) / tn;
        max_dev = max_dev.max(d);
        if te >= avg_from {
            sa += s[0].hypot(s[1]);
            sb += s[2].hypot(s[3]);
            sd += d;
            cnt += 1;
        }
    }
    let c = cnt.max(1) as f64;
    Rk4Run {
        t_end: n as f64 * h,
        mean_a: sa / c,
        mean_b: sb / c,
        max_dev,
        window_dev: sd / c,
        final_s: s,
    }
}

/// The stable stationary regime with the largest B (spatial oscillation) at λ.
pub fn stable_spatial(p: &Params, lambda: f64) -> Option<Stationary> {
    stationary_points(p, lambda)
        .into_iter()
        .filter(|s| s.stable && s.b > 0.5)
        .max_by(|x, y| x.b.total_cmp(&y.b))
}

/// One RK4 confirmation as written to `paper001.json`.
#[derive(Clone, Debug, Serialize)]
pub struct Rk4Check {
    /// What is checked.
    pub name: String,
    /// The parameters of the run.
    pub params: Params,
    /// Detuning λ.
    pub lambda: f64,
    /// The stationary regime compared with.
    pub stationary: StationaryRecord,
    /// The run.
    pub rk4: Rk4Run,
    /// Mean A / stationary A − 1.
    #[serde(rename = "rel_err_A")]
    pub rel_err_a: f64,
    /// Mean B / stationary B − 1.
    #[serde(rename = "rel_err_B")]
    pub rel_err_b: f64,
    /// Whether the check passed (absent for the informative run).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pass: Option<bool>,
    /// The pass criterion.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub criterion: Option<String>,
    /// The informative run left the regime.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub drifts_away: Option<bool>,
    /// A note on the informative run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

/// What one check runs: parameters, λ, the regime, the start, the length and the averaging
/// start, τ.
struct CheckRun {
    name: String,
    p: Params,
    lambda: f64,
    st: Stationary,
    start: [f64; 4],
    t_end: f64,
    avg_from: f64,
}

impl CheckRun {
    fn run(self) -> Rk4Check {
        let r = rk4_eq19(
            &self.p,
            self.lambda,
            &self.start,
            &self.st.s,
            self.t_end,
            self.avg_from,
        );
        Rk4Check {
            name: self.name,
            params: self.p,
            lambda: self.lambda,
            stationary: self.st.record(),
            rk4: r,
            rel_err_a: r.mean_a / self.st.a - 1.0,
            rel_err_b: r.mean_b / self.st.b - 1.0,
            pass: None,
            criterion: None,
            drifts_away: None,
            note: None,
        }
    }
}

/// The RK4 confirmations: stable regimes stay (γ = 0) or are reached (γ > 0), an unstable
/// one is left, and the printed `xy` sign of eq. (19) does not reproduce (22). The six runs
/// go in parallel; returns them and whether every judged one passed.
pub fn rk4_checks() -> Result<(Vec<Rk4Check>, bool)> {
    let runs = check_runs()?;
    let mut checks = try_par_map(runs, |c| Ok(c.run()))?;
    let mut all_ok = true;
    for c in &mut checks[..3] {
        // (1) γ = 0, started on a stable regime: the slow variables stay near it
        let ok = c.rel_err_a.abs() < 0.03 && c.rel_err_b.abs() < 0.03 && c.rk4.max_dev < 0.1;
        c.pass = Some(ok);
        c.criterion = Some("|mean A, B / stationary − 1| < 3 %, max deviation < 10 %".into());
        all_ok &= ok;
    }
    // (2) damped, started 5 % off a stable regime: converges to it
    let c = &mut checks[3];
    let ok = c.rel_err_a.abs() < 0.02 && c.rel_err_b.abs() < 0.02 && c.rk4.window_dev < 0.02;
    c.pass = Some(ok);
    c.criterion =
        Some("last 20 000 τ: |mean A, B / stationary − 1| < 2 %, mean deviation < 2 %".into());
    all_ok &= ok;
    // (3) an unstable regime is left
    let c = &mut checks[4];
    let ok = c.rk4.max_dev > 0.2;
    c.pass = Some(ok);
    c.criterion = Some("max deviation > 20 %".into());
    all_ok &= ok;
    // (4) the printed sign of the xy term: the stable regime of (22) is not one of (19)
    let c = &mut checks[5];
    c.drifts_away = Some(c.rk4.max_dev > 0.1);
    c.note = Some(
        "informative: with the printed sign the regime of (22) is not kept (erratum, see docs)"
            .into(),
    );
    Ok((checks, all_ok))
}

/// The six runs of [`rk4_checks`], in the order of the JSON.
fn check_runs() -> Result<Vec<CheckRun>> {
    let mut runs = Vec::new();
    for (fig, p, lam) in [
        ("fig4", Params::fig4(), 0.5),
        ("fig4", Params::fig4(), 1.0),
        ("fig3", Params::fig3(), 1.0),
    ] {
        let st = stable_spatial(&p, lam).context("no stable spatial regime")?;
        runs.push(CheckRun {
            name: format!("{fig} stable, lambda={lam}"),
            p,
            lambda: lam,
            st,
            start: st.s,
            t_end: 30_000.0,
            avg_from: 0.0,
        });
    }
    let pd = Params {
        gamma: 0.05,
        ..Params::fig4()
    };
    let st = stable_spatial(&pd, 1.0).context("no damped stable regime")?;
    runs.push(CheckRun {
        name: "fig4 with gamma=0.05, stable, lambda=1.0, start 5 % off".into(),
        p: pd,
        lambda: 1.0,
        st,
        start: st.s.map(|x| 1.05 * x),
        t_end: 120_000.0,
        avg_from: 100_000.0,
    });
    let p = Params::fig4();
    let un = stationary_points(&p, 1.0)
        .into_iter()
        .filter(|s| !s.stable && s.b > 0.5)
        .max_by(|x, y| x.max_re.total_cmp(&y.max_re))
        .context("no unstable regime")?;
    runs.push(CheckRun {
        name: "fig4 unstable, lambda=1.0, start 1e-3 off".into(),
        p,
        lambda: 1.0,
        st: un,
        start: [un.s[0] * (1.0 + 1e-3), un.s[1], un.s[2], un.s[3]],
        t_end: 30_000.0,
        avg_from: 0.0,
    });
    let st = stable_spatial(&Params::fig4(), 1.0).context("no stable spatial regime")?;
    runs.push(CheckRun {
        name: "fig4 stable regime integrated with the printed +xy sign of eq. (19)".into(),
        p: Params {
            xy_sign: 1.0,
            ..Params::fig4()
        },
        lambda: 1.0,
        st,
        start: st.s,
        t_end: 30_000.0,
        avg_from: 0.0,
    });
    Ok(runs)
}
