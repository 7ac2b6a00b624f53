//! The firmware's replay table: a simulated record in a compact binary form that the QEMU
//! board serves through its replay devices ([`crate::replay`]), written on the host by
//! `paragyro-fw-replay` (host-sim/fw-replay/, firmware/README.md), which takes every
//! layout constant, slot index and the hash from this module.
//!
//! # Format (`PGFWRPL1`, little-endian)
//!
//! A [`HEADER_BYTES`]-byte header, then `n_samples` samples of [`SAMPLE_BYTES`] bytes.
//!
//! | offset | type       | field |
//! |--------|------------|-------|
//! | 0      | `[u8; 8]`  | magic `PGFWRPL1` |
//! | 8      | `u32`      | format version (1) |
//! | 12     | `u32`      | `n_samples` |
//! | 16     | `u32`      | sample size ([`SAMPLE_BYTES`]) |
//! | 20     | `u32`      | header size ([`HEADER_BYTES`]) |
//! | 24     | `u32`      | ADXL355 range bits the codes are for (1 ±2 g, 2 ±4 g, 3 ±8 g) |
//! | 28     | `u32`      | reserved (0) |
//! | 32     | `f32`      | drive-axis lock-in scale, µm per volt at the ADC input (PGA gain 1, no offset) |
//! | 36     | `f32`      | sense-axis lock-in scale, µm per volt |
//! | 40     | 8 bytes    | reserved (0) |
//! | 48     | `[f64; 40]`| the core configuration, [`cfg`](mod@cfg) slots |
//! | 368    | `[f64; 16]`| the truth of the simulation, [`truth`] slots (never given to the core) |
//! | 496    | `u64`      | FNV-1a 64 of the sample bytes |
//! | 504    | 8 bytes    | reserved (0) |
//! | 512    | `u32`      | number of control events (≤ [`MAX_CONTROLS`]) |
//! | 516    | 12 bytes   | reserved (0) |
//! | 528    | `[Control; 31]` | control events: `u32` tick, `u32` kind ([`control`]), `f64` value |
//!
//! The control events are the scenario's commands to the core (dither on/off, retune
//! on/off, pump-centre jump), given to the core before the tick they are listed for,
//! exactly where the simulator's closed loop gave them.
//!
//! One sample (the record's row `k`, i.e. what the chips deliver at tick `k`):
//!
//! | offset | type         | field |
//! |--------|--------------|-------|
//! | 0      | `[i24; 7]`   | drive-axis ADC codes, lock-in channel order (X0, A1re, A1im, A2re, A2im, A3re, A3im) |
//! | 21     | `[i24; 7]`   | sense-axis ADC codes (Y0, B1re, …) |
//! | 42     | `[i24; 2]`   | ADXL355 X, Y codes (20-bit values, at the header's range) |
//! | 48     | `f64`        | pump frequency in effect at the sample, Hz (the record's `pump_hz`) |
//! | 56     | `f32`        | pump scale s = (V_A/V_A0)² in effect |
//!
//! The pump columns are the *record's* pump: the replay is open loop (the firmware's own
//! DDS command is captured and compared with the record's next pump, but the core is told
//! the pump that produced the lock-in data; see firmware/README.md).

use paragyro_core::Config;
use paragyro_core::config::PumpProfile;

/// Magic of the format.
pub const MAGIC: [u8; 8] = *b"PGFWRPL1";
/// Format version.
pub const VERSION: u32 = 1;
/// Header size, bytes.
pub const HEADER_BYTES: usize = 1024;
/// Size of one sample, bytes.
pub const SAMPLE_BYTES: usize = 60;
/// Offset of the configuration slots.
pub const CFG_OFFSET: usize = 48;
/// Number of configuration slots.
pub const CFG_SLOTS: usize = 40;
/// Offset of the truth slots.
pub const TRUTH_OFFSET: usize = 368;
/// Number of truth slots.
pub const TRUTH_SLOTS: usize = 16;
/// Offset of the FNV-1a 64 of the samples.
pub const HASH_OFFSET: usize = 496;
/// Offset of the number of control events.
pub const CONTROLS_OFFSET: usize = 512;
/// Offset of the first control event.
pub const CONTROL_LIST_OFFSET: usize = 528;
/// Size of one control event.
pub const CONTROL_BYTES: usize = 16;
/// Most control events a table holds.
pub const MAX_CONTROLS: usize = 31;

