//! The simulator re-run open-loop on a record's own inputs (pump frequency and amplitude,
//! accelerations, die temperature), with or without effects, and the output error of its
//! lock-in channels against the record's.

use std::f64::consts::TAU;

use paragyro_core::Cplx;
use paragyro_core::physics::theta_from_physical;
use paragyro_simulator::effects::{EffectSpec, Effects, T_REF_C};
use paragyro_simulator::lockin::LockinOut;
use paragyro_simulator::plant::prewarp::prewarp;
use paragyro_simulator::plant::{GyroSim, PlantInputs, SimConfig, Theta};
use paragyro_simulator::record::Record;
use serde::{Deserialize, Serialize};

use super::Model;
use super::rows::{first_pump_hz, gamma_per_dps, psi_of};

/// Samples re-simulated before a chunk's first sample (from the record's state there) so
/// that the modes and the lock-in have forgotten the restart (0.5 s ≫ the 29 ms mode and
/// 2.6 ms lock-in time constants).
const RESIM_OVERLAP_S: f64 = 0.5;

/// The simulator re-run open-loop on a record's inputs: pump frequency and amplitude,
/// accelerations, die temperature; θ of the model with the given rate (or the rate
/// table's), plus `effects`.
#[derive(Clone, Copy, Debug)]
pub struct Resim<'a> {
    /// The record whose inputs drive the simulator.
    pub rec: &'a Record,
    /// The simulator's configuration.
    pub model: &'a Model,
    /// The rate γ when the record has no rate table (`None`: the model's).
    pub gamma: Option<f64>,
    /// The rate table, °/s per sample (takes precedence over `gamma`).
    pub rate_ref: Option<&'a [f64]>,
    /// Effects added to the simulator.
    pub effects: &'a [EffectSpec],
    /// Angular vibration phase φ0, rad.
    pub vib_phase0: f64,
    /// RK4 steps per carrier period.
    pub steps_per_period: usize,
}

impl Resim<'_> {
    /// The lock-in outputs for the samples `span`, on the record's branch (ψ or ψ + π) of
    /// the parametric oscillation. The span is split in two halves computed in parallel; a half
    /// that does not start at sample 0 starts 0.5 s early from the record's own state.
    pub fn run(&self, span: std::ops::Range<usize>) -> anyhow::Result<Vec<LockinOut>> {
        let rec = self.rec;
        let psi = psi_of(rec);
        let (k0, k1) = (span.start, span.end.min(rec.rows.len()));
        let mid = k0 + (k1 - k0) / 2;
        let halves = paragyro_simulator::par::try_map(
            &[(k0, mid), (mid, k1)],
            |(a, b)| format!("the re-simulation of samples {a}..{b}"),
            |&(a, b)| self.chunk(&psi, a, b),
        )?;
        let mut out: Vec<LockinOut> = halves.into_iter().flatten().collect();
        on_record_branch(rec, &mut out, k0, mid);
        Ok(out)
    }
}

/// The stretches of a re-simulation (`out`, its first sample the record's `k0`) that
/// choose their branch: the first half from rest (to `mid`), and from each collapse of
/// the record's drive ([`rows::COLLAPSE_SHARE`](super::rows::COLLAPSE_SHARE) of its
/// working amplitude, once it has built up to half of it) to the next. Each starts where
/// the drive grows from the floor, and whether it grows at phase 0 or π against the half
/// pump is the floor's: a device's noise, a simulator's smallest terms. A stretch begins
/// at the re-simulation's quietest sample of the collapse (its 1st and 3rd harmonics, which
/// a change of branch negates, at their smallest), so that the change is no step in the
/// rows. The second half starts from the record's state, on its branch.
fn branch_stretches(rec: &Record, out: &[LockinOut], k0: usize, mid: usize) -> Vec<(usize, usize)> {
    let k1 = k0 + out.len();
    let odd = |o: &LockinOut| {
        [o.x_um[0], o.x_um[2], o.y_um[0], o.y_um[2]]
            .iter()
            .map(|v| v.re * v.re + v.im * v.im)
            .sum::<f64>()
    };
    let mut starts = vec![mid];
    if k0 == 0 {
        starts.push(0);
    }
    // the record's own collapses (its drive against itself)
    let x1: Vec<(f64, f64)> = rec.rows[k0..k1]
        .iter()
        .map(|r| (r.lockin.x_um[0].re, r.lockin.x_um[0].im))
        .collect();
    if let Some((_, collapses)) = super::rows::collapses(&x1, &x1) {
        for (a, b) in collapses {
            let quiet = (k0 + a..k0 + b)
                .filter(|&j| odd(&out[j - k0]).is_finite())
                .min_by(|&i, &j| odd(&out[i - k0]).total_cmp(&odd(&out[j - k0])));
            starts.extend(quiet);
        }
    }
    starts.sort_unstable();
    starts.dedup();
    let mut bounds: Vec<(usize, usize)> = Vec::new();
    for (i, &a) in starts.iter().enumerate() {
        let b = starts.get(i + 1).copied().unwrap_or(k1);
        // the half that starts on the record's branch keeps it until its first collapse
        if a != mid && b > a {
            bounds.push((a, b));
        }
    }
    bounds
}

