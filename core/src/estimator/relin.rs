//! Stage 5b, spread over ticks: the re-linearisation (the linearisation point θ_nom
//! moves to the estimate every `rls.relinearize_s` of updates).
//!
//! Done at once it costs ≈ 6.5k instructions on the Cortex-M4F (exact, QEMU; most of it
//! soft-float `f64`: θ̂ = θ_nom + sc·x in `f64` and the row constants from it), all on
//! the one tick. Here a small state machine does one part per tick and swaps at the end:
//!
//! | tick  | part                                                              |
//! |-------|-------------------------------------------------------------------|
//! | k     | trigger (the one-tick version's test), capture x₁, x₂             |
//! | k + 1 | θ̂1 = θ1n + sc1·x₁ (the captured x; `f64`)                        |
//! | k + 2 | θ̂2 = θ2n + sc2·x₂ (`f64`)                                         |
//! | k + 3 | the row constants of the new point ([`NominalConsts::new`])       |
//! | k + 4 | swap (on the next updated tick): the row filters move by Δθ, θ_nom ← θ̂, x ← x − x_captured |
//!
//! (The trigger tick only copies x: its `f64` sums, ≈ 1 000 instructions of soft-float,
//! would fall on the loop's costliest tick, a covariance reset (`firmware/scripts/
//! fil-profile.sh drift-retune TICK` profiles one tick); on tick k + 1 they cost the same
//! and give the same numbers. θ̂1 and θ̂2 are apart: together on one tick with the rate
//! walk, that tick would be the loop's costliest, beyond what the loop test allows above
//! the mean (`cargo fw-loop`).)
//!
//! The trigger waits for phase 1 or 2 of the 25-sample decision interval (`step.rs`): the
//! parts then fall on phases 2–6 and the nominal's refresh in the rate channel on the tick
//! after the swap, none on the decision's tick (phase 0, with the thermal block every other
//! interval) or the rate's zero and lead (phases 8 and 16). Triggered on any phase, the
//! θ̂1 sums (≈ 840 instructions of soft-float) can meet a decision's tick, and that tick
//! then exceeds the loop's budget for the largest tick.
//!
//! The new point is the estimate of tick k; at the swap the RLS keeps what it learnt
//! since (x − x_captured instead of 0), so θ_nom + sc·x is the same before and after
//! the swap (up to rounding), exactly as the one-tick version keeps it. The ticks
//! between use the old point, as they would have before the trigger.
//!
//! (The rate channel's hand-over that ends a long hold after a rate step does not go
//! through these parts: it moves the estimate itself, `Rls::shift` in `update`;
//! host-sim/docs/rate-channel.md.)

use super::design::Design;
use super::state::State;
use crate::drift::DRIFT_COL;
use crate::real::Real;
use crate::rows::NominalConsts;

/// The re-linearisation in progress (`Default`: none).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Relin<T> {
    /// 0 idle, else the next part to do (1: θ̂1, 2: θ̂2, 3: constants, 4: swap).
    phase: u8,
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

