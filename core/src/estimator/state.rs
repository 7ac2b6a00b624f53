//! The estimator's state: what the tick changes. Filters (replica, state-variable bank),
//! the two RLS, the linearisation point, the monitors (stuck channels, change
//! detectors, excitation, settle), the pump scheduler and the retune supervisor, and the
//! step's bookkeeping (sample index, gates, health, counters).
//!
//! Built from the design by [`State::reset`], in place like the design. The commands a
//! caller gives between steps (jump, ramp, dither) act here too.

use super::design::{Design, samples_at};
use crate::config::Config;
use crate::drift::DriftTracker;
use crate::excitation::Scheduler;
use crate::health::{Counters, Health};
use crate::lpf::ReplicaChannel;
use crate::monitor::{ChangeDetector, ExcitationMeter, SettleTest, StuckDetector};
use crate::physics::theta_from_physical;
use crate::rate::RateState;
use crate::real::Real;
use crate::retune::{Supervisor, SupervisorSettings};
use crate::rls::{Rls, RlsSettings};
use crate::rows::{Envelopes, Known, NominalConsts, RowBuilder, RowSet};
use crate::thermal::ThermalState;

/// A commanded pump centre is accepted within this fraction of the reference (the
/// configured centre, ω_ref): ±50 %, a sense resonance of 0.25–2.25× the design's ωy²
/// (the paper's ±50 % parameter switch moves the pump by +22 % / −29 %: `paper-switch`);
/// the scheduler's deviation form keeps `f32` precision there (≈ 3e-8 of ω_ref, 0.7 mHz
/// at 21.9 kHz). A fuzzed 1.3e181 Hz centre had been
/// accepted and made a later dither command produce a NaN pump (regression
/// `tests/fuzz/regressions/estimator_step/nan-pump-1`).
pub const MAX_CENTRE_DEV: f64 = 0.5;

/// One replica channel per known signal: ω − ω_ref, ω² − ω_ref², s − 1, ãx, ãy.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Replicas<T> {
    pub dom: ReplicaChannel<T>,
    pub dom2: ReplicaChannel<T>,
    pub ds: ReplicaChannel<T>,
    pub ax: ReplicaChannel<T>,
    pub ay: ReplicaChannel<T>,
}

/// The last valid sample in the model's units (held through bad samples).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Conditioned<T> {
    /// Lock-in outputs in L0.
    pub env: Envelopes<T>,
    /// Accelerations ã (x, y).
    pub acc: [T; 2],
    /// The pump frequency in effect, Hz, and the pump scale s.
    pub pump_hz: f64,
    pub pump_scale: T,
}

/// The linearisation point θ_nom of the RLS (moved to the estimate by re-linearisation)
/// and the three components ω̂y² needs, in `T`.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Linearisation<T> {
    pub th1n: [f64; 8],
    pub th2n: [f64; 6],
    /// θ14, θ22, θ24 of θ_nom in `T` (ω̂y² on the tick path).
    pub th14n: T,
    pub th22n: T,
    pub th24n: T,
    /// Sample of the last re-linearisation and how many there were.
    pub last_relin: u64,
    pub relins: u32,
    /// The spread re-linearisation in progress (`relin.rs`).
    pub pending: super::relin::Relin<T>,
}

impl<T: Real> Linearisation<T> {
    /// About `(θ1, θ2)`; the counters are kept.
    #[inline(always)]
    pub fn move_to(&mut self, th1n: [f64; 8], th2n: [f64; 6]) {
        self.th14n = T::from_f64(th1n[3]);
        self.th22n = T::from_f64(th2n[1]);
        self.th24n = T::from_f64(th2n[3]);
        self.th1n = th1n;
        self.th2n = th2n;
    }
}

