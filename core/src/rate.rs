//! The fast rate channel: the angular rate every sample, from the sense fundamental row
//! *given* the slow parameters, separate from the slow identification.
//!
//! # Why a second channel
//!
//! The rate lives in θ14 = −(μxy − 2γ) and θ24 = −(μxy + 2γ). The slow RLS (memory
//! λ = 0.999 ≈ 2 s, 10 Hz state-variable filter) is right only while the rate stands
//! still.
//!
//! # The fast row
//!
//! The sense fundamental (DERIVATION §2, k = 1), filtered by a wide-band state-variable
//! filter of its own (`Λf = (D + wf)²`, `wf = 2π·rate.svf_hz`, the same FOH-exact
//! realisation as the slow bank, [`crate::svf`]):
//!
//! ```text
//! F2(B) + 2i F1(ωB) − θ21 F1(B) + F0(v)  =  θ23 F0(A) + θ24 [F1(A) + i F0(ωA)]
//! v = −i ω′B − (ω² + θ22) B − i θ21 ωB − θ25 [Y³]₁
//! ```
//!
//! with θ21, θ22, θ25 and θ23 from the slow RLS. The Coriolis column `c24 ≈ iωA` and the
//! quadrature column `c23 = A` are orthogonal: θ24 is the weighted least squares along
//! `c24` given θ23, and what is left along `c23` is the instantaneous quadrature
//! `−θ23 = ωxy² + γ′`. The left side inverts the identified sense dynamics (the sense mode
//! alone is a ≈ 5 Hz low-pass, f/2Q): the rate's transfer is `F0` (two real poles at `wf`)
//! times the output's second-order section ([`POST_HZ`], [`POST_ZETA`]) times the lock-in
//! low-pass; the price is noise, which grows with frequency as the
//! inverse of the sense dynamics (priced by the CRLB of `paragyro-sim rate-response`). The
//! large terms are combined before filtering (`ω² + θ22` from the small precomputed
//! `ω_ref² + θ22n`), as in [`crate::rows`], so `f32` keeps the precision.
//!
//! **The wide filter's curvature bias.** FOH-exact is exact for inputs linear between
//! samples; at `wT` = 1.88 (150 Hz at 500 Hz) the sample-rate ripple of a smooth input's
//! deviation from its chords leaves the outputs off by `ε_j u″` (`F2` by −25 %;
//! [`crate::svf::parabola_bias`]). The pump dither modulates the envelopes by ±25–45 % at
//! 5 Hz, and the uncorrected row reads that as a ≈ 0.65 °/s rate tone at the dither (∝ dither
//! amplitude × frequency^2.3 and ∝ `svf_hz`^2.7; the same with no rate, with the lock-in
//! low-pass at 100 or 200 Hz, and with a plant integrated twice as finely). Each output of
//! the wide filter is corrected, `F_j − ε_j u″` with `u″ = F2/(1+ε2)` (a few
//! multiply-adds per signal): the noise-free tone is then ≈ 0.08 °/s (0.064 °/s rms
//! deterministic error with the band taps below). Above a few tens of Hz the correction,
//! exact for slow curvature, leaves `F0`'s ratio to the continuous filter 2–6 % from `F1`'s
//! at 60–100 Hz, and the row balances `2iω·F1(B)` against the quadrature's `θ23·F0(A)`: the
//! ringing every DDS word step leaves in the drive (its ≈ 100 Hz envelope mode) would be
//! read as a rate. `F0` (of `A` and of `v`) therefore also takes the band taps,
//! `−a·e0·F2[k] − b·e0·(F2[k] − F2[k−1])`, least squares over 5–100 Hz
//! ([`crate::svf::band_taps`], shipped for the default design; firmware/docs/notes.md
//! "DDS words"). The narrow channel (40 Hz, `wT` = 0.5, `ε2` = −2 %) has no band taps.
//!
//! Rate: `γ̂ = −(θ̂24 + μ̂xy)/2`, μ̂xy the rate's zero: `−(θ14 + θ24)/2` of the slow RLS
//! averaged with a `rate.zero_memory_s` memory ([`RateState::hold_zero`]).
//!
//! # Keeping the slow identification out of rate transients
//!
//! The slow rows resolve θ24 to ~1e-8 per sample (0.02 °/s): a rate that moves makes them
//! inconsistent and fires the change detector. A continuous hand-over (forming the slow
//! rows with the fast rate) is not used: the fast row's own model error at the pump
//! dither and the loop through the slow θ make the slow rows diverge on a 50 °/s² ramp
//! (issue 10's note). What is here:
//!
//! * a second, narrower copy of the row (corner `rate.coupling_hz`, its dither error
//!   ≈ 0.03 °/s) watches the rate: while its acceleration is above `rate.gate_accel_dps2`
//!   or it differs from the slow RLS's rate by more than `rate.gate_dev_dps`, the slow
//!   RLS is gated (no update, no detector), and for `rate.gate_s` after — provided its
//!   quadrature agrees with the slow θ23 to the same tolerance: a drift of the device
//!   (ωy², damping) moves both directions of the row and is left to the slow RLS;
//! * while the narrow channel sees the rate move (the same tests with the quadrature
//!   agreeing, gated or not, and for `rate.gate_s` after: [`RateState::moving`]), the slow
//!   RLS's rate term is a random walk (`rate.walk_dps`, 0.3 °/s per sample,
//!   `estimator/step.rs` `walk_rate`): the sense θ24 takes that process noise on every
//!   update, the drive θ14 the square of the sense θ24's move, so the slow rows follow a
//!   moving rate between gates, and the slow RLS re-identifies a drift of the device while
//!   the rate moves (host-sim/docs/rate-channel.md).
//!
//! After a step the narrow channel's departure from the slow rate renews the gate on every
//! sample, so without a hand-over the slow RLS would stay gated to the end. So, once the
//! narrow channel's rate has stayed within `rate.gate_dev_dps` of its own ≈ 0.26 s
//! average for `rate.gate_s`, the slow estimate takes that average ([`RateState::take_handover`]: θ24 + Δ, θ14 − Δ), and the gate ends
//! as the slow rate agrees (host-sim/docs/rate-channel.md).
//!
//! # Validity
//!
//! The rate is valid when this sample's inputs are valid, the drive is locked, the slow
//! identification has settled at least once since start-up and since the drive last lost
//! its lock, no change of the device
//! is pending (the slow θ the row relies on are being re-identified), the fast row is
//! solvable (|A1| above the lock threshold), the drive is not ringing down (|A1|² has not
//! fallen below [`DRIVE_RING2`] of its slow mean, or it has come back above
//! [`DRIVE_STEADY2`] of it for [`RING_HOLD`] samples since), the narrow channel's
//! quadrature agrees with the slow θ23 to `rate.gate_dev_dps` (a change of the device
//! moves the quadrature at once, while the change detector needs a few samples, and the
//! rate gate holds the detector while the rate moves: without this test `drift-retune`
//! had 3 valid samples up to 40 °/s off at the drift's start, and the same drift under a
//! 5 Hz rate sine ≈ 150 valid samples up to 880 °/s off) and |rate| ≤
//! `rate.full_scale_dps`. The narrow channel gates the slow RLS only while the drive is
//! steady, too.
//!
//! Never panics, never allocates; a non-finite solution is skipped and the last value
//! held.

