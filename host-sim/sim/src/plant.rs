//! The full-rate simulated gyro: paper eq. (6) integrated with fixed-step RK4, plus the
//! analog lock-in front end of [`crate::lockin`], sampled at the 500 Hz estimator rate.
//!
//! # Model (DERIVATION.md §0, non-dimensional time τ = ω0·t, length unit L0 = 1 µm)
//!
//! ```text
//! X'' = θ11 X' + [θ12 + (s−1)θ16] X + θ13 Y + θ14 Y' + [θ15 + (s−1)θ17] X³
//!       + s θ16 X cos2ψ + s θ17 X³ cos2ψ + θ18 ãx
//! Y'' = θ21 Y' + θ22 Y + θ23 X + θ24 X' + θ25 Y³ + θ26 ãy,        ψ' = ω(τ)
//! ```
//!
//! with θ1 (8, [`Theta::drive`]) and θ2 (6, [`Theta::sense`]) in the order of the
//! paper's eq. (25). The right-hand side lives in one function, `rhs`; new physical
//! effects are added there as switchable terms without touching the integrator. The
//! measurement (`Xm = X + n_x`, `Ym = Y + n_y`) lives in one function, `measure`.
//! A term the simulator does not know comes in through [`hook`] (a force, two states of
//! its own and a pick-off offset, carried by [`Effects::hook`]).
//!
//! # Time grid
//!
//! [`GyroSim::advance`] moves the plant by exactly one sample period `Ts = ω0/fs`
//! (135.7 τ at 500 Hz) with `M` classic RK4 steps, `M` chosen so that there are at
//! least `steps_per_period` steps per carrier period `2π/ω_max` (rounded up to a
//! multiple of the lock-in block length, 32 by default; M = 2912 with the defaults).
//! The inputs `ω, s, ãx, ãy` are linear in time over the interval (the DDS sweeps
//! linearly between 500 Hz updates); θ is constant over the interval.
//!
//! # Pump and reference phase
//!
//! ψ is the exact integral of the piecewise-linear ω: `ψ(τ) = ψ_k + ω_k τ + ½ω̇τ²`. It is
//! kept wrapped to [−π, π] in `f64` (Cody–Waite reduction, so no drift accumulates).
//! The RK4 stages and the lock-in need `e^{iψ}` on the half-step grid `τ_j = j·h/2`;
//! because the second difference of ψ on that grid is the constant `ω̇(h/2)²`, the
//! phasor is advanced exactly by two complex multiplications per half step
//! (`r ← r·d`, `d ← d·e^{iω̇(h/2)²}`) and re-synchronised with `sin_cos` at the start of
//! every lock-in block (every 32 steps by default), so rounding never accumulates beyond
//! ~1e-13.
//!
//! # Noise
//!
//! White displacement noise of one-sided density `noise_density` (L0/√Hz), an
//! independent normal of std `σ = density·√(1/(2 h_sec))` per fine step on each axis
//! (as the prototype's `noise_sigma_per_step`). It enters only the measurement. The
//! generator is `Xoshiro256PlusPlus` seeded from [`SimConfig::seed`]; with a density of
//! 0 no random numbers are drawn and the run is exactly deterministic.

use crate::effects::{ES_C3, Effects};
use crate::lockin::{BlockLpf, LockinExt, LockinOut, mixer_products};
use hook::HOOK_STATES;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

pub use paragyro_core::physics::OMEGA0_TABLE2_RAD_S;

mod forcing;
pub mod hook;
pub mod prewarp;

use forcing::Forcing;

/// Table 2 Coriolis coefficient γ (150 °/s), the core's `TABLE2.gamma`.
pub const GAMMA_TABLE2: f64 = paragyro_core::physics::TABLE2.gamma;

/// Table 2 non-dimensional acceleration ã = 10 g/(L0 ω0²).
pub const ACCEL_TABLE2: f64 = 0.0213;

/// Candidate lock-in block lengths in fine steps (see [`crate::lockin`]), longest
/// first: the longest one whose block is short against the low-pass
/// (`wc·T ≤ BLOCK_WC_T`) is used, and `M` is rounded up to a multiple of it.
const LOCKIN_BLOCKS: [usize; 4] = [32, 16, 8, 4];

/// Largest `wc·T` for a lock-in block (0.022 with the defaults, where the lock-in
/// matches the continuous filter to ≲ 1e-12 for slow inputs and ≲ 2e-11 of the carrier
/// components; that error grows roughly as `(wc·T)⁴`).
const BLOCK_WC_T: f64 = 0.03;

/// Largest accepted number of fine steps per sample (guards against absurd configs).
const MAX_STEPS_PER_SAMPLE: usize = 10_000_000;

/// The parameter vectors of eq. (6) in the order of the paper's eq. (25).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Theta {
    /// θ1 = [−μx, −(ωx²−γ²+2β1), −(ωxy²−γ'), −(μxy−2γ), −(2β3+αx), −2β1, −2β3, 1].
    pub drive: [f64; 8],
    /// θ2 = [−μy, −(ωy²−γ²), −(ωxy²+γ'), −(μxy+2γ), −αy, 1].
    pub sense: [f64; 6],
}

