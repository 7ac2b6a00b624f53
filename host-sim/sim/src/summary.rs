//! The typed summaries of a run (`summary.json` of `run`/`demo`) and the value types they
//! share with the replay summary (`record::ReplaySummary`).
//!
//! Everything here is plain data with `serde::Serialize`; the files are written from these
//! structs (through `serde_json::to_value`, whose maps are sorted, so the keys of the
//! written JSON come out in alphabetical order) and nothing in the project reads a summary
//! back by key: the report, the results table and the CLI read the fields.

use std::collections::BTreeMap;

use paragyro_core::Counters;
use paragyro_core::physics::{PHYSICAL_NAMES, Physical};
use serde::Serialize;
use serde::ser::{SerializeMap, Serializer};

use crate::trace::{Precision, THETA_DRIVE_NAMES, THETA_SENSE_NAMES};

/// θ1 (drive, 8) and θ2 (sense, 6) side by side, in eq. (25) order. Serialised as
/// `{"drive": [..8], "sense": [..6]}`; [`theta_flat`] and [`theta_named`] are the two
/// other spellings used in the summaries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ThetaPair<V> {
    /// θ11 … θ18.
    pub drive: [V; 8],
    /// θ21 … θ26.
    pub sense: [V; 6],
}

impl<V: Copy> ThetaPair<V> {
    /// Component `j` in 0..14 (0..8 drive, 8..14 sense).
    pub fn get(&self, j: usize) -> Option<V> {
        if j < 8 {
            Some(self.drive[j])
        } else {
            self.sense.get(j - 8).copied()
        }
    }

    /// The pair built from a function of the component index 0..14.
    pub fn from_fn(mut f: impl FnMut(usize) -> V) -> Self {
        ThetaPair {
            drive: std::array::from_fn(&mut f),
            sense: std::array::from_fn(|j| f(j + 8)),
        }
    }
}

/// Serialises `values` as an object keyed by `names`.
fn named_map<S: Serializer, V: Serialize>(
    s: S,
    names: &[&str],
    values: &[V],
) -> Result<S::Ok, S::Error> {
    let mut m = s.serialize_map(Some(values.len()))?;
    for (n, v) in names.iter().zip(values) {
        m.serialize_entry(n, v)?;
    }
    m.end()
}

/// `serialize_with` spelling of θ1 alone as `{"th11": .., …, "th18": ..}`.
pub fn theta_drive_named<S: Serializer, V: Serialize>(v: &[V; 8], s: S) -> Result<S::Ok, S::Error> {
    named_map(s, &THETA_DRIVE_NAMES, v)
}

/// `serialize_with` spelling of θ2 alone as `{"th21": .., …, "th26": ..}`.
pub fn theta_sense_named<S: Serializer, V: Serialize>(v: &[V; 6], s: S) -> Result<S::Ok, S::Error> {
    named_map(s, &THETA_SENSE_NAMES, v)
}

/// `serialize_with` spelling of a [`ThetaPair`] as one object `{"th11": .., …, "th26": ..}`.
pub fn theta_flat<S: Serializer, V: Serialize>(p: &ThetaPair<V>, s: S) -> Result<S::Ok, S::Error> {
    let mut m = s.serialize_map(Some(14))?;
    for (n, v) in THETA_DRIVE_NAMES.iter().zip(&p.drive) {
        m.serialize_entry(n, v)?;
    }
    for (n, v) in THETA_SENSE_NAMES.iter().zip(&p.sense) {
        m.serialize_entry(n, v)?;
    }
    m.end()
}

/// `serialize_with` spelling of a [`ThetaPair`] as
/// `{"drive": {"th11": .., …}, "sense": {"th21": .., …}}`.
pub fn theta_named<S: Serializer, V: Serialize>(p: &ThetaPair<V>, s: S) -> Result<S::Ok, S::Error> {
    struct Named<'a, V>(&'a [&'a str], &'a [V]);
    impl<V: Serialize> Serialize for Named<'_, V> {
        fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            named_map(s, self.0, self.1)
        }
    }
    let mut m = s.serialize_map(Some(2))?;
    m.serialize_entry("drive", &Named(&THETA_DRIVE_NAMES, &p.drive))?;
    m.serialize_entry("sense", &Named(&THETA_SENSE_NAMES, &p.sense))?;
    m.end()
}

