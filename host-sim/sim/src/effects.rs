//! The sim-to-real effect library: what a real gyro does beyond seed 000's eq. (6)
//! (`/work/shared/design/EFFECTS.md`), as switchable, sized terms of the simulated plant,
//! its measurement and its lock-in.
//!
//! Every effect has a name (`--effect NAME=SIZE`), a size in a stated unit, and an optional
//! secondary parameter (`NAME=SIZE@PARAM`). Non-dimensional time τ = ω0·t, length L0 = 1 µm.
//!
//! | name | size (unit) | what is added |
//! |---|---|---|
//! | `geometric_nonlinearity` | j (–) | drive −j·Y(XY + 2X'Y'), sense +j·Y·X'² (seed 001) |
//! | `angular_vibration` | γ1 (°/s) `@beat_hz` (default 1.5 Hz) | γ → γ + γ1 sin(Ω_v t + φ) with Ω_v/2π = pump centre + beat: drive +2γ1 s Y' + γ1' Y, sense −2γ1 s X' − γ1' X |
//! | `electrostatic_softening` | κ (–) | sense −κ(Y + c3·Y³), c3 = [`ES_C3`] |
//! | `feedthrough` | C (µm) | measured Y + C·s·(1 + cos 2ψ) (V² of the pump, even harmonics only) |
//! | `nonlinear_damping` | η (–) | drive −η X²X', sense −η Y²Y' |
//! | `anisodamping` | d (–) | d_xy − d_yx = d: drive −(d/2)Y', sense +(d/2)X' (γ̂ biased by −d/4) |
//! | `force_leak` | ε (–) | sense +ε·s(1 + cos 2ψ)(θ16 X + θ17 X³): the pump force leaking to the sense axis |
//! | `thermal_drift` | TCF (ppm/K) | ω_x, ω_y scale by (1 + TCF·(T − 25 °C)) with the record's temperature |
//! | `lockin_mismatch` | δ (–) | the lock-in low-pass cut-off is (1 + δ) times the one in the header |
//!
//! Out of the library (the simulator can add them; the diagnosis does not know them, so it
//! should answer `unknown`):
//!
//! | name | size | what is added |
//! |---|---|---|
//! | `quadratic_stiffness` | q (–) | drive −q X², sense −q Y² |
//! | `readout_gain` | g (–) | the sense pick-off reads (1 + g)·Y |
//!
//! Effects no name here describes (the blind benchmark's out-of-library ones) come in
//! through the plant's external-term hook, [`Effects::hook`] ([`crate::plant::hook`]).

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// An effect the simulator can add: its name (`--effect NAME=SIZE`, the records' truth
/// files, the diagnosis reports), the unit of its size, what it adds, whether the diagnosis
/// library knows it, how the simulator adds it ([`Effect::add_to`]) and how the diagnosis
/// tests it ([`Effect::signature`]). Every `match` on it is exhaustive: a new effect is a new
/// variant here, and the compiler lists every place that must learn it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Effect {
    /// j: drive −j·Y(XY + 2X'Y'), sense +j·Y·X'² (seed 001).
    GeometricNonlinearity,
    /// γ1 (°/s) `@beat_hz`: γ → γ + γ1 sin(Ω_v t + φ).
    AngularVibration,
    /// κ: sense −κ(Y + c3·Y³).
    ElectrostaticSoftening,
    /// C (µm): measured Y + C·s·(1 + cos 2ψ).
    Feedthrough,
    /// η: drive −η X²X', sense −η Y²Y'.
    NonlinearDamping,
    /// d = d_xy − d_yx: drive −(d/2)Y', sense +(d/2)X'.
    Anisodamping,
    /// ε: sense +ε·s(1 + cos 2ψ)(θ16 X + θ17 X³).
    ForceLeak,
    /// TCF (ppm/K): ω_x, ω_y scale by (1 + TCF·(T − 25 °C)).
    ThermalDrift,
    /// δ: the lock-in cut-off is (1 + δ) times the header's.
    LockinMismatch,
    /// Out of library. q: drive −q X², sense −q Y².
    QuadraticStiffness,
    /// Out of library. g: the sense pick-off reads (1 + g)·Y.
    ReadoutGain,
}

/// The effects of the diagnosis library (EFFECTS.md names), in a fixed order (the order of
/// the diagnosis's candidates and of the blind benchmark's draw).
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

