//! The excitation protocol of a record, drawn per record and written without a core in
//! the loop (open loop): the pump centred on the device's sense resonance with a
//! frequency dither of 2–6 Hz, a pump-amplitude dither and two pump-amplitude steps, a
//! rate with, in part of the records, a rate-table reversal, accelerations with a slow
//! wobble, and a die temperature ramp.
//!
//! Between two samples the pump frequency, the pump scale and the accelerations move
//! linearly (the record format's convention: the DDS is updated at 500 Hz and is
//! phase-continuous); the rate and the temperature are smooth functions of time.

use rand::Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::{PI, TAU};

/// A smooth step (raised cosine) from 0 at `t0` to 1 at `t0 + len`.
fn smooth_step(t: f64, t0: f64, len: f64) -> f64 {
    if t <= t0 {
        0.0
    } else if t >= t0 + len {
        1.0
    } else {
        0.5 - 0.5 * (PI * (t - t0) / len).cos()
    }
}

/// A pump-amplitude step: s moves to `s` from `t_s` over `ramp_s`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScaleStep {
    /// Start, s.
    pub t_s: f64,
    /// The new pump scale.
    pub s: f64,
    /// Ramp length, s.
    pub ramp_s: f64,
}

/// A rate-table reversal: Ω goes from +R to −R as R·cos(π(t − t0)/T).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reversal {
    /// Start, s.
    pub t_s: f64,
    /// Duration, s.
    pub ramp_s: f64,
}

/// A sine added to the rate from `t_s` on: `amplitude_dps·sin(2π·freq_hz·(t − t_s))`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RateSine {
    /// Start, s.
    pub t_s: f64,
    /// Amplitude, °/s.
    pub amplitude_dps: f64,
    /// Frequency, Hz.
    pub freq_hz: f64,
}

/// The drawn protocol of one record (labels' `protocol`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Protocol {
    /// Duration, s (rows at 0, 1/fs, …, duration).
    pub duration_s: f64,
    /// Sample rate, Hz.
    pub fs_hz: f64,
    /// Pump centre, Hz (twice the drawn device's sense frequency).
    pub pump_centre_hz: f64,
    /// Frequency dither: amplitude, Hz.
    pub dither_amp_hz: f64,
    /// Frequency dither: frequency, Hz.
    pub dither_freq_hz: f64,
    /// Amplitude dither: relative amplitude of s.
    pub scale_dither_frac: f64,
    /// Amplitude dither: frequency, Hz.
    pub scale_dither_freq_hz: f64,
    /// Both dithers start here (raised-cosine taper over 0.5 s), s.
    pub dither_start_s: f64,
    /// Pump-amplitude steps (s = 1 before the first).
    pub scale_steps: Vec<ScaleStep>,
    /// The rate before any reversal, °/s.
    pub rate_dps: f64,
    /// The rate-table reversal, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reversal: Option<Reversal>,
    /// A sine added to the rate, if any (not drawn; for comparisons).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_sine: Option<RateSine>,
    /// Mean accelerations, m/s².
    pub accel_mps2: [f64; 2],
    /// Acceleration wobble: amplitude, m/s² (both axes, in phase quadrature).
    pub accel_wobble_mps2: f64,
    /// Acceleration wobble: frequency, Hz.
    pub accel_wobble_hz: f64,
    /// Die temperature at the start, °C.
    pub temp_start_c: f64,
    /// Its linear rise over the record, K.
    pub temp_rise_k: f64,
    /// V_A0 of the record's header, V.
    pub pump_amp_ref_v: f64,
    /// Tabulated pump and accelerations per row (replaces the dithers, the steps and the
    /// wobble; for replaying another record's inputs), not in the labels.
    #[serde(skip)]
    pub table: Option<Table>,
}

/// Per-row pump frequency (Hz), pump scale and accelerations (m/s²).
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// Pump frequency per row, Hz.
    pub pump_hz: Vec<f64>,
    /// Pump scale per row.
    pub s: Vec<f64>,
    /// Accelerations per row, m/s².
    pub accel: Vec<[f64; 2]>,
}

