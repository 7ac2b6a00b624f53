//! Replay devices: [`SpiDevice`]s that speak the chips' protocols from recorded or
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
//! [`Cell`]s so the `SpiDevice` handed to the driver and the observer can share it.
//!
//! [`looping`]: ReplayAdc::looping

use core::cell::Cell;

use embedded_hal::spi::{self, ErrorKind, ErrorType, Operation, SpiDevice};

use crate::app::IoUpdate;
use crate::drivers::ad9959::{self, AmplitudeWord, Channel};
use crate::drivers::ads131m08::{
    self, CHANNELS, FRAME_BYTES, Frame, LOCKIN_CHANNELS, LockinCalibration, RawCode, opcode,
};
use crate::drivers::adxl355::{self, Range, Register as XlReg};
use crate::table::ReplayTable;

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
fn round_i64(x: f64) -> i64 {
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
fn put(bytes: &mut [u8], pos: usize, src: &[u8]) {
    for (i, b) in src.iter().enumerate() {
        if let Some(slot) = bytes.get_mut(pos.saturating_add(i)) {
            *slot = *b;
        }
    }
}

/// Fill `dst` from `bytes` at position `pos` on (zeros beyond its end).
fn take(bytes: &[u8], pos: usize, dst: &mut [u8]) {
    for (i, d) in dst.iter_mut().enumerate() {
        *d = bytes.get(pos.saturating_add(i)).copied().unwrap_or(0);
    }
}

// ------------------------------------------------------------------------------------------
// ADS131M08

/// ID register of the replayed ADS131M08.
pub const ADC_ID: u16 = 0x2810;
const ADC_MODE_RESET: u16 = 0x0510;
const ADC_CLOCK_RESET: u16 = 0xFF0E;
const ADC_CFG_RESET: u16 = 0x0600;
/// STATUS bits of a replayed frame besides DRDY: WLENGTH = 24 bits.
const ADC_STATUS_WLENGTH_24: u16 = 0x0100;
/// STATUS / MODE bit of the reset flag.
const ADC_RESET_FLAG: u16 = 0x0400;
/// First byte of the CRC word in a frame.
const CRC_BYTE: usize = FRAME_BYTES - 3;

/// Faults of a [`ReplayAdc`], per data-frame index.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AdcFaults {
    /// The frame's CRC word is corrupted (one bit flipped).
    pub crc: Span,
    /// The transaction fails with [`ReplayError`].
    pub spi: Span,
    /// STATUS has no DRDY flag set.
    pub not_ready: Span,
    /// Channel `saturated_channel` reads positive full scale.
    pub saturated: Span,
    /// Lock-in channel (0..7) of `saturated`.
    pub saturated_channel: usize,
    /// Channel `stuck_channel` repeats the code of sample `stuck.start`.
    pub stuck: Span,
    /// Lock-in channel (0..7) of `stuck`.
    pub stuck_channel: usize,
}

/// What the next frame's first word carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Pending {
    /// STATUS (after `NULL`): a data frame.
    Status,
    /// The answer to the previous command.
    Word(u16),
}

/// Where a [`ReplayAdc`]'s samples come from.
#[derive(Clone, Debug)]
enum AdcData<'a> {
    /// Values in µm, encoded through the inverse of `cal`.
    Um {
        samples: &'a [[f32; LOCKIN_CHANNELS]],
        cal: LockinCalibration,
    },
    /// Codes of one axis of a replay table.
    Table { table: ReplayTable<'a>, axis: usize },
}

/// An ADS131M08 replaying lock-in values (µm) of one axis, one sample per data frame.
#[derive(Clone, Debug)]
pub struct ReplayAdc<'a> {
    samples: AdcData<'a>,
    looping: bool,
    faults: AdcFaults,
    next: usize,
    transactions: usize,
    pending: Pending,
    reset_flag: bool,
    mode: u16,
    clock: u16,
    gain1: u16,
    gain2: u16,
    cfg: u16,
}

impl<'a> ReplayAdc<'a> {
    /// Serves `samples` (µm, lock-in channel order) through the inverse of `cal` (use the
    /// calibration the firmware decodes with).
    pub const fn new(samples: &'a [[f32; LOCKIN_CHANNELS]], cal: LockinCalibration) -> Self {
        Self::with_data(AdcData::Um { samples, cal })
    }

    /// Serves the lock-in codes of one axis (0 drive, 1 sense) of a replay table as they
    /// are (the codes the simulator's record was quantised to).
    pub const fn from_table(table: ReplayTable<'a>, axis: usize) -> Self {
        Self::with_data(AdcData::Table { table, axis })
    }

