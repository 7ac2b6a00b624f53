//! Stage 2, the columns: each candidate effect adds known columns to the gap `y ≈ C·a`.
//! A force term is projected on the harmonics (N = 32 synthesis of the record's envelopes)
//! and filtered by the rows' own state-variable filter; a parameter-face effect is a fixed
//! combination of the θ columns; a measurement effect is the finite-difference response of
//! the rows to it (one more estimator pass each); the angular vibration is a pair of
//! columns at a scanned beat ([`super::vibration`]). The catch-all adds every quadratic and
//! cubic force monomial of X, X', Y, Y' on both axes.

use std::f64::consts::TAU;

use paragyro_core::rows::{Envelopes, Known, NROWS};
use paragyro_core::svf::{SvfCoeffs, SvfState};
use paragyro_simulator::effects::{ES_C3, Effect, LIBRARY, Signature, T_REF_C};
use paragyro_simulator::record::Record;

use super::rows::{Pass, Rows, Spans, run_pass};
use super::{NR, Options};

/// What a column of the bank is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColumnId {
    /// The rate γ (fitted when the record has no rate table).
    Rate,
    /// θ column j (θ11…θ18, θ21…θ26).
    Theta(usize),
    /// A single-column library effect.
    Effect(Effect),
    /// The angular vibration's in-phase (`false`) or quadrature (`true`) column.
    Vibration(bool),
    /// A catch-all force monomial.
    Monomial,
}

/// A column of the bank: one weighted row vector per sample.
#[derive(Clone)]
pub(crate) struct Column {
    pub id: ColumnId,
    pub v: Vec<[f64; NR]>,
}

pub(crate) const NSYN: usize = 32;

/// The waveforms of one sample on the synthesis grid.
pub(crate) struct Wave {
    pub x: [f64; NSYN],
    pub xd: [f64; NSYN],
    pub y: [f64; NSYN],
    pub yd: [f64; NSYN],
    pub c2: [f64; NSYN],
    pub s2: [f64; NSYN],
    /// Pump scale s.
    pub s: f64,
}

pub(crate) fn synth(e: &Envelopes<f64>, kn: &Known<f64>) -> Wave {
    let om = kn.om;
    let mut w = Wave {
        x: [0.0; NSYN],
        xd: [0.0; NSYN],
        y: [0.0; NSYN],
        yd: [0.0; NSYN],
        c2: [0.0; NSYN],
        s2: [0.0; NSYN],
        s: 1.0 + kn.ds,
    };
    for j in 0..NSYN {
        let ph = TAU * j as f64 / NSYN as f64;
        let (mut x, mut xd, mut y, mut yd) = (e.x0, 0.0, e.y0, 0.0);
        for k in 0..3 {
            let kf = (k + 1) as f64;
            let (s, c) = (kf * ph).sin_cos();
            let (a, b) = (e.a[k], e.b[k]);
            // Re(A e^{ikφ}) and its derivative Re(ikω A e^{ikφ})
            x += a.re * c - a.im * s;
            xd += kf * om * (-a.re * s - a.im * c);
            y += b.re * c - b.im * s;
            yd += kf * om * (-b.re * s - b.im * c);
        }
        w.x[j] = x;
        w.xd[j] = xd;
        w.y[j] = y;
        w.yd[j] = yd;
        let (s2, c2) = (2.0 * ph).sin_cos();
        w.c2[j] = c2;
        w.s2[j] = s2;
    }
    w
}

/// Precomputed projection tables (cos/sin of φ and 3φ).
pub(crate) struct ProjTables {
    c1: [f64; NSYN],
    s1: [f64; NSYN],
    c3: [f64; NSYN],
    s3: [f64; NSYN],
}

impl ProjTables {
    pub(crate) fn new() -> Self {
        let mut t = ProjTables {
            c1: [0.0; NSYN],
            s1: [0.0; NSYN],
            c3: [0.0; NSYN],
            s3: [0.0; NSYN],
        };
        for j in 0..NSYN {
            let ph = TAU * j as f64 / NSYN as f64;
            t.c1[j] = ph.cos();
            t.s1[j] = ph.sin();
            t.c3[j] = (3.0 * ph).cos();
            t.s3[j] = (3.0 * ph).sin();
        }
        t
    }

