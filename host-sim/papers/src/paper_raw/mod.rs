//! The paper's own estimator, exactly as the paper states it, on the raw fast signals.
//!
//! This is the *other* estimator: not the product's 500 Hz lock-in RLS (paragyro-core), but
//! sections 3–4 of the seed paper taken literally, to answer "does the code implement the
//! paper, and does the paper hold?".
//!
//! # What is integrated (one ODE, one fixed-step classic RK4)
//!
//! * **The plant**, eq. (6) with θ in the eq. (25) order (pump scale s = 1, no dither):
//!
//!   ```text
//!   X'' = θ11 X' + θ12 X + θ13 Y + θ14 Y' + θ15 X³ + θ16 X cos2ψ + θ17 X³ cos2ψ + θ18 ãx
//!   Y'' = θ21 Y' + θ22 Y + θ23 X + θ24 X' + θ25 Y³ + θ26 ãy,        ψ' = ω (constant)
//!   ```
//!
//! * **The state variables x5 … of eqs. (17)–(19)**: every regressor signal u goes through
//!   the paper's Λ(D) = D² + 3D + 2, realised as `s'' + 3 s' + 2 s = u` from rest, which
//!   delivers both `u/Λ = s` and `D u/Λ = s'` (the paper's eq. (19) feeds the plant state
//!   x2 = X' into a second filter to get D X/Λ; with a *measured* X only, `s'` of the X
//!   filter is the same signal up to a transient X(0)·e^{−τ}). Eight filtered signals:
//!   X, Y, X³, X cos2ψ, X³ cos2ψ, ãx, Y³, ãy, all built from the *measured* X, Y.
//!   The regressors (eq. (17), in the eq. (25) order, i.e. components 3↔4 swapped
//!   relative to eq. (17)/(12) as printed):
//!
//!   ```text
//!   Φ1 = [DX/Λ, X/Λ, Y/Λ, DY/Λ, X³/Λ, X cos2ψ/Λ, X³ cos2ψ/Λ, ãx/Λ]
//!   Φ2 = [DY/Λ, Y/Λ, X/Λ, DX/Λ, Y³/Λ, ãy/Λ]
//!   ```
//!
//! * **The continuous-time least squares of eq. (10)**, for each axis:
//!
//!   ```text
//!   θ̂' = P Φ e,   e = Z − Φᵀ θ̂,   P' = λ P − P Φ Φᵀ P,   P(0) = 1e4·I,  θ̂(0) = 0 (eq. 28)
//!   ```
//!
//!   The full 8×8 and 6×6 matrices P are state variables (as the paper says), integrated
//!   by the same RK4 step as the plant ("discretised faithfully at the integration step").
//!
//! # The measurement Z and the "3, 2" shift (eq. 11, 13, 15)
//!
//! Λ X = X'' + 3X' + 2X gives `X = (3 + θ11) DX/Λ + (2 + θ12) X/Λ + Σ_{i≥3} θ1i Φ1i`, so
//! with the paper's literal measurement Z = X (eqs. 11, 13) the estimated vector is
//! θ1 + [3, 2, 0, …] (exactly what eq. (15) prints: "3 − μx", "2 − (ωx² …)"), and likewise
//! θ2 + [3, 2, 0, …]. The paper's figures and eq. (25) show the unshifted θ, so the shift
//! is removed when θ̂ is reported. [`ZForm::Literal`] (default) is that reading, with
//! θ̂(0) = 0 for the shifted vector (eq. 28) — the reported θ̂ starts at [−3, −2, 0, …].
//! [`ZForm::D2`] uses the equivalent measurement Z = D²X/Λ = X − 3 DX/Λ − 2 X/Λ, for
//! which the unshifted θ̂ itself starts at 0. The two give identical dynamics of the
//! error θ̂ − θ; only the initial error differs.
//!
//! # Forgetting factor
//!
//! eq. (10) with λ = 0.2 — but in which time unit? The model is written in τ = ω0 t, so
//! λ = 0.2 per τ ([`LambdaReading::PaperPerTau`]) is a 5 τ = 74 µs memory (less than one
//! carrier period; FINDINGS §4). Read per second ([`LambdaReading::PerSecond`]) it is a
//! 5 s memory (0.2/ω0 = 2.95e-6 per τ). The product's λ_d = 0.999 per 500 Hz sample is a
//! 2 s memory ([`LambdaReading::Product2s`], −ln(0.999)·500/ω0 = 7.37e-6 per τ). With
//! P' = λP − PΦΦᵀP the information matrix obeys (P⁻¹)' = −λP⁻¹ + ΦΦᵀ, so 1/λ is the
//! memory in τ.
//!
//! # The discretised identity is exact
//!
//! The residual r = Z − Φᵀθ (true θ) is a *linear* function of the combined state whose
//! derivatives obey r'' + 3r' + 2r = 0 identically (the nonlinear terms X³, X cos2ψ, …
//! cancel between the plant and the filters). RK4 integrates such a linear invariant as its
//! own linear ODE, so on noise-free data the regression of eq. (15)–(17) holds at the
//! integration step to rounding (≈ 1e-16 relative) once the e^{−τ} start transient
//! (X(0) ≠ 0 with the filters at rest) has died. The plant's RK4 error (7e-6 at 128
//! steps/period, FINDINGS §1) therefore never biases this estimator: in the paper's own
//! noise-free world every error comes from excitation and conditioning.
//!
//! # What it shows (measured; [`write_paper_raw_summary`], tests/paper_raw.rs)
//!
//! * Noise-free, λ = 0.2/τ, estimation from the start-up: all 14 θ within 1 % in ≤ 1 ms and
//!   1e-12…1e-6 after, rate 150.000 °/s. With 50 ms per parameter set (the paper's figures
//!   have a time axis in ms) it tracks eqs. 25 → 26 → 27 to ≤ 1e-7 within 2 ms of each
//!   switch, even with the literal pump. This is what Figs 9–14 show, and only the per-τ
//!   reading of λ can produce it.
//! * With 0.2–0.5 s per set, P winds up in the directions the steady state does not excite
//!   (trace P ≈ 4e11 drive, 3e13 sense), the regressor leaves that subspace at the switch,
//!   2h·ΦᵀPΦ jumps past RK4's stability limit and the explicit step overflows within
//!   microseconds. A 4× finer step (512/period) survives and tracks the re-centred sets to
//!   ≤ 2e-6; with the
//!   literal pump the drive dies (< 1 % of nominal 85 ms after the +50 % switch), the sense
//!   loses all excitation and P overflows at 0.73 s even with the fine step.
//! * The paper's P0 = 1e4·I on an already running gyro gives h·ΦᵀP0Φ ≈ 670: immediate
//!   divergence. The paper's set-up works only from a small-amplitude start-up.
//! * With 1 pm/√Hz of displacement noise, λ = 0.2/τ (5 τ of memory) is useless (errors
//!   10…1e4, rate off by 1e5 °/s). With seconds of memory (0.2/s or 2 s) the steady state
//!   leaves θ14 (the rate-carrying Y' coefficient) and, more weakly, θ17, θ24 poorly
//!   determined: the pump-only steady state has no information on θ14 at all (scaled
//!   condition number ≈ 7e17), and these estimators cannot follow any parameter change.
//!
//! # Noise and time grid
//!
//! Optional white displacement noise on the measured X and Y, one independent normal per
//! RK4 step and axis with σ = density·√(1/(2 h_sec)) (as in [`paragyro_simulator::plant`]), held over
//! the step. The step is `h = ω0·record_every_s / n` with n the smallest integer that gives
//! ≥ `steps_per_period` steps per carrier period 2π/ω at the largest ω of the run, so the
//! records fall exactly on the step grid. Parameter sets and pump frequencies switch at step
//! boundaries; ψ is continuous.
//!
//! # Modules
//!
//! [`config`] (settings), `ode` (the combined ODE and its RK4 step), [`mod@simulate`] (a
//! run), [`records`] (errors, settling), [`switch`] (the ±50 % test), [`mod@compare`]
//! (against the product), [`mod@identifiability`], `report`, `plots` and `tables` (the
//! report's outputs).

pub mod compare;
pub mod config;
pub mod identifiability;
mod ode;
mod plots;
pub mod records;
mod report;
pub mod simulate;
pub mod switch;
mod tables;

pub use compare::{CompareRow, Comparison, LAMBDAS, compare, raw_on_identify_plant};
pub use config::{LambdaReading, PAPER_LAMBDA, PAPER_P0, RawConfig, Segment, ZForm};
pub use identifiability::{
    Identifiability, identifiability, symmetric_eigen, window_identifiability,
};
pub use ode::RK4_STABILITY_LIMIT;
pub use records::{physical_of, rel_err, settle_time, theta_rel_errors};
pub use report::{
    AxisPair, COMPARE_RAW_S, FINE_STEPS_PER_PERIOD, IdentifiabilityReport, LambdaInfo, LateStart,
    PaperRawSummary, RunNumbers, SwitchRecord, write_paper_raw_summary,
};
pub use simulate::{RawRecord, RawRun, simulate};
pub use switch::{
    Pump, SET_LABELS, SegmentSummary, SwitchOptions, SwitchResult, paper_sets, paper_switch,
    segment_summaries,
};