/// The 12 physical parameters of the corrected Table 3, serialised by name (the core's
/// [`PHYSICAL_NAMES`]: `{"mu_x": .., …, "gamma_p": ..}`). A view of the core's
/// [`Physical`] (read its fields through `Deref`); the accelerometer gains `c_ax`, `c_ay`
/// are not part of it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhysicalValues(pub Physical);

impl PhysicalValues {
    /// From the array in `PHYS_NAMES` order.
    pub fn from_array(a: [f64; 12]) -> Self {
        Self(Physical::from_array(a))
    }

    /// The array in `PHYS_NAMES` order.
    pub fn as_array(&self) -> [f64; 12] {
        self.0.as_array()
    }
}

impl Default for PhysicalValues {
    fn default() -> Self {
        Self::from_array([0.0; 12])
    }
}

impl std::ops::Deref for PhysicalValues {
    type Target = Physical;
    fn deref(&self) -> &Physical {
        &self.0
    }
}

impl Serialize for PhysicalValues {
    fn serialize<S: Serializer>(&self, ser: S) -> Result<S::Ok, S::Error> {
        let mut m = ser.serialize_map(Some(PHYSICAL_NAMES.len()))?;
        for (name, v) in PHYSICAL_NAMES.iter().zip(self.as_array()) {
            m.serialize_entry(name, &v)?;
        }
        m.end()
    }
}

/// When each θ settles after the dither starts (see `runner::settle_time`), s; `None`:
/// never within the run. Serialised per tolerance as `{"th11": .., …}`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Convergence {
    /// Within 10 % for good.
    #[serde(serialize_with = "theta_flat")]
    pub within_10pct_s: ThetaPair<Option<f64>>,
    /// Within 1 % for good.
    #[serde(serialize_with = "theta_flat")]
    pub within_1pct_s: ThetaPair<Option<f64>>,
}

/// The core's counters at the end of a run (the subset `summary.json` shows).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[allow(missing_docs)]
pub struct RunCounters {
    pub samples: u32,
    pub updates: u32,
    pub bad_samples: u32,
    pub resets_drive: u32,
    pub resets_sense: u32,
    pub drift_alarms: u32,
    pub retunes: u32,
    pub retune_aborts: u32,
    pub jumps: u32,
}

impl From<&Counters> for RunCounters {
    fn from(c: &Counters) -> Self {
        RunCounters {
            samples: c.samples,
            updates: c.updates,
            bad_samples: c.bad_samples,
            resets_drive: c.resets_drive,
            resets_sense: c.resets_sense,
            drift_alarms: c.drift_alarms,
            retunes: c.retunes,
            retune_aborts: c.retune_aborts,
            jumps: c.jumps,
        }
    }
}

/// The rate output's validity flag over a run (`summary.json` `rate_validity`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct RateValidity {
    /// Samples in the run.
    pub samples: usize,
    /// Samples whose fast rate was flagged valid.
    pub valid: usize,
    /// The largest |fast rate − true rate| over the valid samples, °/s (0 with none).
    pub worst_valid_err_dps: f64,
    /// The time of that sample, s (`None` with no valid sample).
    pub worst_valid_at_s: Option<f64>,
}

impl RateValidity {
    /// From `(rate_valid, fast rate, true rate, t)` of each sample.
    pub fn of(rows: impl Iterator<Item = (bool, f64, f64, f64)>) -> Self {
        let mut v = RateValidity::default();
        for (valid, est, truth, t) in rows {
            v.samples += 1;
            if valid {
                v.valid += 1;
                // a NaN error on a valid sample is the worst there is
                let e = (est - truth).abs();
                let e = if e.is_nan() { f64::INFINITY } else { e };
                if e > v.worst_valid_err_dps || v.worst_valid_at_s.is_none() {
                    v.worst_valid_err_dps = e;
                    v.worst_valid_at_s = Some(t);
                }
            }
        }
        v
    }

    /// Of a run's trace (its `rate_valid`, `rate_dps_est`, `rate_dps_true`, `t_s`).
    pub fn of_trace(trace: &[crate::trace::TraceRow]) -> Self {
        Self::of(
            trace
                .iter()
                .map(|r| (r.rate_valid, r.rate_dps_est, r.rate_dps_true, r.t_s)),
        )
    }
}