use crate::complex::Cplx;
use crate::config::Config;
use crate::physics::theta_from_physical;
use crate::real::Real;
use crate::rows::{Envelopes, Known};
use crate::svf::{BAND_FS_HZ, BAND_SVF_HZ, BAND_TAPS, CSvfState, SvfCoeffs, parabola_bias};

/// The FOH discretisation's curvature bias of one filter, as applied to its outputs
/// (`svf::parabola_bias`): `F0 − e0·F2`, `F1 − e1·F2`, `F2·g` with `e_j = ε_j/(1+ε2)`,
/// `g = 1/(1+ε2)`. Applied where it reaches the rate: `F2(B)`, `F1(ωB)`, `F0(v)` and
/// `F0(A)`. Left out, as too small to matter (an experiment correcting them too moved the
/// noise-free tone at 150 Hz by 0.2 m°/s): `F1(B)` (times θ21 ≈ 1e-3), and `F1(A)`,
/// `F0(ωA)` of the Coriolis column (times θ24: a relative change of the rate of ~1e-7).
///
/// With the band taps ([`crate::svf::band_taps`]) `F0` also takes `−a·e0·F2[k]` and
/// `−b·e0·(F2[k] − F2[k−1])`, which even its ratio to the continuous filter with `F1`'s up
/// to 100 Hz (where the ringing of every DDS word step lies; firmware/docs/notes.md "DDS words"). Shipped
/// for the default design ([`crate::svf::BAND_WT`]); another `rate.svf_hz` or `fs_hz` keeps the
/// curvature correction alone.
#[derive(Clone, Copy, Debug, Default)]
struct Curvature<T> {
    e0: T,
    e1: T,
    g: T,
    /// `b·e0` (0: no band taps); `e0` holds `(1 + a + b)·e0`: `F0 − e0·F2[k] + lead·F2[k−1]`.
    lead: T,
}

impl<T: Real> Curvature<T> {
    /// `taps`: the band taps apply (the default design, [`crate::svf::BAND_WT`]). In `T` past the
    /// curvature's `f64` (on the chip no further soft-`f64`: flash).
    fn of(eps: [f64; 3], taps: bool) -> Self {
        let g = 1.0 / (1.0 + eps[2]);
        let e0 = T::from_f64(eps[0] * g);
        let (a, b) = if taps {
            (T::from_f64(BAND_TAPS[0]), T::from_f64(BAND_TAPS[1]))
        } else {
            (T::ZERO, T::ZERO)
        };
        let lead = b * e0;
        Curvature {
            e0: e0 + a * e0 + lead,
            e1: T::from_f64(eps[1] * g),
            g: T::from_f64(g),
            lead,
        }
    }
}

/// Corner of the output's low-pass, Hz: a second-order section on the fast rate after the
/// row's solution. With the wide filter's double real pole (`rate.svf_hz`) and the
/// lock-in's Butterworth it makes the rate's roll-off steeper: less noise at the same
/// bandwidth (host-sim/docs/rate-channel.md). A design constant, not in [`Config`]: a
/// validated configuration field would cost the stm32f405 image flash for no use.
pub const POST_HZ: f64 = 100.0;
/// Damping ζ of the output's low-pass ([`POST_HZ`]).
pub const POST_ZETA: f64 = 0.55;

/// The output's second-order low-pass ([`POST_HZ`], [`POST_ZETA`]): the bilinear
/// transform (not pre-warped) of `w²/(s² + 2ζ w s + w²)`,
/// `y = g(x + 2x₁ + x₂) − a1 y₁ − a2 y₂` (unit DC gain).
#[derive(Clone, Copy, Debug, Default)]
struct PostCoeffs<T> {
    g: T,
    a1: T,
    a2: T,
}

impl<T: Real> PostCoeffs<T> {
    /// In `T` (on the chip the FPU's single precision, no soft-`f64`: flash).
    fn of(hz: f64, zeta: f64, fs_hz: f64) -> Self {
        let w = T::from_f64(2.0 * core::f64::consts::PI * hz);
        let k = T::from_f64(2.0 * fs_hz);
        let (w2, k2, c) = (w * w, k * k, T::from_f64(2.0) * T::from_f64(zeta) * w * k);
        let inv = T::ONE / (k2 + c + w2);
        PostCoeffs {
            g: w2 * inv,
            a1: T::from_f64(2.0) * (w2 - k2) * inv,
            a2: (k2 - c + w2) * inv,
        }
    }
}

/// The state of [`PostCoeffs`]'s section (direct form I: the last two inputs, outputs).
#[derive(Clone, Copy, Debug, Default)]
struct PostState<T> {
    x: [T; 2],
    y: [T; 2],
}

impl<T: Real> PostState<T> {
    /// At rest at `v` (DC gain 1).
    fn at_rest(v: T) -> Self {
        PostState {
            x: [v, v],
            y: [v, v],
        }
    }

    fn update(&mut self, c: &PostCoeffs<T>, x: T) -> T {
        let y = c.g * (x + self.x[0] + self.x[0] + self.x[1]) - c.a1 * self.y[0] - c.a2 * self.y[1];
        self.x = [x, self.x[0]];
        self.y = [y, self.y[0]];
        y
    }
}

