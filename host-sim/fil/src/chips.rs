//! The chips as the host plays them: the two ADS131M08 lock-in ADCs and the ADXL355
//! (their MISO bytes every tick, from the plant), and the AD9959 (the bytes the firmware
//! wrote, applied at IO_UPDATE), with the faults a scenario injects.

use embedded_hal::spi::{Operation, SpiDevice};
use paragyro_firmware::drivers::ad9959::DEFAULT_SYSCLK_HZ;
use paragyro_firmware::drivers::ads131m08::{CHANNELS, FRAME_BYTES, Frame, RawCode};
use paragyro_firmware::drivers::adxl355::{Range, STANDARD_GRAVITY_MPS2};
use paragyro_firmware::fil::{ACCEL_BURST, FromFw};
use paragyro_firmware::replay::{DdsCapture, Span, accel_bytes, encode_accel, encode_lockin};
use paragyro_firmware::run::calibration;

/// STATUS of a data frame: WLENGTH = 24 bits, the eight DRDY bits.
pub const STATUS_READY: u16 = 0x01FF;
/// STATUS of a frame read before the conversion finished (no DRDY bit).
pub const STATUS_NOT_READY: u16 = 0x0100;
/// ADXL355 STATUS with DATA_RDY.
const XL_DATA_RDY: u8 = 0x01;

/// Faults of a run, by tick (half-open spans; default none).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Faults {
    /// The drive-axis ADC frame's CRC word has one bit flipped.
    pub crc: Span,
    /// DRDY does not come: both ADC frames are read before the conversion (STATUS
    /// without DRDY bits).
    pub no_drdy: Span,
    /// The ADXL355 repeats the burst of the span's first tick.
    pub stuck_accel: Span,
    /// The AD9959's serial port fails every transaction of the tick.
    pub dds_fail: Span,
}

/// The lock-in ADCs' and the accelerometer's MISO bytes.
#[derive(Clone, Debug)]
pub struct SensorChips {
    cal: [paragyro_firmware::drivers::ads131m08::LockinCalibration; 2],
    range: Range,
    faults: Faults,
    held_accel: Option<[u8; ACCEL_BURST]>,
}

impl SensorChips {
    /// Lock-in channels encoded at `um_per_volt` (drive, sense; PGA gain 1), the
    /// accelerometer at `range`.
    pub fn new(um_per_volt: [f32; 2], range: Range, faults: Faults) -> Self {
        Self {
            cal: um_per_volt.map(calibration),
            range,
            faults,
            held_accel: None,
        }
    }

    /// The two ADC frames of tick `k` for the 14 lock-in channels (µm, drive then sense).
    pub fn adc_frames(&self, k: usize, ch: &[f64; 14]) -> [[u8; FRAME_BYTES]; 2] {
        let ready = !self.faults.no_drdy.contains(k);
        let mut out = [[0u8; FRAME_BYTES]; 2];
        for (axis, o) in out.iter_mut().enumerate() {
            let um: [f32; 7] = std::array::from_fn(|i| ch[7 * axis + i] as f32);
            let lockin = encode_lockin(&self.cal[axis], &um);
            let mut codes = [RawCode::default(); CHANNELS];
            codes[..7].copy_from_slice(&lockin);
            let frame = Frame {
                response: if ready {
                    STATUS_READY
                } else {
                    STATUS_NOT_READY
                },
                codes,
            };
            *o = frame.encode();
        }
        if self.faults.crc.contains(k) {
            out[0][FRAME_BYTES - 3] ^= 0x04;
        }
        out
    }

    /// Whether DRDY came at tick `k`.
    pub fn drdy(&self, k: usize) -> bool {
        !self.faults.no_drdy.contains(k)
    }

    /// The STATUS..ZDATA1 burst of tick `k` for X, Y in m/s² (Z: 1 g).
    pub fn accel_burst(&mut self, k: usize, ax: f64, ay: f64) -> [u8; ACCEL_BURST] {
        let mut b = [0u8; ACCEL_BURST];
        b[0] = XL_DATA_RDY;
        for (i, a) in [ax as f32, ay as f32, STANDARD_GRAVITY_MPS2]
            .into_iter()
            .enumerate()
        {
            b[4 + 3 * i..7 + 3 * i].copy_from_slice(&accel_bytes(encode_accel(a, self.range)));
        }
        if self.faults.stuck_accel.contains(k) {
            return *self.held_accel.get_or_insert(b);
        }
        b
    }

    /// Whether the DDS's serial port fails at tick `k`.
    pub fn dds_fails(&self, k: usize) -> bool {
        self.faults.dds_fail.contains(k)
    }
}

/// The AD9959: the register model of `paragyro_firmware::replay::DdsCapture`, fed with
/// the bytes the firmware wrote.
pub struct Dds {
    cap: DdsCapture,
    /// Writes applied so far.
    pub writes: u64,
}

impl Default for Dds {
    fn default() -> Self {
        Self::new()
    }
}

impl Dds {
    /// After a master reset, SYSCLK 500 MHz (the board's).
    pub fn new() -> Self {
        Self {
            cap: DdsCapture::new(DEFAULT_SYSCLK_HZ),
            writes: 0,
        }
    }

    /// Applies one exchange's log in order: writes to the I/O buffers, IO_UPDATE pulses
    /// to the active registers. Returns the number of pulses.
    pub fn apply(&mut self, m: &FromFw) -> anyhow::Result<u32> {
        let mut pulses = 0;
        for e in m.dds_entries() {
            match e {
                Some(bytes) => {
                    let mut spi = self.cap.spi();
                    spi.transaction(&mut [Operation::Write(bytes)])
                        .map_err(|e| anyhow::anyhow!("AD9959 model: {e:?}"))?;
                    self.writes += 1;
                }
                None => {
                    self.cap.pulse();
                    pulses += 1;
                }
            }
        }
        Ok(pulses)
    }

    /// Pump frequency the DDS runs, Hz.
    pub fn pump_hz(&self) -> f64 {
        self.cap.active_pump_hz()
    }

    /// `(ASF/1023)²` of the pump channel.
    pub fn pump_word_scale(&self) -> f64 {
        f64::from(self.cap.active_pump_scale())
    }

    /// The references are phase-locked to the pump (words 2k, k, 3k).
    pub fn phase_locked(&self) -> bool {
        self.cap.active().phase_locked()
    }
}
