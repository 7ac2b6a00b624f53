//! Analog Devices AD9959: 4-channel, 500 MSPS DDS with 10-bit DACs.
//!
//! # Design
//!
//! One AD9959 makes the pump and the lock-in references from one SYSCLK (the board's
//! 125 MHz, [`DEFAULT_SYSCLK_HZ`]): channel 0 the pump at 2Ω (≈ 21.9 kHz), channel 1 the reference at Ω,
//! channel 2 the reference at 3Ω, channel 3 spare ([`Channel::PUMP`] …).
//!
//! **Serial port.** A register access is a communication cycle: an instruction byte
//! (`R/W[7]`, address `[4:0]`) followed by the register's bytes, MSB first. Once a cycle
//! is complete the serial port takes the next byte as the next cycle's instruction, so
//! one chip-select frame (one [`SpiDevice`] transaction) can carry several cycles; raising
//! CS ends the frame and drops an incomplete cycle.
//! The channel registers (CFR, CFTW0, CPOW0, ACR, …) exist once per channel at the same
//! address; the channel-enable bits of CSR select which channels a write reaches, and they
//! act immediately (no I/O update). The driver writes CSR before every channel register,
//! in 3-wire mode (SDIO_0 = MOSI, SDIO_2 = MISO) and MSB-first: `CSR = enables | 0x02`,
//! in the same frame: a channel write is one transaction, and a pump plan's three words
//! with the pump's amplitude ([`Ad9959::write_pump`]) one transaction of up to 27 bytes.
//!
//! **I/O update.** Written words land in buffers and reach the DDS cores only on a rising
//! edge of the `IO_UPDATE` pin, which is a separate GPIO the caller owns. The driver
//! records what has been buffered; [`Ad9959::take_io_update`] returns the pending
//! [`IoUpdate`] (which channels / function registers) and the caller then pulses the pin
//! once. All words written before one pulse take effect together, on the same SYSCLK edge.
//!
//! **Phase-coherent pump and references.** A DDS channel is a 32-bit phase accumulator
//! that adds its frequency tuning word (FTW) every SYSCLK cycle. Changing only the FTW
//! does not touch the accumulator: the new frequency continues from the current phase
//! (phase-continuous switching), and the driver relies on that for every pump retune.
//! With `FTW_ref = k`, `FTW_pump = 2k`, `FTW_3 = 3k` ([`PumpPlan`]: the pump word is
//! chosen even so that both references are exact integers), the accumulators satisfy
//! `acc_pump = 2·acc_ref` and `acc_3 = 3·acc_ref` (mod 2^32) forever once they hold at
//! one instant, and they keep holding across retunes as long as the three FTWs change in
//! the same I/O update. They are made to hold once, at start-up, by clearing all phase
//! accumulators together ([`Ad9959::begin_phase_alignment`] / [`Ad9959::end_phase_alignment`]).
//!
//! **Words.** `FTW = round(f · 2^32 / f_SYSCLK)` and the realised frequency is the exact
//! inverse `FTW · f_SYSCLK / 2^32` (resolution 0.029 Hz at 125 MHz), returned in `f64` so
//! the firmware knows the frequency it actually commanded. Phase offsets are 14-bit
//! (`POW / 2^14` of a turn). Amplitudes are 10-bit ASF with the amplitude multiplier
//! enabled; the pump's voltage scale `s = (V/V0)²` maps to `ASF = round(1023·√s)`, i.e.
//! `V0` is the amplitude at the largest word.
//!
//! # Example
//!
//! ```
//! use paragyro_firmware::drivers::ad9959::{AmplitudeWord, PumpPlan, DEFAULT_SYSCLK_HZ};
//!
//! let plan = PumpPlan::new(21_900.0, DEFAULT_SYSCLK_HZ).unwrap();
//! assert_eq!(plan.pump_ftw(), 752_478);
//! assert_eq!(plan.pump_ftw(), 2 * plan.reference_ftw());
//! assert_eq!(plan.third_ftw(), 3 * plan.reference_ftw());
//! assert!((plan.pump_hz() - 21_900.0).abs() < 0.03); // 21 899.992 Hz
//! assert_eq!(AmplitudeWord::from_scale(0.81).get(), 921);
//! ```

use embedded_hal::spi::{Operation, SpiDevice};

