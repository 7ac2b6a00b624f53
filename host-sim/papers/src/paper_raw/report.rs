//! The report: every scenario of the module run in parallel, the figures, the Markdown
//! tables and the typed `paper_raw_summary.json`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use paragyro_core::physics::{OMEGA0_TABLE2_RAD_S, TABLE2};
use paragyro_simulator::summary::RunSummary;
use serde::Serialize;

use super::compare::{CompareRow, Comparison, LAMBDAS, compare};
use super::config::{LambdaReading, PAPER_P0, RawConfig, Segment};
use super::identifiability::{Identifiability, window_identifiability};
use super::plots::{Quantity, physical_quantity, plot_est_truth, plot_literal, theta_quantity};
use super::simulate::{RawRecord, RawRun, simulate};
use super::switch::{Pump, SwitchOptions, SwitchResult, paper_sets, paper_switch};
use super::tables::tables_md;
use paragyro_simulator::par::try_par_map;

/// The finer step of the extra ±50 % runs (4× the plant's): enough for the explicit RK4 to
/// survive the switches with λ = 0.2/τ.
pub const FINE_STEPS_PER_PERIOD: usize = 512;

/// Simulated seconds of each raw run in the comparison.
pub const COMPARE_RAW_S: f64 = 3.0;

/// `paper_raw_summary.json`: what [`write_paper_raw_summary`] computes.
#[derive(Clone, Debug, Serialize)]
pub struct PaperRawSummary {
    /// ω0, rad/s.
    pub omega0_rad_s: f64,
    /// The plant's RK4 steps per carrier period.
    pub steps_per_period: usize,
    /// The paper's P(0) = p0·I.
    pub p0: f64,
    /// The readings of λ compared.
    pub lambda_readings: Vec<LambdaInfo>,
    /// ±50 % test, pump left at √1.0265, 0.5 s per set (the plant's step, then the fine one).
    pub literal: Vec<SwitchRecord>,
    /// ±50 % test, pump re-centred, 0.5 s per set.
    pub variant: Vec<SwitchRecord>,
    /// ±50 % test, pump left at √1.0265, 50 ms per set.
    pub literal_ms_scale: Vec<SwitchRecord>,
    /// ±50 % test, pump re-centred, 50 ms per set.
    pub variant_ms_scale: Vec<SwitchRecord>,
    /// The side-by-side comparison with the product.
    pub comparison: Vec<CompareRow>,
    /// The product runs' own summaries.
    pub product_summaries: Vec<RunSummary>,
    /// Identifiability of the regressors, steady state and start-up.
    pub identifiability: IdentifiabilityReport,
    /// The paper's P0 on an already running gyro.
    pub estimator_started_on_running_gyro: LateStart,
    /// Files written.
    pub files: Vec<String>,
    /// Wall time of the whole report, s.
    pub wall_s: f64,
    /// The Markdown tables (what `paragyro-sim run paper-raw` prints).
    pub table_md: String,
}

/// One reading of λ with its time scales.
#[derive(Clone, Debug, Serialize)]
pub struct LambdaInfo {
    /// Machine-friendly key.
    pub key: String,
    /// Label.
    pub label: String,
    /// λ per τ.
    pub per_tau: f64,
    /// λ per second.
    pub per_s: f64,
    /// Memory 1/λ, s.
    pub memory_s: f64,
    /// Memory 1/λ, τ.
    pub memory_tau: f64,
    /// The equivalent discrete forgetting factor per 500 Hz sample.
    pub discrete_per_500hz_sample: f64,
}

/// A ±50 % run with the numbers of its integration (the records are not written).
#[derive(Clone, Debug, Serialize)]
pub struct SwitchRecord {
    /// The run's result.
    #[serde(flatten)]
    pub result: SwitchResult,
    /// Numbers of its integration.
    pub run: RunNumbers,
    /// The λ reading's label.
    pub lambda_label: String,
}

