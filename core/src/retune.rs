//! The retune supervisor: moves the pump centre so that 2Ω = 2·ω_y (the paper's rule,
//! ω = √ω̂y²) once the estimate is healthy and settled.
//!
//! * The move is a raised-cosine ramp of the centre (phase-continuous at the DDS),
//!   at least `ramp_s` long and slow enough for `max_rate_hz_per_s`.
//! * The target is clamped inside the drive's principal parametric band computed from
//!   the *estimated* θ (DERIVATION §6): ω² ∈ K ± √((sβ)² − μ²K), K = −(θ12 + (s−1)θ16),
//!   β = |θ16|/2, μ = −θ11, with a margin of `band_margin` of the band's width on each
//!   side. Outside that band the trivial state is stable and the drive dies
//!   (FINDINGS §3.5).
//! * "Drive lock lost": |A1| below `lock_min_um` for `lock_lost_s`. A ramp in progress
//!   is then reversed to where it came from, and no new retune starts until the lock is
//!   back.
//!
//! The decision (ω̂y², the band, the target) runs in the estimator's precision `T`:
//! `f32` on the chip, whose ω̂y² is an `f32` value in the first place, so evaluating it in
//! soft-float `f64` bought nothing and cost ~10k instructions on the deciding tick. Only
//! the move itself (target − centre, the ramp length) is formed in `f64`, where the
//! centre lives.

use crate::real::Real;

/// The drive's principal parametric band in ω (pump half-frequency), from θ1, in the
/// estimator's precision `T` (the same operations as in `f64`, so the host's `f64` core
/// is unchanged; on the chip `f32` keeps the band to ~1e-7 of ω, far inside its margin).
/// Returns `None` when the pump is too weak for any band (β < μ√K) or θ is invalid.
pub fn drive_band<T: Real>(th1: &[T; 8], s: T) -> Option<(T, T)> {
    let k = -(th1[1] + (s - T::ONE) * th1[5]);
    let b = (s * th1[5]).abs() / T::from_f64(2.0);
    let mu = -th1[0];
    if !(k.is_finite() && b.is_finite() && mu.is_finite()) || k <= T::ZERO {
        return None;
    }
    let disc = b * b - mu * mu * k;
    if disc <= T::ZERO {
        return None;
    }
    let r = disc.sqrt();
    if k - r <= T::ZERO {
        return None;
    }
    Some(((k - r).sqrt(), (k + r).sqrt()))
}

/// A tracking move's shortest ramp, samples (50 ms at 500 Hz, the supervisor's decision
/// interval: a move ends before the next is decided; a 0.25 s ramp, tried, set off the
/// change detector dozens of times in the firmware loop's warm-up, `paragyro-fil --
/// warm-up`, with the board's half-step DDS).
pub const TRACK_RAMP: u64 = 25;

/// What the supervisor decided this tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RetuneAction {
    /// Nothing to do.
    None,
    /// Start a ramp of the centre to this ω (absolute, non-dimensional) over `len` samples.
    Start {
        /// Target ω.
        target_om: f64,
        /// Ramp length in samples.
        len: u64,
    },
    /// A tracking move (smaller than the dead band, larger than the tracking step): ramp
    /// the centre to this ω over `len` samples, with no minimum interval after it.
    Track {
        /// Target ω.
        target_om: f64,
        /// Ramp length in samples.
        len: u64,
    },
    /// Drive lock lost during a ramp: ramp back to this ω over `len` samples.
    Abort {
        /// ω to return to.
        back_to_om: f64,
        /// Ramp length in samples.
        len: u64,
    },
}

/// Supervisor state (`Default`: disabled, unlocked, until built by [`Supervisor::new`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct Supervisor<T> {
    /// Retune allowed.
    pub enabled: bool,
    ramp_min: u64,
    max_rate: f64,
    deadband: f64,
    /// Tracking moves are made (a tracking step > 0).
    track_on: bool,
    /// The smallest move made, ω: the tracking step, or the dead band without tracking.
    trigger: f64,
    /// A move of the dead band's size over [`TRACK_RAMP`] is within the rate limit.
    track_within_rate: bool,
    /// The smallest move in view in `T`: the tracking step, or the dead band without
    /// tracking; the margin in `T` (the decision's precision).
    trigger_t: T,
    margin: T,
    min_interval: u64,
    lock_min: T,
    lock_lost_after: u64,
    below_since: Option<u64>,
    locked: bool,
    ramping: Option<(u64, u64, f64)>, // (start k, len, from ω)
    /// The ramp in progress is a tracking move (no minimum interval after it).
    tracking: bool,
    tracks: u32,
    last_end: Option<u64>,
    retunes: u32,
    last_target: f64,
}

