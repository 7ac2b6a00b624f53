//! Configuration in SI units, validated once by [`Config::validate`].
//!
//! Everything a person sets is here, with units in the names (Hz, s, µm, m/s², V).
//! `validate()` checks every field and returns a [`ConfigError`] naming the first bad
//! one; [`Config::validated`] gives the proof [`ValidConfig`] from which the estimator's
//! design is built (`Config::build`, `ValidConfig::build` and the design live with the
//! estimator, `crate::estimator`: this module knows nothing of it). After that, the
//! 500 Hz tick cannot fail.

use crate::physics::{F0_TABLE2_HZ, L0_TABLE2_UM, Physical, TABLE2};
use core::fmt;

/// How the pump generator moves between two 500 Hz commands. The replica of the lock-in
/// low-pass applied to the commanded pump must assume the same, or its output is off by
/// half a sample on every change.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PumpProfile {
    /// A linear sweep from one command to the next (DDS linear-sweep mode; the
    /// simulator's default): the replica is FOH-exact.
    #[default]
    Linear,
    /// Each command holds over the whole interval that ends at its sample (a DDS updated
    /// once per sample, at the sample instant): the replica is ZOH-exact.
    Staircase,
    /// The frequency moves in two steps per interval that are the linear sweep's means
    /// over its halves (the firmware's `App::set_half_steps`), the scale holds each
    /// command over the interval: the frequency's replica is exact for the two steps
    /// (`lpf::ReplicaChannel::update_pump`; the sweep's FOH replica left the rate +0.23 %
    /// after a retune), the scale's is ZOH.
    HalfSteps,
}

/// Pump-frequency dither (the excitation that makes all 14 parameters identifiable).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DitherConfig {
    /// Enabled at start-up (it can be switched at run time).
    pub enabled: bool,
    /// Peak deviation of the pump frequency 2Ω/2π, Hz (±1e-3 of ω0 on Ω ⇔ ±21.6 Hz).
    pub pump_hz: f64,
    /// Dither frequency, Hz (2–5 Hz, FINDINGS §3.3).
    pub freq_hz: f64,
    /// Time after start-up at which the dither begins, s.
    pub start_s: f64,
    /// Raised-cosine taper of the dither amplitude when it is switched on or off, s.
    pub taper_s: f64,
    /// Peak fractional modulation of the pump voltage scale s = (V/V0)² that runs with
    /// the frequency dither (0 disables). θ17 (β3) is told apart from θ15 and θ16 only by
    /// how the terms scale with amplitude and with s; ±10 % of s makes its error 3× smaller
    /// (core/docs/design-notes.md "Excitation"). Smooth (sinusoidal), never stepped: amplitude steps bias
    /// the rows (FINDINGS §3.2).
    pub scale_frac: f64,
    /// Frequency of the pump-scale modulation, Hz (incommensurate with `freq_hz`).
    pub scale_freq_hz: f64,
}

/// Recursive least squares settings (both axes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RlsConfig {
    /// Forgetting factor per 500 Hz sample (0.999 ⇔ 2 s memory). Applied only while the
    /// excitation is sufficient (`monitor.excitation_min_fraction`); once the dither has
    /// been seen, a sample without it is not forgotten over (λ = 1, `rls.rs` "Anti-windup").
    pub forgetting: f64,
    /// Initial covariance, in column-scaled units (relative variance of each θ).
    pub p0: f64,
    /// Covariance after a detected parameter change, scaled units.
    pub p_reset: f64,
    /// Anti-windup: forgetting stops while trace(P) exceeds this factor times the trace
    /// at the moment the estimate first settled (FINDINGS §4: 10×).
    pub trace_bound_factor: f64,
    /// Re-linearise about the current estimate every this many seconds while the RLS
    /// updates (0 disables): keeps the combined signals, and so the `f32` innovation,
    /// small when the design values are far from the device. Exact in exact arithmetic.
    pub relinearize_s: f64,
    /// Drift tracking (module `drift`): the natural-frequency terms θ12, θ22 walk with a
    /// variance of κ² times their measured drift per update squared, so that a warm-up is
    /// followed as a drift, not detected as a jump. 3 (the default) holds the lag a drift
    /// leaves at a third of the noise (module `drift`); 0 disables it.
    pub drift_kappa: f64,
    /// The measured drift's window, s: its EWMA has a fifth of it as time constant, its
    /// wander is learned over ten windows, and after a reset it waits two.
    pub drift_window_s: f64,
    /// The fastest drift followed as a drift, ppm/s of the parameter (ω_x², ω_y² move
    /// 2·TCF·dT/dt: 66 ppm/s at −33 ppm/K and 1 K/s); faster is a jump for the change
    /// detector.
    pub drift_max_ppm_s: f64,
    /// Temperature as an input (module `thermal`): the time constant, s, of the
    /// smoothing that gives the die temperature's rate from the samples' `temp_c`; each
    /// drift column's temperature coefficient is learned and the drift predicted from it.
    /// 0 ignores the temperature (the drift is then followed by the walk alone).
    pub tcf_tau_s: f64,
}

