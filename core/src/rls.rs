//! Bierman UD recursive least squares with exponential forgetting (held while the caller
//! sees no excitation), a trace bound against covariance wind-up, covariance reset and
//! guard statistics.
//!
//! # Model
//!
//! One instance estimates one axis: [`Rls<T, 8>`](Rls) for the drive row θ1 and
//! [`Rls<T, 6>`](Rls) for the sense row θ2. The caller has already
//!
//! * scaled the regressor columns by the nominal |θ| (so every parameter is O(1)),
//! * weighted the rows so that the measurement noise has unit variance, and
//! * subtracted the nominal prediction, so the filter estimates the *deviation*
//!   `x = (θ − θ_nom) / scale` (FINDINGS.md §4, "deviation form").
//!
//! The measurement model is therefore `y = φᵀx + e`, `e ~ N(0, 1)`, and the filter is
//! the exact Bayesian / weighted-least-squares solution for it: after `n` samples, each
//! opened by [`Rls::begin_sample`] and followed by any number of [`Rls::update`]s, the
//! estimate minimises
//!
//! ```text
//!   Σ_k λ^(n−k) Σ_rows (y − φᵀx)²  +  λ^n (x − x₀)ᵀ P₀⁻¹ (x − x₀)
//! ```
//!
//! and `P` is the inverse of that quadratic form's Hessian (the host tests check both
//! against a batch solution to 1e-9 / 1e-8).
//!
//! # Why UD, why this shape
//!
//! The drive rows cancel terms of size ~1 down to ~1e-7 (FINDINGS.md §4). In `f32` the
//! textbook covariance form `P ← P − K φᵀP` loses positive definiteness (prototype:
//! min eigenvalue −1.1e4; the host test
//! `ud_f32_stays_positive_definite_on_ill_conditioned_rows` reproduces it: on rows with
//! column scales 1e-6…1e3 the f32 covariance form is indefinite in 495 of 5000 samples
//! with diagonal entries down to −4.2e3, while the f32 UD filter passes a Cholesky test
//! after every sample and stays within 2e-4 of the f64 filter). Bierman's UD
//! form stores `P = U D Uᵀ` with `U` unit upper triangular and `D` diagonal; every
//! update multiplies `D_j` by a ratio of positive numbers, so `P` is positive definite
//! by construction and only the floor guard below is ever needed. Forgetting is
//! `D ← D/λ` (U is unchanged), a reset is `U = I, D = p·I`.
//!
//! # The innovation
//!
//! The a-priori innovation `y − φᵀx` is summed in index order in `T`, each product rounded
//! once. Large terms can cancel here (at start-up with P0 = 1e4, and right after a ±50 %
//! parameter switch, terms many orders above an innovation of order 1), and the error
//! is then the textbook `γ_(N+1)·(|y| + Σ|φᵢxᵢ|)` (unit test
//! `innovation_error_is_within_the_summation_bound`). Until the firmware's tick budget
//! needed its ≈ 640 instructions per tick on the M4F (`cargo fw-loop`), the sum was
//! Neumaier-compensated. That removed the summation error but not the products' own
//! rounding, which is of the same size, and it changed no result beyond the f32/f64
//! spread: `paragyro-sim results` gives `identify` θ14 0.47 % compensated, 0.49 % plain,
//! 0.48 % in f64, and `drift-retune`'s figures are the same to the digits it prints.
//! Those samples are transients that the estimator gates or forgets; in steady state the
//! deviation form keeps `φᵀx` at the noise level.
//!
//! # Anti-windup
//!
//! Without excitation (steady operation is only rank 5 of 8) forgetting inflates `P`
//! geometrically, by `1/λ` per sample: 148× in 10 s at λ = 0.999, and an idle `f32`
//! filter would overflow after a few minutes. Two rules keep it bounded:
//!
//! 1. **Forget only while excited.** The caller opens a sample with
//!    [`Rls::begin_sample_held`] instead of [`Rls::begin_sample`] when the regression is
//!    not persistently exciting: λ = 1 for that sample, so `P` is carried over and the
//!    updates can only shrink it (`P⁺ = P − K s Kᵀ`), and the estimate keeps the whole
//!    memory it had when the excitation stopped. The estimator does this on every sample
//!    on which its excitation meter (the variance of the filtered pump-frequency
//!    deviation, `monitor.excitation_min_fraction` of the dither's) says "not excited",
//!    once it has said "excited" since start-up and the last covariance reset
//!    (`estimator/step.rs`). Why: with the trace bound alone, `P` sits at `trace_max` in
//!    the weakly excited directions, the filter keeps a 2 s memory there and θ̂
//!    random-walks along them (θ14, the rate term, by tens of % in an hour with the
//!    dither off); held, every θ stays within 2 % (`paragyro-sim soak --hours 1`,
//!    host-sim/docs/reliability.md "Soak"). A covariance reset (a change alarm, a
//!    commanded jump) ends the hold: no excited memory is left to keep, and the filter
//!    forgets as at start-up until the dither is seen again (a hold kept through the reset
//!    leaves ω̂y² stuck off, flagged settled, after an ωy² step with the dither off;
//!    host-sim/docs/reliability.md "Soak").
//! 2. **Trace bound.** [`Rls::begin_sample`] skips the forgetting step whenever
//!    `trace(P) ≥ trace_max` (and whenever `trace(P)/λ` would not be finite), so
//!    `trace(P) ≤ max(trace(P₀), trace_max/λ)` forever. FINDINGS.md recommends
//!    `trace_max` = 10× the converged trace. It still guards what rule 1 does not see:
//!    start-up before the dither, a device whose dither is configured off (never
//!    excited: it forgets on every sample, bounded by this rule) and directions the dither
//!    itself excites only weakly.
//!
//! # Guards (never panic, never allocate)
//!
//! * Non-finite `φ` or `y`, a non-finite innovation, a non-finite or non-positive
//!   `s = 1 + φᵀPφ`, or an update that would produce a non-finite state: the state is
//!   left bit-for-bit untouched, the returned [`Innovation`] is flagged and
//!   [`RlsStats::skipped_non_finite`] counts it. The update is computed on a copy and
//!   committed only when every new value is finite.
//! * `D_j` below [`D_FLOOR`] (possible only through underflow) is clamped to the floor
//!   and counted in [`RlsStats::d_floor_hits`].
//! * All loops run over `0..N` on `[T; N]` arrays, so no index can be out of bounds.
//!
//! # Cost
//!
//! Per [`Rls::update`]: about `1.5 N²` multiply-adds for the Bierman step, `N` divisions,
//! `2N` flops for the innovation and `N² + 2N` finiteness checks.
//! [`Rls::begin_sample`] costs one trace (`N(N+1)/2` multiply-adds) and `N` divisions,
//! [`Rls::begin_sample_held`] the trace only.
//!
//! # Example
//!
//! ```
//! use paragyro_core::rls::{Rls, RlsSettings};
//!
//! let settings = RlsSettings::new(0.999_f32, 1e4, 1e5).unwrap();
//! let mut rls: Rls<f32, 2> = Rls::new(settings);
//! for k in 0..200 {
//!     let t = k as f32 * 0.1;
//!     let phi = [libm::cosf(t), libm::sinf(t)];
//!     rls.begin_sample();
//!     let inn = rls.update(&phi, 0.5 * phi[0] - 0.25 * phi[1]);
//!     assert!(inn.is_applied());
//! }
//! let x = rls.estimate();
//! assert!((x[0] - 0.5).abs() < 1e-4 && (x[1] + 0.25).abs() < 1e-4);
//! ```

