//! Firmware in the loop: the wire format between the `fil` board (QEMU) and the host
//! process that plays the chips (`paragyro-fil`, host-sim/fil), and the board's SPI shims.
//!
//! # The exchange
//!
//! The board opens two named pipes through semihosting file I/O (TOOLCHAIN.md §3.1): it
//! reads `fil_to_fw` and writes `fil_from_fw`. First the host sends an [`Init`] (the core
//! configuration as [`crate::table`] slots, the lock-in calibrations, the pump guard and
//! amplitude mapping); the board initialises its chips through the real drivers, builds
//! the [`App`](crate::app::App), starts the pump and answers with a [`FromFw`] carrying
//! the DDS bytes of the set-up. Then **one exchange per tick**: the host sends a [`ToFw`]
//! (the tick's two ADS131M08 frames as the chips put them on MISO, with STATUS and CRC,
//! the ADXL355's STATUS..ZDATA1 burst, whether DRDY came, whether the DDS's serial port
//! fails this tick, and the control events of the tick), the board runs the unchanged
//! [`App::tick`](crate::app::App::tick) over the shims below and answers with a
//! [`FromFw`]: every byte the firmware wrote to the AD9959 in this tick, in order, with
//! the IO_UPDATE pulses in between, plus the tick's outputs for the host's verdict.
//!
//! # The shims
//!
//! [`FilAdc`], [`FilAccel`], [`FilDds`] and [`FilIo`] are the board's `SpiDevice`s and
//! IO_UPDATE line: during a tick they only move bytes between the drivers and the
//! [`FilBus`] (the chips are the host's). During set-up, before [`FilBus::set_live`], the
//! ADCs and the accelerometer answer the drivers' initialisation from the local register
//! models of [`crate::replay`]; the DDS logs its bytes from the start, so the host's
//! AD9959 sees the whole session.
//!
//! # Counting instructions without the shims
//!
//! Every shim call is bracketed by [`fake_enter`] and [`fake_exit`], and the tick by
//! [`tick_begin`] and [`tick_end`]: four never-inlined functions with distinct bodies.
//! The QEMU plugin `firmware/tools/tickcount.c` counts, per tick, the instructions
//! executed between `tick_begin` and `tick_end` outside `fake_enter`..`fake_exit`: the
//! firmware's own cost, exact, without the fake chips (what remains of a shim is the
//! call into it, a few instructions, where the real board calls its HAL).

use core::cell::Cell;
use core::sync::atomic::{AtomicU8, Ordering};

use embedded_hal::spi::{ErrorType, Operation, SpiDevice};
use paragyro_core::{Config, Estimator};

use crate::app::IoUpdate;
use crate::drivers::ads131m08::{FRAME_BYTES, LockinCalibration};
use crate::replay::{ReplayAccel, ReplayAdc, ReplayError};
use crate::table::{CFG_SLOTS, config_from_slots, control};

/// Bytes of the ADXL355's STATUS..ZDATA1 burst the driver reads each tick.
pub const ACCEL_BURST: usize = 13;
/// Capacity of the DDS byte log of one exchange.
pub const DDS_LOG_BYTES: usize = 192;
/// The DDS log's marker of an IO_UPDATE pulse half a period after DRDY (a write's length
/// byte is at most a few bytes; 0 marks a pulse now).
pub const HALF_PERIOD_PULSE: u8 = 0xFF;
/// Identical ADXL355 X and Y codes in a row that the `fil` board refuses as stuck (the
/// host's accelerometer carries the ADXL355's noise).
pub const ACCEL_STUCK_READS: u32 = 8;
/// Control events one tick can carry.
pub const MAX_TICK_CONTROLS: usize = 2;
/// First bytes of an [`Init`].
pub const INIT_MAGIC: [u8; 4] = *b"FIL1";
/// Length of an encoded [`Init`].
pub const INIT_BYTES: usize = 4 + 8 * CFG_SLOTS + 4 + 4 + 4 + 4 + 8 + 4 + 4;
/// Length of an encoded [`ToFw`].
pub const TO_FW_BYTES: usize = 4 + 1 + 1 + 12 * MAX_TICK_CONTROLS + 2 * FRAME_BYTES + ACCEL_BURST;
/// Length of an encoded [`FromFw`].
pub const FROM_FW_BYTES: usize = 4 + 8 + 4 + 5 * 8 + (COUNTERS + 3) * 4 + 2 + DDS_LOG_BYTES;
/// [`FromFw::tick`] of the set-up answer.
pub const TICK_SETUP: u32 = u32::MAX;
/// [`FromFw::tick`] of the answer to the end message.
pub const TICK_END: u32 = u32::MAX - 1;

