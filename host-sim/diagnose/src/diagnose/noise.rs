//! Each row's noise level for *this* record: lock-in noise at the reference density
//! (1 pm/√Hz through the record's lock-in) added to the record and carried through the
//! rows and the calibrated θ.
//!
//! A row's noise is the lock-in channels' noise through the row's own combination of
//! them, and that combination is the device's (its θ and its envelopes): the sense
//! 1st-harmonic rows' energy at the noise follows the device (on 48 clean toleranced
//! development devices it correlates +0.60 with the device's ωxy² deviation and −0.50
//! with its ωx², and scales with the noise: blind-benchmark.md, "Clean devices read
//! `unknown`"). One profile averaged over devices ([`super::NOISE_ROW_PROFILE`]) put three
//! of those 48 over `none`'s gate; this record's own puts none of them there. (The
//! confirmation by re-simulation keeps the profile: its per-row rule's scatter was
//! measured about it.)
//!
//! The noise: white noise at 8× the sample rate through the record's lock-in low-pass
//! (the core's replica of it), taken every 8th sample, each channel scaled to the
//! simulator's own lock-in noise at the reference density (the energy of its second
//! differences, [`super::resim::lockin_noise_diff_energy`]). The rows are linear in the
//! lock-in channels but for the cubic projections, which the noise barely moves, so the
//! difference of a pass with the noise and the record's pass is the noise's rows; the
//! held-out residual's noise is those rows less the θ columns' noise times the
//! calibration's Δθ (the rows are about the calibrated model: y = z − Φ·θ_model, then
//! `− Φ·Δθ`).

use std::ops::Range;

use paragyro_core::lpf::{ReplicaChannel, ReplicaCoeffs};
use paragyro_simulator::record::Record;
use rand::{Rng, SeedableRng};

use super::NR;
use super::rows::{Rows, run_pass};

/// Oversampling of the white noise ahead of the lock-in low-pass.
const OVERSAMPLE: usize = 8;

/// Seed of the added noise (fixed: a record's diagnosis is reproducible).
const NOISE_SEED: u64 = 0x006e_6f69_7365;

/// Lock-in noise at the reference density for the record's `n` samples, per channel in
/// the order of [`super::resim::channels`], µm: each channel's energy of second
/// differences per sample is `e1`'s. `seed`: [`NOISE_SEED`] for the diagnosis; other
/// seeds give independent realizations (the calibration's σ checked against their spread:
/// src/blind/sigma_tests.rs).
pub(crate) fn lockin_noise(rec: &Record, n: usize, e1: &[f64; 10], seed: u64) -> Vec<[f64; 10]> {
    let h = &rec.header;
    let ts = 1.0 / (h.fs_hz * OVERSAMPLE as f64);
    let wc = std::f64::consts::TAU * h.lockin_lpf_hz;
    let co = ReplicaCoeffs::<f64>::butterworth(h.lockin_lpf_order, wc, ts, false);
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut gauss = move || {
        // Box–Muller (one of the pair)
        let (u1, u2): (f64, f64) = (rng.random(), rng.random());
        (-2.0 * (1.0 - u1).ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    let mut out = vec![[0.0; 10]; n];
    for c in 0..10 {
        let mut ch = ReplicaChannel::at_rest(&co, 0.0);
        // settle the filter on the noise first (many of its time constants)
        for _ in 0..64 * OVERSAMPLE {
            ch.update(&co, gauss());
        }
        for o in out.iter_mut() {
            let mut y = 0.0;
            for _ in 0..OVERSAMPLE {
                y = ch.update(&co, gauss());
            }
            o[c] = y;
        }
        // scale to the reference's energy of second differences
        let dd: f64 = out
            .windows(3)
            .map(|w| (w[2][c] - 2.0 * w[1][c] + w[0][c]).powi(2))
            .sum::<f64>()
            / (n.saturating_sub(2)).max(1) as f64;
        let g = if dd > 0.0 { (e1[c] / dd).sqrt() } else { 0.0 };
        for o in out.iter_mut() {
            o[c] *= g;
        }
    }
    out
}

/// Each row's energy per sample at the reference noise density (× ν² for the record's
/// own), over `span` (the held-out samples whose rows count), for the rows `rows` about
/// the calibrated model and its refinement `dtheta`.
pub(crate) fn row_noise(
    rec: &Record,
    rows: &Rows,
    dtheta: &[f64; 14],
    e1: &[f64; 10],
    span: Range<usize>,
) -> anyhow::Result<[f64; NR]> {
    let n = rec.rows.len();
    let noise = lockin_noise(rec, n, e1, NOISE_SEED);
    let pass = with_noise(rec, rows, &noise)?;
    let base = &rows.base;
    let (mut acc, mut m) = ([0.0; NR], 0usize);
    for k in span.filter(|&k| k < n && rows.usable[k] && pass.usable[k]) {
        for (r, a) in acc.iter_mut().enumerate() {
            let mut e = pass.y[k][r] - base.y[k][r];
            for (j, d) in dtheta.iter().enumerate() {
                e -= d * (pass.theta[k][j][r] - base.theta[k][j][r]);
            }
            *a += e * e;
        }
        m += 1;
    }
    anyhow::ensure!(
        m > 0,
        "no held-out samples to carry the noise through the rows"
    );
    Ok(acc.map(|a| a / m as f64))
}

/// The estimator pass of the record with `noise` (µm, [`lockin_noise`]'s channels) added to
/// its lock-in channels, about the rows' model.
pub(crate) fn with_noise(
    rec: &Record,
    rows: &Rows,
    noise: &[[f64; 10]],
) -> anyhow::Result<super::rows::Pass> {
    run_pass(rec, &rows.cfg, &|k, s| {
        let v = &noise[k];
        let l = &mut s.lockin;
        l.x0_um += v[0];
        l.x_um[0].re += v[1];
        l.x_um[0].im += v[2];
        l.x_um[2].re += v[3];
        l.x_um[2].im += v[4];
        l.y0_um += v[5];
        l.y_um[0].re += v[6];
        l.y_um[0].im += v[7];
        l.y_um[2].re += v[8];
        l.y_um[2].im += v[9];
    })
}
