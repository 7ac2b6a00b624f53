//! The stages of one step, in order (each reads the design, changes the state):
//!
//! 1. **condition** the sample: check it, convert it to the model's units, or flag,
//!    count and skip it (the last valid one is held);
//! 2. **known signals**: the commanded pump and the accelerations through the replica
//!    of the lock-in low-pass;
//! 3. **rows**: projections, the state-variable filter bank, 5 + 5 rows (`rows`);
//! 4. **update** both RLS (unless gated) and run the change detectors;
//! 5. **assess**: settle test, re-linearisation, health;
//! 6. **retune**: the supervisor's decision and the scheduler's ramps;
//! 7. **command** the next pump.
//!
//! Every stage is inlined into the one `step()` frame (the chip's stack and cost).

use super::design::{DECIDE_EVERY, Design};
use super::state::{Conditioned, Replicas, State};
use crate::complex::Cplx;
use crate::drift::DRIFT_COL;
use crate::health::{Counters, Health};
use crate::lpf::ReplicaChannel;
use crate::monitor::InputCheck;
use crate::output::{StepOutput, event};
use crate::rate::RateOutput;
use crate::rate::ZERO_EVERY;

// the rate's zero is held on a phase of the decision interval
const _: () = assert!(ZERO_EVERY as u64 == DECIDE_EVERY);
use crate::real::Real;
use crate::retune::{RetuneAction, RetuneInputs, drive_band};
use crate::rows::{Envelopes, Known, NROWS, Projections};
use crate::sample::Sample;

impl<T: Real> State<T> {
    /// One 500 Hz sample through the stages (module docs).
    #[inline(always)]
    pub fn step(&mut self, d: &Design<T>, s: &Sample<T>) -> StepOutput {
        let k = self.k;
        let mut events = 0u8;
        self.counters.samples = self.counters.samples.wrapping_add(1);
        let good = self.condition(d, s, &mut events);
        let block = self.thermal.push(&d.fit.thermal, s.temp_c);
        let sweep = core::mem::replace(&mut self.pump_sweep_hz, T::from_f64(f64::NAN));
        // the held input, in locals (not a copy of the whole struct per stage)
        let Some(Conditioned {
            env,
            acc,
            pump_hz,
            pump_scale,
        }) = self.last_good
        else {
            return self.hold_centre(d, events);
        };
        // the drift the temperature predicts (module `thermal`; 0 without one): each axis
        // every other sample by two samples' worth, updated or not (the device drifts on)
        if k & 1 == 0 {
            self.rls1.nudge(DRIFT_COL, self.drift.known2(0));
        } else {
            self.rls2.nudge(DRIFT_COL, self.drift.known2(1));
        }
        let exc_var = self.known_signals(d, pump_hz, (good, sweep), pump_scale, acc);
        let excited = self.dithered && exc_var >= self.exc_var_min;
        // forget only while excited: once the dither has excited the regression, a
        // sample without enough excitation holds the RLS memory (λ = 1) instead of
        // letting P grow in the unexcited directions (rls.rs, "Anti-windup")
        let hold = self.excited_once && !excited;
        self.excited_once |= excited;
        let proj = Projections::of(&d.rows, &env);
        // the phase of the decision interval: decisions on 0 (stage 6), the rate's zero and
        // the drift's lead on phases no decision, no thermal block falls on (stage 3a)
        // (of the index's low 32 bits: a 32-bit remainder is a multiply on the chip, a
        // 64-bit one far more; the phase slips once in 2³² samples, 99 days)
        let phase = (k as u32) % (DECIDE_EVERY as u32);
        self.track_rate(d, &env, &proj, phase);
        // the sense drift's own term in its rows (rows.rs, "A drifting coefficient")
        let g_sense = d.fit.drift_f1 * self.drift.lead_sense();
        self.rows.push_projected(
            &d.rows,
            &env,
            &self.last_known,
            &proj,
            g_sense,
            &mut self.last_rows,
        );
        let gated = k < d.watch.gate_startup
            || k < self.jump_gate_until
            || k < self.bad_gate_until
            || self.rate.gates(k);
        let updated = !gated && good;
        if updated {
            self.update(d, k, hold, &mut events);
        }
        let wy2 = self.wy2_fast(d);
        let settled = self.settle(d, k, gated, updated, wy2, &mut events);
        self.maybe_relinearize(d, k, updated, phase);
        if block {
            self.thermal_block(d, k);
        }
        let health = self.assess(d, good, gated, settled, excited, pump_scale);
        let drive_amp = env.a[0].abs();
        let health = self.retune(d, (k, phase == 0), health, wy2, drive_amp, &mut events);
        self.health = health;
        self.rate.assess(
            &d.rate,
            health.inputs_valid,
            health.drive_locked,
            health.settled,
            health.change_detected,
        );
        self.command(d, health, events, updated)
    }