    const fn with_data(samples: AdcData<'a>) -> Self {
        Self {
            samples,
            looping: false,
            faults: AdcFaults {
                crc: Span::NEVER,
                spi: Span::NEVER,
                not_ready: Span::NEVER,
                saturated: Span::NEVER,
                saturated_channel: 0,
                stuck: Span::NEVER,
                stuck_channel: 0,
            },
            next: 0,
            transactions: 0,
            pending: Pending::Status,
            reset_flag: true,
            mode: ADC_MODE_RESET,
            clock: ADC_CLOCK_RESET,
            gain1: 0,
            gain2: 0,
            cfg: ADC_CFG_RESET,
        }
    }

    /// Start over at the first sample after the last one (instead of reporting no data).
    pub const fn looping(mut self) -> Self {
        self.looping = true;
        self
    }

    /// Replace all faults.
    pub const fn with_faults(mut self, faults: AdcFaults) -> Self {
        self.faults = faults;
        self
    }

    /// Corrupt the CRC of the data frames in `span`.
    pub const fn with_crc_error(mut self, span: Span) -> Self {
        self.faults.crc = span;
        self
    }

    /// Fail the data-frame transactions in `span`.
    pub const fn with_spi_error(mut self, span: Span) -> Self {
        self.faults.spi = span;
        self
    }

    /// Clear the DRDY flags of the data frames in `span`.
    pub const fn with_not_ready(mut self, span: Span) -> Self {
        self.faults.not_ready = span;
        self
    }

    /// Lock-in `channel` at positive full scale in `span`.
    pub const fn with_saturation(mut self, span: Span, channel: usize) -> Self {
        self.faults.saturated = span;
        self.faults.saturated_channel = channel;
        self
    }

    /// Lock-in `channel` stuck at its code of sample `span.start` during `span`.
    pub const fn with_stuck(mut self, span: Span, channel: usize) -> Self {
        self.faults.stuck = span;
        self.faults.stuck_channel = channel;
        self
    }

    /// Data frames requested so far (the index of the next sample).
    pub const fn samples_served(&self) -> usize {
        self.next
    }

    /// SPI transactions so far.
    pub const fn transactions(&self) -> usize {
        self.transactions
    }

    /// Index into the table for sample `i` (`None` after the end, unless looping).
    fn table_index(&self, i: usize) -> Option<usize> {
        let len = match &self.samples {
            AdcData::Um { samples, .. } => samples.len(),
            AdcData::Table { table, .. } => table.len(),
        };
        if self.looping {
            i.checked_rem(len)
        } else {
            (i < len).then_some(i)
        }
    }

    fn lockin_codes(&self, i: usize) -> Option<[RawCode; LOCKIN_CHANNELS]> {
        let j = self.table_index(i)?;
        match &self.samples {
            AdcData::Um { samples, cal } => Some(encode_lockin(cal, samples.get(j)?)),
            AdcData::Table { table, axis } => {
                Some(table.adc_codes(j, *axis)?.map(RawCode::saturating_new))
            }
        }
    }

    /// The eight codes of sample `i` with the faults applied (`None` after the end).
    fn codes(&self, i: usize) -> Option<[RawCode; CHANNELS]> {
        let lockin = self.lockin_codes(i)?;
        let mut codes = [RawCode::default(); CHANNELS];
        for (c, l) in codes.iter_mut().zip(lockin) {
            *c = l;
        }
        let f = &self.faults;
        if f.stuck.contains(i)
            && let Some(held) = self.lockin_codes(f.stuck.start)
            && let (Some(c), Some(h)) = (codes.get_mut(f.stuck_channel), held.get(f.stuck_channel))
        {
            *c = *h;
        }
        if f.saturated.contains(i)
            && let Some(c) = codes.get_mut(f.saturated_channel)
        {
            *c = RawCode::POSITIVE_FULL_SCALE;
        }
        Some(codes)
    }

    fn status(&self, drdy: bool) -> u16 {
        let mut s = ADC_STATUS_WLENGTH_24;
        if self.reset_flag {
            s |= ADC_RESET_FLAG;
        }
        if drdy {
            s |= 0x00FF;
        }
        s
    }