/// Effects the simulator can add that are deliberately not in the diagnosis library.
pub const OUT_OF_LIBRARY: [Effect; 2] = [Effect::QuadraticStiffness, Effect::ReadoutGain];

/// How the diagnosis tests an effect of its library (its columns in `y ≈ C·a`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Signature {
    /// A force term projected on the harmonics and filtered like the rows (one column).
    Force,
    /// A fixed combination of the θ columns (one column), possibly needing a record column
    /// (the rate table, the die temperature).
    Theta,
    /// The finite-difference response of the rows to a measurement change (one column).
    Measurement,
    /// An in-phase and a quadrature column at a beat found by a scan (two columns).
    Vibration,
}

impl Effect {
    /// Every effect the simulator knows, library first.
    pub const ALL: [Effect; 11] = [
        Effect::GeometricNonlinearity,
        Effect::AngularVibration,
        Effect::ElectrostaticSoftening,
        Effect::Feedthrough,
        Effect::NonlinearDamping,
        Effect::Anisodamping,
        Effect::ForceLeak,
        Effect::ThermalDrift,
        Effect::LockinMismatch,
        Effect::QuadraticStiffness,
        Effect::ReadoutGain,
    ];

    /// The name (`--effect NAME=SIZE`, truth files, reports).
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

    /// The unit of the size, for reports ("" for non-dimensional sizes).
    pub const fn unit(self) -> &'static str {
        match self {
            Effect::AngularVibration => "°/s",
            Effect::Feedthrough => "µm",
            Effect::ThermalDrift => "ppm/K",
            Effect::GeometricNonlinearity
            | Effect::ElectrostaticSoftening
            | Effect::NonlinearDamping
            | Effect::Anisodamping
            | Effect::ForceLeak
            | Effect::LockinMismatch
            | Effect::QuadraticStiffness
            | Effect::ReadoutGain => "",
        }
    }

    /// One line: the size, its unit and the terms added.
    pub const fn describe(self) -> &'static str {
        match self {
            Effect::GeometricNonlinearity => "j: drive −j·Y(XY + 2X'Y'), sense +j·Y·X'²",
            Effect::AngularVibration => {
                "γ1 °/s [@beat Hz, default 1.5]: γ + γ1·sin(Ω_v t), Ω_v = pump + beat"
            }
            Effect::ElectrostaticSoftening => {
                "κ [@1: driven by the pump, ×s]: sense −κ(Y + c3·Y³), c3 = 2/9"
            }
            Effect::Feedthrough => "C µm: measured Y + C·s(1 + cos2ψ)",
            Effect::NonlinearDamping => "η: drive −ηX²X', sense −ηY²Y'",
            Effect::Anisodamping => "d: drive −(d/2)Y', sense +(d/2)X' (rate bias −d/4 in γ)",
            Effect::ForceLeak => "ε: sense +ε·s(1 + cos2ψ)(θ16 X + θ17 X³)",
            Effect::ThermalDrift => "TCF ppm/K: ω_x, ω_y × (1 + TCF·(T − 25 °C))",
            Effect::LockinMismatch => "δ: lock-in cut-off (1 + δ) × the header's",
            Effect::QuadraticStiffness => "q: drive −qX², sense −qY²",
            Effect::ReadoutGain => "g: sense pick-off reads (1 + g)·Y",
        }
    }

    /// How the diagnosis tests it; `None`: outside the library (the diagnosis should
    /// answer `unknown` for it).
    pub const fn signature(self) -> Option<Signature> {
        match self {
            Effect::GeometricNonlinearity | Effect::NonlinearDamping | Effect::ForceLeak => {
                Some(Signature::Force)
            }
            Effect::ElectrostaticSoftening | Effect::Anisodamping | Effect::ThermalDrift => {
                Some(Signature::Theta)
            }
            Effect::Feedthrough | Effect::LockinMismatch => Some(Signature::Measurement),
            Effect::AngularVibration => Some(Signature::Vibration),
            Effect::QuadraticStiffness | Effect::ReadoutGain => None,
        }
    }

    /// Whether the diagnosis library knows it.
    pub const fn in_library(self) -> bool {
        self.signature().is_some()
    }

    /// Whether it takes a secondary parameter (`NAME=SIZE@PARAM`): the vibration's beat, Hz;
    /// the electrostatic softening's drive (`@1`: its electrodes carry the pump voltage, so
    /// κ scales with the pump's mean square s; `@0` or none: a fixed bias).
    pub const fn takes_param(self) -> bool {
        matches!(
            self,
            Effect::AngularVibration | Effect::ElectrostaticSoftening
        )
    }

    /// How the simulator adds it: `size` (and `param`) into the plant's effect sizes
    /// (sizes of repeated effects add; `gamma_per_dps` converts °/s to the non-dimensional γ).
    pub fn add_to(
        self,
        e: &mut Effects,
        size: f64,
        param: Option<f64>,
        gamma_per_dps: f64,
    ) -> Result<(), String> {
        let v = size;
        match self {
            Effect::GeometricNonlinearity => e.geometric += v,
            Effect::AngularVibration => {
                e.vib_gamma += v * gamma_per_dps;
                if let Some(b) = param {
                    e.vib_beat_hz = b;
                }
            }
            Effect::ElectrostaticSoftening => {
                e.electrostatic += v;
                match param {
                    None => {}
                    Some(p) if p == 0.0 || p == 1.0 => e.es_pump = p == 1.0,
                    Some(p) => {
                        return Err(format!(
                            "electrostatic_softening@{p}: the drive is @0 (fixed bias) or @1 (the pump's s)"
                        ));
                    }
                }
            }
            Effect::Feedthrough => e.feedthrough += v,
            Effect::NonlinearDamping => e.nl_damping += v,
            Effect::Anisodamping => e.anisodamping += v,
            Effect::ForceLeak => e.force_leak += v,
            Effect::ThermalDrift => e.tcf_ppm_k += v,
            Effect::LockinMismatch => {
                if v <= -0.9 {
                    return Err(format!("lockin_mismatch = {v} must be > −0.9"));
                }
                e.lockin_mismatch += v
            }
            Effect::QuadraticStiffness => e.quadratic += v,
            Effect::ReadoutGain => e.readout_gain += v,
        }
        Ok(())
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.name())
    }
}

