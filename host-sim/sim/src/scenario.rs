//! Scenarios: one simulated experiment, described in TOML (or taken from the built-ins).
//!
//! A scenario names the simulated device (`[plant]`, the paper's non-dimensional Table 2
//! parameters plus SI inputs: rate in °/s, accelerations in m/s², initial displacement in µm),
//! the simulation settings (`[sim]`), the estimator's settings and its nominal design
//! (`[estimator]`, `[estimator.nominal]`), scripted changes (`[[event]]`), named window
//! statistics for `summary.json` (`[[measure]]`) and an optional comparison run (`[twin]`).
//! The schema, every key with its unit and default, is documented in `host-sim/scenarios/README.md`.
//!
//! Loading is strict: unknown keys, wrong types and out-of-range values are errors whose message
//! names the file, the line (and column) and the field, e.g.
//! `scenarios/x.toml:12:7: field 'plant.wy2': expected a float, found a string "abc"`.
//!
//! The built-in scenarios are the TOML files in `host-sim/scenarios/`, embedded in the binary.
//!
//! Conventions (ARCHITECTURE.md §4): the plant is non-dimensional (τ = ω0 t, lengths in
//! L0 = 1 µm); everything a person types is in SI or engineering units with the unit in the key.
//! [`Scenario::plant_at`] converts: γ = Ωz·π/180/ω0, γ' = (dΩz/dt)·π/180/ω0², ã = a/(L0 ω0²).

use std::f64::consts::PI;
use std::fmt;
use std::path::Path;

use paragyro_core::physics::{self, Physical};
use serde::{Deserialize, Serialize};
use toml_edit::{ImDocument, Item, TableLike, Value};

use crate::trace::TraceRow;

/// Reference length L0 of the non-dimensional displacements, m (1 µm).
pub const L0_M: f64 = 1e-6;

/// Drive natural frequency ω0/2π implied by Table 2 (the core's
/// [`physics::OMEGA0_TABLE2_RAD_S`]: γ = 3.8581e-5 ⇔ 150 °/s), Hz.
pub const DEFAULT_F0_HZ: f64 = physics::OMEGA0_TABLE2_RAD_S / (2.0 * PI);

/// The built-in scenarios: (name, one-line description, embedded TOML, file name).
const BUILTINS: [(&str, &str, &str, &str); 5] = [
    (
        "identify",
        "Start-up, 0.5 s gate, pump dither from 1 s: identify all 14 θ from a nominal design 3–10 % off (10 s)",
        include_str!("../../scenarios/identify.toml"),
        "identify.toml",
    ),
    (
        "drift-retune",
        "ωy² drifts 1.0265 → 1.03 at 2–2.5 s; the core re-identifies and retunes the pump; twin without retune (8 s)",
        include_str!("../../scenarios/drift-retune.toml"),
        "drift-retune.toml",
    ),
    (
        "paper-switch",
        "The paper's ±50 % test: θ ×1.5 at 3 s and ×0.5 at 6 s, pump re-centred on the sense resonance (9 s)",
        include_str!("../../scenarios/paper-switch.toml"),
        "paper-switch.toml",
    ),
    (
        "paper-claim",
        "The paper's \"sense amplitude drops to 20 %\": pump fixed at 2·√1.0265·f0, ωy² = 1.0265 vs 1.03 twin (2 s)",
        include_str!("../../scenarios/paper-claim.toml"),
        "paper-claim.toml",
    ),
    (
        "characterise",
        "Sim-to-real diagnosis run: dither from 1 s, pump amplitude steps s = 1 → 0.85 → 1.15 (20 s)",
        include_str!("../../scenarios/characterise.toml"),
        "characterise.toml",
    ),
];

// ---------------------------------------------------------------------------------------------
// Specification types
// ---------------------------------------------------------------------------------------------

/// One simulated experiment.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Scenario {
    /// Short name (used in titles and reports).
    pub name: String,
    /// Free text.
    pub description: String,
    /// Length of the run, s.
    pub duration_s: f64,
    /// Seed of the noise generators.
    pub seed: u64,
    /// The simulated device.
    pub plant: PlantSpec,
    /// Integrator, noise and lock-in settings.
    pub sim: SimSpec,
    /// Estimator settings and its nominal design.
    pub estimator: EstimatorSpec,
    /// Scripted changes, sorted by time (stable: file order among equal times).
    pub events: Vec<EventSpec>,
    /// Named window statistics for `summary.json`.
    pub measures: Vec<MeasureSpec>,
    /// An optional second run of the same scenario with overrides.
    pub twin: Option<TwinSpec>,
    /// Where the scenario came from: `"built-in"` or the file path.
    pub source: String,
}

/// The simulated device: non-dimensional paper parameters (Table 2 defaults) and SI inputs.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlantSpec {
    /// Drive damping μx.
    pub mu_x: f64,
    /// Sense damping μy.
    pub mu_y: f64,
    /// Damping coupling μxy.
    pub mu_xy: f64,
    /// Drive stiffness ωx² (1 defines ω0).
    pub wx2: f64,
    /// Sense stiffness ωy².
    pub wy2: f64,
    /// Stiffness coupling (quadrature) ωxy².
    pub wxy2: f64,
    /// Drive cubic stiffness αx.
    pub alpha_x: f64,
    /// Sense cubic stiffness αy.
    pub alpha_y: f64,
    /// Linear parametric pump coefficient β1.
    pub beta1: f64,
    /// Cubic parametric pump coefficient β3.
    pub beta3: f64,
    /// Angular rate Ωz, °/s (γ = Ωz·π/180/ω0).
    pub rate_dps: f64,
    /// Angular acceleration dΩz/dt, °/s² (γ' = dΩz/dt·π/180/ω0²).
    pub rate_accel_dps2: f64,
    /// Acceleration along the drive axis, m/s² (ã = a/(L0 ω0²)).
    pub accel_x_mps2: f64,
    /// Acceleration along the sense axis, m/s².
    pub accel_y_mps2: f64,
    /// Initial drive displacement, µm (start-up from rest needs a seed).
    pub initial_x_um: f64,
    /// Initial sense displacement, µm.
    pub initial_y_um: f64,
}

impl Default for PlantSpec {
    /// Table 2 of the paper (the core's [`physics::TABLE2`]), 150 °/s, 10 g on both axes,
    /// X(0) = 0.01 µm.
    fn default() -> Self {
        let t = &physics::TABLE2;
        Self {
            mu_x: t.mu_x,
            mu_y: t.mu_y,
            mu_xy: t.mu_xy,
            wx2: t.wx2,
            wy2: t.wy2,
            wxy2: t.wxy2,
            alpha_x: t.alpha_x,
            alpha_y: t.alpha_y,
            beta1: t.beta1,
            beta3: t.beta3,
            rate_dps: 150.0,
            rate_accel_dps2: 0.0,
            accel_x_mps2: 98.0665,
            accel_y_mps2: 98.0665,
            initial_x_um: 0.01,
            initial_y_um: 0.0,
        }
    }
}

impl PlantSpec {
    /// The value of a rampable key.
    pub fn get(&self, p: PlantParam) -> f64 {
        match p {
            PlantParam::MuX => self.mu_x,
            PlantParam::MuY => self.mu_y,
            PlantParam::MuXy => self.mu_xy,
            PlantParam::Wx2 => self.wx2,
            PlantParam::Wy2 => self.wy2,
            PlantParam::Wxy2 => self.wxy2,
            PlantParam::AlphaX => self.alpha_x,
            PlantParam::AlphaY => self.alpha_y,
            PlantParam::Beta1 => self.beta1,
            PlantParam::Beta3 => self.beta3,
            PlantParam::RateDps => self.rate_dps,
            PlantParam::RateAccelDps2 => self.rate_accel_dps2,
            PlantParam::AccelXMps2 => self.accel_x_mps2,
            PlantParam::AccelYMps2 => self.accel_y_mps2,
        }
    }

    /// Sets a rampable key.
    pub fn set(&mut self, p: PlantParam, v: f64) {
        let slot = match p {
            PlantParam::MuX => &mut self.mu_x,
            PlantParam::MuY => &mut self.mu_y,
            PlantParam::MuXy => &mut self.mu_xy,
            PlantParam::Wx2 => &mut self.wx2,
            PlantParam::Wy2 => &mut self.wy2,
            PlantParam::Wxy2 => &mut self.wxy2,
            PlantParam::AlphaX => &mut self.alpha_x,
            PlantParam::AlphaY => &mut self.alpha_y,
            PlantParam::Beta1 => &mut self.beta1,
            PlantParam::Beta3 => &mut self.beta3,
            PlantParam::RateDps => &mut self.rate_dps,
            PlantParam::RateAccelDps2 => &mut self.rate_accel_dps2,
            PlantParam::AccelXMps2 => &mut self.accel_x_mps2,
            PlantParam::AccelYMps2 => &mut self.accel_y_mps2,
        };
        *slot = v;
    }

    /// All keys with their values, in file order.
    fn entries(&self) -> [(&'static str, f64); 16] {
        let mut out = [("", 0.0); 16];
        for (slot, p) in out.iter_mut().zip(PlantParam::ALL) {
            *slot = (p.name(), self.get(p));
        }
        out[14] = ("initial_x_um", self.initial_x_um);
        out[15] = ("initial_y_um", self.initial_y_um);
        out
    }
}

/// The [`PlantSpec`] keys that a `ramp` event can change.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PlantParam {
    /// `mu_x`
    MuX,
    /// `mu_y`
    MuY,
    /// `mu_xy`
    MuXy,
    /// `wx2`
    Wx2,
    /// `wy2`
    Wy2,
    /// `wxy2`
    Wxy2,
    /// `alpha_x`
    AlphaX,
    /// `alpha_y`
    AlphaY,
    /// `beta1`
    Beta1,
    /// `beta3`
    Beta3,
    /// `rate_dps`
    RateDps,
    /// `rate_accel_dps2`
    RateAccelDps2,
    /// `accel_x_mps2`
    AccelXMps2,
    /// `accel_y_mps2`
    AccelYMps2,
}

impl PlantParam {
    /// Every rampable key, in file order.
    pub const ALL: [PlantParam; 14] = [
        PlantParam::MuX,
        PlantParam::MuY,
        PlantParam::MuXy,
        PlantParam::Wx2,
        PlantParam::Wy2,
        PlantParam::Wxy2,
        PlantParam::AlphaX,
        PlantParam::AlphaY,
        PlantParam::Beta1,
        PlantParam::Beta3,
        PlantParam::RateDps,
        PlantParam::RateAccelDps2,
        PlantParam::AccelXMps2,
        PlantParam::AccelYMps2,
    ];

