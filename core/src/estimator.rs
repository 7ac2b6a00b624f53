//! The one `step()` per 500 Hz sample that ties the chain together:
//!
//! ```text
//! sample ─► check ─► replica LPF (ω, ω², ω′, s, ã) ─► projections ─► SVF bank ─► rows (5+5)
//!        ─► gate ─► Bierman UD RLS 8×8 + 6×6 ─► change detector ─► θ̂, ω̂y², γ̂, health
//!        ─► retune supervisor ─► pump scheduler (centre + dither) ─► next pump command
//! ```
//!
//! An [`Estimator`] is a **design** (`design`: built once from a [`ValidConfig`]; the
//! coefficients and derived constants of every stage, and the configuration) and a
//! **state** (`state`: filters, RLS, linearisation point, monitors, scheduler,
//! supervisor, counters), like `SvfCoeffs` + `SvfState` in [`crate::svf`]. `step()` reads
//! the design and changes the state, stage by stage (`step`).
//!
//! `step()` never fails, never panics and never allocates: bad input is flagged,
//! counted and skipped, and the estimate is held.
//!
//! Both parts are built **in place** ([`Estimator::blank`], [`Estimator::rebuild`]): a
//! caller that embeds the estimator (the firmware's `App`) never holds an
//! estimator-sized temporary on its stack.

mod design;
mod relin;
mod state;
mod step;
#[cfg(test)]
mod tests;

pub use state::MAX_CENTRE_DEV;

use crate::config::{Config, ConfigError, ValidConfig};
use crate::drift::DRIFT_COL;
use crate::physics::{Physical, physical_from_theta, rate_dps_from_gamma};
use crate::real::Real;
use crate::rows::{Known, NROWS, RowSet};
use design::Design;
pub(crate) use design::SETTLE_EVERY;
use state::State;

pub use crate::health::{Counters, Health};
pub use crate::output::{StepOutput, event};
pub use crate::sample::{Lockin, Sample};

/// What the temperature learner knows ([`Estimator::thermal`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThermalEstimate {
    /// Frequency temperature coefficients of the drive (ω_x) and sense (ω_y) modes,
    /// ppm/K (NaN until learned).
    pub tcf_ppm_k: [f64; 2],
    /// Their standard deviations, ppm/K.
    pub tcf_sigma_ppm_k: [f64; 2],
    /// The smoothed die temperature, °C.
    pub temp_c: f64,
    /// Its rate, K/s.
    pub rate_k_s: f64,
}

/// The estimator (runtime form of a validated [`Config`]): its design and its state.
#[derive(Clone, Debug)]
pub struct Estimator<T: Real> {
    design: Design<T>,
    state: State<T>,
}

impl Config {
    /// Validates and builds the runtime estimator in precision `T`.
    pub fn build<T: Real>(&self) -> Result<Estimator<T>, ConfigError> {
        Ok(self.validated()?.build())
    }
}

impl ValidConfig<'_> {
    /// Builds the runtime estimator in precision `T` (infallible: validated).
    #[inline(always)] // built in its caller's destination (stack, firmware/README.md)
    pub fn build<T: Real>(self) -> Estimator<T> {
        let mut e = Estimator::blank();
        e.rebuild(self);
        e
    }
}