/// An effect name that is not one of [`Effect::ALL`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UnknownEffect(pub String);

impl fmt::Display for UnknownEffect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let known: Vec<&str> = Effect::ALL.iter().map(|e| e.name()).collect();
        write!(
            f,
            "unknown effect '{}' (known: {})",
            self.0,
            known.join(", ")
        )
    }
}

impl std::error::Error for UnknownEffect {}

impl FromStr for Effect {
    type Err = UnknownEffect;

    /// The effect of a name; the error lists the valid names.
    fn from_str(s: &str) -> Result<Self, UnknownEffect> {
        Effect::ALL
            .into_iter()
            .find(|e| e.name() == s)
            .ok_or_else(|| UnknownEffect(s.to_string()))
    }
}

/// Cubic-to-linear ratio of the electrostatic softening (balanced parallel plates with a
/// 3 µm gap: F ∝ y + 2y³/g²).
pub const ES_C3: f64 = 2.0 / 9.0;

/// Default beat between the angular vibration and the pump centre, Hz.
pub const VIB_BEAT_HZ: f64 = 1.5;

/// Reference temperature of the simulator's configuration (thermal drift is 0 there), °C.
pub const T_REF_C: f64 = 25.0;

/// One effect and its size, as given on the command line (`NAME=SIZE[@PARAM]`); serialised
/// (truth files) as `{"name": NAME, "size": SIZE, "param"?: PARAM}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EffectSpec {
    /// The effect.
    #[serde(rename = "name")]
    pub effect: Effect,
    /// Its size (in the effect's unit, see the module docs).
    pub size: f64,
    /// Its secondary parameter (angular vibration: the beat in Hz), if given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub param: Option<f64>,
}

impl fmt::Display for EffectSpec {
    /// `NAME=SIZE[@PARAM]`, the size exact (it parses back to the same `f64`): plain between
    /// 1e-3 and 1e5 (`angular_vibration=26.92@1.5`), else in exponent form
    /// (`nonlinear_damping=9.900176026541055e-7`, not `0.0000009900176026541055`).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let a = self.size.abs();
        if a == 0.0 || (1e-3..1e5).contains(&a) || !a.is_finite() {
            write!(f, "{}={}", self.effect, self.size)?;
        } else {
            write!(f, "{}={:e}", self.effect, self.size)?;
        }
        if let Some(p) = self.param {
            write!(f, "@{p}")?;
        }
        Ok(())
    }
}