    /// The TOML key.
    pub fn name(self) -> &'static str {
        match self {
            PlantParam::MuX => "mu_x",
            PlantParam::MuY => "mu_y",
            PlantParam::MuXy => "mu_xy",
            PlantParam::Wx2 => "wx2",
            PlantParam::Wy2 => "wy2",
            PlantParam::Wxy2 => "wxy2",
            PlantParam::AlphaX => "alpha_x",
            PlantParam::AlphaY => "alpha_y",
            PlantParam::Beta1 => "beta1",
            PlantParam::Beta3 => "beta3",
            PlantParam::RateDps => "rate_dps",
            PlantParam::RateAccelDps2 => "rate_accel_dps2",
            PlantParam::AccelXMps2 => "accel_x_mps2",
            PlantParam::AccelYMps2 => "accel_y_mps2",
        }
    }

    /// Parses a TOML key.
    pub fn from_name(name: &str) -> Option<PlantParam> {
        PlantParam::ALL.into_iter().find(|p| p.name() == name)
    }

    /// Whether the key must stay strictly positive (the squared natural frequencies).
    fn must_be_positive(self) -> bool {
        matches!(self, PlantParam::Wx2 | PlantParam::Wy2)
    }
}

impl Serialize for PlantParam {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

/// Integrator, noise and lock-in settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimSpec {
    /// Drive natural frequency defining ω0 = 2π f0, Hz.
    pub f0_hz: f64,
    /// RK4 steps per carrier period (≥ 128 for identification data, FINDINGS §1).
    pub steps_per_period: usize,
    /// White displacement noise density on X and Y, pm/√Hz.
    pub noise_pm_rthz: f64,
    /// Lock-in low-pass corner, Hz.
    pub lockin_lpf_hz: f64,
    /// Lock-in low-pass order (Butterworth).
    pub lockin_lpf_order: usize,
    /// How the pump generator moves between two 500 Hz commands: `"linear"` (a DDS
    /// linear sweep) or `"staircase"` (the new frequency and amplitude hold over the
    /// whole interval, as a DDS updated once per sample at the sample instant).
    pub pump_profile: PumpProfileSpec,
}

/// How the pump moves between commands (see [`SimSpec::pump_profile`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PumpProfileSpec {
    /// Linear sweep from one command to the next.
    #[default]
    Linear,
    /// Each command holds over the whole interval that ends at its sample.
    Staircase,
}

impl Default for SimSpec {
    fn default() -> Self {
        Self {
            f0_hz: DEFAULT_F0_HZ,
            steps_per_period: 128,
            noise_pm_rthz: 1.0,
            lockin_lpf_hz: 150.0,
            lockin_lpf_order: 4,
            pump_profile: PumpProfileSpec::Linear,
        }
    }
}

/// The estimator's design (nominal) parameters: the [`PlantSpec`] physical keys.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NominalSpec {
    /// μx
    pub mu_x: f64,
    /// μy
    pub mu_y: f64,
    /// μxy
    pub mu_xy: f64,
    /// ωx²
    pub wx2: f64,
    /// ωy²
    pub wy2: f64,
    /// ωxy²
    pub wxy2: f64,
    /// αx
    pub alpha_x: f64,
    /// αy
    pub alpha_y: f64,
    /// β1
    pub beta1: f64,
    /// β3
    pub beta3: f64,
}

impl Default for NominalSpec {
    /// Table 2.
    fn default() -> Self {
        let p = PlantSpec::default();
        Self {
            mu_x: p.mu_x,
            mu_y: p.mu_y,
            mu_xy: p.mu_xy,
            wx2: p.wx2,
            wy2: p.wy2,
            wxy2: p.wxy2,
            alpha_x: p.alpha_x,
            alpha_y: p.alpha_y,
            beta1: p.beta1,
            beta3: p.beta3,
        }
    }
}

impl NominalSpec {
    fn entries(&self) -> [(&'static str, f64); 10] {
        [
            ("mu_x", self.mu_x),
            ("mu_y", self.mu_y),
            ("mu_xy", self.mu_xy),
            ("wx2", self.wx2),
            ("wy2", self.wy2),
            ("wxy2", self.wxy2),
            ("alpha_x", self.alpha_x),
            ("alpha_y", self.alpha_y),
            ("beta1", self.beta1),
            ("beta3", self.beta3),
        ]
    }
}

/// Estimator settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EstimatorSpec {
    /// RLS forgetting factor per 500 Hz sample, in (0, 1].
    pub forgetting: f64,
    /// Initial pump centre 2Ω/2π, Hz; `None`: 2·√(nominal ωy²)·f0 (see [`Scenario::pump_centre_hz`]).
    pub pump_centre_hz: Option<f64>,
    /// Peak pump-frequency dither, Hz (±1e-3 of ω0 on Ω ⇔ ±21.6 Hz on the pump).
    pub dither_pump_hz: f64,
    /// Dither frequency, Hz.
    pub dither_freq_hz: f64,
    /// Peak fractional modulation of the pump voltage scale s that runs with the dither
    /// (0 disables).
    pub dither_scale_frac: f64,
    /// Frequency of the pump-scale modulation, Hz.
    pub dither_scale_freq_hz: f64,
    /// Dither start, s.
    pub dither_start_s: f64,
    /// RLS updates gated off for this long after start-up, s.
    pub gate_startup_s: f64,
    /// Whether the retune supervisor may move the pump centre.
    pub retune: bool,
    /// Duration of the pump-centre ramp of a retune, s.
    pub retune_ramp_s: f64,
    /// Nominal (design) parameters.
    pub nominal: NominalSpec,
}

impl Default for EstimatorSpec {
    fn default() -> Self {
        Self {
            forgetting: 0.999,
            pump_centre_hz: None,
            dither_pump_hz: 21.6,
            dither_freq_hz: 5.0,
            dither_scale_frac: 0.1,
            dither_scale_freq_hz: 1.3,
            dither_start_s: 1.0,
            gate_startup_s: 0.5,
            retune: true,
            retune_ramp_s: 0.5,
            nominal: NominalSpec::default(),
        }
    }
}

/// Optional overrides of the `[plant]` keys for the twin run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
#[allow(missing_docs)]
pub struct PlantOverrides {
    pub mu_x: Option<f64>,
    pub mu_y: Option<f64>,
    pub mu_xy: Option<f64>,
    pub wx2: Option<f64>,
    pub wy2: Option<f64>,
    pub wxy2: Option<f64>,
    pub alpha_x: Option<f64>,
    pub alpha_y: Option<f64>,
    pub beta1: Option<f64>,
    pub beta3: Option<f64>,
    pub rate_dps: Option<f64>,
    pub rate_accel_dps2: Option<f64>,
    pub accel_x_mps2: Option<f64>,
    pub accel_y_mps2: Option<f64>,
    pub initial_x_um: Option<f64>,
    pub initial_y_um: Option<f64>,
}

impl PlantOverrides {
    fn entries(&self) -> [(&'static str, Option<f64>); 16] {
        [
            ("mu_x", self.mu_x),
            ("mu_y", self.mu_y),
            ("mu_xy", self.mu_xy),
            ("wx2", self.wx2),
            ("wy2", self.wy2),
            ("wxy2", self.wxy2),
            ("alpha_x", self.alpha_x),
            ("alpha_y", self.alpha_y),
            ("beta1", self.beta1),
            ("beta3", self.beta3),
            ("rate_dps", self.rate_dps),
            ("rate_accel_dps2", self.rate_accel_dps2),
            ("accel_x_mps2", self.accel_x_mps2),
            ("accel_y_mps2", self.accel_y_mps2),
            ("initial_x_um", self.initial_x_um),
            ("initial_y_um", self.initial_y_um),
        ]
    }

    /// Applies the overrides that are set.
    pub fn apply(&self, plant: &mut PlantSpec) {
        for (name, v) in self.entries() {
            let Some(v) = v else { continue };
            match PlantParam::from_name(name) {
                Some(p) => plant.set(p, v),
                None if name == "initial_x_um" => plant.initial_x_um = v,
                None => plant.initial_y_um = v,
            }
        }
    }
}

/// A second run of the same scenario with overrides (e.g. the same drift without the retune).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TwinSpec {
    /// Overrides `[estimator] retune`; when set, `retune` events are dropped from the twin.
    pub retune: Option<bool>,
    /// Plant overrides (the twin's base plant; events still apply on top).
    pub plant: PlantOverrides,
}

/// A scripted change at a given time.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct EventSpec {
    /// Time, s.
    pub t_s: f64,
    /// What happens.
    #[serde(flatten)]
    pub kind: EventKind,
}

/// The kinds of scripted change.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum EventKind {
    /// Linear ramp of one `[plant]` key from its value at `t_s` to `to` over `duration_s`
    /// (0: a step).
    Ramp {
        /// The key.
        param: PlantParam,
        /// Final value (in the key's unit).
        to: f64,
        /// Ramp length, s.
        duration_s: f64,
    },
    /// The paper's eq. (26)/(27) sets: every θ component except θ18 and θ26 becomes
    /// `factor` × the base θ (from the `[plant]` values at that time). Not cumulative; 1 restores.
    ScaleTheta {
        /// The factor.
        factor: f64,
    },
    /// Commanded re-centring of the pump (the estimator gates its updates after it).
    PumpJump {
        /// Explicit new pump centre, Hz.
        centre_hz: Option<f64>,
        /// Centre = 2·√(−θ22_true)·f0 of the θ in force right after `t_s` (FINDINGS §3.5).
        to_sense_resonance: bool,
    },
    /// Switches the pump-frequency dither on or off, optionally with a new amplitude.
    Dither {
        /// On or off.
        enabled: bool,
        /// New peak pump-frequency dither, Hz (keeps the previous amplitude when absent).
        /// The paper-switch regimes scale it with the parametric band, as the prototype did.
        pump_hz: Option<f64>,
    },
    /// Allows or forbids the retune supervisor.
    Retune {
        /// Allowed or not.
        enabled: bool,
    },
    /// Pump voltage scale s = V²/V0², linear ramp from its value at `t_s` over `ramp_s`.
    PumpScale {
        /// Final scale.
        s: f64,
        /// Ramp length, s (0: a step).
        ramp_s: f64,
    },
}

impl EventKind {
    /// The `kind` string of the TOML file.
    pub fn name(&self) -> &'static str {
        match self {
            EventKind::Ramp { .. } => "ramp",
            EventKind::ScaleTheta { .. } => "scale_theta",
            EventKind::PumpJump { .. } => "pump_jump",
            EventKind::Dither { .. } => "dither",
            EventKind::Retune { .. } => "retune",
            EventKind::PumpScale { .. } => "pump_scale",
        }
    }

    /// Whether the event is a control command (pump, dither, retune) rather than a plant change.
    pub fn is_control(&self) -> bool {
        !matches!(self, EventKind::Ramp { .. } | EventKind::ScaleTheta { .. })
    }
}