    /// Stage 1: checks the sample; a good one becomes the held input in the model's
    /// units, a bad one is counted and gates the RLS for `bad_input_gate_s`.
    #[inline(always)]
    fn condition(&mut self, d: &Design<T>, s: &Sample<T>, events: &mut u8) -> bool {
        let chk = InputCheck::of(s, &d.watch.limits, &mut self.stuck);
        let good = chk.ok();
        if good {
            let u = &d.units;
            // built whole (not from `Envelopes::default()`: zeroing `a` and `b` first
            // cost two `memclr` calls a tick on the chip)
            let k = u.inv_l0;
            let scale = |[z1, z2, z3]: [Cplx<T>; 3]| [z1.scale(k), z2.scale(k), z3.scale(k)];
            let env = Envelopes {
                x0: s.lockin.x0_um * k,
                a: scale(s.lockin.x_um),
                y0: s.lockin.y0_um * k,
                b: scale(s.lockin.y_um),
            };
            let acc = [s.accel_mps2[0] * u.accel_nd, s.accel_mps2[1] * u.accel_nd];
            self.last_good = Some(Conditioned {
                env,
                acc,
                pump_hz: s.pump_hz,
                pump_scale: s.pump_scale,
            });
        } else {
            Counters::bump(&mut self.counters.bad_samples, 1);
            Counters::bump(&mut self.counters.non_finite, chk.non_finite as u32);
            Counters::bump(&mut self.counters.saturated, chk.saturated as u32);
            Counters::bump(&mut self.counters.stuck, chk.stuck as u32);
            self.bad_gate_until = self.k + d.watch.gate_bad + 1;
            *events |= event::BAD_INPUT;
        }
        good
    }

    /// No valid sample yet: hold, keep commanding the centre.
    #[inline(always)]
    fn hold_centre(&mut self, d: &Design<T>, events: u8) -> StepOutput {
        self.k += 1;
        self.health = Health {
            inputs_valid: false,
            ..Health::default()
        };
        StepOutput {
            pump_hz_next: self.pump_command_hz(d),
            pump_scale_next: self.sched.scale_command(),
            health: self.health,
            events,
            updated: false,
            rate: RateOutput {
                valid: false,
                ..self.rate.output(&d.rate)
            },
        }
    }

    /// Stage 2: the known signals through the replica of the lock-in low-pass; returns
    /// the excitation meter's variance of the filtered pump-frequency deviation.
    #[inline(always)]
    fn known_signals(
        &mut self,
        d: &Design<T>,
        pump_hz: f64,
        (good, sweep_hz): (bool, T),
        pump_scale: T,
        acc: [T; 2],
    ) -> T {
        let u = &d.units;
        // ω − ω_ref from the small Hz offset: one exact difference, the rest in T keeps
        // ~1e-10 absolute precision (the offset is at most a few % of the pump)
        let dev = T::from_f64_diff(pump_hz, u.pump_ref_hz) * u.inv_2f0;
        let dom = dev;
        let dom2 = dev * (u.two_om_ref + dev);
        let ds = pump_scale - T::ONE;
        // one set of coefficients, borrowed (not copied) every tick
        let co = &d.replica;
        let rep = self.rep.get_or_insert_with(|| Replicas {
            dom: ReplicaChannel::at_rest(co, dom),
            dom2: ReplicaChannel::at_rest(co, dom2),
            ds: ReplicaChannel::at_rest(co, ds),
            ax: ReplicaChannel::at_rest(co, acc[0]),
            ay: ReplicaChannel::at_rest(co, acc[1]),
        });
        // the interval's sweep as the caller gave it (two known steps)
        if good && sweep_hz.is_finite() {
            let h = sweep_hz;
            let d0 = dev - h * u.inv_2f0;
            rep.dom.restart_from(d0);
            rep.dom2.restart_from(d0 * (u.two_om_ref + d0));
        }
        // the commanded pump (frequency and scale) follows the generator's profile
        let hold = u.staircase;
        let f_dom = rep.dom.update_pump(co, dom, hold);
        let known = Known {
            om: u.om_ref_t + f_dom,
            dom2: rep.dom2.update_pump(co, dom2, hold),
            omd: rep.dom.derivative(co),
            ds: rep.ds.update_with(co, ds, u.scale_held),
            ax: rep.ax.update(co, acc[0]),
            ay: rep.ay.update(co, acc[1]),
        };
        let exc_var = self.exc.push(d.watch.exc_alpha, f_dom);
        self.last_known = known;
        exc_var
    }

