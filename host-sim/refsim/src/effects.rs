//! The effects the generator can add: the project's library effects and some out of it,
//! with the **names and size units of the project's effect library** (so that labels can
//! be scored), each written here anew as an SI term of [`crate::plant`].
//!
//! Sizes are non-dimensional in the project's units (time 1/ω0, length L0 = 1 µm) unless a
//! unit is given; the plant converts them (the table gives the SI term that is added).
//!
//! | name | size | SI term |
//! |---|---|---|
//! | `geometric_nonlinearity` | j | ẍ −= j·y(ω0²xy + 2ẋẏ)/L0², ÿ += j·y·ẋ²/L0² |
//! | `angular_vibration` | γ1 °/s `@beat` Hz | Ω(t) += γ1·sin(2π(f_p + beat)t + φ) in every rate term (Coriolis, Ω̇, Ω²); f_p the first pump frequency |
//! | `electrostatic_softening` | κ (`@1`: × s) | ÿ −= κ·s·ω0²(y + (2/9)·y³/L0²) |
//! | `feedthrough` | C µm | the sense pick-off reads y + C·s(1 + cos2ψ) |
//! | `nonlinear_damping` | η | ẍ −= η·ω0·x²ẋ/L0², ÿ −= η·ω0·y²ẏ/L0² |
//! | `anisodamping` | d | ẍ −= (d/2)·ω0·ẏ, ÿ += (d/2)·ω0·ẋ |
//! | `force_leak` | ε | ÿ −= ε·s(1 + cos2ψ)·(kp·x + cp·x³) (the pump force on the sense axis) |
//! | `thermal_drift` | TCF ppm/K | ωx, ωy × (1 + TCF·(T(t) − 25 °C)), T the die temperature, continuous in time |
//! | `lockin_mismatch` | δ | the lock-in's cut-off is (1 + δ) × the header's |
//! | `quadratic_stiffness` (outside) | q | ẍ −= q·ω0²x²/L0, ÿ −= q·ω0²y²/L0 |
//! | `readout_gain` (outside) | g | the sense pick-off reads (1 + g)·y |
//!
//! Out-of-library types of the blind benchmark ([`Outside`], labels' `outside`):
//!
//! | name | size | SI term |
//! |---|---|---|
//! | `coulomb_friction` | f | ÿ −= f·ω0²L0·tanh(ẏ/(10⁻³·ω0·L0)) |
//! | `spurious_mode` | k | a mode z: z̈ = −10⁻³ω0ż − 1.004·ky·z − k·ω0²y, ÿ −= k·ω0²z |
//! | `charging_drift` | κ | ÿ += κ·ω0²(1 − e^{−t/5 s})(L0 + y) |
//! | `pickoff_lag` | φ rad | the sense pick-off reads y(t − d), d = φ/ωy, to first order y − d·ẏ |

use serde::{Deserialize, Serialize};
use std::fmt;

/// An effect of the project's library, or one of the two out-of-library effects the
/// project's simulator names (serialised with the project's names).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Effect {
    /// j.
    GeometricNonlinearity,
    /// γ1, °/s, `@beat` Hz.
    AngularVibration,
    /// κ (`@1`: driven by the pump).
    ElectrostaticSoftening,
    /// C, µm.
    Feedthrough,
    /// η.
    NonlinearDamping,
    /// d.
    Anisodamping,
    /// ε.
    ForceLeak,
    /// TCF, ppm/K.
    ThermalDrift,
    /// δ.
    LockinMismatch,
    /// Out of library: q.
    QuadraticStiffness,
    /// Out of library: g.
    ReadoutGain,
}

/// The library, in the project's order (the order of the draw).
pub const LIBRARY: [Effect; 9] = [
    Effect::GeometricNonlinearity,
    Effect::AngularVibration,
    Effect::ElectrostaticSoftening,
    Effect::Feedthrough,
    Effect::NonlinearDamping,
    Effect::Anisodamping,
    Effect::ForceLeak,
    Effect::ThermalDrift,
    Effect::LockinMismatch,
];

impl Effect {
    /// The project's name.
    pub const fn name(self) -> &'static str {
        match self {
            Effect::GeometricNonlinearity => "geometric_nonlinearity",
            Effect::AngularVibration => "angular_vibration",
            Effect::ElectrostaticSoftening => "electrostatic_softening",
            Effect::Feedthrough => "feedthrough",
            Effect::NonlinearDamping => "nonlinear_damping",
            Effect::Anisodamping => "anisodamping",
            Effect::ForceLeak => "force_leak",
            Effect::ThermalDrift => "thermal_drift",
            Effect::LockinMismatch => "lockin_mismatch",
            Effect::QuadraticStiffness => "quadratic_stiffness",
            Effect::ReadoutGain => "readout_gain",
        }
    }

    /// The drawn size range (the blind benchmark's protocol numbers).
    pub const fn size_range(self) -> SizeRange {
        match self {
            Effect::GeometricNonlinearity => r(1e-9, 1e-5, 1e-7, true),
            Effect::AngularVibration => r(1.0, 60.0, 20.0, false),
            Effect::ElectrostaticSoftening => r(1e-9, 1e-5, 1e-7, false),
            Effect::Feedthrough => r(1e-6, 1e-2, 1e-4, true),
            Effect::NonlinearDamping => r(1e-9, 1e-5, 1e-7, false),
            Effect::Anisodamping => r(1e-9, 1e-5, 1e-7, true),
            Effect::ForceLeak => r(1e-7, 1e-3, 1e-5, true),
            Effect::ThermalDrift => r(0.05, 50.0, 1.0, false),
            Effect::LockinMismatch => r(1e-5, 1e-1, 1e-3, true),
            Effect::QuadraticStiffness => r(1e-7, 1e-4, 1e-6, true),
            Effect::ReadoutGain => r(1e-5, 3e-2, 1e-3, true),
        }
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.name())
    }
}

