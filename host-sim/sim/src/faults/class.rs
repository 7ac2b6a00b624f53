//! The fault classes and the seeded plan of their episodes.

use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::{Deserialize, Serialize};

/// One class of fault the campaign injects.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultClass {
    /// NaN in one channel (any of the 14 lock-in channels, the 2 accelerometer channels or
    /// the pump frequency), 1–50 ticks.
    Nan,
    /// ±Inf in one channel (as `Nan`), 1–50 ticks.
    Inf,
    /// One lock-in or accelerometer channel at 1–3× its full scale, 1–100 ticks.
    Saturation,
    /// One lock-in channel frozen at its value, 60–1000 ticks (the detector's limit is
    /// `monitor.stuck_samples` = 50 repeats).
    Stuck,
    /// An additive spike inside the full scale (0.05–10 µm, log-uniform) on one lock-in
    /// channel, 1–3 ticks.
    Spike,
    /// 1–5 consecutive samples never reach the core (the plant runs on).
    Dropped,
    /// A time jump: 50–1000 samples (0.1–2 s) never reach the core.
    TimeJump,
    /// An ADS131M08 frame that fails its CRC: the firmware turns that axis' seven
    /// channels into NaN (firmware/src/app.rs), 1–20 ticks.
    SpiCrc,
    /// DRDY missing on both ADCs (their DRDY flags not set): all 14 lock-in channels NaN,
    /// 1–50 ticks.
    DrdyMissing,
    /// The accelerometer lost: both acceleration channels NaN, 50–2500 ticks.
    AccelLost,
    /// The DDS writes fail: the pump in effect (frequency and scale) stays the previous
    /// one, and the sample reports it (as the firmware does), 1–250 ticks.
    DdsFail,
    /// The drive stiffness ωx² moves by ±3–10 %: the pump falls out of the drive's
    /// parametric band, 250–1500 ticks, then back.
    DriveOutOfBand,
    /// The pump amplitude collapses to 0–30 % of its voltage (s ×0–0.09) without the
    /// core knowing, 250–2500 ticks.
    PumpCollapse,
    /// ωy² of the plant jumps by ±0.1–1 % (relative to the scenario's) and stays there
    /// until the next episode.
    ParamJump,
    /// The angular rate jumps to ±3000–20000 °/s (the sense channels beyond 20 µm full
    /// scale at ≳ 2000 °/s), 250–2500 ticks, then back.
    RateOverrange,
}

impl FaultClass {
    /// Every class, in the report's order.
    pub const ALL: [FaultClass; 15] = [
        FaultClass::Nan,
        FaultClass::Inf,
        FaultClass::Saturation,
        FaultClass::Stuck,
        FaultClass::Spike,
        FaultClass::Dropped,
        FaultClass::TimeJump,
        FaultClass::SpiCrc,
        FaultClass::DrdyMissing,
        FaultClass::AccelLost,
        FaultClass::DdsFail,
        FaultClass::DriveOutOfBand,
        FaultClass::PumpCollapse,
        FaultClass::ParamJump,
        FaultClass::RateOverrange,
    ];

