//! The injector of one class ([`LoopHooks`] of the closed loop) and its per-tick score.
//!
//! The score is kept inside the step hook: it sees the sample (after the fault), the
//! core before and after its step and the truth of the tick (from the plant hook).

use std::panic::{AssertUnwindSafe, catch_unwind};

use paragyro_core::estimator::event;
use paragyro_core::physics::{Physical, gamma_from_rate_dps, theta_from_physical};
use paragyro_core::{Estimator, Sample, StepOutput};

use super::class::{Episode, FaultClass};
use crate::plant::PlantInputs;
use crate::runner::LoopHooks;
use crate::scenario::PlantAt;

/// Ticks after an episode's end during which a flag still counts as its flag.
pub const FLAG_GRACE: u64 = 500;
/// The recovery criterion's floor on the relative ω̂y² error (see [`EpisodeScore`]).
pub const RECOVERY_WY2_FLOOR: f64 = 1e-4;
/// The recovery criterion's floor on the rate error, °/s (see [`EpisodeScore`]).
pub const RECOVERY_RATE_FLOOR_DPS: f64 = 1.0;
/// The recovery criterion must hold this many ticks in a row (1 s).
pub const RECOVERY_HOLD: u64 = 500;

/// What happened in one episode.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EpisodeScore {
    /// Relative ω̂y² error on the tick before the episode.
    pub wy2_err_before: f64,
    /// Rate error, °/s, on the tick before the episode.
    pub rate_err_before_dps: f64,
    /// A flag (bad input, change detected, drive lock lost) was raised between the
    /// start and `FLAG_GRACE` ticks after the end.
    pub flagged: bool,
    /// First tick at or after the end with the inputs valid, not gated, no change
    /// pending, the drive locked, the relative ω̂y² error at most
    /// max(2 × `wy2_err_before`, [`RECOVERY_WY2_FLOOR`]) and the rate error at most
    /// max(2 × `rate_err_before_dps`, [`RECOVERY_RATE_FLOOR_DPS`]), and all that for
    /// [`RECOVERY_HOLD`] ticks in a row from there; `None` if that did not happen before
    /// the next episode (or the run's end).
    pub recovered_at: Option<u64>,
    /// The tick since which the criterion holds (not yet for `RECOVERY_HOLD` ticks).
    pub candidate: Option<u64>,
    /// Relative ω̂y² error at the end of the hold.
    pub wy2_err_after: f64,
    /// Absolute rate error, °/s, at the end of the hold.
    pub rate_err_after_dps: f64,
}

/// The injector and score of one class over one run.
pub struct Injector {
    class: FaultClass,
    episodes: Vec<Episode>,
    /// Ticks before the first slot (no false flags counted there).
    warmup: u64,
    omega0_rad_s: f64,
    f0_hz: f64,
    /// The truth of the current tick (plant hook).
    wy2_true: f64,
    rate_true_dps: f64,
    /// Stuck class: the frozen value of the current episode.
    frozen: Option<f32>,
    /// The pump (Hz, scale multiplier) in effect at the current tick.
    in_effect: Option<(f64, f64)>,
    last_wy2_err: f64,
    last_rate_err: f64,
    was_locked: bool,
    /// The score.
    pub scores: Vec<EpisodeScore>,
    /// Steps that panicked (caught).
    pub panics: u64,
    /// Ticks with a non-finite pump command, θ̂, ω̂y² or rate.
    pub non_finite_outputs: u64,
    /// Flagged bad samples whose step changed θ̂.
    pub held_violations: u64,
    /// Flag events after the warm-up, outside every episode and its recovery: bad
    /// input, change detected (either axis), drive lock lost.
    pub false_flags: [u64; 3],
    /// Ticks stepped.
    pub stepped: u64,
}

impl Injector {
    /// An injector of `class` with its planned `episodes`.
    pub fn new(
        class: FaultClass,
        episodes: Vec<Episode>,
        warmup: u64,
        omega0_rad_s: f64,
        f0_hz: f64,
    ) -> Self {
        let scores = vec![EpisodeScore::default(); episodes.len()];
        Injector {
            class,
            episodes,
            warmup,
            omega0_rad_s,
            f0_hz,
            wy2_true: f64::NAN,
            rate_true_dps: f64::NAN,
            frozen: None,
            in_effect: None,
            last_wy2_err: f64::NAN,
            last_rate_err: f64::NAN,
            was_locked: false,
            scores,
            panics: 0,
            non_finite_outputs: 0,
            held_violations: 0,
            false_flags: [0; 3],
            stepped: 0,
        }
    }

    /// The episode faulting tick `k`, if any.
    fn active(&self, k: u64) -> Option<&Episode> {
        self.episodes.iter().find(|e| e.active(k))
    }

    /// Index of the last episode started at or before `k`.
    fn current(&self, k: u64) -> Option<usize> {
        self.episodes.iter().rposition(|e| e.start <= k)
    }

