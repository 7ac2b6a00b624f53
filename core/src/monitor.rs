//! Input validation, the innovation change detector, the excitation measure and the
//! settle test.
//!
//! * **Inputs.** Every lock-in channel, the accelerometer and the pump command are
//!   checked each tick: non-finite (NaN, ±Inf), saturated (at or beyond full scale) or
//!   stuck (the same value repeated; real data always carries noise). A bad sample is
//!   flagged, counted and skipped: the filters see the last good values and the RLS is
//!   gated for a short recovery time; the estimate is held.
//! * **Change detector.** EWMA of the sum over one sample's rows of the normalised
//!   squared innovations e²/(1 + φᵀPφ) (rows are weighted to unit noise, so the nominal
//!   level is about the number of rows). Beyond the threshold (FINDINGS §5: 1e3) the
//!   covariance is reset so the RLS re-identifies quickly after a parameter change.
//! * **Excitation.** rms of the replica pump-frequency deviation about its running mean:
//!   steady operation is not persistently exciting (rank 5 of 8), the dither is.
//! * **Settled.** ω̂y² moved less than a relative tolerance over a window.

use crate::real::Real;

/// Outcome of the input check.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct InputCheck {
    /// Some value is NaN or infinite.
    pub non_finite: bool,
    /// Some channel is at or beyond full scale.
    pub saturated: bool,
    /// Some lock-in channel repeats the same value.
    pub stuck: bool,
}

impl InputCheck {
    /// The sample is usable.
    pub fn ok(&self) -> bool {
        !(self.non_finite || self.saturated || self.stuck)
    }
}

/// Number of lock-in channels checked for stuck values (X0, A1..3 re/im, Y0, B1..3 re/im).
pub const N_LOCKIN_CH: usize = 14;

/// Stuck-channel detector: counts repeats of the exact same value per channel.
#[derive(Clone, Copy, Debug)]
pub struct StuckDetector<T> {
    last: [T; N_LOCKIN_CH],
    repeats: [u32; N_LOCKIN_CH],
    limit: u32,
}

impl<T: Real> StuckDetector<T> {
    /// A placeholder with no design (all zero), built in place by
    /// [`crate::Estimator::blank`]; never used before it is rebuilt.
    #[inline(always)]
    pub(crate) fn blank() -> Self {
        StuckDetector {
            last: [T::ZERO; N_LOCKIN_CH],
            repeats: [0; N_LOCKIN_CH],
            limit: 0,
        }
    }

    /// `limit` repeats make a channel stuck (0 disables).
    pub fn new(limit: u32) -> Self {
        StuckDetector {
            last: [T::ZERO; N_LOCKIN_CH],
            repeats: [0; N_LOCKIN_CH],
            limit,
        }
    }
    /// Feeds one sample's channels; true if any is stuck.
    pub fn push(&mut self, ch: &[T; N_LOCKIN_CH]) -> bool {
        if self.limit == 0 {
            return false;
        }
        let mut stuck = false;
        for i in 0..N_LOCKIN_CH {
            if ch[i] == self.last[i] {
                self.repeats[i] = self.repeats[i].saturating_add(1);
            } else {
                self.repeats[i] = 0;
                self.last[i] = ch[i];
            }
            if self.repeats[i] >= self.limit {
                stuck = true;
            }
        }
        stuck
    }
}

/// The innovation change detector of one axis.
#[derive(Clone, Copy, Debug)]
pub struct ChangeDetector<T> {
    level: T,
    nominal: T,
    alpha: T,
    threshold: T,
    hold: u64,
    last_alarm: Option<u64>,
}

impl<T: Real> ChangeDetector<T> {
    /// A placeholder with no design (all zero), built in place by
    /// [`crate::Estimator::blank`]; never used before it is rebuilt.
    #[inline(always)]
    pub(crate) fn blank() -> Self {
        ChangeDetector {
            level: T::ZERO,
            nominal: T::ZERO,
            alpha: T::ZERO,
            threshold: T::ZERO,
            hold: 0,
            last_alarm: None,
        }
    }

