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

/// The record's dither lines, Hz: the strongest periodic modulation of its pump frequency
/// and of its pump amplitude (each searched over [`DITHER_LINE_HZ`] on the inputs' first
/// differences, so that a step of the pump amplitude does not read as a low line), where
/// an input moves at all. The calibrated model's error at the dither lives at these lines
/// and their harmonics, and the beat scan finds it there: on the project's generator
/// (dither 5 Hz) the scan's best sits at ±4.98–5.01 Hz on 30 of blind run 20's 100 records,
/// up to 7.9σ on a record that reads `none` (docs/notes.md, "A vibration at the noise").
pub(crate) fn dither_lines(rec: &Record) -> Vec<f64> {
    let t: Vec<f64> = rec.rows.iter().map(|r| r.t_s).collect();
    let freq: Vec<f64> = rec.rows.iter().map(|r| r.pump_hz).collect();
    let amp: Vec<f64> = rec.rows.iter().map(|r| r.pump_amp_v).collect();
    [freq, amp]
        .iter()
        .filter_map(|v| strongest_line(&t, v))
        .collect()
}

/// The search range of a dither line, Hz, and its coarse step.
pub(crate) const DITHER_LINE_HZ: (f64, f64) = (0.2, 20.0);
const DITHER_LINE_STEP_HZ: f64 = 0.02;

/// The frequency (Hz) of the periodogram's peak of `v`'s first differences over
/// [`DITHER_LINE_HZ`], refined by golden section; `None` when `v` does not move (or has
/// fewer than 100 finite samples).
fn strongest_line(t: &[f64], v: &[f64]) -> Option<f64> {
    let d: Vec<(f64, f64)> = t
        .windows(2)
        .zip(v.windows(2))
        .filter(|(tt, vv)| tt.iter().chain(vv.iter()).all(|x| x.is_finite()))
        .map(|(tt, vv)| (0.5 * (tt[0] + tt[1]), vv[1] - vv[0]))
        .collect();
    if d.len() < 100 {
        return None;
    }
    let scale = v
        .iter()
        .filter(|x| x.is_finite())
        .fold(0.0_f64, |a, x| a.max(x.abs()));
    if !d.iter().any(|&(_, x)| x.abs() > 1e-9 * scale.max(1e-300)) {
        return None;
    }
    let power = |f: f64| {
        let w = TAU * f;
        let (mut re, mut im) = (0.0, 0.0);
        for &(tk, x) in &d {
            let (s, c) = (w * tk).sin_cos();
            re += x * c;
            im += x * s;
        }
        re * re + im * im
    };
    let (lo, hi) = DITHER_LINE_HZ;
    let n = ((hi - lo) / DITHER_LINE_STEP_HZ).round() as usize;
    let mut best = (f64::MIN, lo);
    for i in 0..=n {
        let f = lo + i as f64 * DITHER_LINE_STEP_HZ;
        let p = power(f);
        if p > best.0 {
            best = (p, f);
        }
    }
    let (mut a, mut b) = (best.1 - DITHER_LINE_STEP_HZ, best.1 + DITHER_LINE_STEP_HZ);
    for _ in 0..12 {
        let m1 = a + 0.382 * (b - a);
        let m2 = a + 0.618 * (b - a);
        if power(m1) > power(m2) {
            b = m2;
        } else {
            a = m1;
        }
    }
    Some(0.5 * (a + b))
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

#[cfg(test)]
mod tests {
    use super::strongest_line;

    /// The pump's dither lines as the generators write them: a 5 Hz frequency dither of
    /// ±21.6 Hz, and a 1.3 Hz amplitude dither of 10 % on top of two amplitude steps
    /// (0.85 at 8 s, 1.15 at 14 s), which do not read as a low line; a constant input has
    /// none.
    #[test]
    fn the_dither_lines_are_found_past_the_amplitude_steps() {
        let t: Vec<f64> = (0..10_001).map(|k| k as f64 / 500.0).collect();
        let on = |tk: f64| if tk >= 1.0 { 1.0 } else { 0.0 };
        let freq: Vec<f64> = t
            .iter()
            .map(|&tk| 21_880.0 + on(tk) * 21.6 * (std::f64::consts::TAU * 5.0 * tk).sin())
            .collect();
        let amp: Vec<f64> = t
            .iter()
            .map(|&tk| {
                let s = if tk >= 14.0 {
                    1.15
                } else if tk >= 8.0 {
                    0.85
                } else {
                    1.0
                };
                s * (1.0 + on(tk) * 0.1 * (std::f64::consts::TAU * 1.3 * tk).sin())
            })
            .collect();
        let f = strongest_line(&t, &freq).unwrap();
        assert!((f - 5.0).abs() < 0.005, "{f}");
        let f = strongest_line(&t, &amp).unwrap();
        assert!((f - 1.3).abs() < 0.005, "{f}");
        assert_eq!(strongest_line(&t, &vec![21_880.0; t.len()]), None);
    }
}
