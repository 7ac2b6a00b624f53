//! The calibrated model's prediction spread: how far its re-simulation moves when its θ move
//! within their uncertainty.
//!
//! The calibration estimates the device's 14 θ with a covariance (cluster-robust over the
//! fit span's blocks). Each twin here is the calibrated model with its θ moved by one draw
//! from that covariance, re-simulated on the record's inputs like the model (on the
//! record's branch, the second half from the record's own state); the spread is the rms over
//! the twins of each sample's difference from the model's run, for the drive's and the
//! sense's 1st-harmonic phasors (µm), beside the record's own departure from the model.
//!
//! Where a parametric drive collapses deep and grows back, its trajectory amplifies a
//! difference in the parameters' last digits a thousandfold (host-sim/diagnose/docs/notes.md,
//! "The model's prediction spread at the drive's regrowths"): there the spread peaks, and a
//! departure of the record of the spread's size is the calibrated model's own uncertainty,
//! not an effect's gap. The diagnosis does not judge with it (yet); `cargo run --profile test
//! -p paragyro-diagnose --example spread -- RECORD.csv` prints it window by window.

use super::{Options, Timing, calibrate, calibration, resim::Resim};
use paragyro_simulator::lockin::LockinOut;
use paragyro_simulator::record::Record;
use rand::{Rng, SeedableRng};

/// The calibrated model's prediction spread against the record's departure, per sample of
/// the usable span (from the first sample after the warm-up to the last usable one).
#[derive(Clone, Debug)]
pub struct PredictionSpread {
    /// Times of the samples, s.
    pub t: Vec<f64>,
    /// The first held-out sample's time, s (the samples before it are the fit span's and
    /// its guard's).
    pub hold_start_s: f64,
    /// The record's drive working amplitude (the 90th percentile of its |x1|), µm.
    pub working_um: f64,
    /// |x1 record − x1 model| and |y1 record − y1 model| (the 1st-harmonic phasors), µm.
    pub departure: Vec<[f64; 2]>,
    /// The rms over the twins of |x1 twin − x1 model| and of |y1 twin − y1 model|, µm.
    pub spread: Vec<[f64; 2]>,
    /// The twins drawn.
    pub draws: usize,
}

/// The drive's (`x1`) and the sense's (`y1`) 1st-harmonic phasors of a lock-in output,
/// times `scale` (a re-simulation's are in L0: `scale` L0 in µm).
fn phasors(l: &LockinOut, scale: f64) -> [(f64, f64); 2] {
    let (x, y) = (l.x_um[0], l.y_um[0]);
    [(x.re * scale, x.im * scale), (y.re * scale, y.im * scale)]
}

fn apart(a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - b.0).hypot(a.1 - b.1)
}

