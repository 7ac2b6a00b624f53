//! Temperature as an input: each mode's temperature coefficient learned online and the
//! drift predicted from it.
//!
//! When the samples carry a die temperature ([`crate::Sample::temp_c`]), the natural
//! frequencies' drift is not only something the rows reveal after the fact (module
//! [`crate::drift`]): it is the learned coefficient times the temperature's rate.
//! Per block of [`ThermalDesign::every`] samples (0.1 s):
//!
//! * **The temperature and its rate.** The block's mean temperature goes through Brown's double
//!   exponential smoothing (time constant `rls.tcf_tau_s`, 2 s): a level without lag on a
//!   ramp and the ramp's rate (which lags a ramp's start or end by about τ: the walk
//!   covers that, below). The block's mean is the temperature reported and recorded.
//! * **The coefficient.** For each drift column (θ12 on the drive, θ22 on the sense, in
//!   the RLS's scaled units, `z` = the estimate advanced over the row filter's delay)
//!   a two-state Kalman filter fits `z = a + b·(T − T_ref)`: the intercept `a` walks
//!   slowly (ageing, hysteresis; a covariance reset makes it uncertain again: a jump is
//!   not a temperature effect), the slope `b` is a constant with a prior of
//!   ±2e-4 /K (≈ ±100 ppm/K in frequency). The estimate's errors are correlated over the
//!   slow RLS's memory, so a block counts as `n_corr` times its variance (the memory in
//!   blocks), and that variance is the larger of the RLS's own and the residuals' mean
//!   square (while the die is steady), plus (b² + the slope's prior variance) times the
//!   block temperature's own (errors in variables: the sensor's noise at a constant
//!   temperature teaches no slope). A residual beyond 10 σ (a jump the detector has not
//!   yet reset) is not taken. Blocks are taken only from a settled estimate two drift
//!   windows after a reset (the same rule as the measured drift).
//! * **The prediction.** Once a slope stands four of its standard deviations out of zero
//!   over a [`LEARNED_SPAN_K`] span it is learned: the drift column moves by `b·Ṫ` per
//!   update (a Kalman filter's time update with a known input,
//!   [`crate::rls::Rls::nudge`]), the lead over the row filter's delay includes it, and the
//!   walk takes the prediction's uncertainty, `σ_b²·Ṫ²` and [`PREDICTED_REL_ERR`] of it, on
//!   top of what is still measured. With the slope right, the corrections the rows make
//!   carry no drift, the measured drift is zero, and the slow RLS keeps its whole memory
//!   through a ramp. Before it is learned, nothing is predicted but the walk takes
//!   `SLOPE_PRIOR²·Ṫ²`: a warm-up's first ramp is followed from the temperature's first
//!   rate on, where the measured drift alone stands out too late (the change detector
//!   fires 0.13 s into a 0.5 K/s ramp, and its resets cascade).
//!
//! Without a temperature (a `None` or non-finite sample, or a value outside
//! [`TEMP_MIN_C`]…[`TEMP_MAX_C`]) nothing is predicted: the drift is followed by the
//! walk alone. The learned slopes, their variances and the temperature they refer to go
//! into the warm-start record ([`crate::persist`]), so a restart at another temperature
//! starts from θ(T).

use crate::real::Real;

/// Lowest plausible die temperature, °C; a colder reading is not taken.
pub const TEMP_MIN_C: f64 = -60.0;
/// Highest plausible die temperature, °C.
pub const TEMP_MAX_C: f64 = 150.0;
/// A slope counts as learned once `|b|` exceeds this many of its standard deviations
/// and the temperatures it was fitted over span [`LEARNED_SPAN_K`].
pub const LEARNED_SIGMAS: f64 = 4.0;
/// The temperature span a slope must have been fitted over to count as learned, K: the
/// estimate's wander over a sensor's noise (0.01 K a block) is not a slope.
pub const LEARNED_SPAN_K: f64 = 1.0;
/// The predicted drift's relative error beyond the slope's own uncertainty (the
/// temperature's rate, the sensor's lag behind the resonator's die): the walk takes
/// its square on top.
pub const PREDICTED_REL_ERR: f64 = 1.0;
/// Blocks of the temperature noise's running mean before it is an EWMA.
pub const VAR_T_BLOCKS: u32 = 20;
/// The floor of the temperature noise's variance, K²: a code of the ADXL355 (0.11 K)
/// squared over 12 (a quantised, otherwise noiseless reading is not exact).
pub const VAR_T_MIN: f64 = 0.0011;
/// Below this temperature rate, K/s, the die is steady: the fits' residuals then measure
/// the estimate's own wander (while it moves they carry a slope still being learned).
pub const STEADY_K_S: f64 = 0.002;
/// Consecutive outlier blocks after which a fit restarts from the slope's prior.
pub const REFUSED_MAX: u32 = 20;
/// Prior standard deviation of a slope, scaled units per K (θ12, θ22 relative to their
/// design values: 2e-4 /K is ≈ 100 ppm/K of frequency).
pub const SLOPE_PRIOR: f64 = 2e-4;