impl FromStr for EffectSpec {
    type Err = String;

    /// Parses `NAME=SIZE` or `NAME=SIZE@PARAM` and checks the name and the numbers.
    fn from_str(s: &str) -> Result<Self, String> {
        let (name, rest) = s
            .split_once('=')
            .ok_or_else(|| format!("'{s}': expected NAME=SIZE (e.g. nonlinear_damping=1e-4)"))?;
        let effect: Effect = name
            .trim()
            .parse()
            .map_err(|e: UnknownEffect| e.to_string())?;
        let (size, param) = match rest.split_once('@') {
            Some((a, b)) => (a, Some(b)),
            None => (rest, None),
        };
        let num = |v: &str, what: &str| -> Result<f64, String> {
            let x: f64 = v
                .trim()
                .parse()
                .map_err(|_| format!("'{s}': {what} '{v}' is not a number"))?;
            if x.is_finite() {
                Ok(x)
            } else {
                Err(format!("'{s}': {what} must be finite"))
            }
        };
        let size = num(size, "size")?;
        let param = param.map(|p| num(p, "parameter")).transpose()?;
        if param.is_some() && !effect.takes_param() {
            return Err(format!(
                "'{s}': only angular_vibration (@beat Hz) and electrostatic_softening (@0 or @1) take @PARAM"
            ));
        }
        Ok(EffectSpec {
            effect,
            size,
            param,
        })
    }
}

/// The effect sizes as the plant, its measurement and the runner use them
/// (non-dimensional unless stated). All zero: the nominal eq. (6).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Effects {
    /// Geometric nonlinearity j.
    pub geometric: f64,
    /// Angular vibration amplitude γ1 (non-dimensional, as γ).
    pub vib_gamma: f64,
    /// Angular vibration: beat against the initial pump centre, Hz.
    pub vib_beat_hz: f64,
    /// Angular vibration: phase φ0 of γ1·sin(Ω_v τ + φ0), rad (0 from `--effect`).
    pub vib_phase0: f64,
    /// Electrostatic softening κ.
    pub electrostatic: f64,
    /// The softening's electrodes carry the pump voltage: κ × s (its mean square).
    pub es_pump: bool,
    /// Pump feedthrough into the sense pick-off, L0 per unit s.
    pub feedthrough: f64,
    /// Amplitude-dependent damping η.
    pub nl_damping: f64,
    /// Anisodamping d = d_xy − d_yx.
    pub anisodamping: f64,
    /// Pump force leak ε.
    pub force_leak: f64,
    /// Temperature coefficient of frequency, ppm/K.
    pub tcf_ppm_k: f64,
    /// Relative lock-in cut-off error δ.
    pub lockin_mismatch: f64,
    /// Out of library: quadratic stiffness q.
    pub quadratic: f64,
    /// Out of library: sense pick-off gain error g.
    pub readout_gain: f64,
    /// An external term the simulator does not know ([`crate::plant::hook`]; `None`: none).
    pub hook: Option<crate::plant::hook::PlantHook>,
}

impl Effects {
    /// From a list of specs (sizes of repeated names add; `gamma_per_dps` converts °/s
    /// to the non-dimensional γ).
    pub fn from_specs(specs: &[EffectSpec], gamma_per_dps: f64) -> Result<Self, String> {
        let mut e = Effects {
            vib_beat_hz: VIB_BEAT_HZ,
            ..Effects::default()
        };
        for s in specs {
            s.effect.add_to(&mut e, s.size, s.param, gamma_per_dps)?;
        }
        Ok(e)
    }

    /// Whether any term of the plant's right-hand side or measurement is active (the
    /// integrator then runs its effect-aware variant).
    pub fn plant_active(&self) -> bool {
        self.geometric != 0.0
            || self.vib_gamma != 0.0
            || self.electrostatic != 0.0
            || self.feedthrough != 0.0
            || self.nl_damping != 0.0
            || self.anisodamping != 0.0
            || self.force_leak != 0.0
            || self.quadratic != 0.0
            || self.readout_gain != 0.0
            || self.hook.is_some()
    }

    /// Whether nothing is added at all.
    pub fn is_nominal(&self) -> bool {
        !self.plant_active() && self.tcf_ppm_k == 0.0 && self.lockin_mismatch == 0.0
    }

