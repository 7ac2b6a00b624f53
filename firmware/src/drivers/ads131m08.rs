//! TI ADS131M08: 8-channel, 24-bit, simultaneous-sampling ΔΣ ADC (one per gyro axis).
//!
//! # Design
//!
//! Each axis of the gyro has one ADS131M08 that samples the analog lock-in outputs of that
//! axis. Seven of its eight channels are used, in the order of [`channel`]: the DC level
//! `X0` and the real/imaginary parts of the 1st, 2nd and 3rd harmonics; channel 7 is spare.
//!
//! **Frames.** The ADS131M08 talks in frames of 24-bit words (the reset word length). A
//! frame on MOSI carries a 16-bit command (MSB-aligned in its 24-bit word), optional
//! command data, and the input CRC; on MISO it carries the *response to the previous
//! frame's command*, the eight channel codes and the output CRC: 10 words = 30 bytes.
//! Every exchange of this driver is one full 30-byte frame in one
//! [`SpiDevice::transaction`] (`transfer_in_place`), so chip select frames it exactly and
//! the device never sees a short frame. Commands whose answer matters (`RREG`, `WREG`,
//! `RESET`, `STANDBY`, `WAKEUP`) are followed by a `NULL` frame that fetches the answer, so
//! after every public method the device's pending response is the STATUS word again and
//! [`Ads131m08::read_frame`] can rely on it.
//!
//! **CRC.** The output CRC is a CRC-16 over every byte of the frame before the CRC word
//! (pad bytes included), seed `0xFFFF`; the driver selects the CCITT polynomial
//! `x^16 + x^12 + x^5 + 1` (`0x1021`, `MODE.CRC_TYPE = 0`), i.e. CRC-16/CCITT-FALSE with
//! no reflection and no final XOR ([`crc16_ccitt`]). The driver also sends an input CRC
//! after every command, so the MODE written by [`Mode::PARAGYRO`] can enable the
//! device's input CRC check (`RX_CRC_EN`): a command corrupted on MOSI is then not
//! executed (except `WREG`, which the device executes anyway; the driver therefore checks
//! the `WREG` acknowledgement). Every received frame is CRC-checked, except the one
//! clocked out while sending `RESET` (its content predates the reset and is discarded).
//!
//! **Codes.** Channel codes are 24-bit two's complement, `+FS = 0x7FFFFF`,
//! `-FS = 0x800000`; the ADC clips there, so a code at either value is reported as
//! saturated ([`RawCode::is_saturated`]). Codes stay raw ([`RawCode`]) until they reach
//! the single conversion point, [`LockinCalibration`].
//!
//! **Data rate.** `f_DATA = f_CLKIN / 2 / OSR`. With the nominal 8.192 MHz CLKIN of
//! high-resolution mode, [`Osr::R8192`] gives exactly the estimator's 500 Hz
//! ([`Clock::PARAGYRO`]); with any other CLKIN the rate is `f_CLKIN / (2·OSR)`
//! ([`Clock::data_rate_hz`]) and the board must be clocked accordingly.
//!
//! # Example
//!
//! Reading one frame (here from `embedded-hal-mock`, with a frame built by
//! [`Frame::encode`]) and converting it to micrometres:
//!
//! ```
//! use embedded_hal_mock::eh1::spi::{Mock, Transaction as T};
//! use paragyro_firmware::drivers::ads131m08::{self, Ads131m08, Frame, LockinCalibration, RawCode};
//!
//! let sent = Frame { response: 0x01FF, codes: [RawCode::from_u24(0x00_1000); 8] };
//! let spi = Mock::new(&[
//!     T::transaction_start(),
//!     T::transfer_in_place(ads131m08::command_frame(&[ads131m08::opcode::NULL]).to_vec(), sent.encode().to_vec()),
//!     T::transaction_end(),
//! ]);
//! let mut adc = Ads131m08::new(spi);
//! let frame = adc.read_frame().unwrap();
//! assert!(!frame.lockin_saturated());
//! let um = LockinCalibration::UNITY.frame_to_um(&frame);
//! assert_eq!(um.x0_um, 4096.0);
//! adc.destroy().done();
//!
//! assert_eq!(ads131m08::crc16_ccitt(b"123456789"), 0x29B1);
//! assert_eq!(RawCode::from_u24(0xFF_FFFF).get(), -1);
//! ```

use embedded_hal::delay::DelayNs;
use embedded_hal::spi::SpiDevice;

/// Number of ADC channels (and channel words in a frame).
pub const CHANNELS: usize = 8;
/// Number of channels carrying lock-in outputs (channel 7 is spare).
pub const LOCKIN_CHANNELS: usize = 7;
/// Bytes per frame word (24-bit word length, the reset default).
pub const WORD_BYTES: usize = 3;
/// Words per frame: response/STATUS + 8 channels + CRC.
pub const FRAME_WORDS: usize = CHANNELS + 2;
/// Bytes per frame.
pub const FRAME_BYTES: usize = FRAME_WORDS * WORD_BYTES;
/// Response word that acknowledges a `RESET` of an ADS131M08 (`0xFF20 | CHANCNT`).
pub const RESET_ACK: u16 = 0xFF28;
/// Upper byte of the ADS131M08 ID register (`0x28xx`: reserved `0x2`, `CHANCNT = 8`).
pub const ID_UPPER_BYTE: u8 = 0x28;
/// Seed of the frame CRC.
pub const CRC_SEED: u16 = 0xFFFF;
/// CRC-16-CCITT polynomial `x^16 + x^12 + x^5 + 1`, top bit implied.
pub const CRC_CCITT_POLY: u16 = 0x1021;
/// Time the driver waits after the `RESET` frame before talking again, in µs (TI's
/// example code waits 1 ms; generous against the datasheet's register-acquisition time).
pub const RESET_WAIT_US: u32 = 1_000;

