//! Drift tracking: the temperature-driven parameters of the slow RLS as random walks
//! whose size follows what the device does.
//!
//! A device's natural frequencies move with its temperature (a silicon resonator's TCF is
//! about −30 ppm/K in frequency, so ω_x², ω_y² move ≈ −60 ppm/K): continuously, over a
//! warm-up of minutes or the ambient of a day. The slow RLS's exponential forgetting
//! follows such a ramp with a lag of about its memory times the drift rate, and the sense
//! and drive rows are so precise (ω̂y² to ≈ 1e-7 at 1 pm/√Hz) that a lag of a few ppm is
//! already many standard deviations of the innovation: without this module the change
//! detector reads every fraction of a second of a warm-up as a jump, resets the covariance
//! and blanks the rate (a 10 K warm-up over 300 s: 670 resets, the rate valid on 4.6 % of
//! the ramp).
//!
//! The parameters that drift with temperature — θ12 = −(ω_x² − γ² + 2β1) and
//! θ22 = −(ω_y² − γ²), column 1 of each axis — are random walks, the Kalman filter's process
//! noise on top of the RLS, sized by the drift the rows show:
//!
//! * **The measured drift.** u_j, an EWMA (time constant `rls.drift_window_s`/5) of the
//!   corrections the rows make to the column at each update, and the EWMA of their squares.
//!   Only what stands out of the EWMA's own noise (two standard deviations, ≈ √(α/2)·σ_c)
//!   counts: a device at a constant temperature measures no drift and keeps the whole
//!   memory of the slow RLS.
//! * **Process noise.** The column walks with `q_j = κ²·u_j²` per update
//!   ([`crate::rls::Rls::add_walk`]; each axis every fourth update with four times the
//!   variance, the chip's tick budget). Why this size: a random-walk Kalman filter with
//!   per-update information h on a ramp of slope u settles at a lag u/√(q·h), so the lag's
//!   share of the normalised innovation is √h·lag = u/√q = 1/κ: with κ = 3 a drift costs a
//!   third of the noise whatever its rate, and the change detector (threshold ≈ 14 σ per
//!   row) does not see it.
//! * **Lead.** The rows come out of the slow state-variable filter (10 Hz, ζ = 1), whose
//!   group delay at DC is 2/w_f = 32 ms: the estimate describes the device that long ago.
//!   What reads it as the device now — the fast rate channel's slow θ and the ω̂y² the
//!   retune supervisor reads — takes it advanced by u_j over that delay (a 10 K warm-up over
//!   40 s otherwise leaves the narrow channel's quadrature out of its gate on a quarter of
//!   the samples).
//!
//! A jump (a mode hop, a shock: ω_y² +0.3 % within 10 ms) moves the column by 3e-3 at once:
//! its innovations cross the detector's threshold on the first samples, and it is reset and
//! re-identified as before. The measured drift is capped at `rls.drift_max_ppm_s` (a faster
//! move is a jump), learns only from a settled estimate two windows after a reset (a
//! re-identification's corrections are not a drift) and is cleared by nothing else: a
//! warm-up that goes on through a jump is followed again once the estimate settles.

use crate::real::Real;

/// Columns of the RLS that drift with temperature: θ12 on the drive, θ22 on the sense
/// (the natural frequencies; column 1 of each axis).
pub const DRIFT_COL: usize = 1;

/// The design of the drift tracker (from `rls.drift_*`).
#[derive(Clone, Copy, Debug, Default)]
pub struct DriftDesign<T> {
    /// EWMA weight of the measured drift per update (5/(window · fs)); 0 disables the
    /// tracker.
    pub alpha: T,
    /// Updates after a covariance reset before the drift is measured (two windows).
    pub quiet: u64,
    /// The fastest drift the tracker follows, per update, in the RLS's scaled (relative)
    /// units (`rls.drift_max_ppm_s`): a faster move is a jump for the change detector.
    pub vmax: T,
    /// 4κ², the walk's variance per squared drift (each axis walks every fourth update).
    pub kappa2: T,
    /// The slow row filter's group delay at DC, in updates (2ζ/w_f).
    pub lead: T,
}

impl<T: Real> DriftDesign<T> {
    /// From κ (0 disables), the window and the row filter's group delay, both in samples,
    /// and the fastest drift per sample (relative).
    pub fn new(kappa: f64, window_samples: f64, lead_samples: f64, vmax: f64) -> Self {
        if !(kappa > 0.0 && window_samples >= 5.0) {
            return DriftDesign::default();
        }
        DriftDesign {
            alpha: T::from_f64(5.0 / window_samples),
            quiet: (2.0 * window_samples) as u64,
            vmax: T::from_f64(vmax),
            kappa2: T::from_f64(4.0 * kappa * kappa),
            lead: T::from_f64(lead_samples),
        }
    }

    /// The tracker runs.
    pub fn enabled(&self) -> bool {
        self.alpha > T::ZERO
    }
}

/// The measured drift of θ12 (drive) and θ22 (sense) per update, in the RLS's scaled
/// units.
#[derive(Clone, Copy, Debug, Default)]
pub struct DriftTracker<T> {
    /// EWMA of the corrections.
    mean: [T; 2],
    /// EWMA of the corrections' squares (their noise, against which the drift is judged).
    power: [T; 2],
}

impl<T: Real> DriftTracker<T> {
    /// Takes one update's correction of the drift column on each axis (scaled units).
    /// `learn` false (not settled, or within two windows of a reset): a re-identification,
    /// not a drift, and not taken. A non-finite correction is not taken.
    #[inline(always)]
    pub fn push(&mut self, d: &DriftDesign<T>, corr: [T; 2], learn: bool) {
        if !learn {
            return;
        }
        for j in 0..2 {
            let c = corr[j];
            // NaN and ±∞ fail the comparison
            if c.abs() < T::MAX {
                self.power[j] += d.alpha * (c * c - self.power[j]);
                let m = self.mean[j] + d.alpha * (c - self.mean[j]);
                self.mean[j] = m.max(-d.vmax).min(d.vmax);
            }
        }
    }