/// Numbers of a run without its records.
#[derive(Clone, Debug, Serialize)]
pub struct RunNumbers {
    /// Step, τ.
    pub h_tau: f64,
    /// Steps per simulated second.
    pub steps_per_s: f64,
    /// Steps.
    pub steps: u64,
    /// Simulated time, s.
    pub sim_s: f64,
    /// Wall time, s.
    pub wall_s: f64,
    /// Wall time per simulated second.
    pub wall_per_sim_s: f64,
    /// λ per τ.
    pub lambda_per_tau: f64,
    /// Estimator blow-up time, s.
    pub estimator_blowup_s: Option<f64>,
    /// h·ΦᵀPΦ at the blow-up.
    pub blowup_h_phi_p_phi: Option<[f64; 2]>,
    /// First time past RK4's stability limit, s.
    pub rk4_limit_exceeded_s: Option<f64>,
    /// Largest trace P (drive, sense) over the records.
    pub max_trace_p: [f64; 2],
    /// Largest h·ΦᵀPΦ (drive, sense) over the records.
    pub max_h_phi_p_phi: [f64; 2],
}

impl RunNumbers {
    /// The numbers of `run`.
    pub fn of(run: &RawRun) -> Self {
        let sim_s = run.records.last().map_or(0.0, |r| r.t_s);
        let max2 = |f: &dyn Fn(&RawRecord) -> [f64; 2]| {
            run.records.iter().fold([0.0f64; 2], |m, r| {
                let v = f(r);
                [m[0].max(v[0]), m[1].max(v[1])]
            })
        };
        Self {
            h_tau: run.h_tau,
            steps_per_s: run.steps_per_s,
            steps: run.steps,
            sim_s,
            wall_s: run.wall_s,
            wall_per_sim_s: run.wall_s / sim_s.max(1e-12),
            lambda_per_tau: run.lambda_per_tau,
            estimator_blowup_s: run.estimator_blowup_s,
            blowup_h_phi_p_phi: run.blowup_h_phi_p_phi,
            rk4_limit_exceeded_s: run.rk4_limit_exceeded_s,
            max_trace_p: max2(&|r| r.trace_p),
            max_h_phi_p_phi: max2(&|r| r.h_phi_p_phi_max),
        }
    }
}

/// Identifiability over two windows.
#[derive(Clone, Debug, Serialize)]
pub struct IdentifiabilityReport {
    /// Steady state, 0.3–0.5 s.
    #[serde(rename = "steady_state_0.3_0.5s")]
    pub steady_state: AxisPair,
    /// Start-up, 0–0.03 s.
    #[serde(rename = "startup_0_0.03s")]
    pub startup: AxisPair,
}

/// Both axes' identifiability.
#[derive(Clone, Debug, Serialize)]
pub struct AxisPair {
    /// Drive axis (θ1).
    pub drive: Identifiability,
    /// Sense axis (θ2).
    pub sense: Identifiability,
}

/// The estimator started with P0 = 1e4·I at 0.3 s on a running gyro.
#[derive(Clone, Debug, Serialize)]
pub struct LateStart {
    /// Start of the estimator, s.
    pub start_s: f64,
    /// λ per τ.
    pub lambda_per_tau: f64,
    /// Largest h·ΦᵀPΦ in the first record after the start.
    pub first_ms_max_h_phi_p_phi: Option<[f64; 2]>,
    /// First time past RK4's stability limit, s.
    pub rk4_limit_exceeded_s: Option<f64>,
    /// Estimator blow-up time, s.
    pub estimator_blowup_s: Option<f64>,
}

/// The ±50 % runs: both pumps × λ readings × (0.5 s, 50 ms per set), plus the fine step
/// for λ = 0.2/τ; the longest first (they are scheduled in this order).
fn switch_jobs() -> Vec<SwitchOptions> {
    let mut jobs = Vec::new();
    for pump in [Pump::Literal, Pump::Recentred] {
        jobs.push(SwitchOptions {
            steps_per_period: FINE_STEPS_PER_PERIOD,
            ..SwitchOptions::new(pump, LambdaReading::PaperPerTau)
        });
    }
    for pump in [Pump::Literal, Pump::Recentred] {
        for l in LAMBDAS {
            jobs.push(SwitchOptions::new(pump, l));
            jobs.push(SwitchOptions::ms_scale(pump, l));
        }
    }
    jobs
}

