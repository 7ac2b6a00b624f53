//! A warm-up's figures and checks (`paragyro-fil warm-up`, [`crate::WarmUp`]): the same
//! reading of the loop and of the host-only loop.

use super::*;
use paragyro_simulator::thermal::lowest_second_ratio;

/// A warm-up's pump centre is the core's pump command averaged over at most the last this
/// long, s (five periods of the 5 Hz frequency dither, which runs to the end): over the
/// whole dither periods at the end after the last retune ramp (health bit 7), where the
/// centre holds and the dither averages out.
pub const PUMP_MEAN_S: f64 = 1.0;

/// `Health::bits` bit of `retuning` (a retune ramp moves the centre).
pub const RETUNING_BIT: u32 = 1 << 7;

/// One tick as a warm-up's figures read it, from the loop or the host-only loop.
#[derive(Clone, Copy, Debug)]
pub struct WarmUpTick {
    /// Time, s.
    pub t_s: f64,
    /// The core's event bits (`paragyro_core::output::event`).
    pub events: u8,
    /// The core's health bits (`Health::bits`).
    pub health: u32,
    /// The rate's own validity flag (`RateOutput::valid`; `None`: not seen, the loop).
    pub rate_valid: Option<bool>,
    /// The fast rate and the true rate, °/s.
    pub rate_dps: f64,
    pub rate_dps_true: f64,
    /// The core's pump command for the next sample (centre and dither), Hz.
    pub pump_hz_next: f64,
    /// True ω_y².
    pub wy2_true: f64,
    /// The plant's sense amplitude |Y1|, µm.
    pub sense_amp_um: f64,
}

/// `Health::bits` of what the rate's validity needs from the health (`rate::assess`):
/// inputs valid (bit 0), drive locked (bit 4), and no change pending (bit 3, clear).
pub const RATE_HEALTH_BITS: (u32, u32) = (1 | DRIVE_LOCKED_BIT, 1 << 3);

/// A warm-up's figures ([`crate::WarmUp`]), in the loop (`Summary::warm_up`) and in the
/// host-only loop (`LoopNumbers::warm_up`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WarmUpNumbers {
    /// The die temperature's ramp the shares are read over, s.
    pub ramp_s: (f64, f64),
    /// Covariance resets (the core's `CHANGE_DRIVE` and `CHANGE_SENSE` events, one a tick
    /// each) before the end of the start-up.
    pub resets_startup: u32,
    /// Drive and sense covariance resets after the start-up.
    pub resets_drive_after: u32,
    pub resets_sense_after: u32,
    /// Samples of the ramp.
    pub ramp_samples: u32,
    /// Share of the ramp's samples whose health allows a valid rate ([`RATE_HEALTH_BITS`]:
    /// necessary, not sufficient; the loop's summary has no per-sample rate flag).
    pub rate_health_share: f64,
    /// Share of the ramp's samples with the rate flagged valid (`RateOutput::valid`; the
    /// host-only loop only: the firmware's answer does not carry it).
    pub rate_valid_share: Option<f64>,
    /// The fast rate's error over the ramp, every sample: rms and largest, °/s.
    pub rate_err_rms_ramp_dps: f64,
    /// The fast rate's error's rms before the ramp (from the end of the start-up to the
    /// ramp's start), °/s.
    pub rate_err_rms_before_dps: f64,
    /// `rate_err_rms_ramp_dps / rate_err_rms_before_dps`.
    pub rate_err_ratio: f64,
    /// The lowest 1 s mean of the sense amplitude during the ramp against the oracle
    /// twin's, whose pump centre sits at twice the true sense resonance
    /// (`paragyro_simulator::thermal::oracle_sense_amp`; `None`: not compared).
    pub sense_amp_vs_oracle_min: Option<f64>,
    pub rate_err_max_ramp_dps: f64,
    /// The pump centre at the end: the core's pump command averaged over whole dither
    /// periods at the end, after the last retune ramp, at most [`PUMP_MEAN_S`], Hz (NaN:
    /// not one whole period after it).
    pub pump_centre_end_hz: f64,
    /// Samples averaged for `pump_centre_end_hz`.
    pub pump_centre_samples: u32,
    /// The core's own centre after the last step, Hz (the host-only loop only).
    pub pump_centre_core_hz: Option<f64>,
    /// Twice the true sense resonance at the end, 2·f0·√ω_y², Hz.
    pub pump_target_end_hz: f64,
    /// `pump_centre_end_hz − pump_target_end_hz`, Hz.
    pub pump_offset_end_hz: f64,
    /// Twice the true sense resonance's move over the run, Hz (what the pump had to follow).
    pub pump_target_move_hz: f64,
    /// The largest |pump centre − 2·f_y| during the ramp, Hz: the centre the command's mean
    /// over each whole dither period of the ramp (blocks with a retune ramp left out), 2·f_y
    /// its mean over the block.
    pub pump_offset_max_ramp_hz: f64,
    /// Dither periods of the ramp read for `pump_offset_max_ramp_hz`.
    pub pump_blocks_ramp: u32,
    /// Retunes the core completed.
    pub retunes: u32,
    /// The frequency TCFs (drive, sense) the core learned, ppm/K (NaN: not learned; the
    /// host-only loop only: the firmware does not report them).
    pub tcf_learned_ppm_k: Option<[f64; 2]>,
}