    /// The drift per update of axis `axis` (0 drive, 1 sense) where it stands out of its
    /// own noise: the EWMA's variance is ≈ (α/2)·σ_c², and what lies within two of its
    /// standard deviations is taken as noise (0); beyond, the excess (so that the walk
    /// and the lead rise continuously).
    #[inline(always)]
    pub fn drift(&self, d: &DriftDesign<T>, axis: usize) -> T {
        let (Some(&u), Some(&p)) = (self.mean.get(axis), self.power.get(axis)) else {
            return T::ZERO;
        };
        // z² · α/2 with z = 2
        let noise2 = T::from_f64(2.0) * d.alpha * (p - u * u);
        let excess2 = u * u - noise2;
        if excess2 > T::ZERO {
            let e = excess2.sqrt();
            if u < T::ZERO { -e } else { e }
        } else {
            T::ZERO
        }
    }

    /// The drift column of axis `axis` now, as a move from the estimate: the drift over
    /// the row filter's delay (scaled units).
    #[inline(always)]
    pub fn lead(&self, d: &DriftDesign<T>, axis: usize) -> T {
        self.drift(d, axis) * d.lead
    }

    /// The walk's variance for axis `axis` (per fourth update), scaled units.
    #[inline(always)]
    pub fn q(&self, d: &DriftDesign<T>, axis: usize) -> T {
        let u = self.drift(d, axis);
        d.kappa2 * u * u
    }

    /// Forgets the measured drift.
    pub fn clear(&mut self) {
        *self = DriftTracker::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn design() -> DriftDesign<f64> {
        DriftDesign::new(3.0, 500.0, 16.0, 1.0)
    }

    #[test]
    fn kappa_zero_or_a_short_window_disables_the_tracker() {
        assert!(!DriftDesign::<f64>::new(0.0, 500.0, 16.0, 1.0).enabled());
        assert!(!DriftDesign::<f64>::new(f64::NAN, 500.0, 16.0, 1.0).enabled());
        assert!(!DriftDesign::<f64>::new(3.0, 4.0, 16.0, 1.0).enabled());
        assert!(design().enabled());
    }

    #[test]
    fn a_steady_drift_is_measured_only_while_learning() {
        let d = design();
        let mut t = DriftTracker::default();
        for _ in 0..500 {
            t.push(&d, [1e-6, -2e-6], false);
        }
        // a re-identification's corrections: nothing measured
        assert_eq!((t.drift(&d, 1), t.q(&d, 1)), (0.0, 0.0));
        for _ in 0..5000 {
            t.push(&d, [1e-6, -2e-6], true);
        }
        // noise-free corrections: the whole drift stands out of their (zero) noise
        assert!((t.drift(&d, 0) - 1e-6).abs() < 1e-15);
        assert!((t.drift(&d, 1) + 2e-6).abs() < 1e-15);
        assert!((t.lead(&d, 1) + 32e-6).abs() < 1e-14);
        assert!((t.q(&d, 1) / (36.0 * 4e-12) - 1.0).abs() < 1e-6);
        t.clear();
        assert_eq!((t.drift(&d, 1), t.q(&d, 1)), (0.0, 0.0));
    }

    #[test]
    fn noise_without_a_drift_measures_no_drift() {
        // ±σ alternating corrections: their mean is within its noise, no walk, no lead
        let d = design();
        let mut t = DriftTracker::default();
        for k in 0..5000 {
            let c = if k % 2 == 0 { 1e-6 } else { -1e-6 };
            t.push(&d, [c, c], true);
        }
        assert_eq!((t.drift(&d, 0), t.q(&d, 1), t.lead(&d, 1)), (0.0, 0.0, 0.0));
        // the same noise on a drift of 0.3 σ (its EWMA's 2 σ are 0.14 σ): it stands out
        let mut t = DriftTracker::default();
        for k in 0..5000 {
            let c = if k % 2 == 0 { 1e-6 } else { -1e-6 };
            t.push(&d, [c + 3e-7, c + 3e-7], true);
        }
        let u = t.drift(&d, 1);
        assert!(u > 2e-7 && u < 3e-7, "{u}");
    }

    #[test]
    fn a_drift_faster_than_the_limit_is_not_taken_beyond_it() {
        let d = DriftDesign::<f64>::new(3.0, 500.0, 16.0, 1e-7);
        let mut t = DriftTracker::default();
        for _ in 0..5000 {
            t.push(&d, [1e-5, -1e-5], true);
        }
        // not followed beyond the limit (here not at all: the corrections' own spread
        // swamps the capped mean): the change detector takes it as a jump
        assert!(t.drift(&d, 0).abs() <= 1e-7 && t.drift(&d, 1).abs() <= 1e-7);
    }

    #[test]
    fn a_non_finite_correction_changes_nothing() {
        let d = design();
        let mut t = DriftTracker::default();
        t.push(&d, [1e-6, 1e-6], true);
        let before = (t.drift(&d, 0), t.drift(&d, 1), t.q(&d, 0), t.q(&d, 1));
        t.push(&d, [f64::NAN, f64::INFINITY], true);
        assert_eq!(
            before,
            (t.drift(&d, 0), t.drift(&d, 1), t.q(&d, 0), t.q(&d, 1))
        );
        assert_eq!(t.drift(&d, 7), 0.0);
    }
}