impl fmt::Display for EventKind {
    /// One line for people: `ramp wy2 → 1.03 over 0.5 s`, `θ scaled ×1.5`, `dither off`, ...
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            EventKind::Ramp {
                param,
                to,
                duration_s,
            } => write!(f, "ramp {} → {to} over {duration_s} s", param.name()),
            EventKind::ScaleTheta { factor } => write!(f, "θ scaled ×{factor} (except θ18, θ26)"),
            EventKind::PumpJump {
                centre_hz: Some(c), ..
            } => write!(f, "pump jump to {c} Hz"),
            EventKind::PumpJump { .. } => write!(f, "pump jump to the sense resonance"),
            EventKind::Dither { enabled, pump_hz } => {
                write!(f, "dither {}", if enabled { "on" } else { "off" })?;
                match pump_hz {
                    Some(a) => write!(f, " (±{a} Hz)"),
                    None => Ok(()),
                }
            }
            EventKind::Retune { enabled } => {
                write!(
                    f,
                    "retune {}",
                    if enabled { "allowed" } else { "forbidden" }
                )
            }
            EventKind::PumpScale { s, ramp_s } => {
                write!(f, "pump scale → {s} over {ramp_s} s")
            }
        }
    }
}

/// Which run a measure is taken on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MeasureRun {
    /// The main run.
    #[default]
    Main,
    /// The `[twin]` run.
    Twin,
}

/// A named window statistic for `summary.json`: the mean sense amplitude |B1| (µm) over
/// `[from_s, to_s]` of one run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeasureSpec {
    /// Key in the summary.
    pub name: String,
    /// Window start, s.
    pub from_s: f64,
    /// Window end, s.
    pub to_s: f64,
    /// The run.
    #[serde(default)]
    pub run: MeasureRun,
}

/// What the simulated plant is at one instant (events applied).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantAt {
    /// True θ1 (drive, eq. 25 order).
    pub theta_drive: [f64; 8],
    /// True θ2 (sense).
    pub theta_sense: [f64; 6],
    /// Physical parameters in `PHYS_NAMES` order, consistent with the θ (corrected Table 3).
    pub phys: [f64; 12],
    /// Angular rate, °/s (consistent with γ = `phys[10]`).
    pub rate_dps: f64,
    /// Non-dimensional drive-axis acceleration ã_x = a_x/(L0 ω0²).
    pub accel_x: f64,
    /// Non-dimensional sense-axis acceleration ã_y.
    pub accel_y: f64,
}

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

/// What went wrong when loading a scenario.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScenarioErrorKind {
    /// The file could not be read.
    Io,
    /// The file is not valid TOML.
    Syntax,
    /// Unknown key, wrong type, missing key, unknown event kind or parameter.
    Schema,
    /// A value out of range or inconsistent.
    Invalid,
    /// Neither a built-in name nor an existing file.
    UnknownScenario,
}

/// A scenario error naming the file, the line and column (where known) and the field.
///
/// Displayed as `file:line:col: context: message`, e.g.
/// `scenarios/x.toml:12:7: field 'plant.wy2': expected a float, found a string "abc"`.
#[derive(Clone, Debug, PartialEq)]
pub struct ScenarioError {
    /// The kind of error.
    pub kind: ScenarioErrorKind,
    /// The file path, `"built-in"`, or empty when there is no file.
    pub file: String,
    /// 1-based line, where known.
    pub line: Option<usize>,
    /// 1-based column (in characters), where known.
    pub column: Option<usize>,
    /// The field or element, e.g. `field 'plant.wy2'` or `event #3 (kind "ramp"), field 'param'`.
    pub context: Option<String>,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if !self.file.is_empty() {
            f.write_str(&self.file)?;
            if let Some(line) = self.line {
                write!(f, ":{line}")?;
                if let Some(col) = self.column {
                    write!(f, ":{col}")?;
                }
            }
            f.write_str(": ")?;
        }
        if let Some(ctx) = &self.context {
            write!(f, "{ctx}: ")?;
        }
        f.write_str(&self.message)
    }
}

impl std::error::Error for ScenarioError {}

/// One step of a path into the TOML document.
#[derive(Clone, Debug, PartialEq)]
enum Seg {
    Key(String),
    Index(usize),
}

fn key(k: &str) -> Seg {
    Seg::Key(k.to_string())
}

fn path(keys: &[&str]) -> Vec<Seg> {
    keys.iter().map(|k| key(k)).collect()
}

/// A semantic problem, located by its path in the document.
#[derive(Clone, Debug)]
struct Problem {
    path: Vec<Seg>,
    message: String,
}

fn problem(path: Vec<Seg>, message: impl Into<String>) -> Problem {
    Problem {
        path,
        message: message.into(),
    }
}

/// Human description of a path: `field 'plant.wy2'`, `event #3 (kind "ramp"), field 'to'`.
fn describe(
    path: &[Seg],
    event_kind: &dyn Fn(usize) -> Option<String>,
    measure_name: &dyn Fn(usize) -> Option<String>,
) -> Option<String> {
    fn dotted(segs: &[Seg]) -> String {
        let mut s = String::new();
        for seg in segs {
            match seg {
                Seg::Key(k) => {
                    if !s.is_empty() {
                        s.push('.');
                    }
                    s.push_str(k);
                }
                Seg::Index(i) => s.push_str(&format!("[{i}]")),
            }
        }
        s
    }
    match path {
        [] => None,
        [Seg::Key(k), Seg::Index(i), rest @ ..] if k == "event" || k == "measure" => {
            let mut s = if k == "event" {
                match event_kind(*i) {
                    Some(kind) => format!("event #{} (kind \"{kind}\")", i + 1),
                    None => format!("event #{}", i + 1),
                }
            } else {
                match measure_name(*i) {
                    Some(name) => format!("measure #{} (\"{name}\")", i + 1),
                    None => format!("measure #{}", i + 1),
                }
            };
            if !rest.is_empty() {
                s.push_str(&format!(", field '{}'", dotted(rest)));
            }
            Some(s)
        }
        _ => Some(format!("field '{}'", dotted(path))),
    }
}

/// 1-based (line, column) of a byte offset.
fn line_col(text: &str, pos: usize) -> (usize, usize) {
    let pos = pos.min(text.len());
    let mut pos = pos;
    while !text.is_char_boundary(pos) {
        pos -= 1;
    }
    let before = &text[..pos];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

/// Deepest element of `path` present in the document: its byte offset (the key when there is one).
fn locate(doc: &toml_edit::Table, path: &[Seg]) -> Option<usize> {
    enum Node<'a> {
        Table(&'a dyn TableLike),
        Tables(&'a toml_edit::ArrayOfTables),
        Array(&'a toml_edit::Array),
        Leaf,
    }
    fn node_of_value(v: &Value) -> Node<'_> {
        match v {
            Value::InlineTable(t) => Node::Table(t),
            Value::Array(a) => Node::Array(a),
            _ => Node::Leaf,
        }
    }
    fn node_of(item: &Item) -> Node<'_> {
        match item {
            Item::Table(t) => Node::Table(t),
            Item::ArrayOfTables(a) => Node::Tables(a),
            Item::Value(v) => node_of_value(v),
            Item::None => Node::Leaf,
        }
    }
    let mut best = doc.span().map(|s| s.start);
    let mut node = Node::Table(doc);
    for seg in path {
        node = match (seg, node) {
            (Seg::Key(k), Node::Table(t)) => match t.get_key_value(k) {
                Some((key, item)) => {
                    best = key.span().or_else(|| item.span()).map(|s| s.start).or(best);
                    node_of(item)
                }
                None => break,
            },
            (Seg::Index(i), Node::Tables(a)) => match a.get(*i) {
                Some(t) => {
                    best = t.span().map(|s| s.start).or(best);
                    Node::Table(t)
                }
                None => break,
            },
            (Seg::Index(i), Node::Array(a)) => match a.get(*i) {
                Some(v) => {
                    best = v.span().map(|s| s.start).or(best);
                    node_of_value(v)
                }
                None => break,
            },
            _ => break,
        };
    }
    best
}

/// The path of the deepest key/value of the document containing byte offset `pos`.
fn path_at(table: &dyn TableLike, pos: usize, out: &mut Vec<Seg>) -> bool {
    let within = |span: Option<std::ops::Range<usize>>| span.is_some_and(|s| s.contains(&pos));
    for (k, item) in table.iter() {
        let key_span = table.key(k).and_then(|key| key.span());
        let whole = match (key_span.clone(), item.span()) {
            (Some(a), Some(b)) => Some(a.start.min(b.start)..a.end.max(b.end)),
            (a, b) => a.or(b),
        };
        match item {
            Item::Table(t) => {
                out.push(key(k));
                if path_at(t, pos, out) || within(t.span()) || within(key_span) {
                    return true;
                }
                out.pop();
            }
            Item::ArrayOfTables(a) => {
                for (i, t) in a.iter().enumerate() {
                    out.push(key(k));
                    out.push(Seg::Index(i));
                    if path_at(t, pos, out) || within(t.span()) {
                        return true;
                    }
                    out.pop();
                    out.pop();
                }
            }
            Item::Value(v) => {
                if within(whole.clone()) {
                    out.push(key(k));
                    match v {
                        Value::InlineTable(t) => {
                            path_at(t, pos, out);
                        }
                        Value::Array(a) => {
                            if let Some((i, v)) =
                                a.iter().enumerate().find(|(_, v)| within(v.span()))
                            {
                                out.push(Seg::Index(i));
                                if let Value::InlineTable(t) = v {
                                    path_at(t, pos, out);
                                }
                            }
                        }
                        _ => {}
                    }
                    return true;
                }
            }
            Item::None => {}
        }
    }
    false
}

/// A sub-table of a TOML table: (index in an array of tables, the table, its span).
type SubTable<'a> = (
    Option<usize>,
    &'a dyn TableLike,
    Option<std::ops::Range<usize>>,
);

/// The path of the (sub)table whose span is exactly `span`.
fn table_with_span(
    table: &dyn TableLike,
    span: &std::ops::Range<usize>,
    out: &mut Vec<Seg>,
) -> bool {
    for (k, item) in table.iter() {
        let subtables: Vec<SubTable<'_>> = match item {
            Item::Table(t) => vec![(None, t as &dyn TableLike, t.span())],
            Item::ArrayOfTables(a) => a
                .iter()
                .enumerate()
                .map(|(i, t)| (Some(i), t as &dyn TableLike, t.span()))
                .collect(),
            Item::Value(Value::InlineTable(t)) => vec![(None, t as &dyn TableLike, t.span())],
            _ => Vec::new(),
        };
        for (index, t, t_span) in subtables {
            out.push(key(k));
            if let Some(i) = index {
                out.push(Seg::Index(i));
            }
            if t_span.as_ref() == Some(span) || table_with_span(t, span, out) {
                return true;
            }
            out.pop();
            if index.is_some() {
                out.pop();
            }
        }
    }
    false
}

