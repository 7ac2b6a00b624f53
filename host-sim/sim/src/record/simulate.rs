//! A record from a simulated scenario, and its truth.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use paragyro_core::Estimator;
use serde_json::{Map, Value, json};

use super::{Record, RecordHeader, RecordRow, write_record};
use crate::effects::Effects;
use crate::runner::{self, Device};
use crate::scenario::{L0_M, PlantAt, Scenario};
use crate::trace::{PHYS_NAMES, THETA_DRIVE_NAMES, THETA_SENSE_NAMES};

/// Pump voltage amplitude V0 at which s = 1 in simulated records, V.
pub const SIM_PUMP_AMP_REF_V: f64 = 1.0;

pub use crate::effects::EffectSpec;

/// Options of a simulated record.
#[derive(Clone, Debug, Default)]
pub struct RecordOptions {
    /// Overrides the scenario's noise seed.
    pub seed: Option<u64>,
    /// Effects added to the simulated device ([`crate::effects`]).
    pub effects: Vec<EffectSpec>,
    /// Die temperature `(start °C, rise K over the run)`, written as `temp_c` (with a
    /// 0.01 K sensor resolution); `None`: no temperature column, unless the thermal drift
    /// is added, which then gets the default 25 °C + 5 K.
    /// A rate table is present: write the scenario's true rate as `rate_ref_dps`.
    pub rate_table: bool,
    /// Die temperature profile (see above).
    pub temp: Option<(f64, f64)>,
}

/// Temperature profile of a record with thermal drift but no profile given: 25 °C + 5 K.
pub const DEFAULT_TEMP_PROFILE: (f64, f64) = (25.0, 5.0);

/// A simulated record of a scenario (main run, no twin) and its truth; see
/// [`simulate_record_with`].
pub fn simulate_record(sc: &Scenario, seed: Option<u64>) -> anyhow::Result<(Record, Value)> {
    let opts = RecordOptions {
        seed,
        ..RecordOptions::default()
    };
    simulate_record_with(sc, &opts, &mut |_| {})
}

/// A simulated record and its truth (JSON).
///
/// The closed loop of [`runner::simulate`] with the `f64` core and [`runner::core_config`]:
/// at every 500 Hz sample the lock-in outputs, the accelerations and the pump in effect go
/// to the core, whose command sets the pump for the next sample; each sample becomes one
/// row (the pump frequency in effect, `pump_amp_v` = V0·√s with V0 = 1 V, accelerations in
/// m/s², the 14 lock-in channels in µm). Same seed, same rows as the runner sees.
/// `progress` gets the fraction done (at most every 100 ms).
pub fn simulate_record_with(
    sc: &Scenario,
    opts: &RecordOptions,
    progress: &mut dyn FnMut(f64),
) -> anyhow::Result<(Record, Value)> {
    let gamma_per_dps = paragyro_core::physics::gamma_from_rate_dps(1.0, sc.omega0_rad_s());
    let effects = Effects::from_specs(&opts.effects, gamma_per_dps).map_err(anyhow::Error::msg)?;
    let temp = opts
        .temp
        .or((effects.tcf_ppm_k != 0.0).then_some(DEFAULT_TEMP_PROFILE));
    let dev = Device { effects, temp };
    let cfg = runner::core_config(sc);
    let mut est: Estimator<f64> = cfg
        .build()
        .map_err(|e| anyhow::anyhow!("core configuration: {e}"))?;
    let seed = opts.seed.unwrap_or(sc.seed);
    let n = (sc.duration_s * cfg.fs_hz).round() as u64;
    let mut rows = Vec::with_capacity(n as usize + 1);
    let pump_centre_initial_hz = est.pump_centre_hz();
    let mut last_progress = Instant::now();
    // the runner's closed loop: the record holds exactly what the core was given
    runner::closed_loop_with(
        sc,
        seed,
        &dev,
        &mut est,
        |_| {},
        |ls| {
            let li = ls.lockin;
            rows.push(RecordRow {
                t_s: ls.t_s,
                pump_hz: ls.sample.pump_hz,
                pump_amp_v: SIM_PUMP_AMP_REF_V * ls.sample.pump_scale.sqrt(),
                ax_mps2: ls.sample.accel_mps2[0],
                ay_mps2: ls.sample.accel_mps2[1],
                x0_um: li.x0,
                x_um: li.x,
                y0_um: li.y0,
                y_um: li.y,
                temp_c: temp.map(|_| (dev.temp_c(ls.t_s, sc.duration_s) * 100.0).round() / 100.0),
                rate_ref_dps: opts.rate_table.then_some(ls.plant.rate_dps),
            });
            if ls.k % 50 == 0 && last_progress.elapsed().as_millis() >= 100 {
                progress(ls.k as f64 / n.max(1) as f64);
                last_progress = Instant::now();
            }
        },
    )?;
    progress(1.0);
    let mut header = RecordHeader::from_config(&cfg);
    header.pump_amp_ref_v = SIM_PUMP_AMP_REF_V;
    header.extra = vec![
        (
            "generator".into(),
            format!("paragyro-sim {}", env!("CARGO_PKG_VERSION")),
        ),
        ("device".into(), "simulated".into()),
    ];
    let t_end = rows.last().map_or(0.0, |r| r.t_s);
    let truth = truth_json(
        sc,
        opts,
        seed,
        t_end,
        rows.len(),
        pump_centre_initial_hz,
        est.pump_centre_hz(),
    );
    let rec = Record {
        header,
        rows,
        warnings: Vec::new(),
    };
    Ok((rec, truth))
}