    /// Stage 3a: the fast rate channel on this sample, given the slow θ of the last
    /// update (module `rate`); its narrow copy gates the slow RLS while the rate moves
    /// and says when the slow RLS's rate walks (stage 4a).
    #[inline(always)]
    fn track_rate(&mut self, d: &Design<T>, env: &Envelopes<T>, p: &Projections<T>, phase: u32) {
        self.rate
            .refresh_nominal(&d.rate, &self.lin.th1n, &self.lin.th2n);
        let x1 = self.rls1.estimate();
        let x2 = self.rls2.estimate();
        let dev14 = d.fit.sc1[3] * x1[3];
        let mut dev2: [T; 6] = core::array::from_fn(|j| d.fit.sc2[j] * x2[j]);
        dev2[DRIFT_COL] += d.fit.sc2[DRIFT_COL] * self.drift.lead_sense();
        // once per decision interval each, on phases that no decision, no thermal block
        // (every 50 samples, from 0) falls on: the tick's largest cost does not grow
        if phase == 8 {
            self.rate
                .hold_zero(&d.rate, dev14, dev2[3], self.was_settled);
        } else if phase == 16 {
            self.drift.refresh_lead(&d.fit.drift);
        }
        let th = self.rate.slow_theta(&dev2);
        // a gate is renewed while it lasts (the gate itself clears `settled`)
        let slow_ok = self.was_settled || self.rate.gates(self.k);
        self.rate.track(
            &d.rate,
            env,
            &self.last_known,
            p.y.cube.h1,
            &th,
            (self.k, slow_ok, self.thermal.moving),
        );
        // a hold after a rate step, once the narrow channel's rate is still: the slow
        // estimate takes its averaged rate (θ24 + Δ, θ14 − Δ; Δ = 0 on all other samples)
        let delta = self.rate.take_handover();
        self.rls2.shift(3, delta / d.fit.sc2[3]);
        self.rls1.shift(3, -delta / d.fit.sc1[3]);
    }

    /// Stage 4: one RLS update per row on both axes (weighted to unit noise, columns
    /// scaled by |θ_design|), then the change detectors on the summed normalised
    /// innovations; an alarm resets that axis' covariance. `hold`: the sample is not
    /// excited (after the dither has been): opened without forgetting.
    #[inline(always)]
    fn update(&mut self, d: &Design<T>, k: u64, hold: bool, events: &mut u8) {
        let f = &d.fit;
        Counters::bump(&mut self.counters.updates, 1);
        // each filter's trace (the anti-windup bound, the health's reading) is read on
        // alternate samples (`Rls::begin_sample_with`)
        let fresh = k & 1 == 0;
        if hold {
            self.rls1.begin_sample_held_with(fresh);
            self.rls2.begin_sample_held_with(!fresh);
        } else {
            self.rls1.begin_sample_with(fresh);
            self.rls2.begin_sample_with(!fresh);
        }
        self.walk_rate(f, k);
        let before = self.walk_drift(f, k);
        let rows = &self.last_rows;
        let mut sum1 = T::ZERO;
        let mut sum2 = T::ZERO;
        for r in 0..NROWS {
            // φ = row ∘ (column scale · row weight), the products formed at design time
            let (a, y) = (&rows.drive_phi[r], rows.drive_y[r] * f.w1[r]);
            sum1 += self
                .rls1
                .update_scaled_unfloored(a, &f.scw1[r], y)
                .normalized_sq();
            let (a, y) = (&rows.sense_phi[r], rows.sense_y[r] * f.w2[r]);
            sum2 += self
                .rls2
                .update_scaled_unfloored(a, &f.scw2[r], y)
                .normalized_sq();
        }
        // the `D` floor once per sample, not per row (`Rls::update_scaled_unfloored`)
        self.rls1.floor_all();
        self.rls2.floor_all();
        if f.drift.enabled() {
            let [b1, b2] = before;
            let corr = [
                self.rls1.estimate_at(DRIFT_COL) - b1,
                self.rls2.estimate_at(DRIFT_COL) - b2,
            ];
            let learn = self.drift_learns(f, k);
            self.drift.push(&f.drift, corr, learn);
        }
        let p = f.p_reset;
        if self.det1.push(&f.change, k, sum1) && !self.walk_instead(f, k, 0) {
            self.rls1.reset_covariance(p);
            self.thermal.jumped(0);
            Counters::bump(&mut self.counters.resets_drive, 1);
            *events |= event::CHANGE_DRIVE;
        }
        if self.det2.push(&f.change, k, sum2) && !self.walk_instead(f, k, 1) {
            self.rls2.reset_covariance(p);
            self.thermal.jumped(1);
            Counters::bump(&mut self.counters.resets_sense, 1);
            *events |= event::CHANGE_SENSE;
        }
        if *events & (event::CHANGE_DRIVE | event::CHANGE_SENSE) != 0 {
            self.last_reset = k;
            self.rate.restart_zero();
            self.drift.clear();
            self.warm_first = false;
            self.change_pending = true;
            self.settle.clear();
            self.lift_trace_bound(d);
        }
    }