/// Input validation, gating and the change detector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MonitorConfig {
    /// No RLS updates for this long after start-up (the start-up transient biases the
    /// rows, FINDINGS §3.2), s.
    pub gate_startup_s: f64,
    /// No RLS updates for this long after a commanded pump jump, s (FINDINGS §3.5).
    pub gate_jump_s: f64,
    /// No RLS updates for this long after a bad input sample (the filters saw held
    /// values), s.
    pub bad_input_gate_s: f64,
    /// Change-detector threshold on the EWMA of the normalised squared innovations
    /// summed over one sample's rows (nominal level ≈ 5), FINDINGS §5: 1e3.
    pub change_threshold: f64,
    /// EWMA weight of the change detector per sample.
    pub change_alpha: f64,
    /// Minimum time between two covariance resets on one axis, s.
    pub change_hold_s: f64,
    /// An alarm whose level crosses `change_threshold` by at most this factor reads as a
    /// drift's lag on a settled estimate: the drift column alone is re-opened instead of
    /// a reset (`monitor::DRIFT_MARGIN`, 25, and why; `drift`, "A drift-like alarm"). 0:
    /// every alarm resets its axis.
    pub change_drift_margin: f64,
    /// Lock-in full scale: a channel at or beyond ±this is saturated, µm.
    pub full_scale_um: f64,
    /// Accelerometer full scale, m/s².
    pub accel_full_scale_mps2: f64,
    /// A lock-in channel that repeats the same value this many samples is stuck
    /// (0 disables; real data always carries noise).
    pub stuck_samples: u32,
    /// Excitation is sufficient when the rms of the filtered pump-frequency deviation
    /// is at least this fraction of the configured dither's rms. Below it (after it was
    /// once reached) the RLS holds its memory instead of forgetting.
    pub excitation_min_fraction: f64,
}

/// The retune supervisor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RetuneConfig {
    /// Retune allowed at start-up (switchable at run time).
    pub enabled: bool,
    /// Duration of the raised-cosine ramp of the pump centre, s.
    pub ramp_s: f64,
    /// Largest rate of the pump-centre ramp, Hz/s (the ramp is made longer if needed).
    pub max_rate_hz_per_s: f64,
    /// No retune for a pump-centre move smaller than this, Hz.
    pub deadband_hz: f64,
    /// Tracking: a move between this and `deadband_hz` is made at once as a short ramp
    /// (50 ms, `retune::TRACK_RAMP`, or longer for `max_rate_hz_per_s`), with no
    /// minimum interval, so that the pump follows a drifting ω̂y continuously within this
    /// of 2ω̂y, Hz. 0: no tracking (the centre moves only by retunes).
    pub track_hz: f64,
    /// The target stays this fraction of the drive's parametric band inside its edges.
    pub band_margin: f64,
    /// The estimate is settled when ω̂y² moved less than `settle_tol` (relative) over
    /// this window, s.
    pub settle_window_s: f64,
    /// Relative tolerance of the settle test.
    pub settle_tol: f64,
    /// Drive lock: |A1| at or above this, µm.
    pub lock_min_um: f64,
    /// Drive lock is lost after |A1| stayed below `lock_min_um` this long, s.
    pub lock_lost_s: f64,
    /// Minimum time between the end of one retune and the start of the next, s.
    pub min_interval_s: f64,
}