/// Puts each stretch of the re-simulation `out` (its first sample the record's `k0`,
/// halves split at `mid`) that chose its own branch ([`branch_stretches`]) on the
/// record's: its 1st and 3rd harmonics negated where that brings its drive 1st harmonic
/// closer to the record's (over the stretch; the first one from rest over its second
/// half, past the start-up). The 2nd harmonic and DC are the same on both branches.
fn on_record_branch(rec: &Record, out: &mut [LockinOut], k0: usize, mid: usize) {
    for (a, b) in branch_stretches(rec, out, k0, mid) {
        let from = if a == 0 { b / 2 } else { a };
        let (mut same, mut flip) = (0.0, 0.0);
        for k in from..b {
            let x = rec.rows[k].lockin.x_um[0];
            let o = out[k - k0].x_um[0].scale(rec.header.l0_um);
            if (x.re + x.im + o.re + o.im).is_finite() {
                same += (x.re - o.re).powi(2) + (x.im - o.im).powi(2);
                flip += (x.re + o.re).powi(2) + (x.im + o.im).powi(2);
            }
        }
        if flip < same {
            for o in &mut out[a - k0..b - k0] {
                for h in [0, 2] {
                    o.x_um[h] = Cplx::new(-o.x_um[h].re, -o.x_um[h].im);
                    o.y_um[h] = Cplx::new(-o.y_um[h].re, -o.y_um[h].im);
                }
            }
        }
    }
}

/// Output error of re-simulated lock-in outputs against a record.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct OutputError {
    /// Drive channels (DC, 1st, 3rd harmonic): rms error relative to the record's rms.
    pub drive: f64,
    /// Sense channels, same.
    pub sense: f64,
    /// Both axes.
    pub combined: f64,
    /// Both axes with the record's own noise removed (its energy estimated from the
    /// sample-to-sample differences of the error and the lock-in noise's known ratio).
    pub above_noise: f64,
}

/// The simulator at the record's lock-in settings with white displacement noise (density
/// 1e-6, seed 7), the Table 2 gyro at rest and its inputs: the noise references below.
fn noise_sim(rec: &Record) -> anyhow::Result<(GyroSim, Theta, PlantInputs)> {
    let h = &rec.header;
    let omega0 = TAU * h.f0_hz;
    let cfg = SimConfig {
        omega0_rad_s: omega0,
        fs_hz: h.fs_hz,
        steps_per_period: 32,
        omega_max: 1.05,
        lpf_order: h.lockin_lpf_order,
        lpf_hz: h.lockin_lpf_hz,
        noise_density: 1e-6,
        seed: 7,
    };
    let sim = GyroSim::new(&cfg, [0.0; 4]).map_err(|e| anyhow::anyhow!("simulator: {e}"))?;
    let mut th = Theta::table2();
    th.drive[5] = 0.0;
    th.drive[6] = 0.0;
    let u = PlantInputs {
        omega: 1.0,
        s: 1.0,
        ax: 0.0,
        ay: 0.0,
    };
    Ok((sim, th, u))
}