use crate::real::Real;
use core::fmt;

/// Smallest value a diagonal factor `D_j` may take (in the scaled units of the
/// parameters, i.e. variance of a unit-noise-normalised deviation).
///
/// Exact arithmetic keeps `D_j > 0`; in floating point `D_j` can only reach zero
/// through underflow of `D_j·α_{j−1}/α_j` when one row carries `|φ| ≳ 1e15`. Such a
/// value is raised to this floor (which keeps `P` positive definite and the filter
/// able to learn) and counted in [`RlsStats::d_floor_hits`]. `1e-30` is a normal
/// number in `f32` (min normal 1.2e-38) and far below the variances a column-scaled,
/// unit-noise filter with λ < 1 reaches (its memory is ~1/(1−λ) samples).
pub const D_FLOOR: f64 = 1e-30;

/// Default forgetting factor per 500 Hz sample: memory `1/(1−λ)` = 1000 samples = 2 s
/// (FINDINGS.md §4, "Forgetting factor").
pub const DEFAULT_FORGETTING: f64 = 0.999;

/// Default initial covariance scale `P₀ = p0·I` (scaled units: a prior standard
/// deviation of 100× the nominal |θ|, i.e. effectively uninformative).
pub const DEFAULT_P0: f64 = 1e4;

/// Default trace bound: `1e5`, above the initial trace `N·p0 = 8e4` of the 8-state
/// drive filter so forgetting runs from the start, yet finite so that an idle `f32`
/// filter cannot overflow. A tuned deployment should use 10× the converged trace
/// (FINDINGS.md §4, "Anti-windup").
pub const DEFAULT_TRACE_MAX: f64 = 1e5;

/// Configuration of an [`Rls`] filter.
///
/// Build it with [`RlsSettings::new`] (validating) or start from
/// [`Default::default`] and check with [`RlsSettings::validate`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RlsSettings<T> {
    /// Forgetting factor λ ∈ (0, 1], applied once per sample by
    /// [`Rls::begin_sample`] as `P ← P/λ`. Default [`DEFAULT_FORGETTING`] (0.999).
    /// `1` disables forgetting (growing-memory least squares).
    pub forgetting: T,
    /// Initial covariance `P₀ = p0·I`, finite and > 0. Default [`DEFAULT_P0`] (1e4).
    pub p0: T,
    /// Anti-windup bound: forgetting is skipped while `trace(P) ≥ trace_max`. Must be
    /// positive; `+∞` (or `T::MAX`) disables the bound. Default [`DEFAULT_TRACE_MAX`].
    pub trace_max: T,
}

impl<T: Real> Default for RlsSettings<T> {
    /// λ = 0.999, p0 = 1e4, trace_max = 1e5 (see the `DEFAULT_*` constants).
    fn default() -> Self {
        RlsSettings {
            forgetting: T::from_f64(DEFAULT_FORGETTING),
            p0: T::from_f64(DEFAULT_P0),
            trace_max: T::from_f64(DEFAULT_TRACE_MAX),
        }
    }
}