/// Text between backticks: "unknown field `a`, expected `b` or `c`" → ["a", "b", "c"].
fn backticked(msg: &str) -> Vec<&str> {
    msg.split('`').skip(1).step_by(2).collect()
}

/// Rewrites serde/toml messages into the wording of this module.
fn humanize(msg: &str) -> String {
    let msg = msg.trim();
    if let Some(rest) = msg.strip_prefix("unknown field ") {
        let names = backticked(rest);
        let (bad, expected) = names.split_first().unwrap_or((&"?", &[]));
        return if expected.is_empty() {
            format!("unknown key '{bad}' (this table takes no keys)")
        } else {
            format!(
                "unknown key '{bad}' (expected one of: {})",
                expected.join(", ")
            )
        };
    }
    if let Some(rest) = msg.strip_prefix("unknown variant ") {
        let names = backticked(rest);
        let (bad, expected) = names.split_first().unwrap_or((&"?", &[]));
        return format!(
            "unknown value '{bad}' (expected one of: {})",
            expected.join(", ")
        );
    }
    if let Some(rest) = msg.strip_prefix("missing field ") {
        let names = backticked(rest);
        return format!(
            "required key '{}' is missing",
            names.first().copied().unwrap_or("?")
        );
    }
    if let Some(rest) = msg.strip_prefix("invalid type: ")
        && let Some((found, expected)) = rest.split_once(", expected ")
    {
        return format!(
            "expected {}, found {}",
            expected_name(expected),
            found_name(found)
        );
    }
    if let Some(rest) = msg.strip_prefix("invalid value: ")
        && let Some((found, expected)) = rest.split_once(", expected ")
    {
        return format!(
            "expected {}, found {}",
            expected_name(expected),
            found_name(found)
        );
    }
    msg.replace('\n', "; ")
}

fn expected_name(e: &str) -> String {
    match e.trim() {
        "f64" | "f32" => "a float".into(),
        "usize" | "u64" | "u32" | "u16" | "u8" => "a non-negative integer".into(),
        "i64" | "i32" => "an integer".into(),
        "a boolean" | "bool" => "a boolean (true or false)".into(),
        "a string" => "a string".into(),
        "a sequence" => "an array (of tables: [[...]])".into(),
        other => other.into(),
    }
}

fn found_name(f: &str) -> String {
    let f = f.trim();
    let value = |prefix: &str| f.strip_prefix(prefix).map(|v| v.trim().trim_matches('`'));
    if let Some(v) = value("string") {
        format!("a string ({v})")
    } else if let Some(v) = value("floating point") {
        format!("a float ({v})")
    } else if let Some(v) = value("integer") {
        format!("an integer ({v})")
    } else if let Some(v) = value("boolean") {
        format!("a boolean ({v})")
    } else if f == "map" {
        "a table".into()
    } else if f == "sequence" {
        "an array".into()
    } else {
        f.into()
    }
}

// ---------------------------------------------------------------------------------------------
// Raw file form
// ---------------------------------------------------------------------------------------------

fn default_seed() -> u64 {
    1
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScenario {
    name: String,
    #[serde(default)]
    description: String,
    duration_s: f64,
    #[serde(default = "default_seed")]
    seed: u64,
    #[serde(default)]
    plant: PlantSpec,
    #[serde(default)]
    sim: SimSpec,
    #[serde(default)]
    estimator: EstimatorSpec,
    #[serde(default)]
    twin: Option<TwinSpec>,
    #[serde(default)]
    event: Vec<RawEvent>,
    #[serde(default)]
    measure: Vec<MeasureSpec>,
}

/// An `[[event]]` table before its kind is known: all keys optional, checked per kind.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEvent {
    t_s: Option<f64>,
    kind: Option<String>,
    param: Option<String>,
    to: Option<f64>,
    duration_s: Option<f64>,
    factor: Option<f64>,
    centre_hz: Option<f64>,
    to_sense_resonance: Option<bool>,
    enabled: Option<bool>,
    s: Option<f64>,
    ramp_s: Option<f64>,
    pump_hz: Option<f64>,
}

/// Event kinds with their required and optional keys (besides `t_s` and `kind`).
const EVENT_KINDS: [(&str, &[&str], &[&str]); 6] = [
    ("ramp", &["param", "to"], &["duration_s"]),
    ("scale_theta", &["factor"], &[]),
    ("pump_jump", &[], &["centre_hz", "to_sense_resonance"]),
    ("dither", &["enabled"], &["pump_hz"]),
    ("retune", &["enabled"], &[]),
    ("pump_scale", &["s"], &["ramp_s"]),
];

impl RawEvent {
    fn present_keys(&self) -> Vec<&'static str> {
        let mut keys = Vec::new();
        let mut add = |k, present: bool| {
            if present {
                keys.push(k)
            }
        };
        add("param", self.param.is_some());
        add("to", self.to.is_some());
        add("duration_s", self.duration_s.is_some());
        add("factor", self.factor.is_some());
        add("centre_hz", self.centre_hz.is_some());
        add("to_sense_resonance", self.to_sense_resonance.is_some());
        add("enabled", self.enabled.is_some());
        add("s", self.s.is_some());
        add("ramp_s", self.ramp_s.is_some());
        add("pump_hz", self.pump_hz.is_some());
        keys
    }

    /// Converts event #`i` (0-based, file order).
    fn convert(&self, i: usize) -> Result<EventSpec, Problem> {
        let at = |k: &str| vec![key("event"), Seg::Index(i), key(k)];
        let kinds: Vec<&str> = EVENT_KINDS.iter().map(|k| k.0).collect();
        let Some(kind) = self.kind.as_deref() else {
            return Err(problem(
                vec![key("event"), Seg::Index(i)],
                format!(
                    "required key 'kind' is missing (one of: {})",
                    kinds.join(", ")
                ),
            ));
        };
        let Some(&(_, required, optional)) = EVENT_KINDS.iter().find(|k| k.0 == kind) else {
            return Err(problem(
                at("kind"),
                format!(
                    "unknown event kind '{kind}' (expected one of: {})",
                    kinds.join(", ")
                ),
            ));
        };
        let Some(t_s) = self.t_s else {
            return Err(problem(
                vec![key("event"), Seg::Index(i)],
                "required key 't_s' is missing",
            ));
        };
        for k in required {
            if !self.present_keys().contains(k) {
                return Err(problem(
                    vec![key("event"), Seg::Index(i)],
                    format!("required key '{k}' is missing"),
                ));
            }
        }
        for k in self.present_keys() {
            if !required.contains(&k) && !optional.contains(&k) {
                let mut allowed = vec!["t_s", "kind"];
                allowed.extend_from_slice(required);
                allowed.extend_from_slice(optional);
                return Err(problem(
                    at(k),
                    format!(
                        "key '{k}' does not apply to a \"{kind}\" event (its keys: {})",
                        allowed.join(", ")
                    ),
                ));
            }
        }
        let kind = match kind {
            "ramp" => {
                let name = self.param.as_deref().unwrap_or_default();
                let Some(param) = PlantParam::from_name(name) else {
                    let names: Vec<&str> = PlantParam::ALL.iter().map(|p| p.name()).collect();
                    return Err(problem(
                        at("param"),
                        format!(
                            "unknown param '{name}' (expected one of: {})",
                            names.join(", ")
                        ),
                    ));
                };
                EventKind::Ramp {
                    param,
                    to: self.to.unwrap_or(f64::NAN),
                    duration_s: self.duration_s.unwrap_or(0.0),
                }
            }
            "scale_theta" => EventKind::ScaleTheta {
                factor: self.factor.unwrap_or(f64::NAN),
            },
            "pump_jump" => EventKind::PumpJump {
                centre_hz: self.centre_hz,
                to_sense_resonance: self.to_sense_resonance.unwrap_or(false),
            },
            "dither" => EventKind::Dither {
                enabled: self.enabled.unwrap_or(false),
                pump_hz: self.pump_hz,
            },
            "retune" => EventKind::Retune {
                enabled: self.enabled.unwrap_or(false),
            },
            _ => EventKind::PumpScale {
                s: self.s.unwrap_or(f64::NAN),
                ramp_s: self.ramp_s.unwrap_or(0.0),
            },
        };
        Ok(EventSpec { t_s, kind })
    }
}

// ---------------------------------------------------------------------------------------------
// Physics (θ ↔ physical parameters)
// ---------------------------------------------------------------------------------------------

/// θ1, θ2 from the physical parameters in `PHYS_NAMES` order (input gains c = 1), by the
/// core's own formulas (`paragyro_core::physics`, eq. 25 order).
fn theta_from_phys(p: &[f64; 12]) -> ([f64; 8], [f64; 6]) {
    physics::theta_from_physical(&Physical::from_array(*p))
}

/// Physical parameters (`PHYS_NAMES` order) from θ1, θ2 by the corrected Table 3 (core).
fn phys_from_theta(d: &[f64; 8], s: &[f64; 6]) -> [f64; 12] {
    physics::physical_from_theta(d, s).as_array()
}

// ---------------------------------------------------------------------------------------------
// Scenario API
// ---------------------------------------------------------------------------------------------

impl Scenario {
    /// The built-in scenarios: (name, one-line description).
    pub fn builtin_names() -> Vec<(&'static str, &'static str)> {
        BUILTINS.iter().map(|b| (b.0, b.1)).collect()
    }

    /// A built-in scenario by name (`None` if there is no such built-in).
    pub fn builtin(name: &str) -> Option<Scenario> {
        let b = BUILTINS.iter().find(|b| b.0 == name)?;
        Scenario::from_toml_str(b.2, &format!("built-in {}", b.3))
            .ok()
            .map(|mut s| {
                s.source = "built-in".to_string();
                s
            })
    }

