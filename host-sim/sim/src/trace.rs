//! The record of one simulated run: what the runner produces and what the report
//! (summary.json, trace.csv, plots) consumes. Plain data, no behaviour; the summary's
//! types are in [`crate::summary`].

use std::fmt;

use serde::Serialize;

use crate::summary::RunSummary;

/// Precision of the core instantiation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// `Estimator<f32>`: what runs on the chip.
    F32,
    /// `Estimator<f64>`: host reference.
    F64,
}

impl Precision {
    /// "f32" / "f64".
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
        }
    }
}

impl fmt::Display for Precision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Names of the 8 drive parameters θ1 (eq. 25 order), for CSV headers and plots.
pub const THETA_DRIVE_NAMES: [&str; 8] = [
    "th11", "th12", "th13", "th14", "th15", "th16", "th17", "th18",
];
/// Names of the 6 sense parameters θ2 (eq. 25 order).
pub const THETA_SENSE_NAMES: [&str; 6] = ["th21", "th22", "th23", "th24", "th25", "th26"];
/// Physical parameters recovered by the corrected Table 3, in this order.
/// (The core's `physics::PHYSICAL_NAMES`.)
pub const PHYS_NAMES: [&str; 12] = paragyro_core::physics::PHYSICAL_NAMES;
/// Health flags in bit order (bit i of `TraceRow::health` is `HEALTH_NAMES[i]`).
pub const HEALTH_NAMES: [&str; 8] = [
    "inputs_valid",
    "excitation_ok",
    "covariance_bounded",
    "change_detected",
    "drive_locked",
    "settled",
    "gated",
    "retuning",
];

/// One 500 Hz sample of a run.
#[derive(Clone, Debug, Default, Serialize)]
pub struct TraceRow {
    /// Time since the start of the run, s.
    pub t_s: f64,
    /// Pump frequency 2Ω/2π in effect at this sample, Hz.
    pub pump_hz: f64,
    /// Pump centre frequency (without the dither), Hz.
    pub pump_centre_hz: f64,
    /// Pump voltage scale s = V_A²/V_A0².
    pub pump_scale: f64,
    /// True θ1 (drive, 8) of the simulated plant at this sample.
    pub theta_drive_true: [f64; 8],
    /// True θ2 (sense, 6).
    pub theta_sense_true: [f64; 6],
    /// Estimated θ1.
    pub theta_drive_est: [f64; 8],
    /// Estimated θ2.
    pub theta_sense_est: [f64; 6],
    /// True physical parameters (order of `PHYS_NAMES`).
    pub phys_true: [f64; 12],
    /// Estimated physical parameters.
    pub phys_est: [f64; 12],
    /// True angular rate, °/s.
    pub rate_dps_true: f64,
    /// Estimated angular rate, °/s: the fast rate channel (every sample).
    pub rate_dps_est: f64,
    /// Drive fundamental amplitude |A1| from the lock-in, µm.
    pub drive_amp_um: f64,
    /// Sense fundamental amplitude |B1| from the lock-in, µm.
    pub sense_amp_um: f64,
    /// Health bits (see `HEALTH_NAMES`).
    pub health: u32,
    /// Cumulative count of covariance resets by the change detector.
    pub resets: u32,
    /// Cumulative count of samples flagged as bad input and skipped.
    pub bad_samples: u32,
    /// The slow rate, °/s: the fast one averaged over the slow RLS memory (γ of
    /// `phys_est`).
    pub rate_dps_slow: f64,
    /// The fast channel's quadrature (ωxy² + γ′) as a rate-equivalent, °/s.
    pub quadrature_dps: f64,
    /// The fast rate's validity flag.
    pub rate_valid: bool,
    /// The die temperature, °C (NaN without a `[temperature]` profile).
    pub temp_c: f64,
    /// The drift of θ12 and θ22 the core's drift tracker follows, ppm/s of |θ_design|
    /// (`Estimator::drift_ppm_s`; θ12, θ22 carry −ω², so a falling frequency drifts up).
    pub drift_ppm_s: [f64; 2],
    /// The frequency temperature coefficients the core has learned, drive and sense,
    /// ppm/K (`Estimator::thermal`; NaN until learned).
    pub tcf_ppm_k: [f64; 2],
    /// Cumulative count of change alarms read as a drift (the drift column's walk opened
    /// instead of a covariance reset; `Counters::drift_alarms`).
    pub drift_alarms: u32,
}

/// Something that happened during a run (change detected, retune started, ...).
#[derive(Clone, Debug, Serialize)]
pub struct Event {
    /// Time, s.
    pub t_s: f64,
    /// Short description.
    pub what: String,
}

/// A whole run: the trace, the events and the summary values.
#[derive(Clone, Debug, Serialize)]
pub struct RunResult {
    /// Scenario name.
    pub scenario: String,
    /// Core precision.
    pub precision: Precision,
    /// One row per 500 Hz sample.
    pub trace: Vec<TraceRow>,
    /// Events in time order.
    pub events: Vec<Event>,
    /// The summary (written as summary.json).
    pub summary: RunSummary,
    /// A twin run's trace (e.g. `drift-retune` without the retune), if the scenario asks for one.
    pub twin: Option<Vec<TraceRow>>,
}