/// The design of the temperature learner (from `rls.tcf_tau_s`, `rls.forgetting`).
#[derive(Clone, Copy, Debug, Default)]
pub struct ThermalDesign<T> {
    /// Samples per block (0.1 s); 0 disables the learner.
    pub every: u32,
    /// Brown's smoothing weight per block (block / τ).
    pub alpha: T,
    /// The slow RLS's memory in blocks: the correlation length of its estimate.
    pub n_corr: T,
    /// 1 / `every` (K per block to K per update).
    pub per_update: T,
    /// The intercept's walk per block, as a fraction of a block's variance.
    pub q_a: T,
    /// [`STEADY_K_S`] per block.
    pub steady_per_block: T,
}

impl<T: Real> ThermalDesign<T> {
    /// From the smoothing time constant (0 disables), the sample rate and the RLS's
    /// forgetting factor.
    pub fn new(tau_s: f64, fs_hz: f64, forgetting: f64) -> Self {
        let every = libm::round(0.1 * fs_hz);
        if !(tau_s > 0.0 && (1.0..1e6).contains(&every)) {
            return ThermalDesign::default();
        }
        let block_s = every / fs_hz;
        let memory = if forgetting < 1.0 {
            1.0 / (1.0 - forgetting)
        } else {
            10.0 * fs_hz
        };
        ThermalDesign {
            every: every as u32,
            alpha: T::from_f64((block_s / tau_s).min(1.0)),
            n_corr: T::from_f64((memory / every).max(1.0)),
            per_update: T::from_f64(1.0 / every),
            // the intercept's own memory ≈ 600 blocks (a minute): √(R/q)
            q_a: T::from_f64(1.0 / (600.0 * 600.0)),
            steady_per_block: T::from_f64(STEADY_K_S * block_s),
        }
    }

    /// The learner runs.
    pub fn enabled(&self) -> bool {
        self.every > 0
    }
}

/// One drift column's fit `z = a + b·(T − T_ref)` and its covariance.
#[derive(Clone, Copy, Debug, Default)]
pub struct SlopeFit<T> {
    /// Intercept (scaled units, the learner's frame).
    pub a: T,
    /// Slope, scaled units per K.
    pub b: T,
    /// Covariance [P_aa, P_ab, P_bb].
    pub p: [T; 3],
    /// Mean square of the residuals after each update (scaled units²): the estimate's
    /// wander about the line, a floor of the block's variance.
    pub r2: T,
    /// The lowest and highest T − T_ref taken.
    pub span: [T; 2],
    /// The intercept starts again from the next block (at the start, after a jump).
    pub fresh: bool,
    /// Consecutive blocks refused as outliers.
    pub refused: u32,
}

impl<T: Real> SlopeFit<T> {
    /// Prior: the slope `b` with variance `p_b`; the intercept is set by the first
    /// block taken.
    pub fn start(b: T, p_b: T) -> Self {
        SlopeFit {
            a: T::ZERO,
            b,
            p: [T::ZERO, T::ZERO, p_b],
            r2: T::ZERO,
            span: [T::ZERO; 2],
            fresh: true,
            refused: 0,
        }
    }

    /// The slope stands [`LEARNED_SIGMAS`] out of zero, over [`LEARNED_SPAN_K`].
    pub fn learned(&self) -> bool {
        let n = T::from_f64(LEARNED_SIGMAS);
        self.b * self.b > n * n * self.p[2]
            && self.span[1] - self.span[0] >= T::from_f64(LEARNED_SPAN_K)
    }

