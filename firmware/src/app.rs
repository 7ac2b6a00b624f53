//! The application layer: the board's chips bound to the estimator, one [`App::tick`] per
//! 500 Hz sample.
//!
//! # Design
//!
//! **Timing.** The two ADS131M08s (drive axis: X0, A1..A3; sense axis: Y0, B1..B3)
//! convert simultaneously from one CLKIN at 500 Hz; the falling edge of DRDY is the
//! board's only time base and its interrupt runs [`App::tick`], in this order:
//!
//! 1. **frames first**: both ADC frames, then the ADXL355 burst. The ADC must be read
//!    within one data period, and reading before any computation keeps the read at a
//!    fixed, short latency after DRDY;
//! 2. the [`Sample`]: lock-in outputs in µm through each axis' [`LockinCalibration`] (the
//!    single conversion point), the accelerometer's X and Y (drive, sense axis), the die
//!    temperature (module `temp`), and the pump frequency and scale *in effect* (what the
//!    DDS realised at the previous
//!    IO_UPDATE, not what the core asked for);
//! 3. [`Estimator::step`];
//! 4. **DDS written last**: the core's `pump_hz_next`, clamped to the [`PumpGuard`], is
//!    planned ([`PumpPlan`]: pump 2k, references k and 3k, so the lock-in references stay
//!    phase-locked to the pump) and written together with the pump amplitude;
//! 5. **IO_UPDATE at the very end** ([`IoUpdate::pulse`], only when the driver has buffered
//!    words): the new frequency and amplitude act from here on, so they are the ones in
//!    effect at the next sample instant, and the realised `PumpPlan::pump_hz` becomes the
//!    known pump of the next [`Sample`].
//!
//! The tick is bounded: two 30-byte frames, one 14-byte burst, one `step`, at most eight
//! short DDS transactions per step (sixteen with two steps per sample); no allocation,
//! no loop that depends on data, no panic. A
//! write is skipped when its word did not change, so a steady pump costs no DDS traffic.
//!
//! **Bad inputs are the core's business.** The firmware never drops a sample: a frame
//! that fails (SPI error, CRC error, DRDY flags not set) turns that axis' seven channels
//! into NaN, a failed or absent accelerometer turns the acceleration into NaN, and the
//! core flags, counts and skips the sample (and holds θ̂). A lock-in code at the ADC's
//! full scale, or an accelerometer code at the end of its 20-bit range, is replaced by a
//! value beyond the core's full scale ([`paragyro_core::config::MonitorConfig`]), so the
//! core counts it as saturated even when the ADC clips below the core's limit. A bad
//! temperature is `temp_c: None` (module `temp`). The firmware's own [`FwCounters`] say
//! which chip failed and how.
//!
//! **DDS errors.** Words reach the DDS cores only at IO_UPDATE, so a tick whose writes
//! fail does not pulse: the DDS keeps its old words, the pump in effect (and so the next
//! sample's known pump) stays the previous one, and the failure is counted. The buffers
//! may then hold a partial write (e.g. a new pump word next to an old reference word), so
//! the next tick rewrites every word before it pulses again. After a bus fault the
//! AD9959's serial port may also need its SYNC_IO pin; that belongs to the board.
//!
//! **Two steps per sample ([`App::set_half_steps`], the stm32f405 and `fil` boards).** The
//! DDS steps its frequency at IO_UPDATE (to a word quantised to 2·f_SYSCLK/2³² ≈ 0.058 Hz
//! at the board's 125 MHz), while the core's replica of the lock-in low-pass for the frequency is
//! first-order-hold exact: it assumes the pump sweeps *linearly* from one sample's value
//! to the next ([`paragyro_core::lpf`]). One step per sample with the core's ZOH replica
//! (`PumpProfile::Staircase`) costs a rate bias of +1.2 % on `identify` (firmware/docs/notes.md
//! "Pump profile"), +0.9 to +1.8 % in the loop; with the FOH replica the core fails (test
//! `a_linear_replica_on_the_stepping_dds_fails`). So each tick writes and pulses a first
//! step and buffers a second, which [`IoUpdate::pulse_at_half_period`] applies half a
//! period after DRDY. The steps are the means over the two halves of the linear sweep
//! from the last command's word to this one's, rounded to whole words with first-order
//! error feedback ([`half_steps`]: each step within a word of its mean, the errors not
//! adding up), and the core is told them exactly: the next sample's pump is the end of
//! the sweep whose half means they are, and that sweep's move goes to
//! [`Estimator::set_pump_sweep_hz`] (the replica then holds what the DDS does). Telling
//! one value per sample cannot do that: steps that are *exactly* the half means of a
//! sweep between told nodes would confine the told pump to a grid of four words (0.93 Hz at
//! 500 MHz), which biases the rate's scale factor while the dither moves the pump; the
//! command's word told with the rounded steps would leave the replica a slope one word
//! off on every tie of the rounding, which the rate row reads as a rate offset that keeps
//! the slow RLS gated after a rate step ([`half_steps`]). The amplitude is one step per sample, told to the core's
//! ZOH replica of the scale (`PumpProfile::HalfSteps`): quantised to 1/1023, its own half
//! steps could not be exact means (the amplitude steps are below one word a tick). Not
//! modelled in the loop: the first pulse's delay after DRDY (the tick's length, ≈ 0.1 ms). The
//! AD9959's **linear sweep mode** (CFTW0 start word, CW1 end word, delta words and ramp
//! rate) cannot replace the steps: its 8-bit ramp rate (≤ 8.16 µs per step at 125 MHz) and
//! 0.029 Hz delta resolution make its slowest sweep ≈ 3.6 kHz/s, far above the core's ≈ 680 Hz/s:
//! it would reach each word within ≈ 0.4 ms of the 2 ms period and hold (a staircase again).
//!
//! **The guard.** The core keeps the pump inside the drive's parametric band by itself
//! (its retune targets stay a margin inside the band, and it never ramps outside). The
//! [`PumpGuard`] is the last line, independent of the estimate: a window
//! `[min_hz, max_hz]` set by the board (the band of the design, with margin). Every
//! command is clamped to it and every clamp counted; a non-finite command keeps the pump
//! where it is. The realised (quantised) word is also kept inside: if rounding would leave
//! the window, the next word inwards is used. Since the sample carries the pump actually in
//! effect, a clamp never misleads the estimator; it only means the core's scheduler and
//! the DDS disagree, which [`FwCounters::guard_clamps`] makes visible.

