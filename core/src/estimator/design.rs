//! The estimator's design: everything the tick reads and never writes, built once from a
//! validated configuration (in `f64`, rounded to `T` once) and grouped by the stage that
//! reads it.
//!
//! The linearisation point (θ_nom), the RLS factors, the detectors, the scheduler and the
//! supervisor change at run time and live in the state (`super::state`). The design is
//! built **in place** ([`Design::init`]), field by field, so that no design-sized
//! temporary exists on the chip's stack (firmware/README.md).

use crate::config::{Config, PumpProfile};
use crate::drift::{DRIFT_COL, DriftDesign};
use crate::lpf::ReplicaCoeffs;
use crate::monitor::{ChangeDesign, InputLimits, SettleDesign};
use crate::physics::theta_from_physical;
use crate::rate::RateDesign;
use crate::real::Real;
use crate::rows::{NROWS, RowDesign};
use crate::thermal::ThermalDesign;

/// Every `DECIDE_EVERY`-th sample the supervisor decides about a retune (20 Hz: plenty
/// for a move of ≥ 0.5 s); lock tracking and ramps run every tick.
pub(crate) const DECIDE_EVERY: u64 = 25;

/// The settle test keeps one ω̂y² every `SETTLE_EVERY` samples.
pub(crate) const SETTLE_EVERY: u64 = 25;

/// Units and the pump reference: the conversion of a sample to the model's
/// non-dimensional units, and of a commanded ω deviation back to Hz.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Units<T> {
    /// f0 (the time unit ω0 = 2π f0), Hz.
    pub f0_hz: f64,
    /// 2·f0, Hz of pump per unit of ω (stored: `2.0 * f0` at run time is an `f0 + f0`,
    /// one soft-float addition per tick on the chip).
    pub two_f0_hz: f64,
    /// 2·f0 in `T` (the dither's Hz).
    pub two_f0_t: T,
    /// The reference ω_ref = pump centre / (2 f0): commands are deviations from it.
    pub om_ref: f64,
    /// ω_ref in `T` (the known ω of the rows is ω_ref + the filtered deviation).
    pub om_ref_t: T,
    /// The reference pump frequency 2·f0·ω_ref, Hz.
    pub pump_ref_hz: f64,
    /// 1/(2 f0) in `T` (Hz of pump → ω).
    pub inv_2f0: T,
    /// 2·ω_ref in `T` (ω² − ω_ref² = δω (2ω_ref + δω)).
    pub two_om_ref: T,
    /// 1/L0 (µm → L0).
    pub inv_l0: T,
    /// 1/(L0·ω0²) (m/s² → ã).
    pub accel_nd: T,
    /// The pump generator holds each frequency command (staircase): the replica is ZOH.
    pub staircase: bool,
    /// The pump generator holds each scale command: its replica is ZOH.
    pub scale_held: bool,
}

impl<T: Real> Units<T> {
    #[inline(always)]
    fn of(cfg: &Config) -> Self {
        let omega0 = cfg.omega0_rad_s();
        let om_ref = om_ref(cfg);
        Units {
            f0_hz: cfg.f0_hz,
            two_f0_hz: 2.0 * cfg.f0_hz,
            two_f0_t: T::from_f64(2.0 * cfg.f0_hz),
            om_ref,
            pump_ref_hz: 2.0 * cfg.f0_hz * om_ref,
            inv_2f0: T::from_f64(1.0 / (2.0 * cfg.f0_hz)),
            om_ref_t: T::from_f64(om_ref),
            two_om_ref: T::from_f64(2.0 * om_ref),
            inv_l0: T::from_f64(1.0 / cfg.l0_um),
            accel_nd: T::from_f64(1.0 / (cfg.l0_um * 1e-6 * omega0 * omega0)),
            staircase: cfg.pump_profile == PumpProfile::Staircase,
            scale_held: cfg.pump_profile != PumpProfile::Linear,
        }
    }

    /// The pump frequency, Hz, of an ω deviation from the reference.
    #[inline]
    pub fn pump_hz_of(&self, dev: f64) -> f64 {
        self.pump_ref_hz + self.two_f0_hz * dev
    }
}

/// The reference ω of a configuration (its pump centre).
#[inline(always)]
pub(crate) fn om_ref(cfg: &Config) -> f64 {
    cfg.pump_centre_hz / (2.0 * cfg.f0_hz)
}

/// Whole samples in `s` seconds (rounded, ≥ 0). Out of line: inlined at its nine uses
/// it would be ~1 KB of the firmware image.
#[inline(never)]
pub(crate) fn samples_at(s: f64, fs_hz: f64) -> u64 {
    libm::round(s * fs_hz).max(0.0) as u64
}

/// The input checks, the gates and the slow monitors (excitation, settle).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Watch<T> {
    /// Full scales and the stuck-channel limit.
    pub limits: InputLimits<T>,
    /// No RLS updates for this many samples after start-up, a commanded jump, a bad
    /// sample.
    pub gate_startup: u64,
    pub gate_jump: u64,
    pub gate_bad: u64,
    /// EWMA weight of the excitation meter (2/fs: 0.5 s).
    pub exc_alpha: T,
    /// EWMA weight of the mean pump scale (1/fs: 1 s).
    pub s_alpha: T,
    /// The settle test and its window in samples (no settle before a reset is this old).
    pub settle: SettleDesign<T>,
    pub settle_window: u64,
}

