//! [`LotRow`]: one flat row per device, its values report.json's own (the same `f64`s),
//! and the column list of the Parquet file ([`columns`]).

use std::collections::BTreeMap;

use paragyro_diagnose::diagnose::Report;
use paragyro_diagnose::diagnose::calibrate::PARAM_NAMES;
use serde::{Deserialize, Serialize};

/// The per-parameter columns, `{name}_{suffix}` for each name of [`PARAM_NAMES`]:
/// report.json's `parameter_face.parameters[]` keys `model`, `device`, `sigma`, `relative`,
/// `relative_sigma` and `t`.
pub const PARAM_SUFFIXES: [&str; 6] = ["model", "device", "sigma", "rel", "rel_sigma", "t"];

/// The diagnosis's stages (report.json's `timing_s` keys), each a column `time_{stage}_s`;
/// a stage not listed here is added to `time_other_s`.
pub const TIMING_STAGES: [&str; 7] = [
    "rows",
    "calibration_fit",
    "noise_face_and_columns",
    "catch_all_and_grams",
    "ranking_and_where",
    "confirm_by_resimulation",
    "resimulate_with_effect",
];

/// The type of a column.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// UTF-8 text (Parquet `BYTE_ARRAY (STRING)`).
    Str,
    /// `f64` (Parquet `DOUBLE`).
    F64,
    /// `i64` (Parquet `INT64`).
    I64,
}

/// One column of the row: its name, type and whether it may be null.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Column {
    /// The column's name (the row's serde key).
    pub name: String,
    /// Its type.
    pub kind: Kind,
    /// Null where absent (every column but `record` and `path`).
    pub nullable: bool,
}

/// The fixed columns, in file order; [`columns`] appends the parameter and timing columns.
const FIXED: [(&str, Kind); 46] = [
    ("record", Kind::Str),
    ("path", Kind::Str),
    ("error", Kind::Str),
    ("report_dir", Kind::Str),
    ("samples", Kind::I64),
    ("duration_s", Kind::F64),
    ("reader_warnings", Kind::I64),
    ("verdict", Kind::Str),
    ("secondary", Kind::Str),
    ("secondary_added_closure", Kind::F64),
    ("closest_library_effect", Kind::Str),
    ("top1_effect", Kind::Str),
    ("top1_size", Kind::F64),
    ("top1_sigma", Kind::F64),
    ("top1_gap_closure", Kind::F64),
    ("top2_effect", Kind::Str),
    ("top2_size", Kind::F64),
    ("top2_sigma", Kind::F64),
    ("top2_gap_closure", Kind::F64),
    ("top3_effect", Kind::Str),
    ("top3_size", Kind::F64),
    ("top3_sigma", Kind::F64),
    ("top3_gap_closure", Kind::F64),
    ("gap_before", Kind::F64),
    ("gap_after", Kind::F64),
    ("gap_closure", Kind::F64),
    ("gap_fraction_of_baseline", Kind::F64),
    ("unexplained_above_noise", Kind::F64),
    ("unexplained_rows", Kind::Str),
    ("residual_over_noise", Kind::F64),
    ("noise_energy_ratio", Kind::F64),
    ("output_error_closure", Kind::F64),
    ("rate_source", Kind::Str),
    ("rate_fitted_dps", Kind::F64),
    ("rate_offset_dps", Kind::F64),
    ("where_drive_share", Kind::F64),
    ("where_sense_share", Kind::F64),
    ("where_time_half_from_s", Kind::F64),
    ("where_time_half_to_s", Kind::F64),
    ("where_time_fraction_holding_half", Kind::F64),
    ("where_time_cusum_extreme_s", Kind::F64),
    ("confirmation_candidates", Kind::I64),
    ("limitations", Kind::Str),
    ("model", Kind::Str),
    ("seconds", Kind::F64),
    ("time_other_s", Kind::F64),
];

