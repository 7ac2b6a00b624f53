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

use serde::Serialize;
use std::fmt;

/// The effects of the diagnosis library (EFFECTS.md names), in a fixed order.
pub const LIBRARY: [&str; 9] = [
    "geometric_nonlinearity",
    "angular_vibration",
    "electrostatic_softening",
    "feedthrough",
    "nonlinear_damping",
    "anisodamping",
    "force_leak",
    "thermal_drift",
    "lockin_mismatch",
];

/// Effects the simulator can add that are deliberately not in the diagnosis library.
pub const OUT_OF_LIBRARY: [&str; 2] = ["quadratic_stiffness", "readout_gain"];

/// Cubic-to-linear ratio of the electrostatic softening (balanced parallel plates with a
/// 3 µm gap: F ∝ y + 2y³/g²).
pub const ES_C3: f64 = 2.0 / 9.0;

/// Default beat between the angular vibration and the pump centre, Hz.
pub const VIB_BEAT_HZ: f64 = 1.5;

/// Reference temperature of the simulator's configuration (thermal drift is 0 there), °C.
pub const T_REF_C: f64 = 25.0;

/// One effect and its size, as given on the command line (`NAME=SIZE[@PARAM]`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EffectSpec {
    /// The effect's name.
    pub name: String,
    /// Its size (in the effect's unit, see the module docs).
    pub size: f64,
    /// Its secondary parameter (angular vibration: the beat in Hz), if given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub param: Option<f64>,
}

impl fmt::Display for EffectSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}={}", self.name, self.size)?;
        if let Some(p) = self.param {
            write!(f, "@{p}")?;
        }
        Ok(())
    }
}

/// Every effect the simulator knows (library first).
pub fn known_effects() -> impl Iterator<Item = &'static str> {
    LIBRARY.iter().chain(OUT_OF_LIBRARY.iter()).copied()
}

/// Each effect with a one-line description (size, unit, terms), library first.
pub fn describe() -> Vec<(&'static str, &'static str)> {
    vec![
        (
            "geometric_nonlinearity",
            "j: drive −j·Y(XY + 2X'Y'), sense +j·Y·X'²",
        ),
        (
            "angular_vibration",
            "γ1 °/s [@beat Hz, default 1.5]: γ + γ1·sin(Ω_v t), Ω_v = pump + beat",
        ),
        (
            "electrostatic_softening",
            "κ: sense −κ(Y + c3·Y³), c3 = 2/9",
        ),
        ("feedthrough", "C µm: measured Y + C·s(1 + cos2ψ)"),
        ("nonlinear_damping", "η: drive −ηX²X', sense −ηY²Y'"),
        (
            "anisodamping",
            "d: drive −(d/2)Y', sense +(d/2)X' (rate bias −d/4 in γ)",
        ),
        ("force_leak", "ε: sense +ε·s(1 + cos2ψ)(θ16 X + θ17 X³)"),
        (
            "thermal_drift",
            "TCF ppm/K: ω_x, ω_y × (1 + TCF·(T − 25 °C))",
        ),
        (
            "lockin_mismatch",
            "δ: lock-in cut-off (1 + δ) × the header's",
        ),
        ("quadratic_stiffness", "q: drive −qX², sense −qY²"),
        ("readout_gain", "g: sense pick-off reads (1 + g)·Y"),
    ]
}

/// The unit of an effect's size, for reports.
pub fn unit(name: &str) -> &'static str {
    match name {
        "angular_vibration" => "°/s",
        "feedthrough" => "µm",
        "thermal_drift" => "ppm/K",
        _ => "",
    }
}

impl std::str::FromStr for EffectSpec {
    type Err = String;

    /// Parses `NAME=SIZE` or `NAME=SIZE@PARAM` and checks the name and the numbers.
    fn from_str(s: &str) -> Result<Self, String> {
        let (name, rest) = s
            .split_once('=')
            .ok_or_else(|| format!("'{s}': expected NAME=SIZE (e.g. nonlinear_damping=1e-4)"))?;
        let name = name.trim();
        if !known_effects().any(|k| k == name) {
            return Err(format!(
                "unknown effect '{name}' (known: {})",
                known_effects().collect::<Vec<_>>().join(", ")
            ));
        }
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
        if param.is_some() && name != "angular_vibration" {
            return Err(format!(
                "'{s}': only angular_vibration takes @PARAM (beat, Hz)"
            ));
        }
        Ok(EffectSpec {
            name: name.to_string(),
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
            let v = s.size;
            match s.name.as_str() {
                "geometric_nonlinearity" => e.geometric += v,
                "angular_vibration" => {
                    e.vib_gamma += v * gamma_per_dps;
                    if let Some(b) = s.param {
                        e.vib_beat_hz = b;
                    }
                }
                "electrostatic_softening" => e.electrostatic += v,
                "feedthrough" => e.feedthrough += v,
                "nonlinear_damping" => e.nl_damping += v,
                "anisodamping" => e.anisodamping += v,
                "force_leak" => e.force_leak += v,
                "thermal_drift" => e.tcf_ppm_k += v,
                "lockin_mismatch" => {
                    if v <= -0.9 {
                        return Err(format!("lockin_mismatch = {v} must be > −0.9"));
                    }
                    e.lockin_mismatch += v
                }
                "quadratic_stiffness" => e.quadratic += v,
                "readout_gain" => e.readout_gain += v,
                other => return Err(format!("unknown effect '{other}'")),
            }
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
            (e.name.as_str(), e.size, e.param),
            ("nonlinear_damping", 1e-4, None)
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