    /// The sample as the fault makes it; false: the sample never reaches the core.
    fn tamper(&mut self, k: u64, s: &mut Sample<f32>, full_scale: (f32, f32)) -> bool {
        let Some(ep) = self.active(k).copied() else {
            self.frozen = None;
            return true;
        };
        let value = |sign: f64, nan: bool| match (nan, sign > 0.0) {
            (true, _) => f32::NAN,
            (false, true) => f32::INFINITY,
            (false, false) => f32::NEG_INFINITY,
        };
        match self.class {
            FaultClass::Nan | FaultClass::Inf => {
                let v = value(ep.size, self.class == FaultClass::Nan);
                if ep.channel == 16 {
                    s.pump_hz = v as f64;
                } else {
                    set_channel(s, ep.channel, v);
                }
            }
            FaultClass::Saturation => {
                let fs = if ep.channel < 14 {
                    full_scale.0
                } else {
                    full_scale.1
                };
                set_channel(s, ep.channel, ep.size as f32 * fs);
            }
            FaultClass::Stuck => {
                let now = get_channel(s, ep.channel);
                let v = *self.frozen.get_or_insert(now);
                set_channel(s, ep.channel, v);
            }
            FaultClass::Spike => {
                let v = get_channel(s, ep.channel) + ep.size as f32;
                let lim = 0.99 * full_scale.0;
                set_channel(s, ep.channel, v.clamp(-lim, lim));
            }
            FaultClass::SpiCrc => {
                for c in 7 * ep.channel..7 * ep.channel + 7 {
                    set_channel(s, c, f32::NAN);
                }
            }
            FaultClass::DrdyMissing => {
                for c in 0..14 {
                    set_channel(s, c, f32::NAN);
                }
            }
            FaultClass::AccelLost => {
                s.accel_mps2 = [f32::NAN; 2];
            }
            FaultClass::Dropped | FaultClass::TimeJump => return false,
            _ => {}
        }
        true
    }

    /// The score of tick `k` after the core's step (`stepped`: the core saw the sample).
    fn score(&mut self, k: u64, est: &Estimator<f32>, out: &StepOutput, stepped: bool, held: bool) {
        let wy2 = est.wy2();
        let rate = est.rate_dps();
        let (t1, t2) = est.theta();
        // the fast rate channel's outputs too (the product's rate, `StepOutput::rate`)
        let finite = out.pump_hz_next.is_finite()
            && out.pump_scale_next.is_finite()
            && wy2.is_finite()
            && rate.is_finite()
            && out.rate.rate_dps.is_finite()
            && out.rate.rate_slow_dps.is_finite()
            && out.rate.quadrature_dps.is_finite()
            && t1.iter().chain(t2.iter()).all(|v| v.is_finite());
        if !finite {
            self.non_finite_outputs += 1;
        }
        if stepped && !out.health.inputs_valid && !held {
            self.held_violations += 1;
        }
        let h = out.health;
        let wy2_err = (wy2 - self.wy2_true).abs() / self.wy2_true.abs();
        let rate_err = (rate - self.rate_true_dps).abs();
        let lock_lost = self.was_locked && !h.drive_locked;
        self.was_locked = h.drive_locked;
        let kinds = [
            stepped && out.events & event::BAD_INPUT != 0,
            stepped && out.events & (event::CHANGE_DRIVE | event::CHANGE_SENSE) != 0,
            stepped && lock_lost,
        ];
        let flag_event = kinds.iter().any(|b| *b);
        let flag_state = !h.inputs_valid || h.change_detected || !h.drive_locked;
        let cur = self.current(k);
        let mut in_influence = false;
        if let Some(i) = cur {
            let ep = self.episodes[i];
            let next_start = self.episodes.get(i + 1).map_or(u64::MAX, |e| e.start);
            let sc = &mut self.scores[i];
            if k == ep.start {
                sc.wy2_err_before = self.last_wy2_err;
                sc.rate_err_before_dps = self.last_rate_err;
            }
            if k < ep.end() + FLAG_GRACE && (flag_state || flag_event) {
                sc.flagged = true;
            }
            if sc.recovered_at.is_none() {
                in_influence = true;
                let tol = (2.0 * sc.wy2_err_before).max(RECOVERY_WY2_FLOOR);
                let tol_rate = (2.0 * sc.rate_err_before_dps).max(RECOVERY_RATE_FLOOR_DPS);
                let ok = k >= ep.end()
                    && k < next_start
                    && h.inputs_valid
                    && !h.gated
                    && !h.change_detected
                    && h.drive_locked
                    && wy2_err <= tol
                    && rate_err <= tol_rate
                    && !flag_event;
                match (ok, sc.candidate) {
                    (false, _) => sc.candidate = None,
                    (true, None) => sc.candidate = Some(k),
                    (true, Some(c)) if k + 1 >= c + RECOVERY_HOLD => {
                        sc.recovered_at = Some(c);
                        sc.wy2_err_after = wy2_err;
                        sc.rate_err_after_dps = rate_err;
                    }
                    (true, Some(_)) => {}
                }
            }
        }
        if k >= self.warmup && !in_influence {
            for (n, hit) in self.false_flags.iter_mut().zip(kinds) {
                *n += hit as u64;
            }
        }
        self.last_wy2_err = wy2_err;
        self.last_rate_err = rate_err;
    }
}

