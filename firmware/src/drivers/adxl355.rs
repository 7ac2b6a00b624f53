//! Analog Devices ADXL355: low-noise 3-axis accelerometer, 20-bit, SPI.
//!
//! # Design
//!
//! The ADXL355 measures the frame's acceleration next to the gyro. Its SPI protocol is a
//! command byte `address << 1 | R/W` (`1` = read) followed by data; multi-byte reads
//! auto-increment the address, so the driver reads related registers in one burst:
//! the three ID registers together, and STATUS through ZDATA1 (13 bytes) for a sample,
//! so that data-ready and the data it refers to arrive in one [`SpiDevice::transaction`].
//!
//! **Absent device.** A missing or unpowered accelerometer reads all-ones (MISO floating
//! high) or all-zeros (stuck low). [`Adxl355::check_id`] turns that into
//! [`Error::BadId`] (see [`Error::is_missing_device`]); [`Adxl355::read_sample`] treats a
//! STATUS byte with reserved bits set (e.g. `0xFF`) as not ready. Nothing panics.
//!
//! **Temperature.** TEMP2 `[3:0]` and TEMP1 hold a 12-bit unsigned code of the
//! temperature sensor, converted with the datasheet's nominal transfer function
//! `T = 25 °C + (code − 1885) / (−9.05 LSB/°C)` ([`temp_c_from_raw`]): the code falls as
//! the temperature rises. Both constants are nominal; the 1885 LSB intercept in
//! particular varies from part to part, so the absolute temperature is uncertain by
//! that spread (changes of temperature are better known): calibrate a part where the
//! absolute value matters. The sensor measures the accelerometer's die, next to the gyro but not the
//! gyro's own die. It runs in measurement mode unless POWER_CTL.TEMP_OFF is set
//! ([`Adxl355::measure`] clears it); in standby, and before its first conversion after
//! a reset, TEMP2/TEMP1 read their reset value 0 (an implausible ≈ 233 °C). The sample
//! burst ([`Adxl355::read_sample`]) carries the code at no extra bus cost
//! ([`AccelSample::temp_raw`]); [`Adxl355::read_temperature_raw`] reads it alone.
//!
//! **Data.** Axis data are 20-bit two's complement, left-justified in three registers
//! (`DATA3 = [19:12]`, `DATA2 = [11:4]`, `DATA1[7:4] = [3:0]`). The scale factor is
//! 3.9 µg/LSB at ±2 g, 7.8 µg/LSB at ±4 g and 15.6 µg/LSB at ±8 g (datasheet typical;
//! ADI's own no-OS driver uses the same), converted with standard gravity
//! 9.806 65 m/s². RANGE and FILTER should be written in standby ([`Adxl355::init`] does).
//!
//! Why not the `adi-adxl355` crate: it does implement embedded-hal 1.0 `SpiDevice`, but
//! its register decoders `panic!` on unexpected values (e.g. an all-ones FILTER read from
//! an absent device), its `configure` ORs the range bits into RANGE without clearing them
//! (±2 g → ±4 g gives ±8 g), it checks only PARTID, and its error type does not fit here.
//!
//! # Example
//!
//! ```
//! use paragyro_firmware::drivers::adxl355::{self, Adxl355, Range};
//! use paragyro_firmware::FailingSpi;
//!
//! // Nothing on the bus: MISO floats high.
//! let mut xl = Adxl355::new(FailingSpi::responding(0xFF));
//! let err = xl.check_id().unwrap_err();
//! assert!(err.is_missing_device());
//!
//! // 20-bit codes to m/s².
//! assert_eq!(adxl355::raw20_from_bytes([0x80, 0x00, 0x00]), -524_288);
//! let one_g = adxl355::RawAccel { x: 0, y: 0, z: 256_410 }.to_mps2(Range::G2)[2];
//! assert!((one_g - 9.806_65).abs() < 1e-3);
//!
//! // TEMP2, TEMP1 to °C: the datasheet's 25 °C point, 9.05 codes per −1 °C.
//! assert_eq!(adxl355::temp_raw12(0x07, 0x5D), 1885);
//! assert_eq!(adxl355::temp_c_from_raw(1885), 25.0);
//! assert!((adxl355::temp_c_from_raw(1885 - 181) - 45.0).abs() < 1e-4);
//! ```

use embedded_hal::spi::{Operation, SpiDevice};

