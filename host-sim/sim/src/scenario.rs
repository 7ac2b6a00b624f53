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
use std::path::Path;

use paragyro_core::physics::{self, Physical};
use serde::Serialize;

use crate::trace::TraceRow;

/// Reference length L0 of the non-dimensional displacements, m (1 µm): the core's
/// [`physics::L0_TABLE2_M`].
pub const L0_M: f64 = physics::L0_TABLE2_M;

/// Drive natural frequency ω0/2π implied by Table 2 (γ = 3.8581e-5 ⇔ 150 °/s), Hz: the
/// core's [`physics::F0_TABLE2_HZ`].
pub const DEFAULT_F0_HZ: f64 = physics::F0_TABLE2_HZ;

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

mod error;
mod events;
mod locate;
mod parse;
mod spec;
mod temperature;
#[cfg(test)]
mod tests;
mod validate;

pub use error::{ScenarioError, ScenarioErrorKind};
pub use events::{EventKind, EventSpec, chirp_phase};
use locate::describe;
pub use spec::{
    EstimatorSpec, MeasureRun, MeasureSpec, NominalSpec, PlantAt, PlantOverrides, PlantParam,
    PlantSpec, PumpProfileSpec, SimSpec, TwinSpec,
};
pub use temperature::TemperatureSpec;

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
    /// The die temperature over the run and the plant's temperature coefficients
    /// (`[temperature]`; `None`: a constant temperature, the plant as given).
    pub temperature: Option<TemperatureSpec>,
    /// Where the scenario came from: `"built-in"` or the file path.
    pub source: String,
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

        // sines and chirps of the rate add to rate_dps (and their slope to γ′)
        for e in &self.events {
            if e.t_s <= t_s {
                let (r, slope) = e.kind.rate_profile_at(t_s - e.t_s);
                p.rate_dps += r;
                rate_slope += slope;
            }
        }
        if let Some(tp) = &self.temperature {
            tp.apply(&mut p, tp.temp_c(t_s));
        }
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

    /// The die temperature at `t_s`, °C (`None` without a `[temperature]` profile).
    pub fn temp_c(&self, t_s: f64) -> Option<f64> {
        self.temperature.as_ref().map(|tp| tp.temp_c(t_s))
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

    /// Whether the scenario moves the rate with a `rate_sine`, a `rate_chirp` or a `ramp`
    /// of `rate_dps` (the closed loop then holds θ over each sample interval at its
    /// midpoint, not its start: the held rate has no half-sample delay against the
    /// continuous one, as a real rate table's is not, and as the diagnosis re-simulates a
    /// record's `rate_ref_dps`).
    pub fn has_rate_profile(&self) -> bool {
        self.events.iter().any(|e| {
            matches!(
                e.kind,
                EventKind::RateSine { .. }
                    | EventKind::RateChirp { .. }
                    | EventKind::Ramp {
                        param: PlantParam::RateDps,
                        ..
                    }
            )
        })
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