    /// Takes `z` at `dt` = T − T_ref with the estimate's own variance `p_z` (scaled
    /// units²) and the block temperature's variance `var_t` (K²; a noisy temperature
    /// adds (b² + P_bb)·var_t to the block's variance, so that the sensor's noise at a
    /// constant temperature teaches no slope). Returns false (nothing changed) for a
    /// residual beyond 10 σ; [`REFUSED_MAX`] refusals in a row restart the fit from the
    /// slope's prior (a fit that refuses everything has stopped learning).
    pub fn take(
        &mut self,
        d: &ThermalDesign<T>,
        z: T,
        dt: T,
        p_z: T,
        (var_t, steady): (T, bool),
    ) -> bool {
        let [paa, pab, pbb] = self.p;
        let own = if self.r2 > p_z { self.r2 } else { p_z };
        // the noisy temperature's share, (b² + the slope's prior variance)·var_t: with the
        // slope's own P_bb instead it would shrink as P_bb does, and a fit at a nearly
        // constant temperature would grow sure of a slope from the sensor's noise
        let prior = T::from_f64(SLOPE_PRIOR * SLOPE_PRIOR);
        let r_var = d.n_corr * own + (self.b * self.b + prior) * var_t;
        if self.fresh {
            // the intercept given the slope: a = z − b·dt (its covariance with b exact)
            self.a = z - self.b * dt;
            self.p = [r_var + dt * dt * pbb, -dt * pbb, pbb];
            self.fresh = false;
            if self.span == [T::ZERO; 2] {
                self.span = [dt, dt];
            }
            return true;
        }
        // the intercept walks with the estimate's own variance (ageing), not with what the
        // residuals or the temperature's noise add
        let paa = paa + d.q_a * d.n_corr * p_z;
        let h0 = paa + dt * pab;
        let h1 = pab + dt * pbb;
        let s = h0 + dt * h1 + r_var;
        let r = z - self.a - self.b * dt;
        // a NaN fails both comparisons: refused
        let within = s > T::ZERO && r * r <= T::from_f64(100.0) * s;
        if !within {
            self.refused += 1;
            if self.refused >= REFUSED_MAX {
                let prior = T::from_f64(SLOPE_PRIOR * SLOPE_PRIOR);
                *self = SlopeFit {
                    span: self.span,
                    ..SlopeFit::start(self.b, if pbb > prior { pbb } else { prior })
                };
            }
            return false;
        }
        self.refused = 0;
        let (k0, k1) = (h0 / s, h1 / s);
        self.a += k0 * r;
        self.b += k1 * r;
        // Joseph's form, P = (I − KH) P (I − KH)ᵀ + K R Kᵀ: stays positive in f32 where
        // P − K H P loses it (the slope's prior is 1e6 times a block's variance)
        let (i00, i01, i10, i11) = (T::ONE - k0, -k0 * dt, -k1, T::ONE - k1 * dt);
        let (a00, a01) = (i00 * paa + i01 * pab, i00 * pab + i01 * pbb);
        let (a10, a11) = (i10 * paa + i11 * pab, i10 * pab + i11 * pbb);
        self.p = [
            a00 * i00 + a01 * i01 + k0 * k0 * r_var,
            a00 * i10 + a01 * i11 + k0 * k1 * r_var,
            a10 * i10 + a11 * i11 + k1 * k1 * r_var,
        ];
        self.span = [self.span[0].min(dt), self.span[1].max(dt)];
        // the residuals' mean square after the update while the die is steady, an EWMA
        // over 20 blocks
        if steady {
            let post = z - self.a - self.b * dt;
            self.r2 += T::from_f64(0.05) * (post * post - self.r2);
        }
        true
    }
}