/// Channel index of each lock-in quantity (the board's wiring).
pub mod channel {
    /// DC level `X0`.
    pub const X0: usize = 0;
    /// 1st harmonic, real part.
    pub const A1_RE: usize = 1;
    /// 1st harmonic, imaginary part.
    pub const A1_IM: usize = 2;
    /// 2nd harmonic, real part.
    pub const A2_RE: usize = 3;
    /// 2nd harmonic, imaginary part.
    pub const A2_IM: usize = 4;
    /// 3rd harmonic, real part.
    pub const A3_RE: usize = 5;
    /// 3rd harmonic, imaginary part.
    pub const A3_IM: usize = 6;
    /// Unused channel.
    pub const SPARE: usize = 7;
}

/// SPI command words (datasheet command table; the response appears in the next frame).
pub mod opcode {
    use super::Register;

    /// No operation; the response is the STATUS register.
    pub const NULL: u16 = 0x0000;
    /// Reset the device; acknowledged by [`super::RESET_ACK`].
    pub const RESET: u16 = 0x0011;
    /// Enter standby; echoed.
    pub const STANDBY: u16 = 0x0022;
    /// Leave standby; echoed.
    pub const WAKEUP: u16 = 0x0033;
    /// Lock the interface; echoed.
    pub const LOCK: u16 = 0x0555;
    /// Unlock the interface; echoed.
    pub const UNLOCK: u16 = 0x0655;

    /// `RREG` of one register: `101a aaaa a000 0000`.
    pub const fn rreg(reg: Register) -> u16 {
        0xA000 | ((reg.addr() as u16 & 0x3F) << 7)
    }

    /// `WREG` of one register: `011a aaaa a000 0000`.
    pub const fn wreg(reg: Register) -> u16 {
        0x6000 | ((reg.addr() as u16 & 0x3F) << 7)
    }

    /// Acknowledgement of a one-register `WREG`: `010a aaaa a000 0000`.
    pub const fn wreg_ack(reg: Register) -> u16 {
        0x4000 | ((reg.addr() as u16 & 0x3F) << 7)
    }
}

/// Errors of the ADS131M08 driver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<E> {
    /// The SPI device failed.
    Spi(E),
    /// A received frame failed its CRC: `expected` is the CRC computed over the received
    /// bytes, `got` the CRC word the device sent.
    Crc {
        /// CRC computed over the received frame.
        expected: u16,
        /// CRC word received.
        got: u16,
    },
    /// The ID register does not read `0x28xx`.
    BadId(u16),
    /// The device did not answer as expected: a command was not acknowledged (`RESET`,
    /// `STANDBY`, `WAKEUP`, `WREG`), a verified register write read back a different
    /// value, or a data frame's DRDY flags of the lock-in channels are not all set.
    NotReady,
}

/// A CRC mismatch found by [`Frame::decode`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CrcError {
    /// CRC computed over the received frame.
    pub expected: u16,
    /// CRC word received.
    pub got: u16,
}

impl<E> From<CrcError> for Error<E> {
    fn from(e: CrcError) -> Self {
        Error::Crc {
            expected: e.expected,
            got: e.got,
        }
    }
}

/// CRC-16-CCITT of every byte value (the bitwise algorithm, run at compile time): the
/// tick checks two 30-byte frames, and a table step is about ten times cheaper than
/// eight shift-and-xor rounds.
#[allow(clippy::indexing_slicing)] // compile-time evaluation: an out-of-bounds index fails the build
const CRC_TABLE: [u16; 256] = {
    let mut t = [0u16; 256];
    let mut i = 0usize;
    while i < 256 {
        let mut crc = (i as u16) << 8;
        let mut b = 0;
        while b < 8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ CRC_CCITT_POLY
            } else {
                crc << 1
            };
            b += 1;
        }
        t[i] = crc;
        i += 1;
    }
    t
};

/// Continue a CRC-16-CCITT (poly `0x1021`, MSB first, no reflection, no final XOR)
/// over `data`, starting from `crc` (table driven).
pub fn crc16_ccitt_update(mut crc: u16, data: &[u8]) -> u16 {
    for &byte in data {
        crc = crc16_ccitt_byte(crc, byte);
    }
    crc
}

/// One byte of the table-driven CRC-16-CCITT.
#[inline(always)]
fn crc16_ccitt_byte(crc: u16, byte: u8) -> u16 {
    let idx = usize::from(((crc >> 8) as u8) ^ byte);
    (crc << 8) ^ CRC_TABLE.get(idx).copied().unwrap_or(0)
}