/// The fast channel's design (built once from the configuration).
#[derive(Clone, Copy, Debug, Default)]
pub struct RateDesign<T> {
    svf: SvfCoeffs<T>,
    /// The output's low-pass.
    post: PostCoeffs<T>,
    /// The wide filter's curvature correction.
    bias: Curvature<T>,
    /// The narrow channel's filter (corner `rate.coupling_hz`).
    svf_cpl: SvfCoeffs<T>,
    /// θ23 and γ of the design's nominal (the outputs before the first solution).
    th23_ref: T,
    gamma_ref: T,
    /// γ → °/s (ω0·180/π).
    to_dps: f64,
    /// The same in `T`: the outputs are scaled in `T` and widened once (on the chip three
    /// soft-`f64` multiplies per tick less, ≈ 280 instructions; for `T = f64` the same
    /// operations as scaling in `f64`).
    to_dps_t: T,
    /// 1/Ts (per τ): the derivative of the fast rate.
    inv_ts: T,
    /// EWMA weight of the slow averages (1 − λ of the slow RLS).
    alpha_slow: T,
    /// Full scale in γ.
    full_scale: T,
    /// The slow-RLS gate: |γ′| threshold (per τ²) and length (samples).
    gate_accel: T,
    gate_len: u64,
    /// The slow-RLS gate: |θ24 narrow − θ24 slow| threshold (= 2·rate difference).
    gate_dev: T,
    /// (lock threshold in L0)²: below it the fast row is not solved.
    min_amp2: T,
    /// 1/(2ω_ref): quadrature coefficient → rate-equivalent γ.
    inv_2om: T,
    /// ω_ref² (f64: the nominal constant ω_ref² + θ22n is formed in f64).
    om_ref2: f64,
    /// The smallest weight of the rate's zero's mean, [`ZERO_EVERY`]/(`rate.zero_memory_s`·fs)
    /// (1: none).
    zero_alpha: T,
    /// The zero's updates left out after the slow estimate was last unsettled: one slow
    /// memory, `1/(1 − rls.forgetting)` samples, in [`ZERO_EVERY`]s.
    zero_quiet: u32,
}

impl<T: Real> RateDesign<T> {
    /// From a validated configuration.
    #[inline(never)] // set-up only: its own frame
    pub fn of(cfg: &Config) -> Self {
        let omega0 = cfg.omega0_rad_s();
        let ts = omega0 / cfg.fs_hz;
        let wf = 2.0 * core::f64::consts::PI * cfg.rate.svf_hz / omega0;
        let wc = 2.0 * core::f64::consts::PI * cfg.rate.coupling_hz / omega0;
        let (_, th2) = theta_from_physical(&cfg.nominal);
        let om_ref = cfg.pump_centre_hz / (2.0 * cfg.f0_hz);
        let to_dps = omega0 * (180.0 / core::f64::consts::PI);
        let lock = T::from_f64(cfg.retune.lock_min_um / cfg.l0_um);
        // the thresholds in `T` (on the chip FPU operations, not soft-`f64` calls: flash)
        let to_dps_t = T::from_f64(to_dps);
        let inv_dps = T::ONE / to_dps_t;
        RateDesign {
            svf: SvfCoeffs::new(wf, ts),
            post: PostCoeffs::of(POST_HZ, POST_ZETA, cfg.fs_hz),
            bias: Curvature::of(
                parabola_bias::<T>(wf, ts),
                cfg.rate.svf_hz == BAND_SVF_HZ && cfg.fs_hz == BAND_FS_HZ,
            ),
            svf_cpl: SvfCoeffs::new(wc, ts),
            th23_ref: T::from_f64(th2[2]),
            gamma_ref: T::from_f64(cfg.nominal.gamma),
            to_dps,
            to_dps_t,
            inv_ts: T::ONE / T::from_f64(ts),
            alpha_slow: T::from_f64(1.0 - cfg.rls.forgetting),
            full_scale: T::from_f64(cfg.rate.full_scale_dps) * inv_dps,
            gate_accel: T::from_f64(cfg.rate.gate_accel_dps2) * inv_dps / T::from_f64(omega0),
            gate_len: libm::round(cfg.rate.gate_s * cfg.fs_hz).max(0.0) as u64,
            gate_dev: T::from_f64(2.0 * cfg.rate.gate_dev_dps) * inv_dps,
            min_amp2: lock * lock,
            inv_2om: T::from_f64(0.5) / T::from_f64(om_ref),
            om_ref2: om_ref * om_ref,
            zero_alpha: T::from_f64(if cfg.rate.zero_memory_s > 0.0 {
                (ZERO_EVERY as f64 / (cfg.rate.zero_memory_s * cfg.fs_hz)).min(1.0)
            } else {
                1.0
            }),
            zero_quiet: libm::ceil(
                (1.0 / (1.0 - cfg.rls.forgetting)).min(cfg.rate.zero_memory_s * cfg.fs_hz)
                    / ZERO_EVERY as f64,
            ) as u32,
        }
    }

    /// γ → °/s.
    pub fn to_dps(&self) -> f64 {
        self.to_dps
    }

    /// °/s per unit of γ, in `T`.
    pub(crate) fn dps_per_gamma(&self) -> T {
        self.to_dps_t
    }
}

/// The slow parameters the fast row needs, in `T` (the nominal part is refreshed when
/// the linearisation point moves; the RLS deviation is added every sample).
#[derive(Clone, Copy, Debug, Default)]
pub struct SlowTheta<T> {
    /// θ21.
    pub th21: T,
    /// ω_ref² + θ22.
    pub c22: T,
    /// θ23 (quadrature prior).
    pub th23: T,
    /// θ25.
    pub th25: T,
    /// μxy = −(θ14 + θ24)/2.
    pub mu_xy: T,
    /// θ24 (the slow RLS's own, total).
    pub th24: T,
}

/// The nominal part of [`SlowTheta`] (θ_nom in `T`, formed in `f64` once per
/// re-linearisation).
#[derive(Clone, Copy, Debug, Default)]
struct NominalSlow<T> {
    th21: T,
    c22: T,
    th23: T,
    th25: T,
    /// The rate's zero: `mu_nom + zero_dev` ([`RateState::hold_zero`]).
    mu_xy: T,
    /// μxy of the linearisation point.
    mu_nom: T,
    /// The zero's deviation from `mu_nom`, averaged.
    zero_dev: T,
    /// Settled updates in that mean since the last reset (0: it follows the slow RLS).
    zero_n: T,
    /// Updates of the zero still left out since the slow estimate was last unsettled.
    zero_wait: u32,
    /// A covariance reset restarted the zero ([`RateState::restart_zero`]): its mean
    /// starts one slow memory after the estimate settles again.
    zero_restarted: bool,
    th24: T,
    /// The θ_nom components it was formed from (bit patterns; `None`: not yet).
    stamp: Option<[u64; 6]>,
}

