//! The record: one CSV format at 500 Hz for real devices and simulations
//! (`paragyro-record 1`, specified in `host-sim/sim/record-format.md`).
//!
//! ```text
//! # format: paragyro-record 1
//! # f0_hz: 10799.814…            drive natural frequency that defines ω0 = 2π·f0
//! # l0_um: 1                     length unit of the lock-in columns, µm
//! # fs_hz: 500
//! # lockin_lpf_order: 4
//! # lockin_lpf_hz: 150
//! # pump_amp_ref_v: 1            V_A0: s = (pump_amp_v / pump_amp_ref_v)²
//! t_s,pump_hz,pump_amp_v,ax_mps2,ay_mps2,x0_um,x1_re_um,…,y3_im_um[,temp_c][,rate_ref_dps]
//! 0,21883.9526,1,98.0665,98.0665,0.01,…
//! ```
//!
//! * [`write_record`] / [`write_record_to`] write it (shortest round-trip numbers);
//!   [`read_record`] / [`parse_record`] / [`read_record_from`] read it line by line with
//!   errors that name the file, the line, the column (number and name)
//!   (`file.csv:123:7: column 'x1_re_um': expected a number, found 'abc'`).
//! * [`simulate_record`] produces one from a scenario (the closed loop of
//!   [`crate::runner::simulate`] with the `f64` core) plus its truth (a JSON value that goes to
//!   `FILE.truth.json`, never into the record).
//! * [`replay`] runs the core open-loop on a record; [`config_for`] is the core
//!   configuration for a record of an unknown device.

use paragyro_core::{Config, Real, Sample};

use crate::lockin::{LockinExt, LockinOut, NCH};

mod error;
mod read;
mod replay;
mod simulate;
mod write;

pub use error::{RecordError, RecordErrorKind};
pub use read::{parse_record, read_record, read_record_from};
pub use replay::{
    ReplayConfig, ReplayCounters, ReplayFinal, ReplayOutputs, ReplayRow, ReplaySummary, config_for,
    replay, replay_csv_header, replay_summary, write_replay, write_replay_csv,
};
pub use simulate::{
    DEFAULT_TEMP_PROFILE, EffectSpec, RecordFiles, RecordOptions, RecordTruth, SIM_PUMP_AMP_REF_V,
    TruthClosedLoop, TruthEvent, TruthLockin, TruthPlant, TruthWhat, TruthXy, simulate_record,
    simulate_record_ext, simulate_record_with, truth_path, write_simulated_record,
    write_simulated_record_ext,
};
pub use write::{push_number, write_record, write_record_to};

/// Name of the format in the `# format:` line.
pub const FORMAT_NAME: &str = "paragyro-record";
/// Version this module reads and writes.
pub const FORMAT_VERSION: u32 = 1;
/// The whole `# format:` value.
pub const FORMAT: &str = "paragyro-record 1";

/// The required header keys, in the order they are written.
pub const HEADER_KEYS: [&str; 7] = [
    "format",
    "f0_hz",
    "l0_um",
    "fs_hz",
    "lockin_lpf_order",
    "lockin_lpf_hz",
    "pump_amp_ref_v",
];

/// Number of required columns: the time, the pump, the accelerations, then the lock-in.
pub const N_REQUIRED: usize = N_HEAD + NCH;

/// Number of required columns before the lock-in's.
const N_HEAD: usize = 5;

/// The required columns, in the order they are written.
pub const REQUIRED_COLUMNS: [&str; N_REQUIRED] = [
    "t_s",
    "pump_hz",
    "pump_amp_v",
    "ax_mps2",
    "ay_mps2",
    "x0_um",
    "x1_re_um",
    "x1_im_um",
    "x2_re_um",
    "x2_im_um",
    "x3_re_um",
    "x3_im_um",
    "y0_um",
    "y1_re_um",
    "y1_im_um",
    "y2_re_um",
    "y2_im_um",
    "y3_re_um",
    "y3_im_um",
];

/// The optional columns (written after the required ones, only when some row has a value;
/// an empty field means "unknown").
pub const OPTIONAL_COLUMNS: [&str; 2] = ["temp_c", "rate_ref_dps"];

/// Largest relative deviation of a `t_s` step from 1/fs_hz.
pub const SAMPLING_TOLERANCE: f64 = 0.01;

/// Index of a column among the known ones (required then optional).
const N_KNOWN: usize = N_REQUIRED + OPTIONAL_COLUMNS.len();
const COL_T: usize = 0;
const COL_TEMP: usize = N_REQUIRED;
const COL_RATE: usize = N_REQUIRED + 1;

fn known_name(i: usize) -> &'static str {
    if i < N_REQUIRED {
        REQUIRED_COLUMNS[i]
    } else {
        OPTIONAL_COLUMNS[i - N_REQUIRED]
    }
}

/// The `# key: value` lines of a record.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordHeader {
    /// Drive natural frequency f0 that defines ω0 = 2π·f0 (the model's time unit), Hz.
    pub f0_hz: f64,
    /// Length unit L0 of the lock-in columns, µm (1).
    pub l0_um: f64,
    /// Sample rate, Hz (500).
    pub fs_hz: f64,
    /// Order of the lock-in's Butterworth low-pass.
    pub lockin_lpf_order: usize,
    /// Cut-off of the lock-in low-pass, Hz.
    pub lockin_lpf_hz: f64,
    /// Pump voltage amplitude V_A0 at which s = 1, V.
    pub pump_amp_ref_v: f64,
    /// Further `# key: value` lines, in file order (kept, not interpreted).
    pub extra: Vec<(String, String)>,
}