/// Every column of a [`LotRow`] in file order: the fixed ones, then `{p}_{suffix}` for each
/// parameter `p` of [`PARAM_NAMES`] and suffix of [`PARAM_SUFFIXES`], then
/// `time_{stage}_s` for each of [`TIMING_STAGES`].
pub fn columns() -> Vec<Column> {
    let mut out: Vec<Column> = FIXED
        .iter()
        .map(|&(name, kind)| Column {
            name: name.into(),
            kind,
            nullable: !matches!(name, "record" | "path"),
        })
        .collect();
    for p in PARAM_NAMES {
        for s in PARAM_SUFFIXES {
            out.push(Column {
                name: format!("{p}_{s}"),
                kind: Kind::F64,
                nullable: true,
            });
        }
    }
    for s in TIMING_STAGES {
        out.push(Column {
            name: timing_column(s),
            kind: Kind::F64,
            nullable: true,
        });
    }
    out
}

fn timing_column(stage: &str) -> String {
    format!("time_{stage}_s")
}

/// One device of the lot: what its record and its diagnosis say, flat. Every value is
/// report.json's own (the same `f64`), absent (`None`, null in Parquet) where report.json
/// has none or the record could not be read or diagnosed (`error`).
///
/// The parameter columns (`wy2_device`, …) and the stages' times (`time_rows_s`, …) are
/// in [`LotRow::values`] (flattened: in JSON and Parquet they are columns like the others;
/// the list is [`columns`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LotRow {
    /// The record's file name.
    pub record: String,
    /// The record's path as given.
    pub path: String,
    /// Why the record could not be read, diagnosed (or its report written); the row is
    /// kept, its diagnosis columns null.
    pub error: Option<String>,
    /// The folder of this device's report (report.md, report.json), when written.
    pub report_dir: Option<String>,
    /// Samples in the record (report.json's `samples`).
    pub samples: Option<i64>,
    /// The record's duration, first to last sample, s.
    pub duration_s: Option<f64>,
    /// The reader's warnings (unknown columns, non-finite rows).
    pub reader_warnings: Option<i64>,
    /// `none`, `unknown` or the effect's name.
    pub verdict: Option<String>,
    /// A second effect, and the share of the explainable gap it adds.
    pub secondary: Option<String>,
    pub secondary_added_closure: Option<f64>,
    /// The verdict before the residual checks.
    pub closest_library_effect: Option<String>,
    /// The three best testable candidates of the ranking (as `paragyro-sim diagnose`
    /// prints them): effect, fitted size, its σ, held-out gap closure.
    pub top1_effect: Option<String>,
    pub top1_size: Option<f64>,
    pub top1_sigma: Option<f64>,
    pub top1_gap_closure: Option<f64>,
    pub top2_effect: Option<String>,
    pub top2_size: Option<f64>,
    pub top2_sigma: Option<f64>,
    pub top2_gap_closure: Option<f64>,
    pub top3_effect: Option<String>,
    pub top3_size: Option<f64>,
    pub top3_sigma: Option<f64>,
    pub top3_gap_closure: Option<f64>,
    /// report.json's `gap_before`, `gap_after`, `gap_closure`, `gap_fraction_of_baseline`.
    pub gap_before: Option<f64>,
    pub gap_after: Option<f64>,
    pub gap_closure: Option<f64>,
    pub gap_fraction_of_baseline: Option<f64>,
    /// Share of the gap above the noise the closest library effect leaves unexplained.
    pub unexplained_above_noise: Option<f64>,
    /// report.json's `unexplained_rows`, joined by `; ` (null when there is none).
    pub unexplained_rows: Option<String>,
    /// Held-out residual over the record's own noise (about 1 at the noise).
    pub residual_over_noise: Option<f64>,
    /// The record's noise level ν² (`parameter_face.noise_energy_ratio`; 1 = 1 pm/√Hz).
    pub noise_energy_ratio: Option<f64>,
    /// `output_error.closure` (null without the re-simulation).
    pub output_error_closure: Option<f64>,
    /// `rate.source`, and the fitted rate (`rate.rate_dps`, without a rate table).
    pub rate_source: Option<String>,
    pub rate_fitted_dps: Option<f64>,
    /// `parameter_face.rate_offset_dps` (with a rate table).
    pub rate_offset_dps: Option<f64>,
    /// `where.axis.drive`, `where.axis.sense`.
    pub where_drive_share: Option<f64>,
    pub where_sense_share: Option<f64>,
    /// `where.time`: `half_of_gap_within_s` (from, to), `fraction_of_time_holding_half`,
    /// `cusum_extreme_at_s`.
    pub where_time_half_from_s: Option<f64>,
    pub where_time_half_to_s: Option<f64>,
    pub where_time_fraction_holding_half: Option<f64>,
    pub where_time_cusum_extreme_s: Option<f64>,
    /// Candidates the confirmation by re-simulation tested (`confirmation`'s length).
    pub confirmation_candidates: Option<i64>,
    /// report.json's `limitations`, `stage: detail` joined by ` | ` (null when none).
    pub limitations: Option<String>,
    /// The simulator configuration compared with (`model`).
    pub model: Option<String>,
    /// Wall time of the diagnosis, s (`seconds`).
    pub seconds: Option<f64>,
    /// `timing_s`'s stages not in [`TIMING_STAGES`], summed, s (null when none).
    pub time_other_s: Option<f64>,
    /// The parameter columns `{p}_{suffix}` ([`PARAM_SUFFIXES`]) and the stage times
    /// `time_{stage}_s`: only those present (a parameter's `rel` is absent when its model
    /// value is 0; every one when the record was not diagnosed).
    #[serde(flatten)]
    pub values: BTreeMap<String, Option<f64>>,
}