/// `DEVID_AD` value (Analog Devices).
pub const DEVID_AD: u8 = 0xAD;
/// `DEVID_MST` value (Analog Devices MEMS).
pub const DEVID_MST: u8 = 0x1D;
/// `PARTID` value of the ADXL355 (octal 355).
pub const PARTID: u8 = 0xED;
/// Code written to RESET for a software reset.
pub const RESET_CODE: u8 = 0x52;
/// Standard gravity, m/s².
pub const STANDARD_GRAVITY_MPS2: f32 = 9.806_65;
/// Upper RANGE bits the driver writes: `I2C_HS = 1` (reset value), `INT_POL = 0`.
pub const RANGE_UPPER_BITS: u8 = 0x80;
/// POWER_CTL.STANDBY: standby (no measurement, temperature sensor off too).
pub const POWER_CTL_STANDBY: u8 = 0x01;
/// POWER_CTL.TEMP_OFF: temperature processing off (TEMP2/TEMP1 not updated).
pub const POWER_CTL_TEMP_OFF: u8 = 0x02;
/// POWER_CTL.DRDY_OFF: the DRDY pin forced low.
pub const POWER_CTL_DRDY_OFF: u8 = 0x04;
/// POWER_CTL written by [`Adxl355::measure`]: measurement mode with the temperature
/// sensor and DRDY on.
pub const POWER_CTL_MEASURE: u8 = 0x00;
const _: () = assert!(
    POWER_CTL_MEASURE & (POWER_CTL_STANDBY | POWER_CTL_TEMP_OFF) == 0,
    "measurement mode keeps the temperature sensor on"
);
/// Temperature code at [`TEMP_INTERCEPT_C`] (datasheet nominal; the intercept varies
/// part to part).
pub const TEMP_INTERCEPT_CODE: u16 = 1885;
/// Temperature of the intercept, °C.
pub const TEMP_INTERCEPT_C: f32 = 25.0;
/// Slope of the temperature code, LSB/°C (datasheet nominal; negative: the code falls
/// as the die warms).
pub const TEMP_SLOPE_LSB_PER_C: f32 = -9.05;

/// ADXL355 registers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Register {
    /// Analog Devices ID, `0xAD`.
    DevIdAd = 0x00,
    /// MEMS ID, `0x1D`.
    DevIdMst = 0x01,
    /// Part ID, `0xED`.
    PartId = 0x02,
    /// Revision ID.
    RevId = 0x03,
    /// STATUS.
    Status = 0x04,
    /// FIFO entries.
    FifoEntries = 0x05,
    /// Temperature `[11:8]`.
    Temp2 = 0x06,
    /// Temperature `[7:0]`.
    Temp1 = 0x07,
    /// X data `[19:12]`.
    XData3 = 0x08,
    /// Y data `[19:12]`.
    YData3 = 0x0B,
    /// Z data `[19:12]`.
    ZData3 = 0x0E,
    /// FILTER: high-pass corner `[6:4]`, ODR/low-pass `[3:0]`.
    Filter = 0x28,
    /// RANGE: `I2C_HS[7] INT_POL[6] RANGE[1:0]`.
    Range = 0x2C,
    /// POWER_CTL: `DRDY_OFF[2] TEMP_OFF[1] STANDBY[0]`.
    PowerCtl = 0x2D,
    /// RESET: write [`RESET_CODE`].
    Reset = 0x2F,
}

impl Register {
    /// Register address.
    pub const fn addr(self) -> u8 {
        self as u8
    }
    /// SPI command byte for a read.
    pub const fn read_cmd(self) -> u8 {
        (self as u8) << 1 | 1
    }
    /// SPI command byte for a write.
    pub const fn write_cmd(self) -> u8 {
        (self as u8) << 1
    }
}

/// Errors of the ADXL355 driver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<E> {
    /// The SPI device failed.
    Spi(E),
    /// The ID registers do not read `0xAD, 0x1D, 0xED`.
    BadId {
        /// DEVID_AD read.
        ad: u8,
        /// DEVID_MST read.
        mst: u8,
        /// PARTID read.
        part: u8,
    },
    /// No new data (STATUS.DATA_RDY clear, or a STATUS byte with reserved bits set).
    NotReady,
}

impl<E> Error<E> {
    /// A [`Error::BadId`] reading all-ones or all-zeros: no device answers (absent,
    /// unpowered, or MISO not connected) rather than a different chip.
    pub const fn is_missing_device(&self) -> bool {
        matches!(
            self,
            Error::BadId {
                ad: 0xFF,
                mst: 0xFF,
                part: 0xFF
            } | Error::BadId {
                ad: 0,
                mst: 0,
                part: 0
            }
        )
    }
}

