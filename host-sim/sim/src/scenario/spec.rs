//! The specification types of a scenario: the plant, the simulation settings, the
//! estimator, the twin run, the measures, and the plant at one instant.

use serde::{Deserialize, Serialize};

use super::DEFAULT_F0_HZ;
use paragyro_core::physics;

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
    pub(super) fn entries(&self) -> [(&'static str, f64); 16] {
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
    pub(super) fn must_be_positive(self) -> bool {
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
    /// linear sweep), `"staircase"` (the new frequency and amplitude hold over the
    /// whole interval, as a DDS updated once per sample at the sample instant) or
    /// `"half-steps"` (two frequency steps per interval, 1/4 and 3/4 of the way, the scale
    /// one step: the stm32f405 and `fil` boards' DDS, its IO_UPDATE pulsed at the sample
    /// and half a period later).
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
    /// Two frequency steps per interval: from the interval's start the value 1/4 of the
    /// way from the previous command to the new one, from its middle the value 3/4 of the
    /// way (a DDS written at the sample instant and pulsed then and half a period later);
    /// each step holds the linear sweep's mean over its half, so the pump's phase at the
    /// samples is the sweep's. The scale holds the new command over the interval (one
    /// step). The core's `PumpProfile::HalfSteps`: the replica of the two steps for the
    /// frequency, ZOH for the scale (firmware/docs/notes.md "Pump profile", measured).
    #[serde(rename = "half-steps")]
    HalfSteps,
}

impl PumpProfileSpec {
    /// Simulator intervals per sample: 2 for [`PumpProfileSpec::HalfSteps`] (each half
    /// holds its own pump), 1 otherwise.
    pub fn sim_substeps(self) -> usize {
        match self {
            PumpProfileSpec::HalfSteps => 2,
            PumpProfileSpec::Linear | PumpProfileSpec::Staircase => 1,
        }
    }
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
    pub(super) fn entries(&self) -> [(&'static str, f64); 10] {
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
    /// Initial pump centre 2Ω/2π, Hz; `None`: 2·√(nominal ωy²)·f0 (see [`super::Scenario::pump_centre_hz`]).
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
    /// The slow RLS's rate random walk per sample, °/s (core `rate.walk_dps`); `None`:
    /// the core's default.
    pub rate_walk_dps: Option<f64>,
    /// The retune supervisor's tracking step, Hz (core `retune.track_hz`; 0: the pump
    /// moves only by retunes); `None`: the core's default (0.25 Hz).
    pub retune_track_hz: Option<f64>,
    /// Memory of the rate's zero μ̂xy, s (core `rate.zero_memory_s`; 0: the slow RLS's
    /// μ̂xy every sample); `None`: the core's default (3600 s).
    pub rate_zero_memory_s: Option<f64>,
    /// Drift tracking's κ (core `rls.drift_kappa`, module `drift`; 0 off); `None`: the
    /// core's default (3).
    pub drift_kappa: Option<f64>,
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
            rate_walk_dps: None,
            retune_track_hz: None,
            rate_zero_memory_s: None,
            drift_kappa: None,
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
    pub(super) fn entries(&self) -> [(&'static str, Option<f64>); 16] {
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