/// `E|Δn|²/E|n|²` of the lock-in output noise of white displacement noise (the simulator's
/// lock-in at the record's settings, gyro at rest): the error's slow part barely moves
/// from sample to sample, its noise part does, by this ratio.
pub fn lockin_noise_diff_ratio(rec: &Record) -> anyhow::Result<f64> {
    let (mut sim, th, u) = noise_sim(rec)?;
    let mut prev: Option<LockinOut> = None;
    let (mut dd, mut nn) = (0.0, 0.0);
    for k in 0..600 {
        sim.advance(&th, &u, &u);
        let o = sim.lockin();
        if k >= 20 {
            let v = |o: &LockinOut| {
                [
                    o.x0_um,
                    o.x_um[0].re,
                    o.x_um[0].im,
                    o.x_um[2].re,
                    o.x_um[2].im,
                    o.y0_um,
                    o.y_um[0].re,
                    o.y_um[0].im,
                    o.y_um[2].re,
                    o.y_um[2].im,
                ]
            };
            if let Some(p) = &prev {
                for (a, b) in v(&o).iter().zip(v(p)) {
                    dd += (a - b).powi(2);
                    nn += a * a;
                }
            }
        }
        prev = Some(o);
    }
    Ok(if nn > 0.0 { dd / nn } else { 1.0 })
}

/// The ten lock-in channels of a sample (DC, 1st, 3rd harmonics of both axes).
fn channels(o: &LockinOut) -> [f64; 10] {
    [
        o.x0_um,
        o.x_um[0].re,
        o.x_um[0].im,
        o.x_um[2].re,
        o.x_um[2].im,
        o.y0_um,
        o.y_um[0].re,
        o.y_um[0].im,
        o.y_um[2].re,
        o.y_um[2].im,
    ]
}

/// Lock-in output noise of white displacement noise at 1 pm/√Hz (the simulator's lock-in
/// at the record's settings, gyro at rest), per channel: the energy of the
/// second sample-to-sample differences per sample, µm².
pub fn lockin_noise_diff_energy(rec: &Record) -> anyhow::Result<[f64; 10]> {
    let h = &rec.header;
    let (mut sim, th, u) = noise_sim(rec)?;
    let mut prev: Option<([f64; 10], [f64; 10])> = None;
    let mut last: Option<[f64; 10]> = None;
    let (mut dd, mut m) = ([0.0; 10], 0usize);
    for k in 0..4000 {
        sim.advance(&th, &u, &u);
        let o = channels(&sim.lockin());
        if k >= 20 {
            if let Some((p2, p1)) = &prev {
                for c in 0..10 {
                    dd[c] += (o[c] - 2.0 * p1[c] + p2[c]).powi(2);
                }
                m += 1;
            }
            if let Some(p1) = last {
                prev = Some((p1, o));
            }
            last = Some(o);
        }
    }
    let l0 = h.l0_um;
    Ok(dd.map(|v| v * l0 * l0 / m.max(1) as f64))
}

/// The record's noise energy against the model's 1 pm/√Hz (ν²): per lock-in channel, the
/// energy of the second sample-to-sample differences of the error between the record and
/// a re-simulation `sim` of it on `span` (the slow, structural error barely moves between
/// samples, its second difference even less; the noise does) over the same for 1 pm/√Hz white displacement noise through
/// the record's lock-in (`e1`, [`lockin_noise_diff_energy`] of the record); the median over
/// the ten channels (a structural error that does move fast lives on a few channels).
/// Samples `keep` marks false (a drive regrowth the re-simulation does not reproduce,
/// the rows' `reproduced`) are left out, as are non-finite ones.
pub fn noise_energy_ratio(
    rec: &Record,
    sim: &[LockinOut],
    span: std::ops::Range<usize>,
    keep: &[bool],
    e1: &[f64; 10],
) -> anyhow::Result<f64> {
    let l0 = rec.header.l0_um;
    let err = |k: usize| -> [f64; 10] {
        let (r, o) = (channels(&rec.rows[k].lockin), channels(&sim[k]));
        std::array::from_fn(|c| r[c] - o[c] * l0)
    };
    let (mut dd, mut m) = ([0.0; 10], 0usize);
    let (mut p2, mut p1): (Option<[f64; 10]>, Option<[f64; 10]>) = (None, None);
    for k in span {
        let e = err(k);
        if keep.get(k).copied().unwrap_or(true) && e.iter().all(|v| v.is_finite()) {
            if let (Some(a), Some(b)) = (p2, p1) {
                for c in 0..10 {
                    dd[c] += (e[c] - 2.0 * b[c] + a[c]).powi(2);
                }
                m += 1;
            }
            (p2, p1) = (p1, Some(e));
        } else {
            (p2, p1) = (None, None);
        }
    }
    anyhow::ensure!(m > 0, "no finite samples to estimate the record's noise");
    let mut r: Vec<f64> = (0..10)
        .map(|c| dd[c] / m as f64 / e1[c].max(1e-300))
        .collect();
    r.sort_by(f64::total_cmp);
    Ok(0.5 * (r[4] + r[5]))
}

