//! The report: the full-rate check of the operating points, the sweeps of both ωy², the
//! typed `averaged.json` and the figure.

use std::collections::BTreeMap;
use std::fs;
use std::path::Path;

use anyhow::{Context, Result};
use paragyro_core::Cplx;
use paragyro_core::physics::OMEGA0_TABLE2_RAD_S;
use paragyro_simulator::plant::{GyroSim, PlantInputs, SimConfig};
use serde::{Serialize, Serializer};

use super::model::{AveragedModel, SEED_A, StateRecord, SteadyState, SweepPoint, pump_khz};
use super::plots::plot_sweep;
use super::sweeps::hysteresis_intervals;
use crate::complex::CplxExt;
use crate::numerics::{BranchPoint, folds};
use paragyro_simulator::par::{par_map, try_par_map};

/// Lock-in fundamentals `(A1, B1)` of the full-rate plant ([`GyroSim`], 128 steps per
/// period, no noise) after `seconds` at constant ω from `X(0) = 0.01`.
pub fn full_sim_envelopes(
    model: &AveragedModel,
    omega: f64,
    seconds: f64,
) -> Result<(Cplx<f64>, Cplx<f64>)> {
    let cfg = SimConfig {
        noise_density: 0.0,
        omega_max: omega.max(1.05),
        ..SimConfig::default()
    };
    let mut sim = GyroSim::new(&cfg, [0.01, 0.0, 0.0, 0.0]).map_err(anyhow::Error::msg)?;
    let u = PlantInputs {
        omega,
        s: model.s,
        ax: model.ax,
        ay: model.ay,
    };
    let n = (seconds * cfg.fs_hz).round() as usize;
    for _ in 0..n {
        sim.advance(&model.theta, &u, &u);
    }
    let o = sim.lockin();
    Ok((o.x_um[0], o.y_um[0]))
}

/// The stable steady state closest to the envelopes `(a, b)` (up to the ± symmetry).
pub fn nearest_stable(states: &[SteadyState], a: Cplx<f64>, b: Cplx<f64>) -> Option<SteadyState> {
    let d = |s: &SteadyState| {
        let p = (s.a - a).modulus() + (s.b - b).modulus();
        let m = (s.a + a).modulus() + (s.b + b).modulus();
        p.min(m)
    };
    states
        .iter()
        .filter(|s| s.stable)
        .min_by(|x, y| d(x).total_cmp(&d(y)))
        .copied()
}

/// Sweep grid: ω from 1.004 to 1.050 (pump 21.69–22.68 kHz) in steps of 2e-4.
pub const SWEEP_LO: f64 = 1.004;
/// Upper end of the sweep grid.
pub const SWEEP_HI: f64 = 1.050;
/// Step of the sweep grid.
pub const SWEEP_STEP: f64 = 2e-4;

/// The paper's two operating points: ω = √1.0265 and √1.03.
const OPS: [(&str, f64); 2] = [("sqrt(1.0265)", 1.0265), ("sqrt(1.03)", 1.03)];
/// The two sense stiffnesses ωy² compared.
const WY2: [f64; 2] = [1.0265, 1.03];

/// Everything the report computes for one ωy².
pub(super) struct Case {
    pub(super) wy2: f64,
    pub(super) branches: Vec<Vec<BranchPoint>>,
    pub(super) up: Vec<SweepPoint>,
    pub(super) down: Vec<SweepPoint>,
    /// Stable steady states at the two operating points.
    pub(super) ops: Vec<SteadyState>,
}

/// `averaged.json`: what [`write_averaged_report`] computes.
#[derive(Clone, Debug, Serialize)]
pub struct AveragedReport {
    /// What the model is.
    pub model: String,
    /// The parameters, in words.
    pub parameters: Parameters,
    /// The rest state's instability band three ways.
    pub band: Band,
    /// Steady states at the operating points (ωy² outer, ω inner) with the full-rate check.
    pub operating_points: Vec<OperatingPoint>,
    /// The paper's "20 %" claim.
    pub paper_20pct_claim: Claim20,
    /// One sweep report per ωy², written as a map keyed `"wy2=<ωy²>"`.
    #[serde(serialize_with = "sweeps_by_wy2")]
    pub sweeps: Vec<SweepReport>,
    /// Files written.
    pub files: Vec<String>,
}