/// The unfiltered signals of the fast row at one sample.
#[derive(Clone, Copy, Debug, Default)]
struct RowSignals<T> {
    a: Cplx<T>,
    b: Cplx<T>,
    oma: Cplx<T>,
    omb: Cplx<T>,
    v: Cplx<T>,
}

#[derive(Clone, Copy, Debug, Default)]
struct FastFilters<T> {
    b: CSvfState<T>,
    omb: CSvfState<T>,
    v: CSvfState<T>,
    a: CSvfState<T>,
    oma: CSvfState<T>,
    /// `F2` of `v` and of `A` at the last sample (the band taps).
    f2_last: [Cplx<T>; 2],
}

impl<T: Real> FastFilters<T> {
    fn at_rest(s: &RowSignals<T>) -> Self {
        FastFilters {
            b: CSvfState::at_rest(s.b),
            omb: CSvfState::at_rest(s.omb),
            v: CSvfState::at_rest(s.v),
            a: CSvfState::at_rest(s.a),
            oma: CSvfState::at_rest(s.oma),
            f2_last: [Cplx::default(); 2],
        }
    }

    /// Filters one sample and solves the row: (θ24, θ23, |c23|²). θ24 is the weighted
    /// least squares along the Coriolis column given θ23 = the slow prior; θ23 is then
    /// what is left along the quadrature column.
    #[inline(never)] // twice per tick (wide and narrow): one copy of the code (flash)
    fn solve(
        &mut self,
        c: &SvfCoeffs<T>,
        cv: Option<&Curvature<T>>,
        s: &RowSignals<T>,
        th: &SlowTheta<T>,
    ) -> (T, T, T) {
        let fb = self.b.update(c, s.b);
        let fomb = self.omb.update(c, s.omb);
        let fv = self.v.update(c, s.v);
        let fa = self.a.update(c, s.a);
        let foma = self.oma.update(c, s.oma);
        // the curvature correction where it reaches the rate (`Curvature`)
        let (f2b, f1omb, f0v, f0a) = match cv {
            Some(cv) => {
                let [v1, a1] = core::mem::replace(&mut self.f2_last, [fv.f2, fa.f2]);
                (
                    fb.f2.scale(cv.g),
                    fomb.f1 - fomb.f2.scale(cv.e1),
                    fv.f0 - fv.f2.scale(cv.e0) + v1.scale(cv.lead),
                    fa.f0 - fa.f2.scale(cv.e0) + a1.scale(cv.lead),
                )
            }
            None => (fb.f2, fomb.f1, fv.f0, fa.f0),
        };
        let z = f2b + f1omb.scale(T::from_f64(2.0)).mul_i() - fb.f1.scale(th.th21) + f0v;
        let c23 = f0a;
        let c24 = fa.f1 + foma.f0.mul_i();
        let r = z - c23.scale(th.th23);
        let t24 = (c24.re * r.re + c24.im * r.im) / c24.norm_sqr();
        let q = z - c24.scale(t24);
        let n23 = c23.norm_sqr();
        let t23 = (c23.re * q.re + c23.im * q.im) / n23;
        (t24, t23, n23)
    }
}

/// What the fast channel produced at the last sample.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RateEstimate<T> {
    /// Fast γ (rate in ω0 units).
    pub gamma: T,
    /// Slow γ: the fast one averaged over the slow RLS memory.
    pub gamma_slow: T,
    /// Fast quadrature −θ23 = ωxy² + γ′ (non-dimensional).
    pub quad: T,
    /// The fast row was solved at this sample (else the last values are held).
    pub solved: bool,
    /// The drive amplitude is steady: not ringing down ([`DRIVE_RING2`]; a drive ringing
    /// down makes the row given the slow θ wrong).
    pub steady: bool,
}

/// The floor of |A1|² relative to its slow mean (memory of the slow RLS) to which a drive
/// that rang down must come back, and stay above for [`RING_HOLD`] samples, before it
/// counts as steady again (amplitude ≥ half its mean).
pub const DRIVE_STEADY2: f64 = 0.25;

/// The depth of |A1|² relative to its slow mean below which the drive is ringing down
/// (amplitude below ≈ 32 % of its mean). The pump dither alone moves the amplitude by about
/// ±30 % (1.2–2.1 µm about 1.7 µm in `rate-response`'s base scenario), and where the 5 Hz
/// and 1.3 Hz dithers' phases meet it dips for ≈ 40 ms to 0.17–0.23 of its mean square
/// (0.115 at the deepest, `characterise` seed 25); the row stays right there (the rate's
/// error on those samples 0.31 °/s rms against 0.24 elsewhere, `warm-up`). When the dithers
/// push the drive out of its parametric band it rings down (`characterise` from 14 s: |x1|
/// to 0.2–1.3 µm and below) and falls through this depth; the fast row, given the slow θ,
/// is right on the way down (within 0.9 °/s) but wrong at the bottom and while the drive
/// re-locks (up to 30 °/s off): from this depth on the rate is flagged invalid until the
/// amplitude is back above [`DRIVE_STEADY2`] of its mean for [`RING_HOLD`] samples.
pub const DRIVE_RING2: f64 = 0.1;

/// Samples (50 ms at 500 Hz) the drive must stay above [`DRIVE_STEADY2`] after a
/// ring-down before it counts as steady: while it re-locks its amplitude jumps back above
/// the floor for a sample or two (a valid sample 5.3 °/s off without the hold,
/// `characterise` seed 25 at 17.246 s).
pub const RING_HOLD: u32 = 25;

/// A warm start's zero counts as at most this many seconds of settled updates
/// ([`RateState::restore_zero`]): its mean goes on from the stored one, and what the device
/// does after the restart outweighs it within this time (a μxy that moved while it was off).
pub const ZERO_RESTORE_S: f64 = 600.0;