/// The board's SYSCLK, Hz: 25 MHz × 5 (the PLL's low VCO range). The pump's word is
/// 2·f_SYSCLK/2³² = 0.058 Hz, a quarter of 500 MHz's 0.233 Hz: each step of the pump's
/// frequency kicks the drive's ≈ 100 Hz envelope mode, which the fast rate channel reads
/// at 75–150 Hz: at 500 MHz the frequency's words add 0.066 °/s rms and a −0.09 to
/// −0.17 °/s bias to the rate, at 125 MHz 0.027–0.031 and +0.01 to +0.03 (`cargo run
/// --release -p paragyro-fil --example dds_words`, `rate-step` seeds 1–3). The pump at
/// ≈ 22 kHz needs nothing of the higher clock.
pub const DEFAULT_SYSCLK_HZ: f64 = 125e6;
/// Highest SYSCLK of the part, Hz.
pub const MAX_SYSCLK_HZ: f64 = 500e6;
/// `2^32`, the FTW scale.
pub const FTW_SCALE: f64 = 4_294_967_296.0;

/// How long IO_UPDATE must stay high, ns, for a SYSCLK of `sysclk_hz`: the part takes the
/// pulse on SYNC_CLK (SYSCLK/4), so one SYNC_CLK period at least (32 ns at the board's
/// 125 MHz, 8 ns at 500 MHz); two periods, rounded up, for margin. A `const fn`: a board
/// gets it at compile time.
pub const fn io_update_hold_ns(sysclk_hz: f64) -> u32 {
    let ns = 2.0 * 4.0e9 / sysclk_hz;
    let whole = ns as u32;
    if (whole as f64) < ns {
        whole.saturating_add(1)
    } else {
        whole
    }
}

/// Largest amplitude scale factor (10 bits).
pub const ASF_MAX: u16 = 1023;
/// CSR serial-mode bits for single-bit 3-wire mode (`CSR[2:1] = 01`).
pub const CSR_3_WIRE: u8 = 0x02;
/// ACR middle byte bit 4 (`ACR[12]`): amplitude multiplier enable.
pub const ACR_MULTIPLIER_ENABLE: u8 = 0x10;
/// FR2 bit 13: auto-clear the phase accumulators of all channels on I/O update.
pub const FR2_ALL_CHANNELS_AUTOCLEAR_PHASE: u16 = 0x2000;

/// AD9959 registers used by the driver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Register {
    /// Channel select register, 1 byte.
    Csr = 0x00,
    /// Function register 1 (PLL, VCO gain, charge pump, …), 3 bytes.
    Fr1 = 0x01,
    /// Function register 2 (accumulator clearing, sync), 2 bytes.
    Fr2 = 0x02,
    /// Channel function register, 3 bytes.
    Cfr = 0x03,
    /// Channel frequency tuning word 0, 4 bytes.
    Cftw0 = 0x04,
    /// Channel phase offset word 0 (14 bits), 2 bytes.
    Cpow0 = 0x05,
    /// Amplitude control register, 3 bytes.
    Acr = 0x06,
}

impl Register {
    /// Register address.
    pub const fn addr(self) -> u8 {
        self as u8
    }
    /// Instruction byte for a write.
    pub const fn write_instruction(self) -> u8 {
        self as u8
    }
    /// Instruction byte for a read.
    pub const fn read_instruction(self) -> u8 {
        0x80 | self as u8
    }
}

/// A DDS channel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Channel {
    /// Channel 0.
    Ch0 = 0,
    /// Channel 1.
    Ch1 = 1,
    /// Channel 2.
    Ch2 = 2,
    /// Channel 3.
    Ch3 = 3,
}

impl Channel {
    /// The pump, 2Ω.
    pub const PUMP: Channel = Channel::Ch0;
    /// The reference at Ω.
    pub const REFERENCE: Channel = Channel::Ch1;
    /// The reference at 3Ω.
    pub const THIRD: Channel = Channel::Ch2;
    /// Unused.
    pub const SPARE: Channel = Channel::Ch3;
    /// All four channels.
    pub const ALL: [Channel; 4] = [Channel::Ch0, Channel::Ch1, Channel::Ch2, Channel::Ch3];