impl Theta {
    /// The nominal parameters of the paper's Table 2 (γ = 3.8581e-5, ωy² = 1.0265).
    pub fn table2() -> Self {
        let t = &paragyro_core::physics::TABLE2;
        let g = t.gamma;
        Self {
            drive: [
                -t.mu_x,
                -(t.wx2 - g * g + 2.0 * t.beta1),
                -t.wxy2,
                -(t.mu_xy - 2.0 * g),
                -(2.0 * t.beta3 + t.alpha_x),
                -2.0 * t.beta1,
                -2.0 * t.beta3,
                t.c_ax,
            ],
            sense: [
                -t.mu_y,
                -(t.wy2 - g * g),
                -t.wxy2,
                -(t.mu_xy + 2.0 * g),
                -t.alpha_y,
                t.c_ay,
            ],
        }
    }

    /// The same parameters with the sense natural frequency moved to `wy2` = ωy²
    /// (θ22 = −(ωy² − γ²), with γ recovered from θ14 − θ24).
    pub fn with_wy2(mut self, wy2: f64) -> Self {
        let g = (self.drive[3] - self.sense[3]) / 4.0;
        self.sense[1] = -(wy2 - g * g);
        self
    }
}

/// The known inputs of the plant at one instant (non-dimensional).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantInputs {
    /// Reference frequency ω = ψ' (half the pump frequency), in units of ω0.
    pub omega: f64,
    /// Pump voltage scale s = V_A²/V_A0² (1 nominal).
    pub s: f64,
    /// Drive-axis acceleration ãx.
    pub ax: f64,
    /// Sense-axis acceleration ãy.
    pub ay: f64,
}

impl PlantInputs {
    /// Operating point "A" of FINDINGS §1: ω = √1.0265, s = 1, ãx = ãy = 0.0213 (10 g).
    pub fn nominal() -> Self {
        Self {
            omega: 1.0265f64.sqrt(),
            s: 1.0,
            ax: ACCEL_TABLE2,
            ay: ACCEL_TABLE2,
        }
    }
}

/// Settings of the simulated gyro and its lock-in (SI units where they have units).
#[derive(Clone, Debug)]
pub struct SimConfig {
    /// Time scale ω0, rad/s (τ = ω0·t).
    pub omega0_rad_s: f64,
    /// Estimator sample rate, Hz (one [`GyroSim::advance`] per sample).
    pub fs_hz: f64,
    /// Minimum RK4 steps per carrier period at `omega_max` (128 for identification
    /// data, FINDINGS §1).
    pub steps_per_period: usize,
    /// Largest reference frequency ω (units of ω0) that the run will use.
    pub omega_max: f64,
    /// Lock-in low-pass order (Butterworth, 1..=8).
    pub lpf_order: usize,
    /// Lock-in low-pass cut-off, Hz.
    pub lpf_hz: f64,
    /// One-sided white displacement-noise density on X and Y, L0/√Hz (1e-6 = 1 pm/√Hz).
    pub noise_density: f64,
    /// Seed of the noise generator.
    pub seed: u64,
}

impl Default for SimConfig {
    /// ω0 = 67 858 rad/s, 500 Hz, 128 steps/period at ω ≤ 1.05, 4th-order 150 Hz
    /// low-pass, 1 pm/√Hz, seed 1.
    fn default() -> Self {
        Self {
            omega0_rad_s: OMEGA0_TABLE2_RAD_S,
            fs_hz: 500.0,
            steps_per_period: 128,
            omega_max: 1.05,
            lpf_order: 4,
            lpf_hz: 150.0,
            noise_density: 1e-6,
            seed: 1,
        }
    }
}

/// Measurement noise source. With `sigma == 0` it is never drawn from.
#[derive(Clone, Debug)]
struct Noise {
    rng: Xoshiro256PlusPlus,
    /// Std per fine step on each axis, L0.
    sigma: f64,
}

impl Noise {
    /// One noise sample `[n_x, n_y]` if `ON`, exact zeros (no draw) otherwise.
    #[inline(always)]
    fn draw<const ON: bool>(&mut self) -> [f64; 2] {
        if ON {
            let a: f64 = StandardNormal.sample(&mut self.rng);
            let b: f64 = StandardNormal.sample(&mut self.rng);
            [self.sigma * a, self.sigma * b]
        } else {
            [0.0; 2]
        }
    }
}

