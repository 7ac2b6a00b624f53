//! Stage 1, the simulator's rows on the record: the core's estimator runs open-loop on the
//! record with its linearisation point fixed at the model, so every sample gives the ten
//! regression rows as the innovation `y = z − Φ·θ_model`, weighted to unit noise. With the
//! re-simulation, the rows of the simulator re-run on the record's inputs are subtracted
//! (the rows' own approximations cancel). Also the spans: warm-up, fit blocks, guard,
//! held-out.

use std::f64::consts::{PI, TAU};
use std::ops::Range;

use paragyro_core::physics::{gamma_from_rate_dps, theta_from_physical};
use paragyro_core::rows::{Envelopes, Known, NROWS};
use paragyro_core::svf::SvfCoeffs;
use paragyro_core::{Config, Estimator};
use paragyro_simulator::effects::EffectSpec;
use paragyro_simulator::lockin::LockinOut;
use paragyro_simulator::record::{Record, config_for};

use super::resim::{Resim, with_lockin};
use super::{BLOCKS, FIT_FRACTION, GUARD_S, Model, NR, Options, Timing, WARMUP_S};

/// One estimator pass: per sample the weighted innovation rows, the weighted θ columns,
/// the envelopes and the known signals the rows were built from.
pub(crate) struct Pass {
    /// Weighted innovations y (5 drive, 5 sense).
    pub y: Vec<[f64; NR]>,
    /// Weighted θ columns (8 drive, 6 sense), each as 10 rows.
    pub theta: Vec<[[f64; NR]; 14]>,
    pub env: Vec<Envelopes<f64>>,
    pub known: Vec<Known<f64>>,
    /// The rows fed the RLS (valid input, not gated).
    pub usable: Vec<bool>,
    /// Row weights (drive, sense).
    pub w: ([f64; NROWS], [f64; NROWS]),
}

pub(crate) fn model_config(rec: &Record, model: &Model, gamma: f64) -> Config {
    let mut cfg = config_for(rec);
    cfg.nominal = model.phys;
    cfg.nominal.gamma = gamma;
    cfg.nominal.gamma_p = 0.0;
    cfg.rls.relinearize_s = 0.0;
    cfg.retune.enabled = false;
    // no rate-channel gate: it would drop rows, and its hand-over at the end of a gate
    // re-linearises the rows about the RLS estimate (`rows.relinearize`, which
    // `relinearize_s = 0` does not stop), so the rows would no longer be about the model.
    // With `gate_s = 0` the gate never holds and no hand-over is made. On `characterise`
    // the gate fires on the drive's ring-downs at s = 1.15 (|x1| < 1.3 µm, the narrow
    // rate 138–166 °/s for a true 150), 5–7 times in the held-out span.
    cfg.rate.gate_s = 0.0;
    // the rate a constant of the fit, as the model's rows have it (the rate walk only
    // moves the pass's RLS estimate, not its rows)
    cfg.rate.walk_dps = 0.0;
    // every change alarm resets its axis, as in the pass the scored blind runs (up to
    // run 17) measured: an alarm read as a drift re-opens the drift column instead, which
    // moves the pass's measured drift and with it the rows' drift term; that changes
    // verdicts (the bench's slowest record reads `force_leak` instead of `unknown`) and
    // waits for a scored run
    cfg.monitor.change_drift_margin = 0.0;
    cfg
}

/// One pass of the estimator over the record, `edit` changing each sample first.
pub(crate) fn run_pass(
    rec: &Record,
    cfg: &Config,
    edit: &dyn Fn(usize, &mut paragyro_core::Sample<f64>),
) -> anyhow::Result<Pass> {
    let mut est: Estimator<f64> = cfg
        .build()
        .map_err(|e| anyhow::anyhow!("core configuration: {e}"))?;
    let n = rec.rows.len();
    let (w1, w2) = est.row_weights();
    let mut p = Pass {
        y: Vec::with_capacity(n),
        theta: Vec::with_capacity(n),
        env: Vec::with_capacity(n),
        known: Vec::with_capacity(n),
        usable: Vec::with_capacity(n),
        w: (w1, w2),
    };
    let inv_l0 = 1.0 / rec.header.l0_um;
    for (k, r) in rec.rows.iter().enumerate() {
        let mut s = r.to_sample::<f64>(&rec.header);
        edit(k, &mut s);
        let o = est.step(&s);
        let rows = est.last_rows();
        let mut y = [0.0; NR];
        let mut th = [[0.0; NR]; 14];
        for i in 0..NROWS {
            y[i] = rows.drive_y[i] * w1[i];
            y[NROWS + i] = rows.sense_y[i] * w2[i];
            for j in 0..8 {
                th[j][i] = rows.drive_phi[i][j] * w1[i];
            }
            for j in 0..6 {
                th[8 + j][NROWS + i] = rows.sense_phi[i][j] * w2[i];
            }
        }
        let l = &s.lockin;
        let mut e = Envelopes {
            x0: l.x0_um * inv_l0,
            y0: l.y0_um * inv_l0,
            ..Envelopes::default()
        };
        for i in 0..3 {
            e.a[i] = l.x_um[i].scale(inv_l0);
            e.b[i] = l.y_um[i].scale(inv_l0);
        }
        p.y.push(y);
        p.theta.push(th);
        p.env.push(e);
        p.known.push(*est.last_known());
        // a row the reader kept with a non-finite value (NaN, ∞) is never a usable row
        p.usable.push(
            o.updated
                && y.iter().all(|v| v.is_finite())
                && r.required().iter().all(|v| v.is_finite()),
        );
    }
    Ok(p)
}

