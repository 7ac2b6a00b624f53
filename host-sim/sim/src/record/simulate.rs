//! A record from a simulated scenario, and its truth.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use paragyro_core::Estimator;
use serde::Serialize;

use super::{Record, RecordHeader, RecordRow, write_record};
use crate::effects::Effects;
use crate::plant::hook::PlantHook;
use crate::runner::{self, Device};
use crate::scenario::{EventKind, EventSpec, L0_M, PlantAt, Scenario};
use crate::summary::PhysicalValues;

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
pub fn simulate_record(sc: &Scenario, seed: Option<u64>) -> anyhow::Result<(Record, RecordTruth)> {
    let opts = RecordOptions {
        seed,
        ..RecordOptions::default()
    };
    simulate_record_with(sc, &opts, &mut |_| {})
}

/// A simulated record and its truth ([`RecordTruth`]).
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
) -> anyhow::Result<(Record, RecordTruth)> {
    simulate_record_ext(sc, opts, None, progress)
}

/// [`simulate_record_with`] with an external term of the plant ([`PlantHook`]: a force,
/// states and a pick-off offset the simulator does not know; the truth names it in
/// `external_term`).
pub fn simulate_record_ext(
    sc: &Scenario,
    opts: &RecordOptions,
    hook: Option<PlantHook>,
    progress: &mut dyn FnMut(f64),
) -> anyhow::Result<(Record, RecordTruth)> {
    anyhow::ensure!(
        sc.sim.pump_profile == crate::scenario::PumpProfileSpec::Linear,
        "a record's pump sweeps linearly between samples (record-format.md); a scenario \
         with pump_profile = {:?} cannot be recorded",
        sc.sim.pump_profile
    );
    let gamma_per_dps = paragyro_core::physics::gamma_from_rate_dps(1.0, sc.omega0_rad_s());
    let mut effects =
        Effects::from_specs(&opts.effects, gamma_per_dps).map_err(anyhow::Error::msg)?;
    effects.hook = hook;
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
                lockin: *li,
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
        // the integrator's grid (not the device's): a re-simulation on the same grid has
        // the same RK4 dispersion, which then cancels (the diagnosis's numerics)
        (
            super::SIM_OMEGA_MAX_KEY.into(),
            format!("{}", runner::omega_max(sc, &cfg)),
        ),
        (
            super::SIM_STEPS_PER_PERIOD_KEY.into(),
            format!("{}", sc.sim.steps_per_period),
        ),
    ];
    let t_end = rows.last().map_or(0.0, |r| r.t_s);
    let closed_loop = TruthClosedLoop {
        core: "f64",
        pump_centre_initial_hz,
        pump_centre_final_hz: est.pump_centre_hz(),
    };
    let mut truth = record_truth(sc, opts, seed, rows.len(), t_end, closed_loop);
    truth.external_term = hook.map(|h| h.to_string());
    let rec = Record {
        header,
        rows,
        warnings: Vec::new(),
    };
    Ok((rec, truth))
}

/// The truth of a simulated record (`FILE.truth.json`, never inside the record): the
/// scenario, the seed, the plant at both ends, the events, the effects and what the closed
/// loop did.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RecordTruth {
    /// `"paragyro-record-truth 1"`.
    pub format: &'static str,
    /// Scenario name.
    pub scenario: String,
    /// Where the scenario came from.
    pub scenario_source: String,
    /// Its description.
    pub description: String,
    /// Noise seed used.
    pub seed: u64,
    /// Rows of the record.
    pub samples: usize,
    /// Time of the last row, s.
    pub duration_s: f64,
    /// Drive natural frequency, Hz.
    pub f0_hz: f64,
    /// ω0 = 2π·f0, rad/s.
    pub omega0_rad_s: f64,
    /// Displacement noise density, pm/√Hz.
    pub noise_pm_rthz: f64,
    /// The lock-in of the simulated front end.
    pub lockin: TruthLockin,
    /// RK4 steps per carrier period.
    pub steps_per_period: usize,
    /// V_A0 of the record, V.
    pub pump_amp_ref_v: f64,
    /// Initial displacement, µm.
    pub initial_state_um: TruthXy,
    /// The plant at t = 0.
    pub plant_start: TruthPlant,
    /// The plant at the last row.
    pub plant_end: TruthPlant,
    /// The scenario's events (time order), with a description and, for a pump jump, the
    /// centre it commands.
    pub events: Vec<TruthEvent>,
    /// The effects added to the simulated device.
    pub effects: Vec<EffectSpec>,
    /// An external term of the plant ([`PlantHook`], `name(parameters)`), if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub external_term: Option<String>,
    /// Whether `rate_ref_dps` was written.
    pub rate_table: bool,
    /// The core that closed the loop while recording.
    pub closed_loop: TruthClosedLoop,
    /// The scenario has a twin run, which a record leaves out.
    pub twin_ignored: bool,
    /// The whole scenario.
    pub scenario_spec: Scenario,
    /// The record's file name (set by [`write_simulated_record`]; `Some(None)`: a path
    /// without a file name).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub record: Option<Option<String>>,
}

