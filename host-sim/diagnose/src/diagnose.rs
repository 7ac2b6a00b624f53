//! The sim-to-real diagnosis (`paragyro-sim diagnose`): where the gap between a record
//! and the simulator lies, which effect of [`paragyro_simulator::effects`] causes it, and how far it
//! shrinks once that effect is added (docs/diagnosis.md).
//!
//! # Method
//!
//! 1. **The simulator's rows on the record.** The core's estimator runs open-loop on the
//!    record with its linearisation point fixed at the simulator's configuration (the
//!    model: Table 2 by default) and never re-linearised, so every sample gives the ten
//!    regression rows (DC, 1st and 3rd harmonic Re/Im, drive and sense) as the innovation
//!    `y = z − Φ·θ_model`, weighted to unit noise. A record of the model itself gives
//!    `y` = noise (plus the small lock-in product approximation); a device that does more
//!    leaves a structured `y`: the gap, in regression form.
//! 2. **Columns.** Each candidate effect adds known columns to `y ≈ C·a`: a force term
//!    is projected on the harmonics (N = 32 synthesis of the record's envelopes) and
//!    filtered by the rows' own state-variable filter; a parameter-face effect is a fixed
//!    combination of the θ columns (electrostatic softening: θ22 and θ25 together;
//!    anisodamping: θ14 and θ24 against each other; thermal drift: θ12 and θ22 times the
//!    record's ΔT); a measurement effect (feedthrough, lock-in mismatch) is the
//!    finite-difference response of the rows to it (one more estimator pass each). The
//!    rate γ is always fitted (the measurand), unless the record has a rate table
//!    (`rate_ref_dps`), which then fixes it.
//! 3. **Held-out scoring.** Every fit uses the first 60 % of the usable record; the gap is
//!    measured on the last part after a guard gap (0.5 s, many correlation times of the
//!    rows). The size uncertainty is cluster-robust (contiguous 16 blocks of the fit
//!    span), so the rows' correlation is accounted for.
//! 4. **Verdict.** A catch-all model (all 14 θ free plus every quadratic and cubic force
//!    monomial of X, X', Y, Y' on both axes) and all library columns together measure how
//!    much of the gap is explainable at all ("floor"). `none`: nothing closes at least
//!    [`GAP_MIN`] of the held-out baseline energy. An effect: it is significant
//!    (|size|/σ ≥ [`T_SIG`]) and closes at least [`SHARE_MIN`] of what the floor closes.
//!    `unknown`: a gap exists but no library effect explains it. The thresholds are
//!    constants, fixed before the blind benchmark ran.
//! 5. **How far.** Gap closure on held-out rows `GC = (E0 − E_c)/(E0 − E_floor)`, and the
//!    output error of the simulator re-run on the record's own inputs (pump frequency and
//!    amplitude, accelerations, temperature) without and with the effect at its fitted size.

use std::f64::consts::{PI, TAU};
use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use paragyro_core::physics::{gamma_from_rate_dps, rate_dps_from_gamma, theta_from_physical};
use paragyro_core::rows::{Envelopes, Known, NROWS};
use paragyro_core::svf::{SvfCoeffs, SvfState};
use paragyro_core::{Config, Estimator, Physical};
use serde_json::{Value, json};

use paragyro_simulator::effects::{ES_C3, EffectSpec, Effects, LIBRARY, T_REF_C};
use paragyro_simulator::lockin::LockinOut;
use paragyro_simulator::plant::{GyroSim, PlantInputs, SimConfig, Theta};
use paragyro_simulator::record::{Record, config_for};

/// Rows per sample (5 drive, then 5 sense).
pub const NR: usize = 2 * NROWS;
/// Names of the rows.
pub const ROW_LABELS: [&str; NR] = [
    "drive/DC",
    "drive/1st in-phase",
    "drive/1st quadrature",
    "drive/3rd in-phase",
    "drive/3rd quadrature",
    "sense/DC",
    "sense/1st in-phase",
    "sense/1st quadrature",
    "sense/3rd in-phase",
    "sense/3rd quadrature",
];

/// Significance: |size| / σ(size) (cluster-robust) at least this.
pub const T_SIG: f64 = 5.0;
/// A gap exists when the best model closes at least this fraction of the held-out
/// baseline energy.
pub const GAP_MIN: f64 = 0.05;
/// An effect is the verdict when it closes at least this share of what the floor closes.
pub const SHARE_MIN: f64 = 0.6;
/// Held-out energy per weighted row of a record of the model itself (noise plus the rows'
/// residual approximations), measured on development records (seed 1 of `blind`: 1.01–1.12,
/// mean 1.08).
pub const NOISE_ROW_ENERGY: f64 = 1.08;
/// The verdict's effect(s) may leave at most this share of the held-out gap above the noise
/// unexplained; otherwise the answer is `unknown` (something else is there too).
pub const UNEXPLAINED_MAX: f64 = 0.05;
/// Per-row residual check: a row holding at least this share of the held-out gap …
pub const ROW_GAP_SHARE: f64 = 0.02;
/// … and at least this much gap energy per sample (noise ≈ 1) …
pub const ROW_GAP_MIN: f64 = 0.05;
/// … must not be left more than this fraction unexplained by the verdict.
pub const ROW_UNEXPLAINED_MAX: f64 = 0.5;
/// A second effect is reported when it adds at least this share of the explainable gap.
pub const SECOND_MIN: f64 = 0.15;
/// Candidates whose columns correlate at least this much (after the rate is projected
/// out) cannot be told apart by this record.
pub const COHERENT: f64 = 0.95;
/// Fraction of the usable span used for fitting.
pub const FIT_FRACTION: f64 = 0.6;
/// Guard gap between the fit and held-out spans, s.
pub const GUARD_S: f64 = 0.5;
/// Samples skipped at the start (filters and the drive's start-up), s.
pub const WARMUP_S: f64 = 0.5;
/// Contiguous blocks of the fit span for the cluster-robust covariance.
pub const BLOCKS: usize = 16;
/// Angular vibration beat search range (|beat| ≤), Hz, and its coarse step.
pub const VIB_BEAT_MAX_HZ: f64 = 6.0;
const VIB_BEAT_STEP_HZ: f64 = 0.1;

/// The simulator configuration the record is compared with.
#[derive(Clone, Debug)]
pub struct Model {
    /// Physical parameters (γ is the rate, used when the record has no rate table).
    pub phys: Physical,
    /// Where it came from (for the report).
    pub source: String,
}

impl Model {
    /// Seed 000's Table 2 (the simulator's default configuration).
    pub fn table2() -> Self {
        Model {
            phys: paragyro_core::physics::TABLE2,
            source: "Table 2 (default)".into(),
        }
    }

    /// The plant of a scenario at t = 0.
    pub fn from_scenario(sc: &paragyro_simulator::scenario::Scenario) -> Self {
        let p = sc.plant_at(0.0).phys;
        let mut phys = paragyro_core::physics::TABLE2;
        phys.mu_x = p[0];
        phys.mu_y = p[1];
        phys.mu_xy = p[2];
        phys.wx2 = p[3];
        phys.wy2 = p[4];
        phys.wxy2 = p[5];
        phys.alpha_x = p[6];
        phys.alpha_y = p[7];
        phys.beta1 = p[8];
        phys.beta3 = p[9];
        phys.gamma = p[10];
        phys.gamma_p = p[11];
        Model {
            phys,
            source: format!("scenario '{}' ({})", sc.name, sc.source),
        }
    }
}

/// Options of a diagnosis.
#[derive(Clone, Debug)]
pub struct Options {
    /// The simulator configuration.
    pub model: Model,
    /// Re-run the simulator on the record's inputs (output error before/after).
    pub resimulate: bool,
    /// RK4 steps per carrier period of the re-run.
    pub steps_per_period: usize,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            model: Model::table2(),
            resimulate: true,
            steps_per_period: 128,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Rows of the record about the model
// ---------------------------------------------------------------------------------------------

/// One estimator pass: per sample the weighted innovation rows, the weighted θ columns,
/// the envelopes and the known signals the rows were built from.
struct Pass {
    /// Weighted innovations y (5 drive, 5 sense).
    y: Vec<[f64; NR]>,
    /// Weighted θ columns (8 drive, 6 sense), each as 10 rows.
    theta: Vec<[[f64; NR]; 14]>,
    env: Vec<Envelopes<f64>>,
    known: Vec<Known<f64>>,
    /// The rows fed the RLS (valid input, not gated).
    usable: Vec<bool>,
    /// Row weights (drive, sense).
    w: ([f64; NROWS], [f64; NROWS]),
}

fn model_config(rec: &Record, model: &Model, gamma: f64) -> Config {
    let mut cfg = config_for(rec);
    cfg.nominal = model.phys;
    cfg.nominal.gamma = gamma;
    cfg.nominal.gamma_p = 0.0;
    cfg.rls.relinearize_s = 0.0;
    cfg.retune.enabled = false;
    cfg
}

fn run_pass(
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
        p.usable.push(o.updated && y.iter().all(|v| v.is_finite()));
    }
    Ok(p)
}

// ---------------------------------------------------------------------------------------------
// Force-term columns: N = 32 synthesis, projection on k = 0, 1, 3, the rows' SVF
// ---------------------------------------------------------------------------------------------

const NSYN: usize = 32;

/// The waveforms of one sample on the synthesis grid.
struct Wave {
    x: [f64; NSYN],
    xd: [f64; NSYN],
    y: [f64; NSYN],
    yd: [f64; NSYN],
    c2: [f64; NSYN],
    s2: [f64; NSYN],
    /// Pump scale s.
    s: f64,
}