    /// The DC, 1st and 3rd harmonic (Re, Im) of a waveform on the grid.
    #[inline]
    pub(crate) fn project(&self, f: &[f64; NSYN]) -> [f64; 5] {
        let mut o = [0.0; 5];
        for j in 0..NSYN {
            o[0] += f[j];
            o[1] += f[j] * self.c1[j];
            o[2] -= f[j] * self.s1[j];
            o[3] += f[j] * self.c3[j];
            o[4] -= f[j] * self.s3[j];
        }
        let n = NSYN as f64;
        [
            o[0] / n,
            2.0 * o[1] / n,
            2.0 * o[2] / n,
            2.0 * o[3] / n,
            2.0 * o[4] / n,
        ]
    }
}

/// The rows' F0 filter for one column (5 real filters per axis).
#[derive(Clone)]
pub(crate) struct ColFilter {
    st: [SvfState<f64>; NR],
    started: bool,
    /// The last finite input of each row (held over a non-finite one).
    last: [f64; NR],
}

impl ColFilter {
    pub(crate) fn new() -> Self {
        ColFilter {
            st: [SvfState::at_rest(0.0); NR],
            started: false,
            last: [0.0; NR],
        }
    }

    /// Filters the projections (drive, sense) of one sample; weighted rows out.
    #[inline]
    pub(crate) fn push(
        &mut self,
        c: &SvfCoeffs<f64>,
        u: &[f64; NR],
        w: &([f64; NROWS], [f64; NROWS]),
    ) -> [f64; NR] {
        // a non-finite input (a record row with NaN or ∞, not usable) holds the last
        // finite one: the filter's state is not poisoned for the rest of the record
        let mut u = *u;
        for (v, l) in u.iter_mut().zip(self.last.iter_mut()) {
            if v.is_finite() {
                *l = *v;
            } else {
                *v = *l;
            }
        }
        let u = &u;
        if !self.started {
            for i in 0..NR {
                self.st[i] = SvfState::at_rest(u[i]);
            }
            self.started = true;
        }
        let mut o = [0.0; NR];
        for i in 0..NR {
            let wi = if i < NROWS { w.0[i] } else { w.1[i - NROWS] };
            o[i] = self.st[i].update(c, u[i]).f0 * wi;
        }
        o
    }
}

/// A force term: (drive force, sense force) at one synthesis point.
pub(crate) type ForceFn = dyn Fn(&Wave, usize) -> (f64, f64) + Sync;

/// Filtered columns of several force terms at once.
fn force_columns(pass: &Pass, svf: &SvfCoeffs<f64>, terms: &[(ColumnId, &ForceFn)]) -> Vec<Column> {
    let tb = ProjTables::new();
    let n = pass.y.len();
    let mut filt = vec![ColFilter::new(); terms.len()];
    let mut out: Vec<Column> = terms
        .iter()
        .map(|(id, _)| Column {
            id: *id,
            v: Vec::with_capacity(n),
        })
        .collect();
    let mut fd = [0.0; NSYN];
    let mut fs = [0.0; NSYN];
    for k in 0..n {
        let wv = synth(&pass.env[k], &pass.known[k]);
        for (ti, (_, f)) in terms.iter().enumerate() {
            for j in 0..NSYN {
                let (a, b) = f(&wv, j);
                fd[j] = a;
                fs[j] = b;
            }
            let pd = tb.project(&fd);
            let ps = tb.project(&fs);
            let mut u = [0.0; NR];
            u[..NROWS].copy_from_slice(&pd);
            u[NROWS..].copy_from_slice(&ps);
            out[ti].v.push(filt[ti].push(svf, &u, &pass.w));
        }
    }
    out
}

/// A finite-difference column: `scale · (rows of pass p − rows of the base pass)`.
fn fd_column(id: ColumnId, p: &Pass, base: &Pass, scale: f64) -> Column {
    Column {
        id,
        v: p.y
            .iter()
            .zip(&base.y)
            .map(|(a, b)| {
                let mut v = [0.0; NR];
                for r in 0..NR {
                    v[r] = scale * (a[r] - b[r]);
                }
                v
            })
            .collect(),
    }
}