/// The state of an estimator (see the module docs).
#[derive(Clone, Debug)]
pub(crate) struct State<T: Real> {
    // ---- signal path
    /// The replica channels, started at rest at the first valid sample.
    pub rep: Option<Replicas<T>>,
    /// The state-variable filter bank of the rows.
    pub rows: RowBuilder<T>,
    /// The last sample's rows and known signals (diagnostics).
    pub last_rows: RowSet<T>,
    pub last_known: Known<T>,
    /// The last valid sample.
    pub last_good: Option<Conditioned<T>>,
    /// How far the pump sweeps over the next sample's interval as the replica takes it,
    /// Hz ([`super::Estimator::set_pump_sweep_hz`]; taken by the next step; NaN: none).
    pub pump_sweep_hz: T,
    // ---- identification
    pub rls1: Rls<T, 8>,
    pub rls2: Rls<T, 6>,
    pub lin: Linearisation<T>,
    /// The fast rate channel (module `rate`).
    pub rate: RateState<T>,
    // ---- monitors
    pub stuck: StuckDetector<T>,
    pub det1: ChangeDetector<T>,
    pub det2: ChangeDetector<T>,
    pub exc: ExcitationMeter<T>,
    pub settle: SettleTest<T>,
    /// The configured dither is on (its rms > 0), and (excitation_min_fraction · rms)²,
    /// the excitation threshold (both follow `set_dither_pump_hz`; a bool, not the f64
    /// rms: the tick compares it without a soft-float call on the chip).
    pub dithered: bool,
    pub exc_var_min: T,
    /// The excitation meter has said "excited" since start-up and the last covariance
    /// reset: from then on a sample without enough excitation is opened without
    /// forgetting ([`crate::rls::Rls::begin_sample_held`]; step.rs, stage 4).
    pub excited_once: bool,
    /// Mean pump voltage scale (EWMA over ~1 s).
    pub last_s: T,
    // ---- pump
    pub sched: Scheduler<T>,
    /// The scheduler's centre (its `f64` bits) and that centre in Hz: converted when it
    /// moves (a retune ramp), not on every sample (`State::pump_command_hz`).
    pub centre_hz: (u64, f64),
    pub sup: Supervisor<T>,
    // ---- bookkeeping
    /// Samples processed.
    pub k: u64,
    /// RLS updates are gated until these samples.
    pub jump_gate_until: u64,
    pub bad_gate_until: u64,
    /// Sample of the last covariance reset.
    pub last_reset: u64,
    /// The sense's θ24 at the drive's last walk (the rate walk carries its moves to θ14).
    pub walk_prev24: Option<T>,
    /// The measured drift of θ12, θ22 (module `drift`).
    pub drift: DriftTracker<T>,
    /// The temperature learner (module `thermal`).
    pub thermal: ThermalState<T>,
    /// A warm start's first settle is due: the settle window counts from the end of the
    /// start-up gate (`persist`); cleared by that settle and by any reset.
    pub warm_first: bool,
    pub change_pending: bool,
    /// The anti-windup bound was learned at a settle since the last reset.
    pub bound_learned: bool,
    pub was_settled: bool,
    pub health: Health,
    pub counters: Counters,
}

/// No centre converted yet (NaN bits that a centre never has, NaN Hz).
const NO_CENTRE_HZ: (u64, f64) = (u64::MAX, f64::NAN);

impl<T: Real> State<T> {
    /// The placeholder of an estimator that is not designed yet (every field a constant;
    /// see [`super::Estimator::blank`]). Stepping it never panics.
    #[inline(always)]
    pub fn blank() -> Self {
        State {
            rep: None,
            rows: RowBuilder::default(),
            last_rows: RowSet::default(),
            last_known: Known::default(),
            last_good: None,
            pump_sweep_hz: T::from_f64(f64::NAN),
            rls1: Rls::blank(),
            rls2: Rls::blank(),
            lin: Linearisation::default(),
            rate: RateState::default(),
            stuck: StuckDetector::default(),
            det1: ChangeDetector::default(),
            det2: ChangeDetector::default(),
            exc: ExcitationMeter::default(),
            settle: SettleTest::default(),
            dithered: false,
            exc_var_min: T::ZERO,
            excited_once: false,
            last_s: T::ONE,
            sched: Scheduler::default(),
            centre_hz: NO_CENTRE_HZ,
            sup: Supervisor::default(),
            k: 0,
            jump_gate_until: 0,
            bad_gate_until: 0,
            last_reset: 0,
            walk_prev24: None,
            drift: DriftTracker::default(),
            thermal: ThermalState::default(),
            warm_first: false,
            change_pending: false,
            bound_learned: false,
            was_settled: false,
            health: Health::default(),
            counters: Counters::default(),
        }
    }