impl RecordHeader {
    /// A header with the settings of a core configuration (no extra keys).
    pub fn from_config(cfg: &Config) -> Self {
        RecordHeader {
            f0_hz: cfg.f0_hz,
            l0_um: cfg.l0_um,
            fs_hz: cfg.fs_hz,
            lockin_lpf_order: cfg.lockin_lpf_order,
            lockin_lpf_hz: cfg.lockin_lpf_hz,
            pump_amp_ref_v: cfg.pump_amp_ref_v,
            extra: Vec::new(),
        }
    }

    /// The value of an extra key, if present (the first one).
    pub fn extra_value(&self, key: &str) -> Option<&str> {
        self.extra
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

/// The header key of a simulated record's integrator grid: the `omega_max` its RK4 step
/// count was chosen for (`runner::omega_max`). At 128 steps per period RK4 leaves an
/// oscillation 4.1e-8 slow, ∝ h⁴: a re-simulation reproduces that grid's dispersion
/// (`plant::prewarp`), or a 2 % different step would differ from the record by ≈ 8e-9 in
/// ω̂y². Only the simulator writes it; a real device's record has none.
pub const SIM_OMEGA_MAX_KEY: &str = "simulator_omega_max";

/// The header key of a simulated record's RK4 steps per carrier period at
/// [`SIM_OMEGA_MAX_KEY`] (a record without it was written at 128).
pub const SIM_STEPS_PER_PERIOD_KEY: &str = "simulator_steps_per_period";

/// One 500 Hz sample of a record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecordRow {
    /// Time, s.
    pub t_s: f64,
    /// Pump frequency 2Ω/2π in effect at the sample instant, Hz.
    pub pump_hz: f64,
    /// Pump voltage amplitude V_A, V.
    pub pump_amp_v: f64,
    /// Acceleration along the drive axis x, m/s².
    pub ax_mps2: f64,
    /// Acceleration along the sense axis y, m/s².
    pub ay_mps2: f64,
    /// The 14 lock-in channels, µm (columns `x0_um` … `y3_im_um`: the DC levels and the
    /// peak complex amplitudes of harmonics 1, 2, 3 against e^{−ikψ}).
    pub lockin: LockinOut,
    /// Temperature, °C (optional column).
    pub temp_c: Option<f64>,
    /// Known reference rate (rate table), °/s (optional column).
    pub rate_ref_dps: Option<f64>,
}

impl RecordRow {
    /// The required columns in [`REQUIRED_COLUMNS`] order (the lock-in's in
    /// [`crate::lockin::CHANNEL_NAMES`] order).
    pub fn required(&self) -> [f64; N_REQUIRED] {
        let mut v = [0.0; N_REQUIRED];
        v[..N_HEAD].copy_from_slice(&[
            self.t_s,
            self.pump_hz,
            self.pump_amp_v,
            self.ax_mps2,
            self.ay_mps2,
        ]);
        v[N_HEAD..].copy_from_slice(&self.lockin.to_channels());
        v
    }

    /// A row from the required columns in [`REQUIRED_COLUMNS`] order and the optional ones.
    pub fn from_required(
        v: &[f64; N_REQUIRED],
        temp_c: Option<f64>,
        rate_ref_dps: Option<f64>,
    ) -> Self {
        let mut ch = [0.0; NCH];
        ch.copy_from_slice(&v[N_HEAD..]);
        RecordRow {
            t_s: v[0],
            pump_hz: v[1],
            pump_amp_v: v[2],
            ax_mps2: v[3],
            ay_mps2: v[4],
            lockin: LockinOut::from_channels(&ch),
            temp_c,
            rate_ref_dps,
        }
    }

    /// The core's input for this sample: s = (pump_amp_v / pump_amp_ref_v)², lock-in in µm
    /// as recorded (the core's [`paragyro_core::Lockin`] is in µm), accelerations in m/s².
    /// NaN passes through (the core flags and skips such a sample).
    pub fn to_sample<T: Real>(&self, header: &RecordHeader) -> Sample<T> {
        Sample {
            lockin: self.lockin.to_precision::<T>(),
            accel_mps2: [T::from_f64(self.ax_mps2), T::from_f64(self.ay_mps2)],
            pump_hz: self.pump_hz,
            pump_scale: Sample::<T>::pump_scale_from_volts(self.pump_amp_v, header.pump_amp_ref_v),
            temp_c: self.temp_c.map(T::from_f64),
        }
    }

    /// |x_k| (k = 1..=3; `NaN` otherwise), µm.
    pub fn x_abs(&self, k: usize) -> f64 {
        self.lockin.x_abs(k)
    }

    /// |y_k| (k = 1..=3; `NaN` otherwise), µm.
    pub fn y_abs(&self, k: usize) -> f64 {
        self.lockin.y_abs(k)
    }
}

/// A whole record.
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    /// The header lines.
    pub header: RecordHeader,
    /// One row per sample.
    pub rows: Vec<RecordRow>,
    /// What the reader ignored or noticed (unknown columns, NaN rows); empty when written.
    pub warnings: Vec<String>,
}

impl Record {
    /// Duration from the first to the last sample, s.
    pub fn duration_s(&self) -> f64 {
        match (self.rows.first(), self.rows.last()) {
            (Some(a), Some(b)) => b.t_s - a.t_s,
            _ => 0.0,
        }
    }
}
