//! The health of the estimate and the counters since start-up.
//!
//! Every estimate comes with its health (ARCHITECTURE §4): nothing downstream (the
//! retune supervisor, a telemetry consumer) acts on an estimate whose
//! [`Health::actionable`] says no. The [`Counters`] say what the input checks, the
//! change detector and the supervisor did, so that nothing is lost silently.

/// Health of the estimate (bit order as in [`Health::bits`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Health {
    /// This sample's inputs were valid.
    pub inputs_valid: bool,
    /// The pump-frequency excitation is sufficient for identification. When not (after
    /// it once was), the RLS opened this sample without forgetting (θ̂ held).
    pub excitation_ok: bool,
    /// Both covariances are finite, positive definite and bounded.
    pub covariance_bounded: bool,
    /// A parameter change was detected and the estimate has not settled since.
    pub change_detected: bool,
    /// The drive oscillates (|A1| above the lock threshold).
    pub drive_locked: bool,
    /// ω̂y² is settled.
    pub settled: bool,
    /// RLS updates are gated (start-up, commanded jump, recovery from bad input).
    pub gated: bool,
    /// A retune ramp of the pump centre is in progress.
    pub retuning: bool,
}

impl Health {
    /// Bits: 0 inputs_valid, 1 excitation_ok, 2 covariance_bounded, 3 change_detected,
    /// 4 drive_locked, 5 settled, 6 gated, 7 retuning.
    pub fn bits(&self) -> u32 {
        [
            self.inputs_valid,
            self.excitation_ok,
            self.covariance_bounded,
            self.change_detected,
            self.drive_locked,
            self.settled,
            self.gated,
            self.retuning,
        ]
        .iter()
        .enumerate()
        .fold(0, |acc, (i, b)| acc | ((*b as u32) << i))
    }

    /// Good enough to act on (retune): valid, excited, bounded, no change pending,
    /// locked, settled, not gated.
    pub fn actionable(&self) -> bool {
        self.inputs_valid
            && self.excitation_ok
            && self.covariance_bounded
            && !self.change_detected
            && self.drive_locked
            && self.settled
            && !self.gated
    }
}

/// Counters since start-up.
///
/// **Overflow, decided per counter** (at 500 Hz a `u32` that counts every tick lasts
/// 2³² / 500 s ≈ 99.4 days; a bare `+= 1` would then panic in a build with overflow
/// checks and wrap silently in release):
///
/// * `samples` **wraps** (modulo 2³²) on purpose: it is a sequence number, read as a
///   difference between two reads (`b.wrapping_sub(a)` is right across the wrap), and a
///   saturated sequence number would stop telling lost samples apart. The estimator's
///   own sample index ([`crate::Estimator::samples`]) is a `u64` and never wraps
///   (2⁶⁴ ticks ≈ 1.2e9 years).
/// * every other counter **saturates** at `u32::MAX` ([`Counters::bump`]): it counts
///   events, and a saturated count still reads "at least 4 294 967 295", where a wrapped
///   one would claim that nothing happened. Only `updates` can get there in practice
///   (≈ 99 days of clean samples); the others need as many faults or resets.
///
/// The RLS statistics saturate as well (`rls`), the stuck detector's repeat counts
/// saturate (`monitor`), and the retune supervisor's own count saturates (`retune`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counters {
    /// Samples seen (wraps modulo 2³²: a sequence number).
    pub samples: u32,
    /// Samples used for RLS updates (saturates).
    pub updates: u32,
    /// Samples flagged as bad and skipped (saturates).
    pub bad_samples: u32,
    /// … because of a NaN or infinite value (saturates).
    pub non_finite: u32,
    /// … because a channel was saturated (saturates).
    pub saturated: u32,
    /// … because a lock-in channel was stuck (saturates).
    pub stuck: u32,
    /// Covariance resets of the drive RLS by the change detector (saturates).
    pub resets_drive: u32,
    /// Covariance resets of the sense RLS (saturates).
    pub resets_sense: u32,
    /// Change alarms read as a drift, which opened the drift column's walk instead of a
    /// covariance reset (`drift`; saturates).
    pub drift_alarms: u32,
    /// Retunes started (saturates).
    pub retunes: u32,
    /// Retunes aborted because the drive lock was lost (saturates).
    pub retune_aborts: u32,
    /// Commanded pump jumps (saturates).
    pub jumps: u32,
}

impl Counters {
    /// Adds `n` to the event counter `c`, saturating at `u32::MAX` (never wraps, never
    /// panics). Every counter but `samples` is counted with this.
    #[inline(always)]
    pub fn bump(c: &mut u32, n: u32) {
        *c = c.saturating_add(n);
    }

    /// Samples seen between two reads of `samples`, right across its wrap.
    #[inline]
    pub fn samples_since(&self, earlier: &Counters) -> u32 {
        self.samples.wrapping_sub(earlier.samples)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bits_follow_the_documented_order() {
        let h = Health {
            inputs_valid: true,
            settled: true,
            retuning: true,
            ..Health::default()
        };
        assert_eq!(h.bits(), 1 | (1 << 5) | (1 << 7));
        assert!(!h.actionable());
        let ok = Health {
            inputs_valid: true,
            excitation_ok: true,
            covariance_bounded: true,
            drive_locked: true,
            settled: true,
            ..Health::default()
        };
        assert!(ok.actionable());
        assert!(!Health { gated: true, ..ok }.actionable());
    }

    #[test]
    fn event_counters_saturate_at_the_boundary() {
        let mut c = u32::MAX - 2;
        Counters::bump(&mut c, 1);
        assert_eq!(c, u32::MAX - 1);
        Counters::bump(&mut c, 1);
        assert_eq!(c, u32::MAX);
        Counters::bump(&mut c, 1);
        assert_eq!(c, u32::MAX, "wrapped past the top");
        Counters::bump(&mut c, 0);
        assert_eq!(c, u32::MAX);
        let mut d = u32::MAX - 1;
        Counters::bump(&mut d, 7);
        assert_eq!(d, u32::MAX);
    }

    #[test]
    fn estimator_counters_at_the_top_saturate_and_the_sample_number_wraps() {
        let mut est = crate::Config::table2().build::<f32>().unwrap();
        {
            let (_, st) = est.parts_mut();
            st.counters = Counters {
                samples: u32::MAX,
                bad_samples: u32::MAX,
                non_finite: u32::MAX - 1,
                ..Counters::default()
            };
        }
        // a NaN sample: bad, non-finite (a step with `+= 1` here panicked with overflow
        // checks, which the test profile has)
        let bad = crate::Sample::<f32> {
            pump_hz: f64::NAN,
            ..crate::Sample::default()
        };
        for _ in 0..3 {
            let _ = est.step(&bad);
        }
        let c = est.counters();
        assert_eq!(c.samples, 2, "the sequence number wraps");
        assert_eq!(c.bad_samples, u32::MAX, "bad_samples saturates");
        assert_eq!(c.non_finite, u32::MAX, "non_finite saturates");
        assert_eq!(est.samples(), 3, "the u64 sample index does not wrap");
    }

    #[test]
    fn sample_sequence_number_difference_is_right_across_the_wrap() {
        let a = Counters {
            samples: u32::MAX - 4,
            ..Counters::default()
        };
        let b = Counters {
            samples: a.samples.wrapping_add(10),
            ..Counters::default()
        };
        assert_eq!(b.samples, 5);
        assert_eq!(b.samples_since(&a), 10);
    }
}
