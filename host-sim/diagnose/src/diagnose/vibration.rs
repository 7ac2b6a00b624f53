//! The angular vibration's columns: γ1 at a beat against the pump centre that the record
//! does not state, so the beat is scanned (a coarse grid of ±[`VIB_BEAT_MAX_HZ`] in
//! 0.1 Hz steps, in parallel, then a golden-section refinement) for the largest drop of
//! the fit-span energy.

use std::f64::consts::TAU;

use paragyro_core::rows::NROWS;
use paragyro_core::svf::SvfCoeffs;
use paragyro_simulator::record::Record;

use super::columns::{ColFilter, Column, ColumnId, NSYN, ProjTables, synth};
use super::lsq::Bank;
use super::rows::{Pass, Rows, Spans, first_pump_hz, psi_of};
use super::{NR, VIB_BEAT_MAX_HZ, VIB_BEAT_STEP_HZ};

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
            id: ColumnId::Vibration(false),
            v: cr,
        },
        Column {
            id: ColumnId::Vibration(true),
            v: ci,
        },
    ]
}

/// The vibration's in-phase and quadrature columns at `beat` about `rows`: about a run of
/// the record with the vibration in it, the Gauss–Newton step of its confirmation
/// ([`super::confirm`]).
pub(crate) fn columns_at(rec: &Record, rows: &Rows, beat: f64) -> [Column; 2] {
    let psi = psi_of(rec);
    let f_ref = first_pump_hz(rec);
    let vbasis = vib_basis(&rows.base, TAU * f_ref / rows.omega0);
    vibration_columns(&rows.base, &vbasis, &rows.svf, &psi, &rows.t, f_ref + beat)
}

/// The beat (Hz) whose vibration columns most reduce the fit-span energy on top of the
/// baseline columns `base_cols`, and those columns.
pub(crate) fn scan_beat(
    rec: &Record,
    rows: &Rows,
    spans: &Spans,
    base_cols: &[Column],
) -> anyhow::Result<(f64, [Column; 2])> {
    let psi = psi_of(rec);
    let f_ref = first_pump_hz(rec);
    let n_base = base_cols.len();
    // Ω_v/ω0 ≈ the pump's: its spread over the scan (±6 Hz of 21.9 kHz) is 3e-4 of γ'
    let vbasis = vib_basis(&rows.base, TAU * f_ref / rows.omega0);
    let scan = |beat: f64| -> (f64, [Column; 2]) {
        let vc = vibration_columns(&rows.base, &vbasis, &rows.svf, &psi, &rows.t, f_ref + beat);
        let c: Vec<&[[f64; NR]]> = base_cols
            .iter()
            .chain(vc.iter())
            .map(|c| c.v.as_slice())
            .collect();
        let bank = Bank::build(&c, &rows.y, &rows.usable, &spans.fit_blocks, 0..0);
        let f0 = bank.fit(&(0..n_base).collect::<Vec<_>>());
        let f1 = bank.fit(&(0..n_base + 2).collect::<Vec<_>>());
        (f0.e_fit - f1.e_fit, vc)
    };
    let steps = (VIB_BEAT_MAX_HZ / VIB_BEAT_STEP_HZ).round() as i64;
    let grid: Vec<f64> = (-steps..=steps)
        .map(|i| i as f64 * VIB_BEAT_STEP_HZ)
        .collect();
    let scores = paragyro_simulator::par::try_map(
        &grid,
        |b| format!("the vibration's beat scan at {b:+.1} Hz"),
        |&b| Ok((b, scan(b).0)),
    )?;
    let mut best_beat = (f64::MIN, 0.0);
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
        let s = paragyro_simulator::par::try_map(
            &[m1, m2],
            |b| format!("the vibration's beat refinement at {b:+.4} Hz"),
            |&b| Ok(scan(b).0),
        )?;
        if s[0] > s[1] {
            hi = m2;
        } else {
            lo = m1;
        }
    }
    let beat = 0.5 * (lo + hi);
    Ok((beat, scan(beat).1))
}
