//! Side by side with the product's estimator on the `identify` plant.

use anyhow::{Context, Result};
use paragyro_simulator::plant::Theta;
use paragyro_simulator::runner::{self, Precision, RunOptions};
use paragyro_simulator::scenario::Scenario;
use paragyro_simulator::trace::RunResult;
use serde::Serialize;

use super::config::{LambdaReading, RawConfig, Segment};
use super::records::rel_err;
use super::simulate::{RawRun, simulate};
use super::switch::segment_summaries;
use paragyro_simulator::par::try_par_map;

/// One estimator configuration in the comparison.
#[derive(Clone, Debug, Serialize)]
pub struct CompareRow {
    /// Short label.
    pub label: String,
    /// "paper (raw)" or "product (lock-in)".
    pub estimator: String,
    /// Noise density, L0/√Hz.
    pub noise_density: f64,
    /// Relative θ errors at the end (θ11…θ18, θ21…θ26).
    pub final_rel_err: [f64; 14],
    /// Time from t = 0 after which each θ stays within 10 % to the end.
    pub within_10pct_s: [Option<f64>; 14],
    /// … within 1 %.
    pub within_1pct_s: [Option<f64>; 14],
    /// Recovered rate at the end, °/s (γ̂ via the corrected Table 3).
    pub rate_dps_est: f64,
    /// True rate, °/s.
    pub rate_dps_true: f64,
    /// What the estimator consumes.
    pub data: String,
    /// Sample instants per second the estimator consumes.
    pub samples_per_s: f64,
    /// Real values per second it consumes (all channels).
    pub values_per_s: f64,
    /// Simulated time, s.
    pub sim_s: f64,
    /// Wall time, s.
    pub wall_s: f64,
    /// Estimator blow-up time (raw runs), s.
    pub blowup_s: Option<f64>,
}

/// The side-by-side comparison.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    /// Rows: the raw paper estimator for each λ reading and noise level, then the product.
    pub rows: Vec<CompareRow>,
    /// The raw runs (same order as the first rows).
    #[serde(skip)]
    pub raw_runs: Vec<RawRun>,
    /// The product runs.
    #[serde(skip)]
    pub product_runs: Vec<RunResult>,
}

/// The product's `identify` scenario (the plant of the comparison).
fn identify_scenario() -> Result<Scenario> {
    Scenario::builtin("identify").context("built-in scenario 'identify' is missing")
}

/// The raw estimator on the plant of the product's `identify` scenario (Table 2, 150 °/s,
/// 10 g, X(0) from the scenario), pump fixed at the scenario's centre (√1.0265, no dither),
/// for `sim_s` seconds.
pub fn raw_on_identify_plant(
    lambda: LambdaReading,
    noise_density: f64,
    sim_s: f64,
) -> Result<RawRun> {
    let sc = identify_scenario()?;
    let pa = sc.plant_at(0.0);
    let w0 = sc.omega0_rad_s();
    let omega = sc.pump_centre_hz() / (2.0 * sc.sim.f0_hz);
    let cfg = RawConfig {
        omega0_rad_s: w0,
        noise_density,
        seed: sc.seed,
        lambda_per_tau: lambda.per_tau(w0),
        x0: [sc.plant.initial_x_um, 0.0, sc.plant.initial_y_um, 0.0],
        accel: [pa.accel_x, pa.accel_y],
        ..RawConfig::default()
    };
    let seg = Segment {
        duration_s: sim_s,
        theta: Theta {
            drive: pa.theta_drive,
            sense: pa.theta_sense,
        },
        omega,
    };
    simulate(&cfg, &[seg]).map_err(|e| anyhow::anyhow!("raw estimator: {e}"))
}

fn raw_row(label: String, noise: f64, run: &RawRun, w0: f64) -> Result<CompareRow> {
    let segs = segment_summaries(run, &["nominal"], w0).map_err(anyhow::Error::msg)?;
    let seg = segs.first().context("a raw run without segments")?;
    Ok(CompareRow {
        label,
        estimator: "paper (raw)".into(),
        noise_density: noise,
        final_rel_err: seg.final_rel_err,
        within_10pct_s: seg.within_10pct_s,
        within_1pct_s: seg.within_1pct_s,
        rate_dps_est: seg.rate_dps_est,
        rate_dps_true: seg.rate_dps_true,
        data: format!(
            "raw X, Y at the integration rate ({:.2} MS/s) + ãx, ãy + pump phase",
            run.steps_per_s / 1e6
        ),
        samples_per_s: run.steps_per_s,
        values_per_s: 4.0 * run.steps_per_s,
        sim_s: seg.end_s,
        wall_s: run.wall_s,
        blowup_s: run.estimator_blowup_s,
    })
}

