//! The replayed ADS131M08 ([`ReplayAdc`]).

use embedded_hal::spi::{ErrorType, Operation, SpiDevice};

use super::*;

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
