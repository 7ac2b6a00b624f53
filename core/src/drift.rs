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
//! and blanks the rate (`paragyro-sim thermal --drift-kappa 0` shows it on a 10 K warm-up).
//!
//! The parameters that drift with temperature — θ12 = −(ω_x² − γ² + 2β1) and
//! θ22 = −(ω_y² − γ²), column 1 of each axis — are random walks, the Kalman filter's process
//! noise on top of the RLS, sized by the drift the rows show:
//!
//! * **The measured drift.** u_j, an EWMA (time constant `rls.drift_window_s`/5) of the
//!   corrections the rows make to the column at each update. The corrections are not white:
//!   the dither's periods (0.2 s, 0.77 s) wander u_j by about half their size, so u_j counts
//!   as a drift only beyond three of its own long-run standard deviations (its mean square
//!   while within them, an EWMA ten windows long, learned from the first settled window on):
//!   a device at a constant temperature measures no drift and keeps the whole memory of
//!   the slow RLS.
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
//!   retune supervisor reads — takes it advanced by u_j over that delay (without it, the
//!   narrow channel's quadrature leaves its gate during a fast warm-up and the rate is
//!   flagged invalid).
//!
//! A jump (a mode hop, a shock: ω_y² +0.3 % within 10 ms) moves the column by 3e-3 at once: its
//! innovations cross the detector's threshold on the first samples, and the slow RLS is reset
//! and re-identifies from the design's start-up. A measured drift faster than
//! `rls.drift_max_ppm_s` is a jump too (no walk, no lead: a fast ramp such as `drift-retune`'s
//! 0.34 % in 0.5 s is left to the detector). A reset clears the measured drift but keeps the
//! wander learned before it (the device's and its dither's, not the drift's): the drift is
//! measured again from a settled estimate two windows after the reset (a re-identification's
//! corrections are not a drift), and a drift that went on through the reset stands out of the
//! kept wander within a window. Relearned after each reset from a drifting device, the wander
//! would take the drift for itself, and each reset would bring the next.
//!
//! * **The drive from the sense.** The drive's rows resolve θ12 several times less well
//!   than the sense's θ22, and the dither wanders its corrections more: a warm-up's
//!   2 ppm/s on ω_x² does not stand out of the drive's wander. Both modes are one
//!   structure at one temperature, so where the drive's own drift does not stand out and
//!   no die temperature predicts it, the drive walks and leads with the sense's measured
//!   drift (relative units; the modes' TCFs differ by tens of percent: its variance is
//!   taken with a relative σ of [`BORROW_SIGMA`]). Without a die temperature the sense's
//!   frequency is the thermometer.
//!
//! * **A drift-like alarm.** Without a die temperature a ramp that starts suddenly
//!   (0 → 33 ppm/s within a sample) builds a lag before its drift stands out, and the
//!   change detector fires. Its level then crosses the threshold by little (a lag grows
//!   sample by sample; [`crate::monitor::DRIFT_MARGIN`]), where a jump's crosses by orders
//!   of magnitude. On a settled estimate, with the drive locked and steady, such an alarm
//!   raises the drift column's variance alone to `rls.p_reset` (the lag is taken at once,
//!   the other columns keep what they know) and opens its walk for a window at `vmax`
//!   ([`DriftTracker::open`]) instead of resetting the axis; the drift's own measure takes
//!   over within that window. What the column alone does not take up alarms again within
//!   it and resets the axis. A reset there would bring the next: during a ramp the
//!   resets come faster than the two quiet windows after each, in which the drift is not
//!   measured.
//!
//! Limits: a device already drifting when the estimate first settles learns that drift as
//! its wander (it is followed by the forgetting alone, and the detector may fire, until the
//! drift changes); the drive's θ12 and the sense's θ22 are the only columns that walk (the
//! damping's temperature coefficient is not tracked); a drift-like alarm within two quiet
//! windows of a reset (a re-identification) still resets: opening the walk there slowed
//! the fault campaign's recoveries (spikes and time jumps 26 % and 11 % recovered in their
//! slot, `core/docs/design-notes.md`). With the die temperature its rate opens the walk at
//! once (module [`crate::thermal`]).

use crate::real::Real;