/// Output error of re-simulated lock-in outputs `sim` (indexed like the record) against
/// the record on `span`: rms error of the DC, 1st and 3rd harmonic channels relative to
/// the rms of the record's channels of both axes; `diff_ratio` from
/// [`lockin_noise_diff_ratio`].
pub fn output_error(
    rec: &Record,
    sim: &[LockinOut],
    span: std::ops::Range<usize>,
    diff_ratio: f64,
) -> OutputError {
    let l0 = rec.header.l0_um;
    let err = |k: usize| -> [f64; 10] {
        let (r, o) = (&rec.rows[k].lockin, &sim[k]);
        [
            r.x0_um - o.x0_um * l0,
            r.x_um[0].re - o.x_um[0].re * l0,
            r.x_um[0].im - o.x_um[0].im * l0,
            r.x_um[2].re - o.x_um[2].re * l0,
            r.x_um[2].im - o.x_um[2].im * l0,
            r.y0_um - o.y0_um * l0,
            r.y_um[0].re - o.y_um[0].re * l0,
            r.y_um[0].im - o.y_um[0].im * l0,
            r.y_um[2].re - o.y_um[2].re * l0,
            r.y_um[2].im - o.y_um[2].im * l0,
        ]
    };
    let (mut ex, mut ey, mut nn, mut dd) = (0.0, 0.0, 0.0, 0.0);
    let mut prev: Option<[f64; 10]> = None;
    for k in span {
        let e = err(k);
        // a row the reader kept with a non-finite value (or a re-simulation that left
        // one): not counted
        if !e.iter().all(|v| v.is_finite()) {
            prev = None;
            continue;
        }
        ex += e[..5].iter().map(|v| v * v).sum::<f64>();
        ey += e[5..].iter().map(|v| v * v).sum::<f64>();
        if let Some(p) = prev {
            dd += e.iter().zip(p).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        }
        prev = Some(e);
        let r = &rec.rows[k].lockin;
        for v in [r.x_um[0], r.x_um[2], r.y_um[0], r.y_um[2]] {
            nn += v.re * v.re + v.im * v.im;
        }
        nn += r.x0_um * r.x0_um + r.y0_um * r.y0_um;
    }
    let nn = nn.max(1e-300);
    let noise = dd / diff_ratio.max(1e-12);
    OutputError {
        drive: (ex / nn).sqrt(),
        sense: (ey / nn).sqrt(),
        combined: ((ex + ey) / nn).sqrt(),
        above_noise: ((ex + ey - noise).max(0.0) / nn).sqrt(),
    }
}

/// State [X, X', Y, Y'] reconstructed from a record row's harmonics at phase ψ.
fn state_of(r: &paragyro_simulator::record::RecordRow, psi: f64, om: f64, l0: f64) -> [f64; 4] {
    let r = &r.lockin;
    let (mut x, mut xd, mut y, mut yd) = (r.x0_um / l0, 0.0, r.y0_um / l0, 0.0);
    for k in 0..3 {
        let kf = (k + 1) as f64;
        let (s, c) = (kf * psi).sin_cos();
        let (a, b) = (r.x_um[k], r.y_um[k]);
        x += (a.re * c - a.im * s) / l0;
        xd += kf * om * (-a.re * s - a.im * c) / l0;
        y += (b.re * c - b.im * s) / l0;
        yd += kf * om * (-b.re * s - b.im * c) / l0;
    }
    [x, xd, y, yd]
}