    /// MISO of this frame: the pending response, and for data frame `index` its codes.
    fn miso(&self, index: Option<usize>) -> [u8; FRAME_BYTES] {
        let zero = [RawCode::default(); CHANNELS];
        let (frame, crc_fault) = match (self.pending, index) {
            (Pending::Word(w), _) => (
                Frame {
                    response: w,
                    codes: zero,
                },
                false,
            ),
            (Pending::Status, None) => (
                Frame {
                    response: self.status(true),
                    codes: zero,
                },
                false,
            ),
            (Pending::Status, Some(i)) => match self.codes(i) {
                Some(codes) => (
                    Frame {
                        response: self.status(!self.faults.not_ready.contains(i)),
                        codes,
                    },
                    self.faults.crc.contains(i),
                ),
                // no more data: DRDY clear
                None => (
                    Frame {
                        response: self.status(false),
                        codes: zero,
                    },
                    self.faults.crc.contains(i),
                ),
            },
        };
        let mut bytes = frame.encode();
        if crc_fault && let Some(b) = bytes.get_mut(CRC_BYTE) {
            *b ^= 0x01;
        }
        bytes
    }

    fn read_register(&self, addr: u16) -> u16 {
        match addr {
            0x00 => ADC_ID,
            0x01 => self.status(true),
            0x02 => {
                let flag = if self.reset_flag { ADC_RESET_FLAG } else { 0 };
                (self.mode & !ADC_RESET_FLAG) | flag
            }
            0x03 => self.clock,
            0x04 => self.gain1,
            0x05 => self.gain2,
            0x06 => self.cfg,
            _ => 0,
        }
    }

    fn write_register(&mut self, addr: u16, value: u16) {
        match addr {
            0x02 => {
                self.mode = value;
                // the reset flag is cleared by writing 0 to it
                self.reset_flag = self.reset_flag && value & ADC_RESET_FLAG != 0;
            }
            0x03 => self.clock = value,
            0x04 => self.gain1 = value,
            0x05 => self.gain2 = value,
            0x06 => self.cfg = value,
            _ => {}
        }
    }

    fn reset(&mut self) {
        self.reset_flag = true;
        self.mode = ADC_MODE_RESET;
        self.clock = ADC_CLOCK_RESET;
        self.gain1 = 0;
        self.gain2 = 0;
        self.cfg = ADC_CFG_RESET;
    }

    /// The response the next frame carries for `command` (with data word `data`).
    fn respond(&mut self, command: u16, data: u16) -> Pending {
        match command {
            opcode::NULL => Pending::Status,
            opcode::RESET => {
                self.reset();
                Pending::Word(ads131m08::RESET_ACK)
            }
            opcode::STANDBY | opcode::WAKEUP | opcode::LOCK | opcode::UNLOCK => {
                Pending::Word(command)
            }
            // RREG: 101a aaaa annn nnnn (one register)
            c if c & 0xE000 == 0xA000 => Pending::Word(self.read_register((c >> 7) & 0x3F)),
            // WREG: 011a aaaa annn nnnn, acknowledged as 010a aaaa annn nnnn
            c if c & 0xE000 == 0x6000 => {
                self.write_register((c >> 7) & 0x3F, data);
                Pending::Word(0x4000 | (c & 0x1FFF))
            }
            _ => Pending::Status,
        }
    }
}

impl ErrorType for ReplayAdc<'_> {
    type Error = ReplayError;
}

impl SpiDevice<u8> for ReplayAdc<'_> {
    // never inlined: the instruction profile then tells the fake chip from the driver
    #[inline(never)]
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), ReplayError> {
        self.transactions = self.transactions.saturating_add(1);
        // pass 1: MOSI (the command word and the first data word are all that matter)
        let mut mosi = [0u8; 6];
        let mut pos = 0usize;
        for op in operations.iter() {
            let (bytes, clocked): (&[u8], usize) = match op {
                Operation::Write(w) => (w, w.len()),
                Operation::TransferInPlace(b) => (b, b.len()),
                Operation::Transfer(r, w) => (w, r.len().max(w.len())),
                Operation::Read(r) => (&[], r.len()),
                Operation::DelayNs(_) => (&[], 0),
            };
            put(&mut mosi, pos, bytes);
            pos = pos.saturating_add(clocked);
        }
        let [c0, c1, _, d0, d1, _] = mosi;
        let command = u16::from_be_bytes([c0, c1]);
        let data = u16::from_be_bytes([d0, d1]);
        let index = (self.pending == Pending::Status && command == opcode::NULL).then(|| {
            let i = self.next;
            self.next = i.saturating_add(1);
            i
        });
        if index.is_some_and(|i| self.faults.spi.contains(i)) {
            return Err(ReplayError);
        }
        // pass 2: MISO
        let miso = self.miso(index);
        let mut pos = 0usize;
        for op in operations.iter_mut() {
            let clocked = match op {
                Operation::Read(r) | Operation::TransferInPlace(r) => {
                    take(&miso, pos, r);
                    r.len()
                }
                Operation::Transfer(r, w) => {
                    take(&miso, pos, r);
                    r.len().max(w.len())
                }
                Operation::Write(w) => w.len(),
                Operation::DelayNs(_) => 0,
            };
            pos = pos.saturating_add(clocked);
        }
        self.pending = self.respond(command, data);
        Ok(())
    }
}