/// The timing stage of a whole-record re-simulation: the model's, or with effects (the
/// confirmation's).
fn resim_stage(effects: &[EffectSpec]) -> &'static str {
    if effects.is_empty() {
        "resimulate_model"
    } else {
        "resimulate_to_confirm"
    }
}

/// The simulator re-run on the record's inputs with the model of `opts`.
fn resim<'a>(
    rec: &'a Record,
    opts: &'a Options,
    gamma: Option<f64>,
    rate_ref: Option<&'a [f64]>,
    effects: &'a [EffectSpec],
    vib_phase0: f64,
) -> Resim<'a> {
    Resim {
        rec,
        model: &opts.model,
        gamma,
        rate_ref,
        effects,
        vib_phase0,
        steps_per_period: opts.steps_per_period,
    }
}

/// γ per °/s at the record's ω0.
pub(crate) fn gamma_per_dps(omega0: f64) -> f64 {
    gamma_from_rate_dps(1.0, omega0)
}

/// The reference phase ψ (half the pump phase) integrated from the record's pump column
/// (trapezoid over the linear sweep between samples: exact for the simulator's DDS).
pub(crate) fn psi_of(rec: &Record) -> Vec<f64> {
    let mut psi = Vec::with_capacity(rec.rows.len());
    let mut p = 0.0f64;
    let mut prev: Option<(f64, f64)> = None;
    for r in &rec.rows {
        // a non-finite pump frequency (a row the reader kept) holds the last finite one:
        // the phase goes on instead of turning NaN for the rest of the record
        let f = match (r.pump_hz.is_finite(), prev) {
            (true, _) => r.pump_hz,
            (false, Some((_, f0))) => f0,
            (false, None) => first_pump_hz(rec),
        };
        if let Some((t0, f0)) = prev {
            let dt = r.t_s - t0;
            p += PI * 0.5 * (f0 + f) * dt; // ψ' = Ω = π·pump_hz
            p = paragyro_simulator::plant::wrap_phase(p);
        }
        psi.push(p);
        prev = Some((r.t_s, f));
    }
    psi
}

/// The first valid pump frequency of a record (the reference of the vibration's beat), Hz.
pub fn first_pump_hz(rec: &Record) -> f64 {
    rec.rows
        .iter()
        .map(|r| r.pump_hz)
        .find(|p| p.is_finite() && *p > 0.0)
        .unwrap_or(0.0)
}

/// A drive collapse: the drive's 1st harmonic below this share of its working amplitude
/// (the 90th percentile of the record's) in the record or in the re-simulation.
pub const COLLAPSE_SHARE: f64 = 0.01;

/// A collapse ends when both drives are back over this share of the working amplitude
/// (above [`COLLAPSE_SHARE`]: a drive that dips under it and out again with the dither is
/// one collapse).
pub const COLLAPSE_END_SHARE: f64 = 0.1;

/// An excursion the re-simulation does not reproduce: somewhere between a collapse and the
/// next, the record's and the re-simulation's drive 1st harmonic (complex) differ by more
/// than this share of the working amplitude.
pub const REGROWTH_MISMATCH: f64 = 0.2;

/// Excursions are left out only when the re-simulation departs from the record on at most
/// this share of them (a regrowth the model cannot reproduce is an event of the floor; a
/// large effect the model lacks moves most of them, and is the gap to explain).
pub const REGROWTH_MAX_SHARE: f64 = 1.0 / 3.0;