    /// Bit `n` for channel `n` (as in [`IoUpdate::channels`]).
    pub const fn mask(self) -> u8 {
        1 << (self as u8)
    }
    /// The channel-enable bit in CSR (`CSR[4 + n]`).
    pub const fn csr_enable(self) -> u8 {
        0x10 << (self as u8)
    }
}

/// A frequency the DDS cannot make (negative, not finite, at or above Nyquist), or an
/// invalid clock configuration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrequencyOutOfRange;

/// Errors of the AD9959 driver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<E> {
    /// The SPI device failed.
    Spi(E),
    /// See [`FrequencyOutOfRange`].
    FrequencyOutOfRange,
}

impl<E> From<FrequencyOutOfRange> for Error<E> {
    fn from(_: FrequencyOutOfRange) -> Self {
        Error::FrequencyOutOfRange
    }
}

fn valid_sysclk(sysclk_hz: f64) -> bool {
    sysclk_hz.is_finite() && sysclk_hz > 0.0 && sysclk_hz <= MAX_SYSCLK_HZ
}

/// `round(x)` for `0 <= x < 2^52` (no `std`); larger values saturate at the cast.
fn round_nonneg(x: f64) -> u64 {
    (x + 0.5) as u64
}

/// `FTW = round(f · 2^32 / f_SYSCLK)` for `0 <= f < f_SYSCLK / 2`.
pub fn ftw_from_hz(f_hz: f64, sysclk_hz: f64) -> Result<u32, FrequencyOutOfRange> {
    if !valid_sysclk(sysclk_hz) || !f_hz.is_finite() || f_hz < 0.0 || f_hz >= sysclk_hz / 2.0 {
        return Err(FrequencyOutOfRange);
    }
    let ftw = round_nonneg(f_hz * FTW_SCALE / sysclk_hz);
    // f < f_SYSCLK/2 gives ftw <= 2^31 (rounding up at the very top): keep it below Nyquist.
    u32::try_from(ftw)
        .ok()
        .filter(|&w| w < 1 << 31)
        .ok_or(FrequencyOutOfRange)
}

/// The frequency a tuning word makes: `FTW · f_SYSCLK / 2^32` (exact inverse of the
/// hardware, up to `f64` rounding).
pub fn hz_from_ftw(ftw: u32, sysclk_hz: f64) -> f64 {
    f64::from(ftw) * sysclk_hz / FTW_SCALE
}

/// Tuning words of the pump (2Ω) and the references (Ω, 3Ω) with exact ratios.
///
/// `reference_ftw = k = round(f_pump/2 · 2^32 / f_SYSCLK)`, `pump_ftw = 2k`,
/// `third_ftw = 3k`, so the pump word is even and `pump/2`, `3·pump/2` are exact. The
/// pump's realised frequency is within one FTW step (0.116 Hz at 500 MHz) of the request.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PumpPlan {
    reference_ftw: u32,
    sysclk_hz: f64,
}

impl PumpPlan {
    /// Plan for a requested pump frequency. Fails if the pump is not positive, if the
    /// reference word would be 0, or if 3Ω would reach Nyquist.
    pub fn new(pump_hz: f64, sysclk_hz: f64) -> Result<Self, FrequencyOutOfRange> {
        if !pump_hz.is_finite() || pump_hz <= 0.0 {
            return Err(FrequencyOutOfRange);
        }
        let k = ftw_from_hz(pump_hz / 2.0, sysclk_hz)?;
        // 3k must stay below 2^31 (Nyquist); this also bounds 2k.
        match k.checked_mul(3) {
            Some(third) if k > 0 && third < 1 << 31 => Ok(Self {
                reference_ftw: k,
                sysclk_hz,
            }),
            _ => Err(FrequencyOutOfRange),
        }
    }

    /// Plan for a reference word `k` (pump `2k`, 3Ω `3k`); `None` unless `k > 0` and
    /// `3k < 2^31`, the same conditions as [`PumpPlan::new`].
    pub fn from_reference_ftw(reference_ftw: u32, sysclk_hz: f64) -> Option<Self> {
        let ok = reference_ftw > 0
            && reference_ftw
                .checked_mul(3)
                .is_some_and(|third| third < 1 << 31);
        ok.then_some(Self {
            reference_ftw,
            sysclk_hz,
        })
    }