    /// Stage 4a: the rate as a random walk of the slow RLS (`rate.walk_dps`). The sense's
    /// θ24 takes the walk's variance every update; the drive's θ14, which the rate moves
    /// by the opposite amount but its rows resolve ~6× less well, takes as its variance
    /// the square of the sense θ24's move since its last walk, so it follows the rate as
    /// far as the rate moves (a constant walk let θ14, and with it μ̂xy and the fast rate,
    /// wander on `characterise`'s ring-downs); it walks every other sample (the chip's
    /// tick budget; the sense walking every other sample with twice the variance failed
    /// `drift-retune-rate-sine`, the drive doing so changed nothing measured). Neither
    /// walks while the sense θ24's variance is above [`WALK_CAP_DPS`] (start-up, a
    /// covariance reset), and the drive not above it either.
    ///
    /// [`WALK_CAP_DPS`]: super::design::WALK_CAP_DPS
    #[inline(always)]
    fn walk_rate(&mut self, f: &super::design::Fit<T>, k: u64) {
        let walked = self.rate.moving(k) && self.rls2.add_walk(3, f.walk2, f.walk_cap2);
        if !walked {
            self.walk_prev24 = None;
        } else if k & 1 == 1 {
            let th24 = self.lin.th24n + f.sc2[3] * self.rls2.estimate()[3];
            if let Some(prev) = self.walk_prev24 {
                let m = (th24 - prev) / f.sc1[3];
                self.rls1.add_walk(3, m * m, f.walk_cap1);
            }
            self.walk_prev24 = Some(th24);
        }
    }

    /// Stage 4b: the drift's walk (module `drift`): one axis every other update, each
    /// axis every fourth with four times the variance (the chip's tick budget; the drift is
    /// slow against 8 ms). Returns the drift columns' estimates before this sample's rows,
    /// whose corrections measure the drift.
    #[inline(always)]
    fn walk_drift(&mut self, f: &super::design::Fit<T>, k: u64) -> [T; 2] {
        if f.drift.enabled() && k & 1 == 0 {
            if k & 2 == 0 {
                self.rls1
                    .add_walk(DRIFT_COL, self.drift.q_at(&f.drift, 0, k), f.p_reset);
            } else {
                self.rls2
                    .add_walk(DRIFT_COL, self.drift.q_at(&f.drift, 1, k), f.p_reset);
            }
        }
        [
            self.rls1.estimate_at(DRIFT_COL),
            self.rls2.estimate_at(DRIFT_COL),
        ]
    }

    /// An alarm of axis `axis` (0 drive, 1 sense) read as a drift (module `drift`): its
    /// level crossed the threshold by little ([`crate::monitor::DRIFT_MARGIN`]), the
    /// estimate has settled since the last reset and that reset is two drift windows
    /// past, the drive is locked and steady. Instead of a reset of the axis's covariance,
    /// its drift column's variance alone is raised to `rls.p_reset` (the lag the drift
    /// built up is taken at once, the other columns keep what they know) and the column
    /// walks for a window as fast as the fastest drift followed
    /// ([`crate::drift::DriftTracker::open`]); true if so. The axis's next alarm within
    /// that window resets it.
    #[inline(never)]
    fn walk_instead(&mut self, f: &super::design::Fit<T>, k: u64, axis: usize) -> bool {
        let det = if axis == 0 { &self.det1 } else { &self.det2 };
        let drift_like = f.drift.enabled()
            && det.drift_like(&f.change)
            && self.bound_learned
            && k >= self.last_reset + f.drift.quiet
            && self.health.drive_locked
            && self.rate.drive_steady();
        if !(drift_like && self.drift.open(&f.drift, axis, k)) {
            return false;
        }
        if axis == 0 {
            self.rls1.add_walk(DRIFT_COL, f.p_reset, f.p_reset);
        } else {
            self.rls2.add_walk(DRIFT_COL, f.p_reset, f.p_reset);
        }
        Counters::bump(&mut self.counters.drift_alarms, 1);
        true
    }