impl<T: Real> Estimator<T> {
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
            design: Design::blank(),
            state: State::blank(),
        }
    }

    /// Rebuilds this estimator in place from a validated configuration (the same
    /// estimator [`Config::build`] returns, designed straight into `self`): the design
    /// first, then the start-up state from it.
    #[inline(never)] // the design's temporaries live in this frame only
    pub fn rebuild(&mut self, cfg: ValidConfig<'_>) {
        self.design.init(cfg.config());
        self.state.reset(&self.design);
    }

    /// The design and the state, for the crate's own extensions of the estimator
    /// (`persist`: the warm start) that live outside this module.
    pub(crate) fn parts_mut(&mut self) -> (&Design<T>, &mut State<T>) {
        (&self.design, &mut self.state)
    }

    /// The design, mutable (`persist`: a warm start's shorter start-up gate).
    pub(crate) fn design_mut(&mut self) -> &mut Design<T> {
        &mut self.design
    }

    /// Processes one 500 Hz sample. Never fails, never panics, never allocates.
    #[inline(never)]
    pub fn step(&mut self, s: &Sample<T>) -> StepOutput {
        self.state.step(&self.design, s)
    }

    /// Two pump steps per sample whose values the caller knows (`PumpProfile::HalfSteps`):
    /// the replica takes the next sample's interval as the linear sweep by `hz` that ends
    /// at that sample's pump (from `pump_hz − hz`), so that steps `a` then `b` are told as
    /// the sweep `1.5·a − 0.5·b` → `1.5·b − 0.5·a` whose half means they are: the sample's
    /// pump the latter, `hz = 2·(b − a)`. Without it the sweep starts at the pump the last
    /// sample was told. For the next step only; a non-finite `hz`, or a sample the input
    /// check refuses, leaves the sweep as it was.
    pub fn set_pump_sweep_hz(&mut self, hz: T) {
        self.state.pump_sweep_hz = hz;
    }

    /// The configuration this estimator was built from.
    pub fn config(&self) -> &Config {
        &self.design.cfg
    }

    // ---- commands

    /// Commands a new pump centre. `jump = true`: at once, with RLS gating for
    /// `gate_jump_s` and a covariance reset (FINDINGS §3.5); `false`: a raised-cosine
    /// ramp of `retune.ramp_s`.
    ///
    /// Refused, with nothing changed and `false` returned, unless the frequency is within
    /// ±50 % ([`MAX_CENTRE_DEV`]) of the configured centre (NaN and ±∞ included).
    pub fn command_pump_centre(&mut self, pump_hz: f64, jump: bool) -> bool {
        self.state.command_pump_centre(&self.design, pump_hz, jump)
    }

    /// Switches the pump-frequency dither on or off (tapered).
    pub fn set_dither(&mut self, on: bool) {
        self.state.sched.set_dither(on);
    }

    /// Changes the peak pump-frequency dither, Hz (e.g. to keep it a fixed fraction of a
    /// narrower parametric band). Refused (`false`, nothing changed) unless finite, ≥ 0
    /// and below 5 % of the pump.
    pub fn set_dither_pump_hz(&mut self, pump_hz: f64) -> bool {
        self.state.set_dither_pump_hz(&self.design, pump_hz)
    }

    /// Allows or forbids the retune supervisor.
    pub fn set_retune(&mut self, on: bool) {
        self.state.sup.enabled = on;
    }

    // ---- the pump

    /// Pump frequency to command before the first sample, Hz.
    pub fn initial_pump_hz(&self) -> f64 {
        self.pump_centre_hz()
    }

    /// Current pump centre (without dither), Hz.
    pub fn pump_centre_hz(&self) -> f64 {
        self.design.units.pump_hz_of(self.state.sched.centre())
    }

    // ---- the estimate and its health

    /// Health after the last step.
    pub fn health(&self) -> Health {
        self.state.health
    }

    /// Counters since start-up.
    pub fn counters(&self) -> Counters {
        self.state.counters
    }

    /// The drift of θ12 (drive) and θ22 (sense) that the drift tracker measures and
    /// follows, relative to each parameter's design value per second (ppm/s; module
    /// [`crate::drift`]); 0 where none stands out of the noise, and with the tracker off.
    pub fn drift_ppm_s(&self) -> [f64; 2] {
        let d = &self.design;
        let per_s = d.cfg.fs_hz * 1e6;
        [0, 1].map(|axis| self.state.drift.drift(&d.fit.drift, axis).to_f64() * per_s)
    }

    /// What the temperature learner knows (module [`crate::thermal`]): each mode's
    /// frequency temperature coefficient, ppm/K, with its standard deviation, and the
    /// smoothed die temperature and its rate. NaN where there is no temperature or the
    /// coefficient is not learned yet.
    pub fn thermal(&self) -> ThermalEstimate {
        let (d, th) = (&self.design, &self.state.thermal);
        // θ12 = −(ω_x² − γ² + 2β1), θ22 = −(ω_y² − γ²): dω²/dT = −sc·b
        let w2 = [self.physical().wx2, self.wy2()];
        let sc = [d.fit.sc1[DRIFT_COL].to_f64(), d.fit.sc2[DRIFT_COL].to_f64()];
        let per_k = |j: usize, v: f64| 0.5e6 * sc[j] * v / w2[j];
        let fit = |j: usize| {
            let f = &th.fit[j];
            if th.t_ref.is_some() && f.learned() {
                (
                    -per_k(j, f.b.to_f64()),
                    per_k(j, libm::sqrt(f.p[2].to_f64())),
                )
            } else {
                (f64::NAN, f64::NAN)
            }
        };
        let (c0, s0) = fit(0);
        let (c1, s1) = fit(1);
        ThermalEstimate {
            tcf_ppm_k: [c0, c1],
            tcf_sigma_ppm_k: [s0, s1],
            temp_c: th.level.map_or(f64::NAN, |t| t.to_f64()),
            rate_k_s: th
                .level
                .map_or(f64::NAN, |_| th.rate.to_f64() * d.cfg.fs_hz),
        }
    }

    /// The warm-start record's thermal part: the smoothed die temperature, and the
    /// learned dθ12/dT, dθ22/dT with their variances (NaN where unknown).
    pub(crate) fn thermal_record(&self) -> (f64, [f64; 2], [f64; 2]) {
        let f = &self.design.fit;
        let sc = [f.sc1[DRIFT_COL].to_f64(), f.sc2[DRIFT_COL].to_f64()];
        self.state.thermal.record(sc)
    }

    /// The rate's zero μxy (the cross-damping the rate subtracts, γ = −(θ24 + μxy)/2) and
    /// the settled updates in its mean, 0 while it follows the slow RLS: what a warm
    /// start restores (module `rate`, `RateState::hold_zero`).
    pub fn rate_zero(&self) -> (f64, f64) {
        self.state.rate.zero()
    }

    /// Samples processed.
    pub fn samples(&self) -> u64 {
        self.state.k
    }

    /// Times the linearisation point moved to the settled estimate.
    pub fn relinearizations(&self) -> u32 {
        self.state.lin.relins
    }

    /// The nominal θ the RLS linearises about.
    pub fn nominal_theta(&self) -> ([f64; 8], [f64; 6]) {
        (self.state.lin.th1n, self.state.lin.th2n)
    }

    /// The current estimate θ̂1 (8), θ̂2 (6) in eq. (25) order.
    pub fn theta(&self) -> ([f64; 8], [f64; 6]) {
        self.state.theta(&self.design)
    }

    /// The fast rate channel's output after the last step (rate, slow rate, quadrature,
    /// validity).
    pub fn rate_output(&self) -> crate::rate::RateOutput {
        self.state.rate.output(&self.design.rate)
    }

    /// The fast rate channel's last estimate (non-dimensional γ, quadrature).
    pub fn rate_estimate(&self) -> crate::rate::RateEstimate<T> {
        *self.state.rate.estimate()
    }

    /// 1-σ uncertainty of θ̂ relative to |θ_design| (the square roots of the diagonal of
    /// the column-scaled covariance; rows are weighted to unit noise, so P is the
    /// estimate's covariance when the configured row noise is right).
    pub fn theta_rel_sigma(&self) -> ([f64; 8], [f64; 6]) {
        let p1 = self.state.rls1.covariance();
        let p2 = self.state.rls2.covariance();
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

    /// Estimated angular rate, °/s: the slow one (γ of [`Estimator::theta`]); the fast
    /// rate channel's is [`Estimator::rate_output`].
    pub fn rate_dps(&self) -> f64 {
        rate_dps_from_gamma(self.physical().gamma, self.design.cfg.omega0_rad_s())
    }

    /// Estimated ω_y² (non-dimensional).
    pub fn wy2(&self) -> f64 {
        let (t1, t2) = self.theta();
        crate::physics::wy2_from_theta(&t1, &t2)
    }

    // ---- diagnostics

    /// The guard statistics of the two RLS (drive, sense): updates, forgetting skipped
    /// by the trace bound, samples held without forgetting (no excitation), resets.
    pub fn rls_stats(&self) -> (crate::rls::RlsStats, crate::rls::RlsStats) {
        (self.state.rls1.stats(), self.state.rls2.stats())
    }

    /// Traces of the (column-scaled) covariances (drive, sense).
    pub fn traces(&self) -> (f64, f64) {
        (
            self.state.rls1.trace().to_f64(),
            self.state.rls2.trace().to_f64(),
        )
    }

    /// Change-detector levels (drive, sense).
    pub fn detector_levels(&self) -> (f64, f64) {
        (self.state.det1.level(), self.state.det2.level())
    }

    /// The last sample's rows, unweighted and unscaled (`y = z − Φθ_nom`), for
    /// diagnostics and calibration.
    pub fn last_rows(&self) -> &RowSet<T> {
        &self.state.last_rows
    }

    /// The last sample's known signals after the replica low-pass (diagnostics).
    pub fn last_known(&self) -> &Known<T> {
        &self.state.last_known
    }

    /// Row weights (drive, sense) = 1/σ.
    pub fn row_weights(&self) -> ([T; NROWS], [T; NROWS]) {
        (self.design.fit.w1, self.design.fit.w2)
    }
}
