//! Validation of every value of a scenario (ranges, finiteness, event times, measure
//! windows), with the path of the bad field.

use super::Scenario;
use super::events::EventKind;
use super::locate::{Problem, Seg, key, path, problem};
use super::spec::MeasureRun;

impl Scenario {
    /// Validation; `file_index(k)` maps the k-th (time-sorted) event to its index in the file.
    pub(super) fn check(&self, file_index: &dyn Fn(usize) -> usize) -> Result<(), Problem> {
        self.check_settings()?;
        self.check_estimator()?;
        self.check_events(file_index)?;
        self.check_twin(file_index)?;
        self.check_measures()?;
        self.check_temperature()
    }

    /// The temperature profile and coefficients.
    fn check_temperature(&self) -> Result<(), Problem> {
        match self.temperature.as_ref().and_then(|t| t.problem()) {
            Some((field, message)) => Err(problem(path(&["temperature", field]), message)),
            None => Ok(()),
        }
    }

    /// The run, the plant and the simulation settings.
    fn check_settings(&self) -> Result<(), Problem> {
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
        Ok(())
    }

    /// The estimator settings and its nominal design.
    fn check_estimator(&self) -> Result<(), Problem> {
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
        if let Some(kappa) = est.drift_kappa {
            non_negative(kappa, path(&["estimator", "drift_kappa"]))?;
        }
        if let Some(w) = est.rate_walk_dps {
            non_negative(w, path(&["estimator", "rate_walk_dps"]))?;
        }
        if let Some(t) = est.retune_track_hz {
            non_negative(t, path(&["estimator", "retune_track_hz"]))?;
        }
        if let Some(m) = est.rate_zero_memory_s {
            non_negative(m, path(&["estimator", "rate_zero_memory_s"]))?;
        }
        for (k, v) in est.nominal.entries() {
            finite(v, path(&["estimator", "nominal", k]))?;
        }
        positive(est.nominal.wx2, path(&["estimator", "nominal", "wx2"]))?;
        positive(est.nominal.wy2, path(&["estimator", "nominal", "wy2"]))?;
        Ok(())
    }

    /// The events: times inside the run, values in range per kind.
    fn check_events(&self, file_index: &dyn Fn(usize) -> usize) -> Result<(), Problem> {
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
                EventKind::RateSine {
                    amplitude_dps,
                    freq_hz,
                    duration_s,
                } => {
                    finite(amplitude_dps, at("amplitude_dps"))?;
                    positive(freq_hz, at("freq_hz"))?;
                    positive(duration_s, at("duration_s"))?;
                }
                EventKind::RateChirp {
                    amplitude_dps,
                    freq_hz,
                    freq_end_hz,
                    duration_s,
                } => {
                    finite(amplitude_dps, at("amplitude_dps"))?;
                    positive(freq_hz, at("freq_hz"))?;
                    positive(freq_end_hz, at("freq_end_hz"))?;
                    positive(duration_s, at("duration_s"))?;
                }
            }
        }
        Ok(())
    }

    /// The twin's overrides, and the twin run as a whole.
    fn check_twin(&self, file_index: &dyn Fn(usize) -> usize) -> Result<(), Problem> {
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
        Ok(())
    }

    /// The measures: names, windows inside the run, a twin for `run = "twin"`.
    fn check_measures(&self) -> Result<(), Problem> {
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

pub(super) fn finite(v: f64, at: Vec<Seg>) -> Result<(), Problem> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(problem(at, format!("must be a finite number (got {v})")))
    }
}

pub(super) fn positive(v: f64, at: Vec<Seg>) -> Result<(), Problem> {
    finite(v, at.clone())?;
    if v > 0.0 {
        Ok(())
    } else {
        Err(problem(at, format!("must be > 0 (got {v})")))
    }
}

pub(super) fn non_negative(v: f64, at: Vec<Seg>) -> Result<(), Problem> {
    finite(v, at.clone())?;
    if v >= 0.0 {
        Ok(())
    } else {
        Err(problem(at, format!("must be >= 0 (got {v})")))
    }
}
