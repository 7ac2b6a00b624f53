//! The simulator's own numerical error on a record's inputs: the re-simulation at its step
//! (RK4 steps per carrier period) against a 4× finer reference of itself on the same inputs
//! (pump frequency and amplitude as the record format defines them between samples,
//! accelerations, temperature, the rate table), both through the same lock-in model and the
//! same regression rows. Per row, the mean energy of the difference over the usable span,
//! in units of the rows' noise (unit-noise weighting: noise alone ≈ [`NOISE_ROW_ENERGY`]).

use serde::{Deserialize, Serialize};

use paragyro_simulator::record::Record;

use paragyro_core::physics::{physical_from_theta, theta_from_physical};

use super::calibrate::PARAM_NAMES;
use super::lsq::Bank;
use super::resim::{Resim, with_lockin};
use super::rows::{Pass, gamma_per_dps, model_config, run_pass};
use super::{Model, NOISE_ROW_ENERGY, NR, ROW_LABELS, WARMUP_S};

/// The simulator's numerical error against its 4× finer reference, per row.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NumericsGap {
    /// RK4 steps per carrier period of the simulator and of the reference.
    pub steps_per_period: usize,
    pub reference_steps_per_period: usize,
    /// (row, mean energy of the difference per sample / the rows' noise energy).
    pub per_row: Vec<(String, f64)>,
    /// The largest of them.
    pub max_over_noise: f64,
    /// The same after the difference's least-squares fit on the 14 θ columns (what the
    /// calibration absorbs: the integrator's frequency error is a stiffness shift).
    pub absorbed_per_row: Vec<(String, f64)>,
    /// The largest of them.
    pub absorbed_max_over_noise: f64,
    /// The parameter shifts the calibration absorbs, relative to the model's
    /// ([`super::calibrate::PARAM_NAMES`] order; 0 where the model's value is 0).
    pub absorbed_relative: Vec<(String, f64)>,
}

/// Runs the model on the record's inputs at `steps` and at `4 × steps` RK4 steps per
/// period and compares their rows.
pub fn numerics_gap(rec: &Record, model: &Model, steps: usize) -> anyhow::Result<NumericsGap> {
    let n = rec.rows.len();
    let rate_ref: Option<Vec<f64>> = rec
        .rows
        .iter()
        .all(|r| r.rate_ref_dps.is_some_and(f64::is_finite))
        .then(|| {
            rec.rows
                .iter()
                .map(|r| r.rate_ref_dps.unwrap_or(0.0))
                .collect()
        });
    let gamma_nom = match &rate_ref {
        Some(v) => {
            gamma_per_dps(std::f64::consts::TAU * rec.header.f0_hz) * v.iter().sum::<f64>()
                / v.len().max(1) as f64
        }
        None => model.phys.gamma,
    };
    let cfg = model_config(rec, model, gamma_nom);
    let run = |spp: usize| -> anyhow::Result<(Vec<[f64; NR]>, Pass)> {
        let sim = Resim {
            rec,
            model,
            gamma: None,
            rate_ref: rate_ref.as_deref(),
            effects: &[],
            vib_phase0: 0.0,
            steps_per_period: spp,
        }
        .run(0..n)?;
        let p = run_pass(&with_lockin(rec, &sim), &cfg, &|_, _| {})?;
        let y =
            p.y.iter()
                .zip(&p.usable)
                .map(|(y, &u)| if u { *y } else { [f64::NAN; NR] })
                .collect();
        Ok((y, p))
    };
    let (a, b) = (run(steps)?, run(4 * steps)?);
    let (ya, pb) = (a.0, b.1);
    let yb = b.0;
    let t0 = rec.rows.first().map_or(0.0, |r| r.t_s) + WARMUP_S;
    let ok: Vec<bool> = (0..n)
        .map(|k| rec.rows[k].t_s >= t0 && ya[k].iter().chain(&yb[k]).all(|v| v.is_finite()))
        .collect();
    let d: Vec<[f64; NR]> = (0..n)
        .map(|k| {
            if ok[k] {
                std::array::from_fn(|r| ya[k][r] - yb[k][r])
            } else {
                [0.0; NR]
            }
        })
        .collect();
    let m = ok.iter().filter(|&&v| v).count();
    anyhow::ensure!(m > 0, "no usable samples to compare");
    // what the calibration absorbs: the 14 θ fitted to the difference
    let cols: Vec<Vec<[f64; NR]>> = (0..14)
        .map(|j| pb.theta.iter().map(|c| c[j]).collect())
        .collect();
    let refs: Vec<&[[f64; NR]]> = cols.iter().map(|c| c.as_slice()).collect();
    // one block (the covariance is not used)
    let whole: Vec<std::ops::Range<usize>> = std::iter::once(0..n).collect();
    let bank = Bank::build(&refs, &d, &ok, &whole, 0..0);
    let fit = bank.fit(&(0..14).collect::<Vec<_>>());
    let energy = |resid: &dyn Fn(usize) -> [f64; NR]| -> Vec<(String, f64)> {
        let mut acc = [0.0; NR];
        for k in (0..n).filter(|&k| ok[k]) {
            let r = resid(k);
            for i in 0..NR {
                acc[i] += r[i] * r[i];
            }
        }
        (0..NR)
            .map(|r| {
                (
                    ROW_LABELS[r].to_string(),
                    acc[r] / m as f64 / NOISE_ROW_ENERGY,
                )
            })
            .collect()
    };
    let per_row = energy(&|k| d[k]);
    let absorbed_per_row = energy(&|k| fit.resid(&d, &refs, k));
    let mx = |v: &[(String, f64)]| v.iter().map(|p| p.1).fold(0.0, f64::max);
    // the θ the difference needs → the physical parameters' relative shift
    let (t1, t2) = theta_from_physical(&model.phys);
    let mut th1 = t1;
    let mut th2 = t2;
    for j in 0..8 {
        th1[j] += fit.beta[j];
    }
    for j in 0..6 {
        th2[j] += fit.beta[8 + j];
    }
    let p0 = physical_from_theta(&t1, &t2);
    let p1 = physical_from_theta(&th1, &th2);
    let (a0, a1) = (p0.as_array(), p1.as_array());
    let absorbed_relative = (0..12)
        .map(|i| {
            (
                PARAM_NAMES[i].to_string(),
                if a0[i] != 0.0 {
                    (a1[i] - a0[i]) / a0[i].abs()
                } else {
                    0.0
                },
            )
        })
        .collect();
    Ok(NumericsGap {
        steps_per_period: steps,
        reference_steps_per_period: 4 * steps,
        max_over_noise: mx(&per_row),
        per_row,
        absorbed_max_over_noise: mx(&absorbed_per_row),
        absorbed_per_row,
        absorbed_relative,
    })
}