    /// `nominal` level (number of rows), EWMA weight, threshold, hold (samples).
    pub fn new(nominal: f64, alpha: f64, threshold: f64, hold: u64) -> Self {
        ChangeDetector {
            level: T::from_f64(nominal),
            nominal: T::from_f64(nominal),
            alpha: T::from_f64(alpha),
            threshold: T::from_f64(threshold),
            hold,
            last_alarm: None,
        }
    }
    /// Current EWMA level.
    pub fn level(&self) -> f64 {
        self.level.to_f64()
    }
    /// Feeds the sum of one sample's normalised squared innovations; true on alarm
    /// (the level then restarts at nominal).
    pub fn push(&mut self, k: u64, sum_norm_sq: T) -> bool {
        if !sum_norm_sq.is_finite() {
            return false;
        }
        self.level += self.alpha * (sum_norm_sq - self.level);
        let free = match self.last_alarm {
            None => true,
            Some(a) => k >= a + self.hold,
        };
        if self.level > self.threshold && free {
            self.last_alarm = Some(k);
            self.level = self.nominal;
            return true;
        }
        false
    }
    /// Sample of the last alarm.
    pub fn last_alarm(&self) -> Option<u64> {
        self.last_alarm
    }
    /// Back to nominal (e.g. after a commanded jump).
    pub fn rearm(&mut self) {
        self.level = self.nominal;
    }
}

/// rms of a signal about its running mean (EWMA with weight `alpha`).
#[derive(Clone, Copy, Debug)]
pub struct ExcitationMeter<T> {
    mean: T,
    var: T,
    alpha: T,
}

impl<T: Real> ExcitationMeter<T> {
    /// A placeholder with no design (all zero), built in place by
    /// [`crate::Estimator::blank`]; never used before it is rebuilt.
    #[inline(always)]
    pub(crate) fn blank() -> Self {
        ExcitationMeter {
            mean: T::ZERO,
            var: T::ZERO,
            alpha: T::ZERO,
        }
    }

    /// EWMA weight per sample.
    pub fn new(alpha: f64) -> Self {
        ExcitationMeter {
            mean: T::ZERO,
            var: T::ZERO,
            alpha: T::from_f64(alpha),
        }
    }
    /// Feeds one value; returns the current variance.
    pub fn push(&mut self, v: T) -> T {
        self.mean += self.alpha * (v - self.mean);
        let d = v - self.mean;
        self.var += self.alpha * (d * d - self.var);
        self.var
    }
    /// Current rms.
    pub fn rms(&self) -> f64 {
        libm::sqrt(self.var.to_f64().max(0.0))
    }
}

/// Capacity of the settle window ring.
pub const SETTLE_RING: usize = 16;

/// Settle test on one scalar, sampled at a low rate into a small ring, in the
/// estimator's precision `T` (the values are `T` in the first place; in `f64` on the chip
/// it was ~2k soft-float instructions on every 25th tick).
#[derive(Clone, Copy, Debug)]
pub struct SettleTest<T> {
    ring: [T; SETTLE_RING],
    len: usize,
    pos: usize,
    every: u64,
    need: usize,
    tol: T,
    /// The verdict, recomputed when a value is pushed (the tick only reads it).
    verdict: bool,
}

impl<T: Real> SettleTest<T> {
    /// A placeholder with no design (all zero), built in place by
    /// [`crate::Estimator::blank`]; never used before it is rebuilt.
    #[inline(always)]
    pub(crate) fn blank() -> Self {
        SettleTest {
            ring: [T::ZERO; SETTLE_RING],
            len: 0,
            pos: 0,
            every: 1,
            need: 1,
            tol: T::ZERO,
            verdict: false,
        }
    }