/// The model's parameters, in words.
#[derive(Clone, Debug, Serialize)]
pub struct Parameters {
    /// θ, s and the accelerations.
    pub theta: String,
    /// ω0, rad/s.
    pub omega0_rad_s: f64,
    /// How the pump frequency follows from ω.
    pub pump_frequency: String,
}

/// The rest state's instability band.
#[derive(Clone, Debug, Serialize)]
pub struct Band {
    /// Closed-form averaged formula (drive only), ω.
    pub hb_formula_omega: [f64; 2],
    /// The same, pump kHz.
    pub hb_formula_pump_khz: [f64; 2],
    /// Averaged flow with the sense coupling, ω.
    pub averaged_coupled_omega: [f64; 2],
    /// The same, pump kHz.
    pub averaged_coupled_pump_khz: [f64; 2],
    /// Floquet exponents of the full linear system, ω.
    pub floquet_omega: Option<[f64; 2]>,
    /// The same, pump kHz.
    pub floquet_pump_khz: Option<[f64; 2]>,
    /// FINDINGS §1, averaged formula.
    pub findings_hb: [f64; 2],
    /// FINDINGS §1, Floquet.
    pub findings_floquet: [f64; 2],
}

/// One operating point (ωy², ω).
#[derive(Clone, Debug, Serialize)]
pub struct OperatingPoint {
    /// ωy².
    pub wy2: f64,
    /// "sqrt(1.0265)" or "sqrt(1.03)".
    pub omega_label: String,
    /// ω.
    pub omega: f64,
    /// Pump frequency, kHz.
    pub pump_khz: f64,
    /// The rest state, classified.
    pub rest_state: StateRecord,
    /// The nontrivial steady states.
    pub steady_states: Vec<StateRecord>,
    /// The full-rate plant after 0.5 s and the steady state it settled on.
    pub full_sim_0p5s: FullSimCheck,
}

/// The full-rate plant's lock-in fundamentals against the nearest stable steady state.
#[derive(Clone, Debug, Serialize)]
pub struct FullSimCheck {
    /// |A1|.
    #[serde(rename = "abs_A1")]
    pub abs_a1: f64,
    /// |B1|.
    #[serde(rename = "abs_B1")]
    pub abs_b1: f64,
    /// A1 as [Re, Im].
    #[serde(rename = "A1")]
    pub a1: [f64; 2],
    /// B1 as [Re, Im].
    #[serde(rename = "B1")]
    pub b1: [f64; 2],
    /// |A| of the nearest stable steady state.
    #[serde(rename = "matched_state_abs_A")]
    pub matched_state_abs_a: Option<f64>,
    /// |B| of the nearest stable steady state.
    #[serde(rename = "matched_state_abs_B")]
    pub matched_state_abs_b: Option<f64>,
    /// |A| / |A1| − 1.
    #[serde(rename = "rel_err_abs_A")]
    pub rel_err_abs_a: Option<f64>,
    /// |B| / |B1| − 1.
    #[serde(rename = "rel_err_abs_B")]
    pub rel_err_abs_b: Option<f64>,
}

/// The paper's "sense amplitude drops to 20 %" claim.
#[derive(Clone, Debug, Serialize)]
pub struct Claim20 {
    /// The claim.
    pub paper: String,
    /// |B| ratio of the averaged model's steady states.
    pub hb_ratio: f64,
    /// |B1| ratio of the full-rate plant.
    pub full_sim_ratio: f64,
    /// `|hb_ratio − 0.2| < 0.05`.
    pub reproduced: bool,
}