/// The simulated gyro: state of eq. (6), reference phase, lock-in filters and noise.
///
/// ```
/// use paragyro_simulator::lockin::LockinExt;
/// use paragyro_simulator::plant::{GyroSim, PlantInputs, SimConfig, Theta};
/// let cfg = SimConfig { noise_density: 0.0, ..SimConfig::default() };
/// let mut sim = GyroSim::new(&cfg, [0.01, 0.0, 0.0, 0.0]).unwrap();
/// let (th, u) = (Theta::table2(), PlantInputs::nominal());
/// for _ in 0..5 {
///     sim.advance(&th, &u, &u); // one 500 Hz sample each
/// }
/// let out = sim.lockin();
/// assert!(out.x_abs(1) > 0.0 && sim.time_tau() > 600.0);
/// ```
#[derive(Clone, Debug)]
pub struct GyroSim {
    /// Fine RK4 steps per sample.
    m: usize,
    /// Sample period, τ.
    ts: f64,
    /// Fine step, τ.
    h: f64,
    /// [X, X', Y, Y'] at the current time.
    z: [f64; 4],
    /// Reference phase at the current time, wrapped to [−π, π].
    psi: f64,
    /// Samples advanced so far.
    k: u64,
    /// Lock-in filter bank (14 channels).
    lpf: BlockLpf,
    /// Noise source (`sigma == 0`: noise-free run, nothing drawn).
    noise: Noise,
    /// Effects beyond eq. (6) (all zero: the nominal model, and the fast path).
    fx: Effects,
    /// The effect terms of `fx` ([`terms_of`]): the integrator's variant.
    terms: u8,
    /// Angular vibration frequency Ω_v/ω0 (non-dimensional).
    vib_omega: f64,
    /// Angular vibration phase Ω_v·τ at the current time, wrapped.
    vib_phase: f64,
    /// The external term's own states ([`hook`]; 0 without one).
    w: [f64; HOOK_STATES],
}

/// Pump and reference quantities at one instant, as seen by `rhs` and `measure`.
#[derive(Clone, Copy, Debug)]
struct Drive {
    /// cos 2ψ.
    cos2psi: f64,
    /// Pump voltage scale s.
    s: f64,
    /// ãx.
    ax: f64,
    /// ãy.
    ay: f64,
    /// Angular vibration γ1·sin(Ω_v τ) (0 without the effect).
    gv: f64,
    /// Its derivative γ1·Ω_v·cos(Ω_v τ).
    gvd: f64,
}

// =======================================================================================
// THE RIGHT-HAND SIDE OF EQ. (6). Every physical effect of the plant goes here (add new
// ones as switchable terms); the integrator below never needs to change.
// =======================================================================================
/// `d/dτ [X, X', Y, Y']` of paper eq. (6) for the parameters `th` and their forcing `f`
/// ([`Forcing::of`] the pump/input values) at the same instant.
#[inline(always)]
fn rhs(th: &Theta, z: &[f64; 4], f: &Forcing) -> [f64; 4] {
    let [x, xd, y, yd] = *z;
    let t1 = &th.drive;
    let t2 = &th.sense;
    // (sums grouped as trees: shorter dependency chains for the integrator)
    let xdd = (t1[0] * xd + t1[3] * yd) + ((t1[2] * y + f.accel_x) + x * (f.kx + f.kx3 * (x * x)));
    let ydd = (t2[0] * yd + t2[3] * xd) + ((t2[2] * x + f.accel_y) + y * (t2[1] + t2[4] * (y * y)));
    [xd, xdd, yd, ydd]
}

/// [`rhs`] plus the effects of [`crate::effects`] (EFFECTS.md terms, non-dimensional); `f`
/// is the forcing of `th` at `d`.
#[inline(always)]
fn rhs_fx(th: &Theta, z: &[f64; 4], d: &Drive, f: &Forcing, fx: &Effects) -> [f64; 4] {
    let [x, xd, y, yd] = *z;
    let [_, xdd, _, ydd] = rhs(th, z, f);
    let (x2, y2) = (x * x, y * y);
    let pump = d.s * (1.0 + d.cos2psi);
    let dx = -fx.geometric * y * (x * y + 2.0 * xd * yd)
        + (2.0 * d.gv - 0.5 * fx.anisodamping) * yd
        + d.gvd * y
        - fx.nl_damping * x2 * xd
        - fx.quadratic * x2;
    let dy = fx.geometric * y * xd * xd + (0.5 * fx.anisodamping - 2.0 * d.gv) * xd
        - d.gvd * x
        - fx.electrostatic * (if fx.es_pump { d.s } else { 1.0 }) * y * (1.0 + ES_C3 * y2)
        - fx.nl_damping * y2 * yd
        + fx.force_leak * pump * x * (th.drive[5] + th.drive[6] * x2)
        - fx.quadratic * y2;
    [xd, xdd + dx, yd, ydd + dy]
}

mod terms;
use terms::{rhs_fx_one, terms_of};

// =======================================================================================
// THE MEASUREMENT: what the pick-off delivers to the lock-in mixers. Measurement effects
// (pump feedthrough, pick-off gain/phase mismatch, ...) go here; `_cos_psi`, `_sin_psi`
// and `_d` are provided for them.
// =======================================================================================
/// Measured displacements `[Xm, Ym]` for the state `z` and the noise sample `noise`.
#[inline(always)]
fn measure(z: &[f64; 4], noise: [f64; 2], _cos_psi: f64, _sin_psi: f64, _d: &Drive) -> [f64; 2] {
    [z[0] + noise[0], z[2] + noise[1]]
}