/// The bitwise CRC-16-CCITT, kept as the reference the table is checked against.
#[cfg(test)]
fn crc16_ccitt_update_bitwise(mut crc: u16, data: &[u8]) -> u16 {
    for &byte in data {
        crc ^= u16::from(byte) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ CRC_CCITT_POLY
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// CRC-16-CCITT of `data` with the ADS131M08 seed `0xFFFF` (= CRC-16/CCITT-FALSE;
/// check value `crc16_ccitt(b"123456789") == 0x29B1`).
pub fn crc16_ccitt(data: &[u8]) -> u16 {
    crc16_ccitt_update(CRC_SEED, data)
}

/// ADS131M08 registers used by the driver (addresses from the register map).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Register {
    /// `ID`, read-only, `0x28xx`.
    Id = 0x00,
    /// `STATUS`, read-only.
    Status = 0x01,
    /// `MODE`: CRC, word length, SPI timeout, DRDY.
    Mode = 0x02,
    /// `CLOCK`: channel enables, oscillator, reference, OSR, power mode.
    Clock = 0x03,
    /// `GAIN1`: PGA gains of channels 0-3.
    Gain1 = 0x04,
    /// `GAIN2`: PGA gains of channels 4-7.
    Gain2 = 0x05,
    /// `CFG`: global chop, current detection.
    Cfg = 0x06,
}

impl Register {
    /// Register address.
    pub const fn addr(self) -> u8 {
        self as u8
    }
}

/// The STATUS register (also the response word of a `NULL` frame).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status(pub u16);

impl Status {
    /// Interface locked.
    pub const fn locked(self) -> bool {
        self.0 & 0x8000 != 0
    }
    /// ADC resynchronization occurred.
    pub const fn f_resync(self) -> bool {
        self.0 & 0x4000 != 0
    }
    /// Register-map CRC fault.
    pub const fn reg_map_fault(self) -> bool {
        self.0 & 0x2000 != 0
    }
    /// The input CRC of a previous command failed.
    pub const fn crc_error(self) -> bool {
        self.0 & 0x1000 != 0
    }
    /// CRC type: `false` CCITT, `true` ANSI.
    pub const fn crc_type_ansi(self) -> bool {
        self.0 & 0x0800 != 0
    }
    /// The device was reset and the flag not yet cleared (by writing MODE).
    pub const fn reset_flag(self) -> bool {
        self.0 & 0x0400 != 0
    }
    /// Word-length code (`0b01` = 24 bits).
    pub const fn word_length(self) -> u8 {
        ((self.0 >> 8) & 0x3) as u8
    }
    /// Data-ready flags, bit `n` for channel `n`.
    pub const fn drdy(self) -> u8 {
        (self.0 & 0xFF) as u8
    }
    /// All seven lock-in channels have new data.
    pub const fn lockin_ready(self) -> bool {
        self.0 & 0x7F == 0x7F
    }
}

/// MODE register content. CRC type (CCITT) and word length (24 bits) are fixed by the
/// driver; DRDY is left at its reset behaviour (most lagging channel, active low level).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Mode {
    /// `REGCRC_EN`: register-map CRC.
    pub regmap_crc: bool,
    /// `RX_CRC_EN`: the device checks the input CRC the driver always sends.
    pub rx_crc: bool,
    /// `TIMEOUT`: SPI frame timeout (reset default on).
    pub spi_timeout: bool,
}

impl Mode {
    /// The project's MODE: input CRC on, SPI timeout on, register-map CRC off:
    /// `0x1110`. Writing it also clears the STATUS `RESET` flag.
    pub const PARAGYRO: Mode = Mode {
        regmap_crc: false,
        rx_crc: true,
        spi_timeout: true,
    };

    /// Register bits: `REGCRC_EN[13] RX_CRC_EN[12] CRC_TYPE[11]=0 RESET[10]=0
    /// WLENGTH[9:8]=01 TIMEOUT[4] DRDY_SEL[3:2]=00 DRDY_HiZ[1]=0 DRDY_FMT[0]=0`.
    pub const fn bits(self) -> u16 {
        (self.regmap_crc as u16) << 13
            | (self.rx_crc as u16) << 12
            | 0x0100
            | (self.spi_timeout as u16) << 4
    }
}

/// Oversampling ratio (`CLOCK.OSR[2:0]`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Osr {
    /// OSR 128.
    R128 = 0,
    /// OSR 256.
    R256 = 1,
    /// OSR 512.
    R512 = 2,
    /// OSR 1024 (reset default).
    R1024 = 3,
    /// OSR 2048.
    R2048 = 4,
    /// OSR 4096.
    R4096 = 5,
    /// OSR 8192: 500 SPS at CLKIN = 8.192 MHz.
    R8192 = 6,
    /// OSR 16256.
    R16256 = 7,
}

impl Osr {
    /// The oversampling ratio.
    pub const fn ratio(self) -> u32 {
        match self {
            Osr::R128 => 128,
            Osr::R256 => 256,
            Osr::R512 => 512,
            Osr::R1024 => 1024,
            Osr::R2048 => 2048,
            Osr::R4096 => 4096,
            Osr::R8192 => 8192,
            Osr::R16256 => 16256,
        }
    }
}

/// Power mode (`CLOCK.PWR[1:0]`); the CLKIN frequency must suit the mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum PowerMode {
    /// Very-low-power.
    VeryLowPower = 0,
    /// Low-power.
    LowPower = 1,
    /// High-resolution (reset default; nominal CLKIN 8.192 MHz).
    HighResolution = 2,
}