/// The sweeps, branches and folds for one ωy².
#[derive(Clone, Debug, Serialize)]
pub struct SweepReport {
    /// ωy² (the key of the map in the JSON).
    #[serde(skip)]
    pub wy2: f64,
    /// The ω grid.
    pub grid: Grid,
    /// Up-sweep from rest.
    pub up_from_rest: SweepSeries,
    /// Down-sweep from rest.
    pub down_from_rest: SweepSeries,
    /// Where the sweeps end in different states, ω.
    pub hysteresis_intervals_omega: Vec<[f64; 2]>,
    /// The same, pump kHz.
    pub hysteresis_intervals_pump_khz: Vec<[f64; 2]>,
    /// Number of branches traced.
    pub branches: usize,
    /// Points on them.
    pub branch_points: usize,
    /// Folds with |A| > 0.05.
    pub folds: Vec<Fold>,
    /// The stable sweep point with the largest |B|.
    #[serde(rename = "largest_stable_abs_B_on_sweeps")]
    pub largest_stable_abs_b_on_sweeps: Option<SweepMax>,
}

/// A sweep grid.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Grid {
    /// First ω.
    pub lo: f64,
    /// Last ω.
    pub hi: f64,
    /// Step.
    pub step: f64,
}

/// One sweep as columns.
#[derive(Clone, Debug, Serialize)]
pub struct SweepSeries {
    /// ω.
    pub omega: Vec<f64>,
    /// |A|.
    #[serde(rename = "abs_A")]
    pub abs_a: Vec<f64>,
    /// |B|.
    #[serde(rename = "abs_B")]
    pub abs_b: Vec<f64>,
    /// Stability of the state.
    pub stable: Vec<bool>,
    /// ω where the sweep jumped.
    pub jumps: Vec<f64>,
}

/// A fold of a branch.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Fold {
    /// ω.
    pub omega: f64,
    /// Pump frequency, kHz.
    pub pump_khz: f64,
    /// |A|.
    #[serde(rename = "abs_A")]
    pub abs_a: f64,
    /// |B|.
    #[serde(rename = "abs_B")]
    pub abs_b: f64,
}

/// A point of a sweep.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct SweepMax {
    /// ω.
    pub omega: f64,
    /// |A|.
    #[serde(rename = "abs_A")]
    pub abs_a: f64,
    /// |B|.
    #[serde(rename = "abs_B")]
    pub abs_b: f64,
}

fn sweeps_by_wy2<S: Serializer>(sweeps: &[SweepReport], s: S) -> Result<S::Ok, S::Error> {
    let map: BTreeMap<String, &SweepReport> = sweeps
        .iter()
        .map(|r| (format!("wy2={}", r.wy2), r))
        .collect();
    map.serialize(s)
}

impl SweepSeries {
    fn new(s: &[SweepPoint]) -> Self {
        Self {
            omega: s.iter().map(|p| p.omega).collect(),
            abs_a: s.iter().map(|p| p.abs_a).collect(),
            abs_b: s.iter().map(|p| p.abs_b).collect(),
            stable: s.iter().map(|p| p.stable).collect(),
            jumps: s.iter().filter(|p| p.jump).map(|p| p.omega).collect(),
        }
    }
}

/// The steady states at one operating point and the full-rate plant's 0.5 s there.
fn operating_point(base: &AveragedModel, wy2: f64, label: &str, w2: f64) -> Result<OperatingPoint> {
    let m = base.with_wy2(wy2);
    let om = w2.sqrt();
    let states = m.steady_states(om);
    let (fa, fb) = full_sim_envelopes(&m, om, 0.5)?;
    let near = nearest_stable(&states, fa, fb);
    Ok(OperatingPoint {
        wy2,
        omega_label: label.to_string(),
        omega: om,
        pump_khz: pump_khz(om),
        rest_state: m.trivial(om).record(),
        steady_states: states.iter().map(SteadyState::record).collect(),
        full_sim_0p5s: FullSimCheck {
            abs_a1: fa.modulus(),
            abs_b1: fb.modulus(),
            a1: [fa.re, fa.im],
            b1: [fb.re, fb.im],
            matched_state_abs_a: near.map(|s| s.a.modulus()),
            matched_state_abs_b: near.map(|s| s.b.modulus()),
            rel_err_abs_a: near.map(|s| s.a.modulus() / fa.modulus() - 1.0),
            rel_err_abs_b: near.map(|s| s.b.modulus() / fb.modulus() - 1.0),
        },
    })
}