/// The rate's zero is updated once in this many samples (the estimator's decision
/// interval: it takes a phase of it that no decision, no thermal block falls on, so the
/// tick's largest cost does not grow); its memory is hundreds of seconds.
pub const ZERO_EVERY: u32 = 25;

/// The fast channel's state.
#[derive(Clone, Copy, Debug, Default)]
pub struct RateState<T> {
    f: FastFilters<T>,
    /// The same row through the narrow channel's filter.
    fc: FastFilters<T>,
    started: bool,
    nom: NominalSlow<T>,
    est: RateEstimate<T>,
    /// The narrow channel's last γ (its derivative is γ′).
    gamma_cpl: T,
    /// The output low-pass on the wide channel's γ.
    post: PostState<T>,
    /// The first solution has been made (the derivative starts from it).
    primed: bool,
    /// Slow mean of |A1|² over solved samples (the steadiness test).
    amp2_slow: T,
    /// Samples still to wait before the drive counts as steady again: set to
    /// [`RING_HOLD`] while |A1|² is below [`DRIVE_STEADY2`] of its slow mean after it fell
    /// below [`DRIVE_RING2`] of it (a ring-down), counted down on samples above.
    ring_hold: u32,
    /// The slow RLS is gated until this sample (the rate moved).
    gate_until: u64,
    /// The rate's acceleration (`fast`) opened or renewed a gate less than a gate's length
    /// before this sample.
    fast_until: u64,
    /// Samples of the current hold that the narrow channel's rate has been still for.
    held: u32,
    /// The hand-over due (Δθ24), 0 if none.
    handover: T,
    /// The narrow channel's θ24 averaged over ≈ 0.26 s (an EMA of 1/128 per sample).
    t24_avg: T,
    /// The rate moved (fast, or away from the slow RLS's) less than a gate's length ago,
    /// whether or not the slow RLS is gated: the slow RLS's rate walks until this sample.
    moving_until: u64,
    /// The slow identification has settled once since start-up.
    settled_once: bool,
    /// Settled samples still to wait after the drive lost its lock (see `assess`).
    relock: u32,
    /// The narrow channel's quadrature agrees with the slow θ23 (this sample).
    quad_ok: bool,
    valid: bool,
}

impl<T: Real> RateState<T> {
    /// The start-up state: filters at rest at the first sample, the rate at the design's
    /// reference until the first solution.
    pub fn new(d: &RateDesign<T>) -> Self {
        RateState {
            est: RateEstimate {
                gamma: d.gamma_ref,
                gamma_slow: d.gamma_ref,
                quad: -d.th23_ref,
                solved: false,
                steady: false,
            },
            ..RateState::default()
        }
    }

    /// Re-forms the nominal part of the slow θ when the linearisation point moved
    /// (compared bit for bit: integer compares, no soft-float on the chip).
    #[inline(always)]
    pub fn refresh_nominal(&mut self, d: &RateDesign<T>, th1n: &[f64; 8], th2n: &[f64; 6]) {
        let key = [
            th1n[3].to_bits(),
            th2n[0].to_bits(),
            th2n[1].to_bits(),
            th2n[2].to_bits(),
            th2n[3].to_bits(),
            th2n[4].to_bits(),
        ];
        // word-wise, no early exit: `==` on the arrays became a byte-wise memcmp,
        // ≈ 350 instructions per tick on the chip (firmware/scripts/fil-profile.sh)
        if let Some(stamp) = self.nom.stamp {
            let diff = stamp
                .iter()
                .zip(key.iter())
                .fold(0u64, |acc, (a, b)| acc | (a ^ b));
            if diff == 0 {
                return;
            }
        }
        let mu_nom = T::from_f64(-0.5 * (th1n[3] + th2n[3]));
        // the held mean is a deviation from the nominal: it keeps its total
        let zero_dev = if self.nom.stamp.is_some() {
            self.nom.zero_dev + (self.nom.mu_nom - mu_nom)
        } else {
            T::ZERO
        };
        self.nom = NominalSlow {
            th21: T::from_f64(th2n[0]),
            c22: T::from_f64(d.om_ref2 + th2n[1]),
            th23: T::from_f64(th2n[2]),
            th25: T::from_f64(th2n[4]),
            mu_xy: mu_nom + zero_dev,
            mu_nom,
            zero_dev,
            zero_n: self.nom.zero_n,
            zero_wait: self.nom.zero_wait,
            zero_restarted: self.nom.zero_restarted,
            th24: T::from_f64(th2n[3]),
            stamp: Some(key),
        };
    }

    /// The slow θ the fast row needs: the nominal part plus the RLS deviations
    /// `dev14`, `dev2[..]` (already multiplied by the column scales); μxy is the rate's
    /// held zero ([`RateState::hold_zero`]).
    #[inline(always)]
    pub fn slow_theta(&self, dev2: &[T; 6]) -> SlowTheta<T> {
        let n = &self.nom;
        SlowTheta {
            th21: n.th21 + dev2[0],
            c22: n.c22 + dev2[1],
            th23: n.th23 + dev2[2],
            th25: n.th25 + dev2[4],
            mu_xy: n.mu_xy,
            th24: n.th24 + dev2[3],
        }
    }

    /// The rate's zero, μxy, every [`ZERO_EVERY`] samples: the slow RLS's μ̂xy (from its
    /// deviations `dev14`, `dev24`) averaged over the settled samples since its last reset,
    /// with weight `1/n` down to `rate.zero_memory_s`'s. The cross-damping does not move
    /// with temperature, and the slow RLS's 2 s memory would pass its estimation noise
    /// (mostly the drive's θ14: a tenth of a °/s over 10 s) into the rate's low
    /// frequencies. Until the first settled sample after the boot the zero follows the
    /// slow RLS, and after a covariance reset until one slow memory after the estimate
    /// settles again ([`Self::restart_zero`]); while the slow estimate is not settled (a
    /// gate, a change pending) a started mean is held, and for one slow memory after too:
    /// θ14 and θ24 re-converge at their own speeds after a rate step (the drive's rows
    /// resolve the rate less well), and their sum carries the step until they have.
    #[inline(always)]
    pub fn hold_zero(&mut self, d: &RateDesign<T>, dev14: T, dev24: T, settled: bool) {
        let n = &mut self.nom;
        let mu_dev = -T::from_f64(0.5) * (dev14 + dev24);
        // before the mean has started (`zero_n` 0) the zero follows the slow RLS; the wait
        // holds a started mean, and after a reset keeps the zero following through the
        // first slow memory of the re-settled estimate (the boot's first settle starts it)
        let started = n.zero_n > T::ZERO;
        if !settled {
            if started || n.zero_restarted {
                n.zero_wait = d.zero_quiet;
            }
            if !started {
                n.zero_dev = mu_dev;
            }
        } else if n.zero_wait > 0 {
            n.zero_wait -= 1;
            if !started {
                n.zero_dev = mu_dev;
            }
        } else {
            n.zero_n += T::ONE;
            let a = T::ONE / n.zero_n;
            let a = if a > d.zero_alpha { a } else { d.zero_alpha };
            n.zero_dev += a * (mu_dev - n.zero_dev);
        }
        n.mu_xy = n.mu_nom + n.zero_dev;
    }

