//! The one `step()` per 500 Hz sample that ties the chain together:
//!
//! ```text
//! sample ─► check ─► replica LPF (ω, ω², ω′, s, ã) ─► projections ─► SVF bank ─► rows (5+5)
//!        ─► gate ─► Bierman UD RLS 8×8 + 6×6 ─► change detector ─► θ̂, ω̂y², γ̂, health
//!        ─► retune supervisor ─► pump scheduler (centre + dither) ─► next pump command
//! ```
//!
//! `step()` never fails, never panics and never allocates: bad input is flagged,
//! counted and skipped, and the estimate is held.

use crate::complex::Cplx;
use crate::config::{Config, ValidConfig};
use crate::excitation::Scheduler;
use crate::lpf::{ReplicaChannel, ReplicaCoeffs};
use crate::monitor::{
    ChangeDetector, ExcitationMeter, InputCheck, N_LOCKIN_CH, SettleTest, StuckDetector,
};
use crate::physics::{Physical, physical_from_theta, rate_dps_from_gamma, theta_from_physical};
use crate::real::Real;
use crate::retune::{RetuneAction, RetuneInputs, Supervisor, SupervisorSettings, drive_band};
use crate::rls::{Rls, RlsSettings};
use crate::rows::{Envelopes, Known, NROWS, NominalConsts, RowBuilder, RowSet};

/// Lock-in outputs of one sample, in µm (peak complex amplitudes against e^{−ikψ}).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Lockin<T> {
    /// Low-passed DC level of the drive displacement, µm.
    pub x0_um: T,
    /// Drive harmonics 1, 2, 3 (complex amplitude), µm.
    pub x_um: [Cplx<T>; 3],
    /// DC level of the sense displacement, µm.
    pub y0_um: T,
    /// Sense harmonics 1, 2, 3, µm.
    pub y_um: [Cplx<T>; 3],
}

impl<T: Real> Lockin<T> {
    /// From a front end that reports amplitude and phase (rad) per harmonic:
    /// `amp·e^{i·phase}`.
    pub fn from_polar(
        x0_um: T,
        x_amp_um: [T; 3],
        x_phase_rad: [T; 3],
        y0_um: T,
        y_amp_um: [T; 3],
        y_phase_rad: [T; 3],
    ) -> Self {
        let p = |a: T, ph: T| {
            let ph = ph.to_f64();
            Cplx::new(
                a * T::from_f64(libm::cos(ph)),
                a * T::from_f64(libm::sin(ph)),
            )
        };
        Lockin {
            x0_um,
            x_um: [
                p(x_amp_um[0], x_phase_rad[0]),
                p(x_amp_um[1], x_phase_rad[1]),
                p(x_amp_um[2], x_phase_rad[2]),
            ],
            y0_um,
            y_um: [
                p(y_amp_um[0], y_phase_rad[0]),
                p(y_amp_um[1], y_phase_rad[1]),
                p(y_amp_um[2], y_phase_rad[2]),
            ],
        }
    }

    fn channels(&self) -> [T; N_LOCKIN_CH] {
        let mut c = [T::ZERO; N_LOCKIN_CH];
        c[0] = self.x0_um;
        c[7] = self.y0_um;
        for i in 0..3 {
            c[1 + 2 * i] = self.x_um[i].re;
            c[2 + 2 * i] = self.x_um[i].im;
            c[8 + 2 * i] = self.y_um[i].re;
            c[9 + 2 * i] = self.y_um[i].im;
        }
        c
    }
}

/// Everything the core needs at one 500 Hz sample.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample<T> {
    /// Lock-in outputs at the sample instant.
    pub lockin: Lockin<T>,
    /// Accelerometer (x = drive axis, y = sense axis), m/s².
    pub accel_mps2: [T; 2],
    /// Pump frequency 2Ω/2π in effect at the sample instant, Hz (f64: 1e-7 relative
    /// matters here).
    pub pump_hz: f64,
    /// Pump voltage scale s = (V_A/V_A0)².
    pub pump_scale: T,
}

impl<T: Real> Sample<T> {
    /// s = (V_A/V_A0)² from the pump voltage amplitude and its reference.
    pub fn pump_scale_from_volts(v: f64, v_ref: f64) -> T {
        T::from_f64((v / v_ref) * (v / v_ref))
    }
}

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

/// Event bits of one step.
pub mod event {
    /// The drive RLS was reset by the change detector.
    pub const CHANGE_DRIVE: u8 = 1;
    /// The sense RLS was reset by the change detector.
    pub const CHANGE_SENSE: u8 = 2;
    /// A retune ramp started.
    pub const RETUNE_START: u8 = 4;
    /// A retune ramp finished.
    pub const RETUNE_DONE: u8 = 8;
    /// A retune was aborted (drive lock lost).
    pub const RETUNE_ABORT: u8 = 16;
    /// The sample was bad and skipped.
    pub const BAD_INPUT: u8 = 32;
    /// The estimate settled (rising edge).
    pub const SETTLED: u8 = 64;
}

/// What one step returns.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepOutput {
    /// Pump frequency to command for the next sample instant, Hz.
    pub pump_hz_next: f64,
    /// Multiplier of the pump voltage scale s = (V/V0)² to command for the next sample
    /// instant (the amplitude part of the excitation; 1 when off). The pump voltage is
    /// V0·√(s_base · pump_scale_next).
    pub pump_scale_next: f64,
    /// Health after this sample.
    pub health: Health,
    /// Events of this step (see [`event`]).
    pub events: u8,
    /// The RLS was updated with this sample.
    pub updated: bool,
}

#[derive(Clone, Copy, Debug)]
struct Replicas<T> {
    dom: ReplicaChannel<T>,
    dom2: ReplicaChannel<T>,
    ds: ReplicaChannel<T>,
    ax: ReplicaChannel<T>,
    ay: ReplicaChannel<T>,
}