/// The samples the re-simulation reproduces, from the drive's 1st harmonic of the record
/// (`rec`) and of the re-simulation (`sim`), each (in-phase, quadrature) per sample. The
/// drive between two collapses ([`COLLAPSE_SHARE`]) is one excursion; where the two differ
/// somewhere in it by more than [`REGROWTH_MISMATCH`] of the working amplitude, its
/// samples are false from its collapse through the end of the next (or to the record's
/// end), when that is so on at most [`REGROWTH_MAX_SHARE`] of the excursions. Collapses
/// count once the record's drive has first reached half its working amplitude (the start
/// from rest is the model's).
///
/// Out of its parametric band the drive rings down to the floor of what drives it, and
/// how and when it grows back (with one of two phases, 0 or π against the half pump) is
/// set by that floor: in a device its thermomechanical noise, in a simulator the forcing's
/// smallest terms and the integrator's; near the band's edge, where it leaves the band
/// again, the trajectory turns on the parameters' last digits. The model cannot reproduce
/// such an excursion from the record's inputs, and one that grows at another time or with
/// the other sign leaves a gap no effect explains (a clean device of the independent
/// generator: 163× its noise; host-sim/diagnose/docs/notes.md, "Drive excursions the
/// re-simulation does not reproduce"). Every sample is kept when no excursion departs so
/// far.
pub(crate) fn unreproduced_regrowths(rec: &[(f64, f64)], sim: &[(f64, f64)]) -> Vec<bool> {
    let n = rec.len().min(sim.len());
    let mut keep = vec![true; rec.len()];
    let Some((working, collapses)) = collapses(rec, sim) else {
        return keep;
    };
    let apart =
        |k: usize| (rec[k].0 - sim[k].0).hypot(rec[k].1 - sim[k].1) > REGROWTH_MISMATCH * working;
    // each excursion: from a collapse's start to the next one's, then left out through
    // the next one's end (the excursion's tail decays into it)
    let departed: Vec<(usize, usize)> = (0..collapses.len())
        .filter_map(|i| {
            let k0 = collapses[i].0;
            let k1 = collapses.get(i + 1).map_or(n, |c| c.0);
            let end = collapses.get(i + 1).map_or(n, |c| c.1);
            (k0..k1).any(apart).then_some((k0, end))
        })
        .collect();
    // a model that misses more than a few of the excursions misses something else (a
    // large effect moves every one): then its gap is the diagnosis's to explain
    if departed.len() as f64 > REGROWTH_MAX_SHARE * collapses.len() as f64 {
        return keep;
    }
    for (k0, end) in departed {
        keep[k0..end].fill(false);
    }
    keep
}

/// The record's drive working amplitude (the 90th percentile of its |x1|) and its collapses
/// once it has built up (its start from rest is the model's): each from the record's or the
/// re-simulation's drive under [`COLLAPSE_SHARE`] of it until both are over
/// [`COLLAPSE_END_SHARE`] (start, end sample); `None` without a working amplitude. With the
/// record as both, the record's own collapses.
pub(crate) fn collapses(
    rec: &[(f64, f64)],
    sim: &[(f64, f64)],
) -> Option<(f64, Vec<(usize, usize)>)> {
    let n = rec.len().min(sim.len());
    let amp = |v: (f64, f64)| v.0.hypot(v.1);
    let mut a: Vec<f64> = rec[..n]
        .iter()
        .map(|v| amp(*v))
        .filter(|v| v.is_finite())
        .collect();
    if a.is_empty() {
        return None;
    }
    a.sort_by(f64::total_cmp);
    let working = a[(a.len() - 1) * 9 / 10];
    if working <= 0.0 {
        return None;
    }
    let (low, high) = (COLLAPSE_SHARE * working, COLLAPSE_END_SHARE * working);
    let up = (0..n).find(|&k| amp(rec[k]) >= 0.5 * working)?;
    let mut collapses: Vec<(usize, usize)> = Vec::new();
    let mut k = up;
    while k < n {
        if amp(rec[k]) < low || amp(sim[k]) < low {
            let end = (k..n)
                .find(|&j| amp(rec[j]) > high && amp(sim[j]) > high)
                .unwrap_or(n);
            collapses.push((k, end));
            k = end;
        } else {
            k += 1;
        }
    }
    Some((working, collapses))
}

/// A regrowth's window: from this long before the end of a collapse (both drives back over
/// [`COLLAPSE_END_SHARE`]) …, s
pub const REGROWTH_BEFORE_S: f64 = 0.1;
/// … to this long after it, s.
pub const REGROWTH_AFTER_S: f64 = 0.2;
/// The drive's departure from the re-simulation is said to sit at its regrowths when at
/// least this share of its held-out energy lies in the regrowths' windows …
pub const REGROWTH_DEPARTURE_SHARE: f64 = 0.5;
/// … at an energy per sample at least this many times the rest of the held-out span's.
pub const REGROWTH_DENSITY: f64 = 10.0;

/// The samples in a regrowth's window ([`REGROWTH_BEFORE_S`] before to
/// [`REGROWTH_AFTER_S`] after the end of each collapse of the record's or the
/// re-simulation's drive, [`collapses`]); `None` without a working amplitude. A collapse
/// that lasts to the record's end has no regrowth.
pub(crate) fn regrowth_windows(
    rec: &[(f64, f64)],
    sim: &[(f64, f64)],
    fs: f64,
) -> Option<Vec<bool>> {
    let n = rec.len().min(sim.len());
    let (_, collapses) = collapses(rec, sim)?;
    let (before, after) = (
        (REGROWTH_BEFORE_S * fs).round() as usize,
        (REGROWTH_AFTER_S * fs).round() as usize,
    );
    let mut near = vec![false; n];
    for (_, end) in collapses.into_iter().filter(|&(_, end)| end < n) {
        near[end.saturating_sub(before)..(end + after).min(n)].fill(true);
    }
    Some(near)
}