/// The learner's state (module docs).
#[derive(Clone, Copy, Debug, Default)]
pub struct ThermalState<T> {
    /// Sum and count of this block's plausible temperatures.
    sum: T,
    n: u32,
    /// Samples left in this block.
    left: u32,
    /// Brown's two smoothings, and whether they started.
    s1: T,
    s2: T,
    started: bool,
    /// The smoothed temperature's rate, K per update (0 without a temperature).
    pub rate: T,
    /// The last block's mean temperature, °C (`None`: that block had none).
    pub level: Option<T>,
    /// The die temperature moves: the last block's smoothed rate is beyond the steady
    /// threshold ([`STEADY_K_S`]; false without a temperature).
    pub moving: bool,
    /// The block temperature's noise variance, K² (the mean square of its one-block
    /// forecast's error, an EWMA over [`VAR_T_BLOCKS`] blocks) and the blocks it has seen.
    pub var_t: T,
    var_n: u32,
    /// The temperature the fits refer to (`None` before the first taken block).
    pub t_ref: Option<T>,
    /// The fits of θ12 (drive) and θ22 (sense).
    pub fit: [SlopeFit<T>; 2],
    /// The learner's frame: θ_col = θ_col at the frame's origin + sc·(off + x); the
    /// re-linearisations move `x` by `-dx` and `off` by `+dx`.
    pub off: [T; 2],
}

impl<T: Real> ThermalState<T> {
    /// Counts one sample, every eighth's temperature into the block's mean (six a block:
    /// the die moves millikelvins in 0.1 s, the board's reading is refreshed at 10 Hz, and
    /// the tick's cost is a countdown); true at the end of a block (then call
    /// [`Self::block`]). A `None`, non-finite or implausible temperature is not taken (one
    /// comparison: |T − centre| within the window's half width).
    #[inline(always)]
    pub fn push(&mut self, d: &ThermalDesign<T>, temp_c: Option<T>) -> bool {
        if self.left & 7 == 0
            && let Some(t) = temp_c
        {
            let centre = T::from_f64(0.5 * (TEMP_MIN_C + TEMP_MAX_C));
            // NaN fails the comparison
            if (t - centre).abs() <= T::from_f64(0.5 * (TEMP_MAX_C - TEMP_MIN_C)) {
                self.sum += t;
                self.n += 1;
            }
        }
        if self.left > 1 {
            self.left -= 1;
            return false;
        }
        self.left = d.every;
        d.every > 0
    }

    /// The block's end: its mean temperature and the smoothed rate; with `learn`, each
    /// column takes `z` (its estimate in the learner's frame, advanced over the row
    /// filter's delay) with variance `p_z`. Returns the block's temperature (`None` where
    /// it had none: then no rate, and nothing predicted).
    pub fn block(
        &mut self,
        d: &ThermalDesign<T>,
        z: [T; 2],
        p_z: [T; 2],
        learn: bool,
    ) -> Option<T> {
        let (sum, n) = (core::mem::take(&mut self.sum), core::mem::take(&mut self.n));
        if n == 0 {
            self.rate = T::ZERO;
            self.level = None;
            self.moving = false;
            return None;
        }
        // the block's mean, referred to its end (where `z` is taken) with the rate so far
        let lag = d.alpha / (T::ONE - d.alpha) * (self.s1 - self.s2) * T::from_f64(0.5);
        let tb = sum / T::ratio(u64::from(n), 1) + lag;
        if self.started {
            // Brown's one-block forecast, and its error's mean square
            let e = tb
                - (T::from_f64(2.0) * self.s1 - self.s2)
                - d.alpha / (T::ONE - d.alpha) * (self.s1 - self.s2);
            let (e2, var) = (e * e, self.var_t.max(T::from_f64(VAR_T_MIN)));
            // the noise's mean square: a running mean over the first blocks, then an EWMA
            // of the errors within 2σ (the lag at a ramp's start or end is not noise)
            let settled = self.var_n >= VAR_T_BLOCKS;
            self.var_n = self.var_n.saturating_add(1);
            if !settled || e2 <= T::from_f64(4.0) * var {
                let w = T::ONE / T::ratio(u64::from(self.var_n.min(VAR_T_BLOCKS)), 1);
                self.var_t += w * (e2 - self.var_t);
            }
            self.s1 += d.alpha * (tb - self.s1);
            self.s2 += d.alpha * (self.s1 - self.s2);
        } else {
            (self.s1, self.s2, self.started) = (tb, tb, true);
        }
        let per_block = d.alpha / (T::ONE - d.alpha) * (self.s1 - self.s2);
        self.rate = per_block * d.per_update;
        // Brown's level overshoots a ramp's end for a few τ: the temperature reported (and
        // written into a warm-start record) is the block's own
        self.level = Some(tb);
        let steady = per_block.abs() < d.steady_per_block;
        self.moving = !steady;
        if learn {
            match self.t_ref {
                None => {
                    self.t_ref = Some(tb);
                    let p_b = T::from_f64(SLOPE_PRIOR * SLOPE_PRIOR);
                    self.fit = [SlopeFit::start(T::ZERO, p_b); 2];
                    for j in 0..2 {
                        self.fit[j].take(d, z[j], T::ZERO, p_z[j], (self.var_t, steady));
                    }
                }
                Some(t0) => {
                    // against the reading, not the smoothed level: that lags a ramp's start
                    // by about τ, and a reading's noise (≈ 0.06 K) is small against any
                    // span the slope is learned from (its variance is in the block's)
                    for j in 0..2 {
                        self.fit[j].take(d, z[j], tb - t0, p_z[j], (self.var_t, steady));
                    }
                }
            }
        }
        Some(tb)
    }