/// Columns of the RLS that drift with temperature: θ12 on the drive, θ22 on the sense
/// (the natural frequencies; column 1 of each axis).
pub const DRIFT_COL: usize = 1;

/// The relative standard deviation of the drive's drift taken from the sense's
/// ([`DriftTracker::drift`]): the two modes' frequency TCFs differ by some tens of percent
/// (a silicon resonator's −30 / −33 ppm/K in `host-sim/scenarios/warm-up.toml`).
pub const BORROW_SIGMA: f64 = 0.5;

/// The design of the drift tracker (from `rls.drift_*`).
#[derive(Clone, Copy, Debug, Default)]
pub struct DriftDesign<T> {
    /// EWMA weight of the measured drift per update (5/(window · fs)); 0 disables the
    /// tracker.
    pub alpha: T,
    /// Updates after a covariance reset before the drift is measured (two windows).
    pub quiet: u64,
    /// The long-run EWMA's weight (a fiftieth of `alpha`).
    pub alpha_slow: T,
    /// Updates measured before a drift can be told (a window).
    pub min_n: u32,
    /// The fastest drift the tracker follows, per update, in the RLS's scaled (relative)
    /// units (`rls.drift_max_ppm_s`): a faster move is a jump, left to the change
    /// detector (no walk, no lead).
    pub vmax: T,
    /// 4κ², the walk's variance per squared drift (each axis walks every fourth update).
    pub kappa2: T,
    /// The walk's variance at the fastest drift followed (4κ²·vmax²): a walk a drift-like
    /// alarm opened ([`DriftTracker::open`]).
    pub q_open: T,
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
            alpha_slow: T::from_f64(0.1 / window_samples),
            min_n: window_samples as u32,
            vmax: T::from_f64(vmax),
            kappa2: T::from_f64(4.0 * kappa * kappa),
            q_open: T::from_f64(4.0 * kappa * kappa * vmax * vmax),
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
    /// The mean square of `mean` while it stands within its own wander (an EWMA fifty
    /// times slower, started as a running mean): how far `mean` wanders without a drift,
    /// the dither's periodic corrections included, against which a drift must stand out.
    var: [T; 2],
    /// Updates taken since the last clear (the running means' start), saturating.
    n: u32,
    /// The drift per update the temperature predicts (module [`crate::thermal`]; 0
    /// without one) and that prediction's variance: the walk and the lead add them.
    known: [T; 2],
    known_var: [T; 2],
    /// Twice `known` (each axis is moved every other sample).
    known2: [T; 2],
    /// The sense's [`DriftTracker::lead`] as of its last [`DriftTracker::refresh_lead`].
    lead_sense: T,
    /// The sample until which a drift-like alarm opened the walk ([`DriftTracker::open`]),
    /// per axis.
    open_until: [u64; 2],
}

impl<T: Real> DriftTracker<T> {
    /// Takes one update's correction of the drift column on each axis (scaled units).
    /// `learn` false (not settled, or within two windows of a reset): a re-identification,
    /// not a drift, and not taken. A non-finite correction is not taken.
    #[inline(always)]
    pub fn push(&mut self, d: &DriftDesign<T>, corr: [T; 2], learn: bool) {
        // NaN and ±∞ fail the comparisons
        let finite = corr[0].abs() < T::MAX && corr[1].abs() < T::MAX;
        if !(learn && finite) {
            return;
        }
        self.n = self.n.saturating_add(1);
        // the slow EWMA's weight, 1/n until it reaches its own (a running mean at first)
        let a_n = T::ONE / T::from_f64(f64::from(self.n));
        let a_slow = if a_n > d.alpha_slow {
            a_n
        } else {
            d.alpha_slow
        };
        let z2 = T::from_f64(9.0);
        for j in 0..2 {
            let m = self.mean[j] + d.alpha * (corr[j] - self.mean[j]);
            self.mean[j] = m;
            // the wander is learned where the measured drift is within it (or while it is
            // first measured), not from a drift that stands out of it
            let m2 = m * m;
            if self.n <= d.min_n || m2 <= z2 * self.var[j] {
                self.var[j] += a_slow * (m2 - self.var[j]);
            }
        }
    }