/// The simulated lock-in's low-pass.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TruthLockin {
    /// Butterworth order.
    pub lpf_order: usize,
    /// Cut-off, Hz.
    pub lpf_hz: f64,
}

/// A pair of drive (x) and sense (y) values.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TruthXy {
    /// Drive axis.
    pub x: f64,
    /// Sense axis.
    pub y: f64,
}

/// The simulated plant at one instant.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TruthPlant {
    /// Time, s.
    pub t_s: f64,
    /// True θ1 (`{"th11": ..}`).
    #[serde(serialize_with = "crate::summary::theta_drive_named")]
    pub theta_drive: [f64; 8],
    /// True θ2 (`{"th21": ..}`).
    #[serde(serialize_with = "crate::summary::theta_sense_named")]
    pub theta_sense: [f64; 6],
    /// True physical parameters.
    pub physical: PhysicalValues,
    /// True rate, °/s.
    pub rate_dps: f64,
    /// Drive-axis acceleration, m/s².
    pub accel_x_mps2: f64,
    /// Sense-axis acceleration, m/s².
    pub accel_y_mps2: f64,
}

impl TruthPlant {
    fn new(pa: &PlantAt, t_s: f64, accel_si: f64) -> Self {
        TruthPlant {
            t_s,
            theta_drive: pa.theta_drive,
            theta_sense: pa.theta_sense,
            physical: PhysicalValues::from_array(pa.phys),
            rate_dps: pa.rate_dps,
            accel_x_mps2: pa.accel_x * accel_si,
            accel_y_mps2: pa.accel_y * accel_si,
        }
    }
}

/// One event of the scenario in the truth.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TruthEvent {
    /// The event as the scenario has it (`t_s`, `kind` and the kind's keys).
    #[serde(flatten)]
    pub event: EventSpec,
    /// One line for people.
    pub what: TruthWhat,
    /// The pump centre a `pump_jump` commands, Hz.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pump_centre_hz: Option<f64>,
}

/// An event's description, serialised as its `Display` line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruthWhat(pub EventKind);

impl Serialize for TruthWhat {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(&self.0)
    }
}

/// What the closed loop did while recording.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TruthClosedLoop {
    /// `"f64"`.
    pub core: &'static str,
    /// Pump centre at the start, Hz.
    pub pump_centre_initial_hz: f64,
    /// Pump centre at the end, Hz.
    pub pump_centre_final_hz: f64,
}

fn record_truth(
    sc: &Scenario,
    opts: &RecordOptions,
    seed: u64,
    samples: usize,
    t_end: f64,
    closed_loop: TruthClosedLoop,
) -> RecordTruth {
    let w0 = sc.omega0_rad_s();
    let accel_si = L0_M * w0 * w0;
    let plant = |t: f64| TruthPlant::new(&sc.plant_at(t), t, accel_si);
    let events = sc
        .events
        .iter()
        .map(|e| TruthEvent {
            event: *e,
            what: TruthWhat(e.kind),
            pump_centre_hz: sc.pump_jump_centre_hz(e),
        })
        .collect();
    RecordTruth {
        format: "paragyro-record-truth 1",
        scenario: sc.name.clone(),
        scenario_source: sc.source.clone(),
        description: sc.description.clone(),
        seed,
        samples,
        duration_s: t_end,
        f0_hz: sc.sim.f0_hz,
        omega0_rad_s: w0,
        noise_pm_rthz: sc.sim.noise_pm_rthz,
        lockin: TruthLockin {
            lpf_order: sc.sim.lockin_lpf_order,
            lpf_hz: sc.sim.lockin_lpf_hz,
        },
        steps_per_period: sc.sim.steps_per_period,
        pump_amp_ref_v: SIM_PUMP_AMP_REF_V,
        initial_state_um: TruthXy {
            x: sc.plant.initial_x_um,
            y: sc.plant.initial_y_um,
        },
        plant_start: plant(0.0),
        plant_end: plant(t_end),
        events,
        effects: opts.effects.clone(),
        external_term: None,
        rate_table: opts.rate_table,
        closed_loop,
        twin_ignored: sc.twin.is_some(),
        scenario_spec: sc.clone(),
        record: None,
    }
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
    write_simulated_record_ext(sc, out, opts, None, progress)
}

/// [`write_simulated_record`] with an external term of the plant ([`simulate_record_ext`]).
pub fn write_simulated_record_ext(
    sc: &Scenario,
    out: &Path,
    opts: &RecordOptions,
    hook: Option<PlantHook>,
    progress: &mut dyn FnMut(f64),
) -> anyhow::Result<(RecordFiles, Record)> {
    let (rec, mut truth) = simulate_record_ext(sc, opts, hook, progress)
        .with_context(|| format!("simulating scenario '{}'", sc.name))?;
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the directory {}", dir.display()))?;
    }
    write_record(out, &rec)?;
    let tp = truth_path(out);
    truth.record = Some(out.file_name().map(|n| n.to_string_lossy().into_owned()));
    let text = crate::summary::to_json_pretty(&truth)?;
    std::fs::write(&tp, text).with_context(|| format!("cannot write {}", tp.display()))?;
    Ok((
        RecordFiles {
            csv: out.to_path_buf(),
            truth: tp,
        },
        rec,
    ))
}