/// Bits of [`Init::flags`].
pub mod init_flag {
    /// Two DDS steps per sample ([`crate::app::App::set_half_steps`]).
    pub const HALF_STEPS: u32 = 1;
}

/// Bits of [`ToFw::flags`].
pub mod flag {
    /// The run is over: the board answers with its counters and exits.
    pub const END: u8 = 1;
    /// DRDY did not come this tick (the board counts it and runs the tick anyway).
    pub const NO_DRDY: u8 = 2;
    /// The AD9959's serial port fails every transaction of this tick.
    pub const DDS_FAIL: u8 = 4;
}

/// Little-endian writer over a byte slice (bytes beyond its end are dropped).
struct Put<'a> {
    buf: &'a mut [u8],
    pos: usize,
}

impl Put<'_> {
    fn bytes(&mut self, b: &[u8]) {
        for x in b {
            if let Some(s) = self.buf.get_mut(self.pos) {
                *s = *x;
            }
            self.pos = self.pos.saturating_add(1);
        }
    }
    fn u8(&mut self, v: u8) {
        self.bytes(&[v]);
    }
    fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.bytes(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.bytes(&v.to_le_bytes());
    }
}

/// Little-endian reader over a byte slice (zeros beyond its end).
struct Get<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl Get<'_> {
    fn array<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        for o in out.iter_mut() {
            *o = self.buf.get(self.pos).copied().unwrap_or(0);
            self.pos = self.pos.saturating_add(1);
        }
        out
    }
    fn u8(&mut self) -> u8 {
        let [v] = self.array::<1>();
        v
    }
    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.array())
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.array())
    }
    fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.array())
    }
    fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.array())
    }
}

/// The session's set-up, host → board.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Init {
    /// The core configuration ([`crate::table::config_slots`]).
    pub cfg_slots: [f64; CFG_SLOTS],
    /// µm per volt at the ADC input of the drive and sense lock-in channels (PGA gain 1).
    pub um_per_volt: [f32; 2],
    /// ADXL355 range bits (1: ±2 g, 2: ±4 g, 3: ±8 g).
    pub accel_range_bits: u32,
    /// Board options ([`init_flag`]).
    pub flags: u32,
    /// Half-width of the pump guard around the configured centre, Hz.
    pub guard_half_width_hz: f64,
    /// Pump scale of the amplitude mapping's base and of the full DDS word.
    pub amplitude: [f32; 2],
}

impl Init {
    /// The wire bytes.
    pub fn encode(&self) -> [u8; INIT_BYTES] {
        let mut b = [0u8; INIT_BYTES];
        let mut p = Put {
            buf: &mut b,
            pos: 0,
        };
        p.bytes(&INIT_MAGIC);
        for v in self.cfg_slots {
            p.f64(v);
        }
        p.f32(self.um_per_volt[0]);
        p.f32(self.um_per_volt[1]);
        p.u32(self.accel_range_bits);
        p.u32(self.flags);
        p.f64(self.guard_half_width_hz);
        p.f32(self.amplitude[0]);
        p.f32(self.amplitude[1]);
        b
    }