    /// A covariance reset: the rate's zero follows the slow RLS again until one slow
    /// memory after it settles. The re-identification's first memory after the settle
    /// still carries the drive's θ14 re-converging (the drive's rows resolve it poorly),
    /// which a mean started at the settle would keep for its whole memory.
    pub fn restart_zero(&mut self) {
        self.nom.zero_n = T::ZERO;
        self.nom.zero_wait = 0;
        self.nom.zero_restarted = true;
    }

    /// The rate's zero, μxy, and the settled updates in its mean (0: it follows the slow
    /// RLS): what a warm start restores ([`Self::restore_zero`]).
    pub fn zero(&self) -> (f64, f64) {
        (self.nom.mu_xy.to_f64(), self.nom.zero_n.to_f64())
    }

    /// A warm start's zero: the stored μxy as a mean of `n` settled updates (at most
    /// [`ZERO_RESTORE_S`] of them), kept as a total through the next re-linearisation;
    /// `n` not finite and positive, or μxy not finite: [`Self::restart_zero`].
    pub fn restore_zero(&mut self, mu_xy: f64, n: f64, fs_hz: f64) {
        let cap = ZERO_RESTORE_S * fs_hz / ZERO_EVERY as f64;
        if !(mu_xy.is_finite() && n.is_finite() && n >= 1.0) {
            self.restart_zero();
            return;
        }
        let mu = T::from_f64(mu_xy);
        // the total is `mu_nom + zero_dev`: with `mu_nom` the stored zero and no stamp
        // that can match, the next nominal keeps it as its deviation
        self.nom.mu_nom = mu;
        self.nom.zero_dev = T::ZERO;
        self.nom.mu_xy = mu;
        self.nom.zero_n = T::from_f64(n.min(cap));
        self.nom.zero_wait = 0;
        self.nom.stamp = Some([u64::MAX; 6]);
    }

    /// One sample: filters the row in both channels and solves it (when the drive is
    /// large enough); at sample `k`, while the slow estimate is settled (`slow_settled`),
    /// a move of the rate (the narrow channel's) gates the slow RLS
    /// ([`RateState::gates`]); while the die temperature moves (`temp_moving`) a gate the
    /// quadrature leaves too ends (a drift). `y3` is the sense cube's fundamental
    /// `[Y³]₁` (the rows' projection).
    #[inline(always)]
    pub fn track(
        &mut self,
        d: &RateDesign<T>,
        e: &Envelopes<T>,
        kn: &Known<T>,
        y3: Cplx<T>,
        th: &SlowTheta<T>,
        (k, slow_settled, temp_moving): (u64, bool, bool),
    ) {
        let (a, b) = (e.a[0], e.b[0]);
        let om = kn.om;
        let lin = th.c22 + kn.dom2;
        let sig = RowSignals {
            a,
            b,
            oma: a.scale(om),
            omb: b.scale(om),
            // v = −i ω′B − i θ21 ωB − (ω² + θ22) B − θ25 [Y³]₁ (small by construction)
            v: -(b.scale(kn.omd) + b.scale(om * th.th21)).mul_i()
                - b.scale(lin)
                - y3.scale(th.th25),
        };
        if !self.started {
            self.f = FastFilters::at_rest(&sig);
            self.fc = FastFilters::at_rest(&sig);
            self.started = true;
        }
        let (t24, t23, n23) = self.f.solve(&d.svf, Some(&d.bias), &sig, th);
        let (t24c, t23c, _) = self.fc.solve(&d.svf_cpl, None, &sig, th);
        let gamma = -(t24 + th.mu_xy) * T::from_f64(0.5);
        let gamma_c = -(t24c + th.mu_xy) * T::from_f64(0.5);
        let big = d.full_scale + d.full_scale;
        let solvable = a.norm_sqr() >= d.min_amp2
            && n23 > T::ZERO
            && n23.is_finite()
            && t23.is_finite()
            && gamma.is_finite()
            && gamma_c.is_finite()
            && gamma.abs() <= big;
        self.est.solved = solvable;
        if !solvable {
            self.est.steady = false;
            self.ring_hold = RING_HOLD;
            self.quad_ok = false;
            return;
        }
        let a2 = a.norm_sqr();
        let prev = if self.primed { self.gamma_cpl } else { gamma_c };
        if !self.primed {
            self.amp2_slow = a2;
            self.post = PostState::at_rest(gamma);
        }
        self.primed = true;
        // the common path (no ring-down) is one product and one comparison
        if a2 < T::from_f64(DRIVE_RING2) * self.amp2_slow {
            self.ring_hold = RING_HOLD;
        } else if self.ring_hold > 0 {
            if a2 < T::from_f64(DRIVE_STEADY2) * self.amp2_slow {
                self.ring_hold = RING_HOLD;
            } else {
                self.ring_hold -= 1;
            }
        }
        let steady = self.ring_hold == 0;
        self.amp2_slow += d.alpha_slow * (a2 - self.amp2_slow);
        self.est.steady = steady;
        self.gamma_cpl = gamma_c;
        let gamma = self.post.update(&d.post, gamma);
        self.est.gamma = gamma;
        self.est.quad = -t23;
        self.est.gamma_slow += d.alpha_slow * (gamma - self.est.gamma_slow);
        let gp = (gamma_c - prev) * d.inv_ts;
        // the rate moved (fast, or away from the slow RLS's) while the quadrature agrees
        // with the slow θ23: a drift of the device (ωy², damping) shows in both
        // directions of the row and is left to the slow RLS
        // ≈ 0.26 s at 500 Hz (a power of two: no design-time constant)
        self.t24_avg += (t24c - self.t24_avg) * T::from_f64(1.0 / 128.0);
        let fast = gp.abs() > d.gate_accel;
        let moved = fast || (t24c - th.th24).abs() > d.gate_dev;
        let quad_ok = (t23c - th.th23).abs() < d.gate_dev;
        self.quad_ok = quad_ok;
        if moved && quad_ok {
            self.moving_until = k + d.gate_len;
        }
        if slow_settled && moved && quad_ok && steady {
            self.gate_until = k + d.gate_len;
            if fast {
                self.fast_until = self.gate_until;
            }
            // a hold the slow RLS cannot end (after a step its own departure from the new
            // rate renews the gate): once the narrow channel's rate has stayed within the
            // gate's deviation of its own average for a gate's length, the slow estimate
            // takes that average (θ24 + Δ, θ14 − Δ), still gated. A sine or a ramp never
            // stays that still; the average lags a step (≈ 0.3 °/s left after 50 °/s), and
            // the rest is the slow RLS's once the gate ends
            let still = !fast && (t24c - self.t24_avg).abs() < d.gate_dev;
            self.held = if still {
                self.held.saturating_add(1)
            } else {
                0
            };
            let delta = self.t24_avg - th.th24;
            if u64::from(self.held) >= d.gate_len && delta.abs() > d.gate_dev {
                self.handover = delta;
                self.held = 0;
            }
        } else {
            self.held = 0;
            // a gate the rate's departure alone opened, whose quadrature has since left the
            // slow θ23 too, while the die temperature moves (module `thermal`): the onset
            // of a drift (ωy² moves both directions of the row, in a ratio the noise decides
            // which crosses the tolerance first), not a move of the rate: it ends, and the
            // slow RLS follows the drift with its walk (modules `drift`, `thermal`; a 20 s
            // warm-up's onset otherwise held the slow RLS for the whole gate while ωy²
            // moved, and the change detector reset it at the gate's end). A gate the
            // acceleration opened or renewed within a gate's length (a step, a sine)
            // holds; at a steady or unknown temperature every gate runs its length and a
            // change of the device is the change detector's once it ends (a jump is
            // detected and re-identified either way).
            if temp_moving && !quad_ok && k < self.gate_until && k >= self.fast_until {
                self.gate_until = k;
            }
        }
    }