/// A θ-column combination: the value of row `r` from the θ columns of sample `k`.
type ThetaFn<'a> = &'a dyn Fn(&[[f64; NR]; 14], usize, usize) -> f64;

/// A fixed combination of the θ columns, per row: `f(θ columns of sample k, k, r)`.
fn theta_column(id: ColumnId, base: &Pass, f: ThetaFn<'_>) -> Column {
    Column {
        id,
        v: base
            .theta
            .iter()
            .enumerate()
            .map(|(k, c)| {
                let mut v = [0.0; NR];
                for r in 0..NR {
                    v[r] = f(c, k, r);
                }
                v
            })
            .collect(),
    }
}

/// The column bank: the 14 θ (the baseline: the calibration refined on the fit span), the
/// library's testable effects, the vibration pair, then (after [`Columns::with_catch_all`])
/// the catch-all monomials.
pub(crate) struct Columns {
    pub cols: Vec<Column>,
    /// The baseline columns (the 14 θ).
    pub base_cols: Vec<usize>,
    /// The catch-all: the monomials (on top of the baseline's θ).
    pub ca_idx: Vec<usize>,
    /// Library effects this record cannot test, and why.
    pub untestable: Vec<(Effect, String)>,
    /// The vibration's beat found by the scan, Hz.
    pub beat: f64,
    /// The record's dither lines, Hz ([`super::vibration::dither_lines`]).
    pub dither_hz: Vec<f64>,
}

impl Columns {
    /// The baseline, θ and library columns (the vibration's beat scanned).
    pub(crate) fn build(
        rec: &Record,
        opts: &Options,
        rows: &Rows,
        spans: &Spans,
    ) -> anyhow::Result<Self> {
        // the baseline: the 14 θ (the calibration's refinement; the rate is θ14 − θ24)
        let mut cols: Vec<Column> = (0..14)
            .map(|j| Column {
                id: ColumnId::Theta(j),
                v: rows.base.theta.iter().map(|c| c[j]).collect(),
            })
            .collect();
        let n_base = cols.len();
        // the beat scan's own baseline: the rate alone (a 14-column baseline in each of its
        // ~140 fits would cost 25× more; the gap is already calibrated)
        let scan_base: Vec<Column> = if rows.rate_ref.is_none() {
            vec![Column {
                id: ColumnId::Rate,
                v: rows.gamma_col.clone(),
            }]
        } else {
            Vec::new()
        };
        let mut untestable = Vec::new();
        let mut beat = 0.0;
        // the force terms are synthesised together (one synthesis per sample)
        let mut forces: Vec<(ColumnId, Box<ForceFn>)> = Vec::new();
        for effect in LIBRARY {
            // an effect whose columns cannot be built on this record (an estimator pass
            // or the beat scan failing) is untestable, with why: not an abort
            let plan =
                library_columns(effect, rec, opts, rows, spans, &scan_base).unwrap_or_else(|e| {
                    Plan::Untestable(format!(
                        "its columns could not be built on this record: {e:#}"
                    ))
                });
            match plan {
                Plan::Force(f) => forces.push((ColumnId::Effect(effect), f)),
                Plan::Columns(c) => cols.extend(c),
                Plan::Vibration(b, pair) => {
                    beat = b;
                    cols.extend(pair);
                }
                Plan::Untestable(why) => untestable.push((effect, why)),
            }
        }
        let refs: Vec<(ColumnId, &ForceFn)> =
            forces.iter().map(|(id, f)| (*id, f.as_ref())).collect();
        cols.extend(force_columns(&rows.base, &rows.svf, &refs));
        Ok(Columns {
            cols,
            base_cols: (0..n_base).collect(),
            ca_idx: Vec::new(),
            untestable,
            beat,
            dither_hz: super::vibration::dither_lines(rec),
        })
    }

