//! Stage 5, where the gap lies: its share by axis × channel, its density over the
//! operating regimes (drive amplitude, detuning, dither phase, die temperature), and over
//! time (0.5 s windows, their CUSUM, the span holding half of it); and the held-out energy
//! per row of the baseline, the closest library effect and everything.

use std::collections::BTreeMap;

use paragyro_core::rows::NROWS;
use paragyro_simulator::record::Record;
use serde::{Deserialize, Serialize};

use super::lsq::Fit;
use super::rows::{Rows, Spans};
use super::verdict::{Answer, Decision};
use super::{NR, Options, Stage};

/// Where the gap lies (report.json's `where`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Where {
    /// Share of the explainable gap energy by axis.
    pub axis: AxisShare,
    /// Share by axis and channel, keyed `drive/DC`, `sense/1st in-phase`, ….
    pub channel: BTreeMap<String, f64>,
    /// Gap density over the operating regimes.
    pub regime: Vec<Regime>,
    /// Where in time.
    pub time: TimeSpan,
}

/// Share of the explainable gap energy on each axis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AxisShare {
    pub drive: f64,
    pub sense: f64,
}

/// The gap density per tercile of a quantity, and its correlation with the gap.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Regime {
    /// The quantity (with its unit).
    pub quantity: String,
    /// Low, middle, high third of the samples sorted by the quantity.
    pub terciles: Vec<Tercile>,
    /// Pearson correlation of the per-sample gap with the quantity.
    pub correlation: f64,
}

/// One third of the samples.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Tercile {
    /// The quantity's range (`None` when the third is empty).
    pub from: Option<f64>,
    pub to: Option<f64>,
    /// Mean gap in this third over the mean gap.
    pub relative_gap_density: f64,
}

/// Where in time the gap lies.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TimeSpan {
    /// The windows holding the top half of the gap energy lie within this span, s.
    pub half_of_gap_within_s: [f64; 2],
    /// The fraction of the windows holding that half.
    pub fraction_of_time_holding_half: f64,
    /// Where the CUSUM of the windowed gap peaks, s.
    pub cusum_extreme_at_s: f64,
}

/// Held-out energy per sample of one row (report.json's `held_out_by_row`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RowEnergy {
    /// The row (index into [`super::ROW_LABELS`]).
    pub row: usize,
    /// After the baseline fit.
    pub baseline: f64,
    /// After the closest library effect.
    pub closest: f64,
    /// After everything (the floor's model).
    pub everything: f64,
}

/// The report's part of this stage.
pub(crate) struct Located {
    pub location: Where,
    pub by_row: Vec<RowEnergy>,
}

/// The plots' part of this stage.
pub(crate) struct LocatePlots {
    /// Time of each usable sample, s.
    pub t: Vec<f64>,
    pub e_base: Vec<f64>,
    pub e_after: Vec<f64>,
    pub shares: Vec<(String, f64)>,
    pub windows: Vec<(f64, f64)>,
    pub cusum: Vec<(f64, f64)>,
}

/// Both parts.
pub(crate) struct Place {
    pub report: Located,
    pub plots: LocatePlots,
}

const CHANNELS: [&str; NROWS] = [
    "DC",
    "1st in-phase",
    "1st quadrature",
    "3rd in-phase",
    "3rd quadrature",
];

