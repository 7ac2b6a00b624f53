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
//!   steady operation is not persistently exciting (rank 5 of 8), the dither is. Below
//!   the threshold (once it has been above) the RLS does not forget (`rls.rs`,
//!   "Anti-windup").
//! * **Settled.** ω̂y² moved less than a relative tolerance over a window.

use crate::real::Real;
use crate::sample::Sample;

pub use crate::sample::N_LOCKIN_CH;

/// `$m!(i)` for every lock-in channel index, written out: the per-sample checks ran as
/// loops at ≈ 11–13 instructions a channel on the M4F (`opt-level = "z"` keeps loops).
macro_rules! each_channel {
    ($m:ident) => {
        $m!(0);
        $m!(1);
        $m!(2);
        $m!(3);
        $m!(4);
        $m!(5);
        $m!(6);
        $m!(7);
        $m!(8);
        $m!(9);
        $m!(10);
        $m!(11);
        $m!(12);
        $m!(13);
    };
}
const _: () = assert!(N_LOCKIN_CH == 14, "each_channel! lists 14 channels");

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

    /// Checks one sample: every lock-in channel and the accelerometer finite and inside
    /// its full scale, the pump frequency finite and positive, the pump scale finite and
    /// ≥ 0; then (only for a finite sample) feeds the stuck detector.
    #[inline]
    pub fn of<T: Real>(
        s: &Sample<T>,
        limits: &InputLimits<T>,
        stuck: &mut StuckDetector<T>,
    ) -> InputCheck {
        let ch = s.lockin.channels();
        let mut c = InputCheck::default();
        let fs = limits.full_scale_um;
        let afs = limits.accel_full_scale_mps2;
        // one comparison per channel on the common path (`|v| < fs` is false for NaN and
        // ±∞ as well as at full scale); which fault it is only when one failed it
        let mut inside = s.accel_mps2[0].abs() < afs && s.accel_mps2[1].abs() < afs;
        macro_rules! inside {
            ($i:expr) => {
                inside &= ch[$i].abs() < fs
            };
        }
        each_channel!(inside);
        if !inside {
            c.classify(&ch, fs);
            c.classify(&s.accel_mps2, afs);
        }
        // finite and > 0 from the bits (0 < bits < those of +∞: sign clear, not ±0, not
        // ∞ or NaN), not an f64 comparison (soft float on the chip)
        let pump_ok = (1..f64::INFINITY.to_bits()).contains(&s.pump_hz.to_bits());
        if !(pump_ok && s.pump_scale.is_finite() && s.pump_scale >= T::ZERO) {
            c.non_finite = true;
        }
        if !c.non_finite && stuck.push(limits.stuck_samples, &ch) {
            c.stuck = true;
        }
        c
    }

    /// Sets `non_finite` or `saturated` for each channel of `v` that is not finite or at
    /// or beyond ±`full_scale`.
    #[inline(never)]
    fn classify<T: Real, const N: usize>(&mut self, v: &[T; N], full_scale: T) {
        for v in v.iter() {
            if !v.is_finite() {
                self.non_finite = true;
            } else if v.abs() >= full_scale {
                self.saturated = true;
            }
        }
    }
}

/// The limits of the input check (design: from `monitor.*` of the configuration).
#[derive(Clone, Copy, Debug, Default)]
pub struct InputLimits<T> {
    /// A lock-in channel at or beyond ±this is saturated, µm.
    pub full_scale_um: T,
    /// An accelerometer channel at or beyond ±this is saturated, m/s².
    pub accel_full_scale_mps2: T,
    /// Repeats of the same value that make a lock-in channel stuck (0 disables).
    pub stuck_samples: u32,
}

/// Stuck-channel detector: counts repeats of the exact same value per channel.
#[derive(Clone, Copy, Debug, Default)]
pub struct StuckDetector<T> {
    last: [T; N_LOCKIN_CH],
    repeats: [u32; N_LOCKIN_CH],
}