    /// The predicted drift of column `axis` per update and its variance (0 until the
    /// slope is learned).
    pub fn predicted(&self, axis: usize) -> (T, T) {
        match self.fit.get(axis) {
            Some(f) if self.t_ref.is_some() && f.learned() => {
                let v = f.b * self.rate;
                let eps = T::from_f64(PREDICTED_REL_ERR);
                (v, f.p[2] * self.rate * self.rate + eps * eps * v * v)
            }
            // not learned yet: nothing predicted, but a moving temperature moves the column
            // by an unknown b·Ṫ, b within the slope's prior: the walk takes that variance
            // (a warm-up's first ramp is followed from the temperature's first rate on)
            // (once the smoothing has seen VAR_T_BLOCKS blocks: its first rates are noise)
            _ if self.var_n >= VAR_T_BLOCKS => {
                let prior = T::from_f64(SLOPE_PRIOR * SLOPE_PRIOR);
                (T::ZERO, prior * self.rate * self.rate)
            }
            _ => (T::ZERO, T::ZERO),
        }
    }

    /// A warm start at `temp_c` with the stored coefficients `slope` (θ per K) and their
    /// variances, `sc` the columns' scales: the slopes are learned from the first block
    /// on, referred to `temp_c`, their intercepts set by the first block taken. Nothing
    /// is restored without a finite temperature and finite coefficients.
    pub fn restore(&mut self, temp_c: Option<f64>, slope: [f64; 2], var: [f64; 2], sc: [f64; 2]) {
        let Some(t) = temp_c.filter(|t| (TEMP_MIN_C..=TEMP_MAX_C).contains(t)) else {
            return;
        };
        let finite = slope.iter().chain(&var).chain(&sc).all(|v| v.is_finite());
        if !finite || sc.iter().any(|s| *s <= 0.0) {
            return;
        }
        self.t_ref = Some(T::from_f64(t));
        for j in 0..2 {
            self.fit[j] = SlopeFit {
                span: [T::from_f64(-LEARNED_SPAN_K), T::ZERO],
                ..SlopeFit::start(
                    T::from_f64(slope[j] / sc[j]),
                    T::from_f64(var[j] / (sc[j] * sc[j])),
                )
            };
        }
    }

    /// What a warm-start record keeps: the smoothed temperature (NaN: none), and each
    /// learned slope in θ per K with its variance (NaN where not learned), `sc` the
    /// columns' scales.
    pub fn record(&self, sc: [f64; 2]) -> (f64, [f64; 2], [f64; 2]) {
        let temp = self.level.map_or(f64::NAN, |t| t.to_f64());
        let mut slope = [f64::NAN; 2];
        let mut var = [f64::NAN; 2];
        for j in 0..2 {
            let f = &self.fit[j];
            if self.t_ref.is_some() && f.learned() {
                slope[j] = f.b.to_f64() * sc[j];
                var[j] = f.p[2].to_f64() * sc[j] * sc[j];
            }
        }
        (temp, slope, var)
    }

    /// A covariance reset of `axis` (a jump): the intercept is unknown again, the slope
    /// is kept.
    pub fn jumped(&mut self, axis: usize) {
        if let Some(f) = self.fit.get_mut(axis) {
            f.fresh = true;
        }
    }