impl<T: Real> RlsSettings<T> {
    /// Validating constructor: `forgetting` ∈ (0, 1], `p0` finite and > 0,
    /// `trace_max` > 0 (may be `+∞`). The error names the first bad field; NaN is
    /// rejected everywhere.
    pub fn new(forgetting: T, p0: T, trace_max: T) -> Result<Self, RlsSettingsError> {
        let s = RlsSettings {
            forgetting,
            p0,
            trace_max,
        };
        s.validate().map(|()| s)
    }

    /// Checks the fields (see [`RlsSettings::new`]); the error names the first bad one,
    /// in the order `forgetting`, `p0`, `trace_max`.
    pub fn validate(&self) -> Result<(), RlsSettingsError> {
        // Written as negated comparisons so that NaN fails every check.
        if !(self.forgetting > T::ZERO && self.forgetting <= T::ONE) {
            return Err(RlsSettingsError::Forgetting);
        }
        if !(self.p0 > T::ZERO && self.p0.is_finite()) {
            return Err(RlsSettingsError::P0);
        }
        let trace_max_positive = self.trace_max > T::ZERO;
        if !trace_max_positive {
            return Err(RlsSettingsError::TraceMax);
        }
        Ok(())
    }

    /// The same settings in another precision (rounded when narrowing), e.g. to run an
    /// `f64` reference filter beside the `f32` one.
    pub fn cast<U: Real>(&self) -> RlsSettings<U> {
        RlsSettings {
            forgetting: U::from_f64(self.forgetting.to_f64()),
            p0: U::from_f64(self.p0.to_f64()),
            trace_max: U::from_f64(self.trace_max.to_f64()),
        }
    }
}

/// A rejected [`RlsSettings`] field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RlsSettingsError {
    /// `forgetting` is NaN or outside (0, 1].
    Forgetting,
    /// `p0` is NaN, infinite or ≤ 0.
    P0,
    /// `trace_max` is NaN or ≤ 0.
    TraceMax,
}

impl RlsSettingsError {
    /// The name of the offending field of [`RlsSettings`] (`"forgetting"`, `"p0"` or
    /// `"trace_max"`).
    pub const fn field(self) -> &'static str {
        match self {
            RlsSettingsError::Forgetting => "forgetting",
            RlsSettingsError::P0 => "p0",
            RlsSettingsError::TraceMax => "trace_max",
        }
    }

    /// The condition the field must satisfy, for error messages.
    pub const fn requirement(self) -> &'static str {
        match self {
            RlsSettingsError::Forgetting => "must be in (0, 1]",
            RlsSettingsError::P0 => "must be finite and > 0",
            RlsSettingsError::TraceMax => "must be > 0 (+inf disables the bound)",
        }
    }
}

impl fmt::Display for RlsSettingsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "invalid RLS setting `{}`: {}",
            self.field(),
            self.requirement()
        )
    }
}

impl core::error::Error for RlsSettingsError {}

/// What [`Rls::update`] did with a measurement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UpdateStatus {
    /// The update was applied.
    Applied,
    /// `φ` or `y` contained NaN or ±∞; nothing was changed.
    NonFiniteInput,
    /// The inputs were finite but the innovation, `s = 1 + φᵀPφ` or the updated state
    /// would not have been finite (overflow) or `s` was not positive; nothing was
    /// changed.
    NumericalFault,
}

/// The a-priori innovation of one scalar measurement, returned by [`Rls::update`].
///
/// `e²/s` is the normalised squared innovation: χ²(1)-distributed with mean 1 when the
/// model holds and the noise has unit variance, which is what a change detector sums.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Innovation<T> {
    /// `e = y − φᵀx` with the estimate *before* this update.
    /// `0` when the update was rejected.
    pub e: T,
    /// Variance factor `s = 1 + φᵀPφ` (`P` after this sample's forgetting, before the
    /// update); the innovation variance in units of the measurement noise. `1` when the
    /// update was rejected.
    pub s: T,
    /// Whether the update was applied, and if not, why.
    pub status: UpdateStatus,
}

impl<T: Real> Innovation<T> {
    /// `true` iff the update was applied ([`UpdateStatus::Applied`]).
    #[inline]
    pub fn is_applied(&self) -> bool {
        self.status == UpdateStatus::Applied
    }

    /// Normalised squared innovation `e²/s` (0 for a rejected update, so a rejected
    /// sample never raises a change alarm by itself).
    #[inline]
    pub fn normalized_sq(&self) -> T {
        self.e * self.e / self.s
    }

    fn rejected(status: UpdateStatus) -> Self {
        Innovation {
            e: T::ZERO,
            s: T::ONE,
            status,
        }
    }
}

/// Counters of what the guards of an [`Rls`] did since construction (saturating).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RlsStats {
    /// Measurement updates applied.
    pub updates: u64,
    /// Updates rejected: non-finite input, innovation, `s` or result
    /// ([`UpdateStatus::NonFiniteInput`] and [`UpdateStatus::NumericalFault`]).
    pub skipped_non_finite: u64,
    /// Samples whose forgetting step was skipped by the trace bound (or because
    /// `trace(P)/λ` would overflow).
    pub forgetting_skipped: u64,
    /// Samples opened by [`Rls::begin_sample_held`]: no forgetting because the caller
    /// saw too little excitation (λ = 1 for that sample).
    pub forgetting_held: u64,
    /// Diagonal factors raised to [`D_FLOOR`] (one count per clamped `D_j`).
    pub d_floor_hits: u64,
    /// Calls of [`Rls::reset_covariance`].
    pub resets: u64,
}