/// The runs of one pump and time scale (0.5 s or 50 ms per set), the plant's step first and
/// the fine step last.
fn pick(switch: &[SwitchResult], pump: Pump, long: bool) -> Vec<&SwitchResult> {
    let mut v: Vec<&SwitchResult> = switch
        .iter()
        .filter(|r| r.pump == pump && (r.segment_s > 0.1) == long)
        .collect();
    v.sort_by_key(|r| r.steps_per_period);
    v
}

/// As [`pick`], taking the results out of `switch` as the JSON's records.
fn take(switch: &mut Vec<SwitchResult>, pump: Pump, long: bool) -> Vec<SwitchRecord> {
    let (mut mine, rest): (Vec<SwitchResult>, Vec<SwitchResult>) = std::mem::take(switch)
        .into_iter()
        .partition(|r| r.pump == pump && (r.segment_s > 0.1) == long);
    *switch = rest;
    mine.sort_by_key(|r| r.steps_per_period);
    mine.into_iter()
        .map(|r| SwitchRecord {
            run: RunNumbers::of(&r.run),
            lambda_label: r.lambda.label(),
            result: r,
        })
        .collect()
}

/// The paper's P0 = 1e4·I switched on at 0.3 s on the running gyro, 20 ms.
fn late_start() -> Result<LateStart> {
    let cfg = RawConfig {
        estimator_start_s: 0.3,
        ..RawConfig::default()
    };
    let seg = Segment {
        duration_s: 0.32,
        theta: paper_sets(&TABLE2)[0],
        omega: 1.0265f64.sqrt(),
    };
    let late = simulate(&cfg, &[seg]).map_err(|e| anyhow::anyhow!(e))?;
    Ok(LateStart {
        start_s: 0.3,
        lambda_per_tau: late.lambda_per_tau,
        first_ms_max_h_phi_p_phi: late
            .records
            .iter()
            .find(|r| r.t_s > 0.3 + 1e-9)
            .map(|r| r.h_phi_p_phi_max),
        rk4_limit_exceeded_s: late.rk4_limit_exceeded_s,
        estimator_blowup_s: late.estimator_blowup_s,
    })
}

/// The five figures; returns their paths.
fn plots(dir: &Path, switch: &[SwitchResult]) -> Result<Vec<PathBuf>> {
    let (var_long, var_ms) = (
        pick(switch, Pump::Recentred, true),
        pick(switch, Pump::Recentred, false),
    );
    let mut files = Vec::new();
    let qs = |r: std::ops::Range<usize>| r.map(theta_quantity).collect::<Vec<_>>();
    let title = |what: &str| {
        format!(
            "paper-raw variant (pump re-centred to √(−θ22)), no noise: {what}; solid = true, dashed = estimates"
        )
    };
    let phys: Vec<Quantity> = (0..6).map(physical_quantity).collect();
    for (name, what, quantities) in [
        ("paper_raw_theta1a.png", "θ11…θ14 (Fig. 9)", qs(0..4)),
        ("paper_raw_theta1b.png", "θ15…θ18 (Fig. 10)", qs(4..8)),
        ("paper_raw_theta2.png", "θ21…θ26 (Fig. 11)", qs(8..14)),
        (
            "paper_raw_physical.png",
            "physical parameters by the corrected Table 3 (Figs 12–14)",
            phys,
        ),
    ] {
        let p = dir.join(name);
        plot_est_truth(&p, &title(what), &quantities, &var_ms, &var_long)
            .with_context(|| format!("cannot draw {}", p.display()))?;
        files.push(p);
    }
    let p = dir.join("paper_raw_literal.png");
    let lit_plot: Vec<&SwitchResult> = pick(switch, Pump::Literal, true)
        .into_iter()
        .filter(|r| r.lambda != LambdaReading::PerSecond)
        .collect();
    plot_literal(&p, &lit_plot).with_context(|| format!("cannot draw {}", p.display()))?;
    files.push(p);
    Ok(files)
}

/// The runs besides the ±50 % test: the comparison with the product, the identifiability
/// windows and the late start.
struct Studies {
    cmp: Comparison,
    steady: (Identifiability, Identifiability),
    startup: (Identifiability, Identifiability),
    late: LateStart,
}