    /// The name in `faults.json` and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            FaultClass::Nan => "nan",
            FaultClass::Inf => "inf",
            FaultClass::Saturation => "saturation",
            FaultClass::Stuck => "stuck",
            FaultClass::Spike => "spike",
            FaultClass::Dropped => "dropped",
            FaultClass::TimeJump => "time_jump",
            FaultClass::SpiCrc => "spi_crc",
            FaultClass::DrdyMissing => "drdy_missing",
            FaultClass::AccelLost => "accel_lost",
            FaultClass::DdsFail => "dds_fail",
            FaultClass::DriveOutOfBand => "drive_out_of_band",
            FaultClass::PumpCollapse => "pump_collapse",
            FaultClass::ParamJump => "param_jump",
            FaultClass::RateOverrange => "rate_overrange",
        }
    }

    /// The class of a name ([`FaultClass::name`]).
    pub fn from_name(name: &str) -> Option<FaultClass> {
        FaultClass::ALL.into_iter().find(|c| c.name() == name)
    }

    /// The core should raise a flag for this class (bad input, change detected or drive
    /// lock lost). Not for the classes the core cannot see in its inputs: a spike inside
    /// the full scale, lost samples (the sample carries no index), a DDS failure (the
    /// sample reports the pump in effect, so the core's known signals stay right).
    pub fn flag_expected(self) -> bool {
        !matches!(
            self,
            FaultClass::Spike | FaultClass::Dropped | FaultClass::TimeJump | FaultClass::DdsFail
        )
    }

    /// Episode length range, ticks (inclusive); `ParamJump` lasts until the next one.
    fn len_range(self) -> (u64, u64) {
        match self {
            FaultClass::Nan | FaultClass::Inf | FaultClass::DrdyMissing => (1, 50),
            FaultClass::Saturation => (1, 100),
            FaultClass::Stuck => (60, 1000),
            FaultClass::Spike => (1, 3),
            FaultClass::Dropped => (1, 5),
            FaultClass::TimeJump => (50, 1000),
            FaultClass::SpiCrc => (1, 20),
            FaultClass::AccelLost => (50, 2500),
            FaultClass::DdsFail => (1, 250),
            FaultClass::DriveOutOfBand => (250, 1500),
            FaultClass::PumpCollapse | FaultClass::RateOverrange => (250, 2500),
            FaultClass::ParamJump => (1, 1),
        }
    }
}

/// Number of channels a value fault may hit: 14 lock-in, 2 accelerometer, the pump.
pub const N_TARGETS: usize = 17;

/// One episode of a fault: ticks `start..start + len`, a channel and a size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Episode {
    /// First faulted tick.
    pub start: u64,
    /// Faulted ticks.
    pub len: u64,
    /// Channel: 0..14 lock-in (`Lockin::channels` order), 14..16 accelerometer, 16 the
    /// pump frequency; for `SpiCrc` 0 drive, 1 sense axis.
    pub channel: usize,
    /// Size, in the class's terms (a multiple of full scale, µm, a relative change,
    /// °/s, a factor on s), sign included.
    pub size: f64,
}

impl Episode {
    /// One past the last faulted tick.
    pub fn end(&self) -> u64 {
        self.start + self.len
    }
    /// Tick `k` is faulted.
    pub fn active(&self, k: u64) -> bool {
        k >= self.start && k < self.end()
    }
}

/// When episodes happen: after `warmup` ticks, one per `slot` ticks, starting at a
/// random offset in the slot's first fifth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Schedule {
    /// Total ticks.
    pub ticks: u64,
    /// Clean ticks before the first slot (the estimate converges).
    pub warmup: u64,
    /// Ticks per episode slot (the episode, then time to recover).
    pub slot: u64,
}

/// The seeded episodes of `class` over `sched`.
pub fn plan(class: FaultClass, sched: &Schedule, seed: u64) -> Vec<Episode> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ (class as u64).wrapping_mul(0x9E37));
    let mut out = Vec::new();
    let (lo, hi) = class.len_range();
    let mut slot0 = sched.warmup;
    while slot0 + sched.slot <= sched.ticks {
        let start = slot0 + rng.random_range(0..=sched.slot / 5);
        let len = rng.random_range(lo..=hi).min(sched.slot / 2);
        let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        let (channel, size) = match class {
            FaultClass::Nan | FaultClass::Inf => (rng.random_range(0..N_TARGETS), sign),
            FaultClass::Saturation => (rng.random_range(0..16), sign * rng.random_range(1.0..3.0)),
            FaultClass::Stuck => (rng.random_range(0..14), 0.0),
            FaultClass::Spike => {
                let mag = 10f64.powf(rng.random_range(0.05f64.log10()..10f64.log10()));
                (rng.random_range(0..14), sign * mag)
            }
            FaultClass::SpiCrc => (rng.random_range(0..2), 0.0),
            FaultClass::DriveOutOfBand => (0, sign * rng.random_range(0.03..0.10)),
            FaultClass::PumpCollapse => {
                let v = rng.random_range(0.0..0.3f64);
                (0, v * v)
            }
            FaultClass::ParamJump => (0, sign * rng.random_range(0.001..0.01)),
            FaultClass::RateOverrange => (0, sign * rng.random_range(3000.0..20000.0)),
            _ => (0, 0.0),
        };
        out.push(Episode {
            start,
            len,
            channel,
            size,
        });
        slot0 += sched.slot;
    }
    out
}