use embedded_hal::spi::SpiDevice;
use paragyro_core::{Config, ConfigError, Cplx, Estimator, Lockin, Sample, StepOutput};

use crate::drivers::ad9959::{self, Ad9959, AmplitudeWord, FTW_SCALE, PumpPlan};
use crate::drivers::ads131m08::{self, Ads131m08, LOCKIN_CHANNELS, LockinCalibration};
use crate::drivers::adxl355::Adxl355;

mod pump;
mod temp;
mod words;

pub use pump::{PumpAmplitude, PumpGuard, half_steps};
pub use temp::{TEMP_EVERY, TEMP_PLAUSIBLE_C, plausible_temp_c};
use words::f64_round_u32;

/// The board's IO_UPDATE line of the AD9959 (a rising edge applies the buffered words).
///
/// Implemented for closures (`&mut || pin.set_high()…`) and for [`PinIoUpdate`]; the
/// replay board uses [`crate::replay::NoIoUpdate`] or [`crate::replay::CaptureIo`]. An
/// implementation may also arm a timer that pulses the pin later in the sample period.
pub trait IoUpdate {
    /// Pulse IO_UPDATE once.
    fn pulse(&mut self);

    /// Pulse IO_UPDATE once, half a sample period after the sample instant (DRDY), for
    /// the second of [`App::set_half_steps`]' two steps; false if this line cannot (the
    /// default: the buffered words then wait for the next tick, and the App counts it).
    fn pulse_at_half_period(&mut self) -> bool {
        false
    }
}

impl<F: FnMut()> IoUpdate for F {
    fn pulse(&mut self) {
        self()
    }
}

/// IO_UPDATE on an [`embedded_hal::digital::OutputPin`]: high, held `HOLD_NS`, then low.
/// The AD9959 needs the pulse high for at least one SYNC_CLK period (SYSCLK/4: 32 ns at the
/// board's 125 MHz), longer than two back-to-back GPIO writes of a 168 MHz Cortex-M4
/// (`ad9959::io_update_hold_ns`). Pin errors are ignored (GPIO writes are infallible on the
/// STM32F4). The high time is a constant: a board's delay then folds it to a fixed wait.
#[derive(Debug)]
pub struct PinIoUpdate<P, D, const HOLD_NS: u32> {
    /// The IO_UPDATE pin.
    pub pin: P,
    /// The delay that holds it.
    pub delay: D,
}

impl<P: embedded_hal::digital::OutputPin, D: embedded_hal::delay::DelayNs, const HOLD_NS: u32>
    IoUpdate for PinIoUpdate<P, D, HOLD_NS>
{
    fn pulse(&mut self) {
        let _ = self.pin.set_high();
        self.delay.delay_ns(HOLD_NS);
        let _ = self.pin.set_low();
    }
}

/// The chips of the board, each behind its own [`SpiDevice`] (chip select included).
#[derive(Debug)]
pub struct Chips<AX, AY, XL, DDS> {
    /// Drive-axis lock-in ADC: X0, A1, A2, A3 (re, im).
    pub adc_x: Ads131m08<AX>,
    /// Sense-axis lock-in ADC: Y0, B1, B2, B3 (re, im).
    pub adc_y: Ads131m08<AY>,
    /// Accelerometer: X along the drive axis, Y along the sense axis.
    pub accel: Adxl355<XL>,
    /// Pump (channel 0) and phase-locked lock-in references (channels 1, 2).
    pub dds: Ad9959<DDS>,
}

/// Firmware-side fault counters since start-up (saturating). The core keeps its own
/// ([`Estimator::counters`]): bad samples by cause, stuck channels, resets, retunes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FwCounters {
    /// ADC frames lost to an SPI error (either axis).
    pub adc_spi_errors: u32,
    /// ADC frames that failed their CRC.
    pub adc_crc_errors: u32,
    /// ADC frames whose lock-in DRDY flags were not all set.
    pub adc_not_ready: u32,
    /// ADC frames with a lock-in channel at full scale.
    pub adc_saturated: u32,
    /// Accelerometer reads that failed (SPI error, not ready, absent device).
    pub accel_errors: u32,
    /// Accelerometer samples with X or Y at the end of the code range.
    pub accel_saturated: u32,
    /// Accelerometer samples refused as stuck: X and Y codes identical for
    /// [`App::set_accel_stuck_limit`] reads in a row (0: never, the default).
    pub accel_stuck: u32,
    /// Ticks whose DDS writes failed (the pump in effect was kept).
    pub dds_errors: u32,
    /// Pump commands refused by the guard: clamped to the window, or not finite.
    pub guard_clamps: u32,
    /// Ticks run.
    pub ticks: u32,
}

/// Bits of [`TickReport::faults`].
pub mod fault {
    /// The drive-axis ADC frame was lost (channels NaN).
    pub const ADC_X: u8 = 1;
    /// The sense-axis ADC frame was lost (channels NaN).
    pub const ADC_Y: u8 = 2;
    /// The accelerometer read failed, or its codes are stuck (acceleration NaN).
    pub const ACCEL: u8 = 4;
    /// A lock-in or accelerometer code was at full scale.
    pub const SATURATED: u8 = 8;
    /// No pump was in effect at the sample (never started, or every DDS write failed).
    pub const PUMP_UNKNOWN: u8 = 16;
    /// The DDS writes of this tick failed; the previous pump stays in effect.
    pub const DDS: u8 = 32;
    /// The guard clamped or refused the core's command.
    pub const GUARD: u8 = 64;
    /// Faults that make the firmware's sample incomplete.
    pub const SAMPLE: u8 = ADC_X | ADC_Y | ACCEL | SATURATED | PUMP_UNKNOWN;
}