impl<T: Real> Watch<T> {
    #[inline(always)]
    fn of(cfg: &Config) -> Self {
        let m = &cfg.monitor;
        let t = &cfg.retune;
        let samples = |s: f64| samples_at(s, cfg.fs_hz);
        let need = ((t.settle_window_s * cfg.fs_hz) / SETTLE_EVERY as f64) as usize + 1;
        Watch {
            limits: InputLimits {
                full_scale_um: T::from_f64(m.full_scale_um),
                accel_full_scale_mps2: T::from_f64(m.accel_full_scale_mps2),
                stuck_samples: m.stuck_samples,
            },
            gate_startup: samples(m.gate_startup_s),
            gate_jump: samples(m.gate_jump_s),
            gate_bad: samples(m.bad_input_gate_s),
            exc_alpha: T::from_f64(1.0 / (0.5 * cfg.fs_hz)),
            s_alpha: T::from_f64(1.0 / cfg.fs_hz),
            settle: SettleDesign::new(SETTLE_EVERY, need, t.settle_tol),
            settle_window: (t.settle_window_s * cfg.fs_hz) as u64,
        }
    }
}

/// The rate walk (`rate.walk_dps`) stops while the rate term's standard deviation is
/// above this, °/s: at start-up and after a covariance reset (p_reset = 1 is ≈ 200 °/s
/// with the Table 2 design), until the slow RLS knows the rate again.
pub const WALK_CAP_DPS: f64 = 20.0;

/// The regression: column scales, row weights, the RLS limits, the change detector and
/// the re-linearisation interval.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Fit<T> {
    /// Column scales |θ_design| (drive, sense): the RLS estimates the scaled deviation.
    pub sc1: [T; 8],
    pub sc2: [T; 6],
    /// Row weights 1/σ (drive, sense): unit noise per row.
    pub w1: [T; NROWS],
    pub w2: [T; NROWS],
    /// Column scale times row weight, `sc[j]·w[r]` rounded once from f64 (drive, sense):
    /// the RLS rows are `row ∘ scw[r]`, one product per element on the tick.
    pub scw1: [[T; 8]; NROWS],
    pub scw2: [[T; 6]; NROWS],
    /// `rls.p_reset` in `T`.
    pub p_reset: T,
    /// The covariance-bounded limits `p0·n·1.0001` (n = 8, 6).
    pub lim1: T,
    pub lim2: T,
    /// The start-up trace bounds `p0·n·10` (n = 8, 6), lifted to again after a reset.
    pub trace_max1: T,
    pub trace_max2: T,
    /// `rls.trace_bound_factor` in `T`: the settled trace bound is the trace times it, in
    /// `T` (for the default 10, exact in `f32`, the same bits as the product in `f64`
    /// rounded once; no soft-float on the chip's settling tick, which is a decision's).
    pub trace_bound: T,
    /// Re-linearise every this many samples (0: never).
    pub relin_every: u64,
    /// The change detector of both axes.
    pub change: ChangeDesign<T>,
    /// The sense θ24's random walk per sample, a variance in scaled units
    /// (`rate.walk_dps`; 0: the rate is a constant of the slow RLS).
    pub walk2: T,
    /// The walks stop while the rate term's variance is above this ([`WALK_CAP_DPS`],
    /// drive θ14 and sense θ24 in their scaled units).
    pub walk_cap1: T,
    pub walk_cap2: T,
    /// The sense drift's row term per unit of its lead (scaled units): `sc2[θ22]/w`
    /// (rows.rs, "A drifting coefficient").
    pub drift_f1: T,
    /// The drift tracker (`rls.drift_kappa`, `rls.drift_window_s`).
    pub drift: DriftDesign<T>,
    /// The temperature learner (`rls.tcf_tau_s`).
    pub thermal: ThermalDesign<T>,
}