    /// The drift (module `drift`) and the temperature coefficients (module `thermal`) are
    /// learned on a settled estimate two drift windows after a reset: a
    /// re-identification's corrections are neither.
    #[inline(always)]
    fn drift_learns(&self, f: &super::design::Fit<T>, k: u64) -> bool {
        self.was_settled && k >= self.last_reset + f.drift.quiet
    }

    /// Stage 5c, every 0.1 s: the temperature learner's block (module `thermal`): each
    /// drift column's estimate in the learner's frame, advanced over the row filter's
    /// delay, against the block's temperature; then the drift it predicts, for the walk
    /// and the lead. Learns on a settled estimate two drift windows after a reset (as the
    /// measured drift).
    #[inline(never)]
    fn thermal_block(&mut self, d: &Design<T>, k: u64) {
        let f = &d.fit;
        let z = [
            self.thermal.off[0] + self.rls1.estimate_at(DRIFT_COL) + self.drift.lead(&f.drift, 0),
            self.thermal.off[1] + self.rls2.estimate_at(DRIFT_COL) + self.drift.lead(&f.drift, 1),
        ];
        let p_z = [
            self.rls1.variance_at(DRIFT_COL),
            self.rls2.variance_at(DRIFT_COL),
        ];
        let learn = self.drift_learns(f, k);
        self.thermal.block(&f.thermal, z, p_z, learn);
        let (v0, q0) = self.thermal.predicted(0);
        let (v1, q1) = self.thermal.predicted(1);
        self.drift.set_known([v0, v1], [q0, q1]);
    }

    /// Stage 5a: the settle test on ω̂y²; at the rising edge a pending change is cleared
    /// and the anti-windup bound learned (a factor over the converged trace, FINDINGS
    /// §4, anew after every reset: a new regime has another trace).
    #[inline(always)]
    fn settle(
        &mut self,
        d: &Design<T>,
        k: u64,
        gated: bool,
        updated: bool,
        wy2: T,
        events: &mut u8,
    ) -> bool {
        if updated {
            self.settle.push(&d.watch.settle, k, wy2);
        }
        let window = d.watch.settle_window;
        // a warm start's first settle: the window counts from the end of its gate
        let window_ok =
            k >= self.last_reset + window || (self.warm_first && k >= d.watch.gate_startup);
        let settled = !gated && self.settle.settled() && window_ok;
        self.warm_first &= !settled;
        if settled && !self.was_settled {
            *events |= event::SETTLED;
            self.change_pending = false;
            if !self.bound_learned {
                let f = d.fit.trace_bound;
                let t1 = self.rls1.trace() * f;
                let t2 = self.rls2.trace() * f;
                self.rls1.set_trace_max(t1);
                self.rls2.set_trace_max(t2);
                self.bound_learned = true;
            }
        }
        self.was_settled = settled;
        settled
    }

    /// Stage 5b: every `rls.relinearize_s` of updates, the linearisation point moves to
    /// a moderate estimate, spread over five ticks from phase 1 or 2 of the decision
    /// interval (`relin.rs`).
    #[inline(always)]
    fn maybe_relinearize(&mut self, d: &Design<T>, k: u64, updated: bool, phase: u32) {
        self.relin_tick(d, k, updated, phase.wrapping_sub(1) < 2);
    }