/// What one [`App::tick`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickReport {
    /// The core's output for this sample (its own verdict on the sample is
    /// `out.health.inputs_valid`, which also covers stuck channels).
    pub out: StepOutput,
    /// The firmware delivered a complete sample: every chip read, no code at full scale,
    /// a known pump (no bit of [`fault::SAMPLE`]).
    pub sample_ok: bool,
    /// Realised pump frequency in effect from now on, i.e. at the next sample, Hz.
    pub pump_hz: f64,
    /// Pump scale `s` in effect from now on.
    pub pump_scale: f32,
    /// [`fault`] bits of this tick.
    pub faults: u8,
}

/// The pump the DDS is running (applied by the last IO_UPDATE).
#[derive(Clone, Copy, Debug, PartialEq)]
struct InEffect {
    plan: PumpPlan,
    asf: AmplitudeWord,
    /// `plan.pump_hz()`, computed once when the plan changes (soft-float on the M4F).
    pump_hz: f64,
}

/// The firmware application: chips, calibrations, the `f32` estimator and the pump.
#[derive(Debug)]
pub struct App<AX, AY, XL, DDS> {
    chips: Chips<AX, AY, XL, DDS>,
    est: Estimator<f32>,
    cal_x: LockinCalibration,
    cal_y: LockinCalibration,
    guard: PumpGuard,
    /// The guard as reference words: [`PumpGuard::plan`] of its ends.
    guard_words: (u32, u32),
    /// Pump Hz per reference word, `2·f_SYSCLK / 2^32` (exact: a power-of-two scaling),
    /// so that [`App::guard_plan`] needs one `f64` division and no multiplication.
    hz_per_ref_word: f64,
    /// The guard's ends as `f64` bit patterns: for a validated guard (`0 < min ≤ max`,
    /// finite) `min ≤ hz ≤ max` ⇔ `min_bits ≤ hz_bits ≤ max_bits` for every `hz` (positive
    /// doubles order like their bits; negatives, −0 and NaN fall outside), so the tick's
    /// guard test needs no soft-float comparisons.
    guard_bits: (u64, u64),
    amplitude: PumpAmplitude,
    /// A lock-in value beyond the core's full scale (saturated codes), µm.
    lockin_beyond_um: f32,
    /// An acceleration beyond the core's full scale, m/s².
    accel_beyond_mps2: f32,
    /// The pump the next sample is told: the DDS's words, or with two steps per sample
    /// the node the steps follow (its `pump_hz`; `plan` is then the second step's).
    pump: Option<InEffect>,
    /// The words in the DDS's active registers (the last pulse's), reference word and
    /// amplitude: what a write is skipped against.
    active: Option<(u32, AmplitudeWord)>,
    /// Two steps per sample ([`App::set_half_steps`]).
    half_steps: bool,
    /// With two steps: the reference word of the last command (the node the next
    /// interval's steps sweep from); `None` after an error (the next command is one step).
    node: Option<i32>,
    /// With two steps: the last step's rounding error, quarter words ([`half_steps`]).
    residual: i32,
    /// [`App::hz_per_ref_word`] in `f32` (the sweep: a few words).
    hz_per_ref_word_f32: f32,
    /// Half of it (`f64`: the told pump on the half-word grid of the two steps' sweeps).
    hz_per_half_word: f64,
    /// The DDS buffers may differ from the words in effect: rewrite all before a pulse.
    dirty: bool,
    counters: FwCounters,
    /// The sample given to the core at the last tick (for the capture mode).
    last: Sample<f32>,
    /// The stuck-accelerometer test ([`App::set_accel_stuck_limit`]).
    accel_stuck: StuckAccel,
    /// Ticks until the next one takes the burst's temperature ([`TEMP_EVERY`]; 0: this one).
    temp_countdown: u8,
}

/// A stuck ADXL355: the same X and Y codes `limit` reads in a row. A real device's noise
/// (25 µg/√Hz: ≈ 18 codes rms at ±8 g and 500 Hz) makes that implausible; noise-free
/// replayed data repeat legitimately, so the test is off (`limit` 0) unless the board
/// enables it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct StuckAccel {
    limit: u32,
    last: (i32, i32),
    repeats: u32,
}

impl StuckAccel {
    /// Feeds one good read's codes; true while they count as stuck.
    fn push(&mut self, xy: (i32, i32)) -> bool {
        if self.limit == 0 {
            return false;
        }
        if xy == self.last {
            self.repeats = self.repeats.saturating_add(1);
        } else {
            self.last = xy;
            self.repeats = 1;
        }
        self.repeats >= self.limit
    }
}

/// A value beyond `full_scale` (twice it, or `f32::MAX` if that overflows).
fn beyond(full_scale: f64) -> f32 {
    let v = (2.0 * full_scale) as f32;
    if v.is_finite() { v } else { f32::MAX }
}

/// The 20-bit code range of the ADXL355 ends at these codes (clipping).
const ACCEL_CODE_MAX: i32 = 0x7_FFFF;
const ACCEL_CODE_MIN: i32 = -0x8_0000;

fn lockin(x: [f32; LOCKIN_CHANNELS], y: [f32; LOCKIN_CHANNELS]) -> Lockin<f32> {
    let [x0, a1r, a1i, a2r, a2i, a3r, a3i] = x;
    let [y0, b1r, b1i, b2r, b2i, b3r, b3i] = y;
    Lockin {
        x0_um: x0,
        x_um: [
            Cplx::new(a1r, a1i),
            Cplx::new(a2r, a2i),
            Cplx::new(a3r, a3i),
        ],
        y0_um: y0,
        y_um: [
            Cplx::new(b1r, b1i),
            Cplx::new(b2r, b2i),
            Cplx::new(b3r, b3i),
        ],
    }
}

fn bump(c: &mut u32) {
    *c = c.saturating_add(1);
}