impl<T: Real> StuckDetector<T> {
    /// Feeds one sample's channels; true if any repeated its value `limit` times
    /// (`limit` 0 disables the detector).
    pub fn push(&mut self, limit: u32, ch: &[T; N_LOCKIN_CH]) -> bool {
        if limit == 0 {
            return false;
        }
        let mut stuck = false;
        macro_rules! push {
            ($i:expr) => {{
                let i = $i;
                if ch[i] == self.last[i] {
                    self.repeats[i] = self.repeats[i].saturating_add(1);
                } else {
                    self.repeats[i] = 0;
                    self.last[i] = ch[i];
                }
                stuck |= self.repeats[i] >= limit;
            }};
        }
        each_channel!(push);
        stuck
    }
}

/// Design of the change detector (shared by both axes).
#[derive(Clone, Copy, Debug, Default)]
pub struct ChangeDesign<T> {
    nominal: T,
    alpha: T,
    threshold: T,
    /// The drift-like margin (`monitor.change_drift_margin`, [`DRIFT_MARGIN`] by default)
    /// times `threshold`.
    drift_level: T,
    hold: u64,
}

/// How far past its threshold the detector's level may be, at the sample it crosses, for
/// the alarm to read as a lag a drift built up ([`ChangeDetector::drift_like`]). A drift
/// the slow RLS does not follow raises the level a little each sample and it crosses by
/// 0.1–20 % (`paragyro-sim thermal host-sim/scenarios/warm-up-cycle.toml --no-sensor`: the
/// cooling ramp's sudden onset and the alarms after it, 1.006–1.198); a drift the rate gate
/// held the slow RLS through for 0.3 s (the gate a sudden onset can open) crosses by
/// 18.5× on the sense and 2.0× on the drive (the 10 K warm-up from 30.4 s, `--no-sensor
/// --seed 4`). The fault campaign's first alarms of an episode cross by 1.0–16 (an
/// out-of-band drive, a pump collapse, a parameter jump) up to 10³–10⁷ (spikes, time
/// jumps, an over-range rate). The level does not tell a slow fault from a drift: what
/// does is that a drift's lag is taken up by its column alone, while a fault's or another
/// parameter's is not and its next alarm resets the axis (the estimator's `update`).
/// Measured with `paragyro-sim faults --ticks 100000`: every class recovers as with every
/// alarm a reset, at 1.5 and at 25.
pub const DRIFT_MARGIN: f64 = 25.0;

impl<T: Real> ChangeDesign<T> {
    /// `nominal` level (number of rows), EWMA weight, threshold, the drift-like margin
    /// ([`DRIFT_MARGIN`] by default; 0: no alarm is drift-like), hold (samples).
    pub fn new(nominal: f64, alpha: f64, threshold: f64, drift_margin: f64, hold: u64) -> Self {
        ChangeDesign {
            nominal: T::from_f64(nominal),
            alpha: T::from_f64(alpha),
            threshold: T::from_f64(threshold),
            drift_level: T::from_f64(threshold * drift_margin),
            hold,
        }
    }
}

/// The innovation change detector of one axis (state; its design is a [`ChangeDesign`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct ChangeDetector<T> {
    level: T,
    last_alarm: Option<u64>,
    /// The level at the last alarm, where it crossed the threshold.
    crossed: T,
}

impl<T: Real> ChangeDetector<T> {
    /// At the nominal level, no alarm yet.
    pub fn new(d: &ChangeDesign<T>) -> Self {
        ChangeDetector {
            level: d.nominal,
            last_alarm: None,
            crossed: T::ZERO,
        }
    }
    /// Current EWMA level.
    pub fn level(&self) -> f64 {
        self.level.to_f64()
    }
    /// Feeds the sum of one sample's normalised squared innovations; true on alarm
    /// (the level then restarts at nominal).
    pub fn push(&mut self, d: &ChangeDesign<T>, k: u64, sum_norm_sq: T) -> bool {
        if !sum_norm_sq.is_finite() {
            return false;
        }
        self.level += d.alpha * (sum_norm_sq - self.level);
        let free = match self.last_alarm {
            None => true,
            Some(a) => k >= a + d.hold,
        };
        if self.level > d.threshold && free {
            self.last_alarm = Some(k);
            self.crossed = self.level;
            self.level = d.nominal;
            return true;
        }
        false
    }
    /// The last alarm's level crossed the threshold by at most [`DRIFT_MARGIN`]: a lag
    /// that grew sample by sample, as a drift's, not a jump's.
    #[inline(always)]
    pub fn drift_like(&self, d: &ChangeDesign<T>) -> bool {
        self.crossed <= d.drift_level
    }
    /// Sample of the last alarm.
    pub fn last_alarm(&self) -> Option<u64> {
        self.last_alarm
    }
    /// Back to nominal (e.g. after a commanded jump).
    pub fn rearm(&mut self, d: &ChangeDesign<T>) {
        self.level = d.nominal;
    }
}