    /// θ scaled for the temperature `temp_c` (thermal drift of ω_x, ω_y): θ12 and θ22
    /// carry −ω², which scale by (1 + TCF·ΔT)².
    pub fn thermal_theta(
        &self,
        drive: &mut [f64; 8],
        sense: &mut [f64; 6],
        wx2: f64,
        wy2: f64,
        temp_c: f64,
    ) {
        if self.tcf_ppm_k == 0.0 {
            return;
        }
        let f = 1.0 + self.tcf_ppm_k * 1e-6 * (temp_c - T_REF_C);
        let g = f * f - 1.0;
        drive[1] -= g * wx2;
        sense[1] -= g * wy2;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_specs() {
        let e: EffectSpec = "nonlinear_damping=1e-4".parse().unwrap();
        assert_eq!(
            (e.effect, e.size, e.param),
            (Effect::NonlinearDamping, 1e-4, None)
        );
        let e: EffectSpec = "angular_vibration=20@2.5".parse().unwrap();
        assert_eq!((e.size, e.param), (20.0, Some(2.5)));
        assert_eq!(e.to_string(), "angular_vibration=20@2.5");
        for bad in [
            "nonlinear_damping",
            "warp_drive=1",
            "feedthrough=abc",
            "feedthrough=inf",
            "feedthrough=1@2",
        ] {
            assert!(bad.parse::<EffectSpec>().is_err(), "{bad}");
        }
        let err = "warp_drive=1".parse::<EffectSpec>().unwrap_err();
        assert!(err.contains("geometric_nonlinearity"), "{err}");
    }

    #[test]
    fn an_unknown_name_is_rejected_with_every_valid_name() {
        let err = "warp_drive".parse::<Effect>().unwrap_err().to_string();
        assert!(
            err.starts_with("unknown effect 'warp_drive' (known: "),
            "{err}"
        );
        for e in Effect::ALL {
            assert!(err.contains(e.name()), "{err} lacks {e}");
        }
        let err = "warp_drive=1".parse::<EffectSpec>().unwrap_err();
        assert!(Effect::ALL.iter().all(|e| err.contains(e.name())), "{err}");
    }

    #[test]
    fn library_and_outside_partition_every_effect() {
        let mut both: Vec<Effect> = LIBRARY.iter().chain(&OUT_OF_LIBRARY).copied().collect();
        assert_eq!(both, Effect::ALL);
        assert!(LIBRARY.iter().all(|e| e.in_library()));
        assert!(OUT_OF_LIBRARY.iter().all(|e| !e.in_library()));
        both.dedup();
        assert_eq!(both.len(), Effect::ALL.len());
        let spec: EffectSpec = "angular_vibration=20@2.5".parse().unwrap();
        let j = serde_json::to_value(&spec).unwrap();
        assert_eq!(
            j,
            serde_json::json!({"name": "angular_vibration", "size": 20.0, "param": 2.5})
        );
        assert_eq!(serde_json::from_value::<EffectSpec>(j).unwrap(), spec);
    }

    #[test]
    fn a_spec_prints_its_exact_size_readably() {
        for (text, shown) in [
            (
                "nonlinear_damping=9.900176026541055e-7",
                "nonlinear_damping=9.900176026541055e-7",
            ),
            (
                "nonlinear_damping=0.0000009900176026541055",
                "nonlinear_damping=9.900176026541055e-7",
            ),
            ("angular_vibration=26.92@1.5", "angular_vibration=26.92@1.5"),
            ("thermal_drift=-45", "thermal_drift=-45"),
            ("feedthrough=1e-4", "feedthrough=1e-4"),
        ] {
            let spec: EffectSpec = text.parse().unwrap();
            assert_eq!(spec.to_string(), shown);
            assert_eq!(shown.parse::<EffectSpec>(), Ok(spec));
        }
    }

    #[test]
    fn sizes_add_and_convert() {
        let specs: Vec<EffectSpec> = [
            "anisodamping=1e-5",
            "anisodamping=2e-5",
            "angular_vibration=10",
        ]
        .iter()
        .map(|s| s.parse().unwrap())
        .collect();
        let e = Effects::from_specs(&specs, 0.5).unwrap();
        assert!((e.anisodamping - 3e-5).abs() < 1e-18);
        assert_eq!(e.vib_gamma, 5.0);
        assert_eq!(e.vib_beat_hz, VIB_BEAT_HZ);
        assert!(e.plant_active() && !e.is_nominal());
        assert!(Effects::default().is_nominal());
    }
}