/// The branches, both sweeps from rest and the stable operating states for one ωy²; the
/// four parts run in parallel.
fn case(base: &AveragedModel, wy2: f64) -> Result<Case> {
    enum Part {
        Branches(Vec<Vec<BranchPoint>>),
        Sweep(Vec<SweepPoint>),
        Ops(Vec<SteadyState>),
    }
    let m = base.with_wy2(wy2);
    let n = ((SWEEP_HI - SWEEP_LO) / SWEEP_STEP).round() as usize;
    let grid: Vec<f64> = (0..=n).map(|i| SWEEP_LO + i as f64 * SWEEP_STEP).collect();
    let rev: Vec<f64> = grid.iter().rev().copied().collect();
    let seed = [SEED_A, 0.0, 0.0, 0.0];
    let parts = par_map(vec![0, 1, 2, 3], |k| match k {
        0 => Part::Branches(m.branches(SWEEP_LO, SWEEP_HI, 0.002)),
        1 => Part::Sweep(m.sweep(&grid, seed)),
        2 => Part::Sweep(m.sweep(&rev, seed)),
        _ => Part::Ops(
            OPS.iter()
                .flat_map(|&(_, w2)| m.steady_states(w2.sqrt()))
                .filter(|s| s.stable)
                .collect(),
        ),
    })?;
    let mut it = parts.into_iter();
    match (it.next(), it.next(), it.next(), it.next()) {
        (
            Some(Part::Branches(branches)),
            Some(Part::Sweep(up)),
            Some(Part::Sweep(down)),
            Some(Part::Ops(ops)),
        ) => Ok(Case {
            wy2,
            branches,
            up,
            down,
            ops,
        }),
        _ => anyhow::bail!("the parts of the ωy² = {wy2} case came back out of order"),
    }
}

impl SweepReport {
    fn new(c: &Case) -> Self {
        let hyst = hysteresis_intervals(&c.up, &c.down, 0.05);
        let folds = c
            .branches
            .iter()
            .flat_map(|b| folds(b))
            .filter(|p| p.v[0].hypot(p.v[1]) > 0.05)
            .map(|p| Fold {
                omega: p.p,
                pump_khz: pump_khz(p.p),
                abs_a: p.v[0].hypot(p.v[1]),
                abs_b: p.v[2].hypot(p.v[3]),
            })
            .collect();
        let best =
            c.up.iter()
                .chain(&c.down)
                .filter(|p| p.stable)
                .max_by(|x, y| x.abs_b.total_cmp(&y.abs_b));
        Self {
            wy2: c.wy2,
            grid: Grid {
                lo: SWEEP_LO,
                hi: SWEEP_HI,
                step: SWEEP_STEP,
            },
            up_from_rest: SweepSeries::new(&c.up),
            down_from_rest: SweepSeries::new(&c.down),
            hysteresis_intervals_omega: hyst.iter().map(|&(a, b)| [a, b]).collect(),
            hysteresis_intervals_pump_khz: hyst
                .iter()
                .map(|&(a, b)| [pump_khz(a), pump_khz(b)])
                .collect(),
            branches: c.branches.len(),
            branch_points: c.branches.iter().map(Vec::len).sum(),
            folds,
            largest_stable_abs_b_on_sweeps: best.map(|p| SweepMax {
                omega: p.omega,
                abs_a: p.abs_a,
                abs_b: p.abs_b,
            }),
        }
    }
}