/// CLOCK register content.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Clock {
    /// `CHn_EN`, bit `n` enables channel `n`.
    pub channel_enable: u8,
    /// `XTAL_DIS`: crystal oscillator off (CLKIN driven by an external clock).
    pub xtal_disabled: bool,
    /// `EXTREF_EN`: external reference instead of the internal 1.2 V.
    pub external_reference: bool,
    /// Oversampling ratio.
    pub osr: Osr,
    /// Power mode.
    pub power: PowerMode,
}

impl Clock {
    /// The project's CLOCK: all channels on (the spare one too, so every frame has the
    /// same shape), CLKIN from an external 8.192 MHz clock (crystal oscillator off),
    /// internal reference, OSR 8192, high resolution: 500 SPS. `0xFF9A`.
    pub const PARAGYRO: Clock = Clock {
        channel_enable: 0xFF,
        xtal_disabled: true,
        external_reference: false,
        osr: Osr::R8192,
        power: PowerMode::HighResolution,
    };

    /// Register bits: `CHn_EN[15:8] XTAL_DIS[7] EXTREF_EN[6] OSR[4:2] PWR[1:0]`.
    pub const fn bits(self) -> u16 {
        (self.channel_enable as u16) << 8
            | (self.xtal_disabled as u16) << 7
            | (self.external_reference as u16) << 6
            | (self.osr as u16) << 2
            | self.power as u16
    }

    /// Output data rate for a given CLKIN frequency: `f_CLKIN / 2 / OSR`.
    pub fn data_rate_hz(self, f_clkin_hz: f32) -> f32 {
        f_clkin_hz / 2.0 / self.osr.ratio() as f32
    }
}

/// PGA gain (`PGAGAINn[2:0]`); the full-scale range is `±1.2 V / gain`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Gain {
    /// Gain 1 (reset default), FSR ±1.2 V.
    G1 = 0,
    /// Gain 2.
    G2 = 1,
    /// Gain 4.
    G4 = 2,
    /// Gain 8.
    G8 = 3,
    /// Gain 16.
    G16 = 4,
    /// Gain 32.
    G32 = 5,
    /// Gain 64.
    G64 = 6,
    /// Gain 128.
    G128 = 7,
}

impl Gain {
    /// The gain factor.
    pub const fn factor(self) -> u32 {
        1 << (self as u32)
    }

    /// Volts per code with the internal 1.2 V reference: `1.2 / gain / 2^23`.
    pub fn volts_per_code(self) -> f32 {
        1.2 / self.factor() as f32 / 8_388_608.0
    }

    /// `GAIN1`/`GAIN2` register bits for four channels (`gains[0]` in bits 2:0).
    pub const fn register_bits(gains: [Gain; 4]) -> u16 {
        let [a, b, c, d] = gains;
        (a as u16) | (b as u16) << 4 | (c as u16) << 8 | (d as u16) << 12
    }
}

/// Everything [`Ads131m08::init`] writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// MODE register.
    pub mode: Mode,
    /// CLOCK register.
    pub clock: Clock,
    /// PGA gain per channel.
    pub gains: [Gain; CHANNELS],
}

impl Config {
    /// [`Mode::PARAGYRO`], [`Clock::PARAGYRO`], all gains 1.
    pub const PARAGYRO: Config = Config {
        mode: Mode::PARAGYRO,
        clock: Clock::PARAGYRO,
        gains: [Gain::G1; CHANNELS],
    };
}

/// A raw ADC code: 24-bit two's complement, sign-extended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RawCode(i32);

impl RawCode {
    /// Positive full scale, `0x7FFFFF`: the ADC clips here.
    pub const POSITIVE_FULL_SCALE: RawCode = RawCode(0x7F_FFFF);
    /// Negative full scale, `0x800000`: the ADC clips here.
    pub const NEGATIVE_FULL_SCALE: RawCode = RawCode(-0x80_0000);

    /// Sign-extend the low 24 bits of `raw` (upper bits ignored).
    pub const fn from_u24(raw: u32) -> Self {
        RawCode(((raw << 8) as i32) >> 8)
    }

    /// From the three bytes of a frame word, MSB first.
    pub const fn from_be_bytes(bytes: [u8; 3]) -> Self {
        let [a, b, c] = bytes;
        Self::from_u24((a as u32) << 16 | (b as u32) << 8 | c as u32)
    }

    /// A code from its value, clamped to the 24-bit range.
    pub const fn saturating_new(value: i32) -> Self {
        if value > Self::POSITIVE_FULL_SCALE.0 {
            Self::POSITIVE_FULL_SCALE
        } else if value < Self::NEGATIVE_FULL_SCALE.0 {
            Self::NEGATIVE_FULL_SCALE
        } else {
            RawCode(value)
        }
    }

    /// The three bytes of a frame word, MSB first.
    pub const fn to_be_bytes(self) -> [u8; 3] {
        let [_, a, b, c] = self.0.to_be_bytes();
        [a, b, c]
    }

    /// The signed code.
    pub const fn get(self) -> i32 {
        self.0
    }

    /// At positive or negative full scale (the ADC output clips there).
    pub const fn is_saturated(self) -> bool {
        self.0 == Self::POSITIVE_FULL_SCALE.0 || self.0 == Self::NEGATIVE_FULL_SCALE.0
    }
}

/// One decoded frame: the response word (STATUS for a data frame) and eight codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Frame {
    /// First word of the frame: the response to the previous frame's command.
    pub response: u16,
    /// Channel codes.
    pub codes: [RawCode; CHANNELS],
}

fn word_bytes(word: u16) -> [u8; 3] {
    let [hi, lo] = word.to_be_bytes();
    [hi, lo, 0]
}