/// Bierman UD-factorised recursive least squares for `N` parameters in precision `T`.
///
/// `P = U D Uᵀ` with `U` unit upper triangular (stored as a full `[[T; N]; N]`, row
/// index first, strictly lower part zero, diagonal one) and `D` positive diagonal.
/// See the [module documentation](self) for the model, the guards and the cost.
///
/// Per 500 Hz sample: one [`begin_sample`](Rls::begin_sample), then one
/// [`update`](Rls::update) per row.
#[derive(Clone, Debug, PartialEq)]
pub struct Rls<T: Real, const N: usize> {
    settings: RlsSettings<T>,
    x: [T; N],
    u: [[T; N]; N],
    d: [T; N],
    stats: RlsStats,
    last_trace: T,
}

impl<T: Real, const N: usize> Rls<T, N> {
    /// A placeholder with no design (all zero), built in place by
    /// [`crate::Estimator::blank`]; never used before it is rebuilt.
    #[inline(always)]
    pub(crate) fn blank() -> Self {
        Rls {
            settings: RlsSettings {
                forgetting: T::ONE,
                p0: T::ONE,
                trace_max: T::MAX,
            },
            x: [T::ZERO; N],
            u: [[T::ZERO; N]; N],
            d: [T::ZERO; N],
            stats: RlsStats {
                updates: 0,
                skipped_non_finite: 0,
                forgetting_skipped: 0,
                forgetting_held: 0,
                d_floor_hits: 0,
                resets: 0,
            },
            last_trace: T::ZERO,
        }
    }

    /// A filter with estimate `x = 0`, `P = p0·I` and zeroed statistics.
    ///
    /// The settings are used as given; validate them first ([`RlsSettings::new`] or
    /// [`Rls::try_new`]). Invalid settings cannot make the filter panic, but e.g. a NaN
    /// `p0` makes every update be rejected.
    #[inline(never)] // set-up only: its own frame (the chip's stack)
    pub fn new(settings: RlsSettings<T>) -> Self {
        let mut u = [[T::ZERO; N]; N];
        for (i, row) in u.iter_mut().enumerate() {
            if let Some(diag) = row.get_mut(i) {
                *diag = T::ONE;
            }
        }
        Rls {
            settings,
            x: [T::ZERO; N],
            u,
            d: [settings.p0; N],
            stats: RlsStats::default(),
            last_trace: settings.p0 * T::from_f64(N as f64),
        }
    }

    /// [`Rls::new`] after [`RlsSettings::validate`].
    pub fn try_new(settings: RlsSettings<T>) -> Result<Self, RlsSettingsError> {
        settings.validate()?;
        Ok(Self::new(settings))
    }

    /// The settings this filter was built with.
    #[inline]
    pub fn settings(&self) -> &RlsSettings<T> {
        &self.settings
    }

    /// Changes the anti-windup bound at run time, e.g. to 10× the converged trace once
    /// the filter has settled (FINDINGS.md §4). Same rule as
    /// [`RlsSettings::trace_max`]: must be > 0 (`+∞` disables the bound); a NaN or
    /// non-positive value is ignored and `false` returned.
    pub fn set_trace_max(&mut self, trace_max: T) -> bool {
        // the rule of `RlsSettings::validate` for this field alone (the others are the
        // filter's own, unchanged): one comparison on the tick that learns the bound, which
        // is a decision's tick too (NaN fails it)
        if trace_max > T::ZERO {
            self.settings.trace_max = trace_max;
            true
        } else {
            false
        }
    }

    /// Opens a sample: exponential forgetting `D ← D/λ` (i.e. `P ← P/λ`), applied once
    /// per 500 Hz sample before that sample's [`update`](Rls::update)s.
    ///
    /// Skipped, and counted in [`RlsStats::forgetting_skipped`], while
    /// `trace(P) ≥ trace_max` (anti-windup) or when `trace(P)/λ` would not be finite.
    /// Returns `true` when forgetting was applied (always for λ = 1, where it is a
    /// no-op and the trace is not even computed).
    pub fn begin_sample(&mut self) -> bool {
        self.begin_sample_with(true)
    }

    /// [`begin_sample`](Rls::begin_sample) reading the trace only when `fresh`; otherwise
    /// the bound is tested on the last trace computed (one sample old when the caller
    /// alternates: the trace moves by the factor 1/λ and the updates' shrinkage per
    /// sample, and the bound is ten times the converged trace; the estimator reads its
    /// two filters' traces on alternate samples, ≈ 70 instructions per tick less on the
    /// chip).
    pub fn begin_sample_with(&mut self, fresh: bool) -> bool {
        let lambda = self.settings.forgetting;
        if lambda == T::ONE {
            return true;
        }
        if fresh {
            self.last_trace = self.trace();
        }
        let tr = self.last_trace;
        // `tr/λ` finite ⇒ every `D_j/λ` finite, since D_j ≤ trace(P) (U_jj = 1).
        if tr < self.settings.trace_max && (tr / lambda).is_finite() {
            for d in self.d.iter_mut() {
                *d /= lambda;
            }
            true
        } else {
            self.stats.forgetting_skipped = self.stats.forgetting_skipped.saturating_add(1);
            false
        }
    }