fn product_row(label: String, noise: f64, res: &RunResult) -> Result<CompareRow> {
    let tr = &res.trace;
    let last = tr.last().context("a product run without samples")?;
    let mut fe = [0.0; 14];
    for j in 0..8 {
        fe[j] = rel_err(last.theta_drive_est[j], last.theta_drive_true[j]);
    }
    for j in 0..6 {
        fe[8 + j] = rel_err(last.theta_sense_est[j], last.theta_sense_true[j]);
    }
    let fs = if tr.len() > 1 {
        1.0 / (tr[1].t_s - tr[0].t_s)
    } else {
        500.0
    };
    Ok(CompareRow {
        label,
        estimator: "product (lock-in)".into(),
        noise_density: noise,
        final_rel_err: fe,
        within_10pct_s: std::array::from_fn(|j| runner::settle_time(tr, j, 0.1, 0.0)),
        within_1pct_s: std::array::from_fn(|j| runner::settle_time(tr, j, 0.01, 0.0)),
        rate_dps_est: last.rate_dps_est,
        rate_dps_true: last.rate_dps_true,
        data: format!(
            "14 lock-in channels + 2 accelerometer + pump at {fs:.0} Hz (dither from 1 s)"
        ),
        samples_per_s: fs,
        values_per_s: 17.0 * fs,
        sim_s: last.t_s,
        wall_s: res.summary.wall_seconds,
        blowup_s: None,
    })
}

/// λ readings compared everywhere.
pub const LAMBDAS: [LambdaReading; 3] = [
    LambdaReading::PaperPerTau,
    LambdaReading::PerSecond,
    LambdaReading::Product2s,
];

/// The side-by-side comparison on the `identify` plant: the raw paper estimator for each λ
/// reading of [`LAMBDAS`], noise-free and at 1 pm/√Hz, `raw_sim_s` seconds each, against the
/// product's `identify` scenario (f64 core, 10 s, 1 pm/√Hz, and the same noise-free).
pub fn compare(raw_sim_s: f64) -> Result<Comparison> {
    let sc = identify_scenario()?;
    let w0 = sc.omega0_rad_s();
    let noise = sc.sim.noise_pm_rthz * 1e-6;
    enum Job {
        Raw(LambdaReading, f64),
        Product(f64),
    }
    let mut jobs = Vec::new();
    for &n in &[0.0, noise] {
        for &l in &LAMBDAS {
            jobs.push(Job::Raw(l, n));
        }
    }
    jobs.push(Job::Product(noise));
    jobs.push(Job::Product(0.0));
    enum Out {
        Raw(RawRun),
        Product(Box<RunResult>),
    }
    let outs = try_par_map(jobs, |j| -> Result<Out> {
        match j {
            Job::Raw(l, n) => Ok(Out::Raw(raw_on_identify_plant(l, n, raw_sim_s)?)),
            Job::Product(n) => {
                let mut s = sc.clone();
                s.sim.noise_pm_rthz = n * 1e6;
                let opts = RunOptions {
                    precision: Precision::F64,
                    seed: None,
                };
                Ok(Out::Product(Box::new(runner::run(&s, &opts, &mut |_| {})?)))
            }
        }
    })?;
    let mut rows = Vec::new();
    let mut raw_runs = Vec::new();
    let mut product_runs = Vec::new();
    let mut k = 0;
    for o in outs {
        match o {
            Out::Raw(r) => {
                let (l, n) = (LAMBDAS[k % 3], if k < 3 { 0.0 } else { noise });
                let nl = if n > 0.0 { "1 pm/√Hz" } else { "noise-free" };
                rows.push(raw_row(format!("paper, {}, {nl}", l.label()), n, &r, w0)?);
                raw_runs.push(r);
                k += 1;
            }
            Out::Product(r) => {
                let n = if product_runs.is_empty() { noise } else { 0.0 };
                let nl = if n > 0.0 { "1 pm/√Hz" } else { "noise-free" };
                rows.push(product_row(
                    format!("product (identify, f64, λd = 0.999), {nl}"),
                    n,
                    &r,
                )?);
                product_runs.push(*r);
            }
        }
    }
    Ok(Comparison {
        rows,
        raw_runs,
        product_runs,
    })
}