/// A parameter's columns, as report.json's `parameter_face.parameters[]` has them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamValues {
    /// The model's value.
    pub model: f64,
    /// The calibrated value.
    pub device: f64,
    /// Its 1σ.
    pub sigma: f64,
    /// `(device − model)/|model|` and its σ (absent when the model's value is 0).
    pub rel: Option<f64>,
    pub rel_sigma: Option<f64>,
    /// `(device − model)/σ`.
    pub t: f64,
}

impl LotRow {
    /// A row for a record that could not be read or diagnosed.
    pub fn failed(record: &str, path: &str, error: String) -> Self {
        LotRow {
            record: record.into(),
            path: path.into(),
            error: Some(error),
            ..LotRow::default()
        }
    }

    /// The row of a diagnosed record: `report` (report.json) with the record's `duration_s`
    /// and its reader's warning count.
    pub fn from_report(
        record: &str,
        path: &str,
        report: &Report,
        duration_s: f64,
        reader_warnings: usize,
    ) -> Self {
        let mut row = LotRow {
            record: record.into(),
            path: path.into(),
            samples: i64::try_from(report.samples).ok(),
            duration_s: Some(duration_s),
            reader_warnings: i64::try_from(reader_warnings).ok(),
            verdict: Some(report.verdict.to_string()),
            secondary: report.verdict.secondary().map(|s| s.effect.to_string()),
            secondary_added_closure: report.verdict.secondary().map(|s| s.added_closure),
            closest_library_effect: Some(report.closest_library_effect.to_string()),
            gap_before: Some(report.gap_before),
            gap_after: Some(report.gap_after),
            gap_closure: Some(report.gap_closure),
            gap_fraction_of_baseline: Some(report.gap_fraction_of_baseline),
            unexplained_above_noise: Some(report.unexplained_above_noise),
            unexplained_rows: joined(report.unexplained_rows.iter().cloned(), "; "),
            residual_over_noise: Some(report.residual_over_noise),
            noise_energy_ratio: Some(report.parameter_face.noise_energy_ratio),
            output_error_closure: report.output_error.as_ref().map(|o| o.closure),
            rate_source: Some(report.rate.source().into()),
            rate_fitted_dps: match report.rate {
                paragyro_diagnose::diagnose::Rate::Fitted { rate_dps } => rate_dps,
                paragyro_diagnose::diagnose::Rate::Table => None,
            },
            rate_offset_dps: report.parameter_face.rate_offset_dps,
            where_drive_share: Some(report.location.axis.drive),
            where_sense_share: Some(report.location.axis.sense),
            where_time_half_from_s: Some(report.location.time.half_of_gap_within_s[0]),
            where_time_half_to_s: Some(report.location.time.half_of_gap_within_s[1]),
            where_time_fraction_holding_half: Some(
                report.location.time.fraction_of_time_holding_half,
            ),
            where_time_cusum_extreme_s: Some(report.location.time.cusum_extreme_at_s),
            confirmation_candidates: i64::try_from(report.confirmation.len()).ok(),
            limitations: joined(
                report
                    .limitations
                    .iter()
                    .map(|l| format!("{}: {}", l.stage, l.detail)),
                " | ",
            ),
            model: Some(report.model.clone()),
            seconds: Some(report.seconds),
            ..LotRow::default()
        };
        row.set_candidates(report);
        row.set_values(report);
        row
    }

