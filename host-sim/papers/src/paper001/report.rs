//! The report: Figs 3–4, the RK4 confirmations and the claims as a typed `paper001.json`.

use std::fs;
use std::path::Path;

use anyhow::{Context, Result};
use serde::Serialize;

use super::claims::{
    ExistenceClaim, ParabolaClaim, V0Claim, existence_claim, parabola_claim, v0_claim,
};
use super::model::Params;
use super::plots::plot_fig;
use super::regimes::{
    AMP_MAX, LAMBDA_HI, LAMBDA_LO, StationaryRecord, branches, stationary_points,
};
use super::rk4::{Rk4Check, rk4_checks};
use crate::numerics::BranchPoint;
use paragyro_simulator::par::par_map;

/// `paper001.json`: what [`write_paper001_report`] computes.
#[derive(Clone, Debug, Serialize)]
pub struct Paper001Report {
    /// The paper and what is reproduced.
    pub paper: String,
    /// The parameters, stated and chosen.
    pub parameters: ReportParameters,
    /// The paper's errata found on the way.
    pub errata: Vec<String>,
    /// Fig. 3 (v1 = 0).
    pub fig3: FigureReport,
    /// Fig. 4 (v1 = 0.1).
    pub fig4: FigureReport,
    /// The direct integrations of eq. (19).
    pub rk4_checks: Vec<Rk4Check>,
    /// Every judged RK4 check passed.
    pub rk4_checks_pass: bool,
    /// The paper's claims.
    pub claims: Paper001Claims,
    /// Files written.
    pub files: Vec<String>,
}

/// The parameters of the figures, what the paper states and what is chosen here.
#[derive(Clone, Debug, Serialize)]
pub struct ReportParameters {
    /// Fig. 3.
    pub fig3: Params,
    /// Fig. 4.
    pub fig4: Params,
    /// What the paper states.
    pub stated_by_paper: String,
    /// What is chosen here.
    pub chosen_here: String,
    /// The λ window of the figures.
    pub lambda_window: [f64; 2],
    /// Branches are followed up to this amplitude.
    pub amplitude_cap: f64,
    /// What "stable" means.
    pub stability: String,
}

/// One figure: its branches (sampled) and the regimes at four detunings.
#[derive(Clone, Debug, Serialize)]
pub struct FigureReport {
    /// The branches.
    pub branches: Vec<BranchSummary>,
    /// The regimes at λ = −0.3, 0.1, 0.5, 1.
    pub regimes_at: Vec<RegimesAt>,
}

/// One branch: its size and every 5th point (and the last) as (λ, A, B, stable).
#[derive(Clone, Debug, Serialize)]
pub struct BranchSummary {
    /// Points.
    pub points: usize,
    /// Stable points.
    pub stable_points: usize,
    /// (λ, A, B, stable) of every 5th point and the last.
    #[serde(rename = "samples_lambda_A_B_stable")]
    pub samples: Vec<(f64, f64, f64, bool)>,
}

/// The stationary regimes at one λ.
#[derive(Clone, Debug, Serialize)]
pub struct RegimesAt {
    /// λ.
    pub lambda: f64,
    /// The regimes.
    pub regimes: Vec<StationaryRecord>,
}

/// The three claims of the paper.
#[derive(Clone, Debug, Serialize)]
pub struct Paper001Claims {
    /// "A family of parabolas".
    pub family_of_parabolas: ParabolaClaim,
    /// "The doubled detuning must exceed v1".
    pub doubled_detuning_exceeds_v1: ExistenceClaim,
    /// "v0 ≠ 0 adds a branch".
    pub v0_adds_a_branch: V0Claim,
}

impl FigureReport {
    fn new(p: &Params, br: &[Vec<BranchPoint>]) -> Self {
        let branches = br
            .iter()
            .map(|b| BranchSummary {
                points: b.len(),
                stable_points: b.iter().filter(|p| p.stable).count(),
                samples: b
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| k % 5 == 0 || *k + 1 == b.len())
                    .map(|(_, pt)| {
                        (
                            pt.p,
                            pt.v[0].hypot(pt.v[1]),
                            pt.v[2].hypot(pt.v[3]),
                            pt.stable,
                        )
                    })
                    .collect(),
            })
            .collect();
        let regimes_at = [-0.3, 0.1, 0.5, 1.0]
            .iter()
            .map(|&l| RegimesAt {
                lambda: l,
                regimes: stationary_points(p, l).iter().map(|s| s.record()).collect(),
            })
            .collect();
        Self {
            branches,
            regimes_at,
        }
    }
}

