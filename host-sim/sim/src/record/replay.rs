//! The core open-loop on a record: estimates, their CSV and the typed summary.

use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::Context;
use paragyro_core::physics::{physical_from_theta, rate_dps_from_gamma};
use paragyro_core::{Config, Counters, Estimator, Real};
use serde::Serialize;

use super::{Record, push_number};
use crate::runner::Precision;
use crate::summary::{PhysicalValues, ThetaPair};
use crate::trace::{HEALTH_NAMES, THETA_DRIVE_NAMES, THETA_SENSE_NAMES};

/// The core's estimates after one sample of a replayed record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReplayRow {
    /// Time, s (from the record).
    pub t_s: f64,
    /// Pump frequency of the record, Hz.
    pub pump_hz: f64,
    /// Pump scale s = (V_A/V_A0)² the core was given.
    pub pump_scale: f64,
    /// θ̂1 (drive, 8).
    pub theta_drive: [f64; 8],
    /// θ̂2 (sense, 6).
    pub theta_sense: [f64; 6],
    /// Estimated rate, °/s.
    pub rate_dps: f64,
    /// ω̂y² (non-dimensional).
    pub wy2: f64,
    /// Health bits (see [`HEALTH_NAMES`]).
    pub health: u32,
    /// Event bits of the step (`paragyro_core::estimator::event`).
    pub events: u8,
    /// The pump frequency the core would have commanded next (ignored in replay), Hz.
    pub pump_hz_cmd: f64,
    /// Counters after the step.
    pub counters: Counters,
}

/// The core configuration for a record of a device known only by its record: Table 2
/// design ([`Config::table2`]) with f0, fs, L0, the lock-in settings and V_A0 of the
/// header, the pump centre at the first finite positive `pump_hz` of the rows and the
/// Table 2 dither amplitude scaled to f0 (2e-3·f0).
pub fn config_for(rec: &Record) -> Config {
    let h = &rec.header;
    let mut c = Config::table2();
    c.f0_hz = h.f0_hz;
    c.fs_hz = h.fs_hz;
    c.l0_um = h.l0_um;
    c.lockin_lpf_order = h.lockin_lpf_order;
    c.lockin_lpf_hz = h.lockin_lpf_hz;
    c.pump_amp_ref_v = h.pump_amp_ref_v;
    c.dither.pump_hz = 2.0e-3 * h.f0_hz;
    if let Some(p) = rec
        .rows
        .iter()
        .map(|r| r.pump_hz)
        .find(|p| p.is_finite() && *p > 0.0)
    {
        c.pump_centre_hz = p;
    }
    c
}

/// Runs the core in precision `T` open-loop on a record: every row becomes a
/// [`paragyro_core::Sample`] ([`super::RecordRow::to_sample`]), the pump is the record's (the core's own pump
/// command is reported in [`ReplayRow::pump_hz_cmd`] and otherwise ignored). Same data
/// and configuration as a closed-loop run ⇒ the same estimates. Errors when `cfg` is
/// invalid or its fs_hz is not the record's.
pub fn replay<T: Real>(rec: &Record, cfg: &Config) -> anyhow::Result<Vec<ReplayRow>> {
    anyhow::ensure!(
        cfg.fs_hz == rec.header.fs_hz,
        "the core runs at fs_hz = {} but the record is sampled at {} Hz",
        cfg.fs_hz,
        rec.header.fs_hz
    );
    let mut est: Estimator<T> = cfg
        .build()
        .map_err(|e| anyhow::anyhow!("core configuration: {e}"))?;
    let w0 = cfg.omega0_rad_s();
    let mut out = Vec::with_capacity(rec.rows.len());
    for r in &rec.rows {
        let s = r.to_sample::<T>(&rec.header);
        let o = est.step(&s);
        let (th1, th2) = est.theta();
        let phys = physical_from_theta(&th1, &th2);
        out.push(ReplayRow {
            t_s: r.t_s,
            pump_hz: r.pump_hz,
            pump_scale: s.pump_scale.to_f64(),
            theta_drive: th1,
            theta_sense: th2,
            rate_dps: rate_dps_from_gamma(phys.gamma, w0),
            wy2: est.wy2(),
            health: o.health.bits(),
            events: o.events,
            pump_hz_cmd: o.pump_hz_next,
            counters: est.counters(),
        });
    }
    Ok(out)
}