/// Where the drive's departure from the re-simulation sits at its regrowths: the share of
/// the held-out (`hold`) energy of |x1 record − x1 re-simulation| in the regrowths' windows
/// ([`regrowth_windows`]), the share of the span those windows take, and the windows, when
/// the first is at least [`REGROWTH_DEPARTURE_SHARE`] and the windows' energy per sample is
/// at least [`REGROWTH_DENSITY`] times the rest's; `None` otherwise (or when the windows
/// take the whole span). After a deep collapse the trajectory amplifies the parameters'
/// last digits hundreds of times, so a departure there can be the calibrated model's own
/// prediction spread (docs/notes.md, "The model's prediction spread at the drive's
/// regrowths"), not an effect's gap.
pub(crate) fn regrowth_departure(
    rec: &[(f64, f64)],
    sim: &[(f64, f64)],
    hold: Range<usize>,
    fs: f64,
) -> Option<(f64, f64, Vec<bool>)> {
    let n = rec.len().min(sim.len());
    let hold = hold.start.min(n)..hold.end.min(n);
    if hold.is_empty() {
        return None;
    }
    let near = regrowth_windows(rec, sim, fs)?;
    let (mut e_in, mut e_out, mut k_in, mut k_out) = (0.0, 0.0, 0usize, 0usize);
    for k in hold.clone() {
        let e = (rec[k].0 - sim[k].0).powi(2) + (rec[k].1 - sim[k].1).powi(2);
        if !e.is_finite() {
            continue;
        }
        if near[k] {
            e_in += e;
            k_in += 1;
        } else {
            e_out += e;
            k_out += 1;
        }
    }
    if k_in == 0 || k_out == 0 || e_in <= 0.0 {
        return None;
    }
    let share = e_in / (e_in + e_out);
    let dense = e_in / k_in as f64 >= REGROWTH_DENSITY * e_out / k_out as f64;
    (share >= REGROWTH_DEPARTURE_SHARE && dense).then_some((
        share,
        k_in as f64 / (k_in + k_out) as f64,
        near,
    ))
}

/// [`regrowth_departure`] said in a report's limitation.
pub(crate) fn regrowth_departure_note(share: f64, time: f64) -> String {
    format!(
        "{:.0} % of the drive's held-out departure from the re-simulation lies at its regrowths after a collapse ({:.0} % of the span): after a deep collapse the trajectory amplifies the parameters' last digits hundreds of times, so a gap there can be the calibrated model's own prediction spread, not an effect (`cargo run --profile test -p paragyro-diagnose --example spread -- RECORD` measures it)",
        100.0 * share,
        100.0 * time
    )
}

/// The time, share and spans (the first three) of the samples `keep` marks false (times
/// `t`, sample rate `fs`); `None` when none is.
fn false_spans(keep: &[bool], t: &[f64], fs: f64) -> Option<(f64, f64, String)> {
    let n = keep.len().min(t.len());
    let out = keep[..n].iter().filter(|&&k| !k).count();
    if out == 0 {
        return None;
    }
    let mut spans: Vec<String> = Vec::new();
    for k in 0..n {
        if !keep[k] && (k == 0 || keep[k - 1]) {
            let end = (k..n).find(|&j| keep[j]).unwrap_or(n);
            spans.push(format!("{:.2}–{:.2} s", t[k], t[end - 1] + 1.0 / fs));
        }
    }
    let more = match spans.len() {
        0..=3 => String::new(),
        m => format!(" and {} more", m - 3),
    };
    spans.truncate(3);
    Some((
        out as f64 / fs,
        100.0 * out as f64 / n as f64,
        format!("{}{more}", spans.join(", ")),
    ))
}

/// The samples `keep` leaves out (times `t`, sample rate `fs`), said in a report's
/// limitation: their time and share of the record, and their spans (the first three);
/// `None` when none is.
pub(crate) fn left_out_note(keep: &[bool], t: &[f64], fs: f64) -> Option<String> {
    false_spans(keep, t, fs).map(|(secs, pct, spans)| {
        format!(
            "{secs:.2} s of the record ({pct:.1} %) left out of the rows and the noise level: drive excursions after a collapse that the re-simulation does not reproduce ({spans}); the gap is judged on the rest"
        )
    })
}