    /// Opens a sample *without* forgetting (λ = 1 for this sample): `P` is carried over
    /// unchanged, so the sample's [`update`](Rls::update)s can only shrink it and the
    /// memory of the past is held. The estimator calls this instead of
    /// [`begin_sample`](Rls::begin_sample) while its excitation meter says the
    /// regression is not persistently exciting (module docs, "Anti-windup"). Counted in
    /// [`RlsStats::forgetting_held`]; the trace is read as by `begin_sample` (same cost,
    /// [`last_trace`](Rls::last_trace) stays a fresh health reading).
    pub fn begin_sample_held(&mut self) {
        self.begin_sample_held_with(true);
    }

    /// [`begin_sample_held`](Rls::begin_sample_held) reading the trace only when `fresh`
    /// (as [`begin_sample_with`](Rls::begin_sample_with)).
    pub fn begin_sample_held_with(&mut self, fresh: bool) {
        if fresh && self.settings.forgetting != T::ONE {
            self.last_trace = self.trace();
        }
        self.stats.forgetting_held = self.stats.forgetting_held.saturating_add(1);
    }

    /// trace(P) as computed by the last [`begin_sample`](Rls::begin_sample) that read it
    /// (or set by a reset): a cheap health reading that costs nothing on the tick path.
    #[inline]
    pub fn last_trace(&self) -> T {
        self.last_trace
    }

    /// [`Rls::update`] on the row `φ = a ∘ s` (element by element): the estimator's rows
    /// times their column scale and row weight. Written out, from a copy of `a` (no zeroed
    /// array and no iterator: `array::from_fn` with two products per element cost the
    /// firmware's tick ≈ 1 400 instructions for its 10 rows at `opt-level = "z"`).
    #[inline(always)]
    pub fn update_scaled(&mut self, a: &[T; N], s: &[T; N], y: T) -> Innovation<T> {
        let inn = self.update_scaled_unfloored(a, s, y);
        if inn.is_applied() {
            self.floor_all();
        }
        inn
    }

    /// [`Rls::update_scaled`] without the `D` floor, for a caller that applies
    /// [`Rls::floor_all`] once after a sample's rows: the estimator (the floor's tests are
    /// ≈ 200 instructions a tick on the chip for its 10 rows). Between two floors a `D_j`
    /// below [`D_FLOOR`] stays ≥ +0 (each update multiplies it by `α_(j−1)/α_j` ∈ (0, 1]),
    /// and the updates stay finite (every `α` ≥ 1).
    #[inline(always)]
    pub(crate) fn update_scaled_unfloored(
        &mut self,
        a: &[T; N],
        s: &[T; N],
        y: T,
    ) -> Innovation<T> {
        let mut phi = *a;
        macro_rules! scale_col {
            ($j:expr $(; $($i:expr),*)?) => {
                phi[$j] *= s[$j]
            };
        }
        unrolled_columns!(scale_col);
        self.update_unfloored(&phi, y)
    }

    /// Raises every `D_j` below [`D_FLOOR`] to it, counted in [`RlsStats::d_floor_hits`]
    /// (after the rows of [`Rls::update_scaled_unfloored`]; [`Rls::update`] applies it itself).
    #[inline(always)]
    pub(crate) fn floor_all(&mut self) {
        let floor = T::from_f64(D_FLOOR);
        // `d` is finite and ≥ +0 here, so a comparison of the bit patterns catches zero
        // and underflow (in index order, written out; the clamp itself is out of line: it
        // never runs in practice)
        macro_rules! floor_col {
            ($j:expr $(; $($i:expr),*)?) => {
                if self.d[$j].lt_nonneg(floor) {
                    self.floor_d($j, floor);
                }
            };
        }
        unrolled_columns!(floor_col);
    }

    /// One scalar measurement `y = φᵀx + e`, `e ~ N(0, 1)`: Bierman's UD update.
    ///
    /// Returns the a-priori innovation `e = y − φᵀx` and its
    /// variance factor `s = 1 + φᵀPφ`. Rejected updates (non-finite input, innovation,
    /// `s` or result; `s ≤ 0`) leave the state untouched, are counted in
    /// [`RlsStats::skipped_non_finite`] and return `e = 0, s = 1` with the reason in
    /// [`Innovation::status`]. New `D_j` below [`D_FLOOR`] are clamped and counted.
    pub fn update(&mut self, phi: &[T; N], y: T) -> Innovation<T> {
        let inn = self.update_unfloored(phi, y);
        if inn.is_applied() {
            self.floor_all();
        }
        inn
    }