/// rms of a signal about its running mean (EWMA; the weight is the caller's design).
#[derive(Clone, Copy, Debug, Default)]
pub struct ExcitationMeter<T> {
    mean: T,
    var: T,
}

impl<T: Real> ExcitationMeter<T> {
    /// Feeds one value with EWMA weight `alpha`; returns the current variance.
    pub fn push(&mut self, alpha: T, v: T) -> T {
        self.mean += alpha * (v - self.mean);
        let d = v - self.mean;
        self.var += alpha * (d * d - self.var);
        self.var
    }
    /// Current rms.
    pub fn rms(&self) -> f64 {
        libm::sqrt(self.var.to_f64().max(0.0))
    }
}

/// Capacity of the settle window.
pub const SETTLE_RING: usize = 16;

/// Design of the settle test: one value kept every `every` samples; settled when the
/// last `need` (2..=16) values span less than `tol` relative.
#[derive(Clone, Copy, Debug, Default)]
pub struct SettleDesign<T> {
    every: u64,
    need: usize,
    tol: T,
}

impl<T: Real> SettleDesign<T> {
    /// How many values must agree.
    pub fn need(&self) -> usize {
        self.need
    }
    /// Keeps one value every `every` samples; settled when the last `need` (≤ 16)
    /// values span less than `tol` relative.
    pub fn new(every: u64, need: usize, tol: f64) -> Self {
        SettleDesign {
            every: every.max(1),
            need: need.clamp(2, SETTLE_RING),
            tol: T::from_f64(tol),
        }
    }
}

/// Settle test on one scalar, sampled at a low rate into a ring of [`SETTLE_RING`]
/// values, in the estimator's precision `T` (the values are `T` in the first place; in
/// `f64` on the chip it would be ~2k soft-float instructions on every 25th tick).
///
/// Its own ring rather than `heapless::HistoryBuf` (whose `write` has bounds checks, the
/// last ones on the tick path that kept `core::fmt` in the firmware image), and the
/// sampling test without a 64-bit division per tick (one every gap, see
/// [`SettleTest::push`]).
#[derive(Clone, Debug)]
pub struct SettleTest<T> {
    ring: [T; SETTLE_RING],
    /// Slot of the next write (`< SETTLE_RING`).
    at: usize,
    /// Values held (`≤ SETTLE_RING`).
    len: usize,
    /// The next `k` that is a multiple of `every` (after the last sampling test).
    next_due: u64,
    /// The `every` that `next_due` belongs to (0: none yet).
    every: u64,
    /// The verdict, recomputed when a value is pushed (the tick only reads it).
    verdict: bool,
}

impl<T: Real> Default for SettleTest<T> {
    fn default() -> Self {
        SettleTest {
            ring: [T::ZERO; SETTLE_RING],
            at: 0,
            len: 0,
            next_due: 0,
            every: 0,
            verdict: false,
        }
    }
}

/// `n mod d` for `d > 0`: a 32-bit division when both fit (the first 99 days at 500 Hz;
/// the M4F divides in hardware), else binary long division (64 steps). No 64-bit division
/// routine (the chip has none, and this is only needed after a gap in the samples).
fn rem_u64(n: u64, d: u64) -> u64 {
    if let (Ok(n32), Ok(d32)) = (u32::try_from(n), u32::try_from(d))
        && d32 != 0
    {
        return u64::from(n32 % d32);
    }
    let mut r: u64 = 0;
    for i in (0..64).rev() {
        let carry = r >> 63;
        r = (r << 1) | ((n >> i) & 1);
        // the true value is carry·2^64 + r < 2d: one subtraction brings it below d
        if carry != 0 || r >= d {
            r = r.wrapping_sub(d);
        }
    }
    r
}

