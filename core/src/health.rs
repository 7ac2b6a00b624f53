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
    /// The pump-frequency excitation is sufficient for identification.
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
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counters {
    /// Samples seen.
    pub samples: u32,
    /// Samples used for RLS updates.
    pub updates: u32,
    /// Samples flagged as bad and skipped.
    pub bad_samples: u32,
    /// … because of a NaN or infinite value.
    pub non_finite: u32,
    /// … because a channel was saturated.
    pub saturated: u32,
    /// … because a lock-in channel was stuck.
    pub stuck: u32,
    /// Covariance resets of the drive RLS by the change detector.
    pub resets_drive: u32,
    /// Covariance resets of the sense RLS.
    pub resets_sense: u32,
    /// Retunes started.
    pub retunes: u32,
    /// Retunes aborted because the drive lock was lost.
    pub retune_aborts: u32,
    /// Commanded pump jumps.
    pub jumps: u32,
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
}