/// [`measure`] with the measurement effects: the pump feedthrough `C·s·(1 + cos2ψ)` and
/// the pick-off gain error on Y.
#[inline(always)]
fn measure_fx(z: &[f64; 4], noise: [f64; 2], d: &Drive, fx: &Effects) -> [f64; 2] {
    let ft = fx.feedthrough * d.s * (1.0 + d.cos2psi);
    [
        z[0] + noise[0],
        (1.0 + fx.readout_gain) * z[2] + ft + noise[1],
    ]
}

/// One classic RK4 step of length `h` with the inputs at the start (`da`), the middle
/// (`dh`) and the end (`de`) of the step.
#[inline(always)]
#[cfg(test)]
fn rk4_step(th: &Theta, z: &[f64; 4], h: f64, da: &Drive, dh: &Drive, de: &Drive) -> [f64; 4] {
    let at = |d: &Drive| (*d, Forcing::of(th, d));
    rk4_step_g::<{ terms::NONE }>(th, z, h, [at(da), at(dh), at(de)], &Effects::default())
}

/// [`rk4_step`] with the effect terms `FX` ([`terms`]); each input comes with its
/// [`Forcing`].
#[inline(always)]
fn rk4_step_g<const FX: u8>(
    th: &Theta,
    z: &[f64; 4],
    h: f64,
    [da, dh, de]: [(Drive, Forcing); 3],
    fx: &Effects,
) -> [f64; 4] {
    let rhs = |th: &Theta, z: &[f64; 4], (d, f): &(Drive, Forcing)| match FX {
        terms::NONE => rhs(th, z, f),
        terms::ALL => rhs_fx(th, z, d, f, fx),
        _ => rhs_fx_one::<FX>(th, z, d, f, fx),
    };
    let hh = 0.5 * h;
    let [x, v, y, w] = *z;
    let k1 = rhs(th, z, &da);
    let k2 = rhs(
        th,
        &[
            x + hh * k1[0],
            v + hh * k1[1],
            y + hh * k1[2],
            w + hh * k1[3],
        ],
        &dh,
    );
    let k3 = rhs(
        th,
        &[
            x + hh * k2[0],
            v + hh * k2[1],
            y + hh * k2[2],
            w + hh * k2[3],
        ],
        &dh,
    );
    let k4 = rhs(
        th,
        &[x + h * k3[0], v + h * k3[1], y + h * k3[2], w + h * k3[3]],
        &de,
    );
    let h6 = h / 6.0;
    [
        (x + h6 * (k1[0] + 2.0 * (k2[0] + k3[0]))) + h6 * k4[0],
        (v + h6 * (k1[1] + 2.0 * (k2[1] + k3[1]))) + h6 * k4[1],
        (y + h6 * (k1[2] + 2.0 * (k2[2] + k3[2]))) + h6 * k4[2],
        (w + h6 * (k1[3] + 2.0 * (k2[3] + k3[3]))) + h6 * k4[3],
    ]
}

/// Complex multiplication on (re, im) pairs.
#[inline(always)]
fn cmul(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0)
}

/// Wraps a phase to [−π, π] without losing the bits of 2π that `f64` cannot hold
/// (two-constant Cody–Waite reduction, fused multiply-add).
pub fn wrap_phase(p: f64) -> f64 {
    const TWO_PI_HI: f64 = std::f64::consts::TAU;
    const TWO_PI_LO: f64 = 2.449_293_598_294_706_4e-16; // 2π − TWO_PI_HI
    let n = (p / TWO_PI_HI).round();
    (-n).mul_add(TWO_PI_HI, p) - n * TWO_PI_LO
}

/// ψ at the end of an interval of length `ts` over which ω goes linearly from `om0` to
/// `om1`: `wrap(ψ_k + ts·(om0 + om1)/2)`, with the products split exactly (fma) and
/// reduced before they are added, so the wrapped phase keeps full `f64` resolution
/// (no ~1e-14 rounding per sample from adding a small ψ to a 137-rad increment).
fn next_psi(psi_k: f64, ts: f64, om0: f64, om1: f64) -> f64 {
    let hts = 0.5 * ts;
    let (p0, p1) = (hts * om0, hts * om1);
    let e = hts.mul_add(om0, -p0) + hts.mul_add(om1, -p1);
    wrap_phase(psi_k + (wrap_phase(p0) + wrap_phase(p1) + e))
}

/// Exact phasor generator of a linear chirp on a uniform grid: `e^{iψ_j}` with
/// `ψ_j = ψ_0 + w·j + ½·a·j²` (here `j` counts half steps), advanced by two complex
/// multiplications per grid point.
#[derive(Clone, Copy, Debug)]
struct Chirp {
    /// `e^{iψ_j}` (cos, sin).
    r: (f64, f64),
    /// `e^{i(ψ_{j+1} − ψ_j)}`.
    d: (f64, f64),
    /// `e^{i a}` (the constant second difference).
    q: (f64, f64),
}