/// The drive excursions the re-simulation does not reproduce (`excursions` false), kept
/// in the rows, said in a report's limitation; `None` when there is none.
pub(crate) fn excursions_note(excursions: &[bool], t: &[f64], fs: f64) -> Option<String> {
    false_spans(excursions, t, fs).map(|(secs, pct, spans)| {
        format!(
            "the re-simulation does not reproduce the drive's excursions after a collapse over {secs:.2} s of the record ({pct:.1} %: {spans}): a gap there can be the regrowth's, set by the drive's noise floor, not an effect; `--leave-out-excursions` judges the rest"
        )
    })
}

/// The gap in regression form, and what the later stages need of the record.
pub(crate) struct Rows {
    /// Sample times, s.
    pub t: Vec<f64>,
    /// Sample rate, Hz.
    pub fs: f64,
    /// ω0 of the record, rad/s.
    pub omega0: f64,
    /// γ per °/s.
    pub gpd: f64,
    /// The rate table (°/s per sample), when every row has one.
    pub rate_ref: Option<Vec<f64>>,
    /// The die temperature per sample, when every row has a finite one.
    pub temps: Option<Vec<f64>>,
    /// The rate the rows are linearised at (the table's mean, or the model's).
    pub gamma_nom: f64,
    /// The rate the simulator runs with: fitted on the rows (`None` with a rate table).
    pub gamma_sim: Option<f64>,
    /// The core configuration of the rows.
    pub cfg: Config,
    /// The drive θ of the model (the force leak's column needs θ16, θ17).
    pub th1m: [f64; 8],
    /// The rows' state-variable filter.
    pub svf: SvfCoeffs<f64>,
    /// The model's pass (θ columns, envelopes).
    pub base: Pass,
    /// The gap: weighted rows of the record minus the simulator's.
    pub y: Vec<[f64; NR]>,
    /// Samples whose rows count.
    pub usable: Vec<bool>,
    /// Samples the re-simulation reproduces: false in a drive excursion it does not
    /// ([`unreproduced_regrowths`]); every sample without the re-simulation.
    pub excursions: Vec<bool>,
    /// The samples the rows ([`Rows::usable`]) and the record's noise level keep:
    /// [`Rows::excursions`] with [`Options::leave_out_excursions`], every one without.
    pub reproduced: Vec<bool>,
    /// The rate column: dθ14/dγ = 2, dθ24/dγ = −2.
    pub gamma_col: Vec<[f64; NR]>,
    /// The simulator's lock-in outputs on the record's inputs (with the re-simulation).
    pub before_sim: Option<Vec<LockinOut>>,
}

impl Rows {
    /// Pass 0 (the model's rows), the rate, and the re-simulation of the model.
    pub(crate) fn build(rec: &Record, opts: &Options, timing: &mut Timing) -> anyhow::Result<Self> {
        Self::build_with(rec, opts, &[], 0.0, timing)
    }