/// Settings of the supervisor in samples and ω units (from `RetuneConfig`).
#[derive(Clone, Copy, Debug)]
pub struct SupervisorSettings {
    /// Allowed at start-up.
    pub enabled: bool,
    /// Minimum ramp length, samples.
    pub ramp_min: u64,
    /// Largest ramp rate, ω per sample.
    pub max_rate: f64,
    /// Dead band, ω.
    pub deadband: f64,
    /// Tracking step, ω (0: no tracking; at most `deadband`).
    pub track: f64,
    /// Band margin, fraction of the band width.
    pub margin: f64,
    /// Minimum interval between retunes, samples.
    pub min_interval: u64,
    /// Lock threshold on |A1|, L0.
    pub lock_min: f64,
    /// Samples below the threshold before the lock counts as lost.
    pub lock_lost_after: u64,
}

/// Health inputs of one decision.
#[derive(Clone, Copy, Debug, Default)]
pub struct RetuneInputs<T> {
    /// Sample index.
    pub k: u64,
    /// Everything healthy and settled (inputs, excitation, covariance, no change).
    pub healthy: bool,
    /// Estimated ω_y².
    pub wy2: T,
    /// Estimated drive band (ω), if any.
    pub band: Option<(T, T)>,
    /// Current centre ω (f64: the move target − centre is formed in f64).
    pub centre_om: f64,
    /// Drive amplitude |A1| (L0).
    pub drive_amp: T,
    /// The scheduler's ramp has finished.
    pub ramp_done: bool,
}

impl<T: Real> Supervisor<T> {
    /// A supervisor with these settings.
    pub fn new(s: SupervisorSettings) -> Self {
        Supervisor {
            enabled: s.enabled,
            ramp_min: s.ramp_min.max(1),
            max_rate: s.max_rate,
            deadband: s.deadband,
            track_on: s.track > 0.0,
            trigger: if s.track > 0.0 { s.track } else { s.deadband },
            track_within_rate: core::f64::consts::FRAC_PI_2 * s.deadband
                <= s.max_rate * TRACK_RAMP as f64,
            trigger_t: T::from_f64(if s.track > 0.0 { s.track } else { s.deadband }),
            margin: T::from_f64(s.margin),
            min_interval: s.min_interval,
            lock_min: T::from_f64(s.lock_min),
            lock_lost_after: s.lock_lost_after,
            below_since: None,
            locked: false,
            ramping: None,
            tracking: false,
            tracks: 0,
            last_end: None,
            retunes: 0,
            last_target: f64::NAN,
        }
    }

    /// Drive locked (|A1| above threshold, not lost).
    pub fn locked(&self) -> bool {
        self.locked
    }
    /// A ramp of the centre is in progress (a retune or a tracking move).
    pub fn ramping(&self) -> bool {
        self.ramping.is_some()
    }
    /// A retune ramp (not a tracking move) is in progress.
    pub fn retuning(&self) -> bool {
        self.ramping.is_some() && !self.tracking
    }
    /// Tracking moves started.
    pub fn tracks(&self) -> u32 {
        self.tracks
    }
    /// Completed or started retunes.
    pub fn retunes(&self) -> u32 {
        self.retunes
    }
    /// Last target ω (NaN before the first retune).
    pub fn last_target(&self) -> f64 {
        self.last_target
    }

    /// Whether a move is in view at sample `k` (so the caller computes the band only
    /// then): allowed, locked, healthy, no ramp running, the minimum interval after a
    /// retune elapsed, and √ω̂y² farther than the tracking step (the dead band without
    /// tracking) from the centre. The band guard clamps the target
    /// of a retune; it does not trigger one by itself.
    pub fn would_retune(&self, k: u64, healthy: bool, wy2: T, centre_om: T) -> bool {
        if !(self.enabled && self.locked && healthy && self.ramping.is_none()) {
            return false;
        }
        if let Some(e) = self.last_end
            && k < e + self.min_interval
        {
            return false;
        }
        // |√wy2 − c| > db without a square root: wy2 outside [(c − db)², (c + db)²]
        let (lo, hi) = (centre_om - self.trigger_t, centre_om + self.trigger_t);
        wy2.is_finite() && wy2 > T::ZERO && (wy2 < lo * lo || wy2 > hi * hi)
    }