    /// From the wire bytes; `None` without the magic.
    pub fn decode(b: &[u8; INIT_BYTES]) -> Option<Self> {
        let mut g = Get { buf: b, pos: 0 };
        if g.array::<4>() != INIT_MAGIC {
            return None;
        }
        let mut cfg_slots = [0.0; CFG_SLOTS];
        for s in cfg_slots.iter_mut() {
            *s = g.f64();
        }
        let um_per_volt = [g.f32(), g.f32()];
        let accel_range_bits = g.u32();
        let flags = g.u32();
        let guard_half_width_hz = g.f64();
        let amplitude = [g.f32(), g.f32()];
        Some(Self {
            cfg_slots,
            um_per_volt,
            accel_range_bits,
            flags,
            guard_half_width_hz,
            amplitude,
        })
    }

    /// The core configuration of the slots.
    pub fn config(&self) -> Config {
        config_from_slots(|i| self.cfg_slots.get(i).copied().unwrap_or(f64::NAN))
    }
}

/// One tick's chip data, host → board.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToFw {
    /// Tick number.
    pub tick: u32,
    /// [`flag`] bits.
    pub flags: u8,
    /// Control events for the core before this tick: (kind of [`control`], value).
    pub controls: [(u32, f64); MAX_TICK_CONTROLS],
    /// How many of `controls` are set.
    pub n_controls: u8,
    /// MISO of the drive- and sense-axis ADS131M08 data frames.
    pub adc: [[u8; FRAME_BYTES]; 2],
    /// MISO of the ADXL355 STATUS..ZDATA1 burst.
    pub accel: [u8; ACCEL_BURST],
}

impl ToFw {
    /// The wire bytes.
    pub fn encode(&self) -> [u8; TO_FW_BYTES] {
        let mut b = [0u8; TO_FW_BYTES];
        let mut p = Put {
            buf: &mut b,
            pos: 0,
        };
        p.u32(self.tick);
        p.u8(self.flags);
        p.u8(self.n_controls);
        for (k, v) in self.controls {
            p.u32(k);
            p.f64(v);
        }
        p.bytes(&self.adc[0]);
        p.bytes(&self.adc[1]);
        p.bytes(&self.accel);
        b
    }

    /// From the wire bytes.
    pub fn decode(b: &[u8; TO_FW_BYTES]) -> Self {
        let mut g = Get { buf: b, pos: 0 };
        let tick = g.u32();
        let flags = g.u8();
        let n_controls = g.u8();
        let mut controls = [(0, 0.0); MAX_TICK_CONTROLS];
        for c in controls.iter_mut() {
            *c = (g.u32(), g.f64());
        }
        Self {
            tick,
            flags,
            controls,
            n_controls,
            adc: [g.array(), g.array()],
            accel: g.array(),
        }
    }
}

/// The firmware's counters the host reports (firmware and core).
pub const COUNTERS: usize = 12;

/// One tick's outcome, board → host.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FromFw {
    /// Tick number ([`TICK_SETUP`], [`TICK_END`] for the set-up and end answers).
    pub tick: u32,
    /// `TickReport::faults`, `sample_ok`, core `inputs_valid`, `updated`, `events`.
    pub faults: u8,
    /// The firmware delivered a complete sample.
    pub sample_ok: bool,
    /// The core's verdict on the sample.
    pub inputs_valid: bool,
    /// The core updated θ̂.
    pub updated: bool,
    /// Core event bits.
    pub events: u8,
    /// Core health bits.
    pub health: u32,
    /// The core's pump command and scale multiplier for the next sample.
    pub pump_hz_next: f64,
    /// Scale multiplier command.
    pub pump_scale_next: f64,
    /// The pump the App believes in effect after the tick, Hz.
    pub pump_hz: f64,
    /// ω̂y².
    pub wy2: f64,
    /// Rate estimate, °/s.
    pub rate_dps: f64,
    /// The rate's own validity flag (`RateOutput::valid`).
    pub rate_valid: bool,
    /// Firmware counters (ADC SPI, CRC, not ready, saturated; accel errors, saturated;
    /// DDS errors, guard clamps), DRDY missing, core retunes, core bad samples, accelerometer
    /// samples refused as stuck.
    pub counters: [u32; COUNTERS],
    /// When the tick pulsed IO_UPDATE (its last action, `App::tick` step 5): SysTick
    /// instructions (±6) from the tick's start to its end, shims included, i.e. when the
    /// new words take effect after DRDY; 0 when it did not pulse.
    pub pulse_at_insns: u32,
    /// SysTick instructions (±6) of the whole tick, shims included.
    pub tick_insns: u32,
    /// The stack's high-water mark since boot, bytes (painted stack; in the end answer).
    pub stack_peak: u32,
    /// The DDS log: `len` then `len` bytes per write, `0` for an IO_UPDATE pulse.
    pub dds_log: [u8; DDS_LOG_BYTES],
    /// Bytes of `dds_log` used.
    pub dds_log_len: u16,
}