    /// [`Rows::build`] with `effects` (and the vibration's phase) added to the simulator
    /// re-run: the gap the model with those effects leaves.
    pub(crate) fn build_with(
        rec: &Record,
        opts: &Options,
        effects: &[EffectSpec],
        vib_phase0: f64,
        timing: &mut Timing,
    ) -> anyhow::Result<Self> {
        let n = rec.rows.len();
        anyhow::ensure!(
            n >= 1000,
            "the record has {n} samples; the diagnosis needs at least 2 s"
        );
        let fs = rec.header.fs_hz;
        let t: Vec<f64> = rec.rows.iter().map(|r| r.t_s).collect();
        let omega0 = TAU * rec.header.f0_hz;
        let gpd = gamma_per_dps(omega0);
        // the rate: a rate table fixes it, otherwise it is fitted
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
            Some(v) => gpd * v.iter().sum::<f64>() / v.len() as f64,
            None => opts.model.phys.gamma,
        };
        let cfg = model_config(rec, &opts.model, gamma_nom);
        let (th1m, _) = theta_from_physical(&cfg.nominal);
        let svf = SvfCoeffs::<f64>::new(TAU * cfg.svf_hz / omega0, omega0 / fs);
        // with a rate table the re-simulation takes the table's rate, not one fitted on the
        // record's rows: it runs first, and the record's pass beside the simulator's (the
        // same passes, on both cores)
        let early = if opts.resimulate && rate_ref.is_some() {
            let sim = resim(rec, opts, None, rate_ref.as_deref(), effects, vib_phase0).run(0..n)?;
            timing.tick(resim_stage(effects));
            let sim_rec = with_lockin(rec, &sim);
            let (base, ps) = rayon::join(
                || run_pass(rec, &cfg, &|_, _| {}),
                || run_pass(&sim_rec, &cfg, &|_, _| {}),
            );
            Some((base?, sim, ps?))
        } else {
            None
        };
        let (base, early) = match early {
            Some((base, sim, ps)) => (base, Some((sim, ps))),
            None => (run_pass(rec, &cfg, &|_, _| {})?, None),
        };
        let gamma_col: Vec<[f64; NR]> = base
            .theta
            .iter()
            .map(|c| {
                let mut v = [0.0; NR];
                for r in 0..NR {
                    v[r] = 2.0 * c[3][r] - 2.0 * c[11][r];
                }
                v
            })
            .collect();
        let temps: Option<Vec<f64>> = rec
            .rows
            .iter()
            .map(|r| r.temp_c.filter(|v| v.is_finite()))
            .collect();
        let mut rows = Rows {
            y: base.y.clone(),
            usable: base.usable.clone(),
            excursions: vec![true; n],
            reproduced: vec![true; n],
            gamma_sim: None,
            t,
            fs,
            omega0,
            gpd,
            rate_ref,
            temps,
            gamma_nom,
            cfg,
            th1m,
            svf,
            base,
            gamma_col,
            before_sim: None,
        };
        rows.gamma_sim = rows.rate_ref.is_none().then(|| rows.fitted_rate());
        timing.tick("rows");
        match early {
            Some((sim, ps)) => rows.subtract_simulated(sim, &ps, opts.leave_out_excursions),
            None => rows.subtract_simulator(rec, opts, effects, vib_phase0, timing)?,
        }
        Ok(rows)
    }

    /// What [`Rows::reproduced`] left out, or the excursions the re-simulation does not
    /// reproduce when nothing was, said in a report's limitation ([`left_out_note`]).
    pub(crate) fn regrowth_note(&self) -> Option<String> {
        left_out_note(&self.reproduced, &self.t, self.fs)
            .or_else(|| excursions_note(&self.excursions, &self.t, self.fs))
    }

    /// The 14 weighted θ columns of the model's pass, each as one column (per sample, 10
    /// rows) for [`super::lsq::Bank`].
    pub(crate) fn theta_columns(&self) -> Vec<Vec<[f64; NR]>> {
        (0..14)
            .map(|j| self.base.theta.iter().map(|c| c[j]).collect())
            .collect()
    }

    /// Removes `Δθ` (the calibration's refinement) from the gap: `y −= Φ·Δθ`.
    pub(crate) fn remove_theta(&mut self, dtheta: &[f64; 14]) {
        for (y, th) in self.y.iter_mut().zip(&self.base.theta) {
            for (j, d) in dtheta.iter().enumerate() {
                for r in 0..NR {
                    y[r] -= d * th[j][r];
                }
            }
        }
    }

    /// The rate fitted on the rows after the warm-up (least squares on the rate column).
    fn fitted_rate(&self) -> f64 {
        let n = self.t.len();
        let warm = (0..n)
            .find(|&k| self.t[k] >= self.t[0] + WARMUP_S)
            .unwrap_or(n);
        let (mut gg, mut gy) = (0.0, 0.0);
        for k in warm..n {
            if self.usable[k] {
                for r in 0..NR {
                    gg += self.gamma_col[k][r] * self.gamma_col[k][r];
                    gy += self.gamma_col[k][r] * self.y[k][r];
                }
            }
        }
        self.gamma_nom + if gg > 0.0 { gy / gg } else { 0.0 }
    }

    /// Subtracts the simulator's rows (its pass `ps` on its lock-in outputs `sim`).
    fn subtract_simulated(&mut self, sim: Vec<LockinOut>, ps: &Pass, leave_out: bool) {
        let drive = |p: &Pass| -> Vec<(f64, f64)> {
            p.env.iter().map(|e| (e.a[0].re, e.a[0].im)).collect()
        };
        self.excursions = unreproduced_regrowths(&drive(&self.base), &drive(ps));
        if leave_out {
            self.reproduced = self.excursions.clone();
        }
        for (k, y) in self.y.iter_mut().enumerate() {
            for r in 0..NR {
                y[r] -= ps.y[k][r];
            }
            self.usable[k] &= ps.usable[k] && self.reproduced[k];
        }
        self.before_sim = Some(sim);
    }

    /// The gap is the record's rows minus the simulator's rows on the same inputs: the
    /// rows' own approximations (lock-in products, truncated harmonics) cancel. Without
    /// the re-simulation, a known rate's column times (γ_ref(t) − γ_nom) is subtracted.
    fn subtract_simulator(
        &mut self,
        rec: &Record,
        opts: &Options,
        effects: &[EffectSpec],
        vib_phase0: f64,
        timing: &mut Timing,
    ) -> anyhow::Result<()> {
        let n = self.t.len();
        if opts.resimulate {
            let resim = resim(
                rec,
                opts,
                self.gamma_sim,
                self.rate_ref.as_deref(),
                effects,
                vib_phase0,
            );
            let sim = resim.run(0..n)?;
            let ps = run_pass(&with_lockin(rec, &sim), &self.cfg, &|_, _| {})?;
            self.subtract_simulated(sim, &ps, opts.leave_out_excursions);
            timing.tick(resim_stage(effects));
        } else if let Some(rr) = &self.rate_ref {
            for k in 0..n {
                let dg = self.gpd * rr[k] - self.gamma_nom;
                for r in 0..NR {
                    self.y[k][r] -= dg * self.gamma_col[k][r];
                }
            }
        }
        Ok(())
    }
}