// ------------------------------------------------------------------------------------------
// ADXL355

/// Number of registers modelled (0x00..=0x2F).
const XL_REGS: usize = 0x30;
/// Code range of one axis.
const XL_CODE_MIN: i64 = -0x8_0000;
const XL_CODE_MAX: i64 = 0x7_FFFF;

/// The 20-bit code of `a_mps2` at `range` (rounded, clamped to the code range, where the
/// device clips; NaN gives positive full scale).
pub fn encode_accel(a_mps2: f32, range: Range) -> i32 {
    if a_mps2.is_nan() {
        return 0x7_FFFF;
    }
    let steps = round_i64(f64::from(a_mps2) / f64::from(range.mps2_per_lsb()));
    i32::try_from(steps.clamp(XL_CODE_MIN, XL_CODE_MAX)).unwrap_or(0)
}

/// The three data bytes (DATA3, DATA2, DATA1) of a 20-bit code, the inverse of
/// [`adxl355::raw20_from_bytes`].
pub fn accel_bytes(code: i32) -> [u8; 3] {
    let [b3, b2, b1, _] = code.wrapping_shl(12).to_be_bytes();
    [b3, b2, b1 & 0xF0]
}

fn xl_reset_registers() -> [u8; XL_REGS] {
    let mut r = [0u8; XL_REGS];
    for (addr, v) in [
        (XlReg::DevIdAd, adxl355::DEVID_AD),
        (XlReg::DevIdMst, adxl355::DEVID_MST),
        (XlReg::PartId, adxl355::PARTID),
        (XlReg::RevId, 0x01),
        (XlReg::Filter, 0x00),
        (XlReg::Range, 0x81),
        (XlReg::PowerCtl, 0x01),
    ] {
        if let Some(slot) = r.get_mut(usize::from(addr.addr())) {
            *slot = v;
        }
    }
    r
}

/// Where a [`ReplayAccel`]'s samples come from.
#[derive(Clone, Debug)]
enum AccelData<'a> {
    /// X, Y in m/s², encoded for the range written to RANGE.
    Mps2(&'a [[f32; 2]]),
    /// X, Y codes of a replay table.
    Table(ReplayTable<'a>),
}

/// An ADXL355 replaying X, Y accelerations (m/s²), one sample per STATUS..ZDATA1 burst.
#[derive(Clone, Debug)]
pub struct ReplayAccel<'a> {
    samples: AccelData<'a>,
    z_mps2: f32,
    looping: bool,
    missing: Span,
    spi_error: Span,
    next: usize,
    transactions: usize,
    regs: [u8; XL_REGS],
}

/// Per-transaction byte-stream state of the ADXL355's serial port.
struct XlStream {
    command: Option<u8>,
    addr: u8,
    read: bool,
    absent: bool,
}

impl<'a> ReplayAccel<'a> {
    /// Serves `samples` (X along the drive axis, Y along the sense axis, m/s²) with
    /// Z = standard gravity (the board lying flat).
    pub fn new(samples: &'a [[f32; 2]]) -> Self {
        Self::with_data(AccelData::Mps2(samples))
    }

    /// Serves the X, Y codes of a replay table as they are (they are for the table's
    /// range: the firmware must set that range), Z = standard gravity.
    pub fn from_table(table: ReplayTable<'a>) -> Self {
        Self::with_data(AccelData::Table(table))
    }

    fn with_data(samples: AccelData<'a>) -> Self {
        Self {
            samples,
            z_mps2: adxl355::STANDARD_GRAVITY_MPS2,
            looping: false,
            missing: Span::NEVER,
            spi_error: Span::NEVER,
            next: 0,
            transactions: 0,
            regs: xl_reset_registers(),
        }
    }

    /// Z acceleration (e.g. 0 for a board on its side).
    pub fn with_z_mps2(mut self, z_mps2: f32) -> Self {
        self.z_mps2 = z_mps2;
        self
    }