impl FromFw {
    /// Nothing yet.
    pub const EMPTY: FromFw = FromFw {
        tick: 0,
        faults: 0,
        sample_ok: false,
        inputs_valid: false,
        updated: false,
        events: 0,
        health: 0,
        pump_hz_next: f64::NAN,
        pump_scale_next: f64::NAN,
        pump_hz: f64::NAN,
        wy2: f64::NAN,
        rate_dps: f64::NAN,
        rate_valid: false,
        counters: [0; COUNTERS],
        pulse_at_insns: 0,
        tick_insns: 0,
        stack_peak: 0,
        dds_log: [0; DDS_LOG_BYTES],
        dds_log_len: 0,
    };

    /// The wire bytes.
    pub fn encode(&self) -> [u8; FROM_FW_BYTES] {
        let mut b = [0u8; FROM_FW_BYTES];
        let mut p = Put {
            buf: &mut b,
            pos: 0,
        };
        p.u32(self.tick);
        p.bytes(&[
            self.faults,
            u8::from(self.sample_ok),
            u8::from(self.inputs_valid),
            u8::from(self.updated),
            self.events,
            u8::from(self.rate_valid),
            0,
            0,
        ]);
        p.u32(self.health);
        for v in [
            self.pump_hz_next,
            self.pump_scale_next,
            self.pump_hz,
            self.wy2,
            self.rate_dps,
        ] {
            p.f64(v);
        }
        for c in self.counters {
            p.u32(c);
        }
        p.u32(self.pulse_at_insns);
        p.u32(self.tick_insns);
        p.u32(self.stack_peak);
        p.u16(self.dds_log_len);
        p.bytes(&self.dds_log);
        b
    }

    /// From the wire bytes.
    pub fn decode(b: &[u8; FROM_FW_BYTES]) -> Self {
        let mut g = Get { buf: b, pos: 0 };
        let tick = g.u32();
        let [faults, ok, valid, updated, events, rate_valid, _, _] = g.array::<8>();
        let health = g.u32();
        let pump_hz_next = g.f64();
        let pump_scale_next = g.f64();
        let pump_hz = g.f64();
        let wy2 = g.f64();
        let rate_dps = g.f64();
        let mut counters = [0; COUNTERS];
        for c in counters.iter_mut() {
            *c = g.u32();
        }
        let pulse_at_insns = g.u32();
        let tick_insns = g.u32();
        let stack_peak = g.u32();
        let dds_log_len = g.u16();
        Self {
            tick,
            faults,
            sample_ok: ok != 0,
            inputs_valid: valid != 0,
            updated: updated != 0,
            events,
            health,
            pump_hz_next,
            pump_scale_next,
            pump_hz,
            wy2,
            rate_dps,
            rate_valid: rate_valid != 0,
            counters,
            pulse_at_insns,
            tick_insns,
            stack_peak,
            dds_log: g.array(),
            dds_log_len,
        }
    }

    /// The DDS log's entries in order: writes and IO_UPDATE pulses.
    pub fn dds_entries(&self) -> DdsEntries<'_> {
        let len = usize::from(self.dds_log_len).min(DDS_LOG_BYTES);
        DdsEntries {
            log: self.dds_log.get(..len).unwrap_or(&[]),
        }
    }
}