    /// SYSCLK the words are for.
    pub const fn sysclk_hz(&self) -> f64 {
        self.sysclk_hz
    }
    /// Reference (Ω) tuning word `k`.
    pub const fn reference_ftw(&self) -> u32 {
        self.reference_ftw
    }
    /// Pump (2Ω) tuning word `2k` (even).
    pub const fn pump_ftw(&self) -> u32 {
        self.reference_ftw.wrapping_mul(2)
    }
    /// Third-harmonic reference (3Ω) tuning word `3k`.
    pub const fn third_ftw(&self) -> u32 {
        self.reference_ftw.wrapping_mul(3)
    }
    /// Realised pump frequency, Hz.
    pub fn pump_hz(&self) -> f64 {
        hz_from_ftw(self.pump_ftw(), self.sysclk_hz)
    }
    /// Realised reference frequency Ω, Hz (exactly half the pump).
    pub fn reference_hz(&self) -> f64 {
        hz_from_ftw(self.reference_ftw, self.sysclk_hz)
    }
    /// Realised 3Ω frequency, Hz.
    pub fn third_hz(&self) -> f64 {
        hz_from_ftw(self.third_ftw(), self.sysclk_hz)
    }
}

/// A 14-bit phase offset word (`POW / 2^14` of a turn).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PhaseWord(u16);

impl PhaseWord {
    /// From a word; only the low 14 bits are kept.
    pub const fn new(word: u16) -> Self {
        Self(word & 0x3FFF)
    }

    /// From a phase in turns (any real; wrapped to one turn, rounded to the nearest
    /// step of 1/16384 turn; NaN gives 0).
    pub fn from_turns(turns: f64) -> Self {
        let x = turns * 16384.0;
        let r = if x >= 0.0 {
            (x + 0.5) as i64
        } else {
            (x - 0.5) as i64
        };
        Self((r & 0x3FFF) as u16)
    }

    /// From a phase in radians.
    pub fn from_radians(rad: f64) -> Self {
        Self::from_turns(rad / core::f64::consts::TAU)
    }

    /// The word.
    pub const fn get(self) -> u16 {
        self.0
    }

    /// The phase it makes, in turns `[0, 1)`.
    pub fn turns(self) -> f64 {
        f64::from(self.0) / 16384.0
    }
}

/// A 10-bit amplitude scale factor (ASF), used with the amplitude multiplier enabled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AmplitudeWord(u16);

impl AmplitudeWord {
    /// The largest word, 1023: the reference amplitude `V0` (`s = 1`).
    pub const FULL: AmplitudeWord = AmplitudeWord(ASF_MAX);
    /// Zero output.
    pub const ZERO: AmplitudeWord = AmplitudeWord(0);

    /// From a word, clamped to 1023.
    pub const fn new(word: u16) -> Self {
        Self(if word > ASF_MAX { ASF_MAX } else { word })
    }

    /// From the pump voltage scale `s = (V/V0)²`: `ASF = round(1023·√s)`, `s` clamped to
    /// `[0, 1]` (NaN gives 0). Computed in integers (the `f32`'s mantissa and exponent,
    /// then an integer square root), so it is exact, needs no `std` and no soft-float
    /// `f64` on the tick path (the same words as the former `f64` form; test
    /// `from_scale_in_integers_equals_the_f64_form`).
    pub fn from_scale(s: f32) -> Self {
        let s = if s > 1.0 {
            1.0
        } else if s > 0.0 {
            s
        } else {
            return Self(0); // also NaN
        };
        // s = mant · 2^(exp − 150) (normal) or frac · 2^−149 (subnormal), exactly
        let bits = s.to_bits();
        let exp = (bits >> 23) & 0xFF;
        let frac = u64::from(bits & 0x7F_FFFF);
        let (mant, shift) = if exp == 0 {
            (frac, 149)
        } else {
            (frac | 0x80_0000, 150u32.saturating_sub(exp))
        };
        // floor(4v), v = 1023²·s: 4·1023²·mant < 2^46 (never saturates), shift ≥ 23
        // (s ≤ 1)
        const FOUR_ASF_MAX_SQ: u64 = 4 * (ASF_MAX as u64) * (ASF_MAX as u64);
        let four_v = FOUR_ASF_MAX_SQ
            .saturating_mul(mant)
            .checked_shr(shift)
            .unwrap_or(0);
        // round(√v) = (floor(2√v) + 1) / 2 and floor(2√v) = isqrt(floor(4v)); 4v ≤
        // 4·1023² < 2^22 (s ≤ 1), so a 32-bit root does (`u64::isqrt` linked a 512 B table
        // and the 64-bit division into the image)
        let asf = isqrt_below_2_22(u32::try_from(four_v).unwrap_or(u32::MAX)).saturating_add(1) / 2;
        Self(u16::try_from(asf).map_or(ASF_MAX, |a| a.min(ASF_MAX)))
    }