    /// [`Rls::update`] without the `D` floor ([`Rls::update_scaled_unfloored`]).
    #[allow(clippy::needless_range_loop)] // triangular index arithmetic; all < N
    #[inline(never)]
    fn update_unfloored(&mut self, phi: &[T; N], y: T) -> Innovation<T> {
        // No finiteness test of the input up front (≈ 56 instructions a row on the M4F):
        // with `x` finite (checked after every update), a non-finite `y` or `φ_j` makes
        // `e` non-finite (±∞·x_j is ±∞ or NaN, NaN propagates, ∞ − ∞ is NaN), and nothing
        // is written before `e` is tested below, where the input is classified.
        // f = Uᵀφ, v = D∘f, s = 1 + fᵀv = 1 + φᵀPφ. (`f` and `v` start as copies of φ
        // rather than zeros: every element is written before it is read, and a copy is
        // cheaper than a zeroing call on the tick path.)
        let mut f = *phi;
        let mut v = *phi;
        let mut s = T::ONE;
        macro_rules! f_col {
            ($j:expr; $($i:expr),*) => {{
                let j = $j;
                #[allow(unused_mut)] // column 0 has no rows above the diagonal
                let mut acc = phi[j];
                $( acc += self.u[$i][j] * phi[$i]; )*
                f[j] = acc;
                v[j] = self.d[j] * acc;
                s += acc * v[j];
            }};
            ($j:expr) => {{
                let j = $j;
                let mut acc = phi[j];
                for i in 0..j {
                    acc += self.u[i][j] * phi[i];
                }
                f[j] = acc;
                v[j] = self.d[j] * acc;
                s += acc * v[j];
            }};
        }
        unrolled_columns!(f_col);
        let e = residual(y, phi, &self.x);
        // `0 < s ≤ MAX` and `|e| ≤ MAX` (false for NaN): finite and positive in three
        // float comparisons (LLVM turned `s > 0 && s.is_finite()` into ≈ 25 integer
        // instructions of class tests on the chip)
        if !(s > T::ZERO && s <= T::MAX && e.abs() <= T::MAX) {
            if !all_finite(y, phi) {
                return self.reject(UpdateStatus::NonFiniteInput);
            }
            // a huge but finite row can overflow s: reject it. If the factors themselves
            // went bad (non-finite D), start the covariance afresh so the filter recovers
            // instead of rejecting every later row.
            if !self.d.iter().all(|t| t.is_finite() && *t > T::ZERO) {
                let p0 = self.settings.p0;
                self.reset_covariance(p0);
            }
            return self.reject(UpdateStatus::NumericalFault);
        }

        // Bierman's update, in place. With finite f, v and a finite positive s every
        // α_j = 1 + Σ_{i≤j} f_i v_i lies in [1, s], so the divisions are safe; only an
        // overflow of U could produce a non-finite value, which the O(N) check below
        // catches on the new x (the old x is kept and the covariance reset).
        // k starts as v: k[j] must be v[j] when column j is reached, and the inner loop
        // of column j only touches k[i] for i < j
        let mut k = v;
        let mut alpha = T::ONE;
        macro_rules! bierman_col {
            ($j:expr; $($i:expr),*) => {{
                let j = $j;
                let alpha_prev = alpha;
                alpha = alpha_prev + f[j] * v[j];
                self.d[j] *= alpha_prev / alpha;
                let lj = -f[j] / alpha_prev;
                $(
                    let uij = self.u[$i][j];
                    self.u[$i][j] = uij + lj * k[$i];
                    k[$i] += v[j] * uij;
                )*
                let _ = lj;
            }};
            ($j:expr) => {{
                let j = $j;
                let alpha_prev = alpha;
                alpha = alpha_prev + f[j] * v[j];
                self.d[j] *= alpha_prev / alpha;
                let lj = -f[j] / alpha_prev;
                for i in 0..j {
                    let uij = self.u[i][j];
                    self.u[i][j] = uij + lj * k[i];
                    k[i] += v[j] * uij;
                }
            }};
        }
        unrolled_columns!(bierman_col);
        // `alpha` now equals `s` (same terms, same order); the gain is k/alpha.
        let g = e / alpha;
        // the new estimate into `k` (x + k·g), kept only if finite; written out like the
        // columns (a rolled loop on the chip: ~3 instructions of loop overhead per element)
        macro_rules! x_col {
            ($j:expr $(; $($i:expr),*)?) => {
                k[$j] = self.x[$j] + k[$j] * g
            };
        }
        unrolled_columns!(x_col);
        // D needs no test: every D_j was multiplied by α_(j−1)/α_j ∈ (0, 1] (the α grow
        // from 1 by f_j·v_j = D_j f_j² ≥ 0 to the finite s tested above), so it is finite
        // and positive where it was
        if !all_finite(T::ZERO, &k) {
            let p0 = self.settings.p0;
            self.reset_covariance(p0);
            return self.reject(UpdateStatus::NumericalFault);
        }
        self.x = k;
        self.stats.updates = self.stats.updates.saturating_add(1);
        Innovation {
            e,
            s: alpha,
            status: UpdateStatus::Applied,
        }
    }

    /// Raises `D_j` to the floor and counts it.
    #[cold]
    #[inline(never)]
    fn floor_d(&mut self, j: usize, floor: T) {
        if let Some(dj) = self.d.get_mut(j) {
            *dj = floor;
            self.stats.d_floor_hits = self.stats.d_floor_hits.saturating_add(1);
        }
    }

    fn reject(&mut self, status: UpdateStatus) -> Innovation<T> {
        self.stats.skipped_non_finite = self.stats.skipped_non_finite.saturating_add(1);
        Innovation::rejected(status)
    }