impl Resim<'_> {
    /// One chunk `[k0, k1)` of [`Resim::run`].
    fn chunk(&self, psi: &[f64], k0: usize, k1: usize) -> anyhow::Result<Vec<LockinOut>> {
        let Resim {
            rec,
            model,
            gamma,
            rate_ref,
            effects,
            vib_phase0,
            steps_per_period,
        } = *self;
        let f_ref = first_pump_hz(rec);
        let h = &rec.header;
        let omega0 = TAU * h.f0_hz;
        let gpd = gamma_per_dps(omega0);
        let mut fx = Effects::from_specs(effects, gpd).map_err(anyhow::Error::msg)?;
        fx.vib_phase0 = vib_phase0;
        let pump_max = rec
            .rows
            .iter()
            .map(|r| r.pump_hz)
            .filter(|p| p.is_finite())
            .fold(0.0, f64::max);
        let simcfg = SimConfig {
            omega0_rad_s: omega0,
            fs_hz: h.fs_hz,
            steps_per_period,
            omega_max: sim_grid(h, pump_max),
            lpf_order: h.lockin_lpf_order,
            lpf_hz: h.lockin_lpf_hz * (1.0 + fx.lockin_mismatch),
            noise_density: 0.0,
            seed: 1,
        };
        let accel_si = h.l0_um * 1e-6 * omega0 * omega0;
        let input = |k: usize| -> PlantInputs {
            let r = &rec.rows[k];
            let ok = |v: f64, d: f64| if v.is_finite() { v } else { d };
            PlantInputs {
                omega: ok(r.pump_hz, f_ref) / (2.0 * h.f0_hz),
                s: ok((r.pump_amp_v / h.pump_amp_ref_v).powi(2), 1.0),
                ax: ok(r.ax_mps2, 0.0) / accel_si,
                ay: ok(r.ay_mps2, 0.0) / accel_si,
            }
        };
        let mut start = if k0 == 0 {
            0
        } else {
            k0.saturating_sub((RESIM_OVERLAP_S * h.fs_hz) as usize)
        };
        // a chunk starts from the record's state: from a row whose state is finite (a row
        // the reader kept with a non-finite value moves the start earlier)
        while start > 0
            && !state_of(&rec.rows[start], psi[start], input(start).omega, h.l0_um)
                .iter()
                .all(|v| v.is_finite())
        {
            start -= 1;
        }
        let first = &rec.rows[start];
        let z0 = if start == 0 && first.x_abs(1) < 0.05 * h.l0_um {
            [0.01, 0.0, 0.0, 0.0] // from rest: the simulator's start-up convention
        } else {
            state_of(first, psi[start], input(start).omega, h.l0_um)
        };
        // (the first row not finite: from rest)
        let z0 = if z0.iter().all(|v| v.is_finite()) {
            z0
        } else {
            [0.01, 0.0, 0.0, 0.0]
        };
        let h_target = record_step(h, &simcfg)?;
        let mut sim = GyroSim::new(&simcfg, z0).map_err(|e| anyhow::anyhow!("simulator: {e}"))?;
        let h_sim = sim.step_tau();
        sim.set_effects(fx, TAU * (f_ref + fx.vib_beat_hz) / omega0);
        if start > 0 {
            sim.restart_at(start as u64, z0, psi[start]);
        }
        let mut phys = model.phys;
        let mut out = Vec::with_capacity(k1 - k0);
        for k in start..k1 {
            if k >= k0 {
                out.push(sim.lockin());
            }
            if k + 1 == rec.rows.len() {
                break;
            }
            phys.gamma = match (rate_ref, gamma) {
                // θ held over the interval at its midpoint, with the table's angular
                // acceleration γ′ = Ω′/ω0² added to the model's (the simulator's convention
                // for a moving rate, `runner`): a reversal's ramp is then part of the
                // model, not a gap; at a constant rate both are the model's own
                (Some(rr), _) => {
                    let (r0, r1) = (rr[k], rr[k + 1]);
                    phys.gamma_p =
                        model.phys.gamma_p + ((r1 - r0) * h.fs_hz).to_radians() / (omega0 * omega0);
                    gpd * 0.5 * (r0 + r1) + model.gamma_offset
                }
                (None, Some(g)) => g,
                (None, None) => model.phys.gamma,
            };
            let (mut d, mut s) = theta_from_physical(&phys);
            if fx.tcf_ppm_k != 0.0 {
                let tc = rec.rows[k].temp_c.unwrap_or(T_REF_C);
                fx.thermal_theta(&mut d, &mut s, phys.wx2, phys.wy2, tc);
            }
            let (u0, u1) = (input(k), input(k + 1));
            let th = prewarp(
                &Theta { drive: d, sense: s },
                0.5 * (u0.omega + u1.omega),
                h_sim,
                h_target,
            );
            sim.advance(&th, &u0, &u1);
        }
        Ok(out)
    }
}