    /// The move Δ of θ24 the slow estimate must take now (θ24 + Δ, θ14 − Δ: a new rate,
    /// μxy unchanged), once; 0 when none is due.
    pub fn take_handover(&mut self) -> T {
        core::mem::replace(&mut self.handover, T::ZERO)
    }

    /// The drive is steady: not ringing down ([`DRIVE_RING2`]) and solvable.
    #[inline(always)]
    pub fn drive_steady(&self) -> bool {
        self.started && self.ring_hold == 0
    }

    /// The rate moved less than a gate's length before sample `k` (the slow RLS's rate
    /// walks).
    pub fn moving(&self, k: u64) -> bool {
        k < self.moving_until
    }

    /// The slow RLS must not update at sample `k` (the rate is moving fast).
    pub fn gates(&self, k: u64) -> bool {
        k < self.gate_until
    }

    /// The validity of this sample's rate (module docs), given the health of the step.
    #[inline(always)]
    pub fn assess(
        &mut self,
        d: &RateDesign<T>,
        inputs_valid: bool,
        drive_locked: bool,
        settled: bool,
        change_pending: bool,
    ) -> bool {
        if settled && !self.settled_once {
            self.est.gamma_slow = self.est.gamma;
        }
        self.settled_once |= settled;
        // a drive that lost its lock fed the slow RLS rows of a vanishing amplitude, and its
        // θ may have jumped, the narrow channel's rate with them, so the gate does not see
        // it (`characterise` at s = 1.15 had valid samples 10 °/s off after one, until the
        // slow RLS updated again): after a lock loss the rate waits for a gate length of
        // samples on which the slow identification is settled (updating, not gated)
        if !drive_locked {
            if self.settled_once {
                self.relock = d.gate_len as u32;
            }
        } else if settled {
            self.relock = self.relock.saturating_sub(1);
        }
        self.valid = inputs_valid
            && drive_locked
            && self.settled_once
            && self.relock == 0
            && !change_pending
            && self.est.solved
            && self.est.steady
            && self.quad_ok
            && self.est.gamma.abs() <= d.full_scale;
        self.valid
    }

    /// The last estimate.
    pub fn estimate(&self) -> &RateEstimate<T> {
        &self.est
    }

    /// The last validity.
    pub fn valid(&self) -> bool {
        self.valid
    }

    /// The step's output in engineering units.
    pub fn output(&self, d: &RateDesign<T>) -> RateOutput {
        let e = &self.est;
        RateOutput {
            rate_dps: (e.gamma * d.to_dps_t).to_f64(),
            rate_slow_dps: (e.gamma_slow * d.to_dps_t).to_f64(),
            quadrature_dps: (e.quad * d.inv_2om * d.to_dps_t).to_f64(),
            valid: self.valid,
        }
    }
}