/// The blind benchmark's out-of-library types (labels' `outside.kind`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outside {
    /// f: dry friction on the sense axis.
    CoulombFriction,
    /// k: a spring-coupled mode at ωz² = 1.004·ωy² (≈ 22 Hz above the sense).
    SpuriousMode,
    /// κ: a trapped charge building up with a 5 s time constant.
    ChargingDrift,
    /// φ: a delay of the sense pick-off.
    PickoffLag,
}

impl Outside {
    /// Every type.
    pub const ALL: [Outside; 4] = [
        Outside::CoulombFriction,
        Outside::SpuriousMode,
        Outside::ChargingDrift,
        Outside::PickoffLag,
    ];

    /// The name.
    pub const fn name(self) -> &'static str {
        match self {
            Outside::CoulombFriction => "coulomb_friction",
            Outside::SpuriousMode => "spurious_mode",
            Outside::ChargingDrift => "charging_drift",
            Outside::PickoffLag => "pickoff_lag",
        }
    }

    /// The drawn size range (the blind benchmark's protocol numbers).
    pub const fn size_range(self) -> SizeRange {
        match self {
            Outside::CoulombFriction => r(1e-9, 1e-5, 1e-7, false),
            Outside::SpuriousMode => r(1e-6, 1e-3, 3e-5, true),
            Outside::ChargingDrift => r(1e-8, 1e-5, 3e-7, true),
            Outside::PickoffLag => r(1e-5, 1e-2, 1e-4, false),
        }
    }
}

impl fmt::Display for Outside {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.name())
    }
}

/// A size range: log-uniform magnitude in [low, high], the stated detection limit, signs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SizeRange {
    /// Smallest magnitude.
    pub low: f64,
    /// Largest magnitude.
    pub high: f64,
    /// The detection limit the project states.
    pub limit: f64,
    /// Both signs are drawn.
    pub signed: bool,
}

const fn r(low: f64, high: f64, limit: f64, signed: bool) -> SizeRange {
    SizeRange {
        low,
        high,
        limit,
        signed,
    }
}

/// One effect with its size (labels' `effects` entries: `{"name", "size", "param"?}`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EffectSpec {
    /// The effect.
    #[serde(rename = "name")]
    pub effect: Effect,
    /// Its size in its unit.
    pub size: f64,
    /// The vibration's beat (Hz) or the softening's drive (`1`: × s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub param: Option<f64>,
}

/// An out-of-library effect with its size (labels' `outside`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct OutsideSpec {
    /// The type.
    pub kind: Outside,
    /// Its size.
    pub size: f64,
}

/// Every effect size of one record, as the plant uses them (zero: absent).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EffectSizes {
    /// j.
    pub geometric: f64,
    /// γ1, °/s.
    pub vib_dps: f64,
    /// The vibration's beat against the first pump frequency, Hz.
    pub vib_beat_hz: f64,
    /// The vibration's phase at t = 0, rad.
    pub vib_phase: f64,
    /// κ.
    pub electrostatic: f64,
    /// κ is multiplied by s.
    pub es_pump: bool,
    /// C, µm.
    pub feedthrough_um: f64,
    /// η.
    pub nl_damping: f64,
    /// d.
    pub anisodamping: f64,
    /// ε.
    pub force_leak: f64,
    /// TCF, ppm/K.
    pub tcf_ppm_k: f64,
    /// δ.
    pub lockin_mismatch: f64,
    /// q.
    pub quadratic: f64,
    /// g.
    pub readout_gain: f64,
    /// f.
    pub friction: f64,
    /// k.
    pub spurious: f64,
    /// κ of the charge.
    pub charging: f64,
    /// φ, rad.
    pub pickoff_lag_rad: f64,
}

impl EffectSizes {
    /// The sizes of `effects` and `outside` (sizes of a repeated effect add).
    pub fn of(effects: &[EffectSpec], outside: Option<OutsideSpec>) -> Self {
        let mut e = EffectSizes {
            vib_beat_hz: 1.5,
            ..Self::default()
        };
        for s in effects {
            let v = s.size;
            match s.effect {
                Effect::GeometricNonlinearity => e.geometric += v,
                Effect::AngularVibration => {
                    e.vib_dps += v;
                    if let Some(b) = s.param {
                        e.vib_beat_hz = b;
                    }
                }
                Effect::ElectrostaticSoftening => {
                    e.electrostatic += v;
                    e.es_pump = s.param == Some(1.0);
                }
                Effect::Feedthrough => e.feedthrough_um += v,
                Effect::NonlinearDamping => e.nl_damping += v,
                Effect::Anisodamping => e.anisodamping += v,
                Effect::ForceLeak => e.force_leak += v,
                Effect::ThermalDrift => e.tcf_ppm_k += v,
                Effect::LockinMismatch => e.lockin_mismatch += v,
                Effect::QuadraticStiffness => e.quadratic += v,
                Effect::ReadoutGain => e.readout_gain += v,
            }
        }
        if let Some(o) = outside {
            match o.kind {
                Outside::CoulombFriction => e.friction += o.size,
                Outside::SpuriousMode => e.spurious += o.size,
                Outside::ChargingDrift => e.charging += o.size,
                Outside::PickoffLag => e.pickoff_lag_rad += o.size,
            }
        }
        e
    }
}