    /// A re-linearisation moved the drift columns' estimates by `-dx`.
    pub fn rebase(&mut self, dx: [T; 2]) {
        self.off[0] += dx[0];
        self.off[1] += dx[1];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn design() -> ThermalDesign<f64> {
        ThermalDesign::new(2.0, 500.0, 0.999)
    }

    #[test]
    fn the_design_follows_the_rate_and_the_memory() {
        let d = design();
        assert_eq!(d.every, 50);
        assert!((d.alpha - 0.05).abs() < 1e-12);
        assert!((d.n_corr - 20.0).abs() < 1e-9);
        assert!(!ThermalDesign::<f64>::new(0.0, 500.0, 0.999).enabled());
        assert!(!ThermalDesign::<f64>::new(f64::NAN, 500.0, 0.999).enabled());
    }

    /// A ramp of temperature (0.5 K/s from 25 °C after 2 s, sensor noise and 0.11 K
    /// codes) and a column that follows it at `slope` per K with a little noise.
    fn run(slope: f64, seconds: f64, temp: bool) -> ThermalState<f64> {
        run_ramp(slope, seconds, temp, 0.5, 1e-14)
    }

    /// [`run`] at `k_per_s` with the estimate's variance `p_z`.
    fn run_ramp(slope: f64, seconds: f64, temp: bool, k_per_s: f64, p_z: f64) -> ThermalState<f64> {
        let d = design();
        let mut s = ThermalState::default();
        let mut seed = 12345u64;
        let mut noise = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let n = (seconds * 500.0) as usize;
        for k in 0..n {
            let t_s = k as f64 / 500.0;
            let truth = 25.0 + k_per_s * (t_s - 2.0).max(0.0);
            let read = libm::round((truth + 0.2 * noise()) * 9.05) / 9.05;
            if s.push(&d, temp.then_some(read)) {
                // the estimate's wander (the dither's 1.3 Hz corrections) and its noise
                let wander = 1e-6 * libm::sin(core::f64::consts::TAU * 1.3 * t_s);
                let z = slope * (truth - 25.0) + wander + 2e-7 * noise();
                s.block(&d, [z, -z], [p_z, p_z], t_s > 0.5);
            }
        }
        s
    }

    #[test]
    fn a_ramp_teaches_the_slope_and_predicts_the_drift() {
        let slope = -6.6e-5;
        let s = run(slope, 22.0, true);
        for (j, sign) in [(0, 1.0), (1, -1.0)] {
            let f = &s.fit[j];
            assert!(f.learned(), "{j}: {f:?}");
            assert!(
                (f.b - sign * slope).abs() < 0.02 * slope.abs(),
                "{j}: {}",
                f.b
            );
            // 0.5 K/s: the drift per update is b·Ṫ/500
            let (v, var) = s.predicted(j);
            let want = sign * slope * 0.5 / 500.0;
            assert!((v - want).abs() < 0.05 * want.abs(), "{j}: {v} vs {want}");
            // its uncertainty: the slope's (small by now) and PREDICTED_REL_ERR of it
            let floor = PREDICTED_REL_ERR * v.abs();
            assert!(var.sqrt() >= floor && var.sqrt() < 1.01 * floor, "{var:e}");
        }
    }

    #[test]
    fn a_slow_small_ramp_teaches_the_slope_of_a_precise_estimate() {
        // 2 K over 300 s, the sense's precision (σ 1e-8 a sample): the sensor's noise in
        // the first, nearly constant, seconds must not make the fit sure of a slope
        let s = run_ramp(-6.6e-5, 302.0, true, 2.0 / 300.0, 1e-16);
        for (j, sign) in [(0, 1.0), (1, -1.0)] {
            let b = s.fit[j].b;
            assert!(s.fit[j].learned(), "{j}");
            assert!((b - sign * -6.6e-5).abs() < 0.03 * 6.6e-5, "{j}: {b}");
        }
    }

    #[test]
    fn a_constant_temperature_learns_no_slope_and_predicts_nothing() {
        // the sensor's noise against the estimate's wander: no slope to learn
        let d = design();
        let mut s = ThermalState::default();
        for k in 0..20_000 {
            let t_s = k as f64 / 500.0;
            let read = libm::round((25.0 + 0.1 * ((k * 7919 % 13) as f64 / 6.0 - 1.0)) * 9.05);
            if s.push(&d, Some(read / 9.05)) {
                let z = 1e-6 * libm::sin(core::f64::consts::TAU * 1.3 * t_s);
                s.block(&d, [z, 2.0 * z], [1e-14, 1e-14], true);
            }
        }
        assert!(!s.fit[0].learned() && !s.fit[1].learned());
        // nothing predicted; the walk's share of the prior for a rate that is noise
        // (within 0.01 K/s) stays below 1e-13 a sample: 0.05 ppm/s
        let (v, var) = s.predicted(1);
        assert_eq!(v, 0.0);
        let bound = SLOPE_PRIOR * 0.01 / 500.0;
        assert!(var <= bound * bound, "{var:e}");
    }

    #[test]
    fn before_its_slope_is_learned_a_moving_temperature_opens_the_walk() {
        // 1.3 s into a 0.5 K/s ramp (0.65 K: no slope yet; the smoothing has seen its 20
        // blocks): nothing predicted, the walk at the prior's share of the rate
        let s = run(-6.6e-5, 3.3, true);
        assert!(!s.fit[1].learned());
        let (v, var) = s.predicted(1);
        assert_eq!(v, 0.0);
        let want = SLOPE_PRIOR * s.rate;
        assert!(s.rate > 0.05 / 500.0, "{}", s.rate * 500.0);
        assert!(
            (var.sqrt() - want.abs()).abs() < 1e-6 * want.abs(),
            "{var:e}"
        );
        // without a temperature, nothing
        let s = run(-6.6e-5, 3.3, false);
        assert_eq!(s.predicted(1), (0.0, 0.0));
    }

    #[test]
    fn without_a_temperature_nothing_is_learned_or_predicted() {
        let s = run(-6.6e-5, 22.0, false);
        assert_eq!(s.t_ref, None);
        assert_eq!(
            (s.rate, s.predicted(0), s.predicted(1)),
            (0.0, (0.0, 0.0), (0.0, 0.0))
        );
    }

    #[test]
    fn implausible_temperatures_are_not_taken() {
        let d = design();
        let mut s = ThermalState::default();
        // every eighth sample is read
        let feed = |s: &mut ThermalState<f64>, t: f64| {
            for _ in 0..8 {
                s.push(&d, Some(t));
            }
        };
        for t in [f64::NAN, f64::INFINITY, -273.0, 400.0, -60.5, 150.5] {
            feed(&mut s, t);
        }
        assert_eq!((s.n, s.sum), (0, 0.0));
        feed(&mut s, -60.0);
        feed(&mut s, 150.0);
        assert_eq!((s.n, s.sum), (2, 90.0));
    }

    #[test]
    fn a_jump_moves_the_intercept_not_the_slope() {
        let d = design();
        let mut f = SlopeFit::start(-6.6e-5, 1e-14);
        for k in 0..100 {
            let dt = k as f64 * 0.05;
            assert!(f.take(&d, -6.6e-5 * dt, dt, 1e-14, (1e-4, true)));
        }
        // a 3e-3 step: refused as an outlier until the reset, then taken by the intercept
        assert!(!f.take(&d, 3e-3 - 6.6e-5 * 5.0, 5.0, 1e-14, (1e-4, true)));
        let mut s = ThermalState {
            fit: [f; 2],
            t_ref: Some(0.0),
            ..ThermalState::default()
        };
        s.jumped(1);
        for _ in 0..50 {
            assert!(s.fit[1].take(&d, 3e-3 - 6.6e-5 * 5.0, 5.0, 1e-14, (1e-4, true)));
        }
        assert!((s.fit[1].a - 3e-3).abs() < 1e-9, "{}", s.fit[1].a);
        assert!((s.fit[1].b + 6.6e-5).abs() < 1e-9, "{}", s.fit[1].b);
        // the covariance stays positive definite throughout
        let [paa, pab, pbb] = s.fit[1].p;
        assert!(paa > 0.0 && pbb > 0.0 && pab * pab < paa * pbb);
    }
}