    /// The start-up state of design `d`, written in place (the pattern names every
    /// field, so none can be left out).
    #[inline(always)]
    pub fn reset(&mut self, d: &Design<T>) {
        let cfg = &d.cfg;
        let (th1n, th2n) = theta_from_physical(&cfg.nominal);
        let om_ref = d.units.om_ref;
        let dither_amp = cfg.dither.pump_hz / (2.0 * cfg.f0_hz);
        let State {
            rep,
            rows,
            last_rows,
            last_known,
            last_good,
            pump_sweep_hz,
            rls1,
            rls2,
            lin,
            rate,
            stuck,
            det1,
            det2,
            exc,
            settle,
            dithered,
            exc_var_min,
            excited_once,
            last_s,
            sched,
            centre_hz,
            sup,
            k,
            jump_gate_until,
            bad_gate_until,
            last_reset,
            walk_prev24,
            drift,
            thermal,
            warm_first,
            change_pending,
            bound_learned,
            was_settled,
            health,
            counters,
        } = self;
        *rep = None;
        *rows = RowBuilder::new(NominalConsts::new(&th1n, &th2n, om_ref));
        *last_rows = RowSet::default();
        *last_known = Known::default();
        *last_good = None;
        *pump_sweep_hz = T::from_f64(f64::NAN);
        *rls1 = Rls::new(rls_settings(cfg, 8.0));
        *rls2 = Rls::new(rls_settings(cfg, 6.0));
        *lin = Linearisation::default();
        lin.move_to(th1n, th2n);
        *rate = RateState::new(&d.rate);
        *walk_prev24 = None;
        *drift = DriftTracker::default();
        *thermal = ThermalState::default();
        *stuck = StuckDetector::default();
        *det1 = ChangeDetector::new(&d.fit.change);
        *det2 = ChangeDetector::new(&d.fit.change);
        *exc = ExcitationMeter::default();
        *settle = SettleTest::default();
        *exc_var_min = {
            let v = cfg.monitor.excitation_min_fraction * dither_amp / core::f64::consts::SQRT_2;
            T::from_f64(v * v)
        };
        // dithered only if the excitation threshold is positive in `T` (see
        // `set_dither_pump_hz`)
        *dithered = *exc_var_min > T::ZERO;
        *excited_once = false;
        *last_s = T::ONE;
        *sched = scheduler(cfg, om_ref, dither_amp);
        *centre_hz = NO_CENTRE_HZ;
        *sup = Supervisor::new(supervisor_settings(cfg));
        *k = 0;
        *jump_gate_until = 0;
        *bad_gate_until = 0;
        *last_reset = 0;
        *warm_first = false;
        *change_pending = false;
        *bound_learned = false;
        *was_settled = false;
        *health = Health::default();
        *counters = Counters::default();
    }

    /// Commands a new pump centre (see [`super::Estimator::command_pump_centre`]).
    pub fn command_pump_centre(&mut self, d: &Design<T>, pump_hz: f64, jump: bool) -> bool {
        let dev = pump_hz / (2.0 * d.units.f0_hz) - d.units.om_ref;
        // `!(… <= …)` also refuses NaN and ±∞
        if !(pump_hz > 0.0 && dev.abs() <= MAX_CENTRE_DEV * d.units.om_ref) {
            return false;
        }
        if jump {
            self.sched.jump(dev);
            self.jump_gate_until = self.k + d.watch.gate_jump;
            let p = d.fit.p_reset;
            self.rls1.reset_covariance(p);
            self.rls2.reset_covariance(p);
            self.det1.rearm(&d.fit.change);
            self.det2.rearm(&d.fit.change);
            self.last_reset = self.k;
            self.rate.restart_zero();
            self.warm_first = false;
            self.change_pending = true;
            self.settle.clear();
            self.lift_trace_bound(d);
            Counters::bump(&mut self.counters.jumps, 1);
        } else {
            let len = libm::round(d.cfg.retune.ramp_s * d.cfg.fs_hz).max(1.0) as u64;
            self.sched.ramp_to(dev, self.k, len);
        }
        true
    }

    /// Changes the peak pump-frequency dither (see
    /// [`super::Estimator::set_dither_pump_hz`]).
    pub fn set_dither_pump_hz(&mut self, d: &Design<T>, pump_hz: f64) -> bool {
        let centre_hz = d.units.pump_hz_of(self.sched.centre());
        let ok = pump_hz.is_finite() && pump_hz >= 0.0 && pump_hz < 0.05 * centre_hz;
        if ok {
            let amp = pump_hz / (2.0 * d.units.f0_hz);
            self.sched.set_dither_amp(amp);
            let rms = amp / core::f64::consts::SQRT_2;
            let v = d.cfg.monitor.excitation_min_fraction * rms;
            self.exc_var_min = T::from_f64(v * v);
            // a dither too small for its excitation threshold to be positive in `T` is no
            // dither: a fuzzed 1e-193 Hz counted as dithered with a zero threshold, so the
            // slow RLS forgot while nothing excited it and the pump command went NaN
            // (regression `tests/fuzz/regressions/estimator_step/nan-pump-25c8d0ac`)
            self.dithered = self.exc_var_min > T::ZERO;
        }
        ok
    }

