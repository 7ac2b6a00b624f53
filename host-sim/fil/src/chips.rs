//! The chips as the host plays them: the two ADS131M08 lock-in ADCs and the ADXL355
//! (their MISO bytes every tick, from the plant; the ADXL355's TEMP2/TEMP1 from the
//! scenario's die temperature), and the AD9959 (the bytes the firmware
//! wrote, applied at IO_UPDATE), with the faults a scenario injects.

use embedded_hal::spi::{Operation, SpiDevice};
use paragyro_firmware::drivers::ad9959::DEFAULT_SYSCLK_HZ;
use paragyro_firmware::drivers::ads131m08::{CHANNELS, FRAME_BYTES, Frame, RawCode};
use paragyro_firmware::drivers::adxl355::TEMP_INTERCEPT_CODE;
use paragyro_firmware::drivers::adxl355::{Range, STANDARD_GRAVITY_MPS2};
use paragyro_firmware::fil::{ACCEL_BURST, DdsEntry, FromFw};
use paragyro_firmware::replay::{
    DdsCapture, Span, accel_bytes, encode_accel, encode_lockin, encode_temp, temp_bytes,
};
use paragyro_firmware::run::calibration;

/// STATUS of a data frame: WLENGTH = 24 bits, the eight DRDY bits.
pub const STATUS_READY: u16 = 0x01FF;
/// STATUS of a frame read before the conversion finished (no DRDY bit).
pub const STATUS_NOT_READY: u16 = 0x0100;
/// ADXL355 STATUS with DATA_RDY.
const XL_DATA_RDY: u8 = 0x01;
/// The ADXL355's noise at ODR 500 Hz (bandwidth 125 Hz): 25 µg/√Hz · √125 Hz, m/s² rms
/// (≈ 18 codes at ±8 g).
pub const ACCEL_NOISE_MPS2: f64 = 25e-6 * 9.806_65 * 11.180_339_887;

/// The ADXL355's TEMP2, TEMP1 for the die temperature `temp_c` (°C, the scenario's
/// `[temperature]` profile): the nearest code under the driver's nominal transfer
/// function (`1885 − 9.05·(T − 25 °C)`, clamped to 12 bits; `encode_temp`); without a
/// profile (`None`) the 25 °C code, 1885.
pub fn temp_registers(temp_c: Option<f64>) -> [u8; 2] {
    temp_bytes(temp_c.map_or(TEMP_INTERCEPT_CODE, encode_temp))
}

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
    /// The temperature sensor's white noise, K rms ([`SensorChips::with_temp_noise`]).
    temp_noise_k: f64,
    rng: rand_xoshiro::Xoshiro256PlusPlus,
}