    /// Adds the catch-all's force monomials, `ca` ([`catch_all_columns`], built beside
    /// [`Columns::build`]).
    pub(crate) fn with_catch_all_columns(mut self, ca: Vec<Column>) -> Self {
        let start = self.cols.len();
        self.cols.extend(ca);
        self.ca_idx.extend(start..self.cols.len());
        self
    }

    /// The bank index of a column.
    pub(crate) fn idx(&self, id: ColumnId) -> Option<usize> {
        self.cols.iter().position(|c| c.id == id)
    }

    /// The columns of a library effect (none if it was not testable).
    pub(crate) fn of(&self, effect: Effect) -> Vec<usize> {
        match effect.signature() {
            Some(Signature::Vibration) => [ColumnId::Vibration(false), ColumnId::Vibration(true)]
                .into_iter()
                .filter_map(|c| self.idx(c))
                .collect(),
            _ => self.idx(ColumnId::Effect(effect)).into_iter().collect(),
        }
    }

    /// The baseline columns followed by `extra`.
    pub(crate) fn with(&self, extra: &[usize]) -> Vec<usize> {
        self.base_cols.iter().chain(extra).copied().collect()
    }
}

/// The columns of one library effect about `rows` (the re-simulation's rows of
/// [`super::confirm`]): none for the vibration (its beat is scanned once, on the
/// calibrated model's rows) and for an effect this record cannot test.
pub(crate) fn effect_columns(
    effect: Effect,
    rec: &Record,
    opts: &Options,
    rows: &Rows,
    spans: &Spans,
) -> anyhow::Result<Vec<Column>> {
    if effect.signature() == Some(Signature::Vibration) {
        return Ok(Vec::new());
    }
    Ok(
        match library_columns(effect, rec, opts, rows, spans, &[])? {
            Plan::Force(f) => force_columns(
                &rows.base,
                &rows.svf,
                &[(ColumnId::Effect(effect), f.as_ref())],
            ),
            Plan::Columns(c) => c,
            Plan::Vibration(..) | Plan::Untestable(_) => Vec::new(),
        },
    )
}

/// How a library effect is tested on this record.
enum Plan {
    /// A force term (synthesised with the others).
    Force(Box<ForceFn>),
    /// Its column(s), ready.
    Columns(Vec<Column>),
    /// The vibration's beat, Hz, and its in-phase and quadrature columns.
    Vibration(f64, [Column; 2]),
    /// Why this record cannot test it.
    Untestable(String),
}