    /// Parses and validates a scenario; `source` names the file in error messages and is kept
    /// in [`Scenario::source`].
    pub fn from_toml_str(text: &str, source: &str) -> Result<Scenario, ScenarioError> {
        let err = |kind, pos: Option<usize>, context: Option<String>, message: String| {
            let (line, column) = match pos {
                Some(p) => {
                    let (l, c) = line_col(text, p);
                    (Some(l), Some(c))
                }
                None => (None, None),
            };
            ScenarioError {
                kind,
                file: source.to_string(),
                line,
                column,
                context,
                message,
            }
        };

        let doc = ImDocument::parse(text).map_err(|e| {
            err(
                ScenarioErrorKind::Syntax,
                e.span().map(|s| s.start),
                None,
                format!("syntax error: {}", e.message().trim().replace('\n', "; ")),
            )
        })?;
        let root = doc.as_table();
        let event_kind = |i: usize| {
            root.get("event")
                .and_then(|e| e.as_array_of_tables())
                .and_then(|a| a.get(i))
                .and_then(|t| t.get("kind"))
                .and_then(|k| k.as_str())
                .map(str::to_string)
        };
        let measure_name = |i: usize| {
            root.get("measure")
                .and_then(|e| e.as_array_of_tables())
                .and_then(|a| a.get(i))
                .and_then(|t| t.get("name"))
                .and_then(|k| k.as_str())
                .map(str::to_string)
        };
        let located = |kind, p: Problem| {
            err(
                kind,
                locate(root, &p.path),
                describe(&p.path, &event_kind, &measure_name),
                p.message,
            )
        };

        let raw: RawScenario = toml::from_str(text).map_err(|e| {
            let pos = e.span().map(|s| s.start);
            let mut at = Vec::new();
            if let Some(p) = pos {
                path_at(root, p, &mut at);
            }
            let message = humanize(e.message());
            if let Some(missing) = e.message().strip_prefix("missing field ") {
                // The span is the table that lacks the key (0..0 for the root): point at its
                // header and name the key in the context.
                let name = backticked(missing)
                    .first()
                    .copied()
                    .unwrap_or("?")
                    .to_string();
                at.clear();
                if let Some(span) = e.span() {
                    table_with_span(root, &span, &mut at);
                }
                let pos = locate(root, &at).filter(|_| !at.is_empty());
                at.push(Seg::Key(name));
                return err(
                    ScenarioErrorKind::Schema,
                    pos,
                    describe(&at, &event_kind, &measure_name),
                    "required key is missing".to_string(),
                );
            }
            // An unknown key: name it in the context.
            if let Some(bad) = e
                .message()
                .strip_prefix("unknown field ")
                .and_then(|r| backticked(r).first().map(|s| s.to_string()))
                && at.last() != Some(&Seg::Key(bad.clone()))
            {
                at.push(Seg::Key(bad));
            }
            err(
                ScenarioErrorKind::Schema,
                pos,
                describe(&at, &event_kind, &measure_name),
                message,
            )
        })?;

        let mut events = Vec::with_capacity(raw.event.len());
        for (i, ev) in raw.event.iter().enumerate() {
            events.push(
                ev.convert(i)
                    .map_err(|p| located(ScenarioErrorKind::Schema, p))?,
            );
        }
        // Time order (stable); `order[k]` = file index of the k-th event in time.
        let mut order: Vec<usize> = (0..events.len()).collect();
        order.sort_by(|&a, &b| events[a].t_s.total_cmp(&events[b].t_s));
        let scenario = Scenario {
            name: raw.name,
            description: raw.description,
            duration_s: raw.duration_s,
            seed: raw.seed,
            plant: raw.plant,
            sim: raw.sim,
            estimator: raw.estimator,
            events: order.iter().map(|&i| events[i]).collect(),
            measures: raw.measure,
            twin: raw.twin,
            source: source.to_string(),
        };
        scenario
            .check(&|k| order[k])
            .map_err(|p| located(ScenarioErrorKind::Invalid, p))?;
        Ok(scenario)
    }