    /// Stage 5c: the health of this sample's estimate (the supervisor's lock and ramp
    /// as of before its tick; `excitation_ok` from the meter, stage 2), and the 1 s mean
    /// of the pump scale.
    #[inline(always)]
    fn assess(
        &mut self,
        d: &Design<T>,
        good: bool,
        gated: bool,
        settled: bool,
        excitation_ok: bool,
        pump_scale: T,
    ) -> Health {
        let (tr1, tr2) = (self.rls1.last_trace(), self.rls2.last_trace());
        let (lim1, lim2) = (d.fit.lim1, d.fit.lim2);
        // positive definite by construction: every `D_j` stays ≥ `rls::D_FLOOR` (the
        // update clamps it, forgetting and walks only grow it, a reset sets p > 0; the
        // property tests in `rls/props.rs`), so the tick reads only the traces (a `min_d`
        // of both filters would cost ≈ 120 instructions a tick on the chip)
        let covariance_bounded = tr1.is_finite() && tr2.is_finite() && tr1 <= lim1 && tr2 <= lim2;
        // mean pump scale (1 s EWMA): the amplitude dither must not make the band guard
        // wobble with the instantaneous s
        self.last_s += d.watch.s_alpha * (pump_scale - self.last_s);
        Health {
            inputs_valid: good,
            excitation_ok,
            covariance_bounded,
            change_detected: self.change_pending,
            drive_locked: self.sup.locked(),
            settled,
            gated,
            retuning: self.sup.retuning(),
        }
    }

    /// Stage 6: the retune supervisor (`drive_amp` = |A1|, its lock). Decisions every [`DECIDE_EVERY`] samples in `T`
    /// (module `retune`); lock tracking and ramps every tick. Returns the health with
    /// the supervisor's lock and ramp after its tick.
    #[inline(always)]
    fn retune(
        &mut self,
        d: &Design<T>,
        (k, decide): (u64, bool),
        mut health: Health,
        wy2: T,
        drive_amp: T,
        events: &mut u8,
    ) -> Health {
        let om_ref = d.units.om_ref;
        let healthy = decide && health.actionable() && k >= self.bad_gate_until;
        // the centre (f64: soft float on the chip) only where it is read: the supervisor
        // reads it on a healthy decision tick, never otherwise
        let centre_om = if healthy {
            om_ref + self.sched.centre()
        } else {
            om_ref
        };
        let wy2 = if decide { wy2 } else { T::ZERO };
        // the band (three square roots) only when a retune is actually in view
        let band = if decide
            && self
                .sup
                .would_retune(k, healthy, wy2, T::from_f64(centre_om))
        {
            drive_band(&self.theta1_t(d), self.last_s)
        } else {
            None
        };
        let act = self.sup.tick(&RetuneInputs {
            k,
            healthy,
            wy2,
            band,
            centre_om,
            drive_amp,
            ramp_done: self.sched.ramp().is_none(),
        });
        match act {
            RetuneAction::Start { target_om, len } => {
                self.sched.ramp_to(target_om - om_ref, k + 1, len);
                Counters::bump(&mut self.counters.retunes, 1);
                *events |= event::RETUNE_START;
            }
            RetuneAction::Track { target_om, len } => {
                self.sched.ramp_to(target_om - om_ref, k + 1, len);
            }
            RetuneAction::Abort { back_to_om, len } => {
                self.sched.ramp_to(back_to_om - om_ref, k + 1, len);
                Counters::bump(&mut self.counters.retune_aborts, 1);
                *events |= event::RETUNE_ABORT;
            }
            RetuneAction::None => {
                if health.retuning && !self.sup.retuning() {
                    *events |= event::RETUNE_DONE;
                }
            }
        }
        health.drive_locked = self.sup.locked();
        health.retuning = self.sup.retuning();
        health
    }

    /// The pump command for sample `self.k`, Hz: the scheduler's centre, converted to Hz
    /// only when it moved, plus its dither in `T` (on the chip added from the bits,
    /// [`Real::add_to_f64`]: not an ω sum, a product and a sum in `f64`).
    #[inline(always)]
    fn pump_command_hz(&mut self, d: &Design<T>) -> f64 {
        let dither = self.sched.command_dither(self.k);
        let centre = self.sched.centre();
        if centre.to_bits() != self.centre_hz.0 {
            self.centre_hz = (centre.to_bits(), d.units.pump_hz_of(centre));
        }
        T::add_to_f64(self.centre_hz.1, d.units.two_f0_t * dither)
    }

    /// Stage 7: the pump command for the next sample instant.
    #[inline(always)]
    fn command(&mut self, d: &Design<T>, health: Health, events: u8, updated: bool) -> StepOutput {
        self.k += 1;
        StepOutput {
            pump_hz_next: self.pump_command_hz(d),
            pump_scale_next: self.sched.scale_command(),
            health,
            events,
            updated,
            rate: self.rate.output(&d.rate),
        }
    }
}