/// Column names of the replay CSV.
pub fn replay_csv_header() -> Vec<String> {
    let mut h: Vec<String> = ["t_s", "pump_hz", "pump_scale"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    h.extend(THETA_DRIVE_NAMES.iter().map(|n| format!("{n}_est")));
    h.extend(THETA_SENSE_NAMES.iter().map(|n| format!("{n}_est")));
    h.extend(
        [
            "rate_dps_est",
            "wy2_est",
            "health",
            "events",
            "pump_hz_cmd",
            "updates",
            "bad_samples",
            "resets_drive",
            "resets_sense",
        ]
        .iter()
        .map(|s| s.to_string()),
    );
    h
}

/// Writes the replay estimates as CSV (one row per sample, [`replay_csv_header`]).
pub fn write_replay_csv<W: Write>(mut w: W, rows: &[ReplayRow]) -> anyhow::Result<()> {
    let mut line = replay_csv_header().join(",");
    line.push('\n');
    w.write_all(line.as_bytes())?;
    for r in rows {
        line.clear();
        for v in [r.t_s, r.pump_hz, r.pump_scale]
            .iter()
            .chain(&r.theta_drive)
            .chain(&r.theta_sense)
            .chain(&[r.rate_dps, r.wy2])
        {
            push_number(&mut line, *v);
            line.push(',');
        }
        let c = &r.counters;
        let _ = write!(line, "{},{},", r.health, r.events);
        push_number(&mut line, r.pump_hz_cmd);
        let _ = writeln!(
            line,
            ",{},{},{},{}",
            c.updates, c.bad_samples, c.resets_drive, c.resets_sense
        );
        w.write_all(line.as_bytes())?;
    }
    w.flush()?;
    Ok(())
}

/// The core configuration a replay ran with (the part `summary.json` shows).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[allow(missing_docs)]
pub struct ReplayConfig {
    pub f0_hz: f64,
    pub fs_hz: f64,
    pub pump_centre_hz: f64,
    pub lockin_lpf_order: usize,
    pub lockin_lpf_hz: f64,
    pub noise_pm_rthz: f64,
}

/// The core's counters at the end of a replay.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[allow(missing_docs)]
pub struct ReplayCounters {
    pub samples: u32,
    pub updates: u32,
    pub bad_samples: u32,
    pub non_finite: u32,
    pub saturated: u32,
    pub stuck: u32,
    pub resets_drive: u32,
    pub resets_sense: u32,
    pub retunes: u32,
    pub retune_aborts: u32,
}

impl From<&Counters> for ReplayCounters {
    fn from(c: &Counters) -> Self {
        ReplayCounters {
            samples: c.samples,
            updates: c.updates,
            bad_samples: c.bad_samples,
            non_finite: c.non_finite,
            saturated: c.saturated,
            stuck: c.stuck,
            resets_drive: c.resets_drive,
            resets_sense: c.resets_sense,
            retunes: c.retunes,
            retune_aborts: c.retune_aborts,
        }
    }
}

/// The estimates at the end of a replay (absent when the record had no row).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReplayFinal {
    /// θ̂ after the last sample (`{"drive": {"th11": ..}, "sense": {..}}`).
    #[serde(serialize_with = "crate::summary::theta_named")]
    pub theta_est: ThetaPair<f64>,
    /// Physical parameters from θ̂.
    pub physical_est: PhysicalValues,
    /// Estimated rate after the last sample, °/s.
    pub rate_dps_est: f64,
    /// ω̂y² after the last sample.
    pub wy2_est: f64,
    /// Mean of the finite rate estimates over the last second, °/s.
    pub rate_dps_est_mean_last_1s: Option<f64>,
    /// Mean of the record's `rate_ref_dps` over the last second, °/s (when it has it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rate_ref_dps_mean_last_1s: Option<f64>,
    /// The difference of the two means, °/s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rate_err_dps_last_1s: Option<f64>,
    /// Health flags set after the last sample (names of [`HEALTH_NAMES`]).
    pub health_final: Vec<&'static str>,
    /// The core's counters at the end.
    pub counters: ReplayCounters,
}

/// `summary.json` of a replay.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReplaySummary {
    /// The record (as named by the caller).
    pub record: String,
    /// Core precision.
    pub precision: Precision,
    /// Rows replayed.
    pub samples: usize,
    /// Duration of the record, s.
    pub duration_s: f64,
    /// The reader's warnings.
    pub warnings: Vec<String>,
    /// The core configuration.
    pub config: ReplayConfig,
    /// The final estimates (its fields are top-level keys of `summary.json`).
    #[serde(flatten)]
    pub last: Option<ReplayFinal>,
}