impl Frame {
    /// The response word read as STATUS.
    pub const fn status(&self) -> Status {
        Status(self.response)
    }

    /// Codes of the seven lock-in channels, in [`channel`] order.
    pub fn lockin_codes(&self) -> [RawCode; LOCKIN_CHANNELS] {
        let mut out = [RawCode::default(); LOCKIN_CHANNELS];
        for (o, c) in out.iter_mut().zip(self.codes.iter()) {
            *o = *c;
        }
        out
    }

    /// Bit `n` set when channel `n` is at full scale.
    pub fn saturated_mask(&self) -> u8 {
        self.codes
            .iter()
            .enumerate()
            .filter(|(_, c)| c.is_saturated())
            .fold(0u8, |m, (i, _)| m | 1u8.checked_shl(i as u32).unwrap_or(0))
    }

    /// Any lock-in channel (0-6) at full scale (= `saturated_mask() & 0x7F != 0`, written
    /// out without branches).
    pub fn lockin_saturated(&self) -> bool {
        let [c0, c1, c2, c3, c4, c5, c6, _] = self.codes;
        c0.is_saturated()
            | c1.is_saturated()
            | c2.is_saturated()
            | c3.is_saturated()
            | c4.is_saturated()
            | c5.is_saturated()
            | c6.is_saturated()
    }

    /// Decode 30 received bytes, checking the output CRC.
    pub fn decode(bytes: &[u8; FRAME_BYTES]) -> Result<Frame, CrcError> {
        // the 27 CRC'd bytes through the table in order, a word (three bytes) per loop
        // step; the codes straight from their bytes (no per-word match, no zeroed frame)
        let (words, _) = bytes.as_chunks::<WORD_BYTES>();
        let (words, _) = words.split_at(FRAME_WORDS_MINUS_ONE);
        let mut crc = u32::from(CRC_SEED);
        let step = |crc: u32, b: u8| {
            (crc << 8)
                ^ u32::from(
                    CRC_TABLE
                        .get(usize::from((crc >> 8) as u8 ^ b))
                        .copied()
                        .unwrap_or(0),
                )
        };
        for &[x, y, z] in words {
            crc = step(step(step(crc, x), y), z);
        }
        let crc = crc as u16;
        #[rustfmt::skip]
        let [
            r0, r1, _, a0, a1, a2, b0, b1, b2, c0, c1, c2, d0, d1, d2, e0, e1, e2, f0, f1, f2,
            g0, g1, g2, h0, h1, h2, k0, k1, _,
        ] = *bytes;
        let got = u16::from_be_bytes([k0, k1]);
        if crc != got {
            return Err(CrcError { expected: crc, got });
        }
        let code = RawCode::from_be_bytes;
        Ok(Frame {
            response: u16::from_be_bytes([r0, r1]),
            codes: [
                code([a0, a1, a2]),
                code([b0, b1, b2]),
                code([c0, c1, c2]),
                code([d0, d1, d2]),
                code([e0, e1, e2]),
                code([f0, f1, f2]),
                code([g0, g1, g2]),
                code([h0, h1, h2]),
            ],
        })
    }

    /// Encode as the device would send it, with a valid CRC (tests, simulation).
    pub fn encode(&self) -> [u8; FRAME_BYTES] {
        let mut bytes = [0u8; FRAME_BYTES];
        let (words, _) = bytes.as_chunks_mut::<WORD_BYTES>();
        let mut crc = CRC_SEED;
        for (i, w) in words.iter_mut().enumerate() {
            *w = match i {
                0 => word_bytes(self.response),
                FRAME_WORDS_MINUS_ONE => word_bytes(crc),
                _ => self
                    .codes
                    .get(i.wrapping_sub(1))
                    .map_or([0; 3], |c| c.to_be_bytes()),
            };
            crc = crc16_ccitt_update(crc, w);
        }
        bytes
    }
}

const FRAME_WORDS_MINUS_ONE: usize = FRAME_WORDS - 1;

/// The bytes the driver clocks out for a frame carrying `words` (command and data), the
/// input CRC and zero padding. Public so that tests and simulations can predict MOSI.
pub fn command_frame(words: &[u16]) -> [u8; FRAME_BYTES] {
    let mut bytes = [0u8; FRAME_BYTES];
    let (slots, _) = bytes.as_chunks_mut::<WORD_BYTES>();
    let mut slots = slots.iter_mut();
    let mut crc = CRC_SEED;
    // `words` first: `zip` stops on it without consuming an extra slot.
    for (&w, slot) in words.iter().zip(slots.by_ref()) {
        *slot = word_bytes(w);
        crc = crc16_ccitt_update(crc, slot);
    }
    if let Some(slot) = slots.next() {
        *slot = word_bytes(crc);
    }
    bytes
}

/// One CRC-16-CCITT step (bitwise, for constants).
const fn crc16_ccitt_byte_const(crc: u16, byte: u8) -> u16 {
    let mut crc = crc ^ ((byte as u16) << 8);
    let mut i = 0u8;
    while i < 8 {
        crc = if crc & 0x8000 != 0 {
            (crc << 1) ^ CRC_CCITT_POLY
        } else {
            crc << 1
        };
        i = i.wrapping_add(1);
    }
    crc
}

