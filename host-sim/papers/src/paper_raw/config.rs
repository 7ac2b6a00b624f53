//! The settings of a run: the paper's constants, the measurement form, the readings of the
//! forgetting factor, the run configuration and its segments.

use paragyro_core::physics::OMEGA0_TABLE2_RAD_S;
use paragyro_simulator::plant::{ACCEL_TABLE2, Theta};
use serde::Serialize;

/// The paper's forgetting factor (eq. 10, section 4).
pub const PAPER_LAMBDA: f64 = 0.2;
/// The paper's initial covariance P(0) = 1e4·I (section 4).
pub const PAPER_P0: f64 = 1e4;
/// The paper's Λ(D) = D² + 3D + 2: coefficients (a1, a0) of D and 1.
pub(super) const LAMBDA_A1: f64 = 3.0;
pub(super) const LAMBDA_A0: f64 = 2.0;

/// How the measurement Z of eq. (10) is formed (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum ZForm {
    /// Z = X (eqs. 11, 13): the estimated vector is θ + [3, 2, 0, …], starting at 0.
    Literal,
    /// Z = D²X/Λ = X − 3 DX/Λ − 2 X/Λ: the estimated vector is θ itself, starting at 0.
    D2,
}

/// Readings of the paper's λ = 0.2 (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub enum LambdaReading {
    /// λ = 0.2 per τ (the model's time unit): 5 τ = 74 µs memory.
    PaperPerTau,
    /// λ = 0.2 per second: 5 s memory.
    PerSecond,
    /// 2 s memory, the product's λ_d = 0.999 per 500 Hz sample.
    Product2s,
    /// Any λ, per τ.
    PerTau(f64),
}

impl LambdaReading {
    /// λ in 1/τ for the time scale `omega0_rad_s`.
    pub fn per_tau(self, omega0_rad_s: f64) -> f64 {
        match self {
            LambdaReading::PaperPerTau => PAPER_LAMBDA,
            LambdaReading::PerSecond => PAPER_LAMBDA / omega0_rad_s,
            LambdaReading::Product2s => -(0.999f64.ln()) * 500.0 / omega0_rad_s,
            LambdaReading::PerTau(l) => l,
        }
    }

    /// Memory 1/λ in seconds.
    pub fn memory_s(self, omega0_rad_s: f64) -> f64 {
        1.0 / (self.per_tau(omega0_rad_s) * omega0_rad_s)
    }

    /// Short label for tables and legends.
    pub fn label(self) -> String {
        match self {
            LambdaReading::PaperPerTau => "λ = 0.2/τ (74 µs)".into(),
            LambdaReading::PerSecond => "λ = 0.2/s (5 s)".into(),
            LambdaReading::Product2s => "λ = 0.5/s (2 s, product)".into(),
            LambdaReading::PerTau(l) => format!("λ = {l:.3e}/τ"),
        }
    }

    /// Machine-friendly key.
    pub fn key(self) -> String {
        match self {
            LambdaReading::PaperPerTau => "per_tau".into(),
            LambdaReading::PerSecond => "per_second".into(),
            LambdaReading::Product2s => "memory_2s".into(),
            LambdaReading::PerTau(l) => format!("per_tau_{l:e}"),
        }
    }
}

/// Settings of one run of the raw paper estimator.
#[derive(Clone, Debug)]
pub struct RawConfig {
    /// Time scale ω0, rad/s (τ = ω0 t).
    pub omega0_rad_s: f64,
    /// Minimum RK4 steps per carrier period 2π/ω at the largest ω of the run (≥ 128).
    pub steps_per_period: usize,
    /// One-sided white displacement noise density on the measured X and Y, L0/√Hz.
    pub noise_density: f64,
    /// Seed of the noise generator.
    pub seed: u64,
    /// Forgetting factor λ of eq. (10), per τ.
    pub lambda_per_tau: f64,
    /// Initial covariance P(0) = p0·I.
    pub p0: f64,
    /// Measurement form.
    pub z_form: ZForm,
    /// Record interval, s (the step grid is aligned to it).
    pub record_every_s: f64,
    /// Initial plant state [X, X', Y, Y'].
    pub x0: [f64; 4],
    /// Constant accelerations [ãx, ãy].
    pub accel: [f64; 2],
    /// The estimator (θ̂, P) is held at its initial value until this time, s (the plant and
    /// the Λ filters run from 0). 0 = the paper (estimation from the start).
    pub estimator_start_s: f64,
    /// θ with which the equation error [`RawRecord::e_true_rms`](super::RawRecord::e_true_rms) is evaluated, if not the
    /// plant's own (to check that the identity is sensitive to θ).
    pub model_theta: Option<Theta>,
    /// Window `[from, to)` in s over which the information matrices ∫ΦΦᵀdτ are accumulated
    /// (for identifiability diagnostics), if any.
    pub info_window_s: Option<(f64, f64)>,
}

impl Default for RawConfig {
    /// Table 2 time scale, 128 steps/period, no noise, the paper's λ = 0.2/τ, P0 = 1e4·I,
    /// literal Z = X, 1 ms records, X(0) = 0.01, ãx = ãy = 0.0213 (10 g).
    fn default() -> Self {
        Self {
            omega0_rad_s: OMEGA0_TABLE2_RAD_S,
            steps_per_period: 128,
            noise_density: 0.0,
            seed: 1,
            lambda_per_tau: PAPER_LAMBDA,
            p0: PAPER_P0,
            z_form: ZForm::Literal,
            record_every_s: 1e-3,
            x0: [0.01, 0.0, 0.0, 0.0],
            accel: [ACCEL_TABLE2, ACCEL_TABLE2],
            estimator_start_s: 0.0,
            model_theta: None,
            info_window_s: None,
        }
    }
}

/// One segment of a run: the plant's θ and the pump's ω (half the pump frequency, units of
/// ω0) held for `duration_s`.
#[derive(Clone, Copy, Debug)]
pub struct Segment {
    /// Length, s (rounded to the step grid).
    pub duration_s: f64,
    /// The plant's θ during the segment (eq. 25 order).
    pub theta: Theta,
    /// Pump ω = ψ' during the segment.
    pub omega: f64,
}