/// Configuration values the tick uses, converted once (the same expressions as before,
/// evaluated at design time instead of in soft-float `f64` on every tick of the chip).
#[derive(Clone, Copy, Debug)]
struct TickConsts<T> {
    /// `monitor.full_scale_um` and `monitor.accel_full_scale_mps2` in T.
    full_scale: T,
    accel_full_scale: T,
    /// `rls.p_reset` in T.
    p_reset: T,
    /// The settle window and the relinearisation interval, samples.
    settle_window: u64,
    relin_every: u64,
    /// The covariance-bounded limits `p0·n·1.0001` (n = 8, 6) in T.
    lim1: T,
    lim2: T,
}

impl<T: Real> TickConsts<T> {
    fn of(cfg: &Config) -> Self {
        TickConsts {
            full_scale: T::from_f64(cfg.monitor.full_scale_um),
            accel_full_scale: T::from_f64(cfg.monitor.accel_full_scale_mps2),
            p_reset: T::from_f64(cfg.rls.p_reset),
            settle_window: (cfg.retune.settle_window_s * cfg.fs_hz) as u64,
            relin_every: (cfg.rls.relinearize_s * cfg.fs_hz) as u64,
            lim1: T::from_f64(cfg.rls.p0 * 8.0 * 1.0001),
            lim2: T::from_f64(cfg.rls.p0 * 6.0 * 1.0001),
        }
    }
}

/// The estimator (runtime form of a validated [`Config`]).
#[derive(Clone, Debug)]
pub struct Estimator<T: Real> {
    cfg: Config,
    tc: TickConsts<T>,
    // derived constants
    f0_hz: f64,
    om_ref: f64,
    inv_l0: T,
    accel_nd: T,
    th1n: [f64; 8],
    th2n: [f64; 6],
    sc1: [T; 8],
    sc2: [T; 6],
    w1: [T; NROWS],
    w2: [T; NROWS],
    gate_startup: u64,
    gate_jump: u64,
    gate_bad: u64,
    dither_rms: f64,
    /// (excitation_min_fraction · dither rms)², compared with the meter's variance.
    exc_var_min: T,
    /// EWMA weight of the mean pump scale (1 s).
    s_alpha: T,
    /// Reference pump frequency 2·f0·ω_ref, Hz (f64), 1/(2 f0) and 2ω_ref in T.
    pump_ref_hz: f64,
    inv_2f0: T,
    two_om_ref: T,
    // blocks
    rep: Option<Replicas<T>>,
    rep_co: ReplicaCoeffs<T>,
    rows: RowBuilder<T>,
    last_rows: RowSet<T>,
    last_known: Known<T>,
    rls1: Rls<T, 8>,
    rls2: Rls<T, 6>,
    det1: ChangeDetector<T>,
    det2: ChangeDetector<T>,
    stuck: StuckDetector<T>,
    exc: ExcitationMeter<T>,
    // nominal θ14, θ22, θ24 in T (for ω̂y² on the tick path)
    th14n: T,
    th22n: T,
    th24n: T,
    settle: SettleTest<T>,
    sched: Scheduler<T>,
    sup: Supervisor<T>,
    // state
    k: u64,
    jump_gate_until: u64,
    bad_gate_until: u64,
    last_reset: u64,
    change_pending: bool,
    bound_learned: bool,
    was_settled: bool,
    last_good: Option<(Envelopes<T>, [T; 2], f64, T)>,
    health: Health,
    counters: Counters,
    /// Mean pump voltage scale (EWMA over ~1 s).
    last_s: T,
    last_relin: u64,
    relins: u32,
}

impl<T: Real> Estimator<T> {
    /// Builds from a configuration that passed [`Config::validate`] (use
    /// [`Config::build`]).
    pub(crate) fn from_valid_config(cfg: &Config) -> Self {
        let mut e = Self::blank();
        e.init_from(cfg);
        e
    }