    /// Reads, parses and validates a scenario file.
    pub fn from_file(path: &Path) -> Result<Scenario, ScenarioError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| ScenarioError {
            kind: ScenarioErrorKind::Io,
            file: file.clone(),
            line: None,
            column: None,
            context: None,
            message: format!("cannot read the scenario file: {e}"),
        })?;
        Scenario::from_toml_str(&text, &file)
    }

    /// A built-in scenario by name, else a scenario file by path. An unknown name gives an
    /// error listing the built-ins.
    pub fn load(name_or_path: &str) -> Result<Scenario, ScenarioError> {
        if let Some(s) = Scenario::builtin(name_or_path) {
            return Ok(s);
        }
        let path = Path::new(name_or_path);
        if path.exists() {
            return Scenario::from_file(path);
        }
        let names: Vec<&str> = BUILTINS.iter().map(|b| b.0).collect();
        Err(ScenarioError {
            kind: ScenarioErrorKind::UnknownScenario,
            file: String::new(),
            line: None,
            column: None,
            context: None,
            message: format!(
                "unknown scenario '{name_or_path}': not a built-in scenario ({}) and no such file",
                names.join(", ")
            ),
        })
    }

    /// ω0 = 2π f0, rad/s.
    pub fn omega0_rad_s(&self) -> f64 {
        2.0 * PI * self.sim.f0_hz
    }

    /// Value of a rampable plant key at `t_s`, using the first `end` (time-sorted) events.
    /// The latest ramp of that key started at or before `t_s` governs; it starts from the
    /// value the key had when it began. Returns the value and its time derivative (per s).
    fn param_at(&self, p: PlantParam, t_s: f64, end: usize) -> (f64, f64) {
        for k in (0..end).rev() {
            let ev = &self.events[k];
            if let EventKind::Ramp {
                param,
                to,
                duration_s,
            } = ev.kind
                && param == p
                && ev.t_s <= t_s
            {
                let (start, _) = self.param_at(p, ev.t_s, k);
                return ramp(start, to, ev.t_s, duration_s, t_s);
            }
        }
        (self.plant.get(p), 0.0)
    }

    /// The plant of the main run at `t_s`: `[plant]` with the ramps interpolated and
    /// `scale_theta` applied at the θ level. A ramp of `rate_dps` adds its slope to γ'.
    pub fn plant_at(&self, t_s: f64) -> PlantAt {
        let mut p = self.plant;
        let mut rate_slope = 0.0;
        let mut done = [false; 14];
        for k in (0..self.events.len()).rev() {
            if let EventKind::Ramp { param, .. } = self.events[k].kind {
                let idx = param as usize;
                if !done[idx] && self.events[k].t_s <= t_s {
                    done[idx] = true;
                    let (v, slope) = self.param_at(param, t_s, k + 1);
                    p.set(param, v);
                    if param == PlantParam::RateDps {
                        rate_slope = slope;
                    }
                }
            }
        }
        let factor = self
            .events
            .iter()
            .rev()
            .find_map(|e| match e.kind {
                EventKind::ScaleTheta { factor } if e.t_s <= t_s => Some(factor),
                _ => None,
            })
            .unwrap_or(1.0);

        let w0 = self.omega0_rad_s();
        let gamma = physics::gamma_from_rate_dps(p.rate_dps, w0);
        let gamma_p = (p.rate_accel_dps2 + rate_slope).to_radians() / (w0 * w0);
        let phys = [
            p.mu_x, p.mu_y, p.mu_xy, p.wx2, p.wy2, p.wxy2, p.alpha_x, p.alpha_y, p.beta1, p.beta3,
            gamma, gamma_p,
        ];
        let (mut theta_drive, mut theta_sense) = theta_from_phys(&phys);
        let mut out_phys = phys;
        if factor != 1.0 {
            for (i, th) in theta_drive.iter_mut().enumerate() {
                if i != 7 {
                    *th *= factor;
                }
            }
            for (i, th) in theta_sense.iter_mut().enumerate() {
                if i != 5 {
                    *th *= factor;
                }
            }
            out_phys = phys_from_theta(&theta_drive, &theta_sense);
        }
        let accel_scale = 1.0 / (L0_M * w0 * w0);
        PlantAt {
            theta_drive,
            theta_sense,
            phys: out_phys,
            rate_dps: p.rate_dps * factor,
            accel_x: p.accel_x_mps2 * accel_scale,
            accel_y: p.accel_y_mps2 * accel_scale,
        }
    }

    /// The twin run as a full scenario: plant overrides applied; a `retune` override sets
    /// `[estimator] retune` and drops the `retune` events; no measures; `twin = None`.
    pub fn twin_scenario(&self) -> Option<Scenario> {
        let twin = self.twin.as_ref()?;
        let mut s = self.clone();
        twin.plant.apply(&mut s.plant);
        if let Some(r) = twin.retune {
            s.estimator.retune = r;
            s.events
                .retain(|e| !matches!(e.kind, EventKind::Retune { .. }));
        }
        s.name = format!("{} (twin)", self.name);
        s.measures.clear();
        s.twin = None;
        Some(s)
    }

    /// θ of `[estimator.nominal]` with the plant's rate (γ, γ') and input coefficients 1.
    pub fn nominal_theta(&self) -> ([f64; 8], [f64; 6]) {
        let n = &self.estimator.nominal;
        let w0 = self.omega0_rad_s();
        let phys = [
            n.mu_x,
            n.mu_y,
            n.mu_xy,
            n.wx2,
            n.wy2,
            n.wxy2,
            n.alpha_x,
            n.alpha_y,
            n.beta1,
            n.beta3,
            physics::gamma_from_rate_dps(self.plant.rate_dps, w0),
            self.plant.rate_accel_dps2.to_radians() / (w0 * w0),
        ];
        theta_from_phys(&phys)
    }

    /// Initial pump centre, Hz: `[estimator] pump_centre_hz`, else 2·√(nominal ωy²)·f0.
    pub fn pump_centre_hz(&self) -> f64 {
        self.estimator
            .pump_centre_hz
            .unwrap_or_else(|| 2.0 * self.estimator.nominal.wy2.sqrt() * self.sim.f0_hz)
    }

    /// The new pump centre commanded by a `pump_jump` event, Hz (`None` for other kinds):
    /// the explicit centre, or 2·√(−θ22)·f0 of the plant right after the event.
    pub fn pump_jump_centre_hz(&self, event: &EventSpec) -> Option<f64> {
        match event.kind {
            EventKind::PumpJump {
                centre_hz: Some(c), ..
            } => Some(c),
            EventKind::PumpJump {
                centre_hz: None, ..
            } => {
                let th22 = self.plant_at(event.t_s).theta_sense[1];
                Some(2.0 * (-th22).sqrt() * self.sim.f0_hz)
            }
            _ => None,
        }
    }

    /// The `pump_jump`, `dither`, `retune` and `pump_scale` events, time-sorted.
    pub fn control_events(&self) -> Vec<EventSpec> {
        self.events
            .iter()
            .filter(|e| e.kind.is_control())
            .copied()
            .collect()
    }

    /// Pump voltage scale s(t) from the `pump_scale` events (1 before any).
    pub fn pump_scale_at(&self, t_s: f64) -> f64 {
        self.pump_scale_upto(t_s, self.events.len())
    }

    fn pump_scale_upto(&self, t_s: f64, end: usize) -> f64 {
        for k in (0..end).rev() {
            let ev = &self.events[k];
            if let EventKind::PumpScale { s, ramp_s } = ev.kind
                && ev.t_s <= t_s
            {
                let start = self.pump_scale_upto(ev.t_s, k);
                return ramp(start, s, ev.t_s, ramp_s, t_s).0;
            }
        }
        1.0
    }

    /// The measures evaluated on a main trace and (optionally) the twin's: mean sense
    /// amplitude |B1| (µm) over each window, skipping NaN; `None` when the window has no data
    /// or the twin trace is missing.
    pub fn measure_values(
        &self,
        main: &[TraceRow],
        twin: Option<&[TraceRow]>,
    ) -> Vec<(String, Option<f64>)> {
        self.measures
            .iter()
            .map(|m| {
                let rows = match m.run {
                    MeasureRun::Main => Some(main),
                    MeasureRun::Twin => twin,
                };
                let value = rows.and_then(|rows| {
                    let (sum, n) = rows
                        .iter()
                        .filter(|r| r.t_s >= m.from_s && r.t_s <= m.to_s)
                        .filter(|r| r.sense_amp_um.is_finite())
                        .fold((0.0, 0usize), |(s, n), r| (s + r.sense_amp_um, n + 1));
                    (n > 0).then(|| sum / n as f64)
                });
                (m.name.clone(), value)
            })
            .collect()
    }

    /// Checks every value (ranges, finiteness, event times, measure windows). The error
    /// names the field; files loaded by [`Scenario::from_toml_str`] are already validated,
    /// with line numbers.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        self.check(&|k| k).map_err(|p| ScenarioError {
            kind: ScenarioErrorKind::Invalid,
            file: self.source.clone(),
            line: None,
            column: None,
            context: describe(
                &p.path,
                &|i| self.events.get(i).map(|e| e.kind.name().to_string()),
                &|i| self.measures.get(i).map(|m| m.name.clone()),
            ),
            message: p.message,
        })
    }

    /// Validation; `file_index(k)` maps the k-th (time-sorted) event to its index in the file.
    fn check(&self, file_index: &dyn Fn(usize) -> usize) -> Result<(), Problem> {
        if self.name.trim().is_empty() {
            return Err(problem(path(&["name"]), "must not be empty"));
        }
        positive(self.duration_s, path(&["duration_s"]))?;

        for (k, v) in self.plant.entries() {
            finite(v, path(&["plant", k]))?;
        }
        positive(self.plant.wx2, path(&["plant", "wx2"]))?;
        positive(self.plant.wy2, path(&["plant", "wy2"]))?;

        let sim = &self.sim;
        positive(sim.f0_hz, path(&["sim", "f0_hz"]))?;
        if sim.steps_per_period < 16 {
            return Err(problem(
                path(&["sim", "steps_per_period"]),
                format!(
                    "must be >= 16 (got {}; use >= 128 for identification data)",
                    sim.steps_per_period
                ),
            ));
        }
        non_negative(sim.noise_pm_rthz, path(&["sim", "noise_pm_rthz"]))?;
        positive(sim.lockin_lpf_hz, path(&["sim", "lockin_lpf_hz"]))?;
        if !(1..=8).contains(&sim.lockin_lpf_order) {
            return Err(problem(
                path(&["sim", "lockin_lpf_order"]),
                format!("must be in 1..=8 (got {})", sim.lockin_lpf_order),
            ));
        }

        let est = &self.estimator;
        let f = est.forgetting;
        if !(f.is_finite() && f > 0.0 && f <= 1.0) {
            return Err(problem(
                path(&["estimator", "forgetting"]),
                format!("must be in (0, 1] (got {f})"),
            ));
        }
        if let Some(c) = est.pump_centre_hz {
            positive(c, path(&["estimator", "pump_centre_hz"]))?;
        }
        non_negative(est.dither_pump_hz, path(&["estimator", "dither_pump_hz"]))?;
        positive(est.dither_freq_hz, path(&["estimator", "dither_freq_hz"]))?;
        non_negative(
            est.dither_scale_frac,
            path(&["estimator", "dither_scale_frac"]),
        )?;
        if est.dither_scale_frac > 0.3 {
            return Err(problem(
                path(&["estimator", "dither_scale_frac"]),
                "must be at most 0.3",
            ));
        }
        positive(
            est.dither_scale_freq_hz,
            path(&["estimator", "dither_scale_freq_hz"]),
        )?;
        non_negative(est.dither_start_s, path(&["estimator", "dither_start_s"]))?;
        non_negative(est.gate_startup_s, path(&["estimator", "gate_startup_s"]))?;
        non_negative(est.retune_ramp_s, path(&["estimator", "retune_ramp_s"]))?;
        for (k, v) in est.nominal.entries() {
            finite(v, path(&["estimator", "nominal", k]))?;
        }
        positive(est.nominal.wx2, path(&["estimator", "nominal", "wx2"]))?;
        positive(est.nominal.wy2, path(&["estimator", "nominal", "wy2"]))?;

        for (k, ev) in self.events.iter().enumerate() {
            let i = file_index(k);
            let at = |key_name: &str| vec![key("event"), Seg::Index(i), key(key_name)];
            let t = ev.t_s;
            if !(t.is_finite() && t >= 0.0 && t <= self.duration_s) {
                return Err(problem(
                    at("t_s"),
                    format!(
                        "event time must be inside the run [0, {}] s (got {t})",
                        self.duration_s
                    ),
                ));
            }
            match ev.kind {
                EventKind::Ramp {
                    param,
                    to,
                    duration_s,
                } => {
                    if param.must_be_positive() {
                        positive(to, at("to"))?;
                    } else {
                        finite(to, at("to"))?;
                    }
                    non_negative(duration_s, at("duration_s"))?;
                }
                EventKind::ScaleTheta { factor } => positive(factor, at("factor"))?,
                EventKind::PumpJump {
                    centre_hz,
                    to_sense_resonance,
                } => match (centre_hz, to_sense_resonance) {
                    (Some(c), false) => positive(c, at("centre_hz"))?,
                    (None, true) => {
                        let th22 = self.plant_at(t).theta_sense[1];
                        if th22.is_nan() || th22 >= 0.0 {
                            return Err(problem(
                                at("to_sense_resonance"),
                                format!(
                                    "the sense resonance is undefined at t = {t} s (θ22 = {th22} must be < 0)"
                                ),
                            ));
                        }
                    }
                    _ => {
                        return Err(problem(
                            vec![key("event"), Seg::Index(i)],
                            "a pump_jump needs either 'centre_hz' or 'to_sense_resonance = true' (not both)",
                        ));
                    }
                },
                EventKind::PumpScale { s, ramp_s } => {
                    non_negative(s, at("s"))?;
                    non_negative(ramp_s, at("ramp_s"))?;
                }
                EventKind::Dither {
                    pump_hz: Some(a), ..
                } => {
                    non_negative(a, at("pump_hz"))?;
                }
                EventKind::Dither { .. } | EventKind::Retune { .. } => {}
            }
        }

        if let Some(twin) = &self.twin {
            for (k, v) in twin.plant.entries() {
                if let Some(v) = v {
                    finite(v, path(&["twin", "plant", k]))?;
                }
            }
            if let Some(v) = twin.plant.wx2 {
                positive(v, path(&["twin", "plant", "wx2"]))?;
            }
            if let Some(v) = twin.plant.wy2 {
                positive(v, path(&["twin", "plant", "wy2"]))?;
            }
            if let Some(ts) = self.twin_scenario() {
                ts.check(file_index).map_err(|mut p| {
                    p.message = format!("in the [twin] run: {}", p.message);
                    p
                })?;
            }
        }

        for (i, m) in self.measures.iter().enumerate() {
            let at = |key_name: &str| vec![key("measure"), Seg::Index(i), key(key_name)];
            if m.name.trim().is_empty() {
                return Err(problem(at("name"), "must not be empty"));
            }
            if self.measures[..i].iter().any(|o| o.name == m.name) {
                return Err(problem(
                    at("name"),
                    format!("duplicate measure name '{}'", m.name),
                ));
            }
            finite(m.from_s, at("from_s"))?;
            finite(m.to_s, at("to_s"))?;
            if m.from_s < 0.0 || m.from_s > self.duration_s {
                return Err(problem(
                    at("from_s"),
                    format!(
                        "window start must be inside the run [0, {}] s (got {})",
                        self.duration_s, m.from_s
                    ),
                ));
            }
            if m.to_s > self.duration_s {
                return Err(problem(
                    at("to_s"),
                    format!(
                        "window end must be inside the run [0, {}] s (got {})",
                        self.duration_s, m.to_s
                    ),
                ));
            }
            if m.from_s >= m.to_s {
                return Err(problem(
                    at("to_s"),
                    format!(
                        "window end must be after its start (from_s = {}, to_s = {})",
                        m.from_s, m.to_s
                    ),
                ));
            }
            if m.run == MeasureRun::Twin && self.twin.is_none() {
                return Err(problem(at("run"), "run = \"twin\" needs a [twin] section"));
            }
        }
        Ok(())
    }
}

/// Linear ramp from `start` (at `t0`) to `to` over `dur` seconds, evaluated at `t`:
/// (value, slope per s).
fn ramp(start: f64, to: f64, t0: f64, dur: f64, t: f64) -> (f64, f64) {
    if dur <= 0.0 || t >= t0 + dur {
        (to, 0.0)
    } else {
        let frac = ((t - t0) / dur).clamp(0.0, 1.0);
        (start + (to - start) * frac, (to - start) / dur)
    }
}

fn finite(v: f64, at: Vec<Seg>) -> Result<(), Problem> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(problem(at, format!("must be a finite number (got {v})")))
    }
}

fn positive(v: f64, at: Vec<Seg>) -> Result<(), Problem> {
    finite(v, at.clone())?;
    if v > 0.0 {
        Ok(())
    } else {
        Err(problem(at, format!("must be > 0 (got {v})")))
    }
}