/// One entry of a DDS log.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DdsEntry<'a> {
    /// The bytes of one SPI write.
    Write(&'a [u8]),
    /// IO_UPDATE pulsed now.
    Pulse,
    /// IO_UPDATE armed for half a sample period after DRDY.
    HalfPeriodPulse,
}

/// Iterator over a DDS log ([`FromFw::dds_entries`]).
#[derive(Debug)]
pub struct DdsEntries<'a> {
    log: &'a [u8],
}

impl<'a> Iterator for DdsEntries<'a> {
    type Item = DdsEntry<'a>;
    fn next(&mut self) -> Option<Self::Item> {
        let (&n, rest) = self.log.split_first()?;
        if n == 0 || n == HALF_PERIOD_PULSE {
            self.log = rest;
            return Some(if n == 0 {
                DdsEntry::Pulse
            } else {
                DdsEntry::HalfPeriodPulse
            });
        }
        let n = usize::from(n).min(rest.len());
        let (w, rest) = rest.split_at(n);
        self.log = rest;
        Some(DdsEntry::Write(w))
    }
}

/// Gives the core one control event ([`control`] kinds); false for an unknown kind.
pub fn apply_control(est: &mut Estimator<f32>, kind: u32, value: f64) -> bool {
    match kind {
        control::DITHER => est.set_dither(value != 0.0),
        // a refused value (out of range) changes nothing, as the core documents
        control::DITHER_PUMP_HZ => {
            let _ = est.set_dither_pump_hz(value);
        }
        control::RETUNE => est.set_retune(value != 0.0),
        control::PUMP_JUMP_HZ => {
            let _ = est.command_pump_centre(value, true);
        }
        _ => return false,
    }
    true
}

/// Written by the markers (and made observable with `black_box`, so that neither the
/// stores nor the calls are optimised away).
static MARK: AtomicU8 = AtomicU8::new(0);

/// Marker: a shim starts (the plugin stops counting). Never inlined, distinct body.
#[inline(never)]
pub fn fake_enter() {
    MARK.store(1, Ordering::Relaxed);
    core::hint::black_box(&MARK);
}

/// Marker: a shim ends (the plugin counts again).
#[inline(never)]
pub fn fake_exit() {
    MARK.store(2, Ordering::Relaxed);
    core::hint::black_box(&MARK);
}

/// Marker: the tick starts (`App::tick` follows).
#[inline(never)]
pub fn tick_begin() {
    MARK.store(3, Ordering::Relaxed);
    core::hint::black_box(&MARK);
}

/// Marker: the tick ended.
#[inline(never)]
pub fn tick_end() {
    MARK.store(4, Ordering::Relaxed);
    core::hint::black_box(&MARK);
}

/// What the shims share with the board: this tick's MISO bytes and the DDS log.
#[derive(Debug)]
pub struct FilBus {
    live: Cell<bool>,
    adc: [Cell<[u8; FRAME_BYTES]>; 2],
    accel: Cell<[u8; ACCEL_BURST]>,
    dds_fail: Cell<bool>,
    log: Cell<[u8; DDS_LOG_BYTES]>,
    log_len: Cell<usize>,
    overflow: Cell<bool>,
}

impl Default for FilBus {
    fn default() -> Self {
        Self::new()
    }
}

impl FilBus {
    /// Set-up mode, empty log.
    pub const fn new() -> Self {
        Self {
            live: Cell::new(false),
            adc: [Cell::new([0; FRAME_BYTES]), Cell::new([0; FRAME_BYTES])],
            accel: Cell::new([0; ACCEL_BURST]),
            dds_fail: Cell::new(false),
            log: Cell::new([0; DDS_LOG_BYTES]),
            log_len: Cell::new(0),
            overflow: Cell::new(false),
        }
    }

    /// From now on the ADC and accelerometer shims serve the host's bytes.
    pub fn set_live(&self, live: bool) {
        self.live.set(live);
    }