/// One axis: the frame in µm, saturated channels beyond the core's full scale, or all
/// NaN if the frame was lost. Returns the values and the fault bits.
fn read_axis<S: SpiDevice>(
    adc: &mut Ads131m08<S>,
    cal: &LockinCalibration,
    beyond_um: f32,
    lost_bit: u8,
    counters: &mut FwCounters,
) -> ([f32; LOCKIN_CHANNELS], u8) {
    match adc.read_frame() {
        Ok(frame) => {
            let mut v = cal.channels_um(&frame);
            if !frame.lockin_saturated() {
                return (v, 0);
            }
            for (val, code) in v.iter_mut().zip(frame.lockin_codes().iter()) {
                if code.is_saturated() {
                    *val = if code.get() > 0 {
                        beyond_um
                    } else {
                        -beyond_um
                    };
                }
            }
            bump(&mut counters.adc_saturated);
            (v, fault::SATURATED)
        }
        Err(e) => {
            bump(match e {
                ads131m08::Error::Spi(_) => &mut counters.adc_spi_errors,
                ads131m08::Error::Crc { .. } => &mut counters.adc_crc_errors,
                // `read_frame` gives no BadId; an unexpected answer is "not ready" too
                ads131m08::Error::NotReady | ads131m08::Error::BadId(_) => {
                    &mut counters.adc_not_ready
                }
            });
            ([f32::NAN; LOCKIN_CHANNELS], lost_bit)
        }
    }
}

/// X and Y acceleration (drive, sense axis), NaN on any error, beyond the core's full
/// scale where the code clipped; and the temperature code of the same burst, 0 (the
/// sensor's reset value, implausible) on any error or a stuck device. No fault bit for the
/// temperature: it is an optional input.
fn read_accel<S: SpiDevice>(
    accel: &mut Adxl355<S>,
    beyond_mps2: f32,
    counters: &mut FwCounters,
    stuck: &mut StuckAccel,
) -> ([f32; 2], u16, u8) {
    match accel.read_sample() {
        Ok(s) if stuck.push((s.raw.x, s.raw.y)) => {
            bump(&mut counters.accel_stuck);
            ([f32::NAN; 2], 0, fault::ACCEL)
        }
        Ok(s) => {
            let [ax, ay, _] = s.accel_mps2;
            let mut faults = 0;
            let mut clip = |v: f32, raw: i32| {
                if raw >= ACCEL_CODE_MAX || raw <= ACCEL_CODE_MIN {
                    faults = fault::SATURATED;
                    if raw > 0 { beyond_mps2 } else { -beyond_mps2 }
                } else {
                    v
                }
            };
            let a = [clip(ax, s.raw.x), clip(ay, s.raw.y)];
            if faults != 0 {
                bump(&mut counters.accel_saturated);
            }
            (a, s.temp_raw, faults)
        }
        // SPI error, not ready, absent device (STATUS 0xFF reads as not ready): alike
        Err(_) => {
            bump(&mut counters.accel_errors);
            ([f32::NAN; 2], 0, fault::ACCEL)
        }
    }
}