/// The fast rate channel (`crate::rate`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RateConfig {
    /// Corner of its wide-band state-variable filter (double real pole), Hz: the rate's
    /// −3 dB bandwidth is ≈ 0.64× this (times the lock-in low-pass). Below fs_hz (the
    /// FOH-exact filter is defined for any corner; above ≈ fs/3 it only adds noise).
    pub svf_hz: f64,
    /// Corner of the narrow channel's filter, Hz: the same row, narrower, whose rate
    /// acceleration gates the slow RLS and whose rate the slow RLS takes at the end of a
    /// transient (`rate`). At most `svf_hz`.
    pub coupling_hz: f64,
    /// Full scale: the rate is flagged invalid beyond it, °/s.
    pub full_scale_dps: f64,
    /// The slow RLS is gated while the rate accelerates faster than this (a step, a
    /// fast sine or chirp), °/s², and for `gate_s` after.
    pub gate_accel_dps2: f64,
    /// See `gate_accel_dps2`, s.
    pub gate_s: f64,
    /// … and while the narrow channel's rate differs from the slow RLS's by more than
    /// this, °/s (a slow move of the rate the slow RLS would otherwise chase).
    pub gate_dev_dps: f64,
    /// The slow RLS's rate term is a random walk of this standard deviation per sample,
    /// °/s: process noise on the sense θ24 (and, as the sense sees it move, on the drive
    /// θ14), so that a moving rate neither biases the other slow θ nor fires the change
    /// detector (host-sim/docs/rate-channel.md). 0: the rate is a constant of the slow RLS.
    pub walk_dps: f64,
    /// Memory of the rate's zero, s: the cross-damping μxy that the rate subtracts
    /// (γ = −(θ24 + μxy)/2) is the slow RLS's μ̂xy averaged since its last reset (a mean
    /// whose weight falls as 1/n down to 1/(this·fs_hz)), not its 2 s estimate: μxy does not
    /// move with temperature, and the slow estimate's wander would be the rate's
    /// low-frequency noise (`rate`). An hour (the default): a 1 h static run's bias
    /// instability is 10.8 °/h once the zero has settled, 17.3 °/h with 600 s
    /// (host-sim/README.md, "Rate-sensor datasheet"). 0: the slow RLS's μ̂xy every sample.
    pub zero_memory_s: f64,
}

/// The whole configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// Drive natural frequency that defines ω0 = 2π·f0 (the paper's time unit), Hz.
    pub f0_hz: f64,
    /// Sample rate of the lock-in outputs, Hz.
    pub fs_hz: f64,
    /// Length unit L0 of the non-dimensional model, µm (1 in the paper).
    pub l0_um: f64,
    /// Order of the lock-in's analog Butterworth low-pass.
    pub lockin_lpf_order: usize,
    /// Cut-off of the lock-in low-pass, Hz.
    pub lockin_lpf_hz: f64,
    /// Pump voltage amplitude V_A0 at which the nominal θ hold, V.
    pub pump_amp_ref_v: f64,
    /// How the pump generator moves between commands (sets the replica's hold).
    pub pump_profile: PumpProfile,
    /// Design (nominal) physical parameters, non-dimensional; the RLS runs on
    /// deviations from the θ they give, with columns scaled by |θ_nom|.
    pub nominal: Physical,
    /// Initial pump centre frequency 2Ω/2π, Hz.
    pub pump_centre_hz: f64,
    /// Pump-frequency dither.
    pub dither: DitherConfig,
    /// Corner of the slow state-variable filter, Hz (DERIVATION §4: 10 Hz, ζ = 1).
    pub svf_hz: f64,
    /// Displacement noise density of the front end, pm/√Hz; rows are weighted to unit
    /// noise by `row_sigma_* × noise_pm_rthz`.
    pub noise_pm_rthz: f64,
    /// Residual standard deviation of the drive rows per 1 pm/√Hz, non-dimensional, in
    /// row order (DC, 1st harmonic Re, Im, 3rd harmonic Re, Im).
    pub row_sigma_drive: [f64; 5],
    /// Same for the sense rows.
    pub row_sigma_sense: [f64; 5],
    /// RLS settings.
    pub rls: RlsConfig,
    /// Validation, gating and change detection.
    pub monitor: MonitorConfig,
    /// Retune supervisor.
    pub retune: RetuneConfig,
    /// The fast rate channel.
    pub rate: RateConfig,
}