    /// Start over at the first sample after the last one.
    pub fn looping(mut self) -> Self {
        self.looping = true;
        self
    }

    /// The device is absent for samples in `span`: every byte reads `0xFF` (MISO floating
    /// high) in those sample reads, and in any other read while the next sample index is
    /// in `span`.
    pub fn with_missing(mut self, span: Span) -> Self {
        self.missing = span;
        self
    }

    /// Fail the sample reads in `span`.
    pub fn with_spi_error(mut self, span: Span) -> Self {
        self.spi_error = span;
        self
    }

    /// Sample reads so far (the index of the next sample).
    pub const fn samples_served(&self) -> usize {
        self.next
    }

    /// SPI transactions so far.
    pub const fn transactions(&self) -> usize {
        self.transactions
    }

    /// The range written to RANGE (reserved code 00 reads as ±2 g).
    pub fn range(&self) -> Range {
        match self.reg(XlReg::Range.addr()) & 0x03 {
            0b10 => Range::G4,
            0b11 => Range::G8,
            _ => Range::G2,
        }
    }

    fn reg(&self, addr: u8) -> u8 {
        self.regs.get(usize::from(addr)).copied().unwrap_or(0)
    }

    fn write_reg(&mut self, addr: u8, value: u8) {
        if addr == XlReg::Reset.addr() {
            if value == adxl355::RESET_CODE {
                self.regs = xl_reset_registers();
            }
            return;
        }
        // 0x00..=0x1D are read-only
        if addr >= 0x1E
            && let Some(slot) = self.regs.get_mut(usize::from(addr))
        {
            *slot = value;
        }
    }

    /// Put sample `i` into STATUS..ZDATA1 (STATUS 0, no data, after the end).
    fn load(&mut self, i: usize) {
        let len = match &self.samples {
            AccelData::Mps2(s) => s.len(),
            AccelData::Table(t) => t.len(),
        };
        let index = if self.looping {
            i.checked_rem(len)
        } else {
            (i < len).then_some(i)
        };
        let range = self.range();
        let codes = index.and_then(|j| match &self.samples {
            AccelData::Mps2(s) => s
                .get(j)
                .map(|&[x, y]| [encode_accel(x, range), encode_accel(y, range)]),
            AccelData::Table(t) => t.accel_codes(j),
        });
        let mut block = [0u8; 13];
        if let Some([x, y]) = codes {
            let [x3, x2, x1] = accel_bytes(x);
            let [y3, y2, y1] = accel_bytes(y);
            let [z3, z2, z1] = accel_bytes(encode_accel(self.z_mps2, range));
            // STATUS (DATA_RDY), FIFO_ENTRIES, TEMP2, TEMP1 (≈ 25 °C), X, Y, Z
            block = [0x01, 0, 0x07, 0x08, x3, x2, x1, y3, y2, y1, z3, z2, z1];
        }
        put(&mut self.regs, usize::from(XlReg::Status.addr()), &block);
    }

    /// One byte of the stream: MOSI in, MISO out.
    fn byte(&mut self, s: &mut XlStream, mosi: u8) -> u8 {
        let miso = match s.command {
            None => {
                s.command = Some(mosi);
                s.addr = mosi >> 1;
                s.read = mosi & 1 == 1;
                0
            }
            Some(_) if s.read => {
                let v = self.reg(s.addr);
                s.addr = s.addr.wrapping_add(1);
                v
            }
            Some(_) => {
                if !s.absent {
                    self.write_reg(s.addr, mosi);
                }
                s.addr = s.addr.wrapping_add(1);
                0
            }
        };
        if s.absent { 0xFF } else { miso }
    }
}

/// The first MOSI byte of a transaction (0 if it starts with a read).
fn first_mosi(operations: &[Operation<'_, u8>]) -> Option<u8> {
    operations.iter().find_map(|op| match op {
        Operation::Write(w) | Operation::Transfer(_, w) => Some(w.first().copied()),
        Operation::TransferInPlace(b) => Some(b.first().copied()),
        Operation::Read(r) => Some(r.first().map(|_| 0)),
        Operation::DelayNs(_) => None,
    })?
}

impl ErrorType for ReplayAccel<'_> {
    type Error = ReplayError;
}