/// Computes the averaged-model results for seed 000's Table 2 gyro, writes
/// `averaged_sweep.png` (|B| and |A| vs pump frequency, both ωy²) and `averaged.json` to
/// `dir`, and returns the report: steady states at the paper's operating points
/// ω = √1.0265 and √1.03 with stability and the full-rate check, the rest-state band
/// (averaged formula and Floquet), the sweeps, jumps, hysteresis intervals and folds, and
/// the paper's "20 %" claim. The operating points and the sweeps of both ωy² run in
/// parallel; a panic in one of them is returned as an error.
pub fn write_averaged_report(dir: &Path) -> Result<AveragedReport> {
    fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let base = AveragedModel::table2();
    let band = base
        .trivial_band()
        .context("pump below the parametric threshold")?;
    let floquet = base.floquet_band(1.005, 1.040, 2.5e-4);
    let rest = base
        .rest_band(1.005, 1.040, 2.5e-4)
        .context("rest state of the averaged flow never unstable")?;

    let op_jobs: Vec<(f64, &str, f64)> = WY2
        .iter()
        .flat_map(|&wy2| OPS.iter().map(move |&(name, w2)| (wy2, name, w2)))
        .collect();
    let operating_points = try_par_map(op_jobs, |(wy2, name, w2)| {
        operating_point(&base, wy2, name, w2)
    })?;
    // |B| at ω = √1.0265 for both ωy² (averaged model and full-rate plant)
    let at_paper: Vec<(f64, f64)> = operating_points
        .iter()
        .filter(|o| o.omega_label == OPS[0].0)
        .map(|o| {
            let f = &o.full_sim_0p5s;
            (f.matched_state_abs_b.unwrap_or(f64::NAN), f.abs_b1)
        })
        .collect();
    let [(b_avg0, b_full0), (b_avg1, b_full1)] = at_paper[..] else {
        anyhow::bail!("expected the operating point √1.0265 for both ωy²");
    };
    let cases = try_par_map(WY2.to_vec(), |wy2| case(&base, wy2))?;

    let hb_ratio = b_avg1 / b_avg0;
    let out = AveragedReport {
        model: "averaged slow flow of seed 000 eq. (6), DERIVATION.md §6 (first-order Krylov–Bogolyubov / harmonic balance, DC + fundamental)".into(),
        parameters: Parameters {
            theta: "Table 2 (plant::Theta::table2), s = 1, ax = ay = 0.0213 (10 g)".into(),
            omega0_rad_s: OMEGA0_TABLE2_RAD_S,
            pump_frequency: "2·ω·ω0/(2π)".into(),
        },
        band: Band {
            hb_formula_omega: [band.0, band.1],
            hb_formula_pump_khz: [pump_khz(band.0), pump_khz(band.1)],
            averaged_coupled_omega: [rest.0, rest.1],
            averaged_coupled_pump_khz: [pump_khz(rest.0), pump_khz(rest.1)],
            floquet_omega: floquet.map(|f| [f.0, f.1]),
            floquet_pump_khz: floquet.map(|f| [pump_khz(f.0), pump_khz(f.1)]),
            findings_hb: [1.01125, 1.03333],
            findings_floquet: [1.0109, 1.0334],
        },
        operating_points,
        paper_20pct_claim: Claim20 {
            paper: "sense amplitude at omega = sqrt(1.0265) drops to 20 % when wy2 goes 1.0265 -> 1.03".into(),
            hb_ratio,
            full_sim_ratio: b_full1 / b_full0,
            reproduced: (hb_ratio - 0.2).abs() < 0.05,
        },
        sweeps: cases.iter().map(SweepReport::new).collect(),
        files: vec!["averaged_sweep.png".into(), "averaged.json".into()],
    };
    plot_sweep(&dir.join("averaged_sweep.png"), &cases, rest, floquet)?;
    crate::write_json(&dir.join("averaged.json"), &out, false)?;
    Ok(out)
}