    /// The drift per update of axis `axis` (0 drive, 1 sense) where it stands out of how
    /// far the measured drift wanders without one: beyond three of its long-run standard
    /// deviations from zero, the excess (so that the walk and the lead rise continuously),
    /// else 0; 0 before a window of updates, and beyond `vmax` (a jump).
    ///
    /// The drive's, where its own does not stand out and no temperature predicts it, is
    /// the sense's: both modes of one structure move with one
    /// temperature, and the sense's rows measure it several times better.
    #[inline(always)]
    pub fn drift(&self, d: &DriftDesign<T>, axis: usize) -> T {
        self.drift_borrowed(d, axis).0
    }

    /// [`DriftTracker::drift`], and whether it is the sense's taken for the drive (`axis`
    /// 0: its own is 0 and no temperature predicts it; without a die temperature the
    /// sense's frequency is the thermometer).
    #[inline(always)]
    fn drift_borrowed(&self, d: &DriftDesign<T>, axis: usize) -> (T, bool) {
        let own = self.measured(d, axis);
        if axis == 0 && own == T::ZERO && self.known[0] == T::ZERO {
            (self.measured(d, 1), true)
        } else {
            (own, false)
        }
    }

    /// [`DriftTracker::drift`] from the axis's own corrections alone.
    #[inline(always)]
    fn measured(&self, d: &DriftDesign<T>, axis: usize) -> T {
        let (Some(&u), Some(&v)) = (self.mean.get(axis), self.var.get(axis)) else {
            return T::ZERO;
        };
        // faster than any temperature moves it: a jump, the change detector's (NaN fails)
        let within = u.abs() <= d.vmax;
        if !within || self.n < d.min_n {
            return T::ZERO;
        }
        let excess2 = u * u - T::from_f64(9.0) * v;
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
        (self.drift(d, axis) + self.known(axis)) * d.lead
    }

    /// Takes the sense's lead now (every few samples: it moves with the 0.2 s drift
    /// average and the temperature's rate, and computing it costs a square root).
    #[inline(always)]
    pub fn refresh_lead(&mut self, d: &DriftDesign<T>) {
        self.lead_sense = self.lead(d, 1);
    }

    /// The sense's lead as of the last [`DriftTracker::refresh_lead`] (scaled units).
    #[inline(always)]
    pub fn lead_sense(&self) -> T {
        self.lead_sense
    }

    /// The drift per update the temperature predicts for axis `axis` (0 without one).
    #[inline(always)]
    pub fn known(&self, axis: usize) -> T {
        self.known.get(axis).copied().unwrap_or(T::ZERO)
    }

    /// Sets the predicted drift per update and its variance, both axes (module
    /// [`crate::thermal`]).
    pub fn set_known(&mut self, v: [T; 2], var: [T; 2]) {
        let two = T::from_f64(2.0);
        (self.known, self.known_var) = (v, var);
        self.known2 = [two * v[0], two * v[1]];
    }

    /// Twice the predicted drift per update of axis `axis` (it moves every other sample).
    #[inline(always)]
    pub fn known2(&self, axis: usize) -> T {
        self.known2.get(axis).copied().unwrap_or(T::ZERO)
    }

    /// The walk's variance for axis `axis` (per fourth update), scaled units: the measured
    /// drift's and the temperature prediction's uncertainty's.
    #[inline(always)]
    pub fn q(&self, d: &DriftDesign<T>, axis: usize) -> T {
        let (u, borrowed) = self.drift_borrowed(d, axis);
        let var = self.known_var.get(axis).copied().unwrap_or(T::ZERO);
        // the sense's drift taken for the drive: the modes' unknown ratio of TCFs
        // (1 ± BORROW_SIGMA) adds to its variance
        let u2 = if borrowed {
            u * u * T::from_f64(1.0 + BORROW_SIGMA * BORROW_SIGMA)
        } else {
            u * u
        };
        d.kappa2 * (u2 + var)
    }

    /// [`DriftTracker::q`] at sample `k`: at least the fastest drift's walk while a
    /// drift-like alarm has it open ([`DriftTracker::open`]).
    #[inline(always)]
    pub fn q_at(&self, d: &DriftDesign<T>, axis: usize, k: u64) -> T {
        let q = self.q(d, axis);
        let open = self.open_until.get(axis).is_some_and(|&until| k < until);
        if open && q < d.q_open { d.q_open } else { q }
    }