    /// Designs this estimator from a configuration that passed [`Config::validate`],
    /// field by field in place: every large part (filters, tables, RLS) is written
    /// straight into its field, so no estimator-sized temporary exists (the chip's
    /// stack). The pattern below names every field, so none can be left out.
    fn init_from(&mut self, cfg: &Config) {
        let omega0 = cfg.omega0_rad_s();
        let ts = omega0 / cfg.fs_hz; // sample period in τ
        let (th1n, th2n) = theta_from_physical(&cfg.nominal);
        let om_ref = cfg.pump_centre_hz / (2.0 * cfg.f0_hz);
        let nom = NominalConsts::<T>::new(&th1n, &th2n, om_ref);
        let w_svf = 2.0 * core::f64::consts::PI * cfg.svf_hz / omega0;
        let wc = 2.0 * core::f64::consts::PI * cfg.lockin_lpf_hz / omega0;
        let mut sc1 = [T::ZERO; 8];
        let mut sc2 = [T::ZERO; 6];
        for j in 0..8 {
            sc1[j] = T::from_f64(libm::fabs(th1n[j]));
        }
        for j in 0..6 {
            sc2[j] = T::from_f64(libm::fabs(th2n[j]));
        }
        let mut w1 = [T::ZERO; NROWS];
        let mut w2 = [T::ZERO; NROWS];
        for r in 0..NROWS {
            w1[r] = T::from_f64(1.0 / (cfg.row_sigma_drive[r] * cfg.noise_pm_rthz));
            w2[r] = T::from_f64(1.0 / (cfg.row_sigma_sense[r] * cfg.noise_pm_rthz));
        }
        // out of line: inlined at its nine uses it was ~1 KB of the firmware image
        #[inline(never)]
        fn samples_at(s: f64, fs_hz: f64) -> u64 {
            libm::round(s * fs_hz).max(0.0) as u64
        }
        let samples = |s: f64| samples_at(s, cfg.fs_hz);
        let r = &cfg.rls;
        let set1 = RlsSettings {
            forgetting: T::from_f64(r.forgetting),
            p0: T::from_f64(r.p0),
            trace_max: T::from_f64(r.p0 * 8.0 * 10.0),
        };
        let set2 = RlsSettings {
            forgetting: T::from_f64(r.forgetting),
            p0: T::from_f64(r.p0),
            trace_max: T::from_f64(r.p0 * 6.0 * 10.0),
        };
        let m = &cfg.monitor;
        let hold = samples(m.change_hold_s).max(1);
        let dither_amp = cfg.dither.pump_hz / (2.0 * cfg.f0_hz);
        let t = &cfg.retune;
        let sup = Supervisor::new(SupervisorSettings {
            enabled: t.enabled,
            ramp_min: samples(t.ramp_s).max(1),
            max_rate: t.max_rate_hz_per_s / (2.0 * cfg.f0_hz) / cfg.fs_hz,
            deadband: t.deadband_hz / (2.0 * cfg.f0_hz),
            margin: t.band_margin,
            min_interval: samples(t.min_interval_s),
            lock_min: t.lock_min_um / cfg.l0_um,
            lock_lost_after: samples(t.lock_lost_s),
        });
        let every = 25u64;
        let need = ((t.settle_window_s * cfg.fs_hz) / every as f64) as usize + 1;
        let Estimator {
            cfg: f_cfg,
            tc: f_tc,
            f0_hz: f_f0_hz,
            om_ref: f_om_ref,
            inv_l0: f_inv_l0,
            accel_nd: f_accel_nd,
            th1n: f_th1n,
            th2n: f_th2n,
            sc1: f_sc1,
            sc2: f_sc2,
            w1: f_w1,
            w2: f_w2,
            gate_startup: f_gate_startup,
            gate_jump: f_gate_jump,
            gate_bad: f_gate_bad,
            dither_rms: f_dither_rms,
            exc_var_min: f_exc_var_min,
            s_alpha: f_s_alpha,
            pump_ref_hz: f_pump_ref_hz,
            inv_2f0: f_inv_2f0,
            two_om_ref: f_two_om_ref,
            rep: f_rep,
            rep_co: f_rep_co,
            rows: f_rows,
            last_rows: f_last_rows,
            last_known: f_last_known,
            rls1: f_rls1,
            rls2: f_rls2,
            det1: f_det1,
            det2: f_det2,
            stuck: f_stuck,
            exc: f_exc,
            th14n: f_th14n,
            th22n: f_th22n,
            th24n: f_th24n,
            settle: f_settle,
            sched: f_sched,
            sup: f_sup,
            k: f_k,
            jump_gate_until: f_jump_gate_until,
            bad_gate_until: f_bad_gate_until,
            last_reset: f_last_reset,
            change_pending: f_change_pending,
            bound_learned: f_bound_learned,
            was_settled: f_was_settled,
            last_good: f_last_good,
            health: f_health,
            counters: f_counters,
            last_s: f_last_s,
            last_relin: f_last_relin,
            relins: f_relins,
        } = self;
        *f_cfg = *cfg;
        *f_tc = TickConsts::of(cfg);
        *f_f0_hz = cfg.f0_hz;
        *f_om_ref = om_ref;
        *f_inv_l0 = T::from_f64(1.0 / cfg.l0_um);
        *f_accel_nd = T::from_f64(1.0 / (cfg.l0_um * 1e-6 * omega0 * omega0));
        *f_th1n = th1n;
        *f_th2n = th2n;
        *f_sc1 = sc1;
        *f_sc2 = sc2;
        *f_w1 = w1;
        *f_w2 = w2;
        *f_gate_startup = samples(m.gate_startup_s);
        *f_gate_jump = samples(m.gate_jump_s);
        *f_gate_bad = samples(m.bad_input_gate_s);
        *f_dither_rms = dither_amp / core::f64::consts::SQRT_2;
        *f_exc_var_min = {
            let v = m.excitation_min_fraction * dither_amp / core::f64::consts::SQRT_2;
            T::from_f64(v * v)
        };
        *f_s_alpha = T::from_f64(1.0 / cfg.fs_hz);
        *f_pump_ref_hz = 2.0 * cfg.f0_hz * om_ref;
        *f_inv_2f0 = T::from_f64(1.0 / (2.0 * cfg.f0_hz));
        *f_two_om_ref = T::from_f64(2.0 * om_ref);
        *f_rep = None;
        *f_rep_co = ReplicaCoeffs::butterworth(cfg.lockin_lpf_order, wc, ts);
        *f_rows = RowBuilder::new(w_svf, ts, nom);
        *f_last_rows = RowSet::default();
        *f_last_known = Known::default();
        *f_rls1 = Rls::new(set1);
        *f_rls2 = Rls::new(set2);
        *f_det1 = ChangeDetector::new(NROWS as f64, m.change_alpha, m.change_threshold, hold);
        *f_det2 = ChangeDetector::new(NROWS as f64, m.change_alpha, m.change_threshold, hold);
        *f_stuck = StuckDetector::new(m.stuck_samples);
        *f_exc = ExcitationMeter::new(1.0 / (0.5 * cfg.fs_hz));
        *f_th14n = T::from_f64(th1n[3]);
        *f_th22n = T::from_f64(th2n[1]);
        *f_th24n = T::from_f64(th2n[3]);
        *f_settle = SettleTest::new(every, need, t.settle_tol);
        *f_sched = Scheduler::new(
            om_ref,
            dither_amp,
            cfg.dither.freq_hz / cfg.fs_hz,
            cfg.dither.taper_s * cfg.fs_hz,
            samples(cfg.dither.start_s),
            cfg.dither.enabled,
        )
        .with_scale_dither(cfg.dither.scale_frac, cfg.dither.scale_freq_hz / cfg.fs_hz);
        *f_sup = sup;
        *f_k = 0;
        *f_jump_gate_until = 0;
        *f_bad_gate_until = 0;
        *f_last_reset = 0;
        *f_change_pending = false;
        *f_bound_learned = false;
        *f_was_settled = false;
        *f_last_good = None;
        *f_health = Health::default();
        *f_counters = Counters::default();
        *f_last_s = T::ONE;
        *f_last_relin = 0;
        *f_relins = 0;
    }

