//! The fuzz harnesses: each takes arbitrary bytes, must never panic, and checks what its
//! code promises. The libFuzzer targets (`fuzz_targets/`) and the corpus test
//! (`tests/corpus.rs`) call the same functions.

pub mod diagnosis;
pub use diagnosis::diagnosis;

use paragyro_core::{Config, Cplx, Estimator, Lockin, Sample};
use paragyro_firmware::drivers::ads131m08::{FRAME_BYTES, Frame};
use paragyro_simulator::record::{parse_record, read_record_from};
use paragyro_simulator::runner::core_config;
use paragyro_simulator::scenario::Scenario;

/// The record reader on any text (and on any bytes through its `BufRead` entry): a
/// record or an error, never a panic; a record it accepts holds only finite samples
/// at the declared rate.
pub fn record_reader(data: &[u8]) {
    let _ = read_record_from(std::io::BufReader::new(data), "fuzz");
    if let Ok(text) = std::str::from_utf8(data)
        && let Ok(rec) = parse_record(text, "fuzz")
    {
        assert!(rec.header.fs_hz.is_finite() && rec.header.fs_hz > 0.0);
        let _ = rec.duration_s();
    }
}

/// The scenario parser on any text: a scenario or an error, never a panic; a scenario
/// it accepts validates, and its core configuration validates or is refused cleanly.
pub fn scenario_parser(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(sc) = Scenario::from_toml_str(text, "fuzz.toml") {
        assert!(sc.validate().is_ok(), "a parsed scenario does not validate");
        let _ = core_config(&sc).validated();
        let _ = sc.plant_at(0.5 * sc.duration_s);
    }
}

/// The ADS131M08 frame decoder on any 30 bytes: a frame or a CRC error, never a panic;
/// a decoded frame encodes to bytes that decode to the same frame.
pub fn ads131m08_frame(data: &[u8]) {
    let Some(bytes) = data.first_chunk::<FRAME_BYTES>() else {
        return;
    };
    if let Ok(f) = Frame::decode(bytes) {
        assert_eq!(Frame::decode(&f.encode()), Ok(f));
        let _ = (f.saturated_mask(), f.lockin_codes(), f.status());
    }
}

/// Reads little-endian values off the input, zero when it runs out.
pub(crate) struct Bytes<'a>(pub(crate) &'a [u8]);

impl Bytes<'_> {
    pub(crate) fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        let n = N.min(self.0.len());
        out[..n].copy_from_slice(&self.0[..n]);
        self.0 = &self.0[n..];
        out
    }
    pub(crate) fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take())
    }
    pub(crate) fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take())
    }
    pub(crate) fn u8(&mut self) -> u8 {
        self.take::<1>()[0]
    }
}

/// `Estimator::step` (f32, Table 2) on arbitrary samples and commands: each record of
/// the input is an opcode and its values (a sample with arbitrary bits in every
/// channel, a pump jump or ramp, dither on/off or amplitude, retune on/off, or a run of
/// plausible samples so that the RLS is actually updating). Never a panic; the pump
/// command is never NaN, the estimate stays finite, and a refused centre command changes
/// nothing.
pub fn estimator_step(data: &[u8]) {
    let mut est: Estimator<f32> = match Config::table2().build() {
        Ok(e) => e,
        Err(_) => return,
    };
    let mut b = Bytes(data);
    let mut pump = est.initial_pump_hz();
    let mut k = 0u64;
    while !b.0.is_empty() {
        match b.u8() % 8 {
            0 | 1 => {
                let mut ch = [0f32; 16];
                for c in ch.iter_mut() {
                    *c = b.f32();
                }
                let s = sample_of(&ch, b.f64(), b.f32());
                check(&est, est.clone().step(&s));
                let out = est.step(&s);
                pump = out.pump_hz_next;
            }
            2 => {
                // a refused centre (NaN, ±∞, beyond ±50 % of the configured one) changes
                // nothing
                let before = est.pump_centre_hz();
                if !est.command_pump_centre(b.f64(), b.u8() & 1 == 1) {
                    assert_eq!(est.pump_centre_hz().to_bits(), before.to_bits());
                }
            }
            3 => est.set_dither(b.u8() & 1 == 1),
            4 => {
                let _ = est.set_dither_pump_hz(b.f64());
            }
            5 => est.set_retune(b.u8() & 1 == 1),
            _ => {
                // plausible samples (the RLS runs past its start-up gate)
                let n = 1 + b.u8() as u64 * 4;
                for _ in 0..n {
                    let out = est.step(&plausible(k, pump));
                    check(&est, out);
                    pump = out.pump_hz_next;
                    k += 1;
                }
            }
        }
    }
}

fn check(est: &Estimator<f32>, out: paragyro_core::StepOutput) {
    assert!(!out.pump_hz_next.is_nan(), "NaN pump command");
    assert!(!out.pump_scale_next.is_nan(), "NaN pump scale command");
    let (t1, t2) = est.theta();
    assert!(
        t1.iter().chain(t2.iter()).all(|v| v.is_finite()),
        "non-finite estimate"
    );
}

fn sample_of(ch: &[f32; 16], pump_hz: f64, pump_scale: f32) -> Sample<f32> {
    Sample {
        lockin: Lockin {
            x0_um: ch[0],
            x_um: [
                Cplx::new(ch[1], ch[2]),
                Cplx::new(ch[3], ch[4]),
                Cplx::new(ch[5], ch[6]),
            ],
            y0_um: ch[7],
            y_um: [
                Cplx::new(ch[8], ch[9]),
                Cplx::new(ch[10], ch[11]),
                Cplx::new(ch[12], ch[13]),
            ],
        },
        accel_mps2: [ch[14], ch[15]],
        temp_c: None,
        pump_hz,
        pump_scale,
    }
}

/// A plausible steady sample of the Table 2 gyro with a little variation.
pub fn plausible(k: u64, pump_hz: f64) -> Sample<f32> {
    let d = |i: u64| (((k + 3 * i) * 7919) % 13) as f32 * 1e-5;
    let ch: [f32; 16] = [
        0.0204 + d(0),
        1.2 + d(1),
        -1.27 + d(2),
        1e-4 + d(3),
        d(4),
        0.001 + d(5),
        0.002 + d(6),
        0.0207 - d(7),
        0.9 + d(8),
        1.2 - d(9),
        d(10),
        1e-4 + d(11),
        0.0005 + d(12),
        -0.001 + d(13),
        98.0665,
        98.0665,
    ];
    sample_of(&ch, pump_hz, 1.0)
}