/// The `NULL` command frame ([`command_frame`]`(&[opcode::NULL])`), precomputed: the
/// frame every data read sends, so the tick path builds no frame and computes no CRC.
pub const NULL_FRAME: [u8; FRAME_BYTES] = {
    let [hi, lo] = opcode::NULL.to_be_bytes();
    let crc = crc16_ccitt_byte_const(
        crc16_ccitt_byte_const(crc16_ccitt_byte_const(CRC_SEED, hi), lo),
        0,
    );
    let [c_hi, c_lo] = crc.to_be_bytes();
    let mut f = [0u8; FRAME_BYTES];
    f[0] = hi;
    f[1] = lo;
    f[3] = c_hi;
    f[4] = c_lo;
    f
};

/// Lock-in outputs of one axis in µm.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LockinUm {
    /// DC level `X0`, µm.
    pub x0_um: f32,
    /// Real parts of harmonics 1, 2, 3, µm.
    pub re_um: [f32; 3],
    /// Imaginary parts of harmonics 1, 2, 3, µm.
    pub im_um: [f32; 3],
}

/// The one place where ADC codes become micrometres, per axis.
///
/// For lock-in channel `i` (in [`channel`] order: X0, A1re, A1im, A2re, A2im, A3re, A3im)
/// `value_um[i] = (code[i] − offset_code[i]) · um_per_code[i]`.
/// `um_per_code` folds together the ADC scale (`1.2 V / gain / 2^23`, see
/// [`LockinCalibration::from_um_per_volt`]), the lock-in output gain and the pick-off
/// transduction; `offset_code` is the code read with zero motion.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LockinCalibration {
    /// Scale of each lock-in channel, µm per code.
    pub um_per_code: [f32; LOCKIN_CHANNELS],
    /// Zero-motion code of each lock-in channel.
    pub offset_code: [i32; LOCKIN_CHANNELS],
}

impl LockinCalibration {
    /// One µm per code, no offset (placeholder before calibration).
    pub const UNITY: LockinCalibration = LockinCalibration {
        um_per_code: [1.0; LOCKIN_CHANNELS],
        offset_code: [0; LOCKIN_CHANNELS],
    };

    /// From the analog scale in µm per volt at the ADC input and the PGA gain of each
    /// channel (internal 1.2 V reference).
    pub fn from_um_per_volt(
        um_per_volt: [f32; LOCKIN_CHANNELS],
        gains: [Gain; LOCKIN_CHANNELS],
        offset_code: [i32; LOCKIN_CHANNELS],
    ) -> Self {
        let mut um_per_code = [0.0; LOCKIN_CHANNELS];
        for ((o, s), g) in um_per_code.iter_mut().zip(um_per_volt).zip(gains) {
            *o = s * g.volts_per_code();
        }
        Self {
            um_per_code,
            offset_code,
        }
    }

    /// Convert the seven lock-in codes to µm.
    pub fn to_um(&self, codes: &[RawCode; LOCKIN_CHANNELS]) -> LockinUm {
        let mut v = [0.0f32; LOCKIN_CHANNELS];
        for (((o, c), s), off) in v
            .iter_mut()
            .zip(codes.iter())
            .zip(self.um_per_code.iter())
            .zip(self.offset_code.iter())
        {
            // A code is 24-bit, so the difference with any sane offset fits an i32; it
            // saturates (rather than wraps) for an absurd one. i32 → f32 is one VCVT,
            // where i64 → f32 would be a library call on the tick path.
            *o = c.get().saturating_sub(*off) as f32 * s;
        }
        let [x0, a1r, a1i, a2r, a2i, a3r, a3i] = v;
        LockinUm {
            x0_um: x0,
            re_um: [a1r, a2r, a3r],
            im_um: [a1i, a2i, a3i],
        }
    }

    /// The lock-in channels of a frame in µm, in code order (`x0, re1, im1, re2, im2, re3,
    /// im3`), written out: the same values as [`LockinCalibration::to_um`] without the
    /// loop and the intermediate copies (the tick path).
    #[inline]
    pub fn channels_um(&self, frame: &Frame) -> [f32; LOCKIN_CHANNELS] {
        let [c0, c1, c2, c3, c4, c5, c6, _] = frame.codes;
        let [s0, s1, s2, s3, s4, s5, s6] = self.um_per_code;
        let [o0, o1, o2, o3, o4, o5, o6] = self.offset_code;
        let f = |c: RawCode, o: i32, s: f32| c.get().saturating_sub(o) as f32 * s;
        [
            f(c0, o0, s0),
            f(c1, o1, s1),
            f(c2, o2, s2),
            f(c3, o3, s3),
            f(c4, o4, s4),
            f(c5, o5, s5),
            f(c6, o6, s6),
        ]
    }

    /// Convert the lock-in channels of a frame to µm.
    pub fn frame_to_um(&self, frame: &Frame) -> LockinUm {
        self.to_um(&frame.lockin_codes())
    }
}

/// ADS131M08 driver over an [`SpiDevice`] (24-bit words, CCITT CRC; SPI mode 1).
#[derive(Debug)]
pub struct Ads131m08<SPI> {
    spi: SPI,
}

impl<SPI: SpiDevice> Ads131m08<SPI> {
    /// Wrap an SPI device; no bus traffic.
    pub const fn new(spi: SPI) -> Self {
        Self { spi }
    }

    /// Give the SPI device back.
    pub fn destroy(self) -> SPI {
        self.spi
    }