    /// A placeholder estimator with no design, to be [`Estimator::rebuild`]t in place
    /// before use: every field is a constant, so a caller embedding it (the firmware's
    /// `App`) gets it written straight into its final place, and `rebuild` then designs
    /// into that place, with no estimator-sized temporary on the stack (on the chip the
    /// estimator is ≈ 4.7 KB and the stack budget 16 KiB). Stepping a blank estimator
    /// never panics, but its outputs mean nothing. Its configuration reads as
    /// [`Config::table2`].
    #[inline(always)]
    pub fn blank() -> Self {
        Estimator {
            cfg: Config::table2(),
            tc: TickConsts {
                full_scale: T::ZERO,
                accel_full_scale: T::ZERO,
                p_reset: T::ZERO,
                settle_window: 0,
                relin_every: 0,
                lim1: T::ZERO,
                lim2: T::ZERO,
            },
            f0_hz: 0.0,
            om_ref: 0.0,
            inv_l0: T::ZERO,
            accel_nd: T::ZERO,
            th1n: [0.0; 8],
            th2n: [0.0; 6],
            sc1: [T::ZERO; 8],
            sc2: [T::ZERO; 6],
            w1: [T::ZERO; NROWS],
            w2: [T::ZERO; NROWS],
            gate_startup: 0,
            gate_jump: 0,
            gate_bad: 0,
            dither_rms: 0.0,
            exc_var_min: T::ZERO,
            s_alpha: T::ZERO,
            pump_ref_hz: 0.0,
            inv_2f0: T::ZERO,
            two_om_ref: T::ZERO,
            rep: None,
            rep_co: ReplicaCoeffs::blank(),
            rows: RowBuilder::blank(),
            last_rows: RowSet::default(),
            last_known: Known::default(),
            rls1: Rls::blank(),
            rls2: Rls::blank(),
            det1: ChangeDetector::blank(),
            det2: ChangeDetector::blank(),
            stuck: StuckDetector::blank(),
            exc: ExcitationMeter::blank(),
            th14n: T::ZERO,
            th22n: T::ZERO,
            th24n: T::ZERO,
            settle: SettleTest::blank(),
            sched: Scheduler::blank(),
            sup: Supervisor::blank(),
            k: 0,
            jump_gate_until: 0,
            bad_gate_until: 0,
            last_reset: 0,
            change_pending: false,
            bound_learned: false,
            was_settled: false,
            last_good: None,
            health: Health::default(),
            counters: Counters::default(),
            last_s: T::ONE,
            last_relin: 0,
            relins: 0,
        }
    }

    /// Rebuilds this estimator in place from a validated configuration (the same
    /// estimator [`Config::build`] returns, designed straight into `self`).
    #[inline(never)] // the design's temporaries live in this frame only
    pub fn rebuild(&mut self, cfg: ValidConfig<'_>) {
        self.init_from(cfg.config());
    }

    /// The configuration this estimator was built from.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Pump frequency to command before the first sample, Hz.
    pub fn initial_pump_hz(&self) -> f64 {
        self.pump_hz_of(self.sched.centre())
    }

    fn pump_hz_of(&self, dev: f64) -> f64 {
        self.pump_ref_hz + 2.0 * self.f0_hz * dev
    }

    /// Current pump centre (without dither), Hz.
    pub fn pump_centre_hz(&self) -> f64 {
        self.pump_hz_of(self.sched.centre())
    }

    /// Commands a new pump centre. `jump = true`: at once, with RLS gating for
    /// `gate_jump_s` and a covariance reset (FINDINGS §3.5); `false`: a raised-cosine
    /// ramp of `retune.ramp_s`.
    pub fn command_pump_centre(&mut self, pump_hz: f64, jump: bool) {
        if !(pump_hz.is_finite() && pump_hz > 0.0) {
            return;
        }
        let dev = pump_hz / (2.0 * self.f0_hz) - self.om_ref;
        if jump {
            self.sched.jump(dev);
            self.jump_gate_until = self.k + self.gate_jump;
            let p = T::from_f64(self.cfg.rls.p_reset);
            self.rls1.reset_covariance(p);
            self.rls2.reset_covariance(p);
            self.det1.rearm();
            self.det2.rearm();
            self.last_reset = self.k;
            self.change_pending = true;
            self.settle.clear();
            self.lift_trace_bound();
            self.counters.jumps += 1;
        } else {
            let len = libm::round(self.cfg.retune.ramp_s * self.cfg.fs_hz).max(1.0) as u64;
            self.sched.ramp_to(dev, self.k, len);
        }
    }

    /// Switches the pump-frequency dither on or off (tapered).
    pub fn set_dither(&mut self, on: bool) {
        self.sched.set_dither(on);
    }

    /// Changes the peak pump-frequency dither, Hz (e.g. to keep it a fixed fraction of a
    /// narrower parametric band). Ignored unless finite, ≥ 0 and below 5 % of the pump.
    pub fn set_dither_pump_hz(&mut self, pump_hz: f64) {
        if pump_hz.is_finite() && pump_hz >= 0.0 && pump_hz < 0.05 * self.pump_centre_hz() {
            let amp = pump_hz / (2.0 * self.f0_hz);
            self.sched.set_dither_amp(amp);
            self.dither_rms = amp / core::f64::consts::SQRT_2;
            let v = self.cfg.monitor.excitation_min_fraction * self.dither_rms;
            self.exc_var_min = T::from_f64(v * v);
        }
    }

    /// Allows or forbids the retune supervisor.
    pub fn set_retune(&mut self, on: bool) {
        self.sup.enabled = on;
    }

    /// After a covariance reset the converged trace of the old regime means nothing:
    /// the bound is lifted to its start-up value and learned again at the next settle.
    fn lift_trace_bound(&mut self) {
        let p0 = self.cfg.rls.p0;
        self.rls1.set_trace_max(T::from_f64(p0 * 8.0 * 10.0));
        self.rls2.set_trace_max(T::from_f64(p0 * 6.0 * 10.0));
        self.bound_learned = false;
    }