fn non_negative(v: f64, at: Vec<Seg>) -> Result<(), Problem> {
    finite(v, at.clone())?;
    if v >= 0.0 {
        Ok(())
    } else {
        Err(problem(at, format!("must be >= 0 (got {v})")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = "host-sim/scenarios/x.toml";

    fn load_err(text: &str) -> ScenarioError {
        match Scenario::from_toml_str(text, FILE) {
            Ok(_) => panic!("expected an error for:\n{text}"),
            Err(e) => e,
        }
    }

    /// Asserts the message starts with `file:line` and mentions every fragment.
    fn assert_err(e: &ScenarioError, line: usize, fragments: &[&str]) {
        let msg = e.to_string();
        assert!(
            msg.starts_with(&format!("{FILE}:{line}:")),
            "wrong file/line (want {FILE}:{line}): {msg}"
        );
        assert_eq!(e.line, Some(line), "{msg}");
        for f in fragments {
            assert!(msg.contains(f), "'{f}' missing from: {msg}");
        }
    }

    const BASE: &str = "name = \"t\"\nduration_s = 4.0\n";

    #[test]
    fn minimal_file_gets_the_defaults() {
        let s = Scenario::from_toml_str(BASE, FILE).unwrap();
        assert_eq!(s.plant, PlantSpec::default());
        assert_eq!(s.sim, SimSpec::default());
        assert_eq!(s.estimator, EstimatorSpec::default());
        assert_eq!(s.seed, 1);
        assert_eq!(s.source, FILE);
        assert!((s.omega0_rad_s() - 2.618 / 3.8581e-5).abs() < 1e-9);
        let pc = 2.0 * 1.0265f64.sqrt() * DEFAULT_F0_HZ;
        assert!((s.pump_centre_hz() - pc).abs() < 1e-9);
        // Table 2 θ (FINDINGS §0: θ13 = −0.002, θ14 = −2.28e-5, θ24 = −1.77e-4).
        let at = s.plant_at(0.0);
        assert!((at.theta_drive[2] + 0.002).abs() < 1e-12);
        assert!((at.theta_drive[3] + 2.2838e-5).abs() < 1e-8);
        assert!((at.theta_sense[3] + 1.7716e-4).abs() < 1e-8);
        assert!((at.phys[10] - 3.8581e-5).abs() < 1e-9);
        assert!((at.accel_x - 0.0213).abs() < 1e-4);
        assert_eq!(at.rate_dps, 150.0);
        // phys ↔ θ consistency.
        let back = phys_from_theta(&at.theta_drive, &at.theta_sense);
        for (a, b) in back.iter().zip(at.phys) {
            assert!((a - b).abs() <= 1e-15 + 1e-12 * b.abs(), "{a} vs {b}");
        }
    }

    #[test]
    fn syntax_error_names_file_line_column() {
        let e = load_err("name = \"t\"\nduration_s = 4.0\n[plant\nwy2 = 1.0\n");
        assert_eq!(e.kind, ScenarioErrorKind::Syntax);
        assert_err(&e, 3, &["syntax error"]);
        assert!(e.column.is_some());
    }

    #[test]
    fn wrong_type_names_the_field() {
        let e = load_err(&format!("{BASE}[plant]\nmu_x = 1e-3\nwy2 = \"abc\"\n"));
        assert_eq!(e.kind, ScenarioErrorKind::Schema);
        assert_err(
            &e,
            5,
            &["field 'plant.wy2'", "expected a float", "found a string"],
        );
        let e = load_err(&format!("{BASE}[sim]\nsteps_per_period = 128.5\n"));
        assert_err(&e, 4, &["field 'sim.steps_per_period'", "integer"]);
        let e = load_err(&format!("{BASE}[estimator]\nretune = 1\n"));
        assert_err(&e, 4, &["field 'estimator.retune'", "boolean"]);
    }

    #[test]
    fn unknown_key_is_named() {
        let e = load_err(&format!("{BASE}[plant]\nwy2 = 1.03\nwz2 = 1.0\n"));
        assert_err(&e, 5, &["plant.wz2", "unknown key 'wz2'", "wy2"]);
        let e = load_err(&format!("{BASE}colour = 3\n"));
        assert_err(&e, 3, &["unknown key 'colour'"]);
        let e = load_err(&format!(
            "{BASE}[[event]]\nt_s = 1.0\nkind = \"dither\"\nenabled = true\nspeed = 2\n"
        ));
        assert_err(
            &e,
            7,
            &["event #1 (kind \"dither\")", "unknown key 'speed'"],
        );
    }

    #[test]
    fn missing_required_key() {
        let e = load_err("name = \"t\"\n[plant]\nwy2 = 1.0\n");
        assert!(e.to_string().contains("field 'duration_s'"), "{e}");
        assert!(e.to_string().contains("missing"), "{e}");
        let e = load_err(&format!("{BASE}[[measure]]\nname = \"a\"\nfrom_s = 1.0\n"));
        assert_err(&e, 3, &["measure #1 (\"a\"), field 'to_s'", "missing"]);
        let e = load_err(&format!(
            "{BASE}[[event]]\nt_s = 1.0\nkind = \"ramp\"\nto = 1.0\n"
        ));
        assert_err(&e, 3, &["event #1 (kind \"ramp\")", "'param'", "missing"]);
    }

    #[test]
    fn unknown_event_kind() {
        let e = load_err(&format!(
            "{BASE}[[event]]\nt_s = 1.0\nkind = \"dither\"\nenabled = true\n\n[[event]]\nt_s = 1.0\nkind = \"rampp\"\n"
        ));
        assert_err(
            &e,
            10,
            &[
                "event #2 (kind \"rampp\")",
                "field 'kind'",
                "unknown event kind 'rampp'",
                "scale_theta",
            ],
        );
    }

    #[test]
    fn unknown_ramp_param() {
        let e = load_err(&format!(
            "{BASE}[[event]]\nt_s = 1.0\nkind = \"ramp\"\nparam = \"wz2\"\nto = 1.0\n"
        ));
        assert_err(
            &e,
            6,
            &[
                "event #1 (kind \"ramp\")",
                "field 'param'",
                "unknown param 'wz2'",
                "wy2",
                "rate_dps",
            ],
        );
    }

    #[test]
    fn key_of_another_kind_is_rejected() {
        let e = load_err(&format!(
            "{BASE}[[event]]\nt_s = 1.0\nkind = \"ramp\"\nparam = \"wy2\"\nto = 1.0\nfactor = 2.0\n"
        ));
        assert_err(
            &e,
            8,
            &["event #1 (kind \"ramp\")", "'factor'", "does not apply"],
        );
    }

    #[test]
    fn negative_duration() {
        let e = load_err("name = \"t\"\n\nduration_s = -1\n");
        assert_eq!(e.kind, ScenarioErrorKind::Invalid);
        assert_err(&e, 3, &["field 'duration_s'", "must be > 0 (got -1)"]);
        let e = load_err(&format!(
            "{BASE}[[event]]\nt_s = 1.0\nkind = \"ramp\"\nparam = \"wy2\"\nto = 1.03\nduration_s = -0.5\n"
        ));
        assert_err(
            &e,
            8,
            &["event #1 (kind \"ramp\")", "field 'duration_s'", ">= 0"],
        );
    }

    #[test]
    fn event_past_the_end() {
        // The second event in the file comes first in time: the message still says #2.
        let e = load_err(&format!(
            "{BASE}[[event]]\nt_s = 5.0\nkind = \"dither\"\nenabled = false\n[[event]]\nt_s = 0.5\nkind = \"retune\"\nenabled = false\n"
        ));
        assert_err(
            &e,
            4,
            &[
                "event #1 (kind \"dither\")",
                "field 't_s'",
                "inside the run",
                "5",
            ],
        );
    }

    #[test]
    fn bad_measure_windows() {
        let e = load_err(&format!(
            "{BASE}[[measure]]\nname = \"a\"\nfrom_s = 2.0\nto_s = 1.0\n"
        ));
        assert_err(
            &e,
            6,
            &["measure #1 (\"a\")", "field 'to_s'", "after its start"],
        );
        let e = load_err(&format!(
            "{BASE}[[measure]]\nname = \"a\"\nfrom_s = 2.0\nto_s = 9.0\n"
        ));
        assert_err(&e, 6, &["field 'to_s'", "inside the run"]);
        let e = load_err(&format!(
            "{BASE}[[measure]]\nname = \"a\"\nfrom_s = 1.0\nto_s = 2.0\nrun = \"twin\"\n"
        ));
        assert_err(&e, 7, &["field 'run'", "[twin]"]);
        let e = load_err(&format!(
            "{BASE}[[measure]]\nname = \"a\"\nfrom_s = 1.0\nto_s = 2.0\nrun = \"other\"\n"
        ));
        assert_err(&e, 7, &["field 'run'", "unknown value 'other'", "twin"]);
    }

    #[test]
    fn non_finite_and_range_checks() {
        let e = load_err(&format!("{BASE}[plant]\nmu_x = nan\n"));
        assert_err(&e, 4, &["field 'plant.mu_x'", "finite"]);
        let e = load_err(&format!("{BASE}[sim]\nsteps_per_period = 8\n"));
        assert_err(&e, 4, &["field 'sim.steps_per_period'", ">= 16"]);
        let e = load_err(&format!("{BASE}[estimator]\nforgetting = 1.5\n"));
        assert_err(&e, 4, &["field 'estimator.forgetting'", "(0, 1]"]);
        let e = load_err(&format!("{BASE}[sim]\nnoise_pm_rthz = -1.0\n"));
        assert_err(&e, 4, &["field 'sim.noise_pm_rthz'"]);
        let e = load_err(&format!("{BASE}[twin.plant]\nwy2 = -1.0\n"));
        assert_err(&e, 4, &["field 'twin.plant.wy2'", "> 0"]);
        let e = load_err(&format!(
            "{BASE}[[event]]\nt_s = 1.0\nkind = \"pump_jump\"\ncentre_hz = 2e4\nto_sense_resonance = true\n"
        ));
        assert_err(&e, 3, &["event #1 (kind \"pump_jump\")", "not both"]);
    }

    #[test]
    fn io_and_unknown_name_errors() {
        let e = Scenario::load("no-such-scenario").unwrap_err();
        assert_eq!(e.kind, ScenarioErrorKind::UnknownScenario);
        let msg = e.to_string();
        for (name, _) in Scenario::builtin_names() {
            assert!(msg.contains(name), "{msg}");
        }
        let e = Scenario::from_file(Path::new("/nonexistent/x.toml")).unwrap_err();
        assert_eq!(e.kind, ScenarioErrorKind::Io);
        assert!(e.to_string().starts_with("/nonexistent/x.toml: "), "{e}");
    }

    fn ramp_scenario() -> Scenario {
        Scenario::from_toml_str(
            &format!(
                "{BASE}[[event]]\nt_s = 2.0\nkind = \"ramp\"\nparam = \"wy2\"\nto = 1.03\nduration_s = 0.5\n"
            ),
            FILE,
        )
        .unwrap()
    }

    #[test]
    fn plant_at_ramp() {
        let s = ramp_scenario();
        let wy2 = |t| s.plant_at(t).phys[4];
        assert_eq!(wy2(0.0), 1.0265);
        assert_eq!(wy2(2.0), 1.0265);
        assert!((wy2(2.25) - (1.0265 + 1.03) / 2.0).abs() < 1e-12);
        assert_eq!(wy2(2.5), 1.03);
        assert_eq!(wy2(3.9), 1.03);
        // θ22 follows: −(ωy² − γ²).
        let at = s.plant_at(2.25);
        let g = at.phys[10];
        assert!((at.theta_sense[1] + (wy2(2.25) - g * g)).abs() < 1e-15);
        // The rest of the plant is untouched.
        assert_eq!(at.phys[3], 1.0);
    }

    #[test]
    fn ramps_chain_from_the_current_value() {
        let s = Scenario::from_toml_str(
            &format!(
                "{BASE}[[event]]\nt_s = 3.0\nkind = \"ramp\"\nparam = \"rate_dps\"\nto = 0.0\nduration_s = 1.0\n\
                 [[event]]\nt_s = 1.0\nkind = \"ramp\"\nparam = \"rate_dps\"\nto = 300.0\nduration_s = 1.0\n"
            ),
            FILE,
        )
        .unwrap();
        assert_eq!(s.events[0].t_s, 1.0, "events are time-sorted");
        assert_eq!(s.plant_at(0.5).rate_dps, 150.0);
        assert_eq!(s.plant_at(1.5).rate_dps, 225.0);
        assert_eq!(s.plant_at(2.5).rate_dps, 300.0);
        assert_eq!(s.plant_at(3.5).rate_dps, 150.0);
        assert_eq!(s.plant_at(4.0).rate_dps, 0.0);
        // During a rate ramp γ' carries its slope (150 °/s per s).
        let w0 = s.omega0_rad_s();
        let gp = s.plant_at(1.5).phys[11];
        assert!((gp - 150f64.to_radians() / (w0 * w0)).abs() < 1e-20);
        assert_eq!(s.plant_at(2.5).phys[11], 0.0);
    }

    #[test]
    fn plant_at_scale_theta() {
        let s = Scenario::from_toml_str(
            &format!(
                "{BASE}[[event]]\nt_s = 1.0\nkind = \"scale_theta\"\nfactor = 1.5\n\
                 [[event]]\nt_s = 2.0\nkind = \"scale_theta\"\nfactor = 0.5\n\
                 [[event]]\nt_s = 3.0\nkind = \"scale_theta\"\nfactor = 1.0\n"
            ),
            FILE,
        )
        .unwrap();
        let base = s.plant_at(0.0);
        for (t, f) in [(1.0, 1.5), (1.5, 1.5), (2.0, 0.5), (2.9, 0.5)] {
            let at = s.plant_at(t);
            for i in 0..8 {
                let want = if i == 7 { 1.0 } else { f * base.theta_drive[i] };
                assert!(
                    (at.theta_drive[i] - want).abs() <= 1e-15 * want.abs(),
                    "t={t} θ1{}",
                    i + 1
                );
            }
            for i in 0..6 {
                let want = if i == 5 { 1.0 } else { f * base.theta_sense[i] };
                assert!(
                    (at.theta_sense[i] - want).abs() <= 1e-15 * want.abs(),
                    "t={t} θ2{}",
                    i + 1
                );
            }
            assert!((at.rate_dps - 150.0 * f).abs() < 1e-9);
            // phys consistent with θ: γ scales, ωy² = −θ22 + γ².
            assert!((at.phys[10] - f * base.phys[10]).abs() < 1e-18);
            let g = at.phys[10];
            assert!((at.phys[4] - (-at.theta_sense[1] + g * g)).abs() < 1e-15);
        }
        assert_eq!(s.plant_at(3.0), base, "factor 1 restores");
        // The paper's re-centred pump (FINDINGS §3.5): √(−θ22) = 1.2409 at ×1.5.
        let w = (-s.plant_at(1.0).theta_sense[1]).sqrt();
        assert!((w - 1.2409).abs() < 1e-4, "{w}");
    }

    #[test]
    fn pump_scale_and_control_events() {
        let s = Scenario::from_toml_str(
            &format!(
                "{BASE}[[event]]\nt_s = 1.0\nkind = \"pump_scale\"\ns = 0.8\nramp_s = 0.2\n\
                 [[event]]\nt_s = 0.5\nkind = \"ramp\"\nparam = \"wy2\"\nto = 1.03\n\
                 [[event]]\nt_s = 2.0\nkind = \"pump_jump\"\ncentre_hz = 21900.0\n\
                 [[event]]\nt_s = 1.5\nkind = \"dither\"\nenabled = false\n"
            ),
            FILE,
        )
        .unwrap();
        assert_eq!(s.pump_scale_at(0.9), 1.0);
        assert!((s.pump_scale_at(1.1) - 0.9).abs() < 1e-12);
        assert_eq!(s.pump_scale_at(1.2), 0.8);
        let c = s.control_events();
        let kinds: Vec<&str> = c.iter().map(|e| e.kind.name()).collect();
        assert_eq!(kinds, ["pump_scale", "dither", "pump_jump"]);
        assert_eq!(s.pump_jump_centre_hz(&c[2]), Some(21900.0));
        // Step ramp (no duration): ωy² = 1.03 from 0.5 s on.
        assert_eq!(s.plant_at(0.5).phys[4], 1.03);
    }

    #[test]
    fn every_builtin_loads_and_validates() {
        let names = Scenario::builtin_names();
        assert_eq!(names.len(), 5);
        for (name, desc) in names {
            let text = BUILTINS.iter().find(|b| b.0 == name).unwrap().2;
            let s = match Scenario::from_toml_str(text, name) {
                Ok(s) => s,
                Err(e) => panic!("built-in {name}: {e}"),
            };
            assert_eq!(s.name, name);
            assert!(!desc.is_empty() && !s.description.is_empty());
            s.validate().unwrap();
            let s = Scenario::builtin(name).unwrap();
            assert_eq!(s.source, "built-in");
            assert_eq!(Scenario::load(name).unwrap(), s);
            if let Some(t) = s.twin_scenario() {
                t.validate().unwrap();
                assert!(t.twin.is_none());
            }
        }
    }

    #[test]
    fn builtin_specifics() {
        let pc_tuned = 2.0 * 1.0265f64.sqrt() * DEFAULT_F0_HZ;

        let s = Scenario::builtin("identify").unwrap();
        assert_eq!(s.duration_s, 10.0);
        assert_eq!(s.estimator.nominal.wy2, 1.03);
        assert!((s.pump_centre_hz() - pc_tuned).abs() < 0.01);
        let (nd, ns) = s.nominal_theta();
        let at = s.plant_at(0.0);
        for (n, t) in nd
            .iter()
            .chain(&ns)
            .zip(at.theta_drive.iter().chain(&at.theta_sense))
        {
            let rel = ((n - t) / t).abs();
            assert!(rel < 0.5, "nominal θ {n} vs true {t}");
        }
        assert!(nd[..7].iter().zip(&at.theta_drive).any(|(n, t)| n != t));

        let s = Scenario::builtin("drift-retune").unwrap();
        assert_eq!(s.duration_s, 8.0);
        assert_eq!(s.plant_at(1.0).phys[4], 1.0265);
        assert_eq!(s.plant_at(2.5).phys[4], 1.03);
        assert!((s.pump_centre_hz() - pc_tuned).abs() < 0.01);
        let twin = s.twin_scenario().unwrap();
        assert!(!twin.estimator.retune);
        assert_eq!(twin.plant_at(3.0).phys[4], 1.03);
        assert_eq!(s.measures.len(), 3);
        assert!(s.estimator.retune);
        assert!(
            s.control_events()
                .iter()
                .any(|e| e.t_s == 6.0 && matches!(e.kind, EventKind::Dither { enabled: false, .. }))
        );

        let s = Scenario::builtin("paper-switch").unwrap();
        let jumps: Vec<f64> = s
            .control_events()
            .iter()
            .filter_map(|e| s.pump_jump_centre_hz(e))
            .collect();
        assert_eq!(jumps.len(), 2);
        // ω = 1.2409 and 0.7164 (FINDINGS §3.5).
        assert!((jumps[0] / (2.0 * s.sim.f0_hz) - 1.2409).abs() < 1e-4);
        assert!((jumps[1] / (2.0 * s.sim.f0_hz) - 0.7164).abs() < 1e-4);
        assert!(!s.estimator.retune);

        let s = Scenario::builtin("paper-claim").unwrap();
        assert!((s.pump_centre_hz() - pc_tuned).abs() < 0.01);
        let twin = s.twin_scenario().unwrap();
        assert_eq!(twin.plant_at(0.0).phys[4], 1.03);
        assert_eq!(twin.pump_centre_hz(), s.pump_centre_hz());
        assert!(!s.estimator.retune);
    }

    #[test]
    fn readme_example_loads() {
        let readme = include_str!("../../scenarios/README.md");
        let example = readme
            .split("## Example")
            .nth(1)
            .and_then(|r| r.split("```toml\n").nth(1))
            .and_then(|r| r.split("```").next())
            .expect("README has a ```toml example");
        let s = Scenario::from_toml_str(example, "README.md").unwrap();
        assert_eq!(s.events.len(), 3);
        assert!((s.plant_at(7.0).phys[4] - 1.0285).abs() < 1e-12);
        assert!((s.plant_at(6.0).rate_dps - 300.0).abs() < 1e-12);
        assert!(s.twin_scenario().is_some());
    }

    #[test]
    fn measure_values_average_the_sense_amplitude() {
        let s = Scenario::builtin("paper-claim").unwrap();
        let row = |t: f64, amp: f64| TraceRow {
            t_s: t,
            pump_hz: 0.0,
            pump_centre_hz: 0.0,
            pump_scale: 1.0,
            theta_drive_true: [0.0; 8],
            theta_sense_true: [0.0; 6],
            theta_drive_est: [0.0; 8],
            theta_sense_est: [0.0; 6],
            phys_true: [0.0; 12],
            phys_est: [0.0; 12],
            rate_dps_true: 0.0,
            rate_dps_est: 0.0,
            drive_amp_um: 0.0,
            sense_amp_um: amp,
            health: 0,
            resets: 0,
            bad_samples: 0,
        };
        let main: Vec<TraceRow> = (0..1000).map(|k| row(k as f64 * 0.002, 1.5)).collect();
        let twin: Vec<TraceRow> = (0..1000).map(|k| row(k as f64 * 0.002, 0.75)).collect();
        let v = s.measure_values(&main, Some(&twin));
        assert_eq!(v[0], ("sense_amp_tuned".to_string(), Some(1.5)));
        assert_eq!(v[1], ("sense_amp_detuned".to_string(), Some(0.75)));
        let v = s.measure_values(&main, None);
        assert_eq!(v[1].1, None);
    }
}