    /// The word.
    pub const fn get(self) -> u16 {
        self.0
    }

    /// The voltage scale the word realises: `(ASF/1023)²`.
    pub fn scale(self) -> f32 {
        let a = f32::from(self.0) / f32::from(ASF_MAX);
        a * a
    }

    /// The three ACR bytes: ramp rate 0, multiplier enabled, ASF.
    pub const fn acr_bytes(self) -> [u8; 3] {
        let [hi, lo] = self.0.to_be_bytes();
        [0x00, ACR_MULTIPLIER_ENABLE | (hi & 0x03), lo]
    }
}

/// `floor(√n)` for `n < 2^22` (no table, no integer division); larger `n` give 2047 (the
/// callers clamp to [`ASF_MAX`] anyway). An `f32` estimate (`n` is exact in `f32`): half
/// the exponent, three Newton steps (relative error < 1e-6, i.e. < 0.003 at √n < 2048),
/// then the integer root corrected by one step either way; checked for every `n` by the
/// test `isqrt_below_2_22_is_the_integer_square_root_everywhere`.
fn isqrt_below_2_22(n: u32) -> u32 {
    if n >= 1 << 22 {
        return 2047;
    }
    if n == 0 {
        return 0;
    }
    let x = n as f32;
    let mut y = f32::from_bits((x.to_bits() >> 1).wrapping_add(0x1FC0_0000));
    y = 0.5 * (y + x / y);
    y = 0.5 * (y + x / y);
    y = 0.5 * (y + x / y);
    // saturating casts; √n < 2048, so the squares below cannot overflow
    let mut r = y as u32;
    if r.wrapping_mul(r) > n {
        r = r.wrapping_sub(1);
    } else if r.wrapping_add(1).wrapping_mul(r.wrapping_add(1)) <= n {
        r = r.wrapping_add(1);
    }
    r
}

/// The CSR byte that selects `ch` alone (3-wire, MSB first).
const fn csr_selecting(ch: Channel) -> u8 {
    (ch.csr_enable() & 0xF0) | CSR_3_WIRE
}

/// A plan's three tuning-word cycles (pump, reference, 3Ω), each after its CSR select:
/// 21 bytes of one frame.
fn plan_cycles(plan: &PumpPlan) -> [u8; 21] {
    let (csr, ftw) = (
        Register::Csr.write_instruction(),
        Register::Cftw0.write_instruction(),
    );
    let [p0, p1, p2, p3] = plan.pump_ftw().to_be_bytes();
    let [r0, r1, r2, r3] = plan.reference_ftw().to_be_bytes();
    let [t0, t1, t2, t3] = plan.third_ftw().to_be_bytes();
    [
        csr,
        csr_selecting(Channel::PUMP),
        ftw,
        p0,
        p1,
        p2,
        p3,
        csr,
        csr_selecting(Channel::REFERENCE),
        ftw,
        r0,
        r1,
        r2,
        r3,
        csr,
        csr_selecting(Channel::THIRD),
        ftw,
        t0,
        t1,
        t2,
        t3,
    ]
}

/// What the caller must do after buffered writes: pulse the `IO_UPDATE` GPIO once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[must_use = "the written words stay buffered until IO_UPDATE is pulsed"]
pub struct IoUpdate {
    /// Channels with buffered channel-register writes, bit `n` for channel `n`.
    pub channels: u8,
    /// FR1/FR2 were written.
    pub function_registers: bool,
}

/// AD9959 driver over an [`SpiDevice`] (SPI mode 0, MSB first, 3-wire serial mode).
#[derive(Debug)]
pub struct Ad9959<SPI> {
    spi: SPI,
    sysclk_hz: f64,
    pending_channels: u8,
    pending_function: bool,
}