/// 2·sqrt(ωy²)·f0 of Table 2, Hz: the pump at twice the sense resonance (a literal, the
/// test `the_table2_pump_centre_is_twice_the_sense_resonance` holds it to the bit).
pub const PUMP_CENTRE_TABLE2_HZ: f64 = 21883.952639786974;

/// [`Config::table2`].
const TABLE2_CONFIG: Config = Config {
    f0_hz: F0_TABLE2_HZ,
    fs_hz: 500.0,
    l0_um: L0_TABLE2_UM,
    lockin_lpf_order: 4,
    lockin_lpf_hz: 150.0,
    pump_amp_ref_v: 1.0,
    pump_profile: PumpProfile::Linear,
    nominal: Physical {
        gamma: 0.0,
        ..TABLE2
    },
    pump_centre_hz: PUMP_CENTRE_TABLE2_HZ,
    dither: DitherConfig {
        enabled: true,
        pump_hz: 2.0e-3 * F0_TABLE2_HZ,
        freq_hz: 5.0,
        start_s: 1.0,
        taper_s: 0.1,
        scale_frac: 0.1,
        scale_freq_hz: 1.3,
    },
    svf_hz: 10.0,
    noise_pm_rthz: 1.0,
    row_sigma_drive: DEFAULT_ROW_SIGMA_DRIVE,
    row_sigma_sense: DEFAULT_ROW_SIGMA_SENSE,
    rls: RlsConfig {
        forgetting: 0.999,
        p0: 1e4,
        p_reset: 1.0,
        trace_bound_factor: 10.0,
        relinearize_s: 0.1,
        drift_kappa: 3.0,
        drift_window_s: 1.0,
        drift_max_ppm_s: 100.0,
        tcf_tau_s: 2.0,
    },
    monitor: MonitorConfig {
        gate_startup_s: 0.5,
        gate_jump_s: 0.5,
        bad_input_gate_s: 0.2,
        change_threshold: 1e3,
        change_alpha: 0.05,
        change_hold_s: 0.05,
        change_drift_margin: crate::monitor::DRIFT_MARGIN,
        full_scale_um: 20.0,
        accel_full_scale_mps2: 400.0,
        stuck_samples: 50,
        excitation_min_fraction: 0.5,
    },
    retune: RetuneConfig {
        enabled: true,
        ramp_s: 0.5,
        max_rate_hz_per_s: 200.0,
        deadband_hz: 2.0,
        track_hz: 0.25,
        band_margin: 0.05,
        settle_window_s: 0.5,
        settle_tol: 2e-5,
        lock_min_um: 0.2,
        lock_lost_s: 0.05,
        min_interval_s: 1.0,
    },
    rate: RateConfig {
        svf_hz: 150.0,
        coupling_hz: 40.0,
        full_scale_dps: 1000.0,
        gate_accel_dps2: 2000.0,
        gate_s: 0.3,
        gate_dev_dps: 1.0,
        walk_dps: 0.3,
        zero_memory_s: 3600.0,
    },
};

impl Config {
    /// The paper's gyro (Table 2), 1 pm/√Hz front end, the recommended scheme of
    /// FINDINGS §6. The nominal parameters are Table 2 with zero rate.
    pub fn table2() -> Self {
        // a constant copied from one place in `.rodata` (built field by field with a
        // `libm` square root, the function held 748 B of the image)
        TABLE2_CONFIG
    }

    /// ω0 = 2π f0, rad/s.
    pub fn omega0_rad_s(&self) -> f64 {
        2.0 * core::f64::consts::PI * self.f0_hz
    }