/// One standard-normal draw (Box–Muller).
fn normal(rng: &mut impl Rng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The square root `V·√Λ` of the covariance `cov` (14 × 14, row-major) from its
/// eigen-decomposition: a draw `root·z` has that covariance (a covariance of rank below 14,
/// as a cluster-robust one can be, draws in its range; a negative rounding of an
/// eigenvalue counts as 0).
fn root(cov: &[f64]) -> nalgebra::DMatrix<f64> {
    let eig = nalgebra::DMatrix::from_row_slice(14, 14, cov).symmetric_eigen();
    let sqrt_l = eig.eigenvalues.map(|l| l.max(0.0).sqrt());
    eig.eigenvectors * nalgebra::DMatrix::from_diagonal(&sqrt_l)
}

/// A draw of `Δθ`, `root·z` ([`root`]).
fn draw(root: &nalgebra::DMatrix<f64>, rng: &mut impl Rng) -> [f64; 14] {
    let z = nalgebra::DVector::from_fn(14, |_, _| normal(rng));
    let d = root * z;
    std::array::from_fn(|i| d[i])
}

/// The calibrated model's prediction spread on `rec` from `draws` twins (seeded by `seed`),
/// beside the record's departure from the model: the diagnosis's calibration (as
/// [`super::diagnose`] runs it, with the budget of runs for the record's length), then one
/// whole-record re-simulation per twin. An error when `draws` is 0, when the record cannot
/// be calibrated with re-simulation, or when a twin's model is not physical.
pub fn prediction_spread(
    rec: &Record,
    opts: &Options,
    draws: usize,
    seed: u64,
) -> anyhow::Result<PredictionSpread> {
    anyhow::ensure!(draws > 0, "the prediction spread needs at least one twin");
    anyhow::ensure!(
        opts.resimulate,
        "the prediction spread needs the re-simulation (not --no-resim)"
    );
    let opts = opts.for_record(rec);
    let mut timing = Timing::new();
    let mut limits = Vec::new();
    let (rows, spans, opts_cal, fit, _) = calibration(rec, &opts, &mut timing, &mut limits)?;
    let Some(model_run) = &rows.before_sim else {
        anyhow::bail!(
            "the calibration could not re-simulate the record: {}",
            limits
                .iter()
                .map(|l| l.detail.as_str())
                .collect::<Vec<_>>()
                .join("; ")
        );
    };
    let n = rec.rows.len().min(model_run.len());
    let span = spans.first..(spans.last + 1).min(n);
    // the model of the rows is the calibration's last re-simulated one, with the last
    // fit's refinement applied linearly: the twins move that model by draws about it
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed);
    let (root, l0) = (root(&fit.cov), rec.header.l0_um);
    let mut sq = vec![[0.0f64; 2]; span.len()];
    for i in 0..draws {
        let dtheta = draw(&root, &mut rng);
        let twin = calibrate::calibrated_model(
            &opts_cal.model,
            &rows,
            &calibrate::ThetaFit {
                dtheta,
                cov: fit.cov.clone(),
            },
            &format!("twin {i}"),
        );
        if let Some(why) = calibrate::unphysical(&twin) {
            anyhow::bail!("twin {i} of the calibrated model is not physical: {why}");
        }
        let run = Resim {
            rec,
            model: &twin,
            gamma: rows.gamma_sim,
            rate_ref: rows.rate_ref.as_deref(),
            effects: &[],
            vib_phase0: 0.0,
            steps_per_period: opts_cal.steps_per_period,
        }
        .run(0..n)?;
        for (s, k) in sq.iter_mut().zip(span.clone()) {
            let (m, w) = (phasors(&model_run[k], l0), phasors(&run[k], l0));
            for c in 0..2 {
                s[c] += apart(w[c], m[c]).powi(2);
            }
        }
    }
    let spread = sq
        .iter()
        .map(|s| [(s[0] / draws as f64).sqrt(), (s[1] / draws as f64).sqrt()])
        .collect();
    let departure = span
        .clone()
        .map(|k| {
            let (r, m) = (
                phasors(&rec.rows[k].lockin, 1.0),
                phasors(&model_run[k], l0),
            );
            [apart(r[0], m[0]), apart(r[1], m[1])]
        })
        .collect();
    let mut amp: Vec<f64> = rec
        .rows
        .iter()
        .map(|r| {
            let x = phasors(&r.lockin, 1.0)[0];
            x.0.hypot(x.1)
        })
        .filter(|a| a.is_finite())
        .collect();
    amp.sort_by(f64::total_cmp);
    let working_um = amp
        .get(amp.len().saturating_sub(1) * 9 / 10)
        .copied()
        .unwrap_or(0.0);
    Ok(PredictionSpread {
        t: span.clone().map(|k| rec.rows[k].t_s).collect(),
        hold_start_s: rec.rows.get(spans.hold_start).map_or(f64::NAN, |r| r.t_s),
        working_um,
        departure,
        spread,
        draws,
    })
}

#[cfg(test)]
mod tests {
    use super::{draw, root};
    use rand::SeedableRng;

    /// The draws have the covariance they are drawn from, a singular one included (a
    /// cluster-robust covariance can be): θ0 and θ1 fully correlated, θ2 fixed.
    #[test]
    fn the_twins_draws_follow_the_calibrations_covariance() {
        let mut cov = vec![0.0; 14 * 14];
        for j in 3..14 {
            cov[j * 14 + j] = (j as f64) * 1e-6;
        }
        for (i, j) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
            cov[i * 14 + j] = 4e-6;
        }
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(3);
        let n = 4000;
        let mut s = vec![0.0; 14 * 14];
        let r = root(&cov);
        for _ in 0..n {
            let d = draw(&r, &mut rng);
            for i in 0..14 {
                for j in 0..14 {
                    s[i * 14 + j] += d[i] * d[j] / n as f64;
                }
            }
        }
        for j in (0..2).chain(3..14) {
            let rel = s[j * 14 + j] / cov[j * 14 + j];
            assert!(
                (rel - 1.0).abs() < 0.1,
                "θ{j}: variance {rel:.3} of the covariance's"
            );
        }
        let corr = s[1] / (s[0] * s[15]).sqrt();
        assert!(corr > 0.999, "θ0 and θ1 correlate {corr}");
        assert!(
            s[2 * 14 + 2] < 1e-20,
            "the fixed θ2 moved: {}",
            s[2 * 14 + 2]
        );
    }
}