/// The claims, the three in parallel (the parabola claim needs both figures' branches).
fn claims(b3: &[Vec<BranchPoint>], b4: &[Vec<BranchPoint>]) -> Result<Paper001Claims> {
    enum Claim {
        Parabolas(ParabolaClaim),
        Existence(ExistenceClaim),
        V0(V0Claim),
    }
    let (p3, p4) = (Params::fig3(), Params::fig4());
    let mut out = par_map(vec![0, 1, 2], |k| match k {
        0 => Claim::Parabolas(parabola_claim(&[("fig3", p3, b3), ("fig4", p4, b4)])),
        1 => Claim::Existence(existence_claim()),
        _ => Claim::V0(v0_claim()),
    })?
    .into_iter();
    match (out.next(), out.next(), out.next()) {
        (Some(Claim::Parabolas(a)), Some(Claim::Existence(b)), Some(Claim::V0(c))) => {
            Ok(Paper001Claims {
                family_of_parabolas: a,
                doubled_detuning_exceeds_v1: b,
                v0_adds_a_branch: c,
            })
        }
        _ => anyhow::bail!("the claims came back out of order"),
    }
}

/// Computes seed 001's Figs 3–4 (branches with stability), the RK4 confirmations and the
/// claims; writes `paper001_fig3.png`, `paper001_fig4.png` and `paper001.json` to `dir`;
/// returns the report. The two figures, the RK4 runs and the claims run in parallel; a
/// panic in one of them is returned as an error.
pub fn write_paper001_report(dir: &Path) -> Result<Paper001Report> {
    fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let p3 = Params::fig3();
    let p4 = Params::fig4();
    let mut figs = par_map(vec![p3, p4], |p| branches(&p, LAMBDA_LO, LAMBDA_HI))?;
    let b4 = figs.pop().context("Fig. 4 branches")?;
    let b3 = figs.pop().context("Fig. 3 branches")?;
    plot_fig(
        &dir.join("paper001_fig3.png"),
        "Seed 001 Fig. 3: amplitude–frequency characteristics, v1 = 0",
        &p3,
        &b3,
    )?;
    plot_fig(
        &dir.join("paper001_fig4.png"),
        "Seed 001 Fig. 4: amplitude–frequency characteristics, v1 = 0.1",
        &p4,
        &b4,
    )?;
    let (rk4, rk4_ok) = rk4_checks()?;
    let out = Paper001Report {
        paper: "seed 001 (Giap): eq. (19), slow flow eq. (22), stationary regimes eq. (23), Figs 3-4".into(),
        parameters: ReportParameters {
            fig3: p3,
            fig4: p4,
            stated_by_paper: "v1 = 0 (Fig. 3), v1 = 0.1 (Fig. 4); γ = 0 and v0 = 0 for the stationary regimes (eq. 23)".into(),
            chosen_here: "j = 1, m0 = 0.05 (eq. 22 units; eq. 23 prints m0 where 4·m0 is consistent), ξ = 3/2 (makes eq. 22 the average of eq. 19), ε = 0.005 (direct integration only), σ = −1 for the xy term of eq. 19 (erratum, from eq. 9)".into(),
            lambda_window: [LAMBDA_LO, LAMBDA_HI],
            amplitude_cap: AMP_MAX,
            stability: "eigenvalues of the Jacobian of (22); γ = 0: stable = all on the imaginary axis (|Re| ≤ 1e-6·|λ|max)".into(),
        },
        errata: vec![
            "eq. (19)/(14)/(15): j·y(x·y + 2x'y') should be j·y(−x·y + 2x'y') (eq. 9 with α'' ≈ −α; only this sign averages to eq. 22)".into(),
            "eq. (22) vs (19): the v1 coefficient −4 corresponds to ξ = 3/2 (general: 2 − 4ξ)".into(),
            "eq. (22) vs (19): −4m0 corresponds to the phase origin shifted by half a forcing period (x = −(q1 cos μτ + p1 sin μτ)); literal averaging gives +4m0".into(),
            "eq. (23) prints −m0 where eq. (22) gives −4m0".into(),
        ],
        fig3: FigureReport::new(&p3, &b3),
        fig4: FigureReport::new(&p4, &b4),
        rk4_checks: rk4,
        rk4_checks_pass: rk4_ok,
        claims: claims(&b3, &b4)?,
        files: ["paper001_fig3.png", "paper001_fig4.png", "paper001.json"]
            .map(String::from)
            .to_vec(),
    };
    crate::write_json(&dir.join("paper001.json"), &out, false)?;
    Ok(out)
}