    /// Loads a tick's MISO bytes and the DDS fault flag.
    pub fn load(&self, m: &ToFw) {
        let [x, y] = m.adc;
        let [a, b] = &self.adc;
        a.set(x);
        b.set(y);
        self.accel.set(m.accel);
        self.dds_fail.set(m.flags & flag::DDS_FAIL != 0);
    }

    fn log_push(&self, bytes: &[u8]) {
        let mut log = self.log.get();
        let mut n = self.log_len.get();
        for b in bytes {
            match log.get_mut(n) {
                Some(s) => {
                    *s = *b;
                    n = n.saturating_add(1);
                }
                None => self.overflow.set(true),
            }
        }
        self.log.set(log);
        self.log_len.set(n);
    }

    /// An IO_UPDATE pulse, in order with the writes.
    pub fn pulse(&self) {
        self.log_push(&[0]);
    }

    /// An IO_UPDATE pulse armed for half a sample period after DRDY (the log's order:
    /// after this tick's writes).
    pub fn pulse_half(&self) {
        self.log_push(&[HALF_PERIOD_PULSE]);
    }

    /// Moves the DDS log into `out` and empties it; false if it overflowed since the
    /// last take (the host then sees an incomplete log and fails the run).
    pub fn take_log(&self, out: &mut FromFw) -> bool {
        out.dds_log = self.log.get();
        out.dds_log_len = u16::try_from(self.log_len.get()).unwrap_or(u16::MAX);
        self.log_len.set(0);
        !self.overflow.replace(false)
    }
}

/// Copies `src` into the read buffers of `ops` in order.
fn serve(ops: &mut [Operation<'_, u8>], src: &[u8]) {
    let mut pos = 0usize;
    for op in ops.iter_mut() {
        let dst: &mut [u8] = match op {
            Operation::Read(b) | Operation::TransferInPlace(b) => b,
            Operation::Transfer(r, _) => r,
            Operation::Write(_) | Operation::DelayNs(_) => continue,
        };
        for d in dst.iter_mut() {
            *d = src.get(pos).copied().unwrap_or(0);
            pos = pos.saturating_add(1);
        }
    }
}

/// The board's ADS131M08 (one axis): the host's frame during ticks.
#[derive(Debug)]
pub struct FilAdc<'a> {
    bus: &'a FilBus,
    axis: usize,
    setup: ReplayAdc<'static>,
}

impl<'a> FilAdc<'a> {
    /// Axis 0 (drive) or 1 (sense) of `bus`.
    pub const fn new(bus: &'a FilBus, axis: usize) -> Self {
        Self {
            bus,
            axis,
            setup: ReplayAdc::new(&[], LockinCalibration::UNITY),
        }
    }
}

impl ErrorType for FilAdc<'_> {
    type Error = ReplayError;
}

impl SpiDevice for FilAdc<'_> {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), ReplayError> {
        fake_enter();
        let r = if self.bus.live.get() {
            let frame = self
                .bus
                .adc
                .get(self.axis)
                .map_or([0; FRAME_BYTES], Cell::get);
            serve(ops, &frame);
            Ok(())
        } else {
            self.setup.transaction(ops)
        };
        fake_exit();
        r
    }
}

/// The board's ADXL355: the host's burst during ticks.
#[derive(Debug)]
pub struct FilAccel<'a> {
    bus: &'a FilBus,
    setup: ReplayAccel<'static>,
}

impl<'a> FilAccel<'a> {
    /// On `bus`.
    pub fn new(bus: &'a FilBus) -> Self {
        Self {
            bus,
            setup: ReplayAccel::new(&[]),
        }
    }
}

impl ErrorType for FilAccel<'_> {
    type Error = ReplayError;
}

impl SpiDevice for FilAccel<'_> {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), ReplayError> {
        fake_enter();
        let r = if self.bus.live.get() {
            serve(ops, &self.bus.accel.get());
            Ok(())
        } else {
            self.setup.transaction(ops)
        };
        fake_exit();
        r
    }
}