    /// The current estimate θ̂1 (8), θ̂2 (6): θ_nom plus the scaled deviation.
    pub fn theta(&self, d: &Design<T>) -> ([f64; 8], [f64; 6]) {
        let x1 = self.rls1.estimate();
        let x2 = self.rls2.estimate();
        let mut t1 = self.lin.th1n;
        let mut t2 = self.lin.th2n;
        // the scaled deviation in T (one rounding in f32, none in f64: the host's f64
        // values are unchanged), the sum with the nominal in f64
        for j in 0..8 {
            t1[j] += (d.fit.sc1[j] * x1[j]).to_f64();
        }
        for j in 0..6 {
            t2[j] += (d.fit.sc2[j] * x2[j]).to_f64();
        }
        (t1, t2)
    }

    /// ω̂y² in `T` from the three θ components it needs (the tick path; the estimator's
    /// `wy2()` is the `f64` value from the full θ̂).
    #[inline(always)]
    pub fn wy2_fast(&self, d: &Design<T>) -> T {
        let x1 = self.rls1.estimate();
        let x2 = self.rls2.estimate();
        let l = &self.lin;
        let t14 = l.th14n + d.fit.sc1[3] * x1[3];
        let t22 = l.th22n + d.fit.sc2[1] * (x2[1] + self.drift.lead(&d.fit.drift, 1));
        let t24 = l.th24n + d.fit.sc2[3] * x2[3];
        let g = (t14 - t24) * T::from_f64(0.25);
        -t22 + g * g
    }

    /// θ̂1 in `T` (the retune's drive band on the tick path; `theta()` is the `f64`
    /// value, the same sums in `f64`).
    pub fn theta1_t(&self, d: &Design<T>) -> [T; 8] {
        let x1 = self.rls1.estimate();
        core::array::from_fn(|j| T::from_f64(self.lin.th1n[j]) + d.fit.sc1[j] * x1[j])
    }

    /// The scaled deviation is moderate (every |δθ_j| ≤ 2|θ_design,j|): not a wild
    /// transient estimate that would make a poor linearisation point.
    pub fn deviation_moderate(&self) -> bool {
        let lim = T::from_f64(2.0);
        self.rls1
            .estimate()
            .iter()
            .all(|v| v.is_finite() && v.abs() <= lim)
            && self
                .rls2
                .estimate()
                .iter()
                .all(|v| v.is_finite() && v.abs() <= lim)
    }

    /// After a covariance reset the converged trace of the old regime means nothing:
    /// the bound is lifted to its start-up value and learned again at the next settle.
    /// Nor is there an excited memory left to hold: until the meter sees the dither
    /// again the RLS forgets as at start-up (`excited_once` cleared).
    pub fn lift_trace_bound(&mut self, d: &Design<T>) {
        // in T from the design (no soft-f64 on the reset tick)
        self.rls1.set_trace_max(d.fit.trace_max1);
        self.rls2.set_trace_max(d.fit.trace_max2);
        self.bound_learned = false;
        self.excited_once = false;
    }
}

/// The RLS settings of an axis with `n` parameters: the start-up trace bound is 10× the
/// initial trace `n·p0`.
fn rls_settings<T: Real>(cfg: &Config, n: f64) -> RlsSettings<T> {
    let r = &cfg.rls;
    RlsSettings {
        forgetting: T::from_f64(r.forgetting),
        p0: T::from_f64(r.p0),
        trace_max: T::from_f64(r.p0 * n * 10.0),
    }
}

/// The pump scheduler of a configuration: the centre at the reference, the frequency and
/// scale dither.
fn scheduler<T: Real>(cfg: &Config, om_ref: f64, dither_amp: f64) -> Scheduler<T> {
    let d = &cfg.dither;
    Scheduler::new(
        om_ref,
        dither_amp,
        d.freq_hz / cfg.fs_hz,
        d.taper_s * cfg.fs_hz,
        samples_at(d.start_s, cfg.fs_hz),
        d.enabled,
    )
    .with_scale_dither(d.scale_frac, d.scale_freq_hz / cfg.fs_hz)
}

/// The retune supervisor's settings in samples and ω units.
fn supervisor_settings(cfg: &Config) -> SupervisorSettings {
    let t = &cfg.retune;
    let samples = |s: f64| samples_at(s, cfg.fs_hz);
    SupervisorSettings {
        enabled: t.enabled,
        ramp_min: samples(t.ramp_s).max(1),
        max_rate: t.max_rate_hz_per_s / (2.0 * cfg.f0_hz) / cfg.fs_hz,
        deadband: t.deadband_hz / (2.0 * cfg.f0_hz),
        track: t.track_hz / (2.0 * cfg.f0_hz),
        margin: t.band_margin,
        min_interval: samples(t.min_interval_s),
        lock_min: t.lock_min_um / cfg.l0_um,
        lock_lost_after: samples(t.lock_lost_s),
    }
}