/// Measurement range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Range {
    /// ±2 g (reset default), 3.9 µg/LSB.
    G2 = 0b01,
    /// ±4 g, 7.8 µg/LSB.
    G4 = 0b10,
    /// ±8 g, 15.6 µg/LSB.
    G8 = 0b11,
}

impl Range {
    /// Scale factor, g per LSB.
    pub const fn g_per_lsb(self) -> f32 {
        match self {
            Range::G2 => 3.9e-6,
            Range::G4 => 7.8e-6,
            Range::G8 => 15.6e-6,
        }
    }

    /// Scale factor, m/s² per LSB.
    pub fn mps2_per_lsb(self) -> f32 {
        self.g_per_lsb() * STANDARD_GRAVITY_MPS2
    }
}

/// Output data rate (the low-pass corner is ODR/4): `FILTER.ODR_LPF[3:0]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Odr {
    /// 4000 Hz (reset default).
    Hz4000 = 0,
    /// 2000 Hz.
    Hz2000 = 1,
    /// 1000 Hz.
    Hz1000 = 2,
    /// 500 Hz.
    Hz500 = 3,
    /// 250 Hz.
    Hz250 = 4,
    /// 125 Hz.
    Hz125 = 5,
    /// 62.5 Hz.
    Hz62_5 = 6,
    /// 31.25 Hz.
    Hz31_25 = 7,
    /// 15.625 Hz.
    Hz15_625 = 8,
    /// 7.813 Hz.
    Hz7_813 = 9,
    /// 3.906 Hz.
    Hz3_906 = 10,
}

impl Odr {
    /// Output data rate, Hz.
    pub fn hz(self) -> f32 {
        4000.0 / (1u32 << (self as u32)) as f32
    }
}

/// High-pass filter corner relative to the ODR: `FILTER.HPF_CORNER[6:4]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum HighPass {
    /// No high-pass filter (reset default).
    Off = 0,
    /// 24.7e-4 × ODR.
    Corner1 = 1,
    /// 6.2084e-4 × ODR.
    Corner2 = 2,
    /// 1.5545e-4 × ODR.
    Corner3 = 3,
    /// 0.3862e-4 × ODR.
    Corner4 = 4,
    /// 0.0954e-4 × ODR.
    Corner5 = 5,
    /// 0.0238e-4 × ODR.
    Corner6 = 6,
}

/// FILTER register value.
pub const fn filter_bits(odr: Odr, hpf: HighPass) -> u8 {
    (hpf as u8) << 4 | odr as u8
}

/// The STATUS register.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status(pub u8);

impl Status {
    /// New X/Y/Z data are ready.
    pub const fn data_ready(self) -> bool {
        self.0 & 0x01 != 0
    }
    /// FIFO watermark reached.
    pub const fn fifo_full(self) -> bool {
        self.0 & 0x02 != 0
    }
    /// FIFO overrun.
    pub const fn fifo_overrun(self) -> bool {
        self.0 & 0x04 != 0
    }
    /// Activity detected.
    pub const fn activity(self) -> bool {
        self.0 & 0x08 != 0
    }
    /// NVM busy (e.g. just after a reset).
    pub const fn nvm_busy(self) -> bool {
        self.0 & 0x10 != 0
    }
    /// Reserved bits 7:5 set: not a plausible STATUS (e.g. MISO floating high).
    pub const fn implausible(self) -> bool {
        self.0 & 0xE0 != 0
    }
}

/// The three ID registers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeviceId {
    /// DEVID_AD.
    pub ad: u8,
    /// DEVID_MST.
    pub mst: u8,
    /// PARTID.
    pub part: u8,
}

impl DeviceId {
    /// The ADXL355's IDs.
    pub const fn is_adxl355(self) -> bool {
        self.ad == DEVID_AD && self.mst == DEVID_MST && self.part == PARTID
    }
}

/// Sign-extend one 20-bit axis value from its three data bytes.
pub const fn raw20_from_bytes(bytes: [u8; 3]) -> i32 {
    let [b3, b2, b1] = bytes;
    (((b3 as u32) << 24 | (b2 as u32) << 16 | ((b1 & 0xF0) as u32) << 8) as i32) >> 12
}