impl<T: Real> SettleTest<T> {
    /// Forgets the history.
    pub fn clear(&mut self) {
        self.at = 0;
        self.len = 0;
        self.verdict = false;
    }
    /// `k` is a multiple of `every` (> 0). Exact for any sequence of `k`; one comparison
    /// when `k` is the next multiple or lies between two (the tick path's rising `k`),
    /// a long division otherwise (after a gap, a new design or a `k` that went back).
    fn sampled(&mut self, every: u64, k: u64) -> bool {
        if every == 0 {
            return k == 0; // a blank design (`u64::is_multiple_of(0)`)
        }
        if every == self.every {
            if k == self.next_due {
                self.advance(k, every);
                return true;
            }
            // strictly between the multiple before `next_due` and `next_due`
            if k < self.next_due && self.next_due - k < every {
                return false;
            }
        }
        let r = rem_u64(k, every);
        // the next multiple after `k`
        self.advance(k - r, every);
        r == 0
    }
    /// `next_due` ← the multiple `m + every` (none past `u64::MAX`: the next test then
    /// takes the long way).
    fn advance(&mut self, m: u64, every: u64) {
        match m.checked_add(every) {
            Some(n) => {
                self.next_due = n;
                self.every = every;
            }
            None => self.every = 0,
        }
    }
    /// Feeds the value at sample `k`.
    pub fn push(&mut self, d: &SettleDesign<T>, k: u64, v: T) {
        if !self.sampled(d.every, k) {
            return;
        }
        if !v.is_finite() {
            self.clear();
            return;
        }
        if let Some(slot) = self.ring.get_mut(self.at) {
            *slot = v;
        }
        self.at = if self.at + 1 >= SETTLE_RING {
            0
        } else {
            self.at + 1
        };
        self.len = (self.len + 1).min(SETTLE_RING);
        self.verdict = self.evaluate(d);
    }
    /// A warm start: the history holds `keep` copies (at most `need − 1`) of the
    /// remembered value `v`, so `need − keep` new values within the tolerance of it and of
    /// each other settle; new values that disagree keep the test open until the
    /// remembered ones have left the window, as from a cold start.
    pub fn seed(&mut self, d: &SettleDesign<T>, v: T, keep: usize) {
        self.clear();
        if !v.is_finite() {
            return;
        }
        for _ in 0..keep.min(d.need.saturating_sub(1)) {
            if let Some(slot) = self.ring.get_mut(self.at) {
                *slot = v;
            }
            self.at = if self.at + 1 >= SETTLE_RING {
                0
            } else {
                self.at + 1
            };
            self.len = (self.len + 1).min(SETTLE_RING);
        }
    }
    /// Settled now.
    pub fn settled(&self) -> bool {
        self.verdict
    }
    fn evaluate(&self, d: &SettleDesign<T>) -> bool {
        if self.len < d.need {
            return false;
        }
        // finite values only (push clears on a non-finite one), so `Real::min/max` agree
        // with `f64::min/max`, and the span does not depend on the order: the newest
        // `need` values, walking back from the last write
        let mut lo = T::MAX;
        let mut hi = -T::MAX;
        let mut i = self.at;
        for _ in 0..d.need {
            i = if i == 0 { SETTLE_RING - 1 } else { i - 1 };
            if let Some(&v) = self.ring.get(i) {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        let scale = hi.abs().max(lo.abs()).max(T::from_f64(1e-30));
        (hi - lo) / scale < d.tol
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    #[test]
    fn long_division_remainder_is_exact() {
        let mut s = 7u64;
        for _ in 0..20_000 {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1);
            let n = s;
            for d in [1, 2, 3, 25, 1000, 1 << 32, (1 << 63) + 5, u64::MAX, n | 1] {
                assert_eq!(rem_u64(n, d), n % d, "{n} mod {d}");
                let small = n >> 40;
                assert_eq!(rem_u64(small, d), small % d, "{small} mod {d}");
            }
        }
    }

    #[test]
    fn sampling_test_equals_is_multiple_of_for_any_sequence() {
        let mut t = SettleTest::<f32>::default();
        let mut s = 3u64;
        let mut k = 0u64;
        let mut every = 25u64;
        for step in 0..200_000u32 {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            // mostly k + 1; sometimes a gap, a jump back, a new `every`, huge k
            k = match (s >> 58) as u8 {
                0 => k.saturating_sub(s >> 50 & 0xFFF),
                1 => k.saturating_add(s >> 40 & 0xFFFF),
                2 => u64::MAX - (s >> 40 & 0xFF),
                3 => 0,
                _ => k.saturating_add(1),
            };
            if step % 5000 == 0 {
                every = [25, 1, 7, 1000, 0][(step / 5000) as usize % 5];
            }
            assert_eq!(
                t.sampled(every, k),
                k.is_multiple_of(every),
                "k {k} every {every}"
            );
        }
    }

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
        let dd = ChangeDesign::<f64>::new(5.0, 0.05, 1e3, DRIFT_MARGIN, 25);
        let mut d = ChangeDetector::new(&dd);
        for k in 0..100_000u64 {
            assert!(!d.push(&dd, k, noise_sum(&mut s)), "false alarm at {k}");
        }
        // a parameter change: innovations 30σ on every row → sum ≈ 5·900
        let mut fired = None;
        for k in 100_000..100_100u64 {
            if d.push(&dd, k, noise_sum(&mut s) + 5.0 * 900.0) {
                fired = Some(k);
                break;
            }
        }
        let k = fired.expect("detector did not fire on the step");
        assert!(k - 100_000 < 10, "slow detection: {} samples", k - 100_000);
    }

    #[test]
    fn a_lag_that_grows_reads_as_a_drift_a_jump_does_not() {
        let dd = ChangeDesign::<f64>::new(12.0, 0.05, 1e3, DRIFT_MARGIN, 25);
        // a drift's lag: the innovations grow sample by sample and the level crosses the
        // threshold by a little
        let mut d = ChangeDetector::new(&dd);
        let fired = (0..10_000u64).find(|&k| d.push(&dd, k, 12.0 + 0.5 * k as f64));
        assert!(fired.is_some());
        assert!(d.drift_like(&dd));
        // a jump: one sample takes the level past the threshold by far more than the margin
        let mut d = ChangeDetector::new(&dd);
        assert!(!d.push(&dd, 0, 12.0));
        assert!(d.push(&dd, 1, 1e3 * DRIFT_MARGIN / 0.05 * 1.01));
        assert!(!d.drift_like(&dd));
        // and the next alarm, grown again, reads as a drift
        let fired = (2..10_000u64).find(|&k| d.push(&dd, k, 12.0 + 0.5 * k as f64));
        assert!(fired.is_some_and(|k| k >= 27), "{fired:?}: within the hold");
        assert!(d.drift_like(&dd));
        // with a margin of 0 no alarm is drift-like (`monitor.change_drift_margin`)
        let d0 = ChangeDesign::<f64>::new(12.0, 0.05, 1e3, 0.0, 25);
        let mut d = ChangeDetector::new(&d0);
        assert!((0..10_000u64).any(|k| d.push(&d0, k, 12.0 + 0.5 * k as f64)));
        assert!(!d.drift_like(&d0));
    }

    #[test]
    fn stuck_detector() {
        // every channel in turn freezes (the checks are written out per channel)
        for frozen in 0..N_LOCKIN_CH {
            let mut d = StuckDetector::<f32>::default();
            let mut ch = [0.0f32; N_LOCKIN_CH];
            for k in 0..100 {
                for (i, c) in ch.iter_mut().enumerate() {
                    *c = (k * 31 + i) as f32;
                }
                assert!(!d.push(5, &ch));
            }
            let mut hit = 0;
            for k in 100..110 {
                for (i, c) in ch.iter_mut().enumerate() {
                    if i != frozen {
                        *c = (k * 31 + i) as f32;
                    }
                }
                if d.push(5, &ch) {
                    hit = k;
                    break;
                }
            }
            assert_eq!(
                hit, 104,
                "channel {frozen}: the 5th repeat of the frozen value"
            );
            assert!(!StuckDetector::<f32>::default().push(0, &ch));
        }
    }

    /// Every lock-in and accelerometer channel is checked (written out per channel), and
    /// the pump frequency's bit test is `finite && > 0`.
    #[test]
    fn input_check_flags_every_channel_and_a_bad_pump() {
        use crate::complex::Cplx;
        use crate::sample::Lockin;
        let limits = InputLimits {
            full_scale_um: 10.0f32,
            accel_full_scale_mps2: 100.0,
            stuck_samples: 0,
        };
        let mut stuck = StuckDetector::default();
        let good = Sample {
            lockin: Lockin {
                x0_um: 0.1,
                x_um: [Cplx::new(1.0, -1.0); 3],
                y0_um: 0.2,
                y_um: [Cplx::new(-2.0, 2.0); 3],
            },
            accel_mps2: [1.0, -1.0],
            pump_hz: 21_883.95,
            pump_scale: 1.0,
            temp_c: None,
        };
        assert!(InputCheck::of(&good, &limits, &mut stuck).ok());
        let set = |s: &mut Sample<f32>, i: usize, v: f32| match i {
            0 => s.lockin.x0_um = v,
            7 => s.lockin.y0_um = v,
            1..=6 => {
                let z = &mut s.lockin.x_um[(i - 1) / 2];
                if i % 2 == 1 { z.re = v } else { z.im = v }
            }
            _ => {
                let z = &mut s.lockin.y_um[(i - 8) / 2];
                if i.is_multiple_of(2) {
                    z.re = v
                } else {
                    z.im = v
                }
            }
        };
        for i in 0..N_LOCKIN_CH {
            for (v, nf, sat) in [
                (f32::NAN, true, false),
                (-f32::INFINITY, true, false),
                (-10.0, false, true),
            ] {
                let mut s = good;
                set(&mut s, i, v);
                assert_eq!(
                    s.lockin.channels()[i].to_bits(),
                    v.to_bits(),
                    "channel order"
                );
                let c = InputCheck::of(&s, &limits, &mut stuck);
                assert_eq!((c.non_finite, c.saturated), (nf, sat), "channel {i} = {v}");
            }
        }
        for i in 0..2 {
            for (v, nf, sat) in [(f32::NAN, true, false), (100.0, false, true)] {
                let mut s = good;
                s.accel_mps2[i] = v;
                let c = InputCheck::of(&s, &limits, &mut stuck);
                assert_eq!((c.non_finite, c.saturated), (nf, sat), "accel {i} = {v}");
            }
        }
        for (hz, ok) in [
            (0.0, false),
            (-0.0, false),
            (-1.0, false),
            (f64::NAN, false),
            (-f64::NAN, false),
            (f64::INFINITY, false),
            (f64::NEG_INFINITY, false),
            (f64::MIN_POSITIVE / 2.0, true),
            (f64::MAX, true),
            (1.0, true),
        ] {
            let s = Sample {
                pump_hz: hz,
                ..good
            };
            assert_eq!(
                InputCheck::of(&s, &limits, &mut stuck).ok(),
                ok,
                "pump {hz}"
            );
        }
    }

    #[test]
    fn settle_and_excitation() {
        let sd = SettleDesign::<f64>::new(50, 6, 2e-5);
        let mut st = SettleTest::default();
        for k in 0..300u64 {
            st.push(&sd, k, 1.03 + 1e-3 * (-(k as f64) / 20.0).exp());
        }
        assert!(!st.settled());
        for k in 300..1000u64 {
            st.push(&sd, k, 1.03 + 1e-7 * (k as f64 * 0.1).sin());
        }
        assert!(st.settled());
        st.clear();
        assert!(!st.settled());
        let mut m = ExcitationMeter::<f64>::default();
        for k in 0..5000 {
            m.push(
                0.004,
                1e-3 * (2.0 * core::f64::consts::PI * 2.0 * k as f64 / 500.0).sin(),
            );
        }
        let r = m.rms();
        assert!((r - 1e-3 / 2f64.sqrt()).abs() < 1e-4, "rms {r}");
    }
}