    /// Covariance reset `P = p·I` (`U = I`, `D = p`), estimate kept; counted in
    /// [`RlsStats::resets`]. Used by the change detector after an alarm (FINDINGS.md §5:
    /// `p = 1` in scaled units). A `p` that is NaN, infinite or ≤ 0 is replaced by the
    /// configured `p0`.
    pub fn reset_covariance(&mut self, p: T) {
        let p = if p > T::ZERO && p.is_finite() {
            p
        } else {
            self.settings.p0
        };
        // zeroed as a block (a word-wise memclr), then the unit diagonal: the branchy
        // per-element loop was ≈ 1 100 instructions on the chip's reset tick (the loop's
        // costliest tick, `firmware/scripts/fil-profile.sh drift-retune 1157`)
        self.u = [[T::ZERO; N]; N];
        for i in 0..N {
            self.u[i][i] = T::ONE;
        }
        self.d = [p; N];
        self.last_trace = p * T::from_f64(N as f64);
        self.stats.resets = self.stats.resets.saturating_add(1);
    }

    /// Process noise on one parameter: `P ← P + q·e_j e_jᵀ` (a random walk of variance `q`
    /// per call on parameter `j`, the Kalman filter's time update for that parameter),
    /// unless `P_jj ≥ cap` already. An Agee–Turner rank-one update of the UD factors:
    /// only `D_0..=j` and the columns `1..=j` of `U` above the diagonal change and every
    /// `D_k` grows, so `P` stays positive definite; `j` divisions, ≈ j² multiply-adds.
    /// Returns whether it walked: a `q` that is not finite and > 0, a `j` ≥ min(N,
    /// [`WALK_J_MAX`] + 1), or `P_jj ≥ cap` (or NaN) changes nothing. The estimate is not
    /// touched.
    pub fn add_walk(&mut self, j: usize, q: T, cap: T) -> bool {
        if !(q > T::ZERO && q.is_finite()) || j >= N || j > WALK_J_MAX {
            return false;
        }
        // P_jj = Σ_{k ≥ j} U[j][k]²·D[k]
        let mut pjj = T::ZERO;
        for k in j..N {
            pjj += self.u[j][k] * self.u[j][k] * self.d[k];
        }
        // NaN is not below the cap
        let below = pjj < cap;
        if !below {
            return false;
        }
        // the update reads and writes the leading 4×4 block only: one copy of its code
        // for every N (the chip's flash)
        let Some(d) = self.d.first_chunk_mut::<4>() else {
            return false;
        };
        let [r0, r1, r2, r3, ..] = &mut self.u[..] else {
            return false;
        };
        let (Some(u0), Some(u1), Some(u2), Some(u3)) = (
            r0.first_chunk_mut::<4>(),
            r1.first_chunk_mut::<4>(),
            r2.first_chunk_mut::<4>(),
            r3.first_chunk_mut::<4>(),
        ) else {
            return false;
        };
        agee_turner_unit(&mut [u0, u1, u2, u3], d, j, q);
        true
    }

    /// Moves one parameter of the estimate by `delta` (a known jump of it); the covariance
    /// is kept. A non-finite `delta` or `j ≥ N` changes nothing.
    pub fn shift(&mut self, j: usize, delta: T) {
        // one comparison (NaN and ±∞ fail it), not `is_finite`'s integer class tests
        if delta.abs() < T::MAX
            && let Some(x) = self.x.get_mut(j)
        {
            *x += delta;
        }
    }

    /// Moves one parameter of the estimate by `delta`, a finite value the caller computed
    /// (a known input's time update; no check, the tick path); `j ≥ N` changes nothing.
    #[inline(always)]
    pub fn nudge(&mut self, j: usize, delta: T) {
        if let Some(x) = self.x.get_mut(j) {
            *x += delta;
        }
    }

    /// Replaces the estimate (e.g. after re-centring the nominal θ); the covariance is
    /// kept. Returns `false` and changes nothing if any entry is NaN or ±∞.
    pub fn set_estimate(&mut self, x: [T; N]) -> bool {
        if x.iter().all(|t| t.is_finite()) {
            self.x = x;
            true
        } else {
            false
        }
    }

    /// The current estimate `x` (scaled deviation from the nominal θ).
    #[inline]
    pub fn estimate(&self) -> [T; N] {
        self.x
    }

    /// One component of the estimate, `x_j` (0 for `j ≥ N`): no copy of the whole vector.
    #[inline]
    pub fn estimate_at(&self, j: usize) -> T {
        self.x.get(j).copied().unwrap_or(T::ZERO)
    }

    /// `P_jj = Σ_{k ≥ j} U_jk²·D_k`, the variance of parameter `j` (0 for `j ≥ N`).
    pub fn variance_at(&self, j: usize) -> T {
        let (Some(u), true) = (self.u.get(j), j < N) else {
            return T::ZERO;
        };
        let mut p = T::ZERO;
        for k in j..N {
            p += u[k] * u[k] * self.d[k];
        }
        p
    }

    /// `trace(P) = Σ_j D_j Σ_{i≤j} U_ij²` (`N(N+1)/2` multiply-adds).
    #[allow(clippy::needless_range_loop)] // triangular index arithmetic; all < N
    pub fn trace(&self) -> T {
        let mut tr = T::ZERO;
        macro_rules! trace_col {
            ($j:expr; $($i:expr),*) => {{
                let j = $j;
                let mut col = T::ZERO;
                $( col += self.u[$i][j] * self.u[$i][j]; )*
                col += self.u[j][j] * self.u[j][j];
                tr += self.d[j] * col;
            }};
            ($j:expr) => {{
                let j = $j;
                let mut col = T::ZERO;
                for i in 0..=j {
                    col += self.u[i][j] * self.u[i][j];
                }
                tr += self.d[j] * col;
            }};
        }
        unrolled_columns!(trace_col);
        tr
    }

