//! Replay devices: [`SpiDevice`](embedded_hal::spi::SpiDevice)s that speak the chips' protocols from recorded or
//! synthetic data, for the host tests of [`crate::app`] and the QEMU board (which has no
//! chips).
//!
//! * [`ReplayAdc`]: an ADS131M08 serving one data frame per
//!   [`Ads131m08::read_frame`](crate::Ads131m08::read_frame) from a table of lock-in
//!   values in µm, encoded to codes with the inverse of a [`LockinCalibration`]
//!   ([`encode_lockin`]), valid STATUS (all DRDY bits) and CRC. It also answers `RESET`,
//!   `RREG`, `WREG`, `STANDBY`, `WAKEUP`, so the driver's `init` runs against it.
//! * [`ReplayAccel`]: an ADXL355 with a register file (IDs, RANGE, FILTER, POWER_CTL,
//!   RESET); every STATUS..ZDATA1 burst serves the next sample of a table of X, Y in m/s²
//!   (Z constant), encoded in 20-bit codes for the range written to RANGE.
//! * [`CaptureDds`] / [`DdsCapture`]: an AD9959 that records the CSR, CFTW0, CPOW0, ACR,
//!   FR1 and FR2 writes per channel in I/O buffers and applies them to the "active"
//!   registers on [`CaptureIo::pulse`], so a test or the QEMU board sees what the
//!   firmware commanded and what the DDS would actually run.
//!
//! A sample index counts the data reads (ADC data frames, accelerometer STATUS bursts),
//! failed ones included, so with one read per tick it is the tick number. Faults are
//! injected per index ([`Span`]): CRC corruption, SPI errors, DRDY flags not set, a code
//! at full scale, a stuck channel (ADC); an absent device, SPI errors (accelerometer);
//! SPI errors per transaction (DDS). After the end of its table a device reports no new
//! data (ADC DRDY clear, ADXL355 DATA_RDY clear) unless it was made [`looping`].
//!
//! Everything is `no_std`, allocation-free and panic-free; the DDS capture uses
//! [`Cell`](core::cell::Cell)s so the `SpiDevice` handed to the driver and the observer can share it.
//!
//! [`looping`]: ReplayAdc::looping

use embedded_hal::spi::{self, ErrorKind, Operation};

use crate::app::IoUpdate;
use crate::drivers::ad9959::{self, AmplitudeWord, Channel};
use crate::drivers::ads131m08::{
    self, CHANNELS, FRAME_BYTES, Frame, LOCKIN_CHANNELS, LockinCalibration, RawCode, opcode,
};
use crate::drivers::adxl355::{self, Range, Register as XlReg};
use crate::table::ReplayTable;

mod accel;
mod adc;
mod dds;

pub use accel::*;
pub use adc::*;
pub use dds::*;

/// The error of a replay device's injected SPI fault.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReplayError;

impl spi::Error for ReplayError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

/// A half-open range `[start, end)` of sample (or transaction) indices where a fault is
/// active; the default is empty.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Span {
    /// First index.
    pub start: usize,
    /// One past the last index.
    pub end: usize,
}

impl Span {
    /// No index.
    pub const NEVER: Span = Span { start: 0, end: 0 };

    /// `[start, end)`.
    pub const fn new(start: usize, end: usize) -> Self {
        Self { start, end }
    }

    /// Index `n` only.
    pub const fn at(n: usize) -> Self {
        Self {
            start: n,
            end: n.saturating_add(1),
        }
    }

    /// Index `n` and every later one.
    pub const fn starting_at(n: usize) -> Self {
        Self {
            start: n,
            end: usize::MAX,
        }
    }

    /// `start ≤ i < end`.
    pub const fn contains(&self, i: usize) -> bool {
        self.start <= i && i < self.end
    }
}

/// `round(x)`, half away from zero, saturating to `i64` (NaN is handled by the callers).
pub(super) fn round_i64(x: f64) -> i64 {
    (if x >= 0.0 { x + 0.5 } else { x - 0.5 }) as i64
}

/// The ADC code whose calibrated value is nearest to `value_um`:
/// `round(value_um / um_per_code) + offset_code`, clamped to the 24-bit range (a value
/// beyond full scale gives the full-scale code, as the ADC clips). NaN gives positive
/// full scale, so that a hole in a table shows up as saturation rather than as zero.
pub fn encode_um(value_um: f32, um_per_code: f32, offset_code: i32) -> RawCode {
    if value_um.is_nan() {
        return RawCode::POSITIVE_FULL_SCALE;
    }
    let steps = round_i64(f64::from(value_um) / f64::from(um_per_code));
    let code = steps.saturating_add(i64::from(offset_code)).clamp(
        i64::from(RawCode::NEGATIVE_FULL_SCALE.get()),
        i64::from(RawCode::POSITIVE_FULL_SCALE.get()),
    );
    i32::try_from(code).map_or(RawCode::POSITIVE_FULL_SCALE, RawCode::saturating_new)
}

/// The seven lock-in codes for values in µm (channel order X0, 1re, 1im, 2re, 2im, 3re,
/// 3im), the inverse of [`LockinCalibration::to_um`] up to half a code.
pub fn encode_lockin(
    cal: &LockinCalibration,
    um: &[f32; LOCKIN_CHANNELS],
) -> [RawCode; LOCKIN_CHANNELS] {
    let mut codes = [RawCode::default(); LOCKIN_CHANNELS];
    for (((c, v), s), off) in codes
        .iter_mut()
        .zip(um.iter())
        .zip(cal.um_per_code.iter())
        .zip(cal.offset_code.iter())
    {
        *c = encode_um(*v, *s, *off);
    }
    codes
}

/// Copy `src` into `bytes` from position `pos` on (bytes beyond its end are dropped).
pub(super) fn put(bytes: &mut [u8], pos: usize, src: &[u8]) {
    for (i, b) in src.iter().enumerate() {
        if let Some(slot) = bytes.get_mut(pos.saturating_add(i)) {
            *slot = *b;
        }
    }
}

/// Fill `dst` from `bytes` at position `pos` on (zeros beyond its end).
pub(super) fn take(bytes: &[u8], pos: usize, dst: &mut [u8]) {
    for (i, d) in dst.iter_mut().enumerate() {
        *d = bytes.get(pos.saturating_add(i)).copied().unwrap_or(0);
    }
}

/// The first MOSI byte of a transaction (0 if it starts with a read).
pub(super) fn first_mosi(operations: &[Operation<'_, u8>]) -> Option<u8> {
    operations.iter().find_map(|op| match op {
        Operation::Write(w) | Operation::Transfer(_, w) => Some(w.first().copied()),
        Operation::TransferInPlace(b) => Some(b.first().copied()),
        Operation::Read(r) => Some(r.first().map(|_| 0)),
        Operation::DelayNs(_) => None,
    })?
}