impl WarmUpNumbers {
    /// The figures of `ticks` (every tick of a run of `sc`) for the warm-up `w`.
    pub fn of(w: &WarmUp, sc: &Scenario, ticks: &[WarmUpTick], retunes: u32) -> Self {
        use paragyro_core::output::event::{CHANGE_DRIVE, CHANGE_SENSE};
        let count = |bit: u8, after: bool| {
            ticks
                .iter()
                .filter(|r| (r.t_s >= w.startup_s) == after && r.events & bit != 0)
                .count() as u32
        };
        let ramp: Vec<&WarmUpTick> = ticks
            .iter()
            .filter(|r| r.t_s >= w.ramp_s.0 && r.t_s < w.ramp_s.1)
            .collect();
        let n = ramp.len().max(1) as f64;
        let (need, clear) = RATE_HEALTH_BITS;
        let healthy = ramp
            .iter()
            .filter(|r| r.health & need == need && r.health & clear == 0)
            .count();
        let valid = ramp
            .iter()
            .map(|r| r.rate_valid)
            .collect::<Option<Vec<bool>>>()
            .map(|v| v.iter().filter(|b| **b).count() as f64 / n);
        let err: Vec<f64> = ramp.iter().map(|r| r.rate_dps - r.rate_dps_true).collect();
        let rms = (err.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
        let before: Vec<f64> = ticks
            .iter()
            .filter(|r| r.t_s >= w.startup_s && r.t_s < w.ramp_s.0)
            .map(|r| r.rate_dps - r.rate_dps_true)
            .collect();
        let rms_before = if before.is_empty() {
            f64::NAN
        } else {
            (before.iter().map(|e| e * e).sum::<f64>() / before.len() as f64).sqrt()
        };
        let max = err.iter().map(|e| e.abs()).fold(0.0, f64::max);
        // the sample rate of the ticks (the core's, 500 Hz)
        let fs = match ticks {
            [a, b, ..] if b.t_s > a.t_s => 1.0 / (b.t_s - a.t_s),
            _ => f64::NAN,
        };
        let period = if fs.is_finite() && sc.estimator.dither_freq_hz > 0.0 {
            ((fs / sc.estimator.dither_freq_hz).round() as usize).max(1)
        } else {
            1
        };
        let held = ticks
            .iter()
            .rposition(|r| r.health & RETUNING_BIT != 0)
            .map_or(ticks, |k| &ticks[k + 1..]);
        let most = if fs.is_finite() {
            (PUMP_MEAN_S * fs).round() as usize
        } else {
            0
        };
        let len = held.len().min(most) / period * period;
        let last = &held[held.len() - len..];
        let centre = if len == 0 {
            f64::NAN
        } else {
            last.iter().map(|r| r.pump_hz_next).sum::<f64>() / len as f64
        };
        let target = |wy2: f64| 2.0 * sc.sim.f0_hz * wy2.sqrt();
        let mut blocks = 0u32;
        let mut offset_max: f64 = 0.0;
        for b in ramp.chunks_exact(period) {
            if b.iter().any(|r| r.health & RETUNING_BIT != 0) {
                continue;
            }
            let mean = |f: &dyn Fn(&WarmUpTick) -> f64| {
                b.iter().map(|r| f(r)).sum::<f64>() / b.len() as f64
            };
            let off = mean(&|r| r.pump_hz_next) - mean(&|r| target(r.wy2_true));
            offset_max = offset_max.max(off.abs());
            blocks += 1;
        }
        let (first, end) = (
            ticks.first().map_or(f64::NAN, |r| target(r.wy2_true)),
            ticks.last().map_or(f64::NAN, |r| target(r.wy2_true)),
        );
        WarmUpNumbers {
            ramp_s: w.ramp_s,
            resets_startup: count(CHANGE_DRIVE, false) + count(CHANGE_SENSE, false),
            resets_drive_after: count(CHANGE_DRIVE, true),
            resets_sense_after: count(CHANGE_SENSE, true),
            ramp_samples: ramp.len() as u32,
            rate_health_share: healthy as f64 / n,
            rate_valid_share: valid,
            rate_err_rms_ramp_dps: rms,
            rate_err_rms_before_dps: rms_before,
            rate_err_ratio: rms / rms_before,
            sense_amp_vs_oracle_min: None,
            rate_err_max_ramp_dps: max,
            pump_centre_end_hz: centre,
            pump_centre_samples: len as u32,
            pump_centre_core_hz: None,
            pump_target_end_hz: end,
            pump_offset_end_hz: centre - end,
            pump_target_move_hz: end - first,
            pump_offset_max_ramp_hz: if blocks > 0 { offset_max } else { f64::NAN },
            pump_blocks_ramp: blocks,
            retunes,
            tcf_learned_ppm_k: None,
        }
    }

    /// Adds the comparison of the sense amplitude with the oracle twin's (`oracle`, the
    /// twin's `(t, |Y1|)` of every sample) over each whole second of the ramp.
    pub fn with_oracle(mut self, ticks: &[WarmUpTick], oracle: &[(f64, f64)]) -> Self {
        let amp: Vec<(f64, f64)> = ticks.iter().map(|r| (r.t_s, r.sense_amp_um)).collect();
        self.sense_amp_vs_oracle_min = lowest_second_ratio(&amp, oracle, self.ramp_s);
        self
    }
}

/// A warm-up's checks ([`crate::WarmUp`]): in the loop, no covariance reset after the
/// start-up, the rate's health on the share of the ramp, the pump centre near twice the
/// sense resonance at the end and through the ramp; in the host-only loop, no reset after
/// the start-up and the rate's own flag on the share. Failures appended.
pub(super) fn warm_up_checks(
    failures: &mut Vec<String>,
    w: &WarmUp,
    fil: &WarmUpNumbers,
    host: Option<&WarmUpNumbers>,
) {
    let mut check = |ok: bool, what: String| {
        if !ok {
            failures.push(what);
        }
    };
    let (d, s) = (fil.resets_drive_after, fil.resets_sense_after);
    check(
        d + s == 0,
        format!(
            "{d} drive and {s} sense covariance resets after the start-up ({} s)",
            w.startup_s
        ),
    );
    check(
        fil.rate_health_share >= w.min_valid_share,
        format!(
            "the rate's health on {:.1} % of the ramp's samples (at least {:.1} %)",
            100.0 * fil.rate_health_share,
            100.0 * w.min_valid_share
        ),
    );
    for (who, n) in [("", Some(fil)), ("host-only: ", host)] {
        let Some(n) = n else { continue };
        let v = n.rate_valid_share.unwrap_or(f64::NAN);
        check(
            v >= w.min_valid_share,
            format!(
                "{who}the rate valid on {:.1} % of the ramp's samples (at least {:.1} %)",
                100.0 * v,
                100.0 * w.min_valid_share
            ),
        );
        check(
            n.rate_err_ratio <= w.max_err_ratio,
            format!(
                "{who}the rate's error during the ramp {:.3} °/s rms, {:.2}× its {:.3} °/s before it (at most {}×)",
                n.rate_err_rms_ramp_dps,
                n.rate_err_ratio,
                n.rate_err_rms_before_dps,
                w.max_err_ratio
            ),
        );
        let a = n.sense_amp_vs_oracle_min.unwrap_or(f64::NAN);
        check(
            a >= w.min_sense_vs_oracle,
            format!(
                "{who}the sense amplitude down to {:.1} % of the oracle twin's in a second of the ramp (at least {:.1} %)",
                100.0 * a,
                100.0 * w.min_sense_vs_oracle
            ),
        );
    }
    check(
        fil.pump_offset_end_hz.abs() <= w.pump_tol_hz,
        format!(
            "pump centre {:.2} Hz at the end, {:+.2} Hz from twice the sense resonance (at most {})",
            fil.pump_centre_end_hz, fil.pump_offset_end_hz, w.pump_tol_hz
        ),
    );
    check(
        fil.pump_offset_max_ramp_hz <= w.pump_tol_hz,
        format!(
            "pump centre up to {:.2} Hz from twice the sense resonance during the ramp (at most {})",
            fil.pump_offset_max_ramp_hz, w.pump_tol_hz
        ),
    );
    let Some(h) = host else {
        failures.push("the host-only loop has no warm-up figures".into());
        return;
    };
    check(
        h.resets_drive_after + h.resets_sense_after == 0,
        format!(
            "host-only: {} drive and {} sense covariance resets after the start-up",
            h.resets_drive_after, h.resets_sense_after
        ),
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `warm-up` is the file's profile at 4 g: the ramp 5–25 s, ωy² falling 660 ppm.
    #[test]
    fn the_warm_up_is_the_files_profile_within_the_accelerometers_range() {
        let ls = crate::by_name("warm-up").unwrap();
        let w = ls.warm_up.unwrap();
        assert_eq!((w.startup_s, w.ramp_s), (2.5, (5.0, 25.0)));
        let sc = &ls.scenario;
        assert_eq!(sc.duration_s, 27.0);
        assert!(sc.plant.accel_x_mps2 < 8.0 * 9.806_65 && sc.plant.accel_y_mps2 < 8.0 * 9.806_65);
        assert_eq!(sc.temp_c(25.0), Some(35.0));
        let (w0, w1) = (sc.plant_at(0.0).phys[4], sc.plant_at(27.0).phys[4]);
        assert!(((w1 / w0 - 1.0) * 1e6 + 659.9).abs() < 0.5, "{w0} → {w1}");
    }

    /// A warm-up's figures: resets counted by their events after the start-up only, the
    /// health's share over the ramp only, the pump centre the dithered command's mean over
    /// the last second, the rate's error during the ramp against before it, the sense
    /// amplitude against the oracle twin's per whole second of the ramp.
    #[test]
    fn the_warm_up_figures_read_resets_health_and_the_pump_centre() {
        use paragyro_core::output::event::{CHANGE_DRIVE, CHANGE_SENSE};
        let ls = crate::warm_up().unwrap();
        let (w, sc) = (ls.warm_up.unwrap(), &ls.scenario);
        let wy2 = 1.0258;
        let centre = 2.0 * sc.sim.f0_hz * f64::sqrt(wy2) + 0.7;
        let ticks: Vec<WarmUpTick> = (0..=13_500u32)
            .map(|k| {
                let t = f64::from(k) / 500.0;
                let mut events = 0;
                let mut health = 1 | DRIVE_LOCKED_BIT;
                match k {
                    500 => events = CHANGE_SENSE,                  // 1 s: start-up
                    5_000 => events = CHANGE_DRIVE,                // 10 s
                    6_000 => events = CHANGE_DRIVE | CHANGE_SENSE, // 12 s
                    5_001..=5_100 => health |= 1 << 3,             // 100 ramp samples pending
                    12_600..=12_700 => health = 0,                 // after the ramp: not counted
                    13_000..=13_260 => health |= RETUNING_BIT,     // the centre moves
                    _ => {}
                }
                let dither = 21.6 * (2.0 * std::f64::consts::PI * 5.0 * t).sin();
                // 1.5 Hz above the centre until a retune ramp over ticks 13 000–13 260
                let centre = match k {
                    ..13_000 => centre + 1.5,
                    13_000..=13_260 => centre + 1.5 - 1.5 * f64::from(k - 13_000) / 260.0,
                    _ => centre,
                };
                // ±0.2 °/s of error every sample, 3 °/s more at 12 s
                let noise = if k % 2 == 0 { 0.2 } else { -0.2 };
                WarmUpTick {
                    t_s: t,
                    events,
                    health,
                    // 50 of the ramp's samples not valid
                    rate_valid: Some(!(7_000..7_050).contains(&k)),
                    rate_dps: 150.0 + noise + if k == 6_000 { 3.0 } else { 0.0 },
                    rate_dps_true: 150.0,
                    pump_hz_next: centre + dither,
                    wy2_true: wy2,
                    sense_amp_um: 1.5,
                }
            })
            .collect();
        // the oracle's amplitude 1.5 µm, 1.6 µm over the second from 10 s
        let oracle: Vec<(f64, f64)> = ticks
            .iter()
            .map(|r| {
                (
                    r.t_s,
                    if (10.0..11.0).contains(&r.t_s) {
                        1.6
                    } else {
                        1.5
                    },
                )
            })
            .collect();
        let n = WarmUpNumbers::of(&w, sc, &ticks, 2).with_oracle(&ticks, &oracle);
        assert_eq!(n.resets_startup, 1);
        assert_eq!((n.resets_drive_after, n.resets_sense_after), (2, 1));
        assert_eq!(n.ramp_samples, 10_000);
        assert!((n.rate_health_share - 0.99).abs() < 1e-12, "{n:?}");
        assert_eq!(n.rate_valid_share, Some(0.995));
        assert!((n.rate_err_max_ramp_dps - 3.2).abs() < 1e-9, "{n:?}");
        assert!((n.rate_err_rms_before_dps - 0.2).abs() < 1e-9, "{n:?}");
        // (0.04 · 9 999 + 3.2²) / 10 000 within the ramp
        let ramp_rms = ((0.04 * 9_999.0 + 3.2 * 3.2) / 10_000.0_f64).sqrt();
        assert!((n.rate_err_ratio - ramp_rms / 0.2).abs() < 1e-9, "{n:?}");
        let a = n.sense_amp_vs_oracle_min.unwrap();
        assert!((a - 1.5 / 1.6).abs() < 1e-12, "{n:?}");
        // two whole dither periods after the ramp (240 samples after it)
        assert_eq!(n.pump_centre_samples, 200);
        assert!((n.pump_offset_end_hz - 0.7).abs() < 1e-6, "{n:?}");
        assert_eq!(n.pump_target_move_hz, 0.0);
        // during the ramp: 0.7 + 1.5 Hz on each of its 100 dither periods
        assert_eq!(n.pump_blocks_ramp, 100);
        assert!((n.pump_offset_max_ramp_hz - 2.2).abs() < 1e-6, "{n:?}");
        let mut failures = Vec::new();
        warm_up_checks(&mut failures, &w, &n, Some(&n));
        // resets in the loop and the host-only loop, the sense amplitude in both
        assert_eq!(failures.len(), 4, "{failures:?}");
        assert!(failures.iter().filter(|f| f.contains("oracle")).count() == 2);
    }
}