/// The spans: first usable sample after the warm-up, the fit blocks, the guard, the
/// held-out span.
pub(crate) struct Spans {
    /// First usable sample after the warm-up.
    pub first: usize,
    /// Last usable sample.
    pub last: usize,
    /// End of the fit span (first sample at or after it).
    pub fit_end: usize,
    /// First held-out sample.
    pub hold_start: usize,
    /// Contiguous blocks of the fit span (cluster-robust covariance).
    pub fit_blocks: Vec<Range<usize>>,
    /// The held-out samples.
    pub hold: Range<usize>,
}

impl Spans {
    pub(crate) fn of(rows: &Rows) -> anyhow::Result<Self> {
        let (t, usable) = (&rows.t, &rows.usable);
        let n = t.len();
        let first = (0..n)
            .find(|&k| usable[k] && t[k] >= t[0] + WARMUP_S)
            .unwrap_or(n);
        let last = (0..n).rev().find(|&k| usable[k]).unwrap_or(0);
        anyhow::ensure!(
            last > first + 500,
            "fewer than 1 s of usable samples after the {WARMUP_S} s warm-up"
        );
        let span = t[last] - t[first];
        let t_fit_end = t[first] + FIT_FRACTION * span;
        let fit_end = (first..=last).find(|&k| t[k] >= t_fit_end).unwrap_or(last);
        let hold_start = (fit_end..=last)
            .find(|&k| t[k] >= t_fit_end + GUARD_S)
            .unwrap_or(last);
        let fit_blocks = (0..BLOCKS)
            .map(|b| {
                let a = first + (fit_end - first) * b / BLOCKS;
                let e = first + (fit_end - first) * (b + 1) / BLOCKS;
                a..e
            })
            .collect();
        Ok(Spans {
            first,
            last,
            fit_end,
            hold_start,
            fit_blocks,
            hold: hold_start..last + 1,
        })
    }
}

#[cfg(test)]
mod tests {
    use std::ops::Range;

    use super::{
        excursions_note, left_out_note, regrowth_departure, regrowth_departure_note,
        unreproduced_regrowths,
    };

    /// A drive of amplitude 2 (phase 0) that collapses to 1e-6 of it over `troughs`
    /// (sample ranges) and regrows; `burst` adds, at those samples, a burst of amplitude
    /// 1.5 that the other trace does not have.
    fn drive(
        n: usize,
        troughs: &[(usize, usize)],
        burst: Option<(usize, usize)>,
    ) -> Vec<(f64, f64)> {
        (0..n)
            .map(|k| {
                let mut a = if k < 50 { 0.0 } else { 2.0 };
                if troughs.iter().any(|&(a0, a1)| (a0..a1).contains(&k)) {
                    a = 2e-6;
                }
                if burst.is_some_and(|(b0, b1)| (b0..b1).contains(&k)) {
                    a = 1.5;
                }
                (a, 0.0)
            })
            .collect()
    }

    /// `sim` with its drive times `factor` over `samples`: the record of a model that
    /// misses it there.
    fn scaled(sim: &[(f64, f64)], samples: Range<usize>, factor: f64) -> Vec<(f64, f64)> {
        let mut rec = sim.to_vec();
        for v in &mut rec[samples] {
            v.0 *= factor;
        }
        rec
    }

    /// `keep` false over `out` and true everywhere else.
    fn left_out_exactly(keep: &[bool], out: Range<usize>) -> bool {
        keep.iter()
            .enumerate()
            .all(|(k, &kept)| kept != out.contains(&k))
    }

    #[test]
    fn a_regrowth_the_model_reproduces_keeps_every_sample() {
        let rec = drive(2000, &[(400, 600), (1200, 1300)], None);
        assert!(unreproduced_regrowths(&rec, &rec).iter().all(|&k| k));
        // the start from rest is the model's: a mismatch before the drive first builds up
        // is not a regrowth
        let mut sim = rec.clone();
        sim[10] = (1.9, 0.0);
        assert!(unreproduced_regrowths(&rec, &sim).iter().all(|&k| k));
    }

    #[test]
    fn a_burst_at_another_time_drops_its_excursion_through_the_next_collapse() {
        let troughs = [(400, 600), (900, 1000), (1400, 1500)];
        // the record's second trough holds a burst the re-simulation does not have
        let rec = drive(2000, &troughs, Some((940, 960)));
        let sim = drive(2000, &troughs, None);
        let keep = unreproduced_regrowths(&rec, &sim);
        // from the collapse the burst comes in (900) through the next one's end (1500)
        assert!(left_out_exactly(&keep, 900..1500));
    }