impl Chirp {
    /// Synchronised at grid point `j` of the chirp `ψ_0 + w·j + ½·a·j²` with `q = e^{ia}`.
    #[inline]
    fn at(psi0: f64, w: f64, a: f64, j: usize, q: (f64, f64)) -> Self {
        let jf = j as f64;
        let (s, c) = (psi0 + jf * (w + 0.5 * a * jf)).sin_cos();
        let (ds, dc) = (w + a * (jf + 0.5)).sin_cos();
        Self {
            r: (c, s),
            d: (dc, ds),
            q,
        }
    }

    /// Moves to the next grid point and returns the new `e^{iψ}`. `CHIRP = false` is
    /// for a constant ω (`a = 0`, `q = 1`), where `d` does not change.
    #[inline(always)]
    fn step<const CHIRP: bool>(&mut self) -> (f64, f64) {
        self.r = cmul(self.r, self.d);
        if CHIRP {
            self.d = cmul(self.d, self.q);
        }
        self.r
    }
}

impl GyroSim {
    /// A simulator at τ = 0 with state `x0 = [X, X', Y, Y']`, ψ = 0 and the lock-in
    /// filters at rest. Validates `cfg` and returns an error that names the bad field.
    pub fn new(cfg: &SimConfig, x0: [f64; 4]) -> Result<Self, String> {
        let pos = |v: f64, name: &str| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("{name} = {v} must be positive and finite"))
            }
        };
        pos(cfg.omega0_rad_s, "omega0_rad_s")?;
        pos(cfg.fs_hz, "fs_hz")?;
        pos(cfg.omega_max, "omega_max")?;
        pos(cfg.lpf_hz, "lpf_hz")?;
        if cfg.steps_per_period < 8 {
            return Err(format!(
                "steps_per_period = {} must be ≥ 8 (RK4 accuracy)",
                cfg.steps_per_period
            ));
        }
        if !(cfg.noise_density.is_finite() && cfg.noise_density >= 0.0) {
            return Err(format!(
                "noise_density = {} must be ≥ 0 and finite",
                cfg.noise_density
            ));
        }
        if x0.iter().any(|v| !v.is_finite()) {
            return Err(format!("initial state {x0:?} must be finite"));
        }
        let ts = cfg.omega0_rad_s / cfg.fs_hz;
        let m_min = (ts * cfg.omega_max * cfg.steps_per_period as f64 / std::f64::consts::TAU)
            .ceil()
            .max(1.0);
        if m_min > MAX_STEPS_PER_SAMPLE as f64 {
            return Err(format!(
                "{m_min} RK4 steps per sample (steps_per_period, omega_max, fs_hz) is too many"
            ));
        }
        let wc = std::f64::consts::TAU * cfg.lpf_hz / cfg.omega0_rad_s;
        let h_max = ts / m_min; // the step only shrinks when M is rounded up
        let blk = LOCKIN_BLOCKS
            .into_iter()
            .find(|&b| wc * b as f64 * h_max <= BLOCK_WC_T)
            .ok_or_else(|| {
                format!(
                    "lpf_hz = {} is too high for the fine step (steps_per_period = {}): \
                     wc·4h = {:.3} > {BLOCK_WC_T}",
                    cfg.lpf_hz,
                    cfg.steps_per_period,
                    wc * 4.0 * h_max
                )
            })?;
        let m = (m_min as usize).div_ceil(blk) * blk;
        let h = ts / m as f64;
        let lpf = BlockLpf::new(cfg.lpf_order, wc, h, blk)
            .map_err(|e| format!("lpf_order/lpf_hz: {e}"))?;
        let h_sec = h / cfg.omega0_rad_s;
        let noise = Noise {
            rng: Xoshiro256PlusPlus::seed_from_u64(cfg.seed),
            sigma: cfg.noise_density * (1.0 / (2.0 * h_sec)).sqrt(),
        };
        let mut sim = Self {
            m,
            ts,
            h,
            z: x0,
            psi: 0.0,
            k: 0,
            lpf,
            noise,
            fx: Effects::default(),
            terms: terms::NONE,
            vib_omega: 0.0,
            vib_phase: 0.0,
            w: [0.0; HOOK_STATES],
        };
        // first lock-in sample at τ = 0 (ψ = 0); s is irrelevant to the measurement here
        let d0 = Drive {
            cos2psi: 1.0,
            s: 1.0,
            ax: 0.0,
            ay: 0.0,
            gv: 0.0,
            gvd: 0.0,
        };
        let n = if sim.noise.sigma > 0.0 {
            sim.noise.draw::<true>()
        } else {
            [0.0; 2]
        };
        let [xm, ym] = measure(&sim.z, n, 1.0, 0.0, &d0);
        sim.lpf.start(&mixer_products(xm, ym, 1.0, 0.0));
        Ok(sim)
    }

    /// Advances the plant and the lock-in by one sample period `[t_k, t_k+1]`.
    ///
    /// `u0` and `u1` are the inputs at the two ends; they are linear in time in between
    /// (ψ is integrated exactly for the linear ω). `theta` holds over the whole interval.
    /// ω should stay ≤ [`SimConfig::omega_max`], otherwise there are fewer than
    /// `steps_per_period` RK4 steps per carrier period. Never allocates, never fails
    /// (non-finite inputs propagate into the state).
    pub fn advance(&mut self, theta: &Theta, u0: &PlantInputs, u1: &PlantInputs) {
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA (detected at run time just above)
            #[allow(unsafe_code)]
            unsafe {
                self.advance_avx2(theta, u0, u1)
            };
            return;
        }
        self.advance_with::<false>(theta, u0, u1);
    }

    /// [`GyroSim::advance`] compiled for AVX2 and FMA ([`crate::simd`]): the same
    /// arithmetic in the same order, bit for bit (no contraction), on 4-wide vectors.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn advance_avx2(&mut self, theta: &Theta, u0: &PlantInputs, u1: &PlantInputs) {
        self.advance_with::<true>(theta, u0, u1);
    }

    /// The body of [`GyroSim::advance`]; `SIMD`: compiled inside [`Self::advance_avx2`]
    /// (its out-of-line callees take their AVX2 builds).
    #[inline(always)]
    fn advance_with<const SIMD: bool>(
        &mut self,
        theta: &Theta,
        u0: &PlantInputs,
        u1: &PlantInputs,
    ) {
        let noise = self.noise.sigma > 0.0;
        let chirp = u1.omega != u0.omega;
        const ALL: u8 = terms::ALL;
        const NONE: u8 = terms::NONE;
        if self.fx.hook.is_some() {
            match (noise, chirp) {
                (true, true) => self.run_interval::<true, true, ALL, true, SIMD>(theta, u0, u1),
                (true, false) => self.run_interval::<true, false, ALL, true, SIMD>(theta, u0, u1),
                (false, true) => self.run_interval::<false, true, ALL, true, SIMD>(theta, u0, u1),
                (false, false) => self.run_interval::<false, false, ALL, true, SIMD>(theta, u0, u1),
            }
        } else if !noise && self.terms != ALL && self.terms != NONE {
            self.advance_one::<SIMD>(theta, u0, u1, chirp);
        } else if self.terms != NONE {
            match (noise, chirp) {
                (true, true) => self.run_interval::<true, true, ALL, false, SIMD>(theta, u0, u1),
                (true, false) => self.run_interval::<true, false, ALL, false, SIMD>(theta, u0, u1),
                (false, true) => self.run_interval::<false, true, ALL, false, SIMD>(theta, u0, u1),
                (false, false) => {
                    self.run_interval::<false, false, ALL, false, SIMD>(theta, u0, u1)
                }
            }
        } else {
            match (noise, chirp) {
                (true, true) => self.run_interval::<true, true, NONE, false, SIMD>(theta, u0, u1),
                (true, false) => self.run_interval::<true, false, NONE, false, SIMD>(theta, u0, u1),
                (false, true) => self.run_interval::<false, true, NONE, false, SIMD>(theta, u0, u1),
                (false, false) => {
                    self.run_interval::<false, false, NONE, false, SIMD>(theta, u0, u1)
                }
            }
        }
        if self.vib_omega != 0.0 {
            self.vib_phase = wrap_phase(self.vib_phase + self.vib_omega * self.ts);
        }
    }

    /// [`GyroSim::advance`] of a noise-free run with one plant effect alone ([`terms_of`]; the
    /// diagnosis's re-simulations): that effect's own terms ([`rhs_fx_one`]), the same
    /// result as the general effect path. Dispatches to an out-of-line body
    /// (`advance_one_portable` or `advance_one_avx2`), so `advance` compiles as it did without
    /// these variants.
    #[inline(always)]
    fn advance_one<const SIMD: bool>(
        &mut self,
        theta: &Theta,
        u0: &PlantInputs,
        u1: &PlantInputs,
        chirp: bool,
    ) {
        #[cfg(target_arch = "x86_64")]
        if SIMD {
            // SAFETY: `SIMD` only inside `advance_avx2`, which runs where the CPU has
            // AVX2 and FMA
            #[allow(unsafe_code)]
            unsafe {
                self.advance_one_avx2(theta, u0, u1, chirp)
            };
            return;
        }
        self.advance_one_portable(theta, u0, u1, chirp);
    }

    #[inline(never)]
    fn advance_one_portable(&mut self, theta: &Theta, u0: &PlantInputs, u1: &PlantInputs, c: bool) {
        self.advance_one_with::<false>(theta, u0, u1, c);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline(never)]
    fn advance_one_avx2(&mut self, theta: &Theta, u0: &PlantInputs, u1: &PlantInputs, c: bool) {
        self.advance_one_with::<true>(theta, u0, u1, c);
    }

    #[inline(always)]
    fn advance_one_with<const SIMD: bool>(
        &mut self,
        theta: &Theta,
        u0: &PlantInputs,
        u1: &PlantInputs,
        chirp: bool,
    ) {
        macro_rules! run_one {
            ($fx:expr) => {
                if chirp {
                    self.run_interval::<false, true, { $fx }, false, SIMD>(theta, u0, u1)
                } else {
                    self.run_interval::<false, false, { $fx }, false, SIMD>(theta, u0, u1)
                }
            };
        }
        match self.terms {
            terms::MEASUREMENT => run_one!(terms::MEASUREMENT),
            terms::GEOMETRIC => run_one!(terms::GEOMETRIC),
            terms::ELECTROSTATIC => run_one!(terms::ELECTROSTATIC),
            terms::NL_DAMPING => run_one!(terms::NL_DAMPING),
            terms::ANISODAMPING => run_one!(terms::ANISODAMPING),
            terms::FORCE_LEAK => run_one!(terms::FORCE_LEAK),
            _ => run_one!(terms::ALL),
        }
    }

    /// Moves the simulator to sample `k` with state `z` and reference phase `psi`, the
    /// lock-in restarted at rest at this instant (for re-running a record from a later
    /// sample: the lock-in and the modes forget the start within a few tens of ms).
    pub fn restart_at(&mut self, k: u64, z: [f64; 4], psi: f64) {
        self.k = k;
        self.z = z;
        self.psi = wrap_phase(psi);
        self.vib_phase = wrap_phase(self.vib_omega * self.time_tau() + self.fx.vib_phase0);
        let (s, c) = self.psi.sin_cos();
        self.lpf.start(&mixer_products(z[0], z[2], c, s));
    }

    /// Adds the plant and measurement effects of `fx` from now on (`vib_omega` = Ω_v/ω0,
    /// the angular vibration's frequency, with phase `fx.vib_phase0` at τ = 0). Thermal drift and the
    /// lock-in mismatch are not plant terms: the runner applies them (θ per sample, the
    /// lock-in cut-off in [`SimConfig::lpf_hz`]).
    pub fn set_effects(&mut self, fx: Effects, vib_omega: f64) {
        self.fx = fx;
        self.terms = terms_of(&fx);
        self.vib_omega = if fx.vib_gamma != 0.0 { vib_omega } else { 0.0 };
        self.vib_phase = wrap_phase(self.vib_omega * self.time_tau() + fx.vib_phase0);
    }

    /// The hot loop: `M/m` lock-in blocks of `m` RK4 steps each (`m` = 32 by default).
    /// `HOOK`: with the external term of `fx.hook` (its force, states and pick-off offset).
    #[inline(always)]
    fn run_interval<
        const NOISE: bool,
        const CHIRP: bool,
        const FX: u8,
        const HOOK: bool,
        const SIMD: bool,
    >(
        &mut self,
        theta: &Theta,
        u0: &PlantInputs,
        u1: &PlantInputs,
    ) {
        let th = *theta;
        let m = self.m;
        let h = self.h;
        let blk = self.lpf.block_len();
        // half-step grid: τ_j = j·h/2, j = 0..2M; linear inputs v_j = v0 + j·dv (exact
        // at every block start, incremented within the block)
        let nh = (2 * m) as f64;
        let (ds, dax, day) = (
            (u1.s - u0.s) / nh,
            (u1.ax - u0.ax) / nh,
            (u1.ay - u0.ay) / nh,
        );
        // ψ_j = ψ_k + w·j + ½·a·j², w = ω0·h/2, a = ω̇·(h/2)²
        let delta = 0.5 * h;
        let w = u0.omega * delta;
        let a = if CHIRP {
            (u1.omega - u0.omega) / self.ts * delta * delta
        } else {
            0.0
        };
        let (qs, qc) = a.sin_cos();
        let q = (qc, qs);
        let psi_k = self.psi;
        let mut z = self.z;
        let fx = self.fx;
        // angular vibration γ1·sin(Ω_v τ): its phasor on the same half-step grid
        let (gv_amp, vo) = (fx.vib_gamma, self.vib_omega);
        let wv = vo * delta;
        let vib_phase = self.vib_phase;
        let hook = fx.hook;
        let mut hw = self.w;
        let tau_k = self.time_tau();
        // the external term's clock: τ at the start of the current RK4 step
        let mut tau = 0.0;
        let meas = |z: &[f64; 4],
                    w: &[f64; HOOK_STATES],
                    tau: f64,
                    n: [f64; 2],
                    rc: f64,
                    rs: f64,
                    d: &Drive| {
            if HOOK && let Some(hk) = &hook {
                let m = measure_fx(z, n, d, &fx);
                let o = hk.offset(&hook::HookAt::at(tau, z, w, d));
                [m[0] + o[0], m[1] + o[1]]
            } else if FX != terms::NONE {
                measure_fx(z, n, d, &fx)
            } else {
                measure(z, n, rc, rs, d)
            }
        };
        for b in 0..m / blk {
            let j0 = 2 * b * blk; // half-step index of the block start
            let mut ch = Chirp::at(psi_k, w, a, j0, q);
            let mut vb = Chirp::at(vib_phase, wv, 0.0, j0, (1.0, 0.0));
            let vib = |r: (f64, f64)| (gv_amp * r.1, gv_amp * vo * r.0);
            let (mut rc, mut rs) = ch.r;
            let jf = j0 as f64;
            let (gv, gvd) = if FX == terms::ALL {
                vib(vb.r)
            } else {
                (0.0, 0.0)
            };
            let mut da = Drive {
                cos2psi: rc * rc - rs * rs,
                s: u0.s + jf * ds,
                ax: u0.ax + jf * dax,
                ay: u0.ay + jf * day,
                gv,
                gvd,
            };
            // `fa` is always the forcing of `da`: computed here at the block's start, then
            // taken over with `da` from the previous step's end (the same instant, θ fixed)
            let mut fa = Forcing::of(&th, &da);
            if HOOK {
                tau = tau_k + jf * delta;
            }
            for i in 0..blk {
                if i > 0 {
                    let n = self.noise.draw::<NOISE>();
                    let [xm, ym] = meas(&z, &hw, tau, n, rc, rs, &da);
                    self.lpf.push_mixed_in::<SIMD>(xm, ym, rc, rs);
                }
                let (hc, hs) = ch.step::<CHIRP>();
                let (gv, gvd) = if FX == terms::ALL {
                    vib(vb.step::<false>())
                } else {
                    (0.0, 0.0)
                };
                let dh = Drive {
                    cos2psi: hc * hc - hs * hs,
                    s: da.s + ds,
                    ax: da.ax + dax,
                    ay: da.ay + day,
                    gv,
                    gvd,
                };
                (rc, rs) = ch.step::<CHIRP>();
                let (gv, gvd) = if FX == terms::ALL {
                    vib(vb.step::<false>())
                } else {
                    (0.0, 0.0)
                };
                let de = Drive {
                    cos2psi: rc * rc - rs * rs,
                    s: dh.s + ds,
                    ax: dh.ax + dax,
                    ay: dh.ay + day,
                    gv,
                    gvd,
                };
                let fe = Forcing::of(&th, &de);
                if HOOK && let Some(hk) = &hook {
                    (z, hw) =
                        hook::rk4_step_hooked(&th, (&z, &hw), h, [&da, &dh, &de], tau, &fx, hk);
                    tau += h;
                } else {
                    let steps = [(da, fa), (dh, Forcing::of(&th, &dh)), (de, fe)];
                    z = rk4_step_g::<FX>(&th, &z, h, steps, &fx);
                }
                (da, fa) = (de, fe);
            }
            // block junction sample (also the first sample of the next block)
            let n = self.noise.draw::<NOISE>();
            let [xm, ym] = meas(&z, &hw, tau, n, rc, rs, &da);
            // once per block: its baseline build is as fast here as an AVX2 one
            self.lpf.finish_block(&mixer_products(xm, ym, rc, rs));
        }
        self.z = z;
        self.w = hw;
        self.psi = next_psi(psi_k, self.ts, u0.omega, u1.omega);
        self.k += 1;
    }

    /// The 14 lock-in outputs at the current time (a 500 Hz sample).
    pub fn lockin(&self) -> LockinOut {
        LockinOut::from_channels(&self.lpf.output())
    }

    /// The plant state `[X, X', Y, Y']` at the current time.
    pub fn state(&self) -> [f64; 4] {
        self.z
    }

    /// The external term's own states ([`hook`]) at the current time.
    pub fn hook_states(&self) -> [f64; HOOK_STATES] {
        self.w
    }

    /// The lock-in reference phase ψ (half the pump phase) at the current time, wrapped
    /// to [−π, π].
    pub fn psi(&self) -> f64 {
        self.psi
    }

    /// The current time τ = ω0·t (number of samples × `Ts`).
    pub fn time_tau(&self) -> f64 {
        self.k as f64 * self.ts
    }

    /// Number of samples advanced so far.
    pub fn samples(&self) -> u64 {
        self.k
    }

    /// The sample period `Ts` in τ units.
    pub fn sample_period_tau(&self) -> f64 {
        self.ts
    }

    /// Number of RK4 steps `M` per sample.
    pub fn steps_per_sample(&self) -> usize {
        self.m
    }

    /// The fine RK4 step `h = Ts/M`, τ (the step [`prewarp`] corrects for).
    pub fn step_tau(&self) -> f64 {
        self.h
    }

    /// Lock-in block length in RK4 steps (the low-pass is advanced once per block; `M`
    /// is a multiple of it). 32 with the default configuration.
    pub fn lockin_block(&self) -> usize {
        self.lpf.block_len()
    }
}

#[cfg(test)]
mod tests;