/// The rate channel's part of a step's output ([`crate::StepOutput::rate`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RateOutput {
    /// The fast rate, °/s (every sample; see [`RateOutput::valid`]).
    pub rate_dps: f64,
    /// The slow rate, °/s: the fast one averaged over the slow RLS memory (≈ 2 s).
    pub rate_slow_dps: f64,
    /// The quadrature (ωxy² + γ′) as a rate-equivalent, °/s: ωxy²/(2ω)·ω0 — the error
    /// term a real gyro fights; it is in phase with the drive displacement, the rate
    /// with its velocity.
    pub quadrature_dps: f64,
    /// Valid: inputs valid, drive locked, slow estimate settled once and no change
    /// pending, row solvable, within full scale.
    pub valid: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The output section at rest stays at rest (unit DC gain), and a sine at its corner
    /// comes out with the prototype's gain 1/(2ζ) (the bilinear transform moves the corner to
    /// `fs/π·atan(π·POST_HZ/fs)`: the gain is checked there).
    #[test]
    fn the_output_section_has_unit_dc_gain_and_the_prototypes_peak_at_its_corner() {
        let fs = 500.0;
        let c = PostCoeffs::<f64>::of(POST_HZ, POST_ZETA, fs);
        let mut s = PostState::at_rest(0.37);
        for _ in 0..100 {
            assert!((s.update(&c, 0.37) - 0.37).abs() < 1e-15);
        }
        let f = fs / core::f64::consts::PI * libm::atan(core::f64::consts::PI * POST_HZ / fs);
        let w = 2.0 * core::f64::consts::PI * f / fs;
        let mut s = PostState::at_rest(0.0);
        let mut peak: f64 = 0.0;
        for k in 0..4000 {
            let y = s.update(&c, libm::sin(w * f64::from(k)));
            if k >= 2000 {
                peak = peak.max(y.abs());
            }
        }
        let want = 1.0 / (2.0 * POST_ZETA);
        assert!((peak - want).abs() < 0.01 * want, "{peak} against {want}");
    }

    /// After the slow estimate was unsettled (a gate) the zero's mean is held for one slow
    /// memory (`1/(1 − λ)` samples): a re-converging μ̂xy in that time does not enter it, one
    /// after it does; after a reset the mean starts at the first settled sample.
    #[test]
    fn the_zero_is_held_for_one_slow_memory_after_a_gate() {
        let cfg = Config::table2();
        let d = RateDesign::<f64>::of(&cfg);
        let memory = 1.0 / (1.0 - cfg.rls.forgetting);
        assert_eq!(d.zero_quiet as f64, libm::ceil(memory / ZERO_EVERY as f64));
        let mut s = RateState::new(&d);
        // settled: the mean takes μ̂xy's deviation (dev14 = dev24 = −1e-6: μ = +1e-6)
        for _ in 0..10 {
            s.hold_zero(&d, -1e-6, -1e-6, true);
        }
        let held = s.nom.zero_dev;
        assert!((held - 1e-6).abs() < 1e-18, "{held}");
        // a gate, then a re-convergence 1e-5 off for one memory: held throughout
        s.hold_zero(&d, 0.0, 0.0, false);
        for _ in 0..d.zero_quiet {
            s.hold_zero(&d, -1e-5, -1e-5, true);
            assert_eq!(s.nom.zero_dev, held);
        }
        // then averaged again
        s.hold_zero(&d, -1e-5, -1e-5, true);
        assert!(s.nom.zero_dev > held, "{} after the memory", s.nom.zero_dev);
        // after a reset the zero follows the slow RLS through the re-settled estimate's
        // first slow memory (its θ14 still re-converging), then the mean starts again
        s.restart_zero();
        s.hold_zero(&d, 0.0, 0.0, false);
        for i in 0..d.zero_quiet {
            let dev = -1e-6 * f64::from(i + 1);
            s.hold_zero(&d, dev, dev, true);
            assert!((s.nom.zero_dev + dev).abs() < 1e-18, "{}", s.nom.zero_dev);
            assert_eq!(s.zero().1, 0.0, "not averaged while it follows");
        }
        s.hold_zero(&d, -3e-6, -3e-6, true);
        assert_eq!(s.zero().1, 1.0);
        assert!((s.nom.zero_dev - 3e-6).abs() < 1e-18, "{}", s.nom.zero_dev);
    }

    /// At the boot the mean starts on the first settled update (no reset has restarted
    /// it; a warm start restores it).
    #[test]
    fn at_the_boot_the_zero_is_averaged_from_the_first_settled_update() {
        let cfg = Config::table2();
        let d = RateDesign::<f64>::of(&cfg);
        let mut s = RateState::new(&d);
        s.hold_zero(&d, -2e-6, -2e-6, false);
        assert!((s.nom.zero_dev - 2e-6).abs() < 1e-18);
        s.hold_zero(&d, -1e-6, -1e-6, true);
        assert_eq!(s.zero().1, 1.0);
        assert!((s.nom.zero_dev - 1e-6).abs() < 1e-18, "{}", s.nom.zero_dev);
    }

    /// A restored zero is kept as a total through the re-linearisation that follows a
    /// warm start (the nominal re-formed about other θ̂), held while the estimate is not
    /// settled, then averaged on with the restored count: a settled μ̂xy 1e-6 away moves
    /// it by 1e-6/(n + 1), not to it.
    #[test]
    fn a_restored_zero_is_kept_through_the_relinearisation_and_averaged_on() {
        let cfg = Config::table2();
        let d = RateDesign::<f64>::of(&cfg);
        let mut s = RateState::new(&d);
        let (t1, t2) = crate::physics::theta_from_physical(&cfg.nominal);
        s.refresh_nominal(&d, &t1, &t2);
        let mu = 1.3e-4;
        s.restore_zero(mu, 1e9, cfg.fs_hz);
        let cap = ZERO_RESTORE_S * cfg.fs_hz / ZERO_EVERY as f64;
        assert_eq!(s.zero(), (mu, cap));
        // the linearisation point moves (a warm start's θ̂): the total stays
        let mut t1w = t1;
        let mut t2w = t2;
        t1w[3] *= 1.1;
        t2w[3] *= 0.9;
        s.refresh_nominal(&d, &t1w, &t2w);
        assert!((s.zero().0 - mu).abs() < 1e-18, "{}", s.zero().0);
        // unsettled (the warm gate): held
        s.hold_zero(&d, -1e-6, -1e-6, false);
        assert!((s.zero().0 - mu).abs() < 1e-18);
        // settled, after the quiet: one update 1e-6 away moves it by 1e-6/(n + 1)
        for _ in 0..d.zero_quiet {
            s.hold_zero(&d, 0.0, 0.0, true);
        }
        let before = s.zero().0;
        let mu_nom = -0.5 * (t1w[3] + t2w[3]);
        // dev14 = dev24 = −(the restored zero − μ_nom) − 1e-6: μ̂xy = the zero + 1e-6
        let dev = -(before - mu_nom) - 1e-6;
        s.hold_zero(&d, dev, dev, true);
        let moved = s.zero().0 - before;
        assert!(
            (moved - 1e-6 / (cap + 1.0)).abs() < 1e-6 / cap * 1e-6,
            "{moved:e}"
        );
        // a record without a zero: the mean restarts
        s.restore_zero(mu, 0.0, cfg.fs_hz);
        assert_eq!(s.zero().1, 0.0);
    }
}