/// Kinds of control event.
pub mod control {
    /// Dither on (value 1) or off (0): `Estimator::set_dither`.
    pub const DITHER: u32 = 1;
    /// Peak pump-frequency dither, Hz: `Estimator::set_dither_pump_hz`.
    pub const DITHER_PUMP_HZ: u32 = 2;
    /// Retune supervisor on (1) or off (0): `Estimator::set_retune`.
    pub const RETUNE: u32 = 3;
    /// Pump-centre jump to the value, Hz: `Estimator::command_pump_centre(value, true)`.
    pub const PUMP_JUMP_HZ: u32 = 4;
}

/// One control event of a table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Control {
    /// Given to the core before this tick.
    pub tick: u32,
    /// [`control`] kind.
    pub kind: u32,
    /// Its value.
    pub value: f64,
}

/// Slots of the configuration block: the fields of [`Config`] that a scenario sets; every
/// other field is [`Config::table2`]'s.
pub mod cfg {
    #![allow(missing_docs)]
    pub const F0_HZ: usize = 0;
    pub const FS_HZ: usize = 1;
    pub const L0_UM: usize = 2;
    pub const LOCKIN_LPF_ORDER: usize = 3;
    pub const LOCKIN_LPF_HZ: usize = 4;
    pub const PUMP_AMP_REF_V: usize = 5;
    /// 0 linear, 1 staircase, 2 half steps.
    pub const PUMP_PROFILE: usize = 6;
    /// μx, μy, μxy, ωx², ωy², ωxy², αx, αy, β1, β3, γ, γ', c_ax, c_ay (14 slots).
    pub const NOMINAL: usize = 7;
    pub const PUMP_CENTRE_HZ: usize = 21;
    pub const DITHER_ENABLED: usize = 22;
    pub const DITHER_PUMP_HZ: usize = 23;
    pub const DITHER_FREQ_HZ: usize = 24;
    pub const DITHER_START_S: usize = 25;
    pub const DITHER_TAPER_S: usize = 26;
    pub const DITHER_SCALE_FRAC: usize = 27;
    pub const DITHER_SCALE_FREQ_HZ: usize = 28;
    pub const NOISE_PM_RTHZ: usize = 29;
    pub const RLS_FORGETTING: usize = 30;
    pub const GATE_STARTUP_S: usize = 31;
    pub const STUCK_SAMPLES: usize = 32;
    pub const RETUNE_ENABLED: usize = 33;
    pub const RETUNE_RAMP_S: usize = 34;
}

/// Slots of the truth block.
pub mod truth {
    #![allow(missing_docs)]
    /// ωy² of the plant at the start.
    pub const WY2_START: usize = 0;
    /// ωy² of the plant at the end.
    pub const WY2_END: usize = 1;
    /// Rate at the end, °/s.
    pub const RATE_DPS_END: usize = 2;
    /// The pump centre at the start, Hz.
    pub const PUMP_CENTRE_START_HZ: usize = 3;
    /// The sense resonance at the end, 2·√ωy²·f0, Hz (where a retune should take the pump).
    pub const SENSE_RESONANCE_END_HZ: usize = 4;
    /// End of the drift (the last ramp), s.
    pub const DRIFT_END_S: usize = 5;
    /// Time the dither is switched off (∞ if never), s.
    pub const DITHER_OFF_S: usize = 6;
    /// The record's pump at the last sample, Hz (the host's f64 closed loop).
    pub const RECORD_PUMP_END_HZ: usize = 7;
}

/// Why a byte slice is not a replay table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TableError {
    /// Shorter than its header says.
    Truncated,
    /// Wrong magic or version.
    BadMagic,
    /// Header or sample size not this module's.
    BadLayout,
    /// The FNV-1a 64 of the samples is not the header's.
    BadHash,
    /// More control events than [`MAX_CONTROLS`].
    BadControls,
}

/// One sample of the table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TableSample {
    /// Drive-axis lock-in codes.
    pub adc_x: [i32; 7],
    /// Sense-axis lock-in codes.
    pub adc_y: [i32; 7],
    /// ADXL355 X, Y codes.
    pub accel: [i32; 2],
    /// Pump frequency in effect, Hz.
    pub pump_hz: f64,
    /// Pump scale in effect.
    pub pump_scale: f32,
}