/// The 12-bit temperature code from TEMP2 (its bits 3:0 are the code's bits 11:8; bits
/// 7:4 reserved, ignored) and TEMP1 (bits 7:0).
pub const fn temp_raw12(temp2: u8, temp1: u8) -> u16 {
    ((temp2 & 0x0F) as u16) << 8 | temp1 as u16
}

/// Die temperature of the accelerometer, °C, from a 12-bit code with the nominal
/// transfer function `25 + (code − 1885) / (−9.05)` (module docs: the intercept varies
/// part to part). Codes outside a plausible range give implausible temperatures (the
/// reset value 0 reads ≈ 233 °C): the caller judges.
pub fn temp_c_from_raw(raw12: u16) -> f32 {
    TEMP_INTERCEPT_C + (f32::from(raw12) - f32::from(TEMP_INTERCEPT_CODE)) / TEMP_SLOPE_LSB_PER_C
}

/// Raw 20-bit codes of the three axes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RawAccel {
    /// X code.
    pub x: i32,
    /// Y code.
    pub y: i32,
    /// Z code.
    pub z: i32,
}

impl RawAccel {
    /// From the nine bytes XDATA3..ZDATA1.
    pub const fn from_bytes(bytes: [u8; 9]) -> Self {
        let [x3, x2, x1, y3, y2, y1, z3, z2, z1] = bytes;
        Self {
            x: raw20_from_bytes([x3, x2, x1]),
            y: raw20_from_bytes([y3, y2, y1]),
            z: raw20_from_bytes([z3, z2, z1]),
        }
    }

    /// Acceleration in m/s² for the given range.
    pub fn to_mps2(self, range: Range) -> [f32; 3] {
        let k = range.mps2_per_lsb();
        [self.x as f32 * k, self.y as f32 * k, self.z as f32 * k]
    }
}

/// One sample read by [`Adxl355::read_sample`].
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AccelSample {
    /// STATUS read in the same burst.
    pub status: Status,
    /// Raw codes.
    pub raw: RawAccel,
    /// X, Y, Z acceleration, m/s².
    pub accel_mps2: [f32; 3],
    /// Temperature code (TEMP2/TEMP1, [`temp_raw12`]) read in the same burst.
    pub temp_raw: u16,
}

impl AccelSample {
    /// The die temperature of the burst, °C ([`temp_c_from_raw`]; not range-checked).
    pub fn temp_c(&self) -> f32 {
        temp_c_from_raw(self.temp_raw)
    }
}

/// ADXL355 driver over an [`SpiDevice`] (SPI mode 0).
#[derive(Debug)]
pub struct Adxl355<SPI> {
    spi: SPI,
    range: Range,
}

impl<SPI: SpiDevice> Adxl355<SPI> {
    /// Wrap an SPI device; no bus traffic. The range is assumed to be the reset default
    /// (±2 g) until [`Adxl355::set_range`].
    pub const fn new(spi: SPI) -> Self {
        Self {
            spi,
            range: Range::G2,
        }
    }

    /// Give the SPI device back.
    pub fn destroy(self) -> SPI {
        self.spi
    }

    /// The range used for conversions (the last one written).
    pub const fn range(&self) -> Range {
        self.range
    }

    fn read_burst(&mut self, start: Register, buf: &mut [u8]) -> Result<(), Error<SPI::Error>> {
        self.spi
            .transaction(&mut [Operation::Write(&[start.read_cmd()]), Operation::Read(buf)])
            .map_err(Error::Spi)
    }

    /// Read one register.
    pub fn read_register(&mut self, reg: Register) -> Result<u8, Error<SPI::Error>> {
        let mut buf = [0u8; 1];
        self.read_burst(reg, &mut buf)?;
        let [v] = buf;
        Ok(v)
    }

    /// Write one register.
    pub fn write_register(&mut self, reg: Register, value: u8) -> Result<(), Error<SPI::Error>> {
        self.spi
            .write(&[reg.write_cmd(), value])
            .map_err(Error::Spi)
    }

    /// Read DEVID_AD, DEVID_MST and PARTID in one burst.
    pub fn read_id(&mut self) -> Result<DeviceId, Error<SPI::Error>> {
        let mut buf = [0u8; 3];
        self.read_burst(Register::DevIdAd, &mut buf)?;
        let [ad, mst, part] = buf;
        Ok(DeviceId { ad, mst, part })
    }