impl<SPI: SpiDevice> Ad9959<SPI> {
    /// Wrap an SPI device; no bus traffic. `sysclk_hz` is the DDS system clock the words
    /// are computed for ([`DEFAULT_SYSCLK_HZ`] on this board; [`Ad9959::set_pll`] updates it).
    pub const fn new(spi: SPI, sysclk_hz: f64) -> Self {
        Self {
            spi,
            sysclk_hz,
            pending_channels: 0,
            pending_function: false,
        }
    }

    /// Give the SPI device back.
    pub fn destroy(self) -> SPI {
        self.spi
    }

    /// SYSCLK the words are computed for, Hz.
    pub const fn sysclk_hz(&self) -> f64 {
        self.sysclk_hz
    }

    fn write(&mut self, reg: Register, data: &[u8]) -> Result<(), Error<SPI::Error>> {
        self.spi
            .transaction(&mut [
                Operation::Write(&[reg.write_instruction()]),
                Operation::Write(data),
            ])
            .map_err(Error::Spi)
    }

    fn select(&mut self, enables: u8) -> Result<(), Error<SPI::Error>> {
        self.write(Register::Csr, &[(enables & 0xF0) | CSR_3_WIRE])
    }

    /// One frame: CSR selecting `ch`, then `reg`'s cycle.
    fn write_channel(
        &mut self,
        ch: Channel,
        reg: Register,
        data: &[u8],
    ) -> Result<(), Error<SPI::Error>> {
        let head = [
            Register::Csr.write_instruction(),
            csr_selecting(ch),
            reg.write_instruction(),
        ];
        self.spi
            .transaction(&mut [Operation::Write(&head), Operation::Write(data)])
            .map_err(Error::Spi)?;
        self.pending_channels |= ch.mask();
        Ok(())
    }

    /// Put the serial port in 3-wire, MSB-first mode with all channels selected
    /// (`CSR = 0xF2`). Call once after a master reset.
    pub fn init(&mut self) -> Result<(), Error<SPI::Error>> {
        self.select(0xF0)
    }

    /// Configure the reference-clock multiplier (FR1): `multiplier` 4..=20 enables the
    /// PLL, 1 bypasses it. The resulting SYSCLK must be ≤ 500 MHz and, with the PLL, in
    /// one of the VCO ranges (< 160 MHz low gain, > 255 MHz high gain). Returns the new
    /// SYSCLK, which later words use; existing FTWs must be rewritten. Needs an I/O update.
    pub fn set_pll(&mut self, ref_clk_hz: f64, multiplier: u8) -> Result<f64, Error<SPI::Error>> {
        let pll = (4..=20).contains(&multiplier);
        if !pll && multiplier != 1 {
            return Err(Error::FrequencyOutOfRange);
        }
        let sysclk = ref_clk_hz * f64::from(multiplier);
        if !valid_sysclk(sysclk) || (pll && (160e6..=255e6).contains(&sysclk)) {
            return Err(Error::FrequencyOutOfRange);
        }
        let vco_high = pll && sysclk > 255e6;
        let divider = if pll { multiplier } else { 0 };
        // FR1[23] VCO gain, FR1[22:18] PLL divider, FR1[17:16] charge pump (75 µA default).
        let fr1 = [(vco_high as u8) << 7 | (divider & 0x1F) << 2, 0x00, 0x00];
        self.write(Register::Fr1, &fr1)?;
        self.pending_function = true;
        self.sysclk_hz = sysclk;
        Ok(sysclk)
    }

    /// Write a channel's frequency tuning word.
    pub fn set_frequency_word(&mut self, ch: Channel, ftw: u32) -> Result<(), Error<SPI::Error>> {
        self.write_channel(ch, Register::Cftw0, &ftw.to_be_bytes())
    }

    /// Set a channel's frequency; returns the realised frequency, Hz.
    pub fn set_frequency(&mut self, ch: Channel, hz: f64) -> Result<f64, Error<SPI::Error>> {
        let ftw = ftw_from_hz(hz, self.sysclk_hz)?;
        self.set_frequency_word(ch, ftw)?;
        Ok(hz_from_ftw(ftw, self.sysclk_hz))
    }