    /// One full frame carrying `words`; returns the raw received bytes.
    fn exchange(&mut self, words: &[u16]) -> Result<[u8; FRAME_BYTES], Error<SPI::Error>> {
        let mut buf = command_frame(words);
        self.spi.transfer_in_place(&mut buf).map_err(Error::Spi)?;
        Ok(buf)
    }

    /// One full frame carrying `words`; returns the CRC-checked received frame.
    fn exchange_checked(&mut self, words: &[u16]) -> Result<Frame, Error<SPI::Error>> {
        // decoded where it was received (no copy of the frame through a `Result`)
        let mut buf = command_frame(words);
        self.spi.transfer_in_place(&mut buf).map_err(Error::Spi)?;
        Ok(Frame::decode(&buf)?)
    }

    /// A command frame followed by a `NULL` frame; returns the command's response word.
    fn command(&mut self, words: &[u16]) -> Result<u16, Error<SPI::Error>> {
        self.exchange_checked(words)?;
        Ok(self.exchange_checked(&[opcode::NULL])?.response)
    }

    /// Software reset: a `RESET` frame (its received content is ignored), a wait of
    /// [`RESET_WAIT_US`], then a `NULL` frame that must answer [`RESET_ACK`].
    /// Afterwards all registers hold their reset values (24-bit words, CCITT CRC).
    pub fn reset<D: DelayNs>(&mut self, delay: &mut D) -> Result<(), Error<SPI::Error>> {
        self.exchange(&[opcode::RESET])?;
        delay.delay_us(RESET_WAIT_US);
        match self.exchange_checked(&[opcode::NULL])?.response {
            RESET_ACK => Ok(()),
            _ => Err(Error::NotReady),
        }
    }

    /// Enter standby (conversions stop); must be echoed.
    pub fn standby(&mut self) -> Result<(), Error<SPI::Error>> {
        match self.command(&[opcode::STANDBY])? {
            opcode::STANDBY => Ok(()),
            _ => Err(Error::NotReady),
        }
    }

    /// Leave standby (conversions restart); must be echoed.
    pub fn wakeup(&mut self) -> Result<(), Error<SPI::Error>> {
        match self.command(&[opcode::WAKEUP])? {
            opcode::WAKEUP => Ok(()),
            _ => Err(Error::NotReady),
        }
    }

    /// Read one register (`RREG` frame, then a `NULL` frame carrying the value).
    pub fn read_register(&mut self, reg: Register) -> Result<u16, Error<SPI::Error>> {
        self.command(&[opcode::rreg(reg)])
    }

    /// Write one register (`WREG` frame with the value, then a `NULL` frame that must
    /// carry the `WREG` acknowledgement).
    pub fn write_register(&mut self, reg: Register, value: u16) -> Result<(), Error<SPI::Error>> {
        if self.command(&[opcode::wreg(reg), value])? == opcode::wreg_ack(reg) {
            Ok(())
        } else {
            Err(Error::NotReady)
        }
    }

    /// Read the ID register and check it is an ADS131M08 (`0x28xx`); returns the ID.
    pub fn check_id(&mut self) -> Result<u16, Error<SPI::Error>> {
        let id = self.read_register(Register::Id)?;
        match id.to_be_bytes() {
            [ID_UPPER_BYTE, _] => Ok(id),
            _ => Err(Error::BadId(id)),
        }
    }

    /// Write one register and read it back (4 frames). The device executes a `WREG` even
    /// when its input CRC fails and the acknowledgement covers only the command word, so
    /// configuration writes are verified: a mismatch gives [`Error::NotReady`].
    pub fn write_register_verified(
        &mut self,
        reg: Register,
        value: u16,
    ) -> Result<(), Error<SPI::Error>> {
        self.write_register(reg, value)?;
        if self.read_register(reg)? == value {
            Ok(())
        } else {
            Err(Error::NotReady)
        }
    }

    /// Write and verify the MODE register.
    pub fn set_mode(&mut self, mode: Mode) -> Result<(), Error<SPI::Error>> {
        self.write_register_verified(Register::Mode, mode.bits())
    }

    /// Write and verify the CLOCK register.
    pub fn set_clock(&mut self, clock: Clock) -> Result<(), Error<SPI::Error>> {
        self.write_register_verified(Register::Clock, clock.bits())
    }

    /// Write and verify GAIN1 and GAIN2.
    pub fn set_gains(&mut self, gains: [Gain; CHANNELS]) -> Result<(), Error<SPI::Error>> {
        let [g0, g1, g2, g3, g4, g5, g6, g7] = gains;
        self.write_register_verified(Register::Gain1, Gain::register_bits([g0, g1, g2, g3]))?;
        self.write_register_verified(Register::Gain2, Gain::register_bits([g4, g5, g6, g7]))
    }

    /// Reset, check the ID, then write MODE, GAIN1/2 and CLOCK (in that order: the input
    /// CRC is checked from the MODE write on, conversions restart with the new OSR last).
    /// Returns the ID register.
    pub fn init<D: DelayNs>(
        &mut self,
        delay: &mut D,
        config: &Config,
    ) -> Result<u16, Error<SPI::Error>> {
        self.reset(delay)?;
        let id = self.check_id()?;
        self.set_mode(config.mode)?;
        self.set_gains(config.gains)?;
        self.set_clock(config.clock)?;
        Ok(id)
    }