    /// Keeps one value every `every` samples; settled when the last `need` (≤ 16)
    /// values span less than `tol` relative.
    pub fn new(every: u64, need: usize, tol: f64) -> Self {
        SettleTest {
            ring: [T::ZERO; SETTLE_RING],
            len: 0,
            pos: 0,
            every: every.max(1),
            need: need.clamp(2, SETTLE_RING),
            tol: T::from_f64(tol),
            verdict: false,
        }
    }
    /// Forgets the history.
    pub fn clear(&mut self) {
        self.len = 0;
        self.pos = 0;
        self.verdict = false;
    }
    /// Feeds the value at sample `k`.
    pub fn push(&mut self, k: u64, v: T) {
        if !k.is_multiple_of(self.every) {
            return;
        }
        if !v.is_finite() {
            self.clear();
            return;
        }
        self.ring[self.pos] = v;
        self.pos = (self.pos + 1) % SETTLE_RING;
        self.len = (self.len + 1).min(SETTLE_RING);
        self.verdict = self.evaluate();
    }
    /// Settled now.
    pub fn settled(&self) -> bool {
        self.verdict
    }
    fn evaluate(&self) -> bool {
        if self.len < self.need {
            return false;
        }
        // finite values only (push clears on a non-finite one), so `Real::min/max` agree
        // with `f64::min/max`
        let mut lo = T::MAX;
        let mut hi = -T::MAX;
        for i in 0..self.need {
            let idx = (self.pos + SETTLE_RING - 1 - i) % SETTLE_RING;
            lo = lo.min(self.ring[idx]);
            hi = hi.max(self.ring[idx]);
        }
        let scale = hi.abs().max(lo.abs()).max(T::from_f64(1e-30));
        (hi - lo) / scale < self.tol
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn lcg(s: &mut u64) -> f64 {
        *s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    /// Gaussian-ish (sum of 12 uniforms) normalised squared innovations of 5 rows.
    fn noise_sum(s: &mut u64) -> f64 {
        let mut sum = 0.0;
        for _ in 0..5 {
            let g: f64 = (0..12).map(|_| 0.5 * (lcg(s) + 1.0)).sum::<f64>() - 6.0;
            sum += g * g;
        }
        sum
    }

    #[test]
    fn change_detector_quiet_on_noise_fires_on_step() {
        let mut s = 7u64;
        let mut d = ChangeDetector::<f64>::new(5.0, 0.05, 1e3, 25);
        for k in 0..100_000u64 {
            assert!(!d.push(k, noise_sum(&mut s)), "false alarm at {k}");
        }
        // a parameter change: innovations 30σ on every row → sum ≈ 5·900
        let mut fired = None;
        for k in 100_000..100_100u64 {
            if d.push(k, noise_sum(&mut s) + 5.0 * 900.0) {
                fired = Some(k);
                break;
            }
        }
        let k = fired.expect("detector did not fire on the step");
        assert!(k - 100_000 < 10, "slow detection: {} samples", k - 100_000);
    }

    #[test]
    fn stuck_detector() {
        let mut d = StuckDetector::<f32>::new(5);
        let mut ch = [0.0f32; N_LOCKIN_CH];
        for k in 0..100 {
            for (i, c) in ch.iter_mut().enumerate() {
                *c = (k * 31 + i) as f32;
            }
            assert!(!d.push(&ch));
        }
        // channel 3 freezes
        let mut hit = 0;
        for k in 100..110 {
            for (i, c) in ch.iter_mut().enumerate() {
                if i != 3 {
                    *c = (k * 31 + i) as f32;
                }
            }
            if d.push(&ch) {
                hit = k;
                break;
            }
        }
        assert_eq!(hit, 104, "the 5th repeat of the frozen value");
        assert!(!StuckDetector::<f32>::new(0).push(&ch));
    }

    #[test]
    fn settle_and_excitation() {
        let mut st = SettleTest::<f64>::new(50, 6, 2e-5);
        for k in 0..300u64 {
            st.push(k, 1.03 + 1e-3 * (-(k as f64) / 20.0).exp());
        }
        assert!(!st.settled());
        for k in 300..1000u64 {
            st.push(k, 1.03 + 1e-7 * (k as f64 * 0.1).sin());
        }
        assert!(st.settled());
        let mut m = ExcitationMeter::<f64>::new(0.004);
        for k in 0..5000 {
            m.push(1e-3 * (2.0 * core::f64::consts::PI * 2.0 * k as f64 / 500.0).sin());
        }
        let r = m.rms();
        assert!((r - 1e-3 / 2f64.sqrt()).abs() < 1e-4, "rms {r}");
    }
}