/// Where the gap lies.
pub(crate) fn locate(st: &Stage<'_>, decision: &Decision) -> Place {
    let Stage {
        rec,
        opts,
        rows,
        spans,
        cols,
        fits,
    } = *st;
    let refs: Vec<&[[f64; NR]]> = cols.cols.iter().map(|c| c.v.as_slice()).collect();
    let resid = |f: &Fit, k: usize| f.resid(&rows.y, &refs, k);
    let closest_fit = match decision.closest {
        Answer::Effect(e) => fits.of(e).unwrap_or(&fits.base_fit),
        Answer::None | Answer::Unknown => &fits.base_fit,
    };
    let by_row = by_row(
        rows,
        spans,
        [&fits.base_fit, closest_fit, &fits.floor_fit],
        &resid,
    );
    // per usable sample: the gap (baseline − floor) by row, energies before and after
    let ks: Vec<usize> = (spans.first..=spans.last)
        .filter(|&k| rows.usable[k])
        .collect();
    let mut share = [0.0f64; NR];
    let mut e_base = Vec::with_capacity(ks.len());
    let mut e_after = Vec::with_capacity(ks.len());
    let mut gap_k = Vec::with_capacity(ks.len());
    for &k in &ks {
        let r0 = resid(&fits.base_fit, k);
        let rf = resid(&fits.floor_fit, k);
        let ra = resid(&decision.after_fit, k);
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
    let mut shares = Vec::new();
    let mut channel = BTreeMap::new();
    for (ax, axn) in ["drive", "sense"].iter().enumerate() {
        for (c, cn) in CHANNELS.iter().enumerate() {
            let v = share[ax * NROWS + c].max(0.0) / tot;
            shares.push((format!("{axn} {cn}"), v));
            channel.insert(format!("{axn}/{cn}"), v);
        }
    }
    let axis_share = |ax: usize| -> f64 {
        (0..NROWS)
            .map(|c| share[ax * NROWS + c].max(0.0))
            .sum::<f64>()
            / tot
    };
    let regime = regimes(rec, opts, rows, &ks, &gap_k);
    let (windows, cusum, time) = in_time(rows, &ks, &gap_k);
    Place {
        report: Located {
            location: Where {
                axis: AxisShare {
                    drive: axis_share(0),
                    sense: axis_share(1),
                },
                channel,
                regime,
                time,
            },
            by_row,
        },
        plots: LocatePlots {
            t: ks.iter().map(|&k| rows.t[k]).collect(),
            e_base,
            e_after,
            shares,
            windows,
            cusum,
        },
    }
}

/// Held-out energy per row (per sample) of the baseline, closest and everything fits.
fn by_row(
    rows: &Rows,
    spans: &Spans,
    fits: [&Fit; 3],
    resid: &dyn Fn(&Fit, usize) -> [f64; NR],
) -> Vec<RowEnergy> {
    let mut acc = [[0.0f64; 3]; NR];
    let mut cnt = 0usize;
    for k in spans.hold.clone().filter(|&k| rows.usable[k]) {
        cnt += 1;
        for (j, f) in fits.iter().enumerate() {
            let r = resid(f, k);
            for i in 0..NR {
                acc[i][j] += r[i] * r[i];
            }
        }
    }
    let c = cnt.max(1) as f64;
    (0..NR)
        .map(|i| RowEnergy {
            row: i,
            baseline: acc[i][0] / c,
            closest: acc[i][1] / c,
            everything: acc[i][2] / c,
        })
        .collect()
}

/// Gap density per tercile of the amplitude, detuning, dither phase and temperature.
fn regimes(rec: &Record, opts: &Options, rows: &Rows, ks: &[usize], gap_k: &[f64]) -> Vec<Regime> {
    let n = rows.t.len();
    let regime = |vals: &dyn Fn(usize) -> f64, name: &str| -> Regime {
        // finite pairs only (a row the reader kept with NaN has no place in a tercile)
        let mut v: Vec<(f64, f64)> = ks
            .iter()
            .zip(gap_k)
            .map(|(&k, &g)| (vals(k), g))
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .collect();
        // a total order (a comparator that calls NaN equal to everything is not one, and
        // the standard library's sort may panic on it since Rust 1.81): NaN last
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        let m = v.len();
        let mean_all = v.iter().map(|p| p.1).sum::<f64>() / m.max(1) as f64;
        let terciles = (0..3)
            .map(|b| {
                let s = &v[m * b / 3..m * (b + 1) / 3];
                let mean = s.iter().map(|p| p.1).sum::<f64>() / s.len().max(1) as f64;
                Tercile {
                    from: s.first().map(|p| p.0),
                    to: s.last().map(|p| p.0),
                    relative_gap_density: if mean_all.abs() > 0.0 {
                        mean / mean_all
                    } else {
                        0.0
                    },
                }
            })
            .collect();
        let correlation = pearson(
            &v.iter().map(|p| p.0).collect::<Vec<_>>(),
            &v.iter().map(|p| p.1).collect::<Vec<_>>(),
        );
        Regime {
            quantity: name.into(),
            terciles,
            correlation,
        }
    };
    let amp = |k: usize| rec.rows[k].x_abs(1);
    let fy_model = rec.header.f0_hz * opts.model.phys.wy2.sqrt();
    let detune = |k: usize| rec.rows[k].pump_hz / 2.0 - fy_model;
    // dither phase: pump deviation from its 1 s running mean → angle of (dev, d dev/dt)
    let pump: Vec<f64> = rec.rows.iter().map(|r| r.pump_hz).collect();
    let dev = deviation(&pump, (rows.fs as usize).max(1));
    let dither_phase = |k: usize| {
        let d = dev[k];
        let dd = if k + 1 < n && k > 0 {
            dev[k + 1] - dev[k - 1]
        } else {
            0.0
        };
        dd.atan2(d)
    };
    let mut out = vec![
        regime(&amp, "drive amplitude (µm)"),
        regime(&detune, "detuning Ω/2π − f_y,model (Hz)"),
        regime(&dither_phase, "dither phase (rad)"),
    ];
    if let Some(tc) = &rows.temps {
        out.push(regime(&|k| tc[k], "die temperature (°C)"));
    }
    out
}

/// (t, value) points of a curve.
type Curve = Vec<(f64, f64)>;

/// The gap in 0.5 s windows, their CUSUM, and the span holding the top half of the gap.
fn in_time(rows: &Rows, ks: &[usize], gap_k: &[f64]) -> (Curve, Curve, TimeSpan) {
    let win = (0.5 * rows.fs) as usize;
    let mut windows = Vec::new();
    for c in ks.chunks(win.max(1)).zip(gap_k.chunks(win.max(1))) {
        let tm = rows.t[c.0[c.0.len() / 2]];
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
    let mut sorted: Vec<(f64, f64)> = windows.clone();
    // largest first, NaN last (a total order: see `regimes`)
    sorted.sort_by(|a, b| nan_low(b.1).total_cmp(&nan_low(a.1)));
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
    let time = TimeSpan {
        half_of_gap_within_s: [lo, hi],
        fraction_of_time_holding_half: ts_top.len() as f64 / windows.len().max(1) as f64,
        cusum_extreme_at_s: cmax.1,
    };
    (windows, cusum, time)
}

/// `v`, with NaN as −∞ (sorted last in a descending order).
pub(crate) fn nan_low(v: f64) -> f64 {
    if v.is_nan() { f64::NEG_INFINITY } else { v }
}

/// Pearson correlation of `a` and `b` (0 when either is constant or too short).
pub(crate) fn pearson(a: &[f64], b: &[f64]) -> f64 {
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
pub(crate) fn deviation(v: &[f64], w: usize) -> Vec<f64> {
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
