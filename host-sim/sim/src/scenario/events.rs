//! Scripted changes: the event types and their `[[event]]` tables.

use std::fmt;

use serde::{Deserialize, Serialize};

use super::locate::{Problem, Seg, key, problem};
use super::spec::PlantParam;

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
    /// A sine of the rate added to `rate_dps` from `t_s` for `duration_s`:
    /// `amplitude_dps · sin(2π freq_hz (t − t_s))` (starts at zero).
    RateSine {
        /// Amplitude, °/s.
        amplitude_dps: f64,
        /// Frequency, Hz.
        freq_hz: f64,
        /// Length, s.
        duration_s: f64,
    },
    /// An exponential (log-frequency) chirp of the rate added to `rate_dps` from `t_s`:
    /// `amplitude_dps · sin φ(t)`, instantaneous frequency `freq_hz → freq_end_hz` over
    /// `duration_s` (constant time per octave).
    RateChirp {
        /// Amplitude, °/s.
        amplitude_dps: f64,
        /// Start frequency, Hz.
        freq_hz: f64,
        /// End frequency, Hz.
        freq_end_hz: f64,
        /// Length, s.
        duration_s: f64,
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
            EventKind::RateSine { .. } => "rate_sine",
            EventKind::RateChirp { .. } => "rate_chirp",
        }
    }

    /// Whether the event is a control command (pump, dither, retune) rather than a plant change.
    pub fn is_control(&self) -> bool {
        !matches!(
            self,
            EventKind::Ramp { .. }
                | EventKind::ScaleTheta { .. }
                | EventKind::RateSine { .. }
                | EventKind::RateChirp { .. }
        )
    }

    /// The rate this profile event adds at `dt` seconds after its start, and its time
    /// derivative: (°/s, °/s²). Zero for other kinds and outside the profile.
    pub fn rate_profile_at(&self, dt: f64) -> (f64, f64) {
        use std::f64::consts::TAU;
        match *self {
            EventKind::RateSine {
                amplitude_dps,
                freq_hz,
                duration_s,
            } if (0.0..duration_s).contains(&dt) => {
                let w = TAU * freq_hz;
                (
                    amplitude_dps * (w * dt).sin(),
                    amplitude_dps * w * (w * dt).cos(),
                )
            }
            EventKind::RateChirp {
                amplitude_dps,
                freq_hz,
                freq_end_hz,
                duration_s,
            } if (0.0..duration_s).contains(&dt) => {
                let (phase, f) = chirp_phase(freq_hz, freq_end_hz, duration_s, dt);
                (
                    amplitude_dps * phase.sin(),
                    amplitude_dps * TAU * f * phase.cos(),
                )
            }
            _ => (0.0, 0.0),
        }
    }
}

/// Phase (rad) and instantaneous frequency (Hz) of an exponential chirp `f0 → f1` over
/// `dur` seconds, `dt` seconds after its start (a constant frequency when `f1 = f0`).
pub fn chirp_phase(f0: f64, f1: f64, dur: f64, dt: f64) -> (f64, f64) {
    use std::f64::consts::TAU;
    let r = (f1 / f0).ln();
    if r.abs() < 1e-12 {
        return (TAU * f0 * dt, f0);
    }
    let l = dur / r;
    let e = (dt / l).exp();
    (TAU * f0 * l * (e - 1.0), f0 * e)
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
            EventKind::RateSine {
                amplitude_dps,
                freq_hz,
                duration_s,
            } => write!(
                f,
                "rate sine ±{amplitude_dps} °/s at {freq_hz} Hz for {duration_s} s"
            ),
            EventKind::RateChirp {
                amplitude_dps,
                freq_hz,
                freq_end_hz,
                duration_s,
            } => write!(
                f,
                "rate chirp ±{amplitude_dps} °/s, {freq_hz} → {freq_end_hz} Hz over {duration_s} s"
            ),
        }
    }
}

/// An `[[event]]` table before its kind is known: all keys optional, checked per kind.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawEvent {
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
    amplitude_dps: Option<f64>,
    freq_hz: Option<f64>,
    freq_end_hz: Option<f64>,
}

/// Event kinds with their required and optional keys (besides `t_s` and `kind`).
pub(super) const EVENT_KINDS: [(&str, &[&str], &[&str]); 8] = [
    ("ramp", &["param", "to"], &["duration_s"]),
    ("scale_theta", &["factor"], &[]),
    ("pump_jump", &[], &["centre_hz", "to_sense_resonance"]),
    ("dither", &["enabled"], &["pump_hz"]),
    ("retune", &["enabled"], &[]),
    ("pump_scale", &["s"], &["ramp_s"]),
    (
        "rate_sine",
        &["amplitude_dps", "freq_hz", "duration_s"],
        &[],
    ),
    (
        "rate_chirp",
        &["amplitude_dps", "freq_hz", "freq_end_hz", "duration_s"],
        &[],
    ),
];

impl RawEvent {
    pub(super) fn present_keys(&self) -> Vec<&'static str> {
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
        add("amplitude_dps", self.amplitude_dps.is_some());
        add("freq_hz", self.freq_hz.is_some());
        add("freq_end_hz", self.freq_end_hz.is_some());
        keys
    }

    /// Converts event #`i` (0-based, file order).
    pub(super) fn convert(&self, i: usize) -> Result<EventSpec, Problem> {
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
            "rate_sine" => EventKind::RateSine {
                amplitude_dps: self.amplitude_dps.unwrap_or(f64::NAN),
                freq_hz: self.freq_hz.unwrap_or(f64::NAN),
                duration_s: self.duration_s.unwrap_or(f64::NAN),
            },
            "rate_chirp" => EventKind::RateChirp {
                amplitude_dps: self.amplitude_dps.unwrap_or(f64::NAN),
                freq_hz: self.freq_hz.unwrap_or(f64::NAN),
                freq_end_hz: self.freq_end_hz.unwrap_or(f64::NAN),
                duration_s: self.duration_s.unwrap_or(f64::NAN),
            },
            _ => EventKind::PumpScale {
                s: self.s.unwrap_or(f64::NAN),
                ramp_s: self.ramp_s.unwrap_or(0.0),
            },
        };
        Ok(EventSpec { t_s, kind })
    }
}