/// The summary of a replay: final θ̂ and physical parameters, rate (and its error against
/// `rate_ref_dps` over the last second, when the record has it), health, counters.
pub fn replay_summary(
    rec: &Record,
    source: &str,
    cfg: &Config,
    precision: Precision,
    rows: &[ReplayRow],
) -> ReplaySummary {
    let config = ReplayConfig {
        f0_hz: cfg.f0_hz,
        fs_hz: cfg.fs_hz,
        pump_centre_hz: cfg.pump_centre_hz,
        lockin_lpf_order: cfg.lockin_lpf_order,
        lockin_lpf_hz: cfg.lockin_lpf_hz,
        noise_pm_rthz: cfg.noise_pm_rthz,
    };
    ReplaySummary {
        record: source.to_string(),
        precision,
        samples: rows.len(),
        duration_s: rec.duration_s(),
        warnings: rec.warnings.clone(),
        config,
        last: rows.last().map(|last| replay_final(rec, rows, last)),
    }
}

fn replay_final(rec: &Record, rows: &[ReplayRow], last: &ReplayRow) -> ReplayFinal {
    let phys = physical_from_theta(&last.theta_drive, &last.theta_sense).as_array();
    let tail: Vec<&ReplayRow> = rows
        .iter()
        .filter(|r| r.t_s >= last.t_s - 1.0 && r.rate_dps.is_finite())
        .collect();
    let mean_rate = (!tail.is_empty())
        .then(|| tail.iter().map(|r| r.rate_dps).sum::<f64>() / tail.len() as f64);
    let refs: Vec<f64> = rec
        .rows
        .iter()
        .filter(|r| r.t_s >= last.t_s - 1.0)
        .filter_map(|r| r.rate_ref_dps)
        .filter(|v| v.is_finite())
        .collect();
    let ref_mean = (!refs.is_empty()).then(|| refs.iter().sum::<f64>() / refs.len() as f64);
    ReplayFinal {
        theta_est: ThetaPair {
            drive: last.theta_drive,
            sense: last.theta_sense,
        },
        physical_est: PhysicalValues::from_array(phys),
        rate_dps_est: last.rate_dps,
        wy2_est: last.wy2,
        rate_dps_est_mean_last_1s: mean_rate,
        rate_ref_dps_mean_last_1s: ref_mean,
        rate_err_dps_last_1s: ref_mean.and_then(|rr| Some(mean_rate? - rr)),
        health_final: HEALTH_NAMES
            .iter()
            .enumerate()
            .filter(|(i, _)| last.health & (1 << i) != 0)
            .map(|(_, n)| *n)
            .collect(),
        counters: ReplayCounters::from(&last.counters),
    }
}

/// What [`write_replay`] produced.
#[derive(Clone, Debug)]
pub struct ReplayOutputs {
    /// The files written (`estimates.csv`, `summary.json`).
    pub files: Vec<PathBuf>,
    /// The summary (as written to `summary.json`).
    pub summary: ReplaySummary,
    /// A few lines for people.
    pub text: String,
}

/// Replays a record with [`config_for`] in `precision` and writes `dir/estimates.csv` and
/// `dir/summary.json` (creating `dir`); `source` names the record in the summary.
pub fn write_replay(
    rec: &Record,
    source: &str,
    dir: &Path,
    precision: Precision,
) -> anyhow::Result<ReplayOutputs> {
    let cfg = config_for(rec);
    let rows = match precision {
        Precision::F32 => replay::<f32>(rec, &cfg),
        Precision::F64 => replay::<f64>(rec, &cfg),
    }
    .with_context(|| format!("replaying {source}"))?;
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the directory {}", dir.display()))?;
    let csv = dir.join("estimates.csv");
    let f = File::create(&csv).with_context(|| format!("cannot create {}", csv.display()))?;
    write_replay_csv(BufWriter::with_capacity(1 << 16, f), &rows)
        .with_context(|| format!("cannot write {}", csv.display()))?;
    let summary = replay_summary(rec, source, &cfg, precision, &rows);
    let sj = dir.join("summary.json");
    std::fs::write(&sj, crate::summary::to_json_pretty(&summary)?)
        .with_context(|| format!("cannot write {}", sj.display()))?;
    let mut text = format!(
        "Replayed {source}: {} samples ({:.3} s) with the {} core (pump centre {:.3} Hz from the record)\n",
        rows.len(),
        rec.duration_s(),
        precision.name(),
        cfg.pump_centre_hz
    );
    if let Some(last) = rows.last() {
        let _ = writeln!(
            text,
            "  final: rate {:.4} °/s, ωy² {:.6}, health [{}], {} bad samples, {} resets",
            last.rate_dps,
            last.wy2,
            summary
                .last
                .as_ref()
                .map(|f| f.health_final.join(", "))
                .unwrap_or_default(),
            last.counters.bad_samples,
            last.counters.resets_drive + last.counters.resets_sense
        );
    }
    Ok(ReplayOutputs {
        files: vec![csv, sj],
        summary,
        text,
    })
}