impl<T: Real> Fit<T> {
    #[inline(always)]
    fn of(cfg: &Config) -> Self {
        let (th1n, th2n) = theta_from_physical(&cfg.nominal);
        let m = &cfg.monitor;
        let hold = samples_at(m.change_hold_s, cfg.fs_hz).max(1);
        let w1: [f64; NROWS] =
            core::array::from_fn(|r| 1.0 / (cfg.row_sigma_drive[r] * cfg.noise_pm_rthz));
        let w2: [f64; NROWS] =
            core::array::from_fn(|r| 1.0 / (cfg.row_sigma_sense[r] * cfg.noise_pm_rthz));
        Fit {
            scw1: core::array::from_fn(|r| {
                core::array::from_fn(|j| T::from_f64(libm::fabs(th1n[j]) * w1[r]))
            }),
            scw2: core::array::from_fn(|r| {
                core::array::from_fn(|j| T::from_f64(libm::fabs(th2n[j]) * w2[r]))
            }),
            sc1: core::array::from_fn(|j| T::from_f64(libm::fabs(th1n[j]))),
            sc2: core::array::from_fn(|j| T::from_f64(libm::fabs(th2n[j]))),
            w1: w1.map(T::from_f64),
            w2: w2.map(T::from_f64),
            p_reset: T::from_f64(cfg.rls.p_reset),
            lim1: T::from_f64(cfg.rls.p0 * 8.0 * 1.0001),
            lim2: T::from_f64(cfg.rls.p0 * 6.0 * 1.0001),
            trace_max1: T::from_f64(cfg.rls.p0 * 8.0 * 10.0),
            trace_max2: T::from_f64(cfg.rls.p0 * 6.0 * 10.0),
            trace_bound: T::from_f64(cfg.rls.trace_bound_factor),
            relin_every: (cfg.rls.relinearize_s * cfg.fs_hz) as u64,
            change: ChangeDesign::new(
                NROWS as f64,
                m.change_alpha,
                m.change_threshold,
                m.change_drift_margin,
                hold,
            ),
            walk2: T::ZERO,
            drift_f1: T::ZERO,
            walk_cap1: T::ZERO,
            walk_cap2: T::ZERO,
            // the row filter (ζ = 1) delays by 2/w_f at DC
            drift: DriftDesign::new(
                cfg.rls.drift_kappa,
                cfg.rls.drift_window_s * cfg.fs_hz,
                2.0 / (2.0 * core::f64::consts::PI * cfg.svf_hz) * cfg.fs_hz,
                cfg.rls.drift_max_ppm_s * 1e-6 / cfg.fs_hz,
            ),
            thermal: ThermalDesign::new(cfg.rls.tcf_tau_s, cfg.fs_hz, cfg.rls.forgetting),
        }
    }
}

/// The design of an estimator (see the module docs).
#[derive(Clone, Debug)]
pub(crate) struct Design<T: Real> {
    /// The configuration it was built from.
    pub cfg: Config,
    /// Units and the pump reference.
    pub units: Units<T>,
    /// Input checks, gates, monitors.
    pub watch: Watch<T>,
    /// The replica of the lock-in low-pass (`lpf`: FOH-exact; the pump channels exact
    /// for the pump's profile).
    pub replica: ReplicaCoeffs<T>,
    /// The slow state-variable filter and the synthesis tables (`rows`).
    pub rows: RowDesign<T>,
    /// The fast rate channel (`rate`).
    pub rate: RateDesign<T>,
    /// Scales, weights, RLS limits, change detector.
    pub fit: Fit<T>,
}

impl<T: Real> Design<T> {
    /// The placeholder of an estimator that is not designed yet: every part is a
    /// constant (all zero; the configuration reads as [`Config::table2`]), so that a
    /// caller embedding it gets it written straight into its final place.
    #[inline(always)]
    pub fn blank() -> Self {
        Design {
            cfg: Config::table2(),
            units: Units::default(),
            watch: Watch::default(),
            replica: ReplicaCoeffs::default(),
            rows: RowDesign::default(),
            rate: RateDesign::default(),
            fit: Fit::default(),
        }
    }

    /// Designs in place from a configuration that passed [`Config::validate`]: each part
    /// is written straight into its field (the pattern names every field, so none can
    /// be left out).
    #[inline(always)]
    pub fn init(&mut self, cfg: &Config) {
        let omega0 = cfg.omega0_rad_s();
        let ts = omega0 / cfg.fs_hz; // sample period in τ
        let w_svf = 2.0 * core::f64::consts::PI * cfg.svf_hz / omega0;
        let wc = 2.0 * core::f64::consts::PI * cfg.lockin_lpf_hz / omega0;
        let Design {
            cfg: f_cfg,
            units,
            watch,
            replica,
            rows,
            rate,
            fit,
        } = self;
        *f_cfg = *cfg;
        *units = Units::of(cfg);
        *watch = Watch::of(cfg);
        let half_steps = cfg.pump_profile == PumpProfile::HalfSteps;
        *replica = ReplicaCoeffs::butterworth(cfg.lockin_lpf_order, wc, ts, half_steps);
        *rows = RowDesign::new(w_svf, ts);
        *rate = RateDesign::of(cfg);
        *fit = Fit::of(cfg);
        // the rate walk and its cap as variances of θ14, θ24 in their scaled units: a rate
        // of `dps` moves them by 2γ, γ = dps/to_dps; in `T` (an `f64` chain here cost
        // ≈ 250 B of soft-float calls in the firmware image). A zero scale gives +∞,
        // which `Rls::add_walk` refuses.
        let two_per_dps = T::from_f64(2.0) / rate.dps_per_gamma();
        let w = T::from_f64(cfg.rate.walk_dps) * two_per_dps;
        let c = T::from_f64(WALK_CAP_DPS) * two_per_dps;
        let (s1, s2) = (fit.sc1[3], fit.sc2[3]);
        fit.walk2 = (w / s2) * (w / s2);
        fit.drift_f1 = fit.sc2[DRIFT_COL] * T::from_f64(rows.inv_w);
        fit.walk_cap1 = (c / s1) * (c / s1);
        fit.walk_cap2 = (c / s2) * (c / s2);
    }
}