/// A parsed replay table (borrowing its bytes, e.g. an `include_bytes!` in flash).
#[derive(Clone, Copy, Debug)]
pub struct ReplayTable<'a> {
    samples: &'a [u8],
    n: usize,
    header: &'a [u8],
}

fn bytes<const N: usize>(b: &[u8], at: usize) -> [u8; N] {
    let mut out = [0u8; N];
    if let Some(src) = at.checked_add(N).and_then(|end| b.get(at..end)) {
        out.copy_from_slice(src);
    }
    out
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(bytes(b, at))
}

fn f64_at(b: &[u8], at: usize) -> f64 {
    f64::from_le_bytes(bytes(b, at))
}

fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(bytes(b, at))
}

/// A signed 24-bit little-endian value.
fn i24_at(b: &[u8], at: usize) -> i32 {
    let [b0, b1, b2] = bytes::<3>(b, at);
    i32::from_le_bytes([0, b0, b1, b2]) >> 8
}

/// FNV-1a 64, streaming (the table's sample hash and the replay run's output digest).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fnv64(pub u64);

impl Default for Fnv64 {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv64 {
    /// Hash `data` in.
    pub fn write(&mut self, data: &[u8]) {
        for b in data {
            self.0 ^= u64::from(*b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

/// FNV-1a 64 of `data`.
pub fn fnv1a64(data: &[u8]) -> u64 {
    let mut h = Fnv64::default();
    h.write(data);
    h.0
}

/// The configuration block of `c`: the [`cfg`](mod@cfg) slots (the fields a scenario sets), written
/// by the host's table generator (`paragyro-fw-replay`); [`config_from_slots`] is its
/// inverse on top of [`Config::table2`].
pub fn config_slots(c: &Config) -> [f64; CFG_SLOTS] {
    let b = |v: bool| if v { 1.0 } else { 0.0 };
    let mut s = [0.0; CFG_SLOTS];
    s[cfg::F0_HZ] = c.f0_hz;
    s[cfg::FS_HZ] = c.fs_hz;
    s[cfg::L0_UM] = c.l0_um;
    s[cfg::LOCKIN_LPF_ORDER] = c.lockin_lpf_order as f64;
    s[cfg::LOCKIN_LPF_HZ] = c.lockin_lpf_hz;
    s[cfg::PUMP_AMP_REF_V] = c.pump_amp_ref_v;
    s[cfg::PUMP_PROFILE] = match c.pump_profile {
        PumpProfile::Linear => 0.0,
        PumpProfile::Staircase => 1.0,
        PumpProfile::HalfSteps => 2.0,
    };
    let n = &c.nominal;
    let nominal = [
        n.mu_x, n.mu_y, n.mu_xy, n.wx2, n.wy2, n.wxy2, n.alpha_x, n.alpha_y, n.beta1, n.beta3,
        n.gamma, n.gamma_p, n.c_ax, n.c_ay,
    ];
    for (slot, v) in s.iter_mut().skip(cfg::NOMINAL).zip(nominal) {
        *slot = v;
    }
    s[cfg::PUMP_CENTRE_HZ] = c.pump_centre_hz;
    s[cfg::DITHER_ENABLED] = b(c.dither.enabled);
    s[cfg::DITHER_PUMP_HZ] = c.dither.pump_hz;
    s[cfg::DITHER_FREQ_HZ] = c.dither.freq_hz;
    s[cfg::DITHER_START_S] = c.dither.start_s;
    s[cfg::DITHER_TAPER_S] = c.dither.taper_s;
    s[cfg::DITHER_SCALE_FRAC] = c.dither.scale_frac;
    s[cfg::DITHER_SCALE_FREQ_HZ] = c.dither.scale_freq_hz;
    s[cfg::NOISE_PM_RTHZ] = c.noise_pm_rthz;
    s[cfg::RLS_FORGETTING] = c.rls.forgetting;
    s[cfg::GATE_STARTUP_S] = c.monitor.gate_startup_s;
    s[cfg::STUCK_SAMPLES] = f64::from(c.monitor.stuck_samples);
    s[cfg::RETUNE_ENABLED] = b(c.retune.enabled);
    s[cfg::RETUNE_RAMP_S] = c.retune.ramp_s;
    s
}

/// The configuration whose [`cfg`](mod@cfg) slots are `slot(i)`, every other field
/// [`Config::table2`]'s: the inverse of [`config_slots`] (the reader of the block).
pub fn config_from_slots(slot: impl Fn(usize) -> f64) -> Config {
    let s = &slot;
    let flag = |i| slot(i) != 0.0;
    let mut c = Config::table2();
    c.f0_hz = s(cfg::F0_HZ);
    c.fs_hz = s(cfg::FS_HZ);
    c.l0_um = s(cfg::L0_UM);
    c.lockin_lpf_order = s(cfg::LOCKIN_LPF_ORDER) as usize;
    c.lockin_lpf_hz = s(cfg::LOCKIN_LPF_HZ);
    c.pump_amp_ref_v = s(cfg::PUMP_AMP_REF_V);
    let profile = s(cfg::PUMP_PROFILE);
    c.pump_profile = if profile == 1.0 {
        PumpProfile::Staircase
    } else if profile == 2.0 {
        PumpProfile::HalfSteps
    } else {
        PumpProfile::Linear
    };
    let n = |k: usize| s(cfg::NOMINAL.saturating_add(k));
    let p = &mut c.nominal;
    p.mu_x = n(0);
    p.mu_y = n(1);
    p.mu_xy = n(2);
    p.wx2 = n(3);
    p.wy2 = n(4);
    p.wxy2 = n(5);
    p.alpha_x = n(6);
    p.alpha_y = n(7);
    p.beta1 = n(8);
    p.beta3 = n(9);
    p.gamma = n(10);
    p.gamma_p = n(11);
    p.c_ax = n(12);
    p.c_ay = n(13);
    c.pump_centre_hz = s(cfg::PUMP_CENTRE_HZ);
    c.dither.enabled = flag(cfg::DITHER_ENABLED);
    c.dither.pump_hz = s(cfg::DITHER_PUMP_HZ);
    c.dither.freq_hz = s(cfg::DITHER_FREQ_HZ);
    c.dither.start_s = s(cfg::DITHER_START_S);
    c.dither.taper_s = s(cfg::DITHER_TAPER_S);
    c.dither.scale_frac = s(cfg::DITHER_SCALE_FRAC);
    c.dither.scale_freq_hz = s(cfg::DITHER_SCALE_FREQ_HZ);
    c.noise_pm_rthz = s(cfg::NOISE_PM_RTHZ);
    c.rls.forgetting = s(cfg::RLS_FORGETTING);
    c.monitor.gate_startup_s = s(cfg::GATE_STARTUP_S);
    c.monitor.stuck_samples = s(cfg::STUCK_SAMPLES) as u32;
    c.retune.enabled = flag(cfg::RETUNE_ENABLED);
    c.retune.ramp_s = s(cfg::RETUNE_RAMP_S);
    c
}

impl<'a> ReplayTable<'a> {
    /// Parses and checks a table (magic, version, sizes, sample hash).
    pub fn parse(data: &'a [u8]) -> Result<Self, TableError> {
        let header = data.get(..HEADER_BYTES).ok_or(TableError::Truncated)?;
        if bytes::<8>(header, 0) != MAGIC || u32_at(header, 8) != VERSION {
            return Err(TableError::BadMagic);
        }
        if u32_at(header, 16) as usize != SAMPLE_BYTES
            || u32_at(header, 20) as usize != HEADER_BYTES
        {
            return Err(TableError::BadLayout);
        }
        let n = u32_at(header, 12) as usize;
        let len = n.checked_mul(SAMPLE_BYTES).ok_or(TableError::Truncated)?;
        let samples = HEADER_BYTES
            .checked_add(len)
            .and_then(|end| data.get(HEADER_BYTES..end))
            .ok_or(TableError::Truncated)?;
        if fnv1a64(samples) != u64::from_le_bytes(bytes(header, HASH_OFFSET)) {
            return Err(TableError::BadHash);
        }
        if u32_at(header, CONTROLS_OFFSET) as usize > MAX_CONTROLS {
            return Err(TableError::BadControls);
        }
        Ok(Self { samples, n, header })
    }

    /// Number of samples.
    pub const fn len(&self) -> usize {
        self.n
    }

    /// No samples.
    pub const fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The FNV-1a 64 of the samples (from the header, checked by [`ReplayTable::parse`]).
    pub fn hash(&self) -> u64 {
        u64::from_le_bytes(bytes(self.header, HASH_OFFSET))
    }

    /// Configuration slot `i` (NaN beyond the block).
    pub fn cfg_slot(&self, i: usize) -> f64 {
        if i < CFG_SLOTS {
            f64_at(self.header, CFG_OFFSET.saturating_add(i.saturating_mul(8)))
        } else {
            f64::NAN
        }
    }

    /// Truth slot `i` (NaN beyond the block).
    pub fn truth(&self, i: usize) -> f64 {
        if i < TRUTH_SLOTS {
            f64_at(
                self.header,
                TRUTH_OFFSET.saturating_add(i.saturating_mul(8)),
            )
        } else {
            f64::NAN
        }
    }

    /// Number of control events.
    pub fn controls(&self) -> usize {
        (u32_at(self.header, CONTROLS_OFFSET) as usize).min(MAX_CONTROLS)
    }

    /// Control event `i` (`None` beyond [`ReplayTable::controls`]).
    pub fn control(&self, i: usize) -> Option<Control> {
        if i >= self.controls() {
            return None;
        }
        let at = CONTROL_LIST_OFFSET.checked_add(i.checked_mul(CONTROL_BYTES)?)?;
        Some(Control {
            tick: u32_at(self.header, at),
            kind: u32_at(self.header, at.checked_add(4)?),
            value: f64_at(self.header, at.checked_add(8)?),
        })
    }

    /// Lock-in scale of the drive axis, µm per volt.
    pub fn um_per_volt_x(&self) -> f32 {
        f32_at(self.header, 32)
    }

    /// Lock-in scale of the sense axis, µm per volt.
    pub fn um_per_volt_y(&self) -> f32 {
        f32_at(self.header, 36)
    }

    /// ADXL355 range bits of the accelerometer codes (1, 2, 3 for ±2, 4, 8 g).
    pub fn accel_range_bits(&self) -> u32 {
        u32_at(self.header, 24)
    }

    /// The core configuration: [`Config::table2`] with the table's slots (validate it with
    /// [`Config::build`]).
    pub fn config(&self) -> Config {
        config_from_slots(|i| self.cfg_slot(i))
    }

    /// Sample `k` (`None` past the end).
    pub fn sample(&self, k: usize) -> Option<TableSample> {
        if k >= self.n {
            return None;
        }
        let at = k.checked_mul(SAMPLE_BYTES)?;
        let b = self.samples.get(at..at.checked_add(SAMPLE_BYTES)?)?;
        let mut adc_x = [0i32; 7];
        let mut adc_y = [0i32; 7];
        let mut off = 0usize;
        for c in adc_x.iter_mut().chain(adc_y.iter_mut()) {
            *c = i24_at(b, off);
            off = off.saturating_add(3);
        }
        Some(TableSample {
            adc_x,
            adc_y,
            accel: [i24_at(b, 42), i24_at(b, 45)],
            pump_hz: f64_at(b, 48),
            pump_scale: f32_at(b, 56),
        })
    }

    /// The lock-in codes of one axis (0 drive, 1 sense) at sample `k`.
    pub fn adc_codes(&self, k: usize, axis: usize) -> Option<[i32; 7]> {
        let at = k
            .checked_mul(SAMPLE_BYTES)?
            .checked_add(if axis == 0 { 0 } else { 21 })?;
        if k >= self.n {
            return None;
        }
        let mut out = [0i32; 7];
        let mut off = at;
        for c in out.iter_mut() {
            *c = i24_at(self.samples, off);
            off = off.saturating_add(3);
        }
        Some(out)
    }

    /// The ADXL355 X, Y codes at sample `k`.
    pub fn accel_codes(&self, k: usize) -> Option<[i32; 2]> {
        if k >= self.n {
            return None;
        }
        let at = k.checked_mul(SAMPLE_BYTES)?.checked_add(42)?;
        Some([
            i24_at(self.samples, at),
            i24_at(self.samples, at.saturating_add(3)),
        ])
    }

    /// The pump (Hz, scale) in effect at sample `k`.
    pub fn pump(&self, k: usize) -> Option<(f64, f32)> {
        if k >= self.n {
            return None;
        }
        let at = k.checked_mul(SAMPLE_BYTES)?.checked_add(48)?;
        Some((
            f64_at(self.samples, at),
            f32_at(self.samples, at.saturating_add(8)),
        ))
    }
}