/// Channel `c` of a sample: 0..14 lock-in (`Lockin::channels` order), 14, 15 the
/// accelerometer.
fn get_channel(s: &Sample<f32>, c: usize) -> f32 {
    if c < 14 {
        s.lockin.channels()[c]
    } else {
        s.accel_mps2[(c - 14).min(1)]
    }
}

/// Sets channel `c` (as [`get_channel`]).
fn set_channel(s: &mut Sample<f32>, c: usize, v: f32) {
    let l = &mut s.lockin;
    match c {
        0 => l.x0_um = v,
        1..=6 => {
            let z = &mut l.x_um[(c - 1) / 2];
            if (c - 1).is_multiple_of(2) {
                z.re = v
            } else {
                z.im = v
            }
        }
        7 => l.y0_um = v,
        8..=13 => {
            let z = &mut l.y_um[(c - 8) / 2];
            if (c - 8).is_multiple_of(2) {
                z.re = v
            } else {
                z.im = v
            }
        }
        _ => s.accel_mps2[(c - 14).min(1)] = v,
    }
}

/// The plant's θ from its (changed) physical parameters.
fn set_phys(pa: &mut PlantAt) {
    let (d, s) = theta_from_physical(&Physical::from_array(pa.phys));
    pa.theta_drive = d;
    pa.theta_sense = s;
}

impl LoopHooks<f32> for Injector {
    fn plant(&mut self, k: u64, pa: &mut PlantAt) {
        match self.class {
            FaultClass::DriveOutOfBand => {
                if let Some(ep) = self.active(k).copied() {
                    pa.phys[3] *= 1.0 + ep.size;
                    set_phys(pa);
                }
            }
            FaultClass::ParamJump => {
                if let Some(i) = self.current(k) {
                    pa.phys[4] *= 1.0 + self.episodes[i].size;
                    set_phys(pa);
                }
            }
            FaultClass::RateOverrange => {
                if let Some(ep) = self.active(k).copied() {
                    pa.rate_dps = ep.size;
                    pa.phys[10] = gamma_from_rate_dps(ep.size, self.omega0_rad_s);
                    set_phys(pa);
                }
            }
            _ => {}
        }
        self.wy2_true = pa.phys[4];
        self.rate_true_dps = pa.rate_dps;
    }

    fn step(
        &mut self,
        k: u64,
        est: &mut Estimator<f32>,
        sample: &mut Sample<f32>,
        last: &StepOutput,
    ) -> StepOutput {
        let m = &est.config().monitor;
        let fs = (m.full_scale_um as f32, m.accel_full_scale_mps2 as f32);
        if !self.tamper(k, sample, fs) {
            self.score(k, est, last, false, true);
            return *last;
        }
        let before = est.theta();
        let out = match catch_unwind(AssertUnwindSafe(|| est.step(sample))) {
            Ok(o) => o,
            Err(_) => {
                self.panics += 1;
                *last
            }
        };
        self.stepped += 1;
        let held = est.theta() == before;
        self.score(k, est, &out, true, held);
        out
    }

    fn inputs(
        &mut self,
        k: u64,
        u0: &mut PlantInputs,
        u1: &mut PlantInputs,
        next: &mut (f64, f64),
    ) {
        match (self.class, self.active(k).copied()) {
            (FaultClass::DdsFail, Some(_)) => {
                if let Some((pump, mult)) = self.in_effect {
                    // the DDS keeps its words: the pump in effect stays
                    u0.omega = pump / (2.0 * self.f0_hz);
                    u1.omega = u0.omega;
                    u1.s = u0.s;
                    *next = (pump, mult);
                }
            }
            (FaultClass::PumpCollapse, Some(ep)) => {
                u0.s *= ep.size;
                u1.s *= ep.size;
            }
            _ => {}
        }
        self.in_effect = Some(*next);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channels_round_trip_in_the_documented_order() {
        let mut s = Sample::<f32>::default();
        for c in 0..16 {
            set_channel(&mut s, c, c as f32 + 1.0);
        }
        let ch = s.lockin.channels();
        for c in 0..14 {
            assert_eq!(ch[c], c as f32 + 1.0);
            assert_eq!(get_channel(&s, c), c as f32 + 1.0);
        }
        assert_eq!(s.accel_mps2, [15.0, 16.0]);
    }
}