    /// Checks every field; the error names the first bad one (in the order of the
    /// fields of [`Config`], section by section).
    #[inline(never)] // set-up only: its own frame, not inlined into App::new (flash, stack)
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.validate_front_end()?;
        self.validate_nominal()?;
        pos(self.pump_centre_hz, "pump_centre_hz")?;
        self.dither.validate(self.pump_centre_hz, self.fs_hz)?;
        self.validate_rows()?;
        self.rls.validate()?;
        self.monitor.validate()?;
        self.retune.validate()?;
        self.rate.validate(self.fs_hz)
    }

    /// f0, the sample rate, L0, the lock-in low-pass and the pump reference.
    #[inline]
    fn validate_front_end(&self) -> Result<(), ConfigError> {
        pos(self.f0_hz, "f0_hz")?;
        pos(self.fs_hz, "fs_hz")?;
        if self.fs_hz >= self.f0_hz {
            return Err(E::new("fs_hz", "must be well below the carrier f0_hz"));
        }
        pos(self.l0_um, "l0_um")?;
        if !(1..=crate::lpf::MAX_ORDER).contains(&self.lockin_lpf_order) {
            return Err(E::new("lockin_lpf_order", "must be 1..=8"));
        }
        pos(self.lockin_lpf_hz, "lockin_lpf_hz")?;
        if self.lockin_lpf_hz >= self.f0_hz {
            return Err(E::new("lockin_lpf_hz", "must be below the carrier f0_hz"));
        }
        pos(self.pump_amp_ref_v, "pump_amp_ref_v")
    }

    /// The design parameters: positive where the physics needs it, finite everywhere,
    /// and no zero θ component (the RLS columns are scaled by |θ_nom|).
    #[inline]
    fn validate_nominal(&self) -> Result<(), ConfigError> {
        let n = &self.nominal;
        for (v, f) in [
            (n.mu_x, "nominal.mu_x"),
            (n.mu_y, "nominal.mu_y"),
            (n.wx2, "nominal.wx2"),
            (n.wy2, "nominal.wy2"),
            (n.beta1, "nominal.beta1"),
        ] {
            pos(v, f)?;
        }
        for (v, f) in [
            (n.mu_xy, "nominal.mu_xy"),
            (n.wxy2, "nominal.wxy2"),
            (n.alpha_x, "nominal.alpha_x"),
            (n.alpha_y, "nominal.alpha_y"),
            (n.beta3, "nominal.beta3"),
            (n.gamma, "nominal.gamma"),
            (n.gamma_p, "nominal.gamma_p"),
            (n.c_ax, "nominal.c_ax"),
            (n.c_ay, "nominal.c_ay"),
        ] {
            if !v.is_finite() {
                return Err(E::new(f, "must be finite"));
            }
        }
        let (t1, t2) = crate::physics::theta_from_physical(n);
        if t1
            .iter()
            .chain(t2.iter())
            .any(|v| *v == 0.0 || !v.is_finite())
        {
            return Err(E::new(
                "nominal",
                "gives a zero θ component (columns are scaled by |θ_nom|): make mu_xy, wxy2, alpha_*, beta3 non-zero",
            ));
        }
        Ok(())
    }

    /// The slow filter corner, the noise density and the row noise.
    #[inline]
    fn validate_rows(&self) -> Result<(), ConfigError> {
        pos(self.svf_hz, "svf_hz")?;
        if self.svf_hz > self.fs_hz / 10.0 {
            return Err(E::new("svf_hz", "must be at most fs_hz/10"));
        }
        pos(self.noise_pm_rthz, "noise_pm_rthz")?;
        for (i, v) in self.row_sigma_drive.iter().enumerate() {
            pos(
                *v,
                [
                    "row_sigma_drive[0]",
                    "row_sigma_drive[1]",
                    "row_sigma_drive[2]",
                    "row_sigma_drive[3]",
                    "row_sigma_drive[4]",
                ][i],
            )?;
        }
        for (i, v) in self.row_sigma_sense.iter().enumerate() {
            pos(
                *v,
                [
                    "row_sigma_sense[0]",
                    "row_sigma_sense[1]",
                    "row_sigma_sense[2]",
                    "row_sigma_sense[3]",
                    "row_sigma_sense[4]",
                ][i],
            )?;
        }
        Ok(())
    }

    /// Validates, giving the proof that `ValidConfig::build` needs: a caller that embeds
    /// the estimator in a larger value (the firmware's `App`) builds it straight into
    /// place instead of moving it out of a `Result` (≈ 5 KB of stack on the chip).
    pub fn validated(&self) -> Result<ValidConfig<'_>, ConfigError> {
        self.validate()?;
        Ok(ValidConfig(self))
    }

    /// The pump frequency the estimator commands before its first sample, Hz
    /// (= [`crate::Estimator::initial_pump_hz`], without building one).
    pub fn initial_pump_hz(&self) -> f64 {
        let om_ref = self.pump_centre_hz / (2.0 * self.f0_hz);
        // the estimator's `pump_hz_of(0.0)`: reference + 2 f0 · 0
        2.0 * self.f0_hz * om_ref + 2.0 * self.f0_hz * 0.0
    }
}