impl<AX, AY, XL, DDS> App<AX, AY, XL, DDS>
where
    AX: SpiDevice,
    AY: SpiDevice,
    XL: SpiDevice,
    DDS: SpiDevice,
{
    /// Binds initialised chips to the `f32` estimator built from `cfg`, with one
    /// calibration per axis and the pump guard (amplitude mapping
    /// [`PumpAmplitude::UNITY`]; see [`App::set_pump_amplitude`]). No bus traffic. Fails
    /// on an invalid `cfg` (the core's error), or with field `"guard"` if the window is
    /// not finite and increasing, holds no realisable pump word, or does not contain the
    /// configured pump centre.
    pub fn new(
        chips: Chips<AX, AY, XL, DDS>,
        cfg: &Config,
        cal_x: LockinCalibration,
        cal_y: LockinCalibration,
        guard: PumpGuard,
    ) -> Result<Self, ConfigError> {
        let mut app = Self::unconfigured(chips);
        app.configure(cfg, cal_x, cal_y, guard)?;
        Ok(app)
    }

    /// Binds initialised chips to a blank estimator (`Estimator::blank`): every field a
    /// constant, so the App is written straight into the caller's place. It must be
    /// [`App::configure`]d before [`App::start`] (which fails until then: the blank
    /// estimator's pump is 0 Hz, outside every guard). The boards build their App this
    /// way so that the estimator is designed in place, not moved (stack, firmware/README.md).
    #[inline(never)]
    pub fn unconfigured(chips: Chips<AX, AY, XL, DDS>) -> Self {
        Self {
            est: Estimator::blank(),
            chips,
            cal_x: LockinCalibration::UNITY,
            cal_y: LockinCalibration::UNITY,
            guard: PumpGuard::new(0.0, 0.0),
            guard_words: (0, 0),
            hz_per_ref_word: 1.0,
            guard_bits: (0, 0),
            amplitude: PumpAmplitude::UNITY,
            lockin_beyond_um: 0.0,
            accel_beyond_mps2: 0.0,
            pump: None,
            active: None,
            half_steps: false,
            node: None,
            residual: 0,
            hz_per_ref_word_f32: 1.0,
            hz_per_half_word: 0.5,
            dirty: true,
            counters: FwCounters::default(),
            last: Sample {
                lockin: lockin([f32::NAN; LOCKIN_CHANNELS], [f32::NAN; LOCKIN_CHANNELS]),
                accel_mps2: [f32::NAN; 2],
                pump_hz: f64::NAN,
                pump_scale: f32::NAN,
                temp_c: None,
            },
            accel_stuck: StuckAccel {
                limit: 0,
                last: (0, 0),
                repeats: 0,
            },
            temp_countdown: 0,
        }
    }

    /// Validates `cfg` and the guard as [`App::new`] does and, if both pass, builds the
    /// `f32` estimator from `cfg` in place (the design's temporaries live only during
    /// this call) and resets the App to its start: calibrations, guard, amplitude mapping
    /// [`PumpAmplitude::UNITY`], no pump known, counters zero. On an error nothing changes.
    #[inline(never)]
    pub fn configure(
        &mut self,
        cfg: &Config,
        cal_x: LockinCalibration,
        cal_y: LockinCalibration,
        guard: PumpGuard,
    ) -> Result<(), ConfigError> {
        let valid = cfg.validated()?;
        let sysclk = self.chips.dds.sysclk_hz();
        guard.validate(sysclk, cfg.initial_pump_hz())?;
        let word = |hz| guard.plan(hz, sysclk).map_or(0, |p| p.reference_ftw());
        self.guard_words = (word(guard.min_hz), word(guard.max_hz));
        self.hz_per_ref_word = sysclk * (2.0 / FTW_SCALE);
        self.hz_per_ref_word_f32 = self.hz_per_ref_word as f32;
        self.hz_per_half_word = sysclk * (1.0 / FTW_SCALE);
        self.guard_bits = (guard.min_hz.to_bits(), guard.max_hz.to_bits());
        self.est.rebuild(valid);
        self.cal_x = cal_x;
        self.cal_y = cal_y;
        self.guard = guard;
        self.amplitude = PumpAmplitude::UNITY;
        self.lockin_beyond_um = beyond(cfg.monitor.full_scale_um);
        self.accel_beyond_mps2 = beyond(cfg.monitor.accel_full_scale_mps2);
        self.pump = None;
        self.active = None;
        self.node = None;
        self.dirty = true;
        self.counters = FwCounters::default();
        self.temp_countdown = 0;
        self.last = Sample {
            lockin: lockin([f32::NAN; LOCKIN_CHANNELS], [f32::NAN; LOCKIN_CHANNELS]),
            accel_mps2: [f32::NAN; 2],
            pump_hz: f64::NAN,
            pump_scale: f32::NAN,
            temp_c: None,
        };
        Ok(())
    }

    /// Refuses the accelerometer's sample (NaN acceleration, fault bit `ACCEL`, counted in
    /// `accel_stuck`) once its X and Y codes have been identical for `reads` reads in a
    /// row, until they change; 0 (the default, kept by [`App::configure`]) disables the
    /// test. Boards with a real (noisy) accelerometer enable it; the replay's noise-free
    /// accelerations would trip it.
    pub fn set_accel_stuck_limit(&mut self, reads: u32) {
        self.accel_stuck = StuckAccel {
            limit: reads,
            ..StuckAccel::default()
        };
    }

    /// Two DDS steps per sample (off by default, kept by [`App::configure`]): each tick
    /// writes the words 1/4 of the way from the last command's word to the new one's and
    /// pulses IO_UPDATE, then buffers the words 3/4 of the way (the frequency rounded to
    /// whole words with error feedback, [`half_steps`]; the amplitude the command's) for
    /// [`IoUpdate::pulse_at_half_period`]. The core keeps its replica of the two steps,
    /// `PumpProfile::HalfSteps` (firmware/docs/notes.md "Pump profile": the one-step staircase biases the
    /// rate by 1.2 %), and is told the steps exactly: the next sample's pump is the end of
    /// the sweep whose half means they are, its move [`Estimator::set_pump_sweep_hz`];
    /// after a failed write or a pulse the line cannot make, the words the DDS holds. The
    /// first command after a start or an error is one step. (With
    /// [`App::tick_with_pump`], the replay's known pump, leave it off.)
    pub fn set_half_steps(&mut self, on: bool) {
        self.half_steps = on;
    }

    /// Changes the amplitude mapping (validated; field `"pump_amplitude"`). The next
    /// tick rewrites the amplitude. Changing `base_scale` while running steps `s`, which
    /// biases the rows for a while (FINDINGS §3.2): do it with the estimator gated.
    pub fn set_pump_amplitude(&mut self, amplitude: PumpAmplitude) -> Result<(), ConfigError> {
        amplitude.validate()?;
        self.amplitude = amplitude;
        self.dirty = true;
        Ok(())
    }

    /// Commands the initial pump: the core's `initial_pump_hz` (inside the guard) and
    /// the scale `s_base`, then pulses IO_UPDATE. Until it succeeds no pump is known and
    /// the ticks' samples are flagged (NaN pump); a failed start is counted in
    /// `dds_errors` and may be retried (or left to the next tick, which writes the
    /// core's command). Returns the realised plan.
    pub fn start<IO: IoUpdate + ?Sized>(
        &mut self,
        io: &mut IO,
    ) -> Result<PumpPlan, ad9959::Error<DDS::Error>> {
        let plan = self
            .guard
            .plan(self.est.initial_pump_hz(), self.chips.dds.sysclk_hz())
            .ok_or(ad9959::Error::FrequencyOutOfRange)?;
        let asf = self.amplitude.word_for(1.0);
        self.apply(plan, asf, io)?;
        Ok(plan)
    }

    /// The 500 Hz tick (DRDY interrupt body): read, step, command. Bounded, allocation-
    /// free, never panics; see the module documentation for the order and fault rules.
    pub fn tick<IO: IoUpdate + ?Sized>(&mut self, io: &mut IO) -> TickReport {
        self.tick_inner(io, None)
    }

    /// [`App::tick`] for an open-loop replay of a record: the sample carries the pump
    /// the record says was in effect (`pump_hz`, `pump_scale`) instead of the DDS's,
    /// because the recorded lock-in data were produced by that pump. Everything else is
    /// the same tick: frames, core step, guard, DDS plan and writes (the realised pump
    /// the DDS would run is then in [`TickReport::pump_hz`] and in the DDS, to be
    /// compared with the record's next pump).
    pub fn tick_with_pump<IO: IoUpdate + ?Sized>(
        &mut self,
        io: &mut IO,
        pump_hz: f64,
        pump_scale: f32,
    ) -> TickReport {
        self.tick_inner(io, Some((pump_hz, pump_scale)))
    }

    fn tick_inner<IO: IoUpdate + ?Sized>(
        &mut self,
        io: &mut IO,
        known_pump: Option<(f64, f32)>,
    ) -> TickReport {
        bump(&mut self.counters.ticks);
        let (x, fx) = read_axis(
            &mut self.chips.adc_x,
            &self.cal_x,
            self.lockin_beyond_um,
            fault::ADC_X,
            &mut self.counters,
        );
        let (y, fy) = read_axis(
            &mut self.chips.adc_y,
            &self.cal_y,
            self.lockin_beyond_um,
            fault::ADC_Y,
            &mut self.counters,
        );
        let (accel, temp_raw, fa) = read_accel(
            &mut self.chips.accel,
            self.accel_beyond_mps2,
            &mut self.counters,
            &mut self.accel_stuck,
        );
        let mut faults = fx | fy | fa;
        let (pump_hz, pump_scale) =
            known_pump.unwrap_or_else(|| (self.pump_hz(), self.pump_scale()));
        if known_pump.is_none() && self.pump.is_none() {
            faults |= fault::PUMP_UNKNOWN;
        }
        // the sample is built in place (a local and a copy into `last` after the step
        // cost an 80-byte `memcpy` a tick); its temperature is held between reads
        self.last.lockin = lockin(x, y);
        self.last.accel_mps2 = accel;
        self.last.pump_hz = pump_hz;
        self.last.pump_scale = pump_scale;
        if let Some(n) = self.temp_countdown.checked_sub(1) {
            self.temp_countdown = n;
        } else {
            self.temp_countdown = TEMP_EVERY - 1;
            self.last.temp_c = plausible_temp_c(temp_raw);
        }
        let out = self.est.step(&self.last);
        faults |= self.command(&out, io);
        TickReport {
            out,
            sample_ok: faults & fault::SAMPLE == 0,
            pump_hz: self.pump_hz(),
            pump_scale: self.pump_scale(),
            faults,
        }
    }

    /// The core's command through the guard to the DDS; returns fault bits.
    fn command<IO: IoUpdate + ?Sized>(&mut self, out: &StepOutput, io: &mut IO) -> u8 {
        let mut faults = 0;
        let current = self.pump;
        let requested = out.pump_hz_next;
        let target = if requested.is_finite() {
            requested
        } else {
            current.map_or(self.guard.midpoint(), |p| p.pump_hz)
        };
        if !self.in_guard(target) || !requested.is_finite() {
            bump(&mut self.counters.guard_clamps);
            faults |= fault::GUARD;
        }
        let m = out.pump_scale_next;
        let asf = if m.is_finite() && m >= 0.0 {
            self.amplitude.word_for(m)
        } else {
            // NaN would switch the pump off: keep the amplitude instead
            bump(&mut self.counters.guard_clamps);
            faults |= fault::GUARD;
            current.map_or(self.amplitude.word_for(1.0), |p| p.asf)
        };
        let Some(plan) = self.guard_plan(target) else {
            // cannot happen for a validated guard; keep the pump and rewrite next time
            bump(&mut self.counters.dds_errors);
            self.dirty = true;
            return faults | fault::DDS;
        };
        let node = self.node.filter(|_| self.half_steps && !self.dirty);
        let steps = node.and_then(|n| self.half_steps_to(n, plan));
        let Some((pa, pb, residual)) = steps else {
            // one step: without two steps, the first command, after an error, or steps
            // that would leave the guard
            if self.apply(plan, asf, io).is_err() {
                self.node = None;
                return faults | fault::DDS;
            }
            self.node = self.half_steps.then_some(plan.reference_ftw() as i32);
            self.residual = 0;
            return faults;
        };
        if self.step_now(pa, asf, io).is_err() {
            return faults | self.hold_active();
        }
        let held = match self.load(pb, asf) {
            Ok(()) if self.chips.dds.take_io_update().is_none() => true,
            Ok(()) if io.pulse_at_half_period() => {
                self.active = Some((pb.reference_ftw(), asf));
                true
            }
            // the line cannot pulse later, or the write failed: the DDS holds the first
            // step, the next sample is told so, the next tick rewrites all
            Ok(()) | Err(_) => {
                bump(&mut self.counters.dds_errors);
                self.dirty = true;
                false
            }
        };
        if !held {
            return faults | self.hold_active();
        }
        self.node = Some(plan.reference_ftw() as i32);
        self.residual = residual;
        self.tell_steps(pa, pb, asf);
        faults
    }

    /// Two steps in the DDS, `pa` then `pb`: the next sample is told the sweep whose half
    /// means they are, A and B, (3A − B)/2 → (3B − A)/2 words (the end exact: half a word
    /// is a power-of-two scaling), a sweep of 2(B − A) words, which the core holds for its
    /// next step (after one step it has none: the replica sweeps from the pump told
    /// before). Not inlined (the stm32f405 image's flash).
    #[inline(never)]
    fn tell_steps(&mut self, pa: PumpPlan, pb: PumpPlan, asf: AmplitudeWord) {
        // words below 2^27 (`half_steps_to`): no overflow
        let (a, b) = (pa.reference_ftw() as i32, pb.reference_ftw() as i32);
        let sweep = b.wrapping_sub(a).wrapping_mul(2);
        self.est
            .set_pump_sweep_hz(sweep as f32 * self.hz_per_ref_word_f32);
        let end = b.wrapping_mul(3).wrapping_sub(a) as u32;
        let pump_hz = f64::from(end) * self.hz_per_half_word;
        self.pump = Some(InEffect {
            plan: pb,
            asf,
            pump_hz,
        });
    }

    /// The two frequency steps from the node `node` (the last command's reference word)
    /// towards the command `plan`, and the residual they leave ([`half_steps`]: the half
    /// means of the sweep node → command, rounded to whole words with error feedback).
    /// The amplitude is one step, the command's word over the whole interval (the core's
    /// ZOH replica of the scale, `PumpProfile::HalfSteps`).
    /// `None` if a step would leave the guard, or for a word of 2^27 or more (a pump above
    /// f_SYSCLK/16: one step, no overflow).
    fn half_steps_to(&self, node: i32, plan: PumpPlan) -> Option<(PumpPlan, PumpPlan, i32)> {
        let c = plan.reference_ftw() as i32;
        // below 2^27 every product and sum here and in `half_steps` stays below 2^31
        if !(0..1 << 27).contains(&c) || !(0..1 << 27).contains(&node) {
            return None;
        }
        let (a, b, residual) = half_steps(node, c, self.residual);
        let (lo, hi) = (self.guard_words.0 as i32, self.guard_words.1 as i32);
        if !(lo <= a.min(b) && a.max(b) <= hi) {
            return None;
        }
        let sysclk = self.chips.dds.sysclk_hz();
        let pa = PumpPlan::from_reference_ftw(a as u32, sysclk)?;
        let pb = PumpPlan::from_reference_ftw(b as u32, sysclk)?;
        Some((pa, pb, residual))
    }

    /// [`PumpGuard::contains`] of the configured guard by its bit patterns (`guard_bits`).
    fn in_guard(&self, hz: f64) -> bool {
        let b = hz.to_bits();
        let (lo, hi) = self.guard_bits;
        lo <= b && b <= hi
    }

    /// [`PumpGuard::plan`] in integer words on the tick path: the nearest reference word
    /// `k = round(f/2 · 2^32 / f_SYSCLK)` (the same `f64` operations as
    /// [`ad9959::ftw_from_hz`]: the power-of-two scalings are exact), clamped to the
    /// guard's words. Rounding is monotone, so this is the word `plan` picks (clamp, round,
    /// step inwards) with one division instead of two plans; NaN and negative requests
    /// give the lower guard word, huge ones the upper.
    fn guard_plan(&self, pump_hz: f64) -> Option<PumpPlan> {
        let sysclk = self.chips.dds.sysclk_hz();
        // = pump_hz · 0.5 · 2^32 / sysclk bit for bit: both divide the same exact
        // quotient's operands scaled by powers of two, rounded once
        let x = pump_hz / self.hz_per_ref_word;
        // round half up, saturating: NaN and negatives give 0, overflow u32::MAX (from the
        // bits: the `as` cast costs two soft-float comparisons besides the conversion)
        let k = f64_round_u32(x);
        let (lo, hi) = self.guard_words;
        // `max`/`min`, not `clamp`: the same word for lo ≤ hi (a validated guard), and no
        // panic path (`clamp`'s `min > max` message kept `core::fmt` in the image)
        PumpPlan::from_reference_ftw(k.max(lo).min(hi), sysclk)
    }

    /// Writes the words that differ from the ones in effect (all of them after an error
    /// or a mapping change), pulses IO_UPDATE if anything was written, and records the
    /// new pump in effect. On an error: no pulse, the old pump stays, counted.
    fn apply<IO: IoUpdate + ?Sized>(
        &mut self,
        plan: PumpPlan,
        asf: AmplitudeWord,
        io: &mut IO,
    ) -> Result<(), ad9959::Error<DDS::Error>> {
        // (with two steps `pump_hz` may be a node's, not its plan's)
        let same_word = self
            .pump
            .filter(|p| !self.half_steps && p.plan.reference_ftw() == plan.reference_ftw());
        self.step_now(plan, asf, io)?;
        // = plan.pump_hz() bit for bit: 2k·f_SYSCLK/2^32 = k·(2·f_SYSCLK/2^32), the
        // same product rounded once and scaled by powers of two (one multiplication
        // fewer)
        let pump_hz = same_word.map_or_else(
            || f64::from(plan.reference_ftw()) * self.hz_per_ref_word,
            |p| p.pump_hz,
        );
        self.pump = Some(InEffect { plan, asf, pump_hz });
        Ok(())
    }

    /// Loads the words that differ from the active ones and pulses IO_UPDATE if any was
    /// written; the DDS then holds them (`active`). On an error: no pulse, counted, every
    /// word rewritten next time.
    fn step_now<IO: IoUpdate + ?Sized>(
        &mut self,
        plan: PumpPlan,
        asf: AmplitudeWord,
        io: &mut IO,
    ) -> Result<(), ad9959::Error<DDS::Error>> {
        match self.load(plan, asf) {
            Ok(()) => {
                if self.chips.dds.take_io_update().is_some() {
                    io.pulse();
                }
                self.active = Some((plan.reference_ftw(), asf));
                self.dirty = false;
                Ok(())
            }
            Err(e) => {
                bump(&mut self.counters.dds_errors);
                self.dirty = true;
                Err(e)
            }
        }
    }

    /// After a failed step: the next sample is told the words the DDS holds (a cold path:
    /// the one place two steps compute the held pump).
    fn hold_active(&mut self) -> u8 {
        self.node = None;
        if let Some((k, asf)) = self.active
            && let Some(plan) = PumpPlan::from_reference_ftw(k, self.chips.dds.sysclk_hz())
        {
            let pump_hz = f64::from(k) * self.hz_per_ref_word;
            self.pump = Some(InEffect { plan, asf, pump_hz });
        }
        fault::DDS
    }

    /// Writes into the DDS's buffers the words that differ from its active ones (all of
    /// them after an error or a mapping change), in one SPI frame. Not inlined:
    /// one copy for both steps (the stm32f405 image's flash budget).
    #[inline(never)]
    fn load(
        &mut self,
        plan: PumpPlan,
        asf: AmplitudeWord,
    ) -> Result<(), ad9959::Error<DDS::Error>> {
        let all = self.dirty;
        let freq = all || self.active.is_none_or(|a| a.0 != plan.reference_ftw());
        let amp = all || self.active.is_none_or(|a| a.1 != asf);
        // one frame: the three tuning words if they changed, the amplitude if it did
        self.chips
            .dds
            .write_pump(freq.then_some(&plan), amp.then_some(asf))
    }

    /// Realised pump frequency in effect (the next sample's known pump), Hz; NaN before
    /// the first successful DDS write. With two steps per sample ([`App::set_half_steps`])
    /// the end of the sweep whose half means the two steps are, `(3B − A)/2` words (the
    /// DDS then runs the second step B).
    pub fn pump_hz(&self) -> f64 {
        self.pump.map_or(f64::NAN, |p| p.pump_hz)
    }

    /// Pump scale `s` in effect; NaN before the first successful DDS write.
    pub fn pump_scale(&self) -> f32 {
        self.pump
            .map_or(f32::NAN, |p| self.amplitude.realised(p.asf))
    }

    /// The DDS plan in effect (pump and reference words).
    pub fn pump_plan(&self) -> Option<PumpPlan> {
        self.pump.map(|p| p.plan)
    }

    /// The sample the core was given at the last tick: lock-in values in µm after the
    /// calibration (NaN for a lost frame, beyond full scale where saturated), the
    /// accelerations, the pump in effect. What the capture mode streams (one
    /// `paragyro-record 1` row per tick); NaN before the first tick.
    pub fn last_sample(&self) -> &Sample<f32> {
        &self.last
    }

    /// Firmware counters.
    pub fn counters(&self) -> FwCounters {
        self.counters
    }

    /// The estimator (θ̂, physical parameters, rate, health, its counters).
    pub fn estimator(&self) -> &Estimator<f32> {
        &self.est
    }

    /// The estimator, for commands between ticks (`command_pump_centre`, `set_dither`,
    /// `set_retune`); the guard still applies to whatever it then commands.
    pub fn estimator_mut(&mut self) -> &mut Estimator<f32> {
        &mut self.est
    }

    /// The pump guard.
    pub fn guard(&self) -> PumpGuard {
        self.guard
    }

    /// The amplitude mapping.
    pub fn pump_amplitude(&self) -> PumpAmplitude {
        self.amplitude
    }

    /// Gives the chips and the estimator back.
    pub fn release(self) -> (Chips<AX, AY, XL, DDS>, Estimator<f32>) {
        (self.chips, self.est)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::FailingSpi;
    use crate::drivers::ad9959::DEFAULT_SYSCLK_HZ;

    /// Chips whose every transfer fails (the App's set-up and pure helpers only).
    fn failing_chips() -> Chips<FailingSpi, FailingSpi, FailingSpi, FailingSpi> {
        Chips {
            adc_x: Ads131m08::new(FailingSpi::always_failing()),
            adc_y: Ads131m08::new(FailingSpi::always_failing()),
            accel: Adxl355::new(FailingSpi::always_failing()),
            dds: Ad9959::new(FailingSpi::always_failing(), DEFAULT_SYSCLK_HZ),
        }
    }

    /// The stuck-accelerometer test: off at 0; with a limit, refused from the limit-th
    /// identical read on, until the codes change.
    #[test]
    fn stuck_accelerometer_from_the_limit_th_identical_read() {
        let mut off = StuckAccel::default();
        assert!((0..100).all(|_| !off.push((5, 7))));
        let mut s = StuckAccel {
            limit: 3,
            ..StuckAccel::default()
        };
        let seen: Vec<bool> = [(1, 2), (1, 2), (1, 2), (1, 2), (1, 3), (1, 3), (1, 3)]
            .into_iter()
            .map(|xy| s.push(xy))
            .collect();
        assert_eq!(seen, [false, false, true, true, false, false, true]);
    }

    /// The realised pump from the reference word and `hz_per_ref_word` equals
    /// `PumpPlan::pump_hz` bit for bit.
    #[test]
    fn pump_hz_from_the_reference_word_equals_the_plan() {
        for sysclk in [DEFAULT_SYSCLK_HZ, 480e6, 25e6 * 17.0, 123_456_789.0] {
            let h = sysclk * (2.0 / FTW_SCALE);
            for k in (1..(1u32 << 31) / 3)
                .step_by(99_991)
                .chain([1, 2, (1 << 31) / 3 - 1])
            {
                let plan = PumpPlan::from_reference_ftw(k, sysclk).unwrap();
                assert_eq!(
                    (f64::from(k) * h).to_bits(),
                    plan.pump_hz().to_bits(),
                    "k {k}, sysclk {sysclk}"
                );
            }
        }
    }

    /// The tick path's guard test by bit patterns equals `PumpGuard::contains`.
    #[test]
    fn guard_test_by_bits_equals_contains() {
        let cfg = Config::table2();
        let chips = failing_chips();
        let guard = PumpGuard::around(cfg.pump_centre_hz, 400.0);
        let cal = LockinCalibration::UNITY;
        let app = App::new(chips, &cfg, cal, cal, guard).unwrap();
        let (lo, hi) = (guard.min_hz, guard.max_hz);
        let mut probes = vec![
            lo,
            hi,
            0.0,
            -0.0,
            -lo,
            -hi,
            1e-300,
            f64::MIN_POSITIVE,
            f64::MAX,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            -f64::NAN,
            0.5 * (lo + hi),
        ];
        for e in [lo, hi] {
            let b = e.to_bits();
            probes.extend([f64::from_bits(b - 1), f64::from_bits(b + 1)]);
        }
        let mut hz = lo - 50.0;
        while hz < hi + 50.0 {
            probes.push(hz);
            hz += 0.37;
        }
        for hz in probes {
            assert_eq!(app.in_guard(hz), guard.contains(hz), "{hz}");
        }
    }

    /// The tick path's integer guard plan picks the very word of `PumpGuard::plan`.
    #[test]
    fn guard_plan_in_words_equals_the_f64_plan() {
        let cfg = Config::table2();
        let chips = failing_chips();
        let guard = PumpGuard::around(cfg.pump_centre_hz, 400.0);
        let cal = LockinCalibration::from_um_per_volt(
            [1.0; LOCKIN_CHANNELS],
            [ads131m08::Gain::G1; LOCKIN_CHANNELS],
            [0; LOCKIN_CHANNELS],
        );
        let app = App::new(chips, &cfg, cal, cal, guard).unwrap();
        let step = 2.0 * DEFAULT_SYSCLK_HZ / FTW_SCALE;
        let mut hz = guard.min_hz - 3.0;
        let mut n = 0;
        while hz < guard.max_hz + 3.0 {
            // steps of a third of a word, so every rounding case and both edges are hit
            let want = guard.plan(hz, DEFAULT_SYSCLK_HZ).unwrap();
            assert_eq!(app.guard_plan(hz), Some(want), "{hz} Hz");
            hz += step / 3.0 + 1e-7;
            n += 1;
        }
        assert!(n > 10_000);
        for hz in [f64::NAN, f64::NEG_INFINITY, -1.0, 0.0] {
            assert_eq!(
                app.guard_plan(hz),
                guard.plan(guard.min_hz, DEFAULT_SYSCLK_HZ)
            );
        }
        for hz in [f64::INFINITY, 1e300, 3e9] {
            assert_eq!(
                app.guard_plan(hz),
                guard.plan(guard.max_hz, DEFAULT_SYSCLK_HZ)
            );
        }
    }
}
