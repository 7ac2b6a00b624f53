//! The rate's scale factor and bias against the die temperature, from a run whose rate
//! alternates between +Ω and −Ω (`host-sim/scenarios/sweep.toml`): per temperature bin,
//! the mean fast rate over the samples at +Ω (m₊) and at −Ω (m₋), each side's first
//! second after reaching the rate left out (the rate channel's step response), give the
//! scale factor's error k = (m₊ − m₋)/(2Ω) − 1 and the bias b = (m₊ + m₋)/2.

use serde::Serialize;

use crate::trace::TraceRow;

/// A side's samples are taken from this long after the true rate reached it, s.
pub const SETTLE_S: f64 = 1.0;

/// One temperature bin of the scale factor and bias.
#[derive(Clone, Debug, Serialize)]
pub struct ScaleBin {
    /// The bin's centre, °C.
    pub temp_c: f64,
    /// Samples at +Ω and at −Ω.
    pub samples: (usize, usize),
    /// The scale factor's error, ppm.
    pub scale_err_ppm: f64,
    /// The bias, °/s.
    pub bias_dps: f64,
}

/// The bins of `width_k` over the rows of `during` (in time order); empty unless the true
/// rate takes both signs at the same magnitude.
pub fn scale_bins(during: &[&TraceRow], width_k: f64) -> Vec<ScaleBin> {
    let omega = during
        .iter()
        .map(|r| r.rate_dps_true.abs())
        .fold(0.0, f64::max);
    let at = |r: &TraceRow| (r.rate_dps_true.abs() - omega).abs() <= 1e-6 * omega;
    // the rows at ±Ω for SETTLE_S already, with their sign
    let mut since: Option<(f64, f64)> = None;
    let mut taken: Vec<(f64, f64, f64)> = Vec::new();
    for r in during {
        if !at(r) {
            since = None;
            continue;
        }
        let sign = r.rate_dps_true.signum();
        let start = match since {
            Some((t0, s)) if s == sign => t0,
            _ => r.t_s,
        };
        since = Some((start, sign));
        if r.t_s - start >= SETTLE_S && r.rate_dps_est.is_finite() {
            taken.push((r.temp_c, sign, r.rate_dps_est));
        }
    }
    let both = taken.iter().any(|t| t.1 > 0.0) && taken.iter().any(|t| t.1 < 0.0);
    if !(omega > 0.0 && both && width_k > 0.0) {
        return Vec::new();
    }
    let lo = taken.iter().map(|t| t.0).fold(f64::INFINITY, f64::min);
    let hi = taken.iter().map(|t| t.0).fold(f64::NEG_INFINITY, f64::max);
    let mut bins = Vec::new();
    let mut k = (lo / width_k).floor() * width_k;
    while k <= hi {
        let side = |s: f64| {
            let v: Vec<f64> = taken
                .iter()
                .filter(|t| t.1 == s && t.0 >= k && t.0 < k + width_k)
                .map(|t| t.2)
                .collect();
            (v.iter().sum::<f64>() / v.len().max(1) as f64, v.len())
        };
        let ((mp, np), (mn, nn)) = (side(1.0), side(-1.0));
        if np > 0 && nn > 0 {
            bins.push(ScaleBin {
                temp_c: k + 0.5 * width_k,
                samples: (np, nn),
                scale_err_ppm: ((mp - mn) / (2.0 * omega) - 1.0) * 1e6,
                bias_dps: 0.5 * (mp + mn),
            });
        }
        k += width_k;
    }
    bins
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(t_s: f64, temp_c: f64, truth: f64, est: f64) -> TraceRow {
        TraceRow {
            t_s,
            temp_c,
            rate_dps_true: truth,
            rate_dps_est: est,
            ..TraceRow::default()
        }
    }

    #[test]
    fn a_gain_and_an_offset_are_told_apart_per_bin() {
        // est = (1 + 200 ppm)·truth + 0.05 °/s, ±150 °/s alternating every 10 s
        let rows: Vec<TraceRow> = (0..40_000)
            .map(|k| {
                let t = k as f64 * 0.002;
                let truth = if ((t / 10.0) as u64).is_multiple_of(2) {
                    150.0
                } else {
                    -150.0
                };
                // the first second after each switch: a transient that must be left out
                let glitch = if t % 10.0 < 0.5 { 30.0 } else { 0.0 };
                row(
                    t,
                    20.0 + 0.25 * t,
                    truth,
                    truth * (1.0 + 200e-6) + 0.05 + glitch,
                )
            })
            .collect();
        let during: Vec<&TraceRow> = rows.iter().collect();
        let bins = scale_bins(&during, 5.0);
        assert_eq!(bins.len(), 4);
        for b in &bins {
            assert!((b.scale_err_ppm - 200.0).abs() < 1e-6, "{b:?}");
            assert!((b.bias_dps - 0.05).abs() < 1e-9, "{b:?}");
        }
        // a constant rate: no bins
        let one: Vec<&TraceRow> = rows.iter().filter(|r| r.rate_dps_true > 0.0).collect();
        assert!(scale_bins(&one, 5.0).is_empty());
    }
}