/// A configuration that passed [`Config::validate`] (from [`Config::validated`]).
#[derive(Clone, Copy, Debug)]
pub struct ValidConfig<'a>(&'a Config);

impl ValidConfig<'_> {
    /// The configuration.
    pub fn config(&self) -> &Config {
        self.0
    }
}

impl DitherConfig {
    /// Checks the dither against the pump centre and the sample rate.
    #[inline]
    fn validate(&self, pump_centre_hz: f64, fs_hz: f64) -> Result<(), ConfigError> {
        let d = self;
        nonneg(d.pump_hz, "dither.pump_hz")?;
        if d.pump_hz >= 0.05 * pump_centre_hz {
            return Err(E::new(
                "dither.pump_hz",
                "must be below 5 % of the pump centre",
            ));
        }
        pos(d.freq_hz, "dither.freq_hz")?;
        if d.freq_hz > fs_hz / 20.0 {
            return Err(E::new("dither.freq_hz", "must be slow: at most fs_hz/20"));
        }
        nonneg(d.start_s, "dither.start_s")?;
        nonneg(d.taper_s, "dither.taper_s")?;
        if !(d.scale_frac.is_finite() && (0.0..=0.3).contains(&d.scale_frac)) {
            return Err(E::new("dither.scale_frac", "must be in [0, 0.3]"));
        }
        pos(d.scale_freq_hz, "dither.scale_freq_hz")?;
        if d.scale_freq_hz > fs_hz / 20.0 {
            return Err(E::new(
                "dither.scale_freq_hz",
                "must be slow: at most fs_hz/20",
            ));
        }
        Ok(())
    }
}

impl RlsConfig {
    #[inline]
    fn validate(&self) -> Result<(), ConfigError> {
        let r = self;
        if !(r.forgetting > 0.0 && r.forgetting <= 1.0) {
            return Err(E::new("rls.forgetting", "must be in (0, 1]"));
        }
        pos(r.p0, "rls.p0")?;
        pos(r.p_reset, "rls.p_reset")?;
        if !(r.trace_bound_factor.is_finite() && r.trace_bound_factor >= 1.0) {
            return Err(E::new("rls.trace_bound_factor", "must be finite and >= 1"));
        }
        nonneg(r.relinearize_s, "rls.relinearize_s")?;
        nonneg(r.drift_kappa, "rls.drift_kappa")?;
        pos(r.drift_window_s, "rls.drift_window_s")?;
        pos(r.drift_max_ppm_s, "rls.drift_max_ppm_s")?;
        nonneg(r.tcf_tau_s, "rls.tcf_tau_s")
    }
}

impl MonitorConfig {
    #[inline]
    fn validate(&self) -> Result<(), ConfigError> {
        let m = self;
        nonneg(m.gate_startup_s, "monitor.gate_startup_s")?;
        nonneg(m.gate_jump_s, "monitor.gate_jump_s")?;
        nonneg(m.bad_input_gate_s, "monitor.bad_input_gate_s")?;
        pos(m.change_threshold, "monitor.change_threshold")?;
        if !(m.change_alpha > 0.0 && m.change_alpha <= 1.0) {
            return Err(E::new("monitor.change_alpha", "must be in (0, 1]"));
        }
        nonneg(m.change_hold_s, "monitor.change_hold_s")?;
        nonneg(m.change_drift_margin, "monitor.change_drift_margin")?;
        pos(m.full_scale_um, "monitor.full_scale_um")?;
        pos(m.accel_full_scale_mps2, "monitor.accel_full_scale_mps2")?;
        nonneg(m.excitation_min_fraction, "monitor.excitation_min_fraction")
    }
}