impl SensorChips {
    /// Lock-in channels encoded at `um_per_volt` (drive, sense; PGA gain 1), the
    /// accelerometer at `range` with its noise ([`ACCEL_NOISE_MPS2`], seeded by `seed`).
    pub fn new(um_per_volt: [f32; 2], range: Range, faults: Faults, seed: u64) -> Self {
        use rand::SeedableRng;
        Self {
            cal: um_per_volt.map(calibration),
            range,
            faults,
            held_accel: None,
            temp_noise_k: 0.0,
            rng: rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed ^ 0xADC1_355A),
        }
    }

    /// The temperature sensor's white noise, K rms, added to the die temperature before it
    /// is coded (the scenario's `[temperature] sensor_noise_k`; 0, the default, draws no
    /// random number, so a run without it keeps the accelerometer's noise sequence).
    #[must_use]
    pub fn with_temp_noise(mut self, k_rms: f64) -> Self {
        self.temp_noise_k = if k_rms.is_finite() {
            k_rms.max(0.0)
        } else {
            0.0
        };
        self
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

    /// The STATUS..ZDATA1 burst of tick `k` for X, Y in m/s² (Z: 1 g), with the device's
    /// noise, and the die temperature `temp_c` with the sensor's noise
    /// ([`SensorChips::with_temp_noise`]) in TEMP2, TEMP1 ([`temp_registers`]).
    pub fn accel_burst(
        &mut self,
        k: usize,
        ax: f64,
        ay: f64,
        temp_c: Option<f64>,
    ) -> [u8; ACCEL_BURST] {
        use rand_distr::{Distribution, Normal};
        let noise = Normal::new(0.0, ACCEL_NOISE_MPS2).expect("a finite, positive σ");
        let mut b = [0u8; ACCEL_BURST];
        b[0] = XL_DATA_RDY;
        let temp_c = match temp_c {
            Some(c) if self.temp_noise_k > 0.0 => {
                let n: f64 = rand_distr::StandardNormal.sample(&mut self.rng);
                Some(c + self.temp_noise_k * n)
            }
            other => other,
        };
        b[2..4].copy_from_slice(&temp_registers(temp_c));
        for (i, a) in [ax, ay, f64::from(STANDARD_GRAVITY_MPS2)]
            .into_iter()
            .enumerate()
        {
            let a = (a + noise.sample(&mut self.rng)) as f32;
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
    /// SPI frames applied so far.
    pub writes: u64,
}

impl Default for Dds {
    fn default() -> Self {
        Self::new()
    }
}

impl Dds {
    /// After a master reset, the board's SYSCLK (`DEFAULT_SYSCLK_HZ`, 125 MHz).
    pub fn new() -> Self {
        Self {
            cap: DdsCapture::new(DEFAULT_SYSCLK_HZ),
            writes: 0,
        }
    }

    /// Applies one exchange's log in order: writes to the I/O buffers, IO_UPDATE pulses
    /// to the active registers. Returns the number of pulses and, if the log armed a
    /// pulse for half a period after DRDY, the pump (Hz, `(ASF/1023)²`) the DDS ran
    /// before it (the first half of the interval; [`Dds::pump_hz`] is then the second's).
    pub fn apply(&mut self, m: &FromFw) -> anyhow::Result<(u32, Option<(f64, f64)>)> {
        let mut pulses = 0;
        let mut first_half = None;
        for e in m.dds_entries() {
            match e {
                DdsEntry::Write(bytes) => {
                    let mut spi = self.cap.spi();
                    spi.transaction(&mut [Operation::Write(bytes)])
                        .map_err(|e| anyhow::anyhow!("AD9959 model: {e:?}"))?;
                    self.writes += 1;
                }
                DdsEntry::Pulse => {
                    anyhow::ensure!(
                        first_half.is_none(),
                        "AD9959 model: a pulse now after the half-period pulse"
                    );
                    self.cap.pulse();
                    pulses += 1;
                }
                DdsEntry::HalfPeriodPulse => {
                    anyhow::ensure!(
                        first_half.is_none(),
                        "AD9959 model: two half-period pulses in one tick"
                    );
                    first_half = Some((self.pump_hz(), self.pump_word_scale()));
                    self.cap.pulse();
                    pulses += 1;
                }
            }
        }
        Ok((pulses, first_half))
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

#[cfg(test)]
mod tests {
    use super::*;
    use paragyro_firmware::drivers::ad9959::{Channel, PumpPlan};
    use paragyro_firmware::drivers::ads131m08::Status;
    use paragyro_firmware::drivers::adxl355::{raw20_from_bytes, temp_c_from_raw, temp_raw12};
    use paragyro_firmware::fil::DDS_LOG_BYTES;

    fn channels() -> [f64; 14] {
        std::array::from_fn(|i| (i as f64 - 6.5) * 0.37)
    }

    #[test]
    fn adc_frames_decode_to_the_plant_values_and_faults_show() {
        let faults = Faults {
            crc: Span::at(3),
            no_drdy: Span::at(5),
            ..Faults::default()
        };
        let chips = SensorChips::new([8.0, 4.0], Range::G8, faults, 1);
        let ch = channels();
        let [x, y] = chips.adc_frames(0, &ch);
        for (axis, bytes) in [x, y].iter().enumerate() {
            let f = Frame::decode(bytes).expect("valid CRC");
            assert!(f.status().lockin_ready());
            let cal = calibration([8.0, 4.0][axis]);
            let u = cal.to_um(&f.lockin_codes());
            let um = [
                u.x0_um, u.re_um[0], u.im_um[0], u.re_um[1], u.im_um[1], u.re_um[2], u.im_um[2],
            ];
            for i in 0..7 {
                let step = f64::from(cal.um_per_code[i]);
                assert!((f64::from(um[i]) - ch[7 * axis + i]).abs() <= 0.51 * step);
            }
        }
        // a CRC error on the drive axis only, at tick 3
        let [x, y] = chips.adc_frames(3, &ch);
        assert!(Frame::decode(&x).is_err() && Frame::decode(&y).is_ok());
        // no DRDY at tick 5: both frames valid but not ready
        let [x, y] = chips.adc_frames(5, &ch);
        for b in [x, y] {
            let f = Frame::decode(&b).unwrap();
            assert_eq!(f.status(), Status(STATUS_NOT_READY));
            assert!(!f.status().lockin_ready());
        }
        assert!(!chips.drdy(5) && chips.drdy(4));
    }

    #[test]
    fn accel_burst_encodes_and_a_stuck_accelerometer_repeats() {
        let faults = Faults {
            stuck_accel: Span::new(2, 4),
            ..Faults::default()
        };
        let mut chips = SensorChips::new([8.0, 4.0], Range::G8, faults, 1);
        let b = chips.accel_burst(0, 39.2266, -12.0, None);
        assert_eq!(b[0] & 1, 1);
        let lsb = f64::from(Range::G8.mps2_per_lsb());
        let x = f64::from(raw20_from_bytes([b[4], b[5], b[6]])) * lsb;
        let y = f64::from(raw20_from_bytes([b[7], b[8], b[9]])) * lsb;
        let tol = 5.0 * ACCEL_NOISE_MPS2 + lsb;
        assert!((x - 39.2266).abs() <= tol && (y + 12.0).abs() <= tol);
        // noisy: two reads of the same acceleration differ
        assert_ne!(
            chips.accel_burst(1, 39.2266, -12.0, None),
            chips.accel_burst(1, 39.2266, -12.0, None)
        );
        let held = chips.accel_burst(2, 1.0, 1.0, Some(30.0));
        assert_eq!(chips.accel_burst(3, 5.0, 5.0, Some(31.0)), held);
        assert_ne!(chips.accel_burst(4, 5.0, 5.0, Some(31.0)), held);
    }

    /// TEMP2/TEMP1 of the model: the datasheet's 25 °C code without a profile, the nearest
    /// code under the driver's transfer function with one (the code falling as the die
    /// warms), TEMP2's upper nibble clear, the 12-bit range's ends where it clips.
    #[test]
    fn temperature_registers_encode_the_scenario_temperature() {
        let code = |t: Option<f64>| {
            let [t2, t1] = temp_registers(t);
            assert_eq!(t2 & 0xF0, 0, "TEMP2 bits 7:4 are reserved");
            temp_raw12(t2, t1)
        };
        assert_eq!(temp_registers(None), [0x07, 0x5D]);
        assert_eq!(code(None), 1885);
        assert_eq!(code(Some(25.0)), 1885);
        // 9.05 codes per kelvin, falling: 35 °C → 1885 − 90.5 → 1794 or 1795
        assert!((1794..=1795).contains(&code(Some(35.0))));
        assert!(code(Some(35.0)) < code(Some(34.0)) && code(Some(-10.0)) > 1885);
        // within half a code of the temperature, decoded by the firmware's driver
        for i in 0..=400 {
            let t = -40.0 + 0.3137 * f64::from(i);
            let back = f64::from(temp_c_from_raw(code(Some(t))));
            assert!((back - t).abs() <= 0.5 / 9.05 + 1e-4, "{t} °C → {back} °C");
        }
        // the code clips at the 12-bit range's ends
        assert_eq!(code(Some(-400.0)), 0x0FFF);
        assert_eq!(code(Some(400.0)), 0);
        // the burst carries them at TEMP2, TEMP1 (bytes 2, 3 after STATUS, FIFO_ENTRIES)
        let mut chips = SensorChips::new([8.0, 4.0], Range::G8, Faults::default(), 1);
        let b = chips.accel_burst(0, 0.0, 0.0, Some(45.0));
        assert_eq!([b[2], b[3]], temp_registers(Some(45.0)));
        let b = chips.accel_burst(1, 0.0, 0.0, None);
        assert_eq!([b[2], b[3]], [0x07, 0x5D]);
    }

    /// A plan for `hz` and the DDS log that writes its three words (CSR, CFTW0 each).
    fn plan_log(hz: f64) -> (PumpPlan, Vec<u8>) {
        let plan = PumpPlan::new(hz, DEFAULT_SYSCLK_HZ).unwrap();
        let mut log = Vec::new();
        for (ch, ftw) in [
            (Channel::PUMP, plan.pump_ftw()),
            (Channel::REFERENCE, plan.reference_ftw()),
            (Channel::THIRD, plan.third_ftw()),
        ] {
            log.extend_from_slice(&[2, 0x00, ch.csr_enable() | 0x02]);
            log.push(5);
            log.push(0x04);
            log.extend_from_slice(&ftw.to_be_bytes());
        }
        (plan, log)
    }

    #[test]
    fn the_dds_model_applies_words_at_io_update_only() {
        let (plan, log) = plan_log(21_900.0);
        let mut m = FromFw::EMPTY;
        m.dds_log[..log.len()].copy_from_slice(&log);
        m.dds_log_len = log.len() as u16;
        let mut dds = Dds::new();
        assert_eq!(dds.apply(&m).unwrap(), (0, None));
        assert_eq!(dds.pump_hz(), 0.0, "buffered, not active before IO_UPDATE");
        m.dds_log[log.len()] = 0;
        m.dds_log_len += 1;
        assert!(usize::from(m.dds_log_len) <= DDS_LOG_BYTES);
        let mut dds = Dds::new();
        assert_eq!(dds.apply(&m).unwrap(), (1, None));
        assert_eq!(dds.pump_hz(), plan.pump_hz());
        assert!(dds.phase_locked());
    }

    #[test]
    fn a_half_period_pulse_splits_the_interval() {
        let (a, mut log) = plan_log(21_900.0);
        log.push(0);
        let (b, log_b) = plan_log(21_901.0);
        log.extend_from_slice(&log_b);
        log.push(paragyro_firmware::fil::HALF_PERIOD_PULSE);
        let mut m = FromFw::EMPTY;
        m.dds_log[..log.len()].copy_from_slice(&log);
        m.dds_log_len = log.len() as u16;
        let mut dds = Dds::new();
        let (pulses, first) = dds.apply(&m).unwrap();
        assert_eq!(pulses, 2);
        assert_eq!(first.map(|f| f.0), Some(a.pump_hz()), "first half");
        assert_eq!(dds.pump_hz(), b.pump_hz(), "second half");
        assert!(dds.phase_locked());
    }
}
