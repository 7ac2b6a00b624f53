//! The paper's claims about the amplitude–frequency characteristics, checked: "a family of
//! parabolas", "the doubled detuning must exceed v1" and "v0 ≠ 0 adds a branch".

use serde::Serialize;

use super::model::Params;
use super::regimes::{Stationary, distinct_amplitudes, stationary_points};
use crate::numerics::BranchPoint;

/// Family of a free (m0 = 0, γ = v0 = 0) stationary regime: `(c, sign)` with
/// `c·j·A² = 8λ + sign·4v1`, `c ∈ {1, 3}`, if A = B and the point lies on that parabola to
/// `tol`; `None` otherwise.
pub fn parabola_family(p: &Params, st: &Stationary, tol: f64) -> Option<(u8, i8)> {
    if (st.a - st.b).abs() > tol * st.a.max(1.0) {
        return None;
    }
    for c in [1u8, 3] {
        for sign in [1i8, -1] {
            let r =
                f64::from(c) * p.j * st.a * st.a - 8.0 * st.lambda - f64::from(sign) * 4.0 * p.v1;
            if r.abs() < tol * (1.0 + 8.0 * st.lambda.abs()) {
                return Some((c, sign));
            }
        }
    }
    None
}

/// The claim "a family of parabolas".
#[derive(Clone, Debug, Serialize)]
pub struct ParabolaClaim {
    /// The claim.
    pub claim: String,
    /// Every free regime lies on one of the parabolas.
    pub holds: bool,
    /// The free regimes (m0 = 0) per (v1, λ).
    pub free_regimes_m0_0: Vec<FreeRegimes>,
    /// The forced figures' distance from the parabolas.
    pub forced_figures: Vec<ForcedDistance>,
    /// What was found, in words.
    pub statement: String,
}

/// Free regimes at one (v1, λ).
#[derive(Clone, Debug, Serialize)]
pub struct FreeRegimes {
    /// v1.
    pub v1: f64,
    /// λ.
    pub lambda: f64,
    /// Regimes found.
    pub regimes: usize,
    /// Of which on a parabola.
    pub on_parabolas: usize,
}

/// Largest λ distance of a forced figure's spatial points from the parabolas.
#[derive(Clone, Debug, Serialize)]
pub struct ForcedDistance {
    /// "fig3" or "fig4".
    pub figure: String,
    /// The distance.
    #[serde(rename = "max_lambda_distance_of_spatial_points_A_B_gt_0.5")]
    pub max_lambda_distance: f64,
}

/// Claim "a family of parabolas": free regimes (m0 = 0) lie exactly on
/// `c·j·A² = 8λ ± 4v1`, A = B (c = 1, 3); for the forced figures, the distance of the
/// spatial regimes from those parabolas.
pub fn parabola_claim(figs: &[(&str, Params, &[Vec<BranchPoint>])]) -> ParabolaClaim {
    let mut free = Vec::new();
    let mut all_on = true;
    // v1 = 0 without forcing is rotation-invariant (a circle of regimes, singular
    // Jacobian); it enters only through the forced figures
    let p = Params {
        m0: 0.0,
        v1: 0.1,
        ..Params::fig3()
    };
    for lam in [0.2, 0.5, 1.0, 1.5] {
        let pts = stationary_points(&p, lam);
        let fam: Vec<Option<(u8, i8)>> = pts.iter().map(|s| parabola_family(&p, s, 1e-8)).collect();
        all_on &= fam.iter().all(Option::is_some);
        free.push(FreeRegimes {
            v1: p.v1,
            lambda: lam,
            regimes: pts.len(),
            on_parabolas: fam.iter().filter(|f| f.is_some()).count(),
        });
    }
    let forced = figs
        .iter()
        .map(|(name, p, br)| ForcedDistance {
            figure: name.to_string(),
            max_lambda_distance: parabola_distance(p, br),
        })
        .collect();
    ParabolaClaim {
        claim: "the amplitude-frequency characteristics A(λ), B(λ) are a family of parabolas".into(),
        holds: all_on,
        free_regimes_m0_0: free,
        forced_figures: forced,
        statement: "for m0 = 0 every regime has A = B on one of λ = (c·j·A² ∓ 4·v1)/8, c = 1, 3 (to 1e-8); with v1 = 0 and forcing, A² = 8λ/(c·j) holds exactly on the spatial branches (sense equation) and B is close to it; the plane branch A = m0/(2|λ|), B = 0 is a hyperbola".into(),
    }
}

/// λ distance of the spatial points (A, B > 0.5) of `br` to the nearest parabola
/// λ = (c j A² ∓ 4 v1)/8.
fn parabola_distance(p: &Params, br: &[Vec<BranchPoint>]) -> f64 {
    let mut worst = 0.0f64;
    for pt in br.iter().flatten() {
        let a = pt.v[0].hypot(pt.v[1]);
        let bb = pt.v[2].hypot(pt.v[3]);
        if bb < 0.5 || a < 0.5 {
            continue;
        }
        let d = [1.0, 3.0]
            .iter()
            .flat_map(|&c| {
                [1.0, -1.0].map(|sg| (pt.p - (c * p.j * a * a - sg * 4.0 * p.v1) / 8.0).abs())
            })
            .fold(f64::INFINITY, f64::min);
        worst = worst.max(d);
    }
    worst
}