impl RetuneConfig {
    #[inline]
    fn validate(&self) -> Result<(), ConfigError> {
        let t = self;
        pos(t.ramp_s, "retune.ramp_s")?;
        pos(t.max_rate_hz_per_s, "retune.max_rate_hz_per_s")?;
        nonneg(t.deadband_hz, "retune.deadband_hz")?;
        nonneg(t.track_hz, "retune.track_hz")?;
        if t.track_hz > t.deadband_hz {
            return Err(E::new(
                "retune.track_hz",
                "must be at most retune.deadband_hz",
            ));
        }
        if !(t.band_margin >= 0.0 && t.band_margin < 0.5) {
            return Err(E::new("retune.band_margin", "must be in [0, 0.5)"));
        }
        pos(t.settle_window_s, "retune.settle_window_s")?;
        pos(t.settle_tol, "retune.settle_tol")?;
        nonneg(t.lock_min_um, "retune.lock_min_um")?;
        nonneg(t.lock_lost_s, "retune.lock_lost_s")?;
        nonneg(t.min_interval_s, "retune.min_interval_s")
    }
}

impl RateConfig {
    #[inline]
    fn validate(&self, fs_hz: f64) -> Result<(), ConfigError> {
        pos(self.svf_hz, "rate.svf_hz")?;
        if self.svf_hz >= fs_hz {
            return Err(E::new("rate.svf_hz", "must be below fs_hz"));
        }
        pos(self.coupling_hz, "rate.coupling_hz")?;
        if self.coupling_hz > self.svf_hz {
            return Err(E::new("rate.coupling_hz", "must be at most rate.svf_hz"));
        }
        pos(self.full_scale_dps, "rate.full_scale_dps")?;
        pos(self.gate_accel_dps2, "rate.gate_accel_dps2")?;
        nonneg(self.gate_s, "rate.gate_s")?;
        pos(self.gate_dev_dps, "rate.gate_dev_dps")?;
        nonneg(self.walk_dps, "rate.walk_dps")?;
        nonneg(self.zero_memory_s, "rate.zero_memory_s")
    }
}

use ConfigError as E;

// The checks are out-of-line functions, not closures inlined at every call (each
// inlined f64 test was ~100 bytes of soft-float calls in the firmware image).
#[inline(never)]
fn pos(v: f64, f: &'static str) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(E::new(f, "must be finite and > 0"))
    }
}

#[inline(never)]
fn nonneg(v: f64, f: &'static str) -> Result<(), ConfigError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(E::new(f, "must be finite and >= 0"))
    }
}

impl Default for Config {
    fn default() -> Self {
        Self::table2()
    }
}

/// Residual std of the drive rows at 1 pm/√Hz (DC, h1 Re, h1 Im, h3 Re, h3 Im),
/// measured with the true θ on the simulator's `identify` scenario at 512 RK4 steps per
/// carrier period (so that the integrator's own error does not count as noise):
/// `paragyro-sim calibrate identify --steps-per-period 512`.
pub const DEFAULT_ROW_SIGMA_DRIVE: [f64; 5] = [3.42e-6, 1.78e-7, 8.61e-8, 3.30e-5, 3.22e-5];
/// Same for the sense rows.
pub const DEFAULT_ROW_SIGMA_SENSE: [f64; 5] = [3.17e-6, 1.82e-8, 2.75e-8, 3.00e-5, 3.05e-5];

/// A configuration field that failed validation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConfigError {
    /// The field, as written in [`Config`] (e.g. `"rls.forgetting"`).
    pub field: &'static str,
    /// What is wrong with it.
    pub reason: &'static str,
}

impl ConfigError {
    const fn new(field: &'static str, reason: &'static str) -> Self {
        ConfigError { field, reason }
    }
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "invalid configuration field `{}`: {}",
            self.field, self.reason
        )
    }
}

#[cfg(test)]
mod tests;