    fn set_candidates(&mut self, report: &Report) {
        let mut top = report.ranking.iter().filter(|c| c.untestable.is_none());
        let slots = [
            (
                &mut self.top1_effect,
                &mut self.top1_size,
                &mut self.top1_sigma,
                &mut self.top1_gap_closure,
            ),
            (
                &mut self.top2_effect,
                &mut self.top2_size,
                &mut self.top2_sigma,
                &mut self.top2_gap_closure,
            ),
            (
                &mut self.top3_effect,
                &mut self.top3_size,
                &mut self.top3_sigma,
                &mut self.top3_gap_closure,
            ),
        ];
        for (effect, size, sigma, closure) in slots {
            if let Some(c) = top.next() {
                *effect = Some(c.effect.to_string());
                *size = c.size;
                *sigma = c.size_sigma;
                *closure = Some(c.gap_closure);
            }
        }
    }

    fn set_values(&mut self, report: &Report) {
        for p in &report.parameter_face.parameters {
            if !PARAM_NAMES.contains(&p.name.as_str()) {
                continue;
            }
            let cols = [
                Some(p.model),
                Some(p.device),
                Some(p.sigma),
                p.relative,
                p.relative_sigma,
                Some(p.t),
            ];
            for (s, v) in PARAM_SUFFIXES.iter().zip(cols) {
                if let Some(v) = v {
                    self.values.insert(format!("{}_{s}", p.name), Some(v));
                }
            }
        }
        let mut other = None;
        for (stage, &s) in &report.timing_s {
            if TIMING_STAGES.contains(&stage.as_str()) {
                self.values.insert(timing_column(stage), Some(s));
            } else {
                *other.get_or_insert(0.0) += s;
            }
        }
        self.time_other_s = other;
    }

    /// A value of [`LotRow::values`] by column name (`wy2_device`, `time_rows_s`).
    pub fn value(&self, column: &str) -> Option<f64> {
        self.values.get(column).copied().flatten()
    }

    /// Parameter `name`'s columns (`None` when the record has no calibrated value of it).
    pub fn param(&self, name: &str) -> Option<ParamValues> {
        let v = |s: &str| self.value(&format!("{name}_{s}"));
        Some(ParamValues {
            model: v("model")?,
            device: v("device")?,
            sigma: v("sigma")?,
            rel: v("rel"),
            rel_sigma: v("rel_sigma"),
            t: v("t")?,
        })
    }

    /// The time of a stage of the diagnosis (`rows`, `calibration_fit`, …), s.
    pub fn stage_seconds(&self, stage: &str) -> Option<f64> {
        self.value(&timing_column(stage))
    }

    /// The record was read and diagnosed (no error).
    pub fn diagnosed(&self) -> bool {
        self.error.is_none() && self.verdict.is_some()
    }
}

fn joined(items: impl Iterator<Item = String>, sep: &str) -> Option<String> {
    let v: Vec<String> = items.collect();
    (!v.is_empty()).then(|| v.join(sep))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Parquet schema and the row's serde keys are one list: a row with every column
    /// set serialises to exactly [`columns`]'s names.
    #[test]
    fn the_columns_are_the_rows_keys() {
        let mut row = LotRow::default();
        for c in columns().into_iter().skip(FIXED.len()) {
            row.values.insert(c.name, Some(1.0));
        }
        let v = serde_json::to_value(&row).unwrap();
        let keys: std::collections::BTreeSet<String> =
            v.as_object().unwrap().keys().cloned().collect();
        let names: std::collections::BTreeSet<String> =
            columns().into_iter().map(|c| c.name).collect();
        assert_eq!(keys, names);
        assert_eq!(names.len(), columns().len(), "column names are unique");
        assert_eq!(
            columns().len(),
            FIXED.len() + PARAM_NAMES.len() * PARAM_SUFFIXES.len() + TIMING_STAGES.len()
        );
    }
}