/// The record with its lock-in channels replaced by `li` (same inputs).
pub(crate) fn with_lockin(rec: &Record, li: &[LockinOut]) -> Record {
    let mut r = rec.clone();
    let l0 = rec.header.l0_um;
    for (row, o) in r.rows.iter_mut().zip(li) {
        let li = &mut row.lockin;
        li.x0_um = o.x0_um * l0;
        li.y0_um = o.y0_um * l0;
        for k in 0..3 {
            li.x_um[k] = Cplx::new(o.x_um[k].re * l0, o.x_um[k].im * l0);
            li.y_um[k] = Cplx::new(o.y_um[k].re * l0, o.y_um[k].im * l0);
        }
    }
    r
}

/// The integrator's `omega_max`: a simulated record's own (its header names it), else the
/// record's largest pump frequency with a 1 % margin.
fn sim_grid(h: &paragyro_simulator::record::RecordHeader, pump_max: f64) -> f64 {
    let w_pump = pump_max / (2.0 * h.f0_hz);
    record_omega_max(h)
        .filter(|w| *w >= w_pump)
        .unwrap_or((w_pump * 1.01).max(0.5))
}

/// The `omega_max` a simulated record's integrator ran at (its header's
/// [`SIM_OMEGA_MAX_KEY`](paragyro_simulator::record::SIM_OMEGA_MAX_KEY)).
fn record_omega_max(h: &paragyro_simulator::record::RecordHeader) -> Option<f64> {
    h.extra_value(paragyro_simulator::record::SIM_OMEGA_MAX_KEY)
        .and_then(|v| v.parse::<f64>().ok())
        .filter(|w| w.is_finite() && *w > 0.0 && *w <= 4.0)
}

/// The RK4 step (τ) whose dispersion the re-simulation reproduces ([`prewarp`]): a
/// simulated record's own (its header names its grid; the same dispersion then cancels),
/// else 0, the exact flow that a device follows.
fn record_step(
    h: &paragyro_simulator::record::RecordHeader,
    sim: &SimConfig,
) -> anyhow::Result<f64> {
    let Some(omega_max) = record_omega_max(h) else {
        return Ok(0.0);
    };
    let steps_per_period = h
        .extra_value(paragyro_simulator::record::SIM_STEPS_PER_PERIOD_KEY)
        .and_then(|v| v.parse::<usize>().ok())
        .filter(|s| (16..=4096).contains(s))
        .unwrap_or(128);
    let cfg = SimConfig {
        omega_max,
        steps_per_period,
        lpf_hz: h.lockin_lpf_hz,
        ..sim.clone()
    };
    let rec_sim = GyroSim::new(&cfg, [0.0; 4]).map_err(|e| anyhow::anyhow!("simulator: {e}"))?;
    Ok(rec_sim.step_tau())
}

#[cfg(test)]
mod tests {
    use super::{LockinOut, on_record_branch};
    use paragyro_core::Cplx;
    use paragyro_simulator::lockin::LockinExt;
    use paragyro_simulator::record::{N_REQUIRED, Record, RecordHeader, RecordRow};

    /// The drive's amplitude: 2 µm, a collapse to 2e-6 µm over samples 1000–1100 (deepest
    /// at 1060), 2 µm again from 1200.
    fn amp(k: usize) -> f64 {
        match k {
            0..1000 | 1200.. => 2.0,
            _ => 2.0 * 10f64.powf(-6.0 * (1.0 - (k as f64 - 1060.0).abs() / 140.0)),
        }
    }