impl SpiDevice<u8> for ReplayAccel<'_> {
    // never inlined: the instruction profile then tells the fake chip from the driver
    #[inline(never)]
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), ReplayError> {
        self.transactions = self.transactions.saturating_add(1);
        let sample_read = first_mosi(operations) == Some(XlReg::Status.read_cmd());
        let mut absent = self.missing.contains(self.next);
        if sample_read {
            let i = self.next;
            self.next = i.saturating_add(1);
            if self.spi_error.contains(i) {
                return Err(ReplayError);
            }
            absent = self.missing.contains(i);
            if !absent {
                self.load(i);
            }
        }
        let mut s = XlStream {
            command: None,
            addr: 0,
            read: false,
            absent,
        };
        for op in operations.iter_mut() {
            match op {
                Operation::Write(w) => {
                    for b in w.iter() {
                        self.byte(&mut s, *b);
                    }
                }
                Operation::Read(r) => {
                    for b in r.iter_mut() {
                        *b = self.byte(&mut s, 0);
                    }
                }
                Operation::TransferInPlace(buf) => {
                    for b in buf.iter_mut() {
                        *b = self.byte(&mut s, *b);
                    }
                }
                Operation::Transfer(r, w) => {
                    let n = r.len().max(w.len());
                    for i in 0..n {
                        let out = self.byte(&mut s, w.get(i).copied().unwrap_or(0));
                        if let Some(slot) = r.get_mut(i) {
                            *slot = out;
                        }
                    }
                }
                Operation::DelayNs(_) => {}
            }
        }
        Ok(())
    }
}

// ------------------------------------------------------------------------------------------
// AD9959

/// Per-channel words of the AD9959 (channel `n` at index `n`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DdsWords {
    /// Frequency tuning words (CFTW0).
    pub ftw: [u32; 4],
    /// Amplitude scale factors (ACR, 10 bits).
    pub asf: [u16; 4],
    /// Phase offset words (CPOW0, 14 bits).
    pub pow: [u16; 4],
}

impl DdsWords {
    fn channel(ch: Channel) -> usize {
        usize::from(ch as u8)
    }

    /// Tuning word of a channel.
    pub fn ftw_of(&self, ch: Channel) -> u32 {
        self.ftw.get(Self::channel(ch)).copied().unwrap_or(0)
    }

    /// Amplitude word of a channel.
    pub fn asf_of(&self, ch: Channel) -> AmplitudeWord {
        AmplitudeWord::new(self.asf.get(Self::channel(ch)).copied().unwrap_or(0))
    }

    /// The references are phase-locked to the pump: pump word 2k, reference k, 3Ω 3k.
    pub fn phase_locked(&self) -> bool {
        let k = self.ftw_of(Channel::REFERENCE);
        Some(self.ftw_of(Channel::PUMP)) == k.checked_mul(2)
            && Some(self.ftw_of(Channel::THIRD)) == k.checked_mul(3)
    }
}

/// The shared record of a [`CaptureDds`]: I/O buffers (last words written), active
/// registers (applied by IO_UPDATE), counters and the fault schedule.
#[derive(Debug)]
pub struct DdsCapture {
    sysclk_hz: f64,
    csr: Cell<u8>,
    fr1: Cell<[u8; 3]>,
    fr2: Cell<u16>,
    buffered: Cell<DdsWords>,
    active: Cell<DdsWords>,
    pulses: Cell<u32>,
    phase_clears: Cell<u32>,
    transactions: Cell<usize>,
    failures: Cell<usize>,
    spi_error: Cell<Span>,
}

impl DdsCapture {
    /// An AD9959 after a master reset (all words 0), at `sysclk_hz` (for the Hz
    /// accessors; use the driver's SYSCLK).
    pub const fn new(sysclk_hz: f64) -> Self {
        Self {
            sysclk_hz,
            csr: Cell::new(0xF0),
            fr1: Cell::new([0; 3]),
            fr2: Cell::new(0),
            buffered: Cell::new(DdsWords {
                ftw: [0; 4],
                asf: [0; 4],
                pow: [0; 4],
            }),
            active: Cell::new(DdsWords {
                ftw: [0; 4],
                asf: [0; 4],
                pow: [0; 4],
            }),
            pulses: Cell::new(0),
            phase_clears: Cell::new(0),
            transactions: Cell::new(0),
            failures: Cell::new(0),
            spi_error: Cell::new(Span::NEVER),
        }
    }