    /// A drift-like alarm on axis `axis` (the change detector's level crossed its
    /// threshold by little: a lag that grew, [`crate::monitor::DRIFT_MARGIN`]), on a
    /// settled estimate that is not already walking so: instead of a covariance reset,
    /// the drift column walks for a window as fast as the fastest drift the tracker
    /// follows (`vmax`), while the drift's own measure catches up. A drift's lag is
    /// absorbed within it and no alarm follows; a jump or a fault is not, and its next
    /// alarm resets the axis. At sample `k`; false when the walk is already open (that
    /// next alarm).
    pub fn open(&mut self, d: &DriftDesign<T>, axis: usize, k: u64) -> bool {
        match self.open_until.get_mut(axis) {
            Some(until) if k >= *until => {
                *until = k + u64::from(d.min_n);
                true
            }
            _ => false,
        }
    }

    /// Forgets the measured drift (a covariance reset): the re-identification's
    /// corrections are not a drift. Kept: how far the measured drift wanders without one
    /// (a property of the device and its dither, learned before; relearned from a drifting
    /// device after a reset it would take the drift for wander, and every later reset
    /// would follow), and the temperature's prediction (set again every block).
    pub fn clear(&mut self) {
        self.mean = [T::ZERO; 2];
        self.lead_sense = T::ZERO;
        self.open_until = [0; 2];
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

    /// `n` updates of alternating ±σ corrections (a wander without a drift) on both axes.
    fn wander(t: &mut DriftTracker<f64>, d: &DriftDesign<f64>, n: usize, drift: f64) {
        for k in 0..n {
            let c = if k % 2 == 0 { 1e-6 } else { -1e-6 };
            t.push(d, [c + drift, c + drift], true);
        }
    }

    #[test]
    fn a_drift_that_stands_out_of_the_learned_wander_is_measured() {
        let d = design();
        let mut t = DriftTracker::default();
        t.push(&d, [1e-6, -2e-6], false);
        // a re-identification's corrections: nothing measured
        assert_eq!((t.drift(&d, 1), t.q(&d, 1), t.n), (0.0, 0.0, 0));
        wander(&mut t, &d, 2000, 0.0);
        assert_eq!(
            (t.drift(&d, 0), t.drift(&d, 1), t.q(&d, 1)),
            (0.0, 0.0, 0.0)
        );
        // then the device drifts by 0.3 σ per update
        wander(&mut t, &d, 2000, 3e-7);
        let u = t.drift(&d, 1);
        assert!((u - 3e-7).abs() < 0.1e-7, "{u}");
        assert!((t.lead(&d, 1) - 16.0 * u).abs() < 1e-18);
        assert!((t.q(&d, 1) - 36.0 * u * u).abs() < 1e-24);
        // and stops: the measured drift falls back within the wander
        wander(&mut t, &d, 2000, 0.0);
        assert_eq!(t.drift(&d, 1), 0.0);
        t.clear();
        assert_eq!(
            (t.drift(&d, 1), t.q(&d, 1), t.lead_sense()),
            (0.0, 0.0, 0.0)
        );
    }

    #[test]
    fn after_a_reset_a_continuing_drift_is_told_again_not_learned_as_wander() {
        let d = design();
        let mut t = DriftTracker::default();
        wander(&mut t, &d, 2000, 0.0);
        wander(&mut t, &d, 2000, 3e-7);
        assert!(t.drift(&d, 1) > 2.5e-7);
        // a reset: the measured drift forgotten, the wander without a drift kept
        t.clear();
        assert_eq!(t.drift(&d, 1), 0.0);
        // the device drifts on: once the re-identification's quiet updates are over, the
        // drift is told again within a window (its EWMA's few time constants), not taken
        // for a wider wander
        let var = t.var;
        wander(&mut t, &d, 300, 3e-7);
        // (the wander learns only while the rising mean is still within it)
        assert!(t.var[1] < 1.05 * var[1], "{:?} from {var:?}", t.var);
        let u = t.drift(&d, 1);
        assert!((u - 3e-7).abs() < 0.3e-7, "{u}");
        wander(&mut t, &d, 5000, 3e-7);
        let u = t.drift(&d, 1);
        assert!((u - 3e-7).abs() < 0.1e-7, "{u}");
    }

    #[test]
    fn the_drive_takes_the_senses_drift_where_its_own_does_not_stand_out() {
        let d = design();
        let mut t = DriftTracker::default();
        // the drive's corrections wander with the dither (a 1.3 Hz sine, its window mean
        // ≈ 0.6 of 2e-6): its drift stays within; the sense's alternate and cancel
        for k in 0..6000 {
            let c = if k % 2 == 0 { 1e-6 } else { -1e-6 };
            let slow = 2e-6 * (core::f64::consts::TAU * 1.3 * k as f64 / 500.0).sin();
            let drift = if k < 2000 { 0.0 } else { 3e-7 };
            t.push(&d, [slow + drift, c + drift], true);
        }
        let u = t.drift(&d, 1);
        assert!((u - 3e-7).abs() < 0.1e-7, "{u}");
        assert_eq!(t.measured(&d, 0), 0.0);
        assert_eq!(t.drift(&d, 0), u);
        assert!((t.lead(&d, 0) - 16.0 * u).abs() < 1e-18);
        assert!((t.q(&d, 0) - 36.0 * 1.25 * u * u).abs() < 1e-24);
        // a temperature that predicts the drive's drift: its own (0) stands, not the sense's
        t.set_known([1e-8, 1e-8], [0.0, 0.0]);
        assert_eq!(t.drift(&d, 0), 0.0);
        assert!((t.q(&d, 0)).abs() < 1e-30);
    }

    #[test]
    fn periodic_corrections_without_a_drift_measure_no_drift() {
        // the dither's corrections are not white: a 1.3 Hz sine at 500 Hz wanders the
        // window's mean by ≈ 0.6 of its amplitude; the learned wander covers it
        let d = design();
        let mut t = DriftTracker::default();
        let mut seen = 0;
        for k in 0..20_000 {
            let c = 1e-6 * (core::f64::consts::TAU * 1.3 * k as f64 / 500.0).sin();
            t.push(&d, [c, c], true);
            if k > 500 && t.drift(&d, 1) != 0.0 {
                seen += 1;
            }
        }
        assert_eq!(seen, 0);
    }

    #[test]
    fn a_drift_faster_than_the_limit_is_not_taken() {
        let d = DriftDesign::<f64>::new(3.0, 500.0, 16.0, 1e-7);
        let mut t = DriftTracker::default();
        wander(&mut t, &d, 2000, 0.0);
        wander(&mut t, &d, 2000, 1e-6);
        // not followed at all: the change detector takes it as a jump
        assert_eq!(
            (t.drift(&d, 0), t.drift(&d, 1), t.q(&d, 1)),
            (0.0, 0.0, 0.0)
        );
    }

    #[test]
    fn a_drift_like_alarm_opens_the_walk_at_the_fastest_drift_for_a_window() {
        let d = DriftDesign::<f64>::new(3.0, 500.0, 16.0, 1e-7);
        let mut t = DriftTracker::default();
        wander(&mut t, &d, 2000, 0.0);
        assert_eq!(t.q_at(&d, 1, 2000), 0.0);
        assert!(t.open(&d, 1, 2000));
        // already open: the next alarm is the caller's reset
        assert!(!t.open(&d, 1, 2100));
        let q_open = 4.0 * 9.0 * 1e-14;
        assert!((d.q_open - q_open).abs() < 1e-27);
        assert_eq!((t.q_at(&d, 1, 2000), t.q_at(&d, 0, 2000)), (d.q_open, 0.0));
        // its own measure of the drift is not touched: no lead from it
        assert_eq!((t.q(&d, 1), t.lead(&d, 1)), (0.0, 0.0));
        // a window later it is closed
        assert_eq!(t.q_at(&d, 1, 2499), d.q_open);
        assert_eq!(t.q_at(&d, 1, 2500), 0.0);
        assert!(t.open(&d, 1, 2500));
        // a reset closes it too
        t.clear();
        assert_eq!(t.q_at(&d, 1, 2600), 0.0);
        assert!(!t.open(&d, 2, 2600));
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