    /// Write the pump, reference and 3Ω tuning words of a plan (channels 0, 1, 2), in one
    /// frame. Pulse IO_UPDATE once afterwards so that the three change on the same SYSCLK
    /// edge (phase-continuous, ratios kept).
    pub fn apply_plan(&mut self, plan: &PumpPlan) -> Result<(), Error<SPI::Error>> {
        self.write_pump(Some(plan), None)
    }

    /// Write what is given in one frame (one transaction; nothing when both are `None`):
    /// the plan's three tuning words ([`Ad9959::apply_plan`]), then the pump's amplitude
    /// (ACR), each cycle after its CSR select. The tick's one DDS write; pulse IO_UPDATE
    /// once afterwards.
    pub fn write_pump(
        &mut self,
        plan: Option<&PumpPlan>,
        asf: Option<AmplitudeWord>,
    ) -> Result<(), Error<SPI::Error>> {
        let words = plan.map(plan_cycles);
        let amplitude = asf.map(|a| {
            let [a0, a1, a2] = a.acr_bytes();
            [
                Register::Csr.write_instruction(),
                csr_selecting(Channel::PUMP),
                Register::Acr.write_instruction(),
                a0,
                a1,
                a2,
            ]
        });
        let r = match (&words, &amplitude) {
            (Some(w), Some(a)) => self
                .spi
                .transaction(&mut [Operation::Write(w), Operation::Write(a)]),
            (Some(w), None) => self.spi.transaction(&mut [Operation::Write(w)]),
            (None, Some(a)) => self.spi.transaction(&mut [Operation::Write(a)]),
            (None, None) => return Ok(()),
        };
        r.map_err(Error::Spi)?;
        if words.is_some() {
            self.pending_channels |=
                Channel::PUMP.mask() | Channel::REFERENCE.mask() | Channel::THIRD.mask();
        }
        if amplitude.is_some() {
            self.pending_channels |= Channel::PUMP.mask();
        }
        Ok(())
    }

    /// Plan and write the pump and references for `pump_hz` at the current SYSCLK;
    /// returns the plan (its realised frequencies).
    pub fn set_pump_frequency(&mut self, pump_hz: f64) -> Result<PumpPlan, Error<SPI::Error>> {
        let plan = PumpPlan::new(pump_hz, self.sysclk_hz)?;
        self.apply_plan(&plan)?;
        Ok(plan)
    }

    /// Write a channel's phase offset word.
    pub fn set_phase(&mut self, ch: Channel, pow: PhaseWord) -> Result<(), Error<SPI::Error>> {
        self.write_channel(ch, Register::Cpow0, &pow.get().to_be_bytes())
    }

    /// Write a channel's amplitude (ACR, multiplier enabled).
    pub fn set_amplitude(
        &mut self,
        ch: Channel,
        asf: AmplitudeWord,
    ) -> Result<(), Error<SPI::Error>> {
        self.write_channel(ch, Register::Acr, &asf.acr_bytes())
    }

    /// Set the pump amplitude from the voltage scale `s = (V/V0)²`; returns the word.
    pub fn set_pump_scale(&mut self, s: f32) -> Result<AmplitudeWord, Error<SPI::Error>> {
        let asf = AmplitudeWord::from_scale(s);
        self.set_amplitude(Channel::PUMP, asf)?;
        Ok(asf)
    }

    /// Start-up phase alignment, step 1: set FR2's all-channel phase-accumulator
    /// auto-clear. Then pulse IO_UPDATE, call [`Ad9959::end_phase_alignment`] and pulse
    /// again: the accumulators of all channels are cleared together, after which the FTW
    /// ratios keep the phases locked.
    pub fn begin_phase_alignment(&mut self) -> Result<(), Error<SPI::Error>> {
        self.write(
            Register::Fr2,
            &FR2_ALL_CHANNELS_AUTOCLEAR_PHASE.to_be_bytes(),
        )?;
        self.pending_function = true;
        Ok(())
    }

    /// Start-up phase alignment, step 2: clear the auto-clear bit again so that later
    /// I/O updates are phase-continuous.
    pub fn end_phase_alignment(&mut self) -> Result<(), Error<SPI::Error>> {
        self.write(Register::Fr2, &[0x00, 0x00])?;
        self.pending_function = true;
        Ok(())
    }