    /// The `SpiDevice` to hand to [`crate::Ad9959::new`].
    pub const fn spi(&self) -> CaptureDds<'_> {
        CaptureDds { cap: self }
    }

    /// The IO_UPDATE line: each pulse applies the buffers.
    pub const fn io_update(&self) -> CaptureIo<'_> {
        CaptureIo { cap: self }
    }

    /// SYSCLK the Hz accessors use.
    pub const fn sysclk_hz(&self) -> f64 {
        self.sysclk_hz
    }

    /// Fail the transactions (0-based, counted over the capture's life) in `span`.
    pub fn fail_transactions(&self, span: Span) {
        self.spi_error.set(span);
    }

    /// The words last written (I/O buffers, not yet applied if no pulse followed).
    pub fn buffered(&self) -> DdsWords {
        self.buffered.get()
    }

    /// The words the DDS runs (applied by the last IO_UPDATE).
    pub fn active(&self) -> DdsWords {
        self.active.get()
    }

    /// Pump frequency the DDS runs, Hz.
    pub fn active_pump_hz(&self) -> f64 {
        ad9959::hz_from_ftw(self.active().ftw_of(Channel::PUMP), self.sysclk_hz)
    }

    /// Pump voltage scale `(ASF/1023)²` the DDS runs.
    pub fn active_pump_scale(&self) -> f32 {
        self.active().asf_of(Channel::PUMP).scale()
    }

    /// Last pump frequency written (buffered), Hz.
    pub fn buffered_pump_hz(&self) -> f64 {
        ad9959::hz_from_ftw(self.buffered().ftw_of(Channel::PUMP), self.sysclk_hz)
    }

    /// Channel select register.
    pub fn csr(&self) -> u8 {
        self.csr.get()
    }

    /// Last FR1 written.
    pub fn fr1(&self) -> [u8; 3] {
        self.fr1.get()
    }

    /// Last FR2 written.
    pub fn fr2(&self) -> u16 {
        self.fr2.get()
    }

    /// IO_UPDATE pulses so far.
    pub fn pulses(&self) -> u32 {
        self.pulses.get()
    }

    /// Pulses that cleared all phase accumulators (FR2 auto-clear set).
    pub fn phase_clears(&self) -> u32 {
        self.phase_clears.get()
    }

    /// SPI transactions so far (failed ones included).
    pub fn transactions(&self) -> usize {
        self.transactions.get()
    }

    /// Transactions failed by the fault schedule.
    pub fn failures(&self) -> usize {
        self.failures.get()
    }

    /// IO_UPDATE: the buffers become active.
    pub fn pulse(&self) {
        self.active.set(self.buffered.get());
        self.pulses.set(self.pulses.get().saturating_add(1));
        if self.fr2.get() & ad9959::FR2_ALL_CHANNELS_AUTOCLEAR_PHASE != 0 {
            self.phase_clears
                .set(self.phase_clears.get().saturating_add(1));
        }
    }

    /// Apply `f` to the buffered words of every channel enabled in CSR.
    fn for_selected(&self, f: impl Fn(&mut DdsWords, usize)) {
        let csr = self.csr.get();
        let mut w = self.buffered.get();
        for ch in Channel::ALL {
            if csr & ch.csr_enable() != 0 {
                f(&mut w, DdsWords::channel(ch));
            }
        }
        self.buffered.set(w);
    }

    /// A complete register write (`data` as long as the register; shorter writes are
    /// ignored, as the serial port would wait for the rest).
    fn write(&self, addr: u8, data: &[u8]) {
        match (addr, data) {
            (0x00, &[csr]) => self.csr.set(csr),
            (0x01, &[a, b, c]) => self.fr1.set([a, b, c]),
            (0x02, &[a, b]) => self.fr2.set(u16::from_be_bytes([a, b])),
            (0x04, &[a, b, c, d]) => self.for_selected(|w, ch| {
                if let Some(s) = w.ftw.get_mut(ch) {
                    *s = u32::from_be_bytes([a, b, c, d]);
                }
            }),
            (0x05, &[a, b]) => self.for_selected(|w, ch| {
                if let Some(s) = w.pow.get_mut(ch) {
                    *s = u16::from_be_bytes([a, b]) & 0x3FFF;
                }
            }),
            (0x06, &[_, b, c]) => self.for_selected(|w, ch| {
                if let Some(s) = w.asf.get_mut(ch) {
                    *s = u16::from_be_bytes([b & 0x03, c]);
                }
            }),
            _ => {}
        }
    }

    /// The bytes a read of `addr` returns (the buffer of the lowest selected channel).
    fn read(&self, addr: u8) -> [u8; 4] {
        let csr = self.csr.get();
        let ch = Channel::ALL
            .into_iter()
            .find(|c| csr & c.csr_enable() != 0)
            .unwrap_or(Channel::Ch0);
        let w = self.buffered.get();
        match addr {
            0x00 => [csr, 0, 0, 0],
            0x01 => {
                let [a, b, c] = self.fr1.get();
                [a, b, c, 0]
            }
            0x02 => {
                let [a, b] = self.fr2.get().to_be_bytes();
                [a, b, 0, 0]
            }
            0x04 => w.ftw_of(ch).to_be_bytes(),
            0x05 => {
                let [a, b] = w
                    .pow
                    .get(DdsWords::channel(ch))
                    .copied()
                    .unwrap_or(0)
                    .to_be_bytes();
                [a, b, 0, 0]
            }
            0x06 => {
                let [a, b, c] = w.asf_of(ch).acr_bytes();
                [a, b, c, 0]
            }
            _ => [0; 4],
        }
    }
}