fn plant_json(pa: &PlantAt, t_s: f64, accel_si: f64) -> Value {
    let named = |names: &[&str], v: &[f64]| {
        let mut o = Map::new();
        for (n, x) in names.iter().zip(v) {
            o.insert((*n).into(), json!(x));
        }
        Value::Object(o)
    };
    json!({
        "t_s": t_s,
        "theta_drive": named(&THETA_DRIVE_NAMES, &pa.theta_drive),
        "theta_sense": named(&THETA_SENSE_NAMES, &pa.theta_sense),
        "physical": named(&PHYS_NAMES, &pa.phys),
        "rate_dps": pa.rate_dps,
        "accel_x_mps2": pa.accel_x * accel_si,
        "accel_y_mps2": pa.accel_y * accel_si,
    })
}

fn truth_json(
    sc: &Scenario,
    opts: &RecordOptions,
    seed: u64,
    t_end: f64,
    samples: usize,
    pump_centre_initial_hz: f64,
    pump_centre_final_hz: f64,
) -> Value {
    let w0 = sc.omega0_rad_s();
    let accel_si = L0_M * w0 * w0;
    let plant = |t: f64| plant_json(&sc.plant_at(t), t, accel_si);
    let events: Vec<Value> = sc
        .events
        .iter()
        .map(|e| {
            let mut v = serde_json::to_value(e).unwrap_or(Value::Null);
            if let Value::Object(m) = &mut v {
                m.insert("what".into(), json!(e.kind.to_string()));
                if let Some(c) = sc.pump_jump_centre_hz(e) {
                    m.insert("pump_centre_hz".into(), json!(c));
                }
            }
            v
        })
        .collect();
    json!({
        "format": "paragyro-record-truth 1",
        "scenario": sc.name,
        "scenario_source": sc.source,
        "description": sc.description,
        "seed": seed,
        "samples": samples,
        "duration_s": t_end,
        "f0_hz": sc.sim.f0_hz,
        "omega0_rad_s": w0,
        "noise_pm_rthz": sc.sim.noise_pm_rthz,
        "lockin": {
            "lpf_order": sc.sim.lockin_lpf_order,
            "lpf_hz": sc.sim.lockin_lpf_hz,
        },
        "steps_per_period": sc.sim.steps_per_period,
        "pump_amp_ref_v": SIM_PUMP_AMP_REF_V,
        "initial_state_um": {"x": sc.plant.initial_x_um, "y": sc.plant.initial_y_um},
        "plant_start": plant(0.0),
        "plant_end": plant(t_end),
        "events": events,
        "effects": opts.effects,
        "rate_table": opts.rate_table,
        "closed_loop": {
            "core": "f64",
            "pump_centre_initial_hz": pump_centre_initial_hz,
            "pump_centre_final_hz": pump_centre_final_hz,
        },
        "twin_ignored": sc.twin.is_some(),
        "scenario_spec": serde_json::to_value(sc).unwrap_or(Value::Null),
    })
}

/// Where the truth of a simulated record goes: `FILE.csv` → `FILE.truth.json`
/// (`FILE` → `FILE.truth.json` without a `.csv` extension).
pub fn truth_path(csv: &Path) -> PathBuf {
    let is_csv = csv
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    let base = if is_csv {
        csv.with_extension("")
    } else {
        csv.to_path_buf()
    };
    let mut name = base.file_name().unwrap_or_default().to_os_string();
    name.push(".truth.json");
    base.with_file_name(name)
}

/// The files of a simulated record.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordFiles {
    /// The record (CSV).
    pub csv: PathBuf,
    /// Its truth (JSON), beside it.
    pub truth: PathBuf,
}

/// Simulates a scenario and writes `out` (the record) and [`truth_path`]`(out)` (the
/// truth, with `"record"` set to the CSV's file name). Creates the parent directory.
pub fn write_simulated_record(
    sc: &Scenario,
    out: &Path,
    opts: &RecordOptions,
    progress: &mut dyn FnMut(f64),
) -> anyhow::Result<(RecordFiles, Record)> {
    let (rec, mut truth) = simulate_record_with(sc, opts, progress)
        .with_context(|| format!("simulating scenario '{}'", sc.name))?;
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the directory {}", dir.display()))?;
    }
    write_record(out, &rec)?;
    let tp = truth_path(out);
    if let Value::Object(m) = &mut truth {
        let name = out.file_name().map(|n| n.to_string_lossy().into_owned());
        m.insert("record".into(), json!(name));
    }
    let text = serde_json::to_string_pretty(&truth)?;
    std::fs::write(&tp, text + "\n").with_context(|| format!("cannot write {}", tp.display()))?;
    Ok((
        RecordFiles {
            csv: out.to_path_buf(),
            truth: tp,
        },
        rec,
    ))
}