fn synth(e: &Envelopes<f64>, kn: &Known<f64>) -> Wave {
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
struct ProjTables {
    c1: [f64; NSYN],
    s1: [f64; NSYN],
    c3: [f64; NSYN],
    s3: [f64; NSYN],
}

impl ProjTables {
    fn new() -> Self {
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
    #[inline]
    fn project(&self, f: &[f64; NSYN]) -> [f64; 5] {
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
struct ColFilter {
    st: [SvfState<f64>; NR],
    started: bool,
}

impl ColFilter {
    fn new() -> Self {
        ColFilter {
            st: [SvfState::at_rest(0.0); NR],
            started: false,
        }
    }
    /// Filters the projections (drive, sense) of one sample; weighted rows out.
    #[inline]
    fn push(
        &mut self,
        c: &SvfCoeffs<f64>,
        u: &[f64; NR],
        w: &([f64; NROWS], [f64; NROWS]),
    ) -> [f64; NR] {
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

/// A named column bank entry.
#[derive(Clone)]
struct Column {
    name: String,
    v: Vec<[f64; NR]>,
}

/// A force term: (drive force, sense force) at one synthesis point.
type ForceFn = dyn Fn(&Wave, usize) -> (f64, f64) + Sync;

/// Filtered columns of several force terms at once.
fn force_columns(pass: &Pass, svf: &SvfCoeffs<f64>, terms: &[(&str, &ForceFn)]) -> Vec<Column> {
    let tb = ProjTables::new();
    let n = pass.y.len();
    let mut filt = vec![ColFilter::new(); terms.len()];
    let mut out: Vec<Column> = terms
        .iter()
        .map(|(name, _)| Column {
            name: (*name).to_string(),
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

/// Per-sample projections for the angular-vibration columns, independent of the beat:
/// with θ = 2φ + β, a term sinθ·a + cosθ·b = cosβ·[sin2φ·a + cos2φ·b] + sinβ·[cos2φ·a −
/// sin2φ·b], so each column is `cosβ·U + sinβ·V` with U, V projected once.
struct VibBasis {
    /// (U, V) of the in-phase column (γ = sinθ, γ' = Ω cosθ), drive then sense rows.
    re: Vec<([f64; NR], [f64; NR])>,
    /// (U, V) of the quadrature column (γ = cosθ, γ' = −Ω sinθ).
    im: Vec<([f64; NR], [f64; NR])>,
}

fn vib_basis(pass: &Pass, ov: f64) -> VibBasis {
    let tb = ProjTables::new();
    let n = pass.y.len();
    let mut b = VibBasis {
        re: Vec::with_capacity(n),
        im: Vec::with_capacity(n),
    };
    let mut f = [[0.0; NSYN]; 8];
    for k in 0..n {
        let wv = synth(&pass.env[k], &pass.known[k]);
        for j in 0..NSYN {
            let (s2, c2) = (wv.s2[j], wv.c2[j]);
            // drive a, b and sense a, b for the in-phase (r) and quadrature (i) columns
            let (ad_r, bd_r) = (2.0 * wv.yd[j], ov * wv.y[j]);
            let (as_r, bs_r) = (-2.0 * wv.xd[j], -ov * wv.x[j]);
            let (ad_i, bd_i) = (-ov * wv.y[j], 2.0 * wv.yd[j]);
            let (as_i, bs_i) = (ov * wv.x[j], -2.0 * wv.xd[j]);
            let uv = |a: f64, bb: f64| (s2 * a + c2 * bb, c2 * a - s2 * bb);
            (f[0][j], f[1][j]) = uv(ad_r, bd_r);
            (f[2][j], f[3][j]) = uv(as_r, bs_r);
            (f[4][j], f[5][j]) = uv(ad_i, bd_i);
            (f[6][j], f[7][j]) = uv(as_i, bs_i);
        }
        let p: Vec<[f64; 5]> = f.iter().map(|w| tb.project(w)).collect();
        let cat = |d: &[f64; 5], s: &[f64; 5]| {
            let mut u = [0.0; NR];
            u[..NROWS].copy_from_slice(d);
            u[NROWS..].copy_from_slice(s);
            u
        };
        b.re.push((cat(&p[0], &p[2]), cat(&p[1], &p[3])));
        b.im.push((cat(&p[4], &p[6]), cat(&p[5], &p[7])));
    }
    b
}

/// The angular-vibration columns (in-phase and quadrature of γ1) for a vibration at
/// `f_v` Hz: γ = gr·sin(θ) + gi·cos(θ), θ = Ω_v t + φ, in the frame of the record's ψ.
fn vibration_columns(
    pass: &Pass,
    basis: &VibBasis,
    svf: &SvfCoeffs<f64>,
    psi: &[f64],
    t: &[f64],
    f_v: f64,
) -> [Column; 2] {
    let n = pass.y.len();
    let mut fr = ColFilter::new();
    let mut fi = ColFilter::new();
    let mut cr = Vec::with_capacity(n);
    let mut ci = Vec::with_capacity(n);
    for k in 0..n {
        // β = Ω_v t − 2ψ
        let beta = TAU * f_v * t[k] - 2.0 * psi[k];
        let (sb, cb) = beta.sin_cos();
        let mix = |p: &([f64; NR], [f64; NR])| {
            let mut u = [0.0; NR];
            for i in 0..NR {
                u[i] = cb * p.0[i] + sb * p.1[i];
            }
            u
        };
        cr.push(fr.push(svf, &mix(&basis.re[k]), &pass.w));
        ci.push(fi.push(svf, &mix(&basis.im[k]), &pass.w));
    }
    [
        Column {
            name: "angular_vibration:re".into(),
            v: cr,
        },
        Column {
            name: "angular_vibration:im".into(),
            v: ci,
        },
    ]
}

// ---------------------------------------------------------------------------------------------
// Least squares on a column bank
// ---------------------------------------------------------------------------------------------

/// Gram sums of a column bank over a set of samples: `G = Σ CᵀC`, `b = Σ Cᵀy`, `yy`.
#[derive(Clone, Debug)]
struct Gram {
    g: Vec<f64>,
    b: Vec<f64>,
    yy: f64,
    rows: usize,
    m: usize,
}

impl Gram {
    fn new(m: usize) -> Self {
        Gram {
            g: vec![0.0; m * m],
            b: vec![0.0; m],
            yy: 0.0,
            rows: 0,
            m,
        }
    }
    fn add(&mut self, o: &Gram) {
        for (a, b) in self.g.iter_mut().zip(&o.g) {
            *a += b;
        }
        for (a, b) in self.b.iter_mut().zip(&o.b) {
            *a += b;
        }
        self.yy += o.yy;
        self.rows += o.rows;
    }
    fn accumulate(
        &mut self,
        cols: &[&[[f64; NR]]],
        y: &[[f64; NR]],
        range: std::ops::Range<usize>,
        ok: &[bool],
    ) {
        let m = self.m;
        let mut row = vec![0.0; m];
        for k in range {
            if !ok[k] {
                continue;
            }
            for r in 0..NR {
                for (j, c) in cols.iter().enumerate() {
                    row[j] = c[k][r];
                }
                let yv = y[k][r];
                self.yy += yv * yv;
                for i in 0..m {
                    let ri = row[i];
                    if ri == 0.0 {
                        continue;
                    }
                    self.b[i] += ri * yv;
                    let gi = &mut self.g[i * m..(i + 1) * m];
                    for j in i..m {
                        gi[j] += ri * row[j];
                    }
                }
                self.rows += 1;
            }
        }
        // mirror
        for i in 0..m {
            for j in 0..i {
                self.g[i * m + j] = self.g[j * m + i];
            }
        }
    }
    /// Energy of `y − C_S β` for the subset `s` and coefficients `beta`.
    fn energy(&self, s: &[usize], beta: &[f64]) -> f64 {
        let m = self.m;
        let mut e = self.yy;
        for (a, &i) in s.iter().enumerate() {
            e -= 2.0 * beta[a] * self.b[i];
            for (c, &j) in s.iter().enumerate() {
                e += beta[a] * beta[c] * self.g[i * m + j];
            }
        }
        e
    }
    fn sub(&self, s: &[usize]) -> (Vec<f64>, Vec<f64>) {
        let p = s.len();
        let mut g = vec![0.0; p * p];
        let mut b = vec![0.0; p];
        for (a, &i) in s.iter().enumerate() {
            b[a] = self.b[i];
            for (c, &j) in s.iter().enumerate() {
                g[a * p + c] = self.g[i * self.m + j];
            }
        }
        (g, b)
    }
}

/// Solves the symmetric positive semi-definite system `g x = b` (p×p) by Cholesky with
/// Jacobi scaling and a tiny ridge (1e-12 of the diagonal) for collinear columns.
/// Also returns the inverse (for covariances).
fn solve_spd(g: &[f64], b: &[f64], p: usize) -> (Vec<f64>, Vec<f64>) {
    if p == 0 {
        return (Vec::new(), Vec::new());
    }
    let d: Vec<f64> = (0..p)
        .map(|i| {
            let v = g[i * p + i];
            if v > 0.0 { 1.0 / v.sqrt() } else { 0.0 }
        })
        .collect();
    let mut a = vec![0.0; p * p];
    for i in 0..p {
        for j in 0..p {
            a[i * p + j] = g[i * p + j] * d[i] * d[j];
        }
        a[i * p + i] += 1e-12 + if d[i] == 0.0 { 1.0 } else { 0.0 };
    }
    // Cholesky a = L Lᵀ
    let mut l = vec![0.0; p * p];
    for i in 0..p {
        for j in 0..=i {
            let mut s = a[i * p + j];
            for k in 0..j {
                s -= l[i * p + k] * l[j * p + k];
            }
            if i == j {
                l[i * p + i] = s.max(1e-300).sqrt();
            } else {
                l[i * p + j] = s / l[j * p + j];
            }
        }
    }
    let solve = |rhs: &[f64]| -> Vec<f64> {
        let mut z = rhs.to_vec();
        for i in 0..p {
            let mut s = z[i];
            for k in 0..i {
                s -= l[i * p + k] * z[k];
            }
            z[i] = s / l[i * p + i];
        }
        for i in (0..p).rev() {
            let mut s = z[i];
            for k in i + 1..p {
                s -= l[k * p + i] * z[k];
            }
            z[i] = s / l[i * p + i];
        }
        z
    };
    let bs: Vec<f64> = (0..p).map(|i| b[i] * d[i]).collect();
    let x: Vec<f64> = solve(&bs).iter().zip(&d).map(|(v, di)| v * di).collect();
    let mut inv = vec![0.0; p * p];
    for c in 0..p {
        let mut e = vec![0.0; p];
        e[c] = 1.0;
        let z = solve(&e);
        for r in 0..p {
            inv[r * p + c] = z[r] * d[r] * d[c];
        }
    }
    (x, inv)
}

/// A fitted subset: coefficients, cluster-robust standard errors, energies.
#[derive(Clone, Debug)]
struct Fit {
    cols: Vec<usize>,
    beta: Vec<f64>,
    sigma: Vec<f64>,
    /// Fit-span energy.
    e_fit: f64,
    /// Held-out energy.
    e_hold: f64,
}

/// The scoring machinery: Grams of the full column bank over the fit blocks and the
/// held-out span.
struct Bank {
    names: Vec<String>,
    blocks: Vec<Gram>,
    fit: Gram,
    hold: Gram,
}

impl Bank {
    fn build(
        cols: &[Column],
        y: &[[f64; NR]],
        ok: &[bool],
        fit: &[std::ops::Range<usize>],
        hold: std::ops::Range<usize>,
    ) -> Self {
        let m = cols.len();
        let refs: Vec<&[[f64; NR]]> = cols.iter().map(|c| c.v.as_slice()).collect();
        let blocks: Vec<Gram> = fit
            .iter()
            .map(|r| {
                let mut g = Gram::new(m);
                g.accumulate(&refs, y, r.clone(), ok);
                g
            })
            .collect();
        let mut fg = Gram::new(m);
        for b in &blocks {
            fg.add(b);
        }
        let mut hg = Gram::new(m);
        hg.accumulate(&refs, y, hold, ok);
        Bank {
            names: cols.iter().map(|c| c.name.clone()).collect(),
            blocks,
            fit: fg,
            hold: hg,
        }
    }

    fn idx(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    fn fit(&self, s: &[usize]) -> Fit {
        let p = s.len();
        let (g, b) = self.fit.sub(s);
        let (beta, inv) = solve_spd(&g, &b, p);
        // cluster-robust covariance: G⁻¹ (Σ s_i s_iᵀ) G⁻¹ · B/(B − 1)
        let mut meat = vec![0.0; p * p];
        for blk in &self.blocks {
            let (gb, bb) = blk.sub(s);
            let sc: Vec<f64> = (0..p)
                .map(|i| bb[i] - (0..p).map(|j| gb[i * p + j] * beta[j]).sum::<f64>())
                .collect();
            for i in 0..p {
                for j in 0..p {
                    meat[i * p + j] += sc[i] * sc[j];
                }
            }
        }
        let nb = self.blocks.len() as f64;
        let corr = if nb > 1.0 { nb / (nb - 1.0) } else { 1.0 };
        let sigma = (0..p)
            .map(|i| {
                let mut v = 0.0;
                for a in 0..p {
                    for c in 0..p {
                        v += inv[i * p + a] * meat[a * p + c] * inv[c * p + i];
                    }
                }
                (v * corr).max(0.0).sqrt()
            })
            .collect();
        Fit {
            cols: s.to_vec(),
            e_fit: self.fit.energy(s, &beta),
            e_hold: self.hold.energy(s, &beta),
            beta,
            sigma,
        }
    }

    /// Correlation of two columns after projecting out `base` (fit span).
    fn partial_corr(&self, a: usize, b: usize, base: &[usize]) -> f64 {
        let m = self.fit.m;
        let g = &self.fit.g;
        let resid = |i: usize, j: usize| -> f64 {
            // (c_i − P c_i)·(c_j − P c_j) = G_ij − G_iB G_BB⁻¹ G_Bj
            if base.is_empty() {
                return g[i * m + j];
            }
            let (gbb, _) = self.fit.sub(base);
            let gbj: Vec<f64> = base.iter().map(|&k| g[k * m + j]).collect();
            let (x, _) = solve_spd(&gbb, &gbj, base.len());
            g[i * m + j]
                - base
                    .iter()
                    .zip(&x)
                    .map(|(&k, v)| g[i * m + k] * v)
                    .sum::<f64>()
        };
        let (aa, bb, ab) = (resid(a, a), resid(b, b), resid(a, b));
        if aa > 0.0 && bb > 0.0 {
            ab / (aa * bb).sqrt()
        } else {
            0.0
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The diagnosis
// ---------------------------------------------------------------------------------------------

/// One candidate's result.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Candidate {
    /// Effect name.
    pub effect: String,
    /// Fitted size in the effect's unit (see [`paragyro_simulator::effects`]).
    pub size: f64,
    /// Its 1σ uncertainty (cluster-robust).
    pub size_sigma: f64,
    /// Held-out gap closure (E0 − E_c)/(E0 − E_floor).
    pub gap_closure: f64,
    /// Whether it is significant (|size|/σ ≥ T_SIG and closes ≥ GAP_MIN of E0).
    pub significant: bool,
    /// Fraction of the held-out baseline energy it removes.
    pub energy_fraction: f64,
    /// ΔBIC against the baseline on the fit span (negative favours the effect).
    pub delta_bic: f64,
    /// What remains explainable after it (catch-all on its residual), as a share of the
    /// explainable gap (the residual check; small is good).
    pub residual_explainable: f64,
    /// Candidates this record cannot tell it apart from.
    pub coherent_with: Vec<String>,
    /// Why the candidate could not be tested, if so.
    pub untestable: Option<String>,
    /// Angular vibration: the beat frequency found, Hz.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub beat_hz: Option<f64>,
}

/// The full result.
#[derive(Clone, Debug)]
pub struct Diagnosis {
    /// The report as JSON (report.json).
    pub json: Value,
    /// The verdict.
    pub verdict: String,
    /// The ranking (best first).
    pub ranking: Vec<Candidate>,
    /// Data for the plots.
    pub plots: PlotData,
}

/// What the plots need.
#[derive(Clone, Debug, Default)]
pub struct PlotData {
    /// Time of each usable sample, s.
    pub t: Vec<f64>,
    /// Baseline residual energy per sample (weighted, all rows).
    pub e_base: Vec<f64>,
    /// Residual energy per sample after the verdict's effect (or the floor).
    pub e_after: Vec<f64>,
    /// Fit span and held-out span, s.
    pub fit_span: (f64, f64),
    /// Held-out span, s.
    pub hold_span: (f64, f64),
    /// Explainable gap share by axis × channel: (label, share).
    pub shares: Vec<(String, f64)>,
    /// Ranking (effect, gap closure, significant).
    pub ranking: Vec<(String, f64, bool)>,
    /// Envelopes on the held-out span: (t, |x1| rec, |y1| rec, |x1| sim before, |y1| sim
    /// before, |x1| after, |y1| after, then |x1 rec − x1 sim| and |y1 rec − y1 sim| before
    /// and after), µm.
    pub envelopes: Vec<[f64; 11]>,
    /// Windowed gap energy over time: (t, baseline − floor).
    pub windows: Vec<(f64, f64)>,
    /// CUSUM of the windowed gap.
    pub cusum: Vec<(f64, f64)>,
}

/// Physical conversions for size reporting.
fn gamma_per_dps(omega0: f64) -> f64 {
    gamma_from_rate_dps(1.0, omega0)
}

/// The reference phase ψ (half the pump phase) integrated from the record's pump column
/// (trapezoid over the linear sweep between samples: exact for the simulator's DDS).
fn psi_of(rec: &Record) -> Vec<f64> {
    let mut psi = Vec::with_capacity(rec.rows.len());
    let mut p = 0.0f64;
    let mut prev: Option<(f64, f64)> = None;
    for r in &rec.rows {
        if let Some((t0, f0)) = prev {
            let dt = r.t_s - t0;
            p += PI * 0.5 * (f0 + r.pump_hz) * dt; // ψ' = Ω = π·pump_hz
            p = paragyro_simulator::plant::wrap_phase(p);
        }
        psi.push(p);
        prev = Some((r.t_s, r.pump_hz));
    }
    psi
}

/// Runs the diagnosis of a record.
pub fn diagnose(rec: &Record, opts: &Options) -> anyhow::Result<Diagnosis> {
    let wall = Instant::now();
    let n = rec.rows.len();
    anyhow::ensure!(
        n >= 1000,
        "the record has {n} samples; the diagnosis needs at least 2 s"
    );
    let fs = rec.header.fs_hz;
    let t: Vec<f64> = rec.rows.iter().map(|r| r.t_s).collect();
    let omega0 = TAU * rec.header.f0_hz;
    let gpd = gamma_per_dps(omega0);

    // --- the rate: a rate table fixes it, otherwise it is fitted
    let rate_ref: Option<Vec<f64>> = if rec
        .rows
        .iter()
        .all(|r| r.rate_ref_dps.is_some_and(f64::is_finite))
    {
        Some(
            rec.rows
                .iter()
                .map(|r| r.rate_ref_dps.unwrap_or(0.0))
                .collect(),
        )
    } else {
        None
    };
    let gamma_nom = match &rate_ref {
        Some(v) => gpd * v.iter().sum::<f64>() / v.len() as f64,
        None => opts.model.phys.gamma,
    };
    let cfg = model_config(rec, &opts.model, gamma_nom);
    let (th1m, _) = theta_from_physical(&cfg.nominal);
    let ts = omega0 / fs;
    let svf = SvfCoeffs::<f64>::new(TAU * cfg.svf_hz / omega0, ts);

    // --- pass 0: the model's rows
    let base = run_pass(rec, &cfg, &|_, _| {})?;
    let mut y = base.y.clone();
    let mut usable = base.usable.clone();
    // θ columns
    let th_names = [
        "th11", "th12", "th13", "th14", "th15", "th16", "th17", "th18", "th21", "th22", "th23",
        "th24", "th25", "th26",
    ];
    let theta_col = |j: usize| -> Vec<[f64; NR]> { base.theta.iter().map(|c| c[j]).collect() };
    let mut cols: Vec<Column> = Vec::new();
    // the rate column: dθ14/dγ = 2, dθ24/dγ = −2
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
    let warm = (0..n).find(|&k| t[k] >= t[0] + WARMUP_S).unwrap_or(n);
    // the rate the simulator runs with: the table's, or fitted on the rows
    let gamma_sim = match &rate_ref {
        Some(_) => None,
        None => {
            let (mut gg, mut gy) = (0.0, 0.0);
            for k in warm..n {
                if usable[k] {
                    for r in 0..NR {
                        gg += gamma_col[k][r] * gamma_col[k][r];
                        gy += gamma_col[k][r] * y[k][r];
                    }
                }
            }
            Some(gamma_nom + if gg > 0.0 { gy / gg } else { 0.0 })
        }
    };
    let mut timing = serde_json::Map::new();
    let mut lap = Instant::now();
    let mut tick = |name: &str, m: &mut serde_json::Map<String, Value>| {
        m.insert(name.into(), json!(lap.elapsed().as_secs_f64()));
        lap = Instant::now();
    };
    tick("rows", &mut timing);
    let mut before_sim: Option<Vec<LockinOut>> = None;
    if opts.resimulate {
        // the gap is the record's rows minus the simulator's rows on the same inputs: the
        // rows' own approximations (lock-in products, truncated harmonics) cancel
        let resim = Resim {
            rec,
            model: &opts.model,
            gamma: gamma_sim,
            rate_ref: rate_ref.as_deref(),
            effects: &[],
            vib_phase0: 0.0,
            steps_per_period: opts.steps_per_period,
        };
        let sim = resim.run(0..n)?;
        let ps = run_pass(&with_lockin(rec, &sim), &cfg, &|_, _| {})?;
        for k in 0..n {
            for r in 0..NR {
                y[k][r] -= ps.y[k][r];
            }
            usable[k] &= ps.usable[k];
        }
        before_sim = Some(sim);
        tick("resimulate_model", &mut timing);
    } else if let Some(rr) = &rate_ref {
        // known rate: subtract its column times (γ_ref(t) − γ_nom)
        for k in 0..n {
            let dg = gpd * rr[k] - gamma_nom;
            for r in 0..NR {
                y[k][r] -= dg * gamma_col[k][r];
            }
        }
    }
    if rate_ref.is_none() {
        cols.push(Column {
            name: "rate".into(),
            v: gamma_col.clone(),
        });
    }
    let n_base = cols.len();
    for (j, nm) in th_names.iter().enumerate() {
        cols.push(Column {
            name: (*nm).into(),
            v: theta_col(j),
        });
    }
    let th_idx: Vec<usize> = (n_base..n_base + 14).collect();

    // --- library columns
    let mut untestable: Vec<(String, String)> = Vec::new();
    let (wx2, wy2) = (opts.model.phys.wx2, opts.model.phys.wy2);
    let lib_force: Vec<(&str, Box<ForceFn>)> = vec![
        (
            "geometric_nonlinearity",
            Box::new(|w: &Wave, j: usize| {
                let (x, xd, yv, yd) = (w.x[j], w.xd[j], w.y[j], w.yd[j]);
                (-yv * (x * yv + 2.0 * xd * yd), yv * xd * xd)
            }),
        ),
        (
            "nonlinear_damping",
            Box::new(|w: &Wave, j: usize| (-w.x[j] * w.x[j] * w.xd[j], -w.y[j] * w.y[j] * w.yd[j])),
        ),
        (
            "force_leak",
            Box::new(move |w: &Wave, j: usize| {
                let x = w.x[j];
                (0.0, w.s * (1.0 + w.c2[j]) * x * (th1m[5] + th1m[6] * x * x))
            }),
        ),
    ];
    let refs: Vec<(&str, &ForceFn)> = lib_force.iter().map(|(n, f)| (*n, f.as_ref())).collect();
    cols.extend(force_columns(&base, &svf, &refs));
    // electrostatic softening: −(θ22 column + c3·θ25 column)
    cols.push(Column {
        name: "electrostatic_softening".into(),
        v: base
            .theta
            .iter()
            .map(|c| {
                let mut v = [0.0; NR];
                for r in 0..NR {
                    v[r] = -(c[9][r] + ES_C3 * c[12][r]);
                }
                v
            })
            .collect(),
    });
    // anisodamping: −(d/2)Y' on the drive (θ14 column), +(d/2)X' on the sense (θ24)
    let aniso: Vec<[f64; NR]> = base
        .theta
        .iter()
        .map(|c| {
            let mut v = [0.0; NR];
            for r in 0..NR {
                v[r] = -0.5 * c[3][r] + 0.5 * c[11][r];
            }
            v
        })
        .collect();
    if rate_ref.is_some() {
        cols.push(Column {
            name: "anisodamping".into(),
            v: aniso,
        });
    } else {
        untestable.push((
            "anisodamping".into(),
            "identical to a rate offset without a rate table (rate_ref_dps): record on a rate table or with zero-rate segments".into(),
        ));
    }
    // thermal drift: needs the die temperature
    let temps: Option<Vec<f64>> = rec
        .rows
        .iter()
        .map(|r| r.temp_c.filter(|v| v.is_finite()))
        .collect();
    match &temps {
        Some(tc)
            if tc.iter().cloned().fold(f64::MIN, f64::max)
                - tc.iter().cloned().fold(f64::MAX, f64::min)
                >= 0.5 =>
        {
            cols.push(Column {
                name: "thermal_drift".into(),
                v: base
                    .theta
                    .iter()
                    .zip(tc)
                    .map(|(c, &tk)| {
                        let g = -2e-6 * (tk - T_REF_C);
                        let mut v = [0.0; NR];
                        for r in 0..NR {
                            v[r] = g * (wx2 * c[1][r] + wy2 * c[9][r]);
                        }
                        v
                    })
                    .collect(),
            });
        }
        Some(_) => untestable.push((
            "thermal_drift".into(),
            "the die temperature moves less than 0.5 K: a temperature step would separate it"
                .into(),
        )),
        None => untestable.push((
            "thermal_drift".into(),
            "no temp_c column: record the die temperature".into(),
        )),
    }
    // feedthrough: d rows / dC with Y0 += C·s, Y2 += C·s
    {
        let eps = 1e-3;
        let p = run_pass(rec, &cfg, &|_, s| {
            let sc = s.pump_scale;
            s.lockin.y0_um += eps * sc;
            s.lockin.y_um[1].re += eps * sc;
        })?;
        cols.push(fd_column("feedthrough", &p, &base, 1.0 / eps));
    }
    // lock-in mismatch: the rows' response to the replica's cut-off (residual of a
    // device whose lock-in is (1 + δ) × the header's ≈ −δ · ∂y/∂(replica cut-off))
    {
        let eps = 0.01;
        let mut c2 = cfg;
        c2.lockin_lpf_hz *= 1.0 + eps;
        let p = run_pass(rec, &c2, &|_, _| {})?;
        cols.push(fd_column("lockin_mismatch", &p, &base, -1.0 / eps));
    }

    // --- spans
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
    let fit_blocks: Vec<std::ops::Range<usize>> = (0..BLOCKS)
        .map(|b| {
            let a = first + (fit_end - first) * b / BLOCKS;
            let e = first + (fit_end - first) * (b + 1) / BLOCKS;
            a..e
        })
        .collect();
    let hold = hold_start..last + 1;

    // --- angular vibration: scan the beat (coarse grid, then refine)
    let psi = psi_of(rec);
    let f_ref = first_pump_hz(rec);
    let base_cols: Vec<usize> = (0..n_base).collect();
    // Ω_v/ω0 ≈ the pump's: its spread over the scan (±6 Hz of 21.9 kHz) is 3e-4 of γ'
    let vbasis = vib_basis(&base, TAU * f_ref / omega0);
    let scan = |beat: f64| -> (f64, [Column; 2]) {
        let vc = vibration_columns(&base, &vbasis, &svf, &psi, &t, f_ref + beat);
        let mut c: Vec<Column> = base_cols.iter().map(|&i| cols[i].clone()).collect();
        c.extend(vc.iter().cloned());
        let bank = Bank::build(&c, &y, &usable, &fit_blocks, 0..0);
        let f0 = bank.fit(&(0..n_base).collect::<Vec<_>>());
        let f1 = bank.fit(&(0..n_base + 2).collect::<Vec<_>>());
        (f0.e_fit - f1.e_fit, vc)
    };
    let mut best_beat = (f64::MIN, 0.0);
    let steps = (VIB_BEAT_MAX_HZ / VIB_BEAT_STEP_HZ).round() as i64;
    let grid: Vec<f64> = (-steps..=steps)
        .map(|i| i as f64 * VIB_BEAT_STEP_HZ)
        .collect();
    let scores: Vec<(f64, f64)> = std::thread::scope(|s| {
        let chunks: Vec<&[f64]> = grid.chunks(grid.len().div_ceil(2)).collect();
        let hs: Vec<_> = chunks
            .into_iter()
            .map(|ch| s.spawn(|| ch.iter().map(|&b| (b, scan(b).0)).collect::<Vec<_>>()))
            .collect();
        hs.into_iter()
            .flat_map(|h| h.join().unwrap_or_default())
            .collect()
    });
    for &(b, sc) in &scores {
        if sc > best_beat.0 {
            best_beat = (sc, b);
        }
    }
    // refine around the best coarse point (golden-section on the fit-span reduction)
    let (mut lo, mut hi) = (
        best_beat.1 - VIB_BEAT_STEP_HZ,
        best_beat.1 + VIB_BEAT_STEP_HZ,
    );
    for _ in 0..8 {
        let m1 = lo + 0.382 * (hi - lo);
        let m2 = lo + 0.618 * (hi - lo);
        if scan(m1).0 > scan(m2).0 {
            hi = m2;
        } else {
            lo = m1;
        }
    }
    let beat = 0.5 * (lo + hi);
    let [vr, vi] = scan(beat).1;
    cols.push(vr);
    cols.push(vi);
    tick("library_columns_and_beat_scan", &mut timing);

    // --- catch-all: quadratic and cubic force monomials of (X, X', Y, Y') on each axis
    let mono: Vec<(String, Box<ForceFn>)> = {
        let mut v: Vec<(String, Box<ForceFn>)> = Vec::new();
        let var = |w: &Wave, j: usize, i: usize| match i {
            0 => w.x[j],
            1 => w.xd[j],
            2 => w.y[j],
            _ => w.yd[j],
        };
        for a in 0..4 {
            for b in a..4 {
                for axis in 0..2 {
                    v.push((
                        format!("m2_{a}{b}_{axis}"),
                        Box::new(move |w: &Wave, j: usize| {
                            let m = var(w, j, a) * var(w, j, b);
                            if axis == 0 { (m, 0.0) } else { (0.0, m) }
                        }),
                    ));
                }
                for c in b..4 {
                    // X³ and Y³ are θ15/θ25 already
                    if (a, b, c) == (0, 0, 0) || (a, b, c) == (2, 2, 2) {
                        continue;
                    }
                    for axis in 0..2 {
                        v.push((
                            format!("m3_{a}{b}{c}_{axis}"),
                            Box::new(move |w: &Wave, j: usize| {
                                let m = var(w, j, a) * var(w, j, b) * var(w, j, c);
                                if axis == 0 { (m, 0.0) } else { (0.0, m) }
                            }),
                        ));
                    }
                }
            }
        }
        v
    };
    let mrefs: Vec<(&str, &ForceFn)> = mono.iter().map(|(n, f)| (n.as_str(), f.as_ref())).collect();
    let ca_start = cols.len();
    cols.extend(force_columns(&base, &svf, &mrefs));
    let ca_idx: Vec<usize> = th_idx.iter().copied().chain(ca_start..cols.len()).collect();

    // --- the bank
    let bank = Bank::build(&cols, &y, &usable, &fit_blocks, hold.clone());
    tick("catch_all_and_grams", &mut timing);
    let base_fit = bank.fit(&base_cols);
    let e0 = base_fit.e_hold;
    let lib_cols = |name: &str| -> Vec<usize> {
        if name == "angular_vibration" {
            ["angular_vibration:re", "angular_vibration:im"]
                .iter()
                .filter_map(|c| bank.idx(c))
                .collect()
        } else {
            bank.idx(name).into_iter().collect()
        }
    };
    let tested: Vec<&str> = LIBRARY
        .iter()
        .copied()
        .filter(|n| !lib_cols(n).is_empty())
        .collect();
    let all_lib: Vec<usize> = tested.iter().flat_map(|n| lib_cols(n)).collect();
    let with = |extra: &[usize]| -> Vec<usize> {
        base_cols
            .iter()
            .copied()
            .chain(extra.iter().copied())
            .collect()
    };
    let ca_fit = bank.fit(&with(&ca_idx));
    let everything: Vec<usize> = ca_idx
        .iter()
        .copied()
        .chain(all_lib.iter().copied())
        .collect();
    let floor_fit = bank.fit(&with(&everything));
    // the floor: the best held-out energy any model reaches (the everything-model can
    // generalise worse than a single candidate to the held-out operating point)
    // each candidate with the rate, fitted once
    let cand_fits: Vec<(&str, Vec<usize>, Fit)> = tested
        .iter()
        .map(|&name| {
            let ci = lib_cols(name);
            let f = bank.fit(&with(&ci));
            (name, ci, f)
        })
        .collect();
    let e_floor = cand_fits
        .iter()
        .map(|c| c.2.e_hold)
        .fold(floor_fit.e_hold.min(e0).min(ca_fit.e_hold), f64::min);
    let explainable = (e0 - e_floor).max(0.0);
    let n_fit_rows = bank.fit.rows as f64;
    // effective sample count for the BIC: rows over the baseline residual's correlation
    let n_eff = (n_fit_rows / corr_length(&y, &usable, &cols, &base_fit, first..fit_end)).max(1.0);

    let mut ranking: Vec<Candidate> = Vec::new();
    for (name, ci, f) in &cand_fits {
        let (name, ci) = (*name, ci);
        let k0 = base_cols.len();
        let (size, sigma) = if name == "angular_vibration" {
            let (gr, gi) = (f.beta[k0], f.beta[k0 + 1]);
            let amp = gr.hypot(gi);
            let sig = if amp > 0.0 {
                ((gr * f.sigma[k0]).powi(2) + (gi * f.sigma[k0 + 1]).powi(2)).sqrt() / amp
            } else {
                f.sigma[k0].max(f.sigma[k0 + 1])
            };
            (amp / gpd, sig / gpd)
        } else {
            (f.beta[k0], f.sigma[k0])
        };
        let efrac = if e0 > 0.0 { (e0 - f.e_hold) / e0 } else { 0.0 };
        let gc = if explainable > 0.0 {
            (e0 - f.e_hold) / explainable
        } else {
            0.0
        };
        let dbic = n_eff * (f.e_fit / base_fit.e_fit).ln() + ci.len() as f64 * n_eff.ln();
        // residual check: the catch-all on top of the candidate
        let both = bank.fit(&with(
            &ci.iter()
                .copied()
                .chain(ca_idx.iter().copied())
                .collect::<Vec<_>>(),
        ));
        let resid_expl = if explainable > 0.0 {
            ((f.e_hold - both.e_hold) / explainable).max(0.0)
        } else {
            0.0
        };
        let significant = sigma > 0.0 && size.abs() / sigma >= T_SIG && efrac >= GAP_MIN;
        ranking.push(Candidate {
            effect: name.into(),
            size,
            size_sigma: sigma,
            gap_closure: gc,
            significant,
            energy_fraction: efrac,
            delta_bic: dbic,
            residual_explainable: resid_expl,
            coherent_with: Vec::new(),
            untestable: None,
            beat_hz: (name == "angular_vibration").then_some(beat),
        });
    }
    // coherence: single-column candidates against each other, rate projected out
    for i in 0..ranking.len() {
        for j in 0..ranking.len() {
            if i == j {
                continue;
            }
            let (a, b) = (lib_cols(&ranking[i].effect), lib_cols(&ranking[j].effect));
            if a.len() == 1
                && b.len() == 1
                && bank.partial_corr(a[0], b[0], &base_cols).abs() >= COHERENT
            {
                let other = ranking[j].effect.clone();
                ranking[i].coherent_with.push(other);
            }
        }
    }
    ranking.sort_by(|a, b| {
        b.gap_closure
            .partial_cmp(&a.gap_closure)
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    for (name, why) in &untestable {
        ranking.push(Candidate {
            effect: name.clone(),
            size: f64::NAN,
            size_sigma: f64::NAN,
            gap_closure: 0.0,
            significant: false,
            energy_fraction: 0.0,
            delta_bic: 0.0,
            residual_explainable: 0.0,
            coherent_with: Vec::new(),
            untestable: Some(why.clone()),
            beat_hz: None,
        });
    }

    // --- verdict
    let gap_fraction = if e0 > 0.0 { explainable / e0 } else { 0.0 };
    let best = ranking.first().cloned();
    let verdict = match &best {
        _ if gap_fraction < GAP_MIN => "none".to_string(),
        Some(b) if b.significant && b.gap_closure >= SHARE_MIN => b.effect.clone(),
        _ => "unknown".to_string(),
    };
    // a second effect on top of the verdict
    let mut secondary: Option<(String, f64)> = None;
    if let Some(b) = best
        .as_ref()
        .filter(|_| verdict != "none" && verdict != "unknown")
    {
        let c1 = lib_cols(&b.effect);
        let e1 = cand_fits
            .iter()
            .find(|c| c.0 == b.effect)
            .map_or(e0, |c| c.2.e_hold);
        for c in ranking.iter().skip(1).filter(|c| c.untestable.is_none()) {
            let c2 = lib_cols(&c.effect);
            let f = bank.fit(&with(
                &c1.iter().chain(c2.iter()).copied().collect::<Vec<_>>(),
            ));
            let k = base_cols.len() + c1.len();
            let add = if explainable > 0.0 {
                (e1 - f.e_hold) / explainable
            } else {
                0.0
            };
            let tstat = f.beta[k].abs() / f.sigma[k].max(1e-300);
            if add >= SECOND_MIN && tstat >= T_SIG && secondary.as_ref().is_none_or(|s| add > s.1) {
                secondary = Some((c.effect.clone(), add));
            }
        }
    }
    let verdict_cols: Vec<usize> = if verdict == "none" || verdict == "unknown" {
        Vec::new()
    } else {
        let mut v = lib_cols(&verdict);
        if let Some((s, _)) = &secondary {
            v.extend(lib_cols(s));
        }
        v
    };
    let after_fit = bank.fit(&with(&verdict_cols));
    // the verdict must explain the gap above the noise, not just most of what the floor does
    let noise_e = NOISE_ROW_ENERGY * bank.hold.rows as f64;
    let unexplained = if e0 > noise_e {
        ((after_fit.e_hold - noise_e) / (e0 - noise_e)).max(0.0)
    } else {
        0.0
    };
    // and it must explain every row where the gap lives, not just the energy in total: a
    // row holding a share of the gap that the verdict leaves mostly unexplained means
    // something else is there (e.g. a quadratic stiffness: its drive DC and 1st quadrature)
    let unexplained_rows: Vec<usize> = if verdict_cols.is_empty() {
        Vec::new()
    } else {
        let e_b = row_energy(&base_fit, &y, &cols, &usable, hold.clone());
        let e_a = row_energy(&after_fit, &y, &cols, &usable, hold.clone());
        let e_f = row_energy(&floor_fit, &y, &cols, &usable, hold.clone());
        let g0: Vec<f64> = (0..NR).map(|i| e_b[i] - e_f[i].min(e_a[i])).collect();
        let tot: f64 = g0.iter().map(|v| v.max(0.0)).sum();
        (0..NR)
            .filter(|&i| {
                let ga = e_a[i] - e_f[i].min(e_a[i]);
                g0[i] > ROW_GAP_SHARE * tot
                    && g0[i] > ROW_GAP_MIN
                    && ga > ROW_UNEXPLAINED_MAX * g0[i]
            })
            .collect()
    };
    let closest = verdict.clone();
    let (verdict, verdict_cols, secondary, after_fit) = if !verdict_cols.is_empty()
        && (unexplained > UNEXPLAINED_MAX || !unexplained_rows.is_empty())
    {
        (
            "unknown".to_string(),
            Vec::new(),
            None,
            bank.fit(&base_cols),
        )
    } else {
        (verdict, verdict_cols, secondary, after_fit)
    };
    let gap_before = explainable;
    let gap_after = (after_fit.e_hold - e_floor).max(0.0);

    // --- where: per-sample residuals (baseline, floor), by axis × channel, regime, time
    let resid = |f: &Fit, k: usize| -> [f64; NR] {
        let mut r = y[k];
        for (a, &c) in f.cols.iter().enumerate() {
            for i in 0..NR {
                r[i] -= f.beta[a] * cols[c].v[k][i];
            }
        }
        r
    };
    // held-out energy per row (per sample): baseline, the closest library effect, everything
    let closest_fit = cand_fits
        .iter()
        .find(|c| c.0 == closest)
        .map_or_else(|| base_fit.clone(), |c| c.2.clone());
    let by_row = {
        let mut acc = [[0.0f64; 3]; NR];
        let mut cnt = 0usize;
        for k in hold.clone().filter(|&k| usable[k]) {
            cnt += 1;
            for (j, f) in [&base_fit, &closest_fit, &floor_fit].iter().enumerate() {
                let r = resid(f, k);
                for i in 0..NR {
                    acc[i][j] += r[i] * r[i];
                }
            }
        }
        let c = cnt.max(1) as f64;
        (0..NR)
            .map(|i| json!({"row": i, "baseline": acc[i][0] / c, "closest": acc[i][1] / c, "everything": acc[i][2] / c}))
            .collect::<Vec<_>>()
    };
    let ks: Vec<usize> = (first..=last).filter(|&k| usable[k]).collect();
    let mut share = [0.0f64; NR];
    let mut e_base = Vec::with_capacity(ks.len());
    let mut e_after = Vec::with_capacity(ks.len());
    let mut gap_k = Vec::with_capacity(ks.len());
    for &k in &ks {
        let r0 = resid(&base_fit, k);
        let rf = resid(&floor_fit, k);
        let ra = resid(&after_fit, k);
        let mut g = 0.0;
        for i in 0..NR {
            let d = r0[i] * r0[i] - rf[i] * rf[i];
            share[i] += d;
            g += d;
        }
        e_base.push(r0.iter().map(|v| v * v).sum::<f64>());
        e_after.push(ra.iter().map(|v| v * v).sum::<f64>());
        gap_k.push(g);
    }
    let tot: f64 = share.iter().map(|v| v.max(0.0)).sum::<f64>().max(1e-300);
    let ch_names = [
        "DC",
        "1st in-phase",
        "1st quadrature",
        "3rd in-phase",
        "3rd quadrature",
    ];
    let mut shares = Vec::new();
    let mut where_channels = serde_json::Map::new();
    for (ax, axn) in ["drive", "sense"].iter().enumerate() {
        for (c, cn) in ch_names.iter().enumerate() {
            let v = share[ax * NROWS + c].max(0.0) / tot;
            shares.push((format!("{axn} {cn}"), v));
            where_channels.insert(format!("{axn}/{cn}"), json!(v));
        }
    }
    let axis_share = |ax: usize| -> f64 {
        (0..NROWS)
            .map(|c| share[ax * NROWS + c].max(0.0))
            .sum::<f64>()
            / tot
    };
    // regimes: amplitude, detuning, dither phase, temperature — gap density per tercile
    let regime = |vals: &dyn Fn(usize) -> f64, name: &str| -> Value {
        let mut v: Vec<(f64, f64)> = ks.iter().zip(&gap_k).map(|(&k, &g)| (vals(k), g)).collect();
        v.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap_or(std::cmp::Ordering::Equal));
        let m = v.len();
        let mean_all = v.iter().map(|p| p.1).sum::<f64>() / m.max(1) as f64;
        let bins: Vec<Value> = (0..3)
            .map(|b| {
                let s = &v[m * b / 3..m * (b + 1) / 3];
                let mean = s.iter().map(|p| p.1).sum::<f64>() / s.len().max(1) as f64;
                json!({
                    "from": s.first().map_or(f64::NAN, |p| p.0),
                    "to": s.last().map_or(f64::NAN, |p| p.0),
                    "relative_gap_density": if mean_all.abs() > 0.0 { mean / mean_all } else { 0.0 },
                })
            })
            .collect();
        let corr = pearson(
            &v.iter().map(|p| p.0).collect::<Vec<_>>(),
            &v.iter().map(|p| p.1).collect::<Vec<_>>(),
        );
        json!({"quantity": name, "terciles": bins, "correlation": corr})
    };
    let amp = |k: usize| rec.rows[k].x_abs(1);
    let fy_model = rec.header.f0_hz * opts.model.phys.wy2.sqrt();
    let detune = |k: usize| rec.rows[k].pump_hz / 2.0 - fy_model;
    // dither phase: pump deviation from its 1 s running mean → angle of (dev, d dev/dt)
    let pump: Vec<f64> = rec.rows.iter().map(|r| r.pump_hz).collect();
    let dev = deviation(&pump, (fs as usize).max(1));
    let dither_phase = |k: usize| {
        let d = dev[k];
        let dd = if k + 1 < n && k > 0 {
            dev[k + 1] - dev[k - 1]
        } else {
            0.0
        };
        dd.atan2(d)
    };
    let mut regimes = vec![
        regime(&amp, "drive amplitude (µm)"),
        regime(&detune, "detuning Ω/2π − f_y,model (Hz)"),
        regime(&dither_phase, "dither phase (rad)"),
    ];
    if let Some(tc) = &temps {
        regimes.push(regime(&|k| tc[k], "die temperature (°C)"));
    }
    // time: 0.5 s windows and their CUSUM
    let win = (0.5 * fs) as usize;
    let mut windows = Vec::new();
    for c in ks.chunks(win.max(1)).zip(gap_k.chunks(win.max(1))) {
        let tm = t[c.0[c.0.len() / 2]];
        windows.push((tm, c.1.iter().sum::<f64>() / c.1.len() as f64));
    }
    let wmean = windows.iter().map(|w| w.1).sum::<f64>() / windows.len().max(1) as f64;
    let mut cs = 0.0;
    let mut cusum = Vec::new();
    let mut cmax = (0.0f64, 0.0f64);
    for &(tm, g) in &windows {
        cs += g - wmean;
        cusum.push((tm, cs));
        if cs.abs() > cmax.0.abs() {
            cmax = (cs, tm);
        }
    }
    // the span holding the top half of the gap energy
    let span_json = {
        let mut sorted: Vec<(f64, f64)> = windows.clone();
        sorted.sort_by(|a, b| b.1.partial_cmp(&a.1).unwrap_or(std::cmp::Ordering::Equal));
        let total: f64 = sorted.iter().map(|w| w.1.max(0.0)).sum();
        let mut acc = 0.0;
        let mut ts_top = Vec::new();
        for w in &sorted {
            if acc >= 0.5 * total {
                break;
            }
            acc += w.1.max(0.0);
            ts_top.push(w.0);
        }
        let lo = ts_top.iter().cloned().fold(f64::MAX, f64::min);
        let hi = ts_top.iter().cloned().fold(f64::MIN, f64::max);
        json!({
            "half_of_gap_within_s": [lo, hi],
            "fraction_of_time_holding_half": ts_top.len() as f64 / windows.len().max(1) as f64,
            "cusum_extreme_at_s": cmax.1,
        })
    };

    // --- how far: the simulator re-run on the record's inputs
    let gamma_fit = match (&rate_ref, gamma_sim) {
        (Some(_), _) => None,
        (None, Some(g)) => Some(g + base_fit.beta.first().copied().unwrap_or(0.0)),
        (None, None) => Some(gamma_nom),
    };
    let mut verdict_spec: Vec<EffectSpec> = Vec::new();
    let mut vib_phase = 0.0;
    if !verdict_cols.is_empty() {
        let mut names = vec![verdict.clone()];
        if let Some((s, _)) = &secondary {
            names.push(s.clone());
        }
        // after_fit is the fit of exactly these columns
        let f = &after_fit;
        let mut k = base_cols.len();
        for nm in names {
            if nm == "angular_vibration" {
                let (gr, gi) = (f.beta[k], f.beta[k + 1]);
                vib_phase = gi.atan2(gr);
                verdict_spec.push(EffectSpec {
                    name: nm,
                    size: gr.hypot(gi) / gpd,
                    param: Some(beat),
                });
                k += 2;
            } else {
                verdict_spec.push(EffectSpec {
                    name: nm,
                    size: f.beta[k],
                    param: None,
                });
                k += 1;
            }
        }
    }
    tick("ranking_and_where", &mut timing);
    let hold_t = (t[hold_start], t[last]);
    let mut envelopes = Vec::new();
    let mut oe = json!(null);
    if let Some(before) = &before_sim {
        // the effect's run covers the held-out span (starting 0.5 s early from the record)
        let resim = Resim {
            rec,
            model: &opts.model,
            gamma: gamma_fit,
            rate_ref: rate_ref.as_deref(),
            effects: &verdict_spec,
            vib_phase0: vib_phase,
            steps_per_period: opts.steps_per_period,
        };
        let after_h = resim.run(hold_start..last + 1)?;
        let mut after = before.clone();
        after[hold_start..last + 1].clone_from_slice(&after_h);
        let ratio = lockin_noise_diff_ratio(rec)?;
        let b = output_error(rec, before, hold_start..last + 1, ratio);
        let a = output_error(rec, &after, hold_start..last + 1, ratio);
        let cl = |x: f64, y: f64| if x > 0.0 { 1.0 - y / x } else { 0.0 };
        oe = json!({
            "held_out_span_s": [hold_t.0, hold_t.1],
            "before": {"drive": b.drive, "sense": b.sense, "combined": b.combined, "above_noise": b.above_noise},
            "after": {"drive": a.drive, "sense": a.sense, "combined": a.combined, "above_noise": a.above_noise},
            "closure": cl(b.above_noise, a.above_noise),
            "closure_raw": cl(b.combined, a.combined),
            "noise_diff_ratio": ratio,
            "added": verdict_spec.iter().map(|s| s.to_string()).collect::<Vec<_>>(),
            "rate_dps": gamma_fit.map(|g| rate_dps_from_gamma(g, omega0)),
            "note": "rms of the lock-in channel errors (DC, 1st, 3rd harmonics of each axis) relative to the rms of the record's channels, on the held-out span; above_noise removes the record's own noise (estimated from the error's sample-to-sample differences); closure uses above_noise; simulator re-run open-loop on the record's pump, amplitude, accelerations and temperature",
        });
        tick("resimulate_with_effect", &mut timing);
        let stride = ((last + 1 - hold_start) / 2000).max(1);
        let l0 = rec.header.l0_um;
        for k in (hold_start..=last).step_by(stride) {
            let r = &rec.rows[k];
            let h = |v: (f64, f64)| v.0.hypot(v.1);
            let d = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0 * l0).hypot(a.1 - b.1 * l0);
            envelopes.push([
                t[k],
                h(r.x_um[0]),
                h(r.y_um[0]),
                h(before[k].x[0]) * l0,
                h(before[k].y[0]) * l0,
                h(after[k].x[0]) * l0,
                h(after[k].y[0]) * l0,
                d(r.x_um[0], before[k].x[0]),
                d(r.y_um[0], before[k].y[0]),
                d(r.x_um[0], after[k].x[0]),
                d(r.y_um[0], after[k].y[0]),
            ]);
        }
    }

    let cand_json: Vec<Value> = ranking
        .iter()
        .map(|c| serde_json::to_value(c).unwrap_or(Value::Null))
        .collect();
    let json = json!({
        "format": "paragyro-diagnosis 1",
        "verdict": verdict,
        "secondary": secondary.as_ref().map(|s| json!({"effect": s.0, "added_closure": s.1})),
        "ranking": cand_json,
        "gap_before": gap_before,
        "gap_after": gap_after,
        "gap_closure": if gap_before > 0.0 { 1.0 - gap_after / gap_before } else { 0.0 },
        "gap_fraction_of_baseline": gap_fraction,
        "unexplained_above_noise": unexplained,
        "unexplained_rows": unexplained_rows.iter().map(|&i| ROW_LABELS[i]).collect::<Vec<_>>(),
        "closest_library_effect": closest,
        "held_out_by_row": by_row,
        "energies": {
            "note": "weighted row energy on the held-out span (unit-noise rows: noise alone gives about one per row)",
            "baseline": e0,
            "catch_all": ca_fit.e_hold,
            "floor": e_floor,
            "after": after_fit.e_hold,
            "rows": bank.hold.rows,
        },
        "output_error": oe,
        "where": {
            "axis": {"drive": axis_share(0), "sense": axis_share(1)},
            "channel": Value::Object(where_channels),
            "regime": regimes,
            "time": span_json,
        },
        "model": opts.model.source,
        "rate": match &rate_ref {
            Some(_) => json!({"source": "rate_ref_dps (rate table)"}),
            None => json!({"source": "fitted", "rate_dps": gamma_fit.map(|g| rate_dps_from_gamma(g, omega0))}),
        },
        "spans_s": {
            "fit": [t[first], t[fit_end]],
            "guard_s": GUARD_S,
            "held_out": [hold_t.0, hold_t.1],
        },
        "thresholds": {"t_sig": T_SIG, "gap_min": GAP_MIN, "share_min": SHARE_MIN, "second_min": SECOND_MIN, "coherent": COHERENT, "noise_row_energy": NOISE_ROW_ENERGY, "unexplained_max": UNEXPLAINED_MAX, "row_gap_share": ROW_GAP_SHARE, "row_gap_min": ROW_GAP_MIN, "row_unexplained_max": ROW_UNEXPLAINED_MAX},
        "vibration_beat_scan": {"range_hz": VIB_BEAT_MAX_HZ, "best_hz": beat},
        "separating_excitation": separating(&ranking),
        "samples": n,
        "seconds": wall.elapsed().as_secs_f64(),
        "timing_s": Value::Object(timing),
    });
    let plots = PlotData {
        t: ks.iter().map(|&k| t[k]).collect(),
        e_base,
        e_after,
        fit_span: (t[first], t[fit_end]),
        hold_span: hold_t,
        shares,
        ranking: ranking
            .iter()
            .filter(|c| c.untestable.is_none())
            .map(|c| (c.effect.clone(), c.gap_closure, c.significant))
            .collect(),
        envelopes,
        windows,
        cusum,
    };
    Ok(Diagnosis {
        json,
        verdict,
        ranking,
        plots,
    })
}

/// The excitation that separates coherent candidates (and untestable ones).
fn separating(ranking: &[Candidate]) -> Vec<Value> {
    let how = |a: &str, b: &str| -> &'static str {
        let pair = |x: &str, y: &str| (a == x && b == y) || (a == y && b == x);
        if pair("electrostatic_softening", "thermal_drift") {
            "a temperature step at constant bias, or a bias-voltage step at constant temperature"
        } else if pair("electrostatic_softening", "geometric_nonlinearity") {
            "drive-amplitude steps (geometric shifts ω_y² ∝ |A|², electrostatic does not)"
        } else if pair("nonlinear_damping", "geometric_nonlinearity") {
            "ring-down segments (decay rate versus frequency shift)"
        } else if a == "anisodamping" || b == "anisodamping" {
            "a known rate: a rate table or zero-rate segments"
        } else {
            "amplitude and pump-frequency steps that move the two terms differently"
        }
    };
    let mut out = Vec::new();
    for c in ranking {
        for o in &c.coherent_with {
            if c.effect < *o {
                out.push(json!({"pair": [c.effect, o], "excitation": how(&c.effect, o)}));
            }
        }
        if let Some(u) = &c.untestable {
            out.push(json!({"pair": [c.effect], "excitation": u}));
        }
    }
    out
}

fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    if n < 2.0 {
        return 0.0;
    }
    let ma = a.iter().sum::<f64>() / n;
    let mb = b.iter().sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    if saa > 0.0 && sbb > 0.0 {
        sab / (saa * sbb).sqrt()
    } else {
        0.0
    }
}

/// `v` minus its centred running mean over `w` samples.
fn deviation(v: &[f64], w: usize) -> Vec<f64> {
    let n = v.len();
    let mut pre = vec![0.0; n + 1];
    for i in 0..n {
        pre[i + 1] = pre[i] + if v[i].is_finite() { v[i] } else { 0.0 };
    }
    (0..n)
        .map(|i| {
            let a = i.saturating_sub(w / 2);
            let b = (i + w / 2 + 1).min(n);
            v[i] - (pre[b] - pre[a]) / (b - a) as f64
        })
        .collect()
}

/// A finite-difference column: `scale · (rows of pass p − rows of the base pass)`.
fn fd_column(name: &str, p: &Pass, base: &Pass, scale: f64) -> Column {
    Column {
        name: name.into(),
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

/// The first valid pump frequency of a record (the reference of the vibration's beat), Hz.
pub fn first_pump_hz(rec: &Record) -> f64 {
    rec.rows
        .iter()
        .map(|r| r.pump_hz)
        .find(|p| p.is_finite() && *p > 0.0)
        .unwrap_or(0.0)
}

/// Held-out energy per row (per sample) of the residual of a fit.
fn row_energy(
    f: &Fit,
    y: &[[f64; NR]],
    cols: &[Column],
    ok: &[bool],
    span: std::ops::Range<usize>,
) -> [f64; NR] {
    let mut acc = [0.0; NR];
    let mut n = 0usize;
    for k in span.filter(|&k| ok[k]) {
        n += 1;
        for i in 0..NR {
            let mut r = y[k][i];
            for (a, &c) in f.cols.iter().enumerate() {
                r -= f.beta[a] * cols[c].v[k][i];
            }
            acc[i] += r * r;
        }
    }
    acc.map(|v| v / n.max(1) as f64)
}

/// Integrated correlation length (in rows) of the baseline residual on the fit span:
/// 1 + 2Σρ(lag) over sample lags up to 250 (0.5 s), per row, averaged; at least 1.
fn corr_length(
    y: &[[f64; NR]],
    ok: &[bool],
    cols: &[Column],
    f: &Fit,
    span: std::ops::Range<usize>,
) -> f64 {
    let r: Vec<[f64; NR]> = span
        .clone()
        .filter(|&k| ok[k])
        .map(|k| {
            let mut v = y[k];
            for (a, &c) in f.cols.iter().enumerate() {
                for i in 0..NR {
                    v[i] -= f.beta[a] * cols[c].v[k][i];
                }
            }
            v
        })
        .collect();
    let m = r.len();
    if m < 500 {
        return 1.0;
    }
    let mut tau = 0.0;
    for i in 0..NR {
        let var: f64 = r.iter().map(|v| v[i] * v[i]).sum::<f64>() / m as f64;
        if var <= 0.0 {
            continue;
        }
        let mut s = 1.0;
        for lag in 1..250 {
            let c: f64 =
                (0..m - lag).map(|k| r[k][i] * r[k + lag][i]).sum::<f64>() / (m - lag) as f64 / var;
            if c <= 0.0 {
                break;
            }
            s += 2.0 * c;
        }
        tau += s;
    }
    (tau / NR as f64).max(1.0)
}

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
    /// the parametric oscillation. The span is split in two halves on two threads; a half
    /// that does not start at sample 0 starts 0.5 s early from the record's own state.
    pub fn run(&self, span: std::ops::Range<usize>) -> anyhow::Result<Vec<LockinOut>> {
        let rec = self.rec;
        let psi = psi_of(rec);
        let (k0, k1) = (span.start, span.end.min(rec.rows.len()));
        let mid = k0 + (k1 - k0) / 2;
        let go = |a: usize, b: usize| self.chunk(&psi, a, b);
        let (a, b) = std::thread::scope(|s| {
            let h = s.spawn(|| go(mid, k1));
            let a = go(k0, mid);
            (a, h.join())
        });
        let b = b.map_err(|_| anyhow::anyhow!("the re-simulation thread panicked"))?;
        let mut out = a?;
        out.extend(b?);
        if k0 == 0 {
            // the first half starts from rest: put it on the record's branch
            let (mut same, mut flip) = (0.0, 0.0);
            for k in mid / 2..mid {
                let x = rec.rows[k].x_um[0];
                let o = out[k].x[0];
                same += (x.0 - o.0).powi(2) + (x.1 - o.1).powi(2);
                flip += (x.0 + o.0).powi(2) + (x.1 + o.1).powi(2);
            }
            if flip < same {
                for o in out.iter_mut().take(mid) {
                    o.x[0] = (-o.x[0].0, -o.x[0].1);
                    o.x[2] = (-o.x[2].0, -o.x[2].1);
                    o.y[0] = (-o.y[0].0, -o.y[0].1);
                    o.y[2] = (-o.y[2].0, -o.y[2].1);
                }
            }
        }
        Ok(out)
    }
}

/// Output error of re-simulated lock-in outputs against a record.
#[derive(Clone, Copy, Debug, Default)]
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

/// `E|Δn|²/E|n|²` of the lock-in output noise of white displacement noise (the simulator's
/// lock-in at the record's settings, gyro at rest): the error's slow part barely moves
/// from sample to sample, its noise part does, by this ratio.
pub fn lockin_noise_diff_ratio(rec: &Record) -> anyhow::Result<f64> {
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
    let mut sim = GyroSim::new(&cfg, [0.0; 4]).map_err(|e| anyhow::anyhow!("simulator: {e}"))?;
    let mut th = Theta::table2();
    th.drive[5] = 0.0;
    th.drive[6] = 0.0;
    let u = PlantInputs {
        omega: 1.0,
        s: 1.0,
        ax: 0.0,
        ay: 0.0,
    };
    let mut prev: Option<LockinOut> = None;
    let (mut dd, mut nn) = (0.0, 0.0);
    for k in 0..600 {
        sim.advance(&th, &u, &u);
        let o = sim.lockin();
        if k >= 20 {
            let v = |o: &LockinOut| {
                [
                    o.x0, o.x[0].0, o.x[0].1, o.x[2].0, o.x[2].1, o.y0, o.y[0].0, o.y[0].1,
                    o.y[2].0, o.y[2].1,
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
        let (r, o) = (&rec.rows[k], &sim[k]);
        [
            r.x0_um - o.x0 * l0,
            r.x_um[0].0 - o.x[0].0 * l0,
            r.x_um[0].1 - o.x[0].1 * l0,
            r.x_um[2].0 - o.x[2].0 * l0,
            r.x_um[2].1 - o.x[2].1 * l0,
            r.y0_um - o.y0 * l0,
            r.y_um[0].0 - o.y[0].0 * l0,
            r.y_um[0].1 - o.y[0].1 * l0,
            r.y_um[2].0 - o.y[2].0 * l0,
            r.y_um[2].1 - o.y[2].1 * l0,
        ]
    };
    let (mut ex, mut ey, mut nn, mut dd) = (0.0, 0.0, 0.0, 0.0);
    let mut prev: Option<[f64; 10]> = None;
    for k in span {
        let e = err(k);
        ex += e[..5].iter().map(|v| v * v).sum::<f64>();
        ey += e[5..].iter().map(|v| v * v).sum::<f64>();
        if let Some(p) = prev {
            dd += e.iter().zip(p).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        }
        prev = Some(e);
        let r = &rec.rows[k];
        for v in [r.x_um[0], r.x_um[2], r.y_um[0], r.y_um[2]] {
            nn += v.0 * v.0 + v.1 * v.1;
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
    let (mut x, mut xd, mut y, mut yd) = (r.x0_um / l0, 0.0, r.y0_um / l0, 0.0);
    for k in 0..3 {
        let kf = (k + 1) as f64;
        let (s, c) = (kf * psi).sin_cos();
        let (a, b) = (r.x_um[k], r.y_um[k]);
        x += (a.0 * c - a.1 * s) / l0;
        xd += kf * om * (-a.0 * s - a.1 * c) / l0;
        y += (b.0 * c - b.1 * s) / l0;
        yd += kf * om * (-b.0 * s - b.1 * c) / l0;
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
            omega_max: (pump_max / (2.0 * h.f0_hz) * 1.01).max(0.5),
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
        let start = if k0 == 0 {
            0
        } else {
            k0.saturating_sub((RESIM_OVERLAP_S * h.fs_hz) as usize)
        };
        let first = &rec.rows[start];
        let z0 = if start == 0 && first.x_abs(1) < 0.05 * h.l0_um {
            [0.01, 0.0, 0.0, 0.0] // from rest: the simulator's start-up convention
        } else {
            state_of(first, psi[start], input(start).omega, h.l0_um)
        };
        let mut sim = GyroSim::new(&simcfg, z0).map_err(|e| anyhow::anyhow!("simulator: {e}"))?;
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
                (Some(rr), _) => gpd * rr[k],
                (None, Some(g)) => g,
                (None, None) => model.phys.gamma,
            };
            let (mut d, mut s) = theta_from_physical(&phys);
            if fx.tcf_ppm_k != 0.0 {
                let tc = rec.rows[k].temp_c.unwrap_or(T_REF_C);
                fx.thermal_theta(&mut d, &mut s, phys.wx2, phys.wy2, tc);
            }
            sim.advance(&Theta { drive: d, sense: s }, &input(k), &input(k + 1));
        }
        Ok(out)
    }
}

/// The record with its lock-in channels replaced by `li` (same inputs).
fn with_lockin(rec: &Record, li: &[LockinOut]) -> Record {
    let mut r = rec.clone();
    let l0 = rec.header.l0_um;
    for (row, o) in r.rows.iter_mut().zip(li) {
        row.x0_um = o.x0 * l0;
        row.y0_um = o.y0 * l0;
        for k in 0..3 {
            row.x_um[k] = (o.x[k].0 * l0, o.x[k].1 * l0);
            row.y_um[k] = (o.y[k].0 * l0, o.y[k].1 * l0);
        }
    }
    r
}

/// Writes report.json, report.md and the plots into `dir`.
pub fn write_report(
    dir: &Path,
    d: &Diagnosis,
    record_name: &str,
) -> anyhow::Result<Vec<std::path::PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut files = Vec::new();
    let jp = dir.join("report.json");
    std::fs::write(&jp, serde_json::to_string_pretty(&d.json)? + "\n")
        .with_context(|| format!("cannot write {}", jp.display()))?;
    files.push(jp);
    files.extend(crate::diagplot::plots(dir, d)?);
    let mp = dir.join("report.md");
    std::fs::write(&mp, markdown(d, record_name))
        .with_context(|| format!("cannot write {}", mp.display()))?;
    files.push(mp);
    Ok(files)
}

/// A number with 4 significant digits (scientific when small or large).
fn g4(v: f64) -> String {
    if v == 0.0 || (1e-3..1e5).contains(&v.abs()) {
        format!("{v:.4}")
    } else {
        format!("{v:.3e}")
    }
}

fn markdown(d: &Diagnosis, record_name: &str) -> String {
    let j = &d.json;
    let f = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
    let mut s = format!("# Sim-to-real diagnosis of `{record_name}`\n\n");
    s.push_str(&format!(
        "**Verdict: `{}`**{}\n\nModel: {}. Rate: {}.\n\n",
        d.verdict,
        j["secondary"]["effect"]
            .as_str()
            .map(|e| format!(" (and `{e}`)"))
            .unwrap_or_default(),
        j["model"].as_str().unwrap_or(""),
        j["rate"]["source"].as_str().unwrap_or("")
    ));
    let ex = match d.verdict.as_str() {
        "none" => format!(
            "No significant gap: the best model closes {:.1} % of the held-out baseline row energy (threshold {:.0} %).",
            100.0 * f(&j["gap_fraction_of_baseline"]),
            100.0 * GAP_MIN
        ),
        "unknown" => format!(
            "A gap exists but no library effect explains it: the closest, `{}`, leaves {:.0} % of the held-out gap above the noise unexplained (at most {:.0} % allowed) or is not significant. An effect outside the library.",
            j["closest_library_effect"].as_str().unwrap_or("–"),
            100.0 * f(&j["unexplained_above_noise"]),
            100.0 * UNEXPLAINED_MAX
        ),
        v => format!(
            "`{v}` is significant and closes {:.0} % of the explainable held-out gap.",
            100.0 * d.ranking.first().map_or(0.0, |c| c.gap_closure)
        ),
    };
    s.push_str(&ex);
    s.push_str("\n\n## How far (held-out span)\n\n");
    s.push_str(&format!(
        "| measure | before | after | closure |\n|---|---|---|---|\n| regression gap (row energy above the floor) | {} | {} | {:.1} % |\n",
        g4(f(&j["gap_before"])),
        g4(f(&j["gap_after"])),
        100.0 * f(&j["gap_closure"])
    ));
    if !j["output_error"].is_null() {
        let o = &j["output_error"];
        s.push_str(&format!(
            "| simulator output error above the record's noise (relative rms) | {:.3e} | {:.3e} | {:.1} % |\n| simulator output error, raw (noise included) | {:.3e} | {:.3e} | {:.1} % |\n",
            f(&o["before"]["above_noise"]),
            f(&o["after"]["above_noise"]),
            100.0 * f(&o["closure"]),
            f(&o["before"]["combined"]),
            f(&o["after"]["combined"]),
            100.0 * f(&o["closure_raw"])
        ));
        s.push_str(&format!(
            "\nRe-run with: {}.\n\n![envelopes](envelopes.png)\n",
            o["added"]
                .as_array()
                .filter(|a| !a.is_empty())
                .map_or("nothing added".into(), |a| a
                    .iter()
                    .filter_map(|v| v.as_str())
                    .collect::<Vec<_>>()
                    .join(", "))
        ));
    }
    s.push_str("\n## Which\n\n| effect | size | ±1σ | gap closure | significant | ΔBIC | left explainable | coherent with |\n|---|---|---|---|---|---|---|---|\n");
    for c in &d.ranking {
        if let Some(u) = &c.untestable {
            s.push_str(&format!(
                "| {} | – | – | – | not testable: {u} | | | |\n",
                c.effect
            ));
            continue;
        }
        s.push_str(&format!(
            "| {} | {} {} | {} | {:.1} % | {} | {:.1} | {:.1} % | {} |\n",
            c.effect,
            g4(c.size),
            paragyro_simulator::effects::unit(&c.effect),
            g4(c.size_sigma),
            100.0 * c.gap_closure,
            if c.significant { "yes" } else { "no" },
            c.delta_bic,
            100.0 * c.residual_explainable,
            c.coherent_with.join(", ")
        ));
    }
    if let Some(sep) = j["separating_excitation"]
        .as_array()
        .filter(|a| !a.is_empty())
    {
        s.push_str("\nWhat this record cannot separate, and the excitation that would:\n\n");
        for v in sep {
            s.push_str(&format!(
                "- {}: {}\n",
                v["pair"].as_array().map_or(String::new(), |a| a
                    .iter()
                    .filter_map(|x| x.as_str())
                    .collect::<Vec<_>>()
                    .join(" vs ")),
                v["excitation"].as_str().unwrap_or("")
            ));
        }
    }
    s.push_str("\n![ranking](ranking.png)\n\n## Where\n\n");
    s.push_str(&format!(
        "Axis: drive {:.0} %, sense {:.0} % of the explainable gap energy.\n\n| channel | share |\n|---|---|\n",
        100.0 * f(&j["where"]["axis"]["drive"]),
        100.0 * f(&j["where"]["axis"]["sense"])
    ));
    if let Some(m) = j["where"]["channel"].as_object() {
        for (k, v) in m {
            s.push_str(&format!("| {k} | {:.1} % |\n", 100.0 * f(v)));
        }
    }
    s.push_str("\nRegimes (gap density per tercile relative to the mean; correlation of the per-sample gap with the quantity):\n\n| quantity | low | mid | high | correlation |\n|---|---|---|---|---|\n");
    if let Some(rs) = j["where"]["regime"].as_array() {
        for r in rs {
            let b = |i: usize| f(&r["terciles"][i]["relative_gap_density"]);
            s.push_str(&format!(
                "| {} | {:.2} | {:.2} | {:.2} | {:+.2} |\n",
                r["quantity"].as_str().unwrap_or(""),
                b(0),
                b(1),
                b(2),
                f(&r["correlation"])
            ));
        }
    }
    let tm = &j["where"]["time"];
    s.push_str(&format!(
        "\nTime: half of the gap energy lies within {:.1}–{:.1} s ({:.0} % of the time); the CUSUM of the windowed gap peaks at {:.1} s.\n\n![where](where.png)\n![time](time.png)\n",
        f(&tm["half_of_gap_within_s"][0]),
        f(&tm["half_of_gap_within_s"][1]),
        100.0 * f(&tm["fraction_of_time_holding_half"]),
        f(&tm["cusum_extreme_at_s"])
    ));
    s.push_str(&format!(
        "\n## Method\n\nThe record's rows about the model (the core's estimator, never re-linearised, rows weighted to unit noise) minus the rows of the simulator re-run on the record's inputs; each library effect fitted with the rate on the fit span {:.1}–{:.1} s and scored on the held-out span {:.1}–{:.1} s (guard {GUARD_S} s). The floor is the best held-out energy of any model: each effect, the catch-all (14 θ free plus the quadratic and cubic force monomials), and both together. Thresholds: size/σ ≥ {T_SIG}, gap ≥ {:.0} % of the baseline, verdict share ≥ {:.0} % of the explainable gap, at most {:.0} % of the gap above the noise left unexplained. See docs/diagnosis.md.\n",
        f(&j["spans_s"]["fit"][0]),
        f(&j["spans_s"]["fit"][1]),
        f(&j["spans_s"]["held_out"][0]),
        f(&j["spans_s"]["held_out"][1]),
        100.0 * GAP_MIN,
        100.0 * SHARE_MIN,
        100.0 * UNEXPLAINED_MAX
    ));
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_of_known_waveforms() {
        // f = 1 + 2cos φ − 3 sin 3φ → [f]0 = 1, [f]1 = 2, [f]3 = 3i (e^{−ikφ} convention)
        let mut f = [0.0; NSYN];
        for j in 0..NSYN {
            let ph = TAU * j as f64 / NSYN as f64;
            f[j] = 1.0 + 2.0 * ph.cos() - 3.0 * (3.0 * ph).sin();
        }
        let p = ProjTables::new().project(&f);
        for (a, b) in p.iter().zip([1.0, 2.0, 0.0, 0.0, 3.0]) {
            assert!((a - b).abs() < 1e-12, "{p:?}");
        }
    }

    #[test]
    fn spd_solver_handles_collinear_columns() {
        // two identical columns: the solve must stay finite and reproduce b
        let g = [2.0, 2.0, 2.0, 2.0];
        let (x, _) = solve_spd(&g, &[4.0, 4.0], 2);
        assert!(x.iter().all(|v| v.is_finite()));
        assert!((2.0 * x[0] + 2.0 * x[1] - 4.0).abs() < 1e-6, "{x:?}");
        let g = [4.0, 1.0, 1.0, 3.0];
        let (x, inv) = solve_spd(&g, &[1.0, 2.0], 2);
        assert!((4.0 * x[0] + x[1] - 1.0).abs() < 1e-9 && (x[0] + 3.0 * x[1] - 2.0).abs() < 1e-9);
        assert!((inv[0] - 3.0 / 11.0).abs() < 1e-9);
    }
}