/// `summary.json` of a run: the final sample's θ and physical parameters (true and
/// estimated), the rate, the convergence times, the core's counters, the scenario's
/// `[[measure]]` values (keys of their own, by the measure's name) and the ratios of the
/// sense-amplitude measures the built-in scenarios define.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RunSummary {
    /// Scenario name.
    pub scenario: String,
    /// Core precision.
    pub precision: Precision,
    /// Noise seed used.
    pub seed: u64,
    /// Time of the last sample, s.
    pub sim_seconds: f64,
    /// True θ at the end.
    pub theta_true: ThetaPair<f64>,
    /// Estimated θ at the end.
    pub theta_est: ThetaPair<f64>,
    /// |est − true|/|true| (|est − true| where true = 0) at the end.
    pub theta_rel_err: ThetaPair<f64>,
    /// True physical parameters at the end.
    pub physical_true: PhysicalValues,
    /// Estimated physical parameters at the end.
    pub physical_est: PhysicalValues,
    /// True rate at the end, °/s.
    pub rate_dps_true: f64,
    /// Estimated rate at the end, °/s.
    pub rate_dps_est: f64,
    /// Relative error of the rate at the end.
    pub rate_rel_err: f64,
    /// The rate output's validity over the run: how many samples were flagged valid, and
    /// the largest |fast rate − true rate| among them.
    pub rate_validity: RateValidity,
    /// True ωy² at the end.
    pub wy2_true_final: f64,
    /// Estimated ωy² at the end.
    pub wy2_est_final: f64,
    /// Pump centre at the end, Hz.
    pub pump_centre_final_hz: f64,
    /// Settling times after the dither starts.
    pub convergence_after_dither_start: Convergence,
    /// The core's counters at the end.
    pub counters: RunCounters,
    /// The scenario's measures by name (mean sense amplitude |B1| over a window, µm;
    /// `None` without data), in name order; each is a top-level key of `summary.json`.
    #[serde(flatten)]
    pub measures: BTreeMap<String, Option<f64>>,
    /// `sense_amp_detuned / sense_amp_tuned`, when both measures exist.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sense_amp_ratio: Option<f64>,
    /// `sense_amp_after_drift / sense_amp_before_drift`, when both exist.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sense_amp_after_drift_ratio: Option<f64>,
    /// `sense_amp_after_retune / sense_amp_before_drift`, when both exist.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sense_amp_after_retune_ratio: Option<f64>,
    /// The twin run's pump centre at the end, Hz (with a twin run).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub twin_pump_centre_final_hz: Option<f64>,
    /// Wall-clock time of the run (and its twin), s.
    pub wall_seconds: f64,
}

impl RunSummary {
    /// The value of the measure `name` (`None` if there is no such measure or it had no
    /// data).
    pub fn measure(&self, name: &str) -> Option<f64> {
        self.measures.get(name).copied().flatten()
    }

    /// The JSON text of `summary.json` (pretty, keys in alphabetical order, non-finite
    /// numbers as `null`), with the final newline.
    pub fn to_json_pretty(&self) -> serde_json::Result<String> {
        to_json_pretty(self)
    }
}

/// Pretty JSON of a summary with its maps sorted by key (the spelling of every
/// `summary.json`), plus the final newline.
pub fn to_json_pretty<T: Serialize>(v: &T) -> serde_json::Result<String> {
    Ok(serde_json::to_string_pretty(&serde_json::to_value(v)?)? + "\n")
}

#[cfg(test)]
mod tests {
    use super::RateValidity;

    #[test]
    fn rate_validity_counts_and_finds_the_worst_valid_sample() {
        let v = RateValidity::of(
            [
                (true, 150.5, 150.0, 0.0),
                (false, 900.0, 150.0, 0.002),
                (true, 148.0, 150.0, 0.004),
                (true, 150.0, 150.0, 0.006),
            ]
            .into_iter(),
        );
        assert_eq!((v.samples, v.valid), (4, 3));
        assert_eq!(
            (v.worst_valid_err_dps, v.worst_valid_at_s),
            (2.0, Some(0.004))
        );
        // none valid: no worst sample
        let v = RateValidity::of([(false, 1.0, 0.0, 0.0)].into_iter());
        assert_eq!((v.valid, v.worst_valid_at_s), (0, None));
        // a NaN rate flagged valid is the worst there is
        let v = RateValidity::of([(true, 1.0, 0.0, 0.0), (true, f64::NAN, 0.0, 1.0)].into_iter());
        assert_eq!(
            (v.worst_valid_err_dps, v.worst_valid_at_s),
            (f64::INFINITY, Some(1.0))
        );
    }
}