    /// Check the three IDs; a wrong or absent device gives [`Error::BadId`].
    pub fn check_id(&mut self) -> Result<DeviceId, Error<SPI::Error>> {
        let id = self.read_id()?;
        if id.is_adxl355() {
            Ok(id)
        } else {
            Err(Error::BadId {
                ad: id.ad,
                mst: id.mst,
                part: id.part,
            })
        }
    }

    /// Software reset (write [`RESET_CODE`]); the device returns to standby, ±2 g.
    /// Wait for STATUS.NVM_BUSY to clear before configuring.
    pub fn reset(&mut self) -> Result<(), Error<SPI::Error>> {
        self.write_register(Register::Reset, RESET_CODE)?;
        self.range = Range::G2;
        Ok(())
    }

    /// Set the range (write in standby). Writes `RANGE = 0x80 | range`.
    pub fn set_range(&mut self, range: Range) -> Result<(), Error<SPI::Error>> {
        self.write_register(Register::Range, RANGE_UPPER_BITS | range as u8)?;
        self.range = range;
        Ok(())
    }

    /// Set output data rate / low-pass and high-pass corner (write in standby).
    pub fn set_filter(&mut self, odr: Odr, hpf: HighPass) -> Result<(), Error<SPI::Error>> {
        self.write_register(Register::Filter, filter_bits(odr, hpf))
    }

    /// Enter measurement mode (temperature and DRDY on, TEMP_OFF clear):
    /// `POWER_CTL = 0x00` ([`POWER_CTL_MEASURE`]).
    pub fn measure(&mut self) -> Result<(), Error<SPI::Error>> {
        self.write_register(Register::PowerCtl, POWER_CTL_MEASURE)
    }

    /// Enter standby: `POWER_CTL = 0x01`.
    pub fn standby(&mut self) -> Result<(), Error<SPI::Error>> {
        self.write_register(Register::PowerCtl, POWER_CTL_STANDBY)
    }

    /// Read STATUS.
    pub fn status(&mut self) -> Result<Status, Error<SPI::Error>> {
        self.read_register(Register::Status).map(Status)
    }

    /// Check the IDs, go to standby, set range and filter, start measuring (with the
    /// temperature sensor on: POWER_CTL.TEMP_OFF clear).
    pub fn init(
        &mut self,
        range: Range,
        odr: Odr,
        hpf: HighPass,
    ) -> Result<DeviceId, Error<SPI::Error>> {
        let id = self.check_id()?;
        self.standby()?;
        self.set_range(range)?;
        self.set_filter(odr, hpf)?;
        self.measure()?;
        Ok(id)
    }

    /// Read X, Y, Z (XDATA3..ZDATA1) in one burst, without a data-ready check.
    pub fn read_raw(&mut self) -> Result<RawAccel, Error<SPI::Error>> {
        let mut buf = [0u8; 9];
        self.read_burst(Register::XData3, &mut buf)?;
        Ok(RawAccel::from_bytes(buf))
    }

    /// Read the temperature code: TEMP2 and TEMP1 in one burst ([`temp_raw12`]).
    pub fn read_temperature_raw(&mut self) -> Result<u16, Error<SPI::Error>> {
        let mut buf = [0u8; 2];
        self.read_burst(Register::Temp2, &mut buf)?;
        let [t2, t1] = buf;
        Ok(temp_raw12(t2, t1))
    }

    /// Read the die temperature, °C ([`Adxl355::read_temperature_raw`],
    /// [`temp_c_from_raw`]; not range-checked).
    pub fn read_temperature_c(&mut self) -> Result<f32, Error<SPI::Error>> {
        self.read_temperature_raw().map(temp_c_from_raw)
    }

    /// Read STATUS..ZDATA1 (13 bytes, the temperature code included) in one burst;
    /// [`Error::NotReady`] unless STATUS.DATA_RDY is set (and STATUS is plausible).
    /// Converts to m/s².
    pub fn read_sample(&mut self) -> Result<AccelSample, Error<SPI::Error>> {
        let mut buf = [0u8; 13];
        self.read_burst(Register::Status, &mut buf)?;
        let [st, _fifo, t2, t1, x3, x2, x1, y3, y2, y1, z3, z2, z1] = buf;
        let status = Status(st);
        if !status.data_ready() || status.implausible() {
            return Err(Error::NotReady);
        }
        let raw = RawAccel::from_bytes([x3, x2, x1, y3, y2, y1, z3, z2, z1]);
        Ok(AccelSample {
            status,
            raw,
            accel_mps2: raw.to_mps2(self.range),
            temp_raw: temp_raw12(t2, t1),
        })
    }
}