    /// Read back a channel's frequency tuning word (link check; an absent chip reads
    /// `0xFFFF_FFFF` or 0).
    pub fn read_frequency_word(&mut self, ch: Channel) -> Result<u32, Error<SPI::Error>> {
        self.select(ch.csr_enable())?;
        let mut buf = [0u8; 4];
        self.spi
            .transaction(&mut [
                Operation::Write(&[Register::Cftw0.read_instruction()]),
                Operation::Read(&mut buf),
            ])
            .map_err(Error::Spi)?;
        Ok(u32::from_be_bytes(buf))
    }

    /// The I/O update the caller must now pulse on the `IO_UPDATE` GPIO, if any; clears
    /// the record (the driver assumes the caller pulses).
    pub fn take_io_update(&mut self) -> Option<IoUpdate> {
        if self.pending_channels == 0 && !self.pending_function {
            return None;
        }
        let update = IoUpdate {
            channels: self.pending_channels,
            function_registers: self.pending_function,
        };
        self.pending_channels = 0;
        self.pending_function = false;
        Some(update)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn isqrt_below_2_22_is_the_integer_square_root_everywhere() {
        for n in 0..(1u32 << 22) {
            assert_eq!(isqrt_below_2_22(n), n.isqrt(), "n = {n}");
        }
        assert_eq!(isqrt_below_2_22(1 << 22), 2047);
        assert_eq!(isqrt_below_2_22(u32::MAX), 2047);
    }

    /// The former `f64` form of `from_scale` (the reference).
    fn from_scale_f64(s: f32) -> AmplitudeWord {
        let s = if s > 1.0 {
            1.0
        } else if s > 0.0 {
            f64::from(s)
        } else {
            0.0
        };
        let v = f64::from(ASF_MAX) * f64::from(ASF_MAX) * s;
        let n = ((4.0 * v) as u64).isqrt();
        let asf = n.saturating_add(1) / 2;
        AmplitudeWord(u16::try_from(asf).map_or(ASF_MAX, |a| a.min(ASF_MAX)))
    }

    #[test]
    fn from_scale_in_integers_equals_the_f64_form() {
        let specials = [
            0.0f32,
            -0.0,
            -1.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MIN_POSITIVE,
            1e-45,
            1.0,
            1.000_000_1,
            0.999_999_94,
            0.81,
            2.0,
        ];
        // every word's boundary (1023·√s = n + ½) and its f32 neighbours
        let edges = (0..1023u32).flat_map(|n| {
            let b = ((f64::from(n) + 0.5) / 1023.0).powi(2) as f32;
            [
                b,
                f32::from_bits(b.to_bits() + 1),
                f32::from_bits(b.to_bits() - 1),
            ]
        });
        // and a sweep over (0, 1.2]
        let sweep = (1..=120_000).map(|i| i as f32 * 1e-5);
        let mut n = 0;
        for s in specials.into_iter().chain(edges).chain(sweep) {
            assert_eq!(AmplitudeWord::from_scale(s), from_scale_f64(s), "s = {s:e}");
            n += 1;
        }
        assert_eq!(n, 13 + 3 * 1023 + 120_000);
    }

    #[test]
    fn rounding_and_clock_validation() {
        assert_eq!(round_nonneg(0.0), 0);
        assert_eq!(round_nonneg(0.49), 0);
        assert_eq!(round_nonneg(0.5), 1);
        assert_eq!(round_nonneg(188_119.567_564_8), 188_120);
        assert_eq!(round_nonneg(f64::NAN), 0);
        assert!(valid_sysclk(500e6));
        assert!(!valid_sysclk(500.1e6));
        assert!(!valid_sysclk(0.0));
        assert!(!valid_sysclk(f64::INFINITY));
    }

    /// IO_UPDATE is held two SYNC_CLK periods (SYSCLK/4), rounded up: 64 ns at the board's
    /// 125 MHz, 16 ns at 500 MHz, 54 ns at 150 MHz (53.3 rounded up).
    #[test]
    fn io_update_is_held_two_sync_clk_periods() {
        assert_eq!(io_update_hold_ns(DEFAULT_SYSCLK_HZ), 64);
        assert_eq!(io_update_hold_ns(500e6), 16);
        assert_eq!(io_update_hold_ns(150e6), 54);
    }
}
