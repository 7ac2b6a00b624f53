//! The replayed ADXL355 ([`ReplayAccel`]).

use embedded_hal::spi::{ErrorType, Operation, SpiDevice};

use super::*;

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

/// The 12-bit temperature code nearest to `temp_c` under the driver's nominal transfer
/// function (`adxl355::temp_c_from_raw`: `1885 − 9.05·(T − 25 °C)`, rounded, clamped to
/// 0..=4095). NaN gives 0, the registers' reset value (no temperature).
pub fn encode_temp(temp_c: f64) -> u16 {
    if temp_c.is_nan() {
        return 0;
    }
    let code = f64::from(adxl355::TEMP_INTERCEPT_CODE)
        + (temp_c - f64::from(adxl355::TEMP_INTERCEPT_C))
            * f64::from(adxl355::TEMP_SLOPE_LSB_PER_C);
    u16::try_from(round_i64(code).clamp(0, 0x0FFF)).unwrap_or(0)
}

/// TEMP2, TEMP1 of a 12-bit temperature code (the inverse of `adxl355::temp_raw12`).
pub fn temp_bytes(code: u16) -> [u8; 2] {
    let [hi, lo] = code.to_be_bytes();
    [hi & 0x0F, lo]
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
    temp_raw: u16,
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
            temp_raw: 0,
        }
    }

    /// TEMP2/TEMP1 serve this 12-bit temperature code (`adxl355::temp_raw12`'s inverse;
    /// bits above 11 are dropped). The default is 0, the registers' reset value, which the
    /// firmware reads as no temperature (≈ 233 °C, implausible): a replayed record
    /// carries none.
    pub fn with_temp_raw(mut self, code: u16) -> Self {
        self.temp_raw = code & 0x0FFF;
        put(
            &mut self.regs,
            usize::from(XlReg::Temp2.addr()),
            &temp_bytes(self.temp_raw),
        );
        self
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
            let [t2, t1] = temp_bytes(self.temp_raw);
            // STATUS (DATA_RDY), FIFO_ENTRIES, TEMP2, TEMP1, X, Y, Z
            block = [0x01, 0, t2, t1, x3, x2, x1, y3, y2, y1, z3, z2, z1];
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