    #[test]
    fn a_regrowth_with_the_other_sign_drops_its_excursion() {
        // after the first trough the drive grows back at phase π in the record, 0 in the
        // model: the same amplitude, the opposite sign, until the next collapse
        let troughs = [(400, 600), (1000, 1100), (1500, 1600)];
        let sim = drive(2000, &troughs, None);
        let rec = scaled(&sim, 600..1000, -1.0);
        let keep = unreproduced_regrowths(&rec, &sim);
        assert!(left_out_exactly(&keep, 400..1100));
    }

    #[test]
    fn a_model_that_misses_most_excursions_keeps_every_sample() {
        // the record's drive 25 % low after every collapse (a large effect the model
        // lacks): its gap is the diagnosis's to explain, nothing is left out
        let troughs = [(400, 600), (1000, 1100), (1500, 1600)];
        let sim = drive(2000, &troughs, None);
        let rec = scaled(&sim, 600..2000, 0.75);
        assert!(unreproduced_regrowths(&rec, &sim).iter().all(|&k| k));
    }

    #[test]
    fn a_few_percent_of_amplitude_after_a_regrowth_is_kept() {
        // a difference of 3 % of the drive is a gap to explain, not an excursion the
        // model misses
        let sim = drive(2000, &[(400, 600)], None);
        let rec = scaled(&sim, 0..2000, 1.03);
        assert!(unreproduced_regrowths(&rec, &sim).iter().all(|&k| k));
    }

    #[test]
    fn what_is_left_out_is_said_with_its_time_share_and_spans() {
        let t: Vec<f64> = (0..1000).map(|k| k as f64 / 500.0).collect();
        assert_eq!(left_out_note(&[true; 1000], &t, 500.0), None);
        let mut keep = vec![true; 1000];
        for r in [100..200, 300..310, 400..450, 500..505, 990..1000] {
            keep[r].fill(false);
        }
        let note = left_out_note(&keep, &t, 500.0).unwrap();
        assert!(
            note.starts_with("0.35 s of the record (17.5 %) left out")
                && note.contains("(0.20–0.40 s, 0.60–0.62 s, 0.80–0.90 s and 2 more)"),
            "{note}"
        );
        let kept = excursions_note(&keep, &t, 500.0).unwrap();
        assert!(
            kept.contains("over 0.35 s of the record (17.5 %: 0.20–0.40 s,")
                && kept.contains("`--leave-out-excursions`"),
            "{kept}"
        );
        assert_eq!(excursions_note(&[true; 1000], &t, 500.0), None);
    }

    /// `sim` with a departure of `size` added to its drive's in-phase part over `samples`
    /// and a small one (1e-4) everywhere: the record of a model that departs there.
    fn departing(sim: &[(f64, f64)], samples: Range<usize>, size: f64) -> Vec<(f64, f64)> {
        let mut rec = sim.to_vec();
        for (k, v) in rec.iter_mut().enumerate() {
            v.0 += if samples.contains(&k) { size } else { 1e-4 };
        }
        rec
    }

    #[test]
    fn a_departure_at_a_regrowth_is_said_to_lie_there() {
        // collapses at 2000 and 3500 (500 Hz), the held-out span 1500..5000; the model
        // departs by 0.1 for 40 ms just after the second collapse (2 % of the working
        // amplitude: not an excursion)
        let sim = drive(5000, &[(2000, 2010), (3500, 3510)], None);
        let rec = departing(&sim, 3510..3530, 0.1);
        assert!(unreproduced_regrowths(&rec, &sim).iter().all(|&k| k));
        let (share, time, _) = regrowth_departure(&rec, &sim, 1500..5000, 500.0).unwrap();
        assert!(share > 0.9, "share {share}");
        // two windows of 0.3 s in the 7 s span
        assert!((time - 300.0 / 3500.0).abs() < 0.01, "time {time}");
        let note = regrowth_departure_note(share, time);
        assert!(note.contains("prediction spread"), "{note}");
    }

    #[test]
    fn a_departure_away_from_the_regrowths_or_without_a_collapse_is_not() {
        // the same departure 1.5 s after the regrowth, then spread over the span,
        // then on a drive that never collapses
        let sim = drive(5000, &[(2000, 2010), (3500, 3510)], None);
        let late = departing(&sim, 4300..4320, 0.1);
        assert_eq!(regrowth_departure(&late, &sim, 1500..5000, 500.0), None);
        let even: Vec<(f64, f64)> = sim.iter().map(|v| (v.0 + 1e-3, v.1)).collect();
        assert_eq!(regrowth_departure(&even, &sim, 1500..5000, 500.0), None);
        let steady = drive(5000, &[], None);
        let rec = departing(&steady, 3510..3530, 0.1);
        assert_eq!(regrowth_departure(&rec, &steady, 1500..5000, 500.0), None);
        // an empty or out-of-range held-out span
        assert_eq!(regrowth_departure(&late, &sim, 6000..7000, 500.0), None);
    }
}