    /// Lock-in outputs whose odd harmonics have the drive's amplitude with `sign(k)`; the
    /// 2nd harmonic and the DC levels are the same on both branches.
    fn outputs(n: usize, sign: impl Fn(usize) -> f64) -> Vec<LockinOut> {
        (0..n)
            .map(|k| {
                let (a, s) = (amp(k), sign(k));
                let mut o = LockinOut::from_channels(&[0.0; 14]);
                o.x0_um = 0.1;
                o.y0_um = -0.1;
                o.x_um = [
                    Cplx::new(s * a, 0.3 * s * a),
                    Cplx::new(0.05, 0.0),
                    Cplx::new(0.01 * s * a, 0.0),
                ];
                o.y_um = [
                    Cplx::new(-0.4 * s * a, 0.5 * s * a),
                    Cplx::new(0.0, 0.02),
                    Cplx::new(0.0, 0.02 * s * a),
                ];
                o
            })
            .collect()
    }

    fn record(lockin: &[LockinOut]) -> Record {
        Record {
            header: RecordHeader {
                f0_hz: 10_800.0,
                l0_um: 1.0,
                fs_hz: 500.0,
                lockin_lpf_order: 4,
                lockin_lpf_hz: 150.0,
                pump_amp_ref_v: 1.0,
                extra: Vec::new(),
            },
            rows: lockin
                .iter()
                .enumerate()
                .map(|(k, o)| {
                    let mut r = RecordRow::from_required(&[0.0; N_REQUIRED], None, None);
                    r.t_s = k as f64 / 500.0;
                    r.lockin = *o;
                    r
                })
                .collect(),
            warnings: Vec::new(),
        }
    }

    #[test]
    fn a_regrowth_on_the_other_branch_is_put_on_the_records() {
        let n = 3000;
        // the record grows back at phase π, the re-simulation at 0
        let rec = record(&outputs(n, |k| if k < 1060 { 1.0 } else { -1.0 }));
        let mut sim = outputs(n, |_| 1.0);
        // one half (`mid` at the end): the start from rest, then the regrowth
        on_record_branch(&rec, &mut sim, 0, n);
        for (k, (o, r)) in sim.iter().zip(&rec.rows).enumerate() {
            assert_eq!(*o, r.lockin, "sample {k}");
        }
    }

    #[test]
    fn the_branch_changes_at_the_collapses_quietest_sample() {
        let n = 3000;
        // the record changed branch at 1030, deep in the collapse but not at its floor:
        // the re-simulation is cut at its own quietest sample (1060), where the two
        // differ by twice 1e-6 of the working amplitude at most
        let rec = record(&outputs(n, |k| if k < 1030 { 1.0 } else { -1.0 }));
        let mut sim = outputs(n, |_| 1.0);
        let before = sim.clone();
        on_record_branch(&rec, &mut sim, 0, n);
        assert_eq!(sim[..1060], before[..1060]);
        let b = before[1060].x_um[0];
        assert_eq!(sim[1060].x_um[0], Cplx::new(-b.re, -b.im));
        assert_eq!(sim[1060].x_um[1], before[1060].x_um[1]);
        assert_eq!(sim[1060].x0_um, before[1060].x0_um);
    }

    #[test]
    fn a_regrowth_on_the_records_branch_and_the_second_half_are_left_alone() {
        let n = 3000;
        let rec = record(&outputs(n, |k| if k < 1060 { 1.0 } else { -1.0 }));
        let mut same = outputs(n, |k| if k < 1060 { 1.0 } else { -1.0 });
        on_record_branch(&rec, &mut same, 0, n);
        assert_eq!(same, outputs(n, |k| if k < 1060 { 1.0 } else { -1.0 }));
        // a second half (from 1500) starts from the record's state: its first stretch is
        // the record's, whatever it holds
        let mut sim = outputs(n, |k| if (1060..1500).contains(&k) { -1.0 } else { 1.0 });
        let before = sim.clone();
        on_record_branch(&rec, &mut sim, 0, 1500);
        assert_eq!(sim, before);
    }
}