    /// Target ω for an estimated ω_y² and band.
    pub fn target(&self, wy2: T, band: Option<(T, T)>) -> Option<T> {
        if !(wy2.is_finite() && wy2 > T::ZERO) {
            return None;
        }
        let (lo, hi) = band?;
        let w = hi - lo;
        let (lo, hi) = (lo + self.margin * w, hi - self.margin * w);
        // not `f64::clamp`: it panics when lo > hi or either is NaN (a bad band or a
        // margin above 0.5); max/min never panic and agree with it everywhere else
        // (`sqrt(wy2)` is finite here, and so is the band `drive_band` returns). Its panic
        // message also pulled ≈ 15 KB of float formatting into the firmware image.
        Some(wy2.sqrt().max(lo).min(hi))
    }

    /// One tick of the supervisor.
    pub fn tick(&mut self, i: &RetuneInputs<T>) -> RetuneAction {
        // drive lock
        if i.drive_amp.is_finite() && i.drive_amp >= self.lock_min {
            self.below_since = None;
            self.locked = true;
        } else {
            let since = *self.below_since.get_or_insert(i.k);
            if i.k >= since + self.lock_lost_after {
                self.locked = false;
            }
        }
        if let Some((k0, len, from)) = self.ramping {
            if !self.locked {
                self.ramping = None;
                self.tracking = false;
                self.last_end = Some(i.k);
                let done = (i.k - k0).min(len);
                return RetuneAction::Abort {
                    back_to_om: from,
                    len: done.max(self.ramp_min / 2).max(1),
                };
            }
            if i.ramp_done || i.k >= k0 + len {
                self.ramping = None;
                if !self.tracking {
                    self.last_end = Some(i.k);
                }
            }
            return RetuneAction::None;
        }
        if !self.enabled || !self.locked || !i.healthy {
            return RetuneAction::None;
        }
        if let Some(e) = self.last_end
            && i.k < e + self.min_interval
        {
            return RetuneAction::None;
        }
        let Some(target) = self.target(i.wy2, i.band) else {
            return RetuneAction::None;
        };
        // the move in f64, where the centre lives
        let target = target.to_f64();
        let delta = target - i.centre_om;
        let size = libm::fabs(delta);
        // one soft-float comparison on a decision that makes no move (the chip's tick); a
        // NaN or infinite move (an estimate gone wild) is none
        if !(size > self.trigger && size.is_finite()) {
            return RetuneAction::None;
        }
        let tracking = self.track_on && size <= self.deadband;
        // raised cosine peak slope = π/2 · Δ / len  ≤ max_rate
        let by_rate =
            |size: f64| (core::f64::consts::FRAC_PI_2 * size / self.max_rate.max(1e-30)) as u64 + 1;
        self.tracking = tracking;
        self.last_target = target;
        if tracking {
            // within the next decision: the move is done before the next one is made (the
            // rate limit's length only where a dead band's move would exceed it, so that
            // a tracking move's tick costs no soft-float division)
            let len = if self.track_within_rate {
                TRACK_RAMP
            } else {
                TRACK_RAMP.max(by_rate(size))
            };
            self.ramping = Some((i.k, len, i.centre_om));
            self.tracks = self.tracks.saturating_add(1);
            return RetuneAction::Track {
                target_om: target,
                len,
            };
        }
        let len = self.ramp_min.max(by_rate(size));
        self.ramping = Some((i.k, len, i.centre_om));
        self.retunes = self.retunes.saturating_add(1);
        RetuneAction::Start {
            target_om: target,
            len,
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn th1_table2() -> [f64; 8] {
        let g: f64 = 3.8581e-5;
        [
            -1e-3,
            -(1.0 - g * g + 0.0452),
            -0.002,
            -(1e-4 - 2.0 * g),
            -(2.0 * 6.33e-5 + 0.002303),
            -0.0452,
            -1.266e-4,
            1.0,
        ]
    }

    #[test]
    fn band_matches_derivation() {
        // DERIVATION §6: (1.01125, 1.03333) for Table 2
        let (lo, hi) = drive_band(&th1_table2(), 1.0).unwrap();
        assert!(
            (lo - 1.01125).abs() < 5e-5 && (hi - 1.03333).abs() < 5e-5,
            "{lo} {hi}"
        );
        // a weak pump has no band
        assert!(drive_band(&th1_table2(), 0.02).is_none());
    }

    fn settings() -> SupervisorSettings {
        SupervisorSettings {
            enabled: true,
            ramp_min: 250,
            max_rate: 1e-5,
            deadband: 1e-4,
            track: 0.0,
            margin: 0.1,
            min_interval: 500,
            lock_min: 0.2,
            lock_lost_after: 25,
        }
    }

    #[test]
    fn retunes_to_sqrt_wy2_once_healthy() {
        let mut s = Supervisor::<f64>::new(settings());
        let band = drive_band(&th1_table2(), 1.0);
        let mut inp = RetuneInputs {
            k: 0,
            healthy: false,
            wy2: 1.03,
            band,
            centre_om: 1.0265f64.sqrt(),
            drive_amp: 1.7,
            ramp_done: true,
        };
        assert_eq!(s.tick(&inp), RetuneAction::None, "not healthy yet");
        inp.k = 1;
        inp.healthy = true;
        match s.tick(&inp) {
            RetuneAction::Start { target_om, len } => {
                assert!((target_om - 1.03f64.sqrt()).abs() < 1e-12);
                assert!(len >= 250);
            }
            a => panic!("expected a retune, got {a:?}"),
        }
        assert!(s.ramping());
        // lock lost mid-ramp → abort back
        inp.drive_amp = 0.0;
        inp.ramp_done = false;
        let mut aborted = false;
        for k in 2..100 {
            inp.k = k;
            if let RetuneAction::Abort { back_to_om, .. } = s.tick(&inp) {
                assert!((back_to_om - 1.0265f64.sqrt()).abs() < 1e-12);
                aborted = true;
                break;
            }
        }
        assert!(aborted && !s.locked());
    }

    /// With a tracking step: a move between it and the dead band is a tracking move of
    /// [`TRACK_RAMP`] samples, not a retune (no `retuning`, no minimum interval: the next
    /// decision after it may move again); a move within the step is none; beyond the dead
    /// band a retune as without tracking.
    #[test]
    fn moves_below_the_dead_band_are_tracking_moves() {
        let mut s = Supervisor::<f64>::new(SupervisorSettings {
            track: 2e-5,
            ..settings()
        });
        let band = drive_band(&th1_table2(), 1.0);
        let c = 1.02f64;
        let mut inp = RetuneInputs {
            k: 0,
            healthy: true,
            wy2: (c + 1e-5) * (c + 1e-5),
            band,
            centre_om: c,
            drive_amp: 1.7,
            ramp_done: true,
        };
        assert_eq!(s.tick(&inp), RetuneAction::None, "within the tracking step");
        inp.wy2 = (c + 5e-5) * (c + 5e-5);
        inp.k = 25;
        match s.tick(&inp) {
            RetuneAction::Track { target_om, len } => {
                assert!((target_om - (c + 5e-5)).abs() < 1e-12);
                assert_eq!(len, TRACK_RAMP);
            }
            a => panic!("expected a tracking move, got {a:?}"),
        }
        assert!(s.ramping() && !s.retuning());
        assert_eq!((s.tracks(), s.retunes()), (1, 0));
        // the move ends; the next decision moves again, with no minimum interval
        inp.k = 50;
        assert_eq!(s.tick(&inp), RetuneAction::None);
        assert!(!s.ramping());
        inp.centre_om = c + 5e-5;
        inp.wy2 = (c + 1e-4) * (c + 1e-4);
        inp.k = 75;
        assert!(matches!(s.tick(&inp), RetuneAction::Track { .. }));
        // beyond the dead band: a retune
        inp.k = 200;
        inp.ramp_done = true;
        assert_eq!(s.tick(&inp), RetuneAction::None);
        inp.wy2 = (c + 5e-4) * (c + 5e-4);
        inp.k = 225;
        assert!(matches!(s.tick(&inp), RetuneAction::Start { .. }));
        assert!(s.retuning());
        assert_eq!((s.tracks(), s.retunes()), (2, 1));
    }

    #[test]
    fn target_is_clamped_into_the_band() {
        let s = Supervisor::<f64>::new(settings());
        let band = drive_band(&th1_table2(), 1.0).unwrap();
        let t = s.target(1.2, Some(band)).unwrap();
        assert!(t < band.1 && t > band.0);
        assert!(s.target(1.03, None).is_none());
    }
}