/// Claim "the doubled detuning must exceed v1": which free (m0 = 0) families exist vs λ.
pub fn existence_scan(v1: f64, lambdas: &[f64]) -> Vec<(f64, usize, usize, usize)> {
    let p = Params {
        m0: 0.0,
        v1,
        ..Params::fig3()
    };
    lambdas
        .iter()
        .map(|&lam| {
            let pts = stationary_points(&p, lam);
            let (mut minus, mut plus, mut other) = (0, 0, 0);
            for s in &pts {
                match parabola_family(&p, s, 1e-8) {
                    Some((_, -1)) => minus += 1,
                    Some((_, _)) => plus += 1,
                    None => other += 1,
                }
            }
            (lam, minus, plus, other)
        })
        .collect()
}

/// The claim "the doubled detuning 2λ must exceed v1".
#[derive(Clone, Debug, Serialize)]
pub struct ExistenceClaim {
    /// The claim.
    pub claim: String,
    /// v1.
    pub v1: f64,
    /// The families found per λ.
    pub free_regimes_m0_0: Vec<FamilyCount>,
    /// First λ with a regime of the −4v1 family.
    pub minus_family_first_lambda: Option<f64>,
    /// First λ with a regime of the +4v1 family.
    pub plus_family_first_lambda: Option<f64>,
    /// The −4v1 family exists exactly where 2λ > v1.
    pub minus_family_exists_iff_2lambda_gt_v1: bool,
    /// The +4v1 family exists exactly where 2λ > −v1.
    pub plus_family_exists_iff_2lambda_gt_minus_v1: bool,
    /// "partly" or "no".
    pub holds: String,
    /// What was found, in words.
    pub statement: String,
}

/// Regimes per family at one λ.
#[derive(Clone, Debug, Serialize)]
pub struct FamilyCount {
    /// λ.
    pub lambda: f64,
    /// On a −4v1 parabola.
    pub minus_family: usize,
    /// On a +4v1 parabola.
    pub plus_family: usize,
    /// On none.
    pub other: usize,
}

/// The claim "the doubled detuning must exceed v1", scanned over λ ∈ [−0.149, 0.151].
pub fn existence_claim() -> ExistenceClaim {
    let v1 = 0.1;
    let lams: Vec<f64> = (0..=30).map(|i| -0.149 + 0.01 * i as f64).collect();
    let scan = existence_scan(v1, &lams);
    let minus_ok = scan.iter().all(|r| (r.1 > 0) == (2.0 * r.0 > v1));
    let plus_ok = scan.iter().all(|r| (r.2 > 0) == (2.0 * r.0 > -v1));
    ExistenceClaim {
        claim: "the doubled detuning 2λ must exceed v1".into(),
        v1,
        free_regimes_m0_0: scan
            .iter()
            .map(|r| FamilyCount {
                lambda: r.0,
                minus_family: r.1,
                plus_family: r.2,
                other: r.3,
            })
            .collect(),
        minus_family_first_lambda: scan.iter().find(|r| r.1 > 0).map(|r| r.0),
        plus_family_first_lambda: scan.iter().find(|r| r.2 > 0).map(|r| r.0),
        minus_family_exists_iff_2lambda_gt_v1: minus_ok,
        plus_family_exists_iff_2lambda_gt_minus_v1: plus_ok,
        holds: if minus_ok && plus_ok { "partly" } else { "no" }.into(),
        statement: "for m0 = 0 the families c·j·A² = 8λ − 4v1 (c = 1, 3) exist only for 2λ > v1, as the paper says; the families c·j·A² = 8λ + 4v1 exist already for 2λ > −v1 (the rest state is parametrically unstable for |2λ| < v1); with forcing (the figures) a forced regime exists at every λ".into(),
    }
}

/// The claim "v0 ≠ 0 adds a branch".
#[derive(Clone, Debug, Serialize)]
pub struct V0Claim {
    /// The claim.
    pub claim: String,
    /// The v0 compared with 0.
    pub v0: f64,
    /// Some λ has more distinct (A, B) with v0.
    pub holds: bool,
    /// Distinct (A, B) per figure and λ.
    pub counts: Vec<V0Count>,
    /// What was found, in words.
    pub statement: String,
}

/// Distinct (A, B) without and with v0 at one λ.
#[derive(Clone, Debug, Serialize)]
pub struct V0Count {
    /// "fig3" or "fig4".
    pub figure: String,
    /// λ.
    pub lambda: f64,
    /// With v0 = 0.
    #[serde(rename = "distinct_AB_v0_0")]
    pub distinct_ab_v0_0: usize,
    /// With v0 = 0.1.
    #[serde(rename = "distinct_AB_v0_0.1")]
    pub distinct_ab_v0_01: usize,
}

/// The claim "v0 ≠ 0 adds a branch" at five detunings of both figures.
pub fn v0_claim() -> V0Claim {
    let lams = [0.02, 0.1, 0.3, 0.5, 1.0];
    let mut counts = Vec::new();
    let mut adds = false;
    for (name, base) in [("fig3", Params::fig3()), ("fig4", Params::fig4())] {
        for &lam in &lams {
            let n0 = distinct_amplitudes(&stationary_points(&base, lam)).len();
            let p1 = Params { v0: 0.1, ..base };
            let n1 = distinct_amplitudes(&stationary_points(&p1, lam)).len();
            adds |= n1 > n0;
            counts.push(V0Count {
                figure: name.into(),
                lambda: lam,
                distinct_ab_v0_0: n0,
                distinct_ab_v0_01: n1,
            });
        }
    }
    V0Claim {
        claim: "v0 ≠ 0 adds a branch to the amplitude-frequency characteristic".into(),
        v0: 0.1,
        holds: adds,
        counts,
        statement: "with v0 = 0 the regimes come in symmetric pairs with equal (A, B) (e.g. (q2, p2) → −(q2, p2) for v1 = 0); v0 couples x and y linearly, breaks that symmetry and splits such pairs into distinct (A, B) branches".into(),
    }
}