impl<T: Real> State<T> {
    /// One tick of the spread re-linearisation (module docs): triggers on an updated
    /// tick every `relin_every` samples with a moderate deviation, on a phase of the
    /// decision interval that lets its parts miss the decision's and the rate's ticks
    /// (`trigger_phase`), else does the next part of the one in progress.
    #[inline(always)]
    pub(crate) fn relin_tick(&mut self, d: &Design<T>, k: u64, updated: bool, trigger_phase: bool) {
        let f = &d.fit;
        match self.lin.pending.phase {
            0 => {
                let relin_every = f.relin_every;
                if relin_every > 0
                    && updated
                    && trigger_phase
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
                p.phase = 2;
            }
            2 => {
                let p = &mut self.lin.pending;
                for j in 0..6 {
                    p.t2[j] = self.lin.th2n[j] + (f.sc2[j] * p.x2[j]).to_f64();
                }
                // a non-finite point is dropped (as the one-tick version drops it)
                let finite = p.t1.iter().chain(p.t2.iter()).all(|v| v.is_finite());
                p.phase = if finite { 3 } else { 0 };
            }
            3 => {
                let p = &mut self.lin.pending;
                p.nom = NominalConsts::new(&p.t1, &p.t2, d.units.om_ref);
                p.t14 = T::from_f64(p.t1[3]);
                p.t22 = T::from_f64(p.t2[1]);
                p.t24 = T::from_f64(p.t2[3]);
                p.phase = 4;
            }
            // the swap waits for an updated tick: a flagged (held) sample must leave θ̂
            // exactly as it was, and the swap moves it by rounding
            _ if !updated => {}
            _ => {
                // by reference (the pending part is not copied on this tick)
                let State {
                    rows,
                    lin,
                    rls1,
                    rls2,
                    thermal,
                    ..
                } = self;
                let p = &mut lin.pending;
                p.phase = 0;
                rows.relinearize_to(&p.nom);
                // Linearisation::move_to, its conversions done on the tick before
                (lin.th1n, lin.th2n) = (p.t1, p.t2);
                (lin.th14n, lin.th22n, lin.th24n) = (p.t14, p.t22, p.t24);
                let x1 = rls1.estimate();
                let x2 = rls2.estimate();
                rls1.set_estimate(core::array::from_fn(|j| x1[j] - p.x1[j]));
                rls2.set_estimate(core::array::from_fn(|j| x2[j] - p.x2[j]));
                thermal.rebase([p.x1[DRIFT_COL], p.x2[DRIFT_COL]]);
                lin.relins = lin.relins.saturating_add(1);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use crate::config::Config;

    /// The five parts in order: nothing moves until the swap; at the swap θ_nom becomes
    /// the trigger tick's estimate, the RLS keeps what it learnt since, and θ̂ = θ_nom +
    /// sc·x is the same before and after (f64: to rounding).
    #[test]
    fn spread_relinearisation_keeps_theta_and_swaps_on_the_fifth_tick() {
        let mut est = Config::table2().build::<f64>().unwrap();
        let (d, s) = (&est.design, &mut est.state);
        let every = d.fit.relin_every;
        assert!(every > 0);
        let x1: [f64; 8] = core::array::from_fn(|j| 0.01 * (j as f64 + 1.0));
        let x2: [f64; 6] = core::array::from_fn(|j| -0.02 * (j as f64 + 1.0));
        assert!(s.rls1.set_estimate(x1) && s.rls2.set_estimate(x2));
        let k = s.lin.last_relin + every;
        let (t1_trigger, t2_trigger) = s.theta(d);
        // not yet due, not an updated tick, or not a trigger phase: nothing starts
        s.relin_tick(d, k - 1, true, true);
        s.relin_tick(d, k, false, true);
        s.relin_tick(d, k, true, false);
        assert_eq!(s.lin.pending.phase, 0);
        s.relin_tick(d, k, true, true);
        assert_eq!((s.lin.pending.phase, s.lin.last_relin), (1, k));
        // the RLS moves on between trigger and swap
        let mut x1b = x1;
        x1b[3] += 0.005;
        assert!(s.rls1.set_estimate(x1b));
        s.relin_tick(d, k + 1, true, true);
        s.relin_tick(d, k + 2, true, true);
        s.relin_tick(d, k + 3, true, true);
        assert_eq!(s.lin.pending.phase, 4);
        assert_eq!(s.lin.relins, 0);
        let (b1, b2) = s.theta(d);
        // a held (not updated) tick leaves the swap pending and θ̂ bit for bit
        s.relin_tick(d, k + 4, false, true);
        assert_eq!((s.lin.pending.phase, s.lin.relins), (4, 0));
        assert_eq!(s.theta(d), (b1, b2));
        s.relin_tick(d, k + 4, true, true);
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
}
