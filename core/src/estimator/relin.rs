//! Stage 5b, spread over ticks: the re-linearisation (the linearisation point θ_nom
//! moves to the estimate every `rls.relinearize_s` of updates).
//!
//! Done at once it costs ≈ 6.5k instructions on the Cortex-M4F (exact, QEMU; most of it
//! soft-float `f64`: θ̂ = θ_nom + sc·x in `f64` and the row constants from it), all on
//! the one tick. Here a small state machine does one part per tick and swaps at the end:
//!
//! | tick  | part                                                              |
//! |-------|-------------------------------------------------------------------|
//! | k     | trigger (same test as before), capture x₁, x₂                     |
//! | k + 1 | θ̂1 = θ1n + sc1·x₁, θ̂2 = θ2n + sc2·x₂ (the captured x; `f64`)     |
//! | k + 2 | the row constants of the new point ([`NominalConsts::new`])       |
//! | k + 3 | swap (on the next updated tick): the row filters move by Δθ, θ_nom ← θ̂, x ← x − x_captured |
//!
//! (The trigger tick only copies x: its `f64` sums, ≈ 1 000 instructions of soft-float,
//! had fallen on the loop's costliest tick, a covariance reset, `firmware/scripts/
//! fil-profile.sh drift-retune 1157`; on tick k + 1 they cost the same and give the same
//! numbers.)
//!
//! The new point is the estimate of tick k; at the swap the RLS keeps what it learnt
//! since (x − x_captured instead of 0), so θ_nom + sc·x is the same before and after
//! the swap (up to rounding), exactly as the one-tick version keeps it. The ticks
//! between use the old point, as they would have before the trigger.
//!
//! The rate channel's hand-over (a new rate at the end of a rate transient, θ24 + Δ,
//! θ14 − Δ, [`crate::rate`]) goes through the same four parts: requested with
//! [`Relin::request_handover`], it starts at the next tick (a periodic one in progress
//! is dropped: nothing of it was swapped yet), adds Δ to the captured point, and swaps
//! on the fourth tick if that sample is good. The slow RLS stays gated from the request
//! to the swap ([`Relin::handover_pending`]), so x does not move meanwhile and θ̂ takes
//! exactly the new rate; its cost is spread like the periodic one.

use super::design::Design;
use super::state::State;
use crate::real::Real;
use crate::rows::NominalConsts;

/// The re-linearisation in progress (`Default`: none).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Relin<T> {
    /// 0 idle, else the next part to do (1: θ̂1 and θ̂2, 2: constants, 3: swap).
    phase: u8,
    /// A hand-over of the rate is requested (Δθ24 = `want_delta`), not yet started.
    want: bool,
    want_delta: f64,
    /// The one in progress is a hand-over: Δθ24 added to the captured point.
    handover: bool,
    delta: f64,
    x1: [T; 8],
    x2: [T; 6],
    t1: [f64; 8],
    t2: [f64; 6],
    nom: NominalConsts<T>,
    /// θ14, θ22, θ24 of the new point in `T` (`Linearisation::move_to`'s conversions).
    t14: T,
    t22: T,
    t24: T,
}

impl<T> Relin<T> {
    /// Requests the rate hand-over θ24 + `delta`, θ14 − `delta` (module docs); a
    /// periodic re-linearisation in progress is dropped.
    pub(crate) fn request_handover(&mut self, delta: f64) {
        if !self.handover {
            self.phase = 0;
        }
        self.want = true;
        self.want_delta = delta;
    }

    /// A hand-over is requested or in progress: the slow RLS must not update.
    pub(crate) fn handover_pending(&self) -> bool {
        self.want || self.handover
    }
}