/// The dither envelope: 0 before the start, a 0.5 s raised-cosine taper, then 1.
const TAPER_S: f64 = 0.5;

impl Protocol {
    /// A plain protocol: no dither, no steps, no reversal, no wobble, 25 °C.
    pub fn plain(duration_s: f64, pump_centre_hz: f64, rate_dps: f64, accel: [f64; 2]) -> Self {
        Self {
            duration_s,
            fs_hz: 500.0,
            pump_centre_hz,
            dither_amp_hz: 0.0,
            dither_freq_hz: 0.0,
            scale_dither_frac: 0.0,
            scale_dither_freq_hz: 0.0,
            dither_start_s: 0.0,
            scale_steps: Vec::new(),
            rate_dps,
            reversal: None,
            rate_sine: None,
            accel_mps2: accel,
            accel_wobble_mps2: 0.0,
            accel_wobble_hz: 0.0,
            temp_start_c: 25.0,
            temp_rise_k: 0.0,
            pump_amp_ref_v: 1.0,
            table: None,
        }
    }

    /// Draws a protocol of `duration_s` for a device whose pump centre is
    /// `pump_centre_hz`, at `rate_dps` and `accel_mps2` (the device draw's), with a
    /// rate-table reversal with probability `reversal_share`.
    pub fn draw(
        rng: &mut impl Rng,
        duration_s: f64,
        pump_centre_hz: f64,
        rate_dps: f64,
        accel_mps2: [f64; 2],
        temp_rise_k: f64,
        reversal_share: f64,
    ) -> Self {
        let d = duration_s;
        let mut u = |a: f64, b: f64| a + (b - a) * rng.random::<f64>();
        let dither_amp_hz = u(15.0, 30.0);
        let dither_freq_hz = u(2.0, 6.0);
        let scale_dither_frac = u(0.05, 0.12);
        let scale_dither_freq_hz = u(0.8, 2.0);
        let dither_start_s = u(0.5, 1.5).min(0.1 * d);
        let scale_steps = vec![
            ScaleStep {
                t_s: u(0.3, 0.45) * d,
                s: u(0.82, 0.92),
                ramp_s: u(0.1, 0.3),
            },
            ScaleStep {
                t_s: u(0.6, 0.75) * d,
                s: u(1.08, 1.18),
                ramp_s: u(0.1, 0.3),
            },
        ];
        let reversal = (u(0.0, 1.0) < reversal_share).then(|| Reversal {
            t_s: u(0.35, 0.65) * d,
            ramp_s: u(0.2, 1.0).min(0.2 * d),
        });
        let accel_wobble_mps2 = u(0.0, 0.5);
        let accel_wobble_hz = u(0.2, 2.0);
        let temp_start_c = u(23.0, 27.0);
        Self {
            duration_s,
            fs_hz: 500.0,
            pump_centre_hz,
            dither_amp_hz,
            dither_freq_hz,
            scale_dither_frac,
            scale_dither_freq_hz,
            dither_start_s,
            scale_steps,
            rate_dps,
            reversal,
            rate_sine: None,
            accel_mps2,
            accel_wobble_mps2,
            accel_wobble_hz,
            temp_start_c,
            temp_rise_k,
            pump_amp_ref_v: 1.0,
            table: None,
        }
    }

    /// Number of sample intervals (rows − 1).
    pub fn intervals(&self) -> usize {
        (self.duration_s * self.fs_hz).round() as usize
    }

    /// Time of row `k`, s.
    pub fn t(&self, k: usize) -> f64 {
        k as f64 / self.fs_hz
    }

    /// The table's row at `t` (the rows are the only instants at which the tabulated
    /// inputs are asked for).
    fn tab(&self, t: f64) -> Option<(&Table, usize)> {
        self.table.as_ref().map(|tb| {
            let k = ((t * self.fs_hz).round().max(0.0) as usize).min(tb.pump_hz.len() - 1);
            (tb, k)
        })
    }

    fn envelope(&self, t: f64) -> f64 {
        smooth_step(t, self.dither_start_s, TAPER_S)
    }