    /// The covariance `P = U D Uᵀ` (`O(N³)`; for diagnostics and tests, not the tick
    /// path). The upper triangle is computed and mirrored, so the result is exactly
    /// symmetric.
    #[allow(clippy::needless_range_loop)] // triangular index arithmetic; all < N
    pub fn covariance(&self) -> [[T; N]; N] {
        let mut p = [[T::ZERO; N]; N];
        for i in 0..N {
            for k in i..N {
                // P_ik = Σ_{j ≥ k} U_ij D_j U_kj   (U upper triangular, i ≤ k)
                let mut acc = T::ZERO;
                for j in k..N {
                    acc += self.u[i][j] * self.d[j] * self.u[k][j];
                }
                p[i][k] = acc;
                p[k][i] = acc;
            }
        }
        p
    }

    /// The UD factors `(U, D)`: `U` unit upper triangular (row index first), `D` the
    /// diagonal. For diagnostics and tests.
    #[inline]
    pub fn factors(&self) -> ([[T; N]; N], [T; N]) {
        (self.u, self.d)
    }

    /// `min_j D_j`, a cheap health indicator (> 0 always; `T::MAX` for `N = 0`).
    pub fn min_d(&self) -> T {
        self.d.iter().fold(T::MAX, |m, &dj| m.min(dj))
    }

    /// Guard statistics since construction.
    #[inline]
    pub fn stats(&self) -> RlsStats {
        self.stats
    }
}

/// `y − φᵀx` with Neumaier-compensated summation of the products: the summation error
/// (the part that grows with cancellation between large terms) is carried in a second
/// accumulator, at ~4 extra flops per term. The products themselves are rounded once;
/// the estimator keeps them small (it forms the innovation about θ_nom at the signal
/// level and re-linearises every 0.1 s, so φᵀx stays near the noise level).
/// Runs the column macro `$col` for j = 0, 1, …, N − 1 in order: the first eight columns
/// written out with their row indices i < j (the triangular loops completely unrolled:
/// the release profile builds the image for size and does not unroll them itself; `if
/// j < N` folds away per instantiation), any further ones in a plain loop. Same
/// operations in the same order as `for j in 0..N { for i in 0..j { … } }`.
macro_rules! unrolled_columns {
    ($col:ident) => {{
        if 0 < N { $col!(0usize;); }
        if 1 < N { $col!(1usize; 0); }
        if 2 < N { $col!(2usize; 0, 1); }
        if 3 < N { $col!(3usize; 0, 1, 2); }
        if 4 < N { $col!(4usize; 0, 1, 2, 3); }
        if 5 < N { $col!(5usize; 0, 1, 2, 3, 4); }
        if 6 < N { $col!(6usize; 0, 1, 2, 3, 4, 5); }
        if 7 < N { $col!(7usize; 0, 1, 2, 3, 4, 5, 6); }
        for j in 8..N {
            $col!(j);
        }
    }};
}
use unrolled_columns;

/// `y` and every element of `v` are finite: `y·0 + Σ vᵢ·0` is ±0 exactly when they all
/// are (∞·0 and NaN·0 are NaN, and NaN propagates through the sum), in one test instead
/// of one per element.
#[inline]
fn all_finite<T: Real, const N: usize>(y: T, v: &[T; N]) -> bool {
    let mut acc = y * T::ZERO;
    macro_rules! add {
        ($j:expr $(; $($i:expr),*)?) => {
            acc += v[$j] * T::ZERO
        };
    }
    unrolled_columns!(add);
    acc == T::ZERO
}

/// `y − φᵀx`, summed in index order (module docs, "The innovation"). Non-finite after a
/// non-finite input or an overflow; the caller rejects the update then.
#[inline]
fn residual<T: Real, const N: usize>(y: T, phi: &[T; N], x: &[T; N]) -> T {
    let mut r = y;
    macro_rules! term {
        ($j:expr $(; $($i:expr),*)?) => {
            r -= phi[$j] * x[$j]
        };
    }
    // in index order, the first eight written out (see `unrolled_columns`)
    unrolled_columns!(term);
    r
}

#[cfg(test)]
mod props;

/// The largest parameter index [`Rls::add_walk`] takes (its update works on the leading
/// 4×4 block of the UD factors; the estimator walks θ14 and θ24, index 3).
pub const WALK_J_MAX: usize = 3;

/// `U D Uᵀ + q e_j e_jᵀ` on the leading 4×4 block (Agee–Turner with `v = e_j`: the
/// entries of `v` above `j` start at 0 and pick up `−U[i][k]·v_k` on the way down).
#[inline(never)]
fn agee_turner_unit<T: Real>(u: &mut [&mut [T; 4]; 4], d: &mut [T; 4], j: usize, q: T) {
    let mut v = [T::ZERO; 4];
    let mut c = q;
    for k in (1..4).rev() {
        if k > j {
            continue;
        }
        let s = if k == j { T::ONE } else { v[k] };
        let dn = d[k] + c * s * s;
        let inv = T::ONE / dn;
        let b = c * s * inv;
        c = c * d[k] * inv;
        d[k] = dn;
        for i in 0..k {
            v[i] -= s * u[i][k];
            u[i][k] += b * v[i];
        }
    }
    let s = if j == 0 { T::ONE } else { v[0] };
    d[0] += c * s * s;
}

#[cfg(test)]
mod tests;