/// [`Studies`], the four in parallel (the comparison's own runs in parallel inside it).
fn studies() -> Result<Studies> {
    enum Out {
        Compare(Box<Comparison>),
        Window((Identifiability, Identifiability)),
        Late(LateStart),
    }
    let outs = try_par_map(vec![0, 1, 2, 3], |k| {
        Ok(match k {
            0 => Out::Compare(Box::new(compare(COMPARE_RAW_S)?)),
            1 => Out::Window(window_identifiability((0.3, 0.5))?),
            2 => Out::Window(window_identifiability((0.0, 0.03))?),
            _ => Out::Late(late_start()?),
        })
    })?;
    let mut it = outs.into_iter();
    match (it.next(), it.next(), it.next(), it.next()) {
        (
            Some(Out::Compare(cmp)),
            Some(Out::Window(steady)),
            Some(Out::Window(startup)),
            Some(Out::Late(late)),
        ) => Ok(Studies {
            cmp: *cmp,
            steady,
            startup,
            late,
        }),
        _ => anyhow::bail!("the studies came back out of order"),
    }
}

fn lambda_info(l: LambdaReading, w0: f64) -> LambdaInfo {
    LambdaInfo {
        key: l.key(),
        label: l.label(),
        per_tau: l.per_tau(w0),
        per_s: l.per_tau(w0) * w0,
        memory_s: l.memory_s(w0),
        memory_tau: 1.0 / l.per_tau(w0),
        discrete_per_500hz_sample: (-l.per_tau(w0) * w0 / 500.0).exp(),
    }
}

/// Runs every scenario of this module, writes `paper_raw_theta1a.png`,
/// `paper_raw_theta1b.png`, `paper_raw_theta2.png` (Figs 9–11 style), `paper_raw_physical.png`
/// (Figs 12–14), `paper_raw_literal.png` and `paper_raw_summary.json` into `dir` (created if
/// needed), and returns the summary (all numbers, and in
/// [`PaperRawSummary::table_md`] the Markdown tables). The runs go in parallel; a panic in
/// one of them is returned as an error.
///
/// About 20 s wall on 2 cores (≈ 30 simulated seconds of the raw estimator at 1.4–1.7 M
/// RK4 steps per simulated second, plus two 10 s product runs).
pub fn write_paper_raw_summary(dir: &Path) -> Result<PaperRawSummary> {
    let wall = Instant::now();
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the output directory {}", dir.display()))?;
    let w0 = OMEGA0_TABLE2_RAD_S;
    let mut switch = try_par_map(switch_jobs(), |o| {
        paper_switch(&o).map_err(|e| anyhow::anyhow!("±50 % runs: {e}"))
    })?;
    let Studies {
        cmp,
        steady: (ss1, ss2),
        startup: (su1, su2),
        late,
    } = studies()?;
    let files = plots(dir, &switch)?;
    let table_md = {
        let long: Vec<&SwitchResult> = [Pump::Literal, Pump::Recentred]
            .iter()
            .flat_map(|&p| pick(&switch, p, true))
            .collect();
        let short: Vec<&SwitchResult> = [Pump::Literal, Pump::Recentred]
            .iter()
            .flat_map(|&p| pick(&switch, p, false))
            .collect();
        tables_md(&cmp, &long, &short)
    };
    let out = PaperRawSummary {
        omega0_rad_s: w0,
        steps_per_period: RawConfig::default().steps_per_period,
        p0: PAPER_P0,
        lambda_readings: LAMBDAS.iter().map(|&l| lambda_info(l, w0)).collect(),
        literal: take(&mut switch, Pump::Literal, true),
        variant: take(&mut switch, Pump::Recentred, true),
        literal_ms_scale: take(&mut switch, Pump::Literal, false),
        variant_ms_scale: take(&mut switch, Pump::Recentred, false),
        comparison: cmp.rows,
        product_summaries: cmp.product_runs.iter().map(|r| r.summary.clone()).collect(),
        identifiability: IdentifiabilityReport {
            steady_state: AxisPair {
                drive: ss1,
                sense: ss2,
            },
            startup: AxisPair {
                drive: su1,
                sense: su2,
            },
        },
        estimator_started_on_running_gyro: late,
        files: files.iter().map(|p| p.display().to_string()).collect(),
        wall_s: wall.elapsed().as_secs_f64(),
        table_md,
    };
    crate::write_json(&dir.join("paper_raw_summary.json"), &out, true)?;
    Ok(out)
}