impl<T: Real> State<T> {
    /// One tick of the spread re-linearisation (module docs): triggers on an updated
    /// tick every `relin_every` samples with a moderate deviation, or on a requested
    /// hand-over, else does the next part of the one in progress. `good`: this sample
    /// is not flagged (a hand-over swaps on a good sample; the RLS is gated then).
    #[inline(always)]
    pub(crate) fn relin_tick(&mut self, d: &Design<T>, k: u64, updated: bool, good: bool) {
        let f = &d.fit;
        match self.lin.pending.phase {
            0 if self.lin.pending.want => {
                let x1 = self.rls1.estimate();
                let x2 = self.rls2.estimate();
                let p = &mut self.lin.pending;
                (p.want, p.handover, p.delta) = (false, true, p.want_delta);
                (p.x1, p.x2) = (x1, x2);
                p.phase = 1;
            }
            0 => {
                let relin_every = f.relin_every;
                if relin_every > 0
                    && updated
                    && k >= self.lin.last_relin + relin_every
                    && self.deviation_moderate()
                {
                    self.lin.last_relin = k;
                    let x1 = self.rls1.estimate();
                    let x2 = self.rls2.estimate();
                    let p = &mut self.lin.pending;
                    (p.x1, p.x2) = (x1, x2);
                    p.phase = 1;
                }
            }
            1 => {
                let p = &mut self.lin.pending;
                for j in 0..8 {
                    p.t1[j] = self.lin.th1n[j] + (f.sc1[j] * p.x1[j]).to_f64();
                }
                for j in 0..6 {
                    p.t2[j] = self.lin.th2n[j] + (f.sc2[j] * p.x2[j]).to_f64();
                }
                if p.handover {
                    p.t1[3] -= p.delta;
                    p.t2[3] += p.delta;
                }
                // a non-finite point is dropped (as the one-tick version drops it)
                let finite = p.t1.iter().chain(p.t2.iter()).all(|v| v.is_finite());
                p.phase = if finite { 2 } else { 0 };
                p.handover &= finite;
            }
            2 => {
                let p = &mut self.lin.pending;
                p.nom = NominalConsts::new(&p.t1, &p.t2, d.units.om_ref);
                p.t14 = T::from_f64(p.t1[3]);
                p.t22 = T::from_f64(p.t2[1]);
                p.t24 = T::from_f64(p.t2[3]);
                p.phase = 3;
            }
            // the swap waits for an updated tick: a flagged (held) sample must leave θ̂
            // exactly as it was, and the swap moves it by rounding (a hand-over, gated,
            // waits for a good sample)
            _ if !(updated || (self.lin.pending.handover && good)) => {}
            _ => {
                // by reference (the pending part is not copied on this tick)
                let State {
                    rows,
                    lin,
                    rls1,
                    rls2,
                    ..
                } = self;
                let p = &mut lin.pending;
                p.phase = 0;
                p.handover = false;
                rows.relinearize_to(&p.nom);
                // Linearisation::move_to, its conversions done on the tick before
                (lin.th1n, lin.th2n) = (p.t1, p.t2);
                (lin.th14n, lin.th22n, lin.th24n) = (p.t14, p.t22, p.t24);
                let x1 = rls1.estimate();
                let x2 = rls2.estimate();
                rls1.set_estimate(core::array::from_fn(|j| x1[j] - p.x1[j]));
                rls2.set_estimate(core::array::from_fn(|j| x2[j] - p.x2[j]));
                lin.relins = lin.relins.saturating_add(1);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use crate::config::Config;

    /// The four parts in order: nothing moves until the swap; at the swap θ_nom becomes
    /// the trigger tick's estimate, the RLS keeps what it learnt since, and θ̂ = θ_nom +
    /// sc·x is the same before and after (f64: to rounding).
    #[test]
    fn spread_relinearisation_keeps_theta_and_swaps_on_the_fourth_tick() {
        let mut est = Config::table2().build::<f64>().unwrap();
        let (d, s) = (&est.design, &mut est.state);
        let every = d.fit.relin_every;
        assert!(every > 0);
        let x1: [f64; 8] = core::array::from_fn(|j| 0.01 * (j as f64 + 1.0));
        let x2: [f64; 6] = core::array::from_fn(|j| -0.02 * (j as f64 + 1.0));
        assert!(s.rls1.set_estimate(x1) && s.rls2.set_estimate(x2));
        let k = s.lin.last_relin + every;
        let (t1_trigger, t2_trigger) = s.theta(d);
        // not yet due, or not an updated tick: nothing starts
        s.relin_tick(d, k - 1, true, true);
        s.relin_tick(d, k, false, true);
        assert_eq!(s.lin.pending.phase, 0);
        s.relin_tick(d, k, true, true);
        assert_eq!((s.lin.pending.phase, s.lin.last_relin), (1, k));
        // the RLS moves on between trigger and swap
        let mut x1b = x1;
        x1b[3] += 0.005;
        assert!(s.rls1.set_estimate(x1b));
        s.relin_tick(d, k + 1, true, true);
        s.relin_tick(d, k + 2, true, true);
        assert_eq!(s.lin.pending.phase, 3);
        assert_eq!(s.lin.relins, 0);
        let (b1, b2) = s.theta(d);
        // a held (not updated) tick leaves the swap pending and θ̂ bit for bit
        s.relin_tick(d, k + 3, false, true);
        assert_eq!((s.lin.pending.phase, s.lin.relins), (3, 0));
        assert_eq!(s.theta(d), (b1, b2));
        s.relin_tick(d, k + 3, true, true);
        assert_eq!((s.lin.pending.phase, s.lin.relins), (0, 1));
        let (a1, a2) = s.theta(d);
        for (b, a) in b1.iter().chain(b2.iter()).zip(a1.iter().chain(a2.iter())) {
            assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "{b} → {a}");
        }
        // the new point is the trigger tick's estimate; x keeps only the later step
        assert_eq!(s.lin.th1n, t1_trigger);
        assert_eq!(s.lin.th2n, t2_trigger);
        let x = s.rls1.estimate();
        assert!((x[3] - 0.005).abs() < 1e-15 && x[0].abs() < 1e-15);
        assert!(s.rls2.estimate().iter().all(|v| v.abs() < 1e-15));
    }

    /// The rate hand-over through the same four parts: requested during a periodic
    /// re-linearisation it drops that one, keeps the RLS gated until the swap, swaps on a
    /// good (not updated: gated) sample and moves θ24 by +Δ, θ14 by −Δ, the rest kept.
    #[test]
    fn rate_handover_moves_theta24_and_theta14_on_the_fourth_tick() {
        let mut est = Config::table2().build::<f64>().unwrap();
        let (d, s) = (&est.design, &mut est.state);
        let x1: [f64; 8] = core::array::from_fn(|j| 0.01 * (j as f64 + 1.0));
        let x2: [f64; 6] = core::array::from_fn(|j| -0.02 * (j as f64 + 1.0));
        assert!(s.rls1.set_estimate(x1) && s.rls2.set_estimate(x2));
        let k = s.lin.last_relin + d.fit.relin_every;
        s.relin_tick(d, k, true, true);
        assert_eq!(s.lin.pending.phase, 1);
        let (b1, b2) = s.theta(d);
        let delta = 3e-6;
        s.lin.pending.request_handover(delta);
        assert!(s.lin.pending.handover_pending());
        assert_eq!(s.lin.pending.phase, 0, "the periodic one is dropped");
        for i in 1..=3 {
            s.relin_tick(d, k + i, false, true);
            assert!(s.lin.pending.handover_pending());
        }
        // a flagged sample holds the swap
        s.relin_tick(d, k + 4, false, false);
        assert!(s.lin.pending.handover_pending());
        assert_eq!(s.lin.relins, 0);
        s.relin_tick(d, k + 5, false, true);
        assert!(!s.lin.pending.handover_pending());
        assert_eq!(s.lin.relins, 1);
        let (a1, a2) = s.theta(d);
        for j in 0..8 {
            let want = if j == 3 { b1[j] - delta } else { b1[j] };
            assert!(
                (a1[j] - want).abs() <= 1e-12 * want.abs().max(1e-6),
                "θ1{j}"
            );
        }
        for j in 0..6 {
            let want = if j == 3 { b2[j] + delta } else { b2[j] };
            assert!(
                (a2[j] - want).abs() <= 1e-12 * want.abs().max(1e-6),
                "θ2{j}"
            );
        }
    }
}