    /// The pump frequency in effect at `t`, Hz (sampled at the rows).
    pub fn pump_hz(&self, t: f64) -> f64 {
        if let Some((tb, k)) = self.tab(t) {
            return tb.pump_hz[k];
        }
        let ph = TAU * self.dither_freq_hz * (t - self.dither_start_s);
        self.pump_centre_hz + self.dither_amp_hz * self.envelope(t) * ph.sin()
    }

    /// The pump scale s at `t` (sampled at the rows).
    pub fn pump_scale(&self, t: f64) -> f64 {
        if let Some((tb, k)) = self.tab(t) {
            return tb.s[k];
        }
        let mut s = 1.0;
        for st in &self.scale_steps {
            s += (st.s - s) * smooth_step(t, st.t_s, st.ramp_s);
        }
        let ph = TAU * self.scale_dither_freq_hz * (t - self.dither_start_s);
        s * (1.0 + self.scale_dither_frac * self.envelope(t) * ph.sin())
    }

    /// The accelerations at `t`, m/s² (sampled at the rows).
    pub fn accel(&self, t: f64) -> [f64; 2] {
        if let Some((tb, k)) = self.tab(t) {
            return tb.accel[k];
        }
        let (sn, cs) = (TAU * self.accel_wobble_hz * t).sin_cos();
        [
            self.accel_mps2[0] + self.accel_wobble_mps2 * sn,
            self.accel_mps2[1] + self.accel_wobble_mps2 * cs,
        ]
    }

    /// The rate (°/s) and its derivative (°/s²) at `t`.
    pub fn rate_dps(&self, t: f64) -> (f64, f64) {
        let (r, rd) = self.table_rate_dps(t);
        match self.rate_sine {
            Some(v) if t > v.t_s => {
                let w = TAU * v.freq_hz;
                let (sn, cs) = (w * (t - v.t_s)).sin_cos();
                (r + v.amplitude_dps * sn, rd + v.amplitude_dps * w * cs)
            }
            _ => (r, rd),
        }
    }

    /// The rate table's part of the rate: the drawn rate and its reversal.
    fn table_rate_dps(&self, t: f64) -> (f64, f64) {
        let r = self.rate_dps;
        match self.reversal {
            Some(v) if t > v.t_s => {
                if t >= v.t_s + v.ramp_s {
                    (-r, 0.0)
                } else {
                    let a = PI * (t - v.t_s) / v.ramp_s;
                    (r * a.cos(), -r * PI / v.ramp_s * a.sin())
                }
            }
            _ => (r, 0.0),
        }
    }

    /// The die temperature at `t`, °C (linear over the record).
    pub fn temp_c(&self, t: f64) -> f64 {
        self.temp_start_c + self.temp_rise_k * (t / self.duration_s).clamp(0.0, 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn a_reversal_is_smooth_and_complete() {
        let mut p = Protocol::plain(10.0, 21_000.0, 100.0, [0.0; 2]);
        p.reversal = Some(Reversal {
            t_s: 4.0,
            ramp_s: 0.5,
        });
        assert_eq!(p.rate_dps(3.9), (100.0, 0.0));
        assert_eq!(p.rate_dps(4.6).0, -100.0);
        let (r, rd) = p.rate_dps(4.25);
        assert!(r.abs() < 1e-9 && (rd + 100.0 * PI / 0.5).abs() < 1e-9);
        // the derivative is the slope of the rate
        let h = 1e-6;
        let num = (p.rate_dps(4.1 + h).0 - p.rate_dps(4.1 - h).0) / (2.0 * h);
        assert!((num - p.rate_dps(4.1).1).abs() < 1e-4);
    }

    #[test]
    fn drawn_dithers_are_in_range() {
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(9);
        for _ in 0..100 {
            let p = Protocol::draw(&mut rng, 20.0, 21_884.0, 50.0, [1.0, 2.0], 4.0, 0.4);
            assert!((2.0..=6.0).contains(&p.dither_freq_hz));
            let s_min = (0..=p.intervals())
                .map(|k| p.pump_scale(p.t(k)))
                .fold(f64::INFINITY, f64::min);
            assert!(s_min > 0.6, "{s_min}");
            assert_eq!(p.pump_hz(0.0), 21_884.0);
        }
    }
}