/// The [`SpiDevice`] side of a [`DdsCapture`]: an AD9959 serial port (instruction byte,
/// then the register bytes, one register per transaction).
#[derive(Clone, Copy, Debug)]
pub struct CaptureDds<'a> {
    cap: &'a DdsCapture,
}

impl CaptureDds<'_> {
    /// The shared record.
    pub const fn capture(&self) -> &DdsCapture {
        self.cap
    }
}

impl ErrorType for CaptureDds<'_> {
    type Error = ReplayError;
}

/// Per-transaction byte-stream state of the AD9959's serial port.
struct DdsStream {
    instruction: Option<u8>,
    data: [u8; 4],
    len: usize,
    read: [u8; 4],
    read_pos: usize,
}

impl DdsStream {
    fn byte(&mut self, cap: &DdsCapture, mosi: u8) -> u8 {
        match self.instruction {
            None => {
                self.instruction = Some(mosi);
                if mosi & 0x80 != 0 {
                    self.read = cap.read(mosi & 0x1F);
                }
                0
            }
            Some(i) if i & 0x80 != 0 => {
                let v = self.read.get(self.read_pos).copied().unwrap_or(0);
                self.read_pos = self.read_pos.saturating_add(1);
                v
            }
            Some(_) => {
                if let Some(slot) = self.data.get_mut(self.len) {
                    *slot = mosi;
                }
                self.len = self.len.saturating_add(1);
                0
            }
        }
    }
}

impl SpiDevice<u8> for CaptureDds<'_> {
    // never inlined: the instruction profile then tells the fake chip from the driver
    #[inline(never)]
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), ReplayError> {
        let cap = self.cap;
        let index = cap.transactions.get();
        cap.transactions.set(index.saturating_add(1));
        if cap.spi_error.get().contains(index) {
            cap.failures.set(cap.failures.get().saturating_add(1));
            return Err(ReplayError);
        }
        let mut s = DdsStream {
            instruction: None,
            data: [0; 4],
            len: 0,
            read: [0; 4],
            read_pos: 0,
        };
        for op in operations.iter_mut() {
            match op {
                Operation::Write(w) => {
                    for b in w.iter() {
                        s.byte(cap, *b);
                    }
                }
                Operation::Read(r) => {
                    for b in r.iter_mut() {
                        *b = s.byte(cap, 0);
                    }
                }
                Operation::TransferInPlace(buf) => {
                    for b in buf.iter_mut() {
                        *b = s.byte(cap, *b);
                    }
                }
                Operation::Transfer(r, w) => {
                    let n = r.len().max(w.len());
                    for i in 0..n {
                        let out = s.byte(cap, w.get(i).copied().unwrap_or(0));
                        if let Some(slot) = r.get_mut(i) {
                            *slot = out;
                        }
                    }
                }
                Operation::DelayNs(_) => {}
            }
        }
        if let Some(i) = s.instruction
            && i & 0x80 == 0
            && let Some(data) = s.data.get(..s.len)
        {
            cap.write(i & 0x1F, data);
        }
        Ok(())
    }
}

/// The IO_UPDATE line of a [`DdsCapture`].
#[derive(Clone, Copy, Debug)]
pub struct CaptureIo<'a> {
    cap: &'a DdsCapture,
}

impl IoUpdate for CaptureIo<'_> {
    fn pulse(&mut self) {
        self.cap.pulse();
    }
}

/// An IO_UPDATE line that does nothing (replay without a DDS model).
#[derive(Clone, Copy, Debug, Default)]
pub struct NoIoUpdate;

impl IoUpdate for NoIoUpdate {
    fn pulse(&mut self) {}
}