    /// Read one data frame (STATUS + 8 channels + CRC) in one transaction, sending `NULL`.
    /// Call it after DRDY asserts. Fails with [`Error::Crc`] on a corrupted frame and
    /// with [`Error::NotReady`] when the DRDY flags of the lock-in channels are not all set.
    pub fn read_frame(&mut self) -> Result<Frame, Error<SPI::Error>> {
        let mut buf = NULL_FRAME;
        self.spi.transfer_in_place(&mut buf).map_err(Error::Spi)?;
        let frame = Frame::decode(&buf)?;
        if frame.status().lockin_ready() {
            Ok(frame)
        } else {
            Err(Error::NotReady)
        }
    }
}

#[cfg(test)]
mod tests {
    /// The former loop form of [`Frame::decode`] (the reference of its test).
    fn decode_loop(bytes: &[u8; FRAME_BYTES]) -> Result<Frame, CrcError> {
        use super::*;

        let (words, _) = bytes.as_chunks::<WORD_BYTES>();
        let mut crc = CRC_SEED;
        let mut frame = Frame::default();
        let mut got = 0u16;
        for (i, w) in words.iter().enumerate() {
            let [a, b, _] = *w;
            match i {
                0 => frame.response = u16::from_be_bytes([a, b]),
                FRAME_WORDS_MINUS_ONE => {
                    got = u16::from_be_bytes([a, b]);
                    continue;
                }
                _ => {
                    if let Some(slot) = frame.codes.get_mut(i.wrapping_sub(1)) {
                        *slot = RawCode::from_be_bytes(*w);
                    }
                }
            }
            crc = crc16_ccitt_update(crc, w);
        }
        if crc == got {
            Ok(frame)
        } else {
            Err(CrcError { expected: crc, got })
        }
    }

    #[test]
    fn channels_um_and_lockin_saturated_equal_their_loop_forms() {
        use super::*;
        let cal = LockinCalibration {
            um_per_code: [0.5, -1.25, 3.0e-3, 7.0, 1.0, 2.5e-6, -0.75],
            offset_code: [0, 100, -100, i32::MAX, i32::MIN, 12345, -7],
        };
        let mut x = 0x2545_F491u32;
        for n in 0..20_000u32 {
            let mut codes = [RawCode::default(); CHANNELS];
            for c in codes.iter_mut() {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                *c = match x % 7 {
                    0 => RawCode::POSITIVE_FULL_SCALE,
                    1 if n % 3 == 0 => RawCode::NEGATIVE_FULL_SCALE,
                    _ => RawCode::from_u24(x >> 8),
                };
            }
            let f = Frame { response: 0, codes };
            let u = cal.frame_to_um(&f);
            let [r1, r2, r3] = u.re_um;
            let [i1, i2, i3] = u.im_um;
            let want = [u.x0_um, r1, i1, r2, i2, r3, i3];
            let got = cal.channels_um(&f);
            assert!(
                want.iter()
                    .zip(got.iter())
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
            assert_eq!(f.lockin_saturated(), f.saturated_mask() & 0x7F != 0);
        }
    }

    #[test]
    fn written_out_decode_equals_the_loop() {
        use super::{FRAME_BYTES, Frame};
        let mut x = 0x9E37_79B9u32;
        for n in 0..20_000u32 {
            let mut f = [0u8; FRAME_BYTES];
            for b in f.iter_mut() {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                *b = x as u8;
            }
            // half of them with a valid CRC (then one bit flipped in some)
            if n % 2 == 0 {
                let crc = super::crc16_ccitt(&f[..27]).to_be_bytes();
                f[27] = crc[0];
                f[28] = crc[1];
                if n % 6 == 0 {
                    f[(x % 29) as usize] ^= 1 << (x % 8);
                }
            }
            assert_eq!(Frame::decode(&f), decode_loop(&f));
        }
    }
    #[test]
    fn null_frame_constant_is_the_null_command_frame() {
        assert_eq!(
            super::NULL_FRAME,
            super::command_frame(&[super::opcode::NULL])
        );
    }

    #[test]
    fn table_crc_equals_bitwise_crc() {
        let mut data = [0u8; 300];
        let mut x = 0x1234_5678u32;
        for b in data.iter_mut() {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            *b = x as u8;
        }
        for len in [0usize, 1, 2, 29, 30, 300] {
            let d = &data[..len];
            assert_eq!(
                crc16_ccitt_update(0xFFFF, d),
                crc16_ccitt_update_bitwise(0xFFFF, d)
            );
            assert_eq!(
                crc16_ccitt_update(0x0000, d),
                crc16_ccitt_update_bitwise(0x0000, d)
            );
        }
        assert_eq!(crc16_ccitt(b"123456789"), 0x29B1);
    }
    use super::*;

    #[test]
    fn words_are_msb_aligned_with_a_zero_pad_byte() {
        assert_eq!(word_bytes(0xA180), [0xA1, 0x80, 0x00]);
        assert_eq!(FRAME_BYTES, 30);
        assert_eq!(FRAME_WORDS_MINUS_ONE, 9);
    }

    #[test]
    fn encode_decode_round_trip() {
        let mut f = Frame {
            response: 0x0512,
            ..Frame::default()
        };
        for (i, c) in f.codes.iter_mut().enumerate() {
            *c = RawCode::saturating_new(i as i32 * 1_000_003 - 4_000_000);
        }
        assert_eq!(Frame::decode(&f.encode()), Ok(f));
    }
}