    /// The scaled deviation is moderate (every |δθ_j| ≤ 2|θ_design,j|): not a wild
    /// transient estimate that would make a poor linearisation point.
    fn deviation_moderate(&self) -> bool {
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

    /// Moves the linearisation point θ_nom to the current estimate (δθ → 0). The
    /// column scales stay those of the configured design, so P keeps its meaning.
    fn relinearize(&mut self) {
        let (t1, t2) = self.theta();
        if t1.iter().chain(t2.iter()).any(|v| !v.is_finite()) {
            return;
        }
        self.rows.relinearize(&t1, &t2, self.om_ref);
        self.th1n = t1;
        self.th2n = t2;
        self.th14n = T::from_f64(t1[3]);
        self.th22n = T::from_f64(t2[1]);
        self.th24n = T::from_f64(t2[3]);
        self.rls1.set_estimate([T::ZERO; 8]);
        self.rls2.set_estimate([T::ZERO; 6]);
        self.relins += 1;
    }

    /// Times the linearisation point moved to the settled estimate.
    pub fn relinearizations(&self) -> u32 {
        self.relins
    }

    /// Health after the last step.
    pub fn health(&self) -> Health {
        self.health
    }

    /// Counters since start-up.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// Samples processed.
    pub fn samples(&self) -> u64 {
        self.k
    }

    /// The nominal θ the RLS linearises about.
    pub fn nominal_theta(&self) -> ([f64; 8], [f64; 6]) {
        (self.th1n, self.th2n)
    }

    /// The current estimate θ̂1 (8), θ̂2 (6) in eq. (25) order.
    pub fn theta(&self) -> ([f64; 8], [f64; 6]) {
        let x1 = self.rls1.estimate();
        let x2 = self.rls2.estimate();
        let mut t1 = self.th1n;
        let mut t2 = self.th2n;
        // the scaled deviation in T (one rounding in f32, none in f64: the host's f64
        // values are unchanged), the sum with the nominal in f64
        for j in 0..8 {
            t1[j] += (self.sc1[j] * x1[j]).to_f64();
        }
        for j in 0..6 {
            t2[j] += (self.sc2[j] * x2[j]).to_f64();
        }
        (t1, t2)
    }

    /// 1-σ uncertainty of θ̂ relative to |θ_design| (the square roots of the diagonal of
    /// the column-scaled covariance; rows are weighted to unit noise, so P is the
    /// estimate's covariance when the configured row noise is right).
    pub fn theta_rel_sigma(&self) -> ([f64; 8], [f64; 6]) {
        let p1 = self.rls1.covariance();
        let p2 = self.rls2.covariance();
        let mut s1 = [0.0; 8];
        let mut s2 = [0.0; 6];
        for j in 0..8 {
            s1[j] = libm::sqrt(p1[j][j].to_f64().max(0.0));
        }
        for j in 0..6 {
            s2[j] = libm::sqrt(p2[j][j].to_f64().max(0.0));
        }
        (s1, s2)
    }

    /// The physical parameters from θ̂ (corrected Table 3).
    pub fn physical(&self) -> Physical {
        let (t1, t2) = self.theta();
        physical_from_theta(&t1, &t2)
    }

    /// Estimated angular rate, °/s.
    pub fn rate_dps(&self) -> f64 {
        rate_dps_from_gamma(self.physical().gamma, self.cfg.omega0_rad_s())
    }

    /// ω̂y² in `T` from the three θ components it needs (the tick path; `wy2()` is the
    /// `f64` value from the full θ̂).
    fn wy2_fast(&self) -> T {
        let x1 = self.rls1.estimate();
        let x2 = self.rls2.estimate();
        let t14 = self.th14n + self.sc1[3] * x1[3];
        let t22 = self.th22n + self.sc2[1] * x2[1];
        let t24 = self.th24n + self.sc2[3] * x2[3];
        let g = (t14 - t24) * T::from_f64(0.25);
        -t22 + g * g
    }

    /// θ̂1 in `T` (the retune's drive band on the tick path; `theta()` is the `f64`
    /// value, the same sums in `f64`).
    fn theta1_t(&self) -> [T; 8] {
        let x1 = self.rls1.estimate();
        core::array::from_fn(|j| T::from_f64(self.th1n[j]) + self.sc1[j] * x1[j])
    }

    /// Estimated ω_y² (non-dimensional).
    pub fn wy2(&self) -> f64 {
        let (t1, t2) = self.theta();
        let g = (t1[3] - t2[3]) / 4.0;
        -t2[1] + g * g
    }

    /// Traces of the (column-scaled) covariances (drive, sense).
    pub fn traces(&self) -> (f64, f64) {
        (self.rls1.trace().to_f64(), self.rls2.trace().to_f64())
    }

    /// Change-detector levels (drive, sense).
    pub fn detector_levels(&self) -> (f64, f64) {
        (self.det1.level(), self.det2.level())
    }

    /// The last sample's rows, unweighted and unscaled (`y = z − Φθ_nom`), for
    /// diagnostics and calibration.
    pub fn last_rows(&self) -> &RowSet<T> {
        &self.last_rows
    }

    /// The last sample's known signals after the replica low-pass (diagnostics).
    pub fn last_known(&self) -> &Known<T> {
        &self.last_known
    }

    /// Row weights (drive, sense) = 1/σ.
    pub fn row_weights(&self) -> ([T; NROWS], [T; NROWS]) {
        (self.w1, self.w2)
    }

    fn check(&mut self, s: &Sample<T>) -> InputCheck {
        let ch = s.lockin.channels();
        let mut c = InputCheck::default();
        let fs = self.tc.full_scale;
        let afs = self.tc.accel_full_scale;
        for v in ch.iter() {
            if !v.is_finite() {
                c.non_finite = true;
            } else if v.abs() >= fs {
                c.saturated = true;
            }
        }
        for v in s.accel_mps2.iter() {
            if !v.is_finite() {
                c.non_finite = true;
            } else if v.abs() >= afs {
                c.saturated = true;
            }
        }
        if !(s.pump_hz.is_finite()
            && s.pump_hz > 0.0
            && s.pump_scale.is_finite()
            && s.pump_scale >= T::ZERO)
        {
            c.non_finite = true;
        }
        if !c.non_finite && self.stuck.push(&ch) {
            c.stuck = true;
        }
        c
    }

    /// Processes one 500 Hz sample. Never fails, never panics, never allocates.
    #[inline(never)]
    pub fn step(&mut self, s: &Sample<T>) -> StepOutput {
        let k = self.k;
        let mut events = 0u8;
        self.counters.samples = self.counters.samples.wrapping_add(1);
        let chk = self.check(s);
        let good = chk.ok();
        if good {
            let mut e = Envelopes {
                x0: s.lockin.x0_um * self.inv_l0,
                y0: s.lockin.y0_um * self.inv_l0,
                ..Envelopes::default()
            };
            for i in 0..3 {
                e.a[i] = s.lockin.x_um[i].scale(self.inv_l0);
                e.b[i] = s.lockin.y_um[i].scale(self.inv_l0);
            }
            let acc = [
                s.accel_mps2[0] * self.accel_nd,
                s.accel_mps2[1] * self.accel_nd,
            ];
            self.last_good = Some((e, acc, s.pump_hz, s.pump_scale));
        } else {
            self.counters.bad_samples += 1;
            self.counters.non_finite += chk.non_finite as u32;
            self.counters.saturated += chk.saturated as u32;
            self.counters.stuck += chk.stuck as u32;
            self.bad_gate_until = k + self.gate_bad + 1;
            events |= event::BAD_INPUT;
        }
        let Some((env, acc, pump_hz, pscale)) = self.last_good else {
            // nothing valid yet: hold, keep commanding the centre
            self.k += 1;
            self.health = Health {
                inputs_valid: false,
                ..Health::default()
            };
            let dev = self.sched.command(self.k);
            return StepOutput {
                pump_hz_next: self.pump_hz_of(dev),
                pump_scale_next: self.sched.scale_command(),
                health: self.health,
                events,
                updated: false,
            };
        };

        // ---- known signals through the replica of the lock-in low-pass
        // ω − ω_ref from the small Hz offset: one f64 subtraction, the rest in T keeps
        // ~1e-10 absolute precision (the offset is at most a few % of the pump)
        let dev = T::from_f64(pump_hz - self.pump_ref_hz) * self.inv_2f0;
        let dom = dev;
        let dom2 = dev * (self.two_om_ref + dev);
        let ds = pscale - T::ONE;
        // one set of coefficients, borrowed (not copied) every tick
        let co = &self.rep_co;
        let rep = self.rep.get_or_insert_with(|| Replicas {
            dom: ReplicaChannel::at_rest(co, dom),
            dom2: ReplicaChannel::at_rest(co, dom2),
            ds: ReplicaChannel::at_rest(co, ds),
            ax: ReplicaChannel::at_rest(co, acc[0]),
            ay: ReplicaChannel::at_rest(co, acc[1]),
        });
        // the commanded pump (frequency and scale) follows the generator's profile
        let hold = self.cfg.pump_profile == crate::config::PumpProfile::Staircase;
        let f_dom = rep.dom.update_with(co, dom, hold);
        let known = Known {
            om: T::from_f64(self.om_ref) + f_dom,
            dom2: rep.dom2.update_with(co, dom2, hold),
            omd: rep.dom.derivative(co),
            ds: rep.ds.update_with(co, ds, hold),
            ax: rep.ax.update(co, acc[0]),
            ay: rep.ay.update(co, acc[1]),
        };
        let exc_var = self.exc.push(f_dom);
        self.last_known = known;

        // ---- rows
        self.rows.push(&env, &known, &mut self.last_rows);
        let rows = &self.last_rows;

        // ---- gating and RLS
        let gated = k < self.gate_startup || k < self.jump_gate_until || k < self.bad_gate_until;
        let mut updated = false;
        if !gated && good {
            updated = true;
            self.counters.updates += 1;
            self.rls1.begin_sample();
            self.rls2.begin_sample();
            let mut sum1 = T::ZERO;
            let mut sum2 = T::ZERO;
            for r in 0..NROWS {
                let w = self.w1[r];
                // built by `from_fn`, not zeroed then filled (no memclr on the tick path)
                let phi: [T; 8] = core::array::from_fn(|j| rows.drive_phi[r][j] * self.sc1[j] * w);
                let inn = self.rls1.update(&phi, rows.drive_y[r] * w);
                sum1 += inn.normalized_sq();
                let w = self.w2[r];
                let phi: [T; 6] = core::array::from_fn(|j| rows.sense_phi[r][j] * self.sc2[j] * w);
                let inn = self.rls2.update(&phi, rows.sense_y[r] * w);
                sum2 += inn.normalized_sq();
            }
            let p = self.tc.p_reset;
            if self.det1.push(k, sum1) {
                self.rls1.reset_covariance(p);
                self.counters.resets_drive += 1;
                events |= event::CHANGE_DRIVE;
            }
            if self.det2.push(k, sum2) {
                self.rls2.reset_covariance(p);
                self.counters.resets_sense += 1;
                events |= event::CHANGE_SENSE;
            }
            if events & (event::CHANGE_DRIVE | event::CHANGE_SENSE) != 0 {
                self.last_reset = k;
                self.change_pending = true;
                self.settle.clear();
                self.lift_trace_bound();
            }
        }

        // ---- settle, excitation, health
        let wy2 = self.wy2_fast();
        if updated {
            self.settle.push(k, wy2);
        }
        let window = self.tc.settle_window;
        let settled = !gated && self.settle.settled() && k >= self.last_reset + window;
        if settled && !self.was_settled {
            events |= event::SETTLED;
            self.change_pending = false;
            if !self.bound_learned {
                // anti-windup bound: a factor over the converged trace (FINDINGS §4),
                // learned anew after every reset (a new regime has another trace)
                let f = self.cfg.rls.trace_bound_factor;
                let t1 = T::from_f64(self.rls1.trace().to_f64() * f);
                let t2 = T::from_f64(self.rls2.trace().to_f64() * f);
                self.rls1.set_trace_max(t1);
                self.rls2.set_trace_max(t2);
                self.bound_learned = true;
            }
        }
        self.was_settled = settled;
        let relin_every = self.tc.relin_every;
        if relin_every > 0
            && updated
            && k >= self.last_relin + relin_every
            && self.deviation_moderate()
        {
            self.relinearize();
            self.last_relin = k;
        }
        let excitation_ok = self.dither_rms > 0.0 && exc_var >= self.exc_var_min;
        let (tr1, tr2) = (self.rls1.last_trace(), self.rls2.last_trace());
        let (lim1, lim2) = (self.tc.lim1, self.tc.lim2);
        let covariance_bounded = tr1.is_finite()
            && tr2.is_finite()
            && tr1 <= lim1
            && tr2 <= lim2
            && self.rls1.min_d() > T::ZERO
            && self.rls2.min_d() > T::ZERO;
        let drive_amp = env.a[0].abs();
        // mean pump scale (1 s EWMA): the amplitude dither must not make the band guard
        // wobble with the instantaneous s
        self.last_s += self.s_alpha * (pscale - self.last_s);
        let mut health = Health {
            inputs_valid: good,
            excitation_ok,
            covariance_bounded,
            change_detected: self.change_pending,
            drive_locked: self.sup.locked(),
            settled,
            gated,
            retuning: self.sup.ramping(),
        };

        // ---- retune supervisor
        let centre_om = self.om_ref + self.sched.centre();
        // retune decisions at 20 Hz (every 25 samples): plenty for a move of ≥ 0.5 s;
        // lock tracking and ramps run every tick. The decision is in T (module retune).
        let decide = k.is_multiple_of(25);
        let healthy = decide && health.actionable() && k >= self.bad_gate_until;
        let wy2 = if decide { wy2 } else { T::ZERO };
        // the band (three square roots) only when a retune is actually in view
        let band = if decide
            && self
                .sup
                .would_retune(k, healthy, wy2, T::from_f64(centre_om))
        {
            drive_band(&self.theta1_t(), self.last_s)
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
                self.sched.ramp_to(target_om - self.om_ref, k + 1, len);
                self.counters.retunes += 1;
                events |= event::RETUNE_START;
            }
            RetuneAction::Abort { back_to_om, len } => {
                self.sched.ramp_to(back_to_om - self.om_ref, k + 1, len);
                self.counters.retune_aborts += 1;
                events |= event::RETUNE_ABORT;
            }
            RetuneAction::None => {
                if health.retuning && !self.sup.ramping() {
                    events |= event::RETUNE_DONE;
                }
            }
        }
        health.drive_locked = self.sup.locked();
        health.retuning = self.sup.ramping();
        self.health = health;

        // ---- next pump command
        self.k += 1;
        let dev = self.sched.command(self.k);
        StepOutput {
            pump_hz_next: self.pump_hz_of(dev),
            pump_scale_next: self.sched.scale_command(),
            health,
            events,
            updated,
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    #[test]
    fn validated_build_and_initial_pump_match_build() {
        let cfg = Config::table2();
        let a = cfg.build::<f32>().unwrap();
        let b = cfg.validated().unwrap().build::<f32>();
        assert_eq!(std::format!("{a:?}"), std::format!("{b:?}"));
        // built in place over a blank one (which steps without panicking)
        let mut c = Estimator::<f32>::blank();
        for k in 0..300 {
            let _ = c.step(&sample(k, 21_000.0));
        }
        c.rebuild(cfg.validated().unwrap());
        assert_eq!(std::format!("{a:?}"), std::format!("{c:?}"));
        assert_eq!(
            cfg.initial_pump_hz().to_bits(),
            a.initial_pump_hz().to_bits()
        );
        let mut bad = cfg;
        bad.fs_hz = f64::NAN;
        assert_eq!(bad.validated().unwrap_err().field, "fs_hz");
    }
    use crate::config::Config;

    /// A plausible steady sample of the Table 2 gyro with a little variation (so that no
    /// channel is stuck).
    fn sample(k: u64, pump_hz: f64) -> Sample<f32> {
        // every channel moves a little (real data always carries noise)
        let d = |i: u64| (((k + 3 * i) * 7919) % 13) as f32 * 1e-5;
        Sample {
            lockin: Lockin {
                x0_um: 0.0204 + d(0),
                x_um: [
                    Cplx::new(1.2 + d(1), -1.27 + d(2)),
                    Cplx::new(1e-4 + d(3), d(4)),
                    Cplx::new(0.001 + d(5), 0.002 + d(6)),
                ],
                y0_um: 0.0207 - d(7),
                y_um: [
                    Cplx::new(0.9 + d(8), 1.2 - d(9)),
                    Cplx::new(d(10), 1e-4 + d(11)),
                    Cplx::new(0.0005 + d(12), -0.001 + d(13)),
                ],
            },
            accel_mps2: [98.0665, 98.0665],
            pump_hz,
            pump_scale: 1.0,
        }
    }

    fn run_to(est: &mut Estimator<f32>, n: u64) -> f64 {
        let mut pump = est.initial_pump_hz();
        for k in 0..n {
            pump = est.step(&sample(k, pump)).pump_hz_next;
        }
        pump
    }

    fn check_bad(mutate: impl Fn(&mut Sample<f32>), field: &str) {
        let mut est = Config::table2().build::<f32>().unwrap();
        let pump = run_to(&mut est, 600); // past the start-up gate: the RLS updates
        let before = est.theta();
        let c0 = est.counters();
        let mut s = sample(600, pump);
        mutate(&mut s);
        let out = est.step(&s);
        assert!(!out.health.inputs_valid, "{field}: not flagged");
        assert!(!out.updated, "{field}: the RLS used a bad sample");
        assert!(out.events & event::BAD_INPUT != 0, "{field}: no event");
        assert_eq!(est.theta(), before, "{field}: estimate not held");
        assert_eq!(
            est.counters().bad_samples,
            c0.bad_samples + 1,
            "{field}: counter"
        );
        assert!(out.pump_hz_next.is_finite() && out.pump_hz_next > 0.0);
        // recovery: good samples are gated for bad_input_gate_s, then used again
        let mut pump = out.pump_hz_next;
        let gate = (est.config().monitor.bad_input_gate_s * 500.0) as u64;
        for k in 0..gate + 5 {
            let o = est.step(&sample(601 + k, pump));
            pump = o.pump_hz_next;
            assert!(o.health.inputs_valid);
            if k + 1 < gate {
                assert!(!o.updated, "{field}: updated during the recovery gate");
            }
            if k > gate + 1 {
                assert!(o.updated, "{field}: never recovered");
            }
        }
    }

    #[test]
    fn nan_inf_saturated_are_flagged_skipped_and_counted() {
        check_bad(|s| s.lockin.x_um[0].re = f32::NAN, "NaN in A1");
        check_bad(|s| s.lockin.y0_um = f32::INFINITY, "+Inf in Y0");
        check_bad(|s| s.lockin.y_um[2].im = f32::NEG_INFINITY, "-Inf in B3");
        check_bad(|s| s.accel_mps2[1] = f32::NAN, "NaN accelerometer");
        check_bad(|s| s.pump_hz = f64::NAN, "NaN pump");
        check_bad(|s| s.lockin.x_um[0].re = 20.0, "saturated A1");
        check_bad(|s| s.lockin.x0_um = -25.0, "saturated X0");
        check_bad(|s| s.accel_mps2[0] = 1e4, "saturated accelerometer");
        let mut est = Config::table2().build::<f32>().unwrap();
        run_to(&mut est, 600);
        assert_eq!(est.counters().non_finite, 0);
    }

    #[test]
    fn stuck_channel_is_flagged() {
        let mut est = Config::table2().build::<f32>().unwrap();
        let mut pump = run_to(&mut est, 600);
        let limit = est.config().monitor.stuck_samples as u64;
        let frozen = sample(600, pump).lockin.y_um[0];
        let mut flagged_at = None;
        for k in 0..limit + 10 {
            let mut s = sample(600 + k, pump);
            s.lockin.y_um[0] = frozen; // B1 stuck
            let before = est.theta();
            let o = est.step(&s);
            pump = o.pump_hz_next;
            if !o.health.inputs_valid {
                flagged_at.get_or_insert(k);
                assert_eq!(est.theta(), before, "estimate not held on a stuck sample");
            }
        }
        assert_eq!(
            flagged_at,
            Some(limit),
            "stuck channel flagged after {limit} repeats"
        );
        assert!(est.counters().stuck >= 10);
    }

    #[test]
    fn no_valid_sample_yet_holds_the_centre() {
        let mut est = Config::table2().build::<f32>().unwrap();
        let p0 = est.initial_pump_hz();
        let mut s = sample(0, p0);
        s.lockin.x0_um = f32::NAN;
        for _ in 0..10 {
            let o = est.step(&s);
            assert_eq!(o.pump_hz_next, p0);
            assert!(!o.health.inputs_valid && !o.updated);
        }
        let (t1, _) = est.theta();
        assert_eq!(t1, est.nominal_theta().0);
    }

    #[test]
    fn amplitude_phase_front_end_is_converted() {
        // A = |A|·e^{iφ}: (2, 0.3 rad) → (2cos0.3, 2sin0.3); DC levels pass through
        let l = Lockin::<f64>::from_polar(
            0.02,
            [2.0, 0.1, 0.003],
            [0.3, -1.0, 2.5],
            -0.01,
            [1.5, 0.0, 0.001],
            [-0.7, 0.0, 3.1],
        );
        let close = |z: Cplx<f64>, a: f64, ph: f64| {
            (z.re - a * ph.cos()).abs() < 1e-15 && (z.im - a * ph.sin()).abs() < 1e-15
        };
        assert!(
            close(l.x_um[0], 2.0, 0.3)
                && close(l.x_um[1], 0.1, -1.0)
                && close(l.x_um[2], 0.003, 2.5)
        );
        assert!(close(l.y_um[0], 1.5, -0.7) && close(l.y_um[2], 0.001, 3.1));
        assert_eq!((l.x0_um, l.y0_um), (0.02, -0.01));
        assert!((l.x_um[0].abs() - 2.0).abs() < 1e-15);
    }

    #[test]
    fn config_errors_name_the_field() {
        let mut c = Config::table2();
        c.rls.forgetting = 1.5;
        assert_eq!(c.build::<f32>().unwrap_err().field, "rls.forgetting");
        let mut c = Config::table2();
        c.lockin_lpf_hz = f64::NAN;
        assert_eq!(c.build::<f64>().unwrap_err().field, "lockin_lpf_hz");
        let mut c = Config::table2();
        c.nominal.mu_xy = 0.0; // θ14 nominal would be zero: columns cannot be scaled
        let e = c.build::<f32>().unwrap_err();
        assert_eq!(e.field, "nominal");
        let msg = std::format!("{e}");
        assert!(msg.contains("nominal") && msg.contains("θ"), "{msg}");
        let mut c = Config::table2();
        c.dither.freq_hz = 100.0;
        assert_eq!(c.build::<f32>().unwrap_err().field, "dither.freq_hz");
    }

    #[test]
    fn jump_gates_and_resets() {
        let mut est = Config::table2().build::<f64>().unwrap();
        let mut pump = run_to_f64(&mut est, 700);
        est.command_pump_centre(22000.0, true);
        let gate = (est.config().monitor.gate_jump_s * 500.0) as u64;
        for k in 0..gate + 3 {
            let o = est.step(&sample_f64(700 + k, pump));
            pump = o.pump_hz_next;
            if k + 1 < gate {
                assert!(!o.updated && o.health.gated);
            }
        }
        assert!((pump - 22000.0).abs() < 30.0, "pump {pump}");
        assert_eq!(est.counters().jumps, 1);
        assert!((est.pump_centre_hz() - 22000.0).abs() < 1e-6);
    }

    fn sample_f64(k: u64, pump_hz: f64) -> Sample<f64> {
        let s = sample(k, pump_hz);
        let c = |z: Cplx<f32>| Cplx::new(z.re as f64, z.im as f64);
        Sample {
            lockin: Lockin {
                x0_um: s.lockin.x0_um as f64,
                x_um: s.lockin.x_um.map(c),
                y0_um: s.lockin.y0_um as f64,
                y_um: s.lockin.y_um.map(c),
            },
            accel_mps2: [98.0665, 98.0665],
            pump_hz,
            pump_scale: 1.0,
        }
    }

    fn run_to_f64(est: &mut Estimator<f64>, n: u64) -> f64 {
        let mut pump = est.initial_pump_hz();
        for k in 0..n {
            pump = est.step(&sample_f64(k, pump)).pump_hz_next;
        }
        pump
    }
}