/// How the diagnosis tests each library effect: its columns on this record.
fn library_columns(
    effect: Effect,
    rec: &Record,
    opts: &Options,
    rows: &Rows,
    spans: &Spans,
    base_cols: &[Column],
) -> anyhow::Result<Plan> {
    let id = ColumnId::Effect(effect);
    let theta = |f: ThetaFn<'_>| Plan::Columns(vec![theta_column(id, &rows.base, f)]);
    let (wx2, wy2) = (opts.model.phys.wx2, opts.model.phys.wy2);
    let th1m = rows.th1m;
    Ok(match effect {
        Effect::GeometricNonlinearity => Plan::Force(Box::new(|w: &Wave, j: usize| {
            let (x, xd, yv, yd) = (w.x[j], w.xd[j], w.y[j], w.yd[j]);
            (-yv * (x * yv + 2.0 * xd * yd), yv * xd * xd)
        })),
        Effect::NonlinearDamping => Plan::Force(Box::new(|w: &Wave, j: usize| {
            (-w.x[j] * w.x[j] * w.xd[j], -w.y[j] * w.y[j] * w.yd[j])
        })),
        Effect::ForceLeak => Plan::Force(Box::new(move |w: &Wave, j: usize| {
            let x = w.x[j];
            (0.0, w.s * (1.0 + w.c2[j]) * x * (th1m[5] + th1m[6] * x * x))
        })),
        // −(θ22 column + c3·θ25 column) × s: a softening whose electrodes carry the pump
        // (a fixed one is a tolerance of wy2 and alpha_y: the parameter face)
        Effect::ElectrostaticSoftening => {
            let s: Vec<f64> = rows.base.known.iter().map(|k| 1.0 + k.ds).collect();
            theta(&move |c, k, r| -(c[9][r] + ES_C3 * c[12][r]) * s[k])
        }
        // −(d/2)Y' on the drive (θ14 column), +(d/2)X' on the sense (θ24): moves θ14
        // against θ24, which the calibration fits: the parameter face tests it
        Effect::Anisodamping => Plan::Untestable(match rows.rate_ref {
            Some(_) => "a constant θ14 − θ24 against the rate table: tested on the parameter face (the calibration)".into(),
            None => "identical to a rate offset without a rate table (rate_ref_dps): record on a rate table or with zero-rate segments".into(),
        }),
        Effect::ThermalDrift => match &rows.temps {
            Some(tc)
                if tc.iter().cloned().fold(f64::MIN, f64::max)
                    - tc.iter().cloned().fold(f64::MAX, f64::min)
                    >= 0.5 =>
            {
                theta(&|c, k, r| {
                    let g = -2e-6 * (tc[k] - T_REF_C);
                    g * (wx2 * c[1][r] + wy2 * c[9][r])
                })
            }
            Some(_) => Plan::Untestable(
                "the die temperature moves less than 0.5 K: a temperature step would separate it"
                    .into(),
            ),
            None => Plan::Untestable("no temp_c column: record the die temperature".into()),
        },
        // d rows / dC with Y0 += C·s, Y2 += C·s
        Effect::Feedthrough => {
            let eps = 1e-3;
            let p = run_pass(rec, &rows.cfg, &|_, s| {
                let sc = s.pump_scale;
                s.lockin.y0_um += eps * sc;
                s.lockin.y_um[1].re += eps * sc;
            })?;
            Plan::Columns(vec![fd_column(id, &p, &rows.base, 1.0 / eps)])
        }
        // the rows' response to the replica's cut-off (residual of a device whose lock-in
        // is (1 + δ) × the header's ≈ −δ · ∂y/∂(replica cut-off))
        Effect::LockinMismatch => {
            let eps = 0.01;
            let mut c2 = rows.cfg;
            c2.lockin_lpf_hz *= 1.0 + eps;
            let p = run_pass(rec, &c2, &|_, _| {})?;
            Plan::Columns(vec![fd_column(id, &p, &rows.base, -1.0 / eps)])
        }
        Effect::AngularVibration => {
            let (beat, pair) = super::vibration::scan_beat(rec, rows, spans, base_cols)?;
            Plan::Vibration(beat, pair)
        }
        Effect::QuadraticStiffness | Effect::ReadoutGain => {
            Plan::Untestable("outside the library".into())
        }
    })
}

/// The catch-all's force monomials: quadratic and cubic in (X, X', Y, Y'), on each axis
/// (X³ and Y³ are θ15/θ25 already).
pub(crate) fn catch_all_columns(base: &Pass, svf: &SvfCoeffs<f64>) -> Vec<Column> {
    let var = |w: &Wave, j: usize, i: usize| match i {
        0 => w.x[j],
        1 => w.xd[j],
        2 => w.y[j],
        _ => w.yd[j],
    };
    let on_axis = |m: f64, axis: usize| if axis == 0 { (m, 0.0) } else { (0.0, m) };
    let mut mono: Vec<Box<ForceFn>> = Vec::new();
    for a in 0..4 {
        for b in a..4 {
            for axis in 0..2 {
                mono.push(Box::new(move |w: &Wave, j: usize| {
                    on_axis(var(w, j, a) * var(w, j, b), axis)
                }));
            }
            for c in b..4 {
                if (a, b, c) == (0, 0, 0) || (a, b, c) == (2, 2, 2) {
                    continue;
                }
                for axis in 0..2 {
                    mono.push(Box::new(move |w: &Wave, j: usize| {
                        on_axis(var(w, j, a) * var(w, j, b) * var(w, j, c), axis)
                    }));
                }
            }
        }
    }
    let refs: Vec<(ColumnId, &ForceFn)> = mono
        .iter()
        .map(|f| (ColumnId::Monomial, f.as_ref()))
        .collect();
    force_columns(base, svf, &refs)
}