/// The board's AD9959: logs every byte written (the host's AD9959 applies them).
#[derive(Debug)]
pub struct FilDds<'a> {
    bus: &'a FilBus,
}

impl<'a> FilDds<'a> {
    /// On `bus`.
    pub const fn new(bus: &'a FilBus) -> Self {
        Self { bus }
    }
}

impl ErrorType for FilDds<'_> {
    type Error = ReplayError;
}

impl SpiDevice for FilDds<'_> {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), ReplayError> {
        fake_enter();
        let r = if self.bus.dds_fail.get() {
            Err(ReplayError)
        } else {
            // one transaction = one frame of register cycles (at most 27 bytes:
            // `Ad9959::write_pump`)
            let mut buf = [0u8; 32];
            let mut n = 0usize;
            for op in ops.iter_mut() {
                match op {
                    Operation::Write(w) => {
                        for b in w.iter() {
                            if let Some(s) = buf.get_mut(n) {
                                *s = *b;
                                n = n.saturating_add(1);
                            }
                        }
                    }
                    Operation::Read(b) | Operation::TransferInPlace(b) => b.fill(0),
                    Operation::Transfer(r, _) => r.fill(0),
                    Operation::DelayNs(_) => {}
                }
            }
            if n > 0 {
                let len = [u8::try_from(n).unwrap_or(0)];
                self.bus.log_push(&len);
                self.bus.log_push(buf.get(..n).unwrap_or(&[]));
            }
            Ok(())
        };
        fake_exit();
        r
    }
}

/// The board's IO_UPDATE line: logged in order with the writes.
#[derive(Debug)]
pub struct FilIo<'a> {
    bus: &'a FilBus,
    /// Pulses so far.
    pub pulses: u32,
}

impl<'a> FilIo<'a> {
    /// On `bus`.
    pub const fn new(bus: &'a FilBus) -> Self {
        Self { bus, pulses: 0 }
    }
}

impl IoUpdate for FilIo<'_> {
    fn pulse(&mut self) {
        fake_enter();
        self.bus.pulse();
        self.pulses = self.pulses.saturating_add(1);
        fake_exit();
    }

    fn pulse_at_half_period(&mut self) -> bool {
        fake_enter();
        self.bus.pulse_half();
        self.pulses = self.pulses.saturating_add(1);
        fake_exit();
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_round_trip() {
        let init = Init {
            cfg_slots: core::array::from_fn(|i| i as f64 * 1.5),
            um_per_volt: [8.0, 4.0],
            accel_range_bits: 3,
            flags: init_flag::HALF_STEPS,
            guard_half_width_hz: 400.0,
            amplitude: [1.0, 1.5625],
        };
        assert_eq!(Init::decode(&init.encode()), Some(init));
        let m = ToFw {
            tick: 7,
            flags: flag::NO_DRDY,
            controls: [(1, 0.0), (2, 21.6)],
            n_controls: 2,
            adc: [[3; FRAME_BYTES], [9; FRAME_BYTES]],
            accel: [5; ACCEL_BURST],
        };
        assert_eq!(ToFw::decode(&m.encode()), m);
        let mut f = FromFw::EMPTY;
        f.tick = 3;
        f.wy2 = 1.03;
        f.counters[4] = 17;
        f.rate_valid = true;
        f.dds_log[..5].copy_from_slice(&[2, 0x00, 0xF2, 0, HALF_PERIOD_PULSE]);
        f.dds_log_len = 5;
        let g = FromFw::decode(&f.encode());
        assert_eq!(g.tick, 3);
        assert_eq!(g.counters, f.counters);
        assert!(g.rate_valid);
        let e: Vec<_> = g.dds_entries().collect();
        assert_eq!(
            e,
            vec![
                DdsEntry::Write(&[0x00u8, 0xF2][..]),
                DdsEntry::Pulse,
                DdsEntry::HalfPeriodPulse
            ]
        );
    }
}
