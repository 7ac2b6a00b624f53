//! The capturing AD9959 ([`CaptureDds`], [`DdsCapture`]).

use core::cell::Cell;

use embedded_hal::spi::{ErrorType, Operation, SpiDevice};

use super::*;

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

/// The [`SpiDevice`] side of a [`DdsCapture`]: an AD9959 serial port. A transaction is
/// one chip-select frame of communication cycles, each an instruction byte then as many
/// bytes as its register has ([`register_len`]); a write takes effect when its cycle is
/// complete, an incomplete last cycle is dropped (CS high resets the port).
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

/// Bytes of the AD9959 register at `addr` (datasheet register map: CSR 1, FR1 3, FR2 2,
/// CFR 3, CFTW0 4, CPOW0 2, ACR 3, LSRR 2, RDW/FDW and the profile words 4).
pub const fn register_len(addr: u8) -> usize {
    match addr & 0x1F {
        0x00 => 1,
        0x02 | 0x05 | 0x07 => 2,
        0x01 | 0x03 | 0x06 => 3,
        _ => 4,
    }
}

/// Per-transaction byte-stream state of the AD9959's serial port: the cycle in progress.
struct DdsStream {
    instruction: Option<u8>,
    data: [u8; 4],
    len: usize,
    read: [u8; 4],
}

impl DdsStream {
    fn byte(&mut self, cap: &DdsCapture, mosi: u8) -> u8 {
        let Some(i) = self.instruction else {
            self.instruction = Some(mosi);
            self.len = 0;
            if mosi & 0x80 != 0 {
                self.read = cap.read(mosi & 0x1F);
            }
            return 0;
        };
        let out = if i & 0x80 != 0 {
            self.read.get(self.len).copied().unwrap_or(0)
        } else {
            if let Some(slot) = self.data.get_mut(self.len) {
                *slot = mosi;
            }
            0
        };
        self.len = self.len.saturating_add(1);
        let n = register_len(i);
        if self.len >= n {
            // the cycle is complete: a write takes effect, the next byte is an instruction
            if i & 0x80 == 0
                && let Some(data) = self.data.get(..n)
            {
                cap.write(i & 0x1F, data);
            }
            self.instruction = None;
        }
        out
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
        // an incomplete last cycle is dropped
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
