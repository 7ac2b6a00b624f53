//! Host tests of the SPI drivers: every public operation transaction by transaction with
//! embedded-hal-mock (each `SpiDevice` transaction bracketed by `transaction_start` /
//! `transaction_end`, every mock `.done()`), the data paths (CRC, sign extension,
//! saturation, unit conversions, tuning words) and the error paths with `FailingSpi`.

use embedded_hal::spi::SpiDevice;
use embedded_hal_mock::eh1::delay::{CheckedDelay, NoopDelay, Transaction as DelayTx};
use embedded_hal_mock::eh1::spi::{Mock, Transaction as T};
use paragyro_firmware::drivers::ad9959::{
    self, Ad9959, AmplitudeWord, Channel, FrequencyOutOfRange, IoUpdate, PhaseWord, PumpPlan,
};
use paragyro_firmware::drivers::ads131m08::{
    self, Ads131m08, Clock, Config, FRAME_BYTES, Frame, Gain, LockinCalibration, Mode, Osr,
    PowerMode, RawCode, Register as AdcReg,
};
use paragyro_firmware::drivers::adxl355::{self, Adxl355, HighPass, Odr, Range};
use paragyro_firmware::drivers::failing::{FailingSpi, FailingSpiError};

// ------------------------------------------------------------------------------------------
// helpers

/// One `SpiDevice::transaction` made of the given operations.
fn txn(ops: Vec<T<u8>>) -> Vec<T<u8>> {
    let mut v = vec![T::transaction_start()];
    v.extend(ops);
    v.push(T::transaction_end());
    v
}

fn assert_close(a: f64, b: f64, tol: f64) {
    assert!((a - b).abs() <= tol, "{a} vs {b} (tol {tol})");
}

// ------------------------------------------------------------------------------------------
// ADS131M08

/// STATUS of a data frame: 24-bit words (WLENGTH = 01), all DRDY flags set.
const STATUS_ALL_READY: u16 = 0x01FF;

/// A frame as the device sends it (valid CRC, built with the driver's CRC function).
fn adc_frame(response: u16, codes: [i32; 8]) -> [u8; FRAME_BYTES] {
    Frame {
        response,
        codes: codes.map(RawCode::saturating_new),
    }
    .encode()
}

/// One ADS131M08 frame exchange: MOSI carries `words` + input CRC, MISO `miso`.
fn adc_xfer(words: &[u16], miso: [u8; FRAME_BYTES]) -> Vec<T<u8>> {
    txn(vec![T::transfer_in_place(
        ads131m08::command_frame(words).to_vec(),
        miso.to_vec(),
    )])
}

/// Expectations of `write_register`: the WREG frame, then a NULL frame with the ack.
fn adc_write_reg(reg: AdcReg, value: u16) -> Vec<T<u8>> {
    let mut v = adc_xfer(
        &[ads131m08::opcode::wreg(reg), value],
        adc_frame(STATUS_ALL_READY, [0; 8]),
    );
    v.extend(adc_xfer(
        &[0],
        adc_frame(ads131m08::opcode::wreg_ack(reg), [0; 8]),
    ));
    v
}

/// Expectations of `write_register_verified`: write, then read back `read_back`.
fn adc_write_verified(reg: AdcReg, value: u16, read_back: u16) -> Vec<T<u8>> {
    let mut v = adc_write_reg(reg, value);
    v.extend(adc_read_reg(reg, read_back));
    v
}

/// Expectations of `read_register`: the RREG frame, then a NULL frame with the value.
fn adc_read_reg(reg: AdcReg, value: u16) -> Vec<T<u8>> {
    let mut v = adc_xfer(
        &[ads131m08::opcode::rreg(reg)],
        adc_frame(STATUS_ALL_READY, [0; 8]),
    );
    v.extend(adc_xfer(&[0], adc_frame(value, [0; 8])));
    v
}

fn adc_reset() -> Vec<T<u8>> {
    // The frame clocked out with RESET predates the reset: garbage, not CRC-checked.
    let mut v = adc_xfer(&[ads131m08::opcode::RESET], [0xA5; FRAME_BYTES]);
    v.extend(adc_xfer(&[0], adc_frame(ads131m08::RESET_ACK, [0; 8])));
    v
}

#[test]
fn adc_crc_matches_published_check_value() {
    // CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no xorout) check value.
    assert_eq!(ads131m08::crc16_ccitt(b"123456789"), 0x29B1);
    assert_eq!(ads131m08::crc16_ccitt(b""), 0xFFFF);
    // Incremental == one-shot, and data followed by its CRC leaves remainder 0.
    let part = ads131m08::crc16_ccitt_update(0xFFFF, b"1234");
    assert_eq!(ads131m08::crc16_ccitt_update(part, b"56789"), 0x29B1);
    assert_eq!(ads131m08::crc16_ccitt(b"123456789\x29\xB1"), 0);
}

#[test]
fn adc_command_frames_match_independent_computation() {
    // Values computed with an independent bitwise CRC (Python), not with the driver.
    let null = ads131m08::command_frame(&[0x0000]);
    assert_eq!(
        null[..9],
        [0x00, 0x00, 0x00, 0xCC, 0x9C, 0x00, 0x00, 0x00, 0x00]
    );
    assert!(null[6..].iter().all(|&b| b == 0));
    let rreg_id = ads131m08::command_frame(&[ads131m08::opcode::rreg(AdcReg::Id)]);
    assert_eq!(rreg_id[..6], [0xA0, 0x00, 0x00, 0x71, 0x00, 0x00]);
    let wreg_mode = ads131m08::command_frame(&[ads131m08::opcode::wreg(AdcReg::Mode), 0x1110]);
    assert_eq!(
        wreg_mode[..9],
        [0x61, 0x00, 0x00, 0x11, 0x10, 0x00, 0x63, 0x88, 0x00]
    );
    let reset = ads131m08::command_frame(&[ads131m08::opcode::RESET]);
    assert_eq!(reset[..6], [0x00, 0x11, 0x00, 0xFC, 0xDE, 0x00]);
    assert_eq!(null.len(), 30);
}

#[test]
fn adc_register_words() {
    use ads131m08::opcode;
    assert_eq!(opcode::rreg(AdcReg::Id), 0xA000);
    assert_eq!(opcode::rreg(AdcReg::Clock), 0xA180);
    assert_eq!(opcode::wreg(AdcReg::Mode), 0x6100);
    assert_eq!(opcode::wreg_ack(AdcReg::Mode), 0x4100);
    assert_eq!(opcode::wreg(AdcReg::Gain2), 0x6280);
    assert_eq!(Mode::PARAGYRO.bits(), 0x1110);
    let all_off = Mode {
        regmap_crc: false,
        rx_crc: false,
        spi_timeout: false,
    };
    assert_eq!(all_off.bits(), 0x0100);
    assert_eq!(Clock::PARAGYRO.bits(), 0xFF9A);
    let reset_clock = Clock {
        channel_enable: 0xFF,
        xtal_disabled: false,
        external_reference: false,
        osr: Osr::R1024,
        power: PowerMode::HighResolution,
    };
    assert_eq!(
        reset_clock.bits(),
        0xFF0E,
        "the datasheet's CLOCK reset value"
    );
    assert_eq!(
        Gain::register_bits([Gain::G1, Gain::G2, Gain::G4, Gain::G128]),
        0x7210
    );
    assert_eq!(Gain::G16.factor(), 16);
}

#[test]
fn adc_osr_8192_gives_500_sps_at_8_192_mhz() {
    assert_eq!(Clock::PARAGYRO.osr, Osr::R8192);
    assert_eq!(Clock::PARAGYRO.data_rate_hz(8.192e6), 500.0);
    assert_eq!(Osr::R16256.ratio(), 16256);
    let mut c = Clock::PARAGYRO;
    c.osr = Osr::R1024;
    assert_eq!(c.data_rate_hz(8.192e6), 4000.0);
}

#[test]
fn adc_sign_extension() {
    assert_eq!(RawCode::from_u24(0x80_0000).get(), -8_388_608);
    assert_eq!(RawCode::from_u24(0x7F_FFFF).get(), 8_388_607);
    assert_eq!(RawCode::from_u24(0xFF_FFFF).get(), -1);
    assert_eq!(RawCode::from_u24(0x00_0001).get(), 1);
    assert_eq!(RawCode::from_u24(0x00_0000).get(), 0);
    assert_eq!(
        RawCode::from_u24(0xAB_FF_FF_FF).get(),
        -1,
        "upper byte ignored"
    );
    assert_eq!(RawCode::from_be_bytes([0x80, 0x00, 0x00]).get(), -8_388_608);
    assert_eq!(RawCode::from_be_bytes([0x7F, 0xFF, 0xFF]).get(), 8_388_607);
    assert_eq!(RawCode::from_be_bytes([0xFF, 0xFF, 0xFF]).get(), -1);
    for v in [-8_388_608, -1, 0, 1, 123_456, 8_388_607] {
        let c = RawCode::saturating_new(v);
        assert_eq!(RawCode::from_be_bytes(c.to_be_bytes()), c);
    }
    assert_eq!(
        RawCode::saturating_new(i32::MAX),
        RawCode::POSITIVE_FULL_SCALE
    );
    assert_eq!(
        RawCode::saturating_new(i32::MIN),
        RawCode::NEGATIVE_FULL_SCALE
    );
}

#[test]
fn adc_saturation_detected() {
    assert!(RawCode::from_u24(0x7F_FFFF).is_saturated());
    assert!(RawCode::from_u24(0x80_0000).is_saturated());
    assert!(!RawCode::from_u24(0x7F_FFFE).is_saturated());
    assert!(!RawCode::from_u24(0x80_0001).is_saturated());
    assert!(!RawCode::from_u24(0).is_saturated());

    let f = Frame::decode(&adc_frame(
        STATUS_ALL_READY,
        [0, 8_388_607, 5, -8_388_608, 0, 0, 0, 0],
    ))
    .unwrap();
    assert_eq!(f.saturated_mask(), 0b0000_1010);
    assert!(f.lockin_saturated());
    // Only the spare channel clipped: not a lock-in saturation.
    let f = Frame::decode(&adc_frame(
        STATUS_ALL_READY,
        [0, 0, 0, 0, 0, 0, 0, 8_388_607],
    ))
    .unwrap();
    assert_eq!(f.saturated_mask(), 0b1000_0000);
    assert!(!f.lockin_saturated());
}

#[test]
fn adc_frame_crc_accepts_good_frame_and_rejects_any_single_bit_flip() {
    let codes = [
        1, -2, 3_000_000, -4_000_000, 8_388_607, -8_388_608, 0x1234, -77,
    ];
    let good = adc_frame(STATUS_ALL_READY, codes);
    let f = Frame::decode(&good).expect("good frame");
    assert_eq!(f.response, STATUS_ALL_READY);
    assert_eq!(f.codes.map(RawCode::get), codes);
    assert!(f.status().lockin_ready());
    assert_eq!(f.status().word_length(), 0b01);
    // The CRC word itself: the CRC over everything before it.
    assert_eq!(
        u16::from_be_bytes([good[27], good[28]]),
        ads131m08::crc16_ccitt(&good[..27])
    );
    // Every bit of every covered byte (0..27) and of the CRC word (27, 28).
    for byte in 0..29 {
        for bit in 0..8 {
            let mut bad = good;
            bad[byte] ^= 1 << bit;
            match Frame::decode(&bad) {
                Err(e) => assert_ne!(e.expected, e.got),
                Ok(_) => panic!("flip of byte {byte} bit {bit} not detected"),
            }
        }
    }
    // Byte 29 is the CRC word's pad byte: neither covered nor compared.
    let mut pad = good;
    pad[29] = 0xFF;
    assert!(Frame::decode(&pad).is_ok());
}

#[test]
fn adc_reset_transactions() {
    let spi = Mock::new(&adc_reset());
    let mut delay = CheckedDelay::new(&[DelayTx::delay_us(ads131m08::RESET_WAIT_US)]);
    let mut adc = Ads131m08::new(spi);
    adc.reset(&mut delay).unwrap();
    adc.destroy().done();
    delay.done();
}

#[test]
fn adc_reset_not_acknowledged_is_not_ready() {
    // Echo of the RESET command instead of 0xFF28: the device saw no full frame.
    let mut exp = adc_xfer(&[ads131m08::opcode::RESET], [0; FRAME_BYTES]);
    exp.extend(adc_xfer(&[0], adc_frame(0x0011, [0; 8])));
    let mut adc = Ads131m08::new(Mock::new(&exp));
    assert_eq!(
        adc.reset(&mut NoopDelay::new()),
        Err(ads131m08::Error::NotReady)
    );
    adc.destroy().done();
}

#[test]
fn adc_read_register_transactions() {
    let mut adc = Ads131m08::new(Mock::new(&adc_read_reg(AdcReg::Clock, 0xFF0E)));
    assert_eq!(adc.read_register(AdcReg::Clock), Ok(0xFF0E));
    adc.destroy().done();
}

#[test]
fn adc_write_register_transactions() {
    let mut adc = Ads131m08::new(Mock::new(&adc_write_reg(AdcReg::Cfg, 0x0600)));
    adc.write_register(AdcReg::Cfg, 0x0600).unwrap();
    adc.destroy().done();
}

#[test]
fn adc_write_register_wrong_ack_is_not_ready() {
    let mut exp = adc_xfer(
        &[ads131m08::opcode::wreg(AdcReg::Mode), 0x1110],
        adc_frame(STATUS_ALL_READY, [0; 8]),
    );
    exp.extend(adc_xfer(&[0], adc_frame(STATUS_ALL_READY, [0; 8])));
    let mut adc = Ads131m08::new(Mock::new(&exp));
    assert_eq!(
        adc.write_register(AdcReg::Mode, 0x1110),
        Err(ads131m08::Error::NotReady)
    );
    adc.destroy().done();
}

#[test]
fn adc_check_id_accepts_0x28xx() {
    let mut adc = Ads131m08::new(Mock::new(&adc_read_reg(AdcReg::Id, 0x2802)));
    assert_eq!(adc.check_id(), Ok(0x2802));
    adc.destroy().done();
}

#[test]
fn adc_check_id_rejects_other_parts() {
    // An ADS131M04 (0x24xx).
    let mut adc = Ads131m08::new(Mock::new(&adc_read_reg(AdcReg::Id, 0x2401)));
    assert_eq!(adc.check_id(), Err(ads131m08::Error::BadId(0x2401)));
    adc.destroy().done();
}

#[test]
fn adc_standby_and_wakeup_transactions() {
    use ads131m08::opcode::{STANDBY, WAKEUP};
    let mut exp = adc_xfer(&[STANDBY], adc_frame(STATUS_ALL_READY, [0; 8]));
    exp.extend(adc_xfer(&[0], adc_frame(STANDBY, [0; 8])));
    exp.extend(adc_xfer(&[WAKEUP], adc_frame(0x0100, [0; 8])));
    exp.extend(adc_xfer(&[0], adc_frame(WAKEUP, [0; 8])));
    // A wrong echo.
    exp.extend(adc_xfer(&[STANDBY], adc_frame(0x0100, [0; 8])));
    exp.extend(adc_xfer(&[0], adc_frame(0x0100, [0; 8])));
    let mut adc = Ads131m08::new(Mock::new(&exp));
    adc.standby().unwrap();
    adc.wakeup().unwrap();
    assert_eq!(adc.standby(), Err(ads131m08::Error::NotReady));
    adc.destroy().done();
}

#[test]
fn adc_write_register_verified_transactions() {
    let mut exp = adc_write_verified(AdcReg::Cfg, 0x0600, 0x0600);
    // Written but reads back something else (e.g. the data word was corrupted).
    exp.extend(adc_write_verified(AdcReg::Cfg, 0x0600, 0x0604));
    let mut adc = Ads131m08::new(Mock::new(&exp));
    adc.write_register_verified(AdcReg::Cfg, 0x0600).unwrap();
    assert_eq!(
        adc.write_register_verified(AdcReg::Cfg, 0x0600),
        Err(ads131m08::Error::NotReady)
    );
    adc.destroy().done();
}

#[test]
fn adc_set_mode_clock_gains_transactions() {
    let mut exp = adc_write_verified(AdcReg::Mode, 0x1110, 0x1110);
    exp.extend(adc_write_verified(AdcReg::Clock, 0xFF9A, 0xFF9A));
    exp.extend(adc_write_verified(AdcReg::Gain1, 0x3210, 0x3210));
    exp.extend(adc_write_verified(AdcReg::Gain2, 0x7654, 0x7654));
    let mut adc = Ads131m08::new(Mock::new(&exp));
    adc.set_mode(Mode::PARAGYRO).unwrap();
    adc.set_clock(Clock::PARAGYRO).unwrap();
    adc.set_gains([
        Gain::G1,
        Gain::G2,
        Gain::G4,
        Gain::G8,
        Gain::G16,
        Gain::G32,
        Gain::G64,
        Gain::G128,
    ])
    .unwrap();
    adc.destroy().done();
}

#[test]
fn adc_init_transactions() {
    let mut exp = adc_reset();
    exp.extend(adc_read_reg(AdcReg::Id, 0x2800));
    exp.extend(adc_write_verified(AdcReg::Mode, 0x1110, 0x1110));
    exp.extend(adc_write_verified(AdcReg::Gain1, 0x0000, 0x0000));
    exp.extend(adc_write_verified(AdcReg::Gain2, 0x0000, 0x0000));
    exp.extend(adc_write_verified(AdcReg::Clock, 0xFF9A, 0xFF9A));
    let mut delay = CheckedDelay::new(&[DelayTx::delay_us(1000)]);
    let mut adc = Ads131m08::new(Mock::new(&exp));
    assert_eq!(adc.init(&mut delay, &Config::PARAGYRO), Ok(0x2800));
    adc.destroy().done();
    delay.done();
}

#[test]
fn adc_read_frame_transaction() {
    let codes = [100, -200, 300, -400, 500, -600, 700, 0];
    let exp = adc_xfer(&[0], adc_frame(STATUS_ALL_READY, codes));
    let mut adc = Ads131m08::new(Mock::new(&exp));
    let f = adc.read_frame().unwrap();
    assert_eq!(f.codes.map(RawCode::get), codes);
    assert_eq!(
        f.lockin_codes().map(RawCode::get),
        [100, -200, 300, -400, 500, -600, 700]
    );
    adc.destroy().done();
}

#[test]
fn adc_read_frame_rejects_corruption_and_missing_drdy() {
    let mut corrupted = adc_frame(STATUS_ALL_READY, [1; 8]);
    corrupted[10] ^= 0x04;
    let mut exp = adc_xfer(&[0], corrupted);
    // DRDY of channel 6 missing (the spare's DRDY does not matter).
    exp.extend(adc_xfer(&[0], adc_frame(0x01BF, [0; 8])));
    exp.extend(adc_xfer(&[0], adc_frame(0x017F, [0; 8])));
    let mut adc = Ads131m08::new(Mock::new(&exp));
    assert!(matches!(
        adc.read_frame(),
        Err(ads131m08::Error::Crc { .. })
    ));
    assert_eq!(adc.read_frame(), Err(ads131m08::Error::NotReady));
    assert!(adc.read_frame().is_ok());
    adc.destroy().done();
}

#[test]
fn adc_calibration_converts_codes_to_um_in_one_place() {
    let cal = LockinCalibration {
        um_per_code: [1e-3, 2e-3, 3e-3, 4e-3, 5e-3, 6e-3, 7e-3],
        offset_code: [10, -10, 0, 0, 0, 0, 1000],
    };
    let f = Frame::decode(&adc_frame(
        STATUS_ALL_READY,
        [1010, 990, 1000, -1000, 2000, 0, 0, 12345],
    ))
    .unwrap();
    let um = cal.frame_to_um(&f);
    assert_close(um.x0_um.into(), 1.0, 1e-6);
    assert_close(um.re_um[0].into(), 2.0, 1e-6); // (990 + 10) · 2e-3
    assert_close(um.im_um[0].into(), 3.0, 1e-6);
    assert_close(um.re_um[1].into(), -4.0, 1e-6);
    assert_close(um.im_um[1].into(), 10.0, 1e-6);
    assert_close(um.re_um[2].into(), 0.0, 1e-9);
    assert_close(um.im_um[2].into(), -7.0, 1e-6); // (0 - 1000) · 7e-3
    // Extreme offsets do not overflow.
    let wild = LockinCalibration {
        um_per_code: [1.0; 7],
        offset_code: [i32::MAX; 7],
    };
    let um = wild.to_um(&[RawCode::NEGATIVE_FULL_SCALE; 7]);
    assert!(um.x0_um < -2.1e9 && um.x0_um.is_finite());
    // From the analog scale: 1.2 V / gain / 2^23 per code.
    let cal = LockinCalibration::from_um_per_volt(
        [10.0; 7],
        [
            Gain::G1,
            Gain::G2,
            Gain::G1,
            Gain::G1,
            Gain::G1,
            Gain::G1,
            Gain::G4,
        ],
        [0; 7],
    );
    assert_close(cal.um_per_code[0].into(), 10.0 * 1.2 / 8_388_608.0, 1e-12);
    assert_close(cal.um_per_code[1].into(), 10.0 * 0.6 / 8_388_608.0, 1e-12);
    assert_close(cal.um_per_code[6].into(), 10.0 * 0.3 / 8_388_608.0, 1e-12);
    assert_eq!(
        LockinCalibration::UNITY
            .to_um(&[RawCode::from_u24(5); 7])
            .x0_um,
        5.0
    );
}

#[test]
fn adc_every_operation_reports_spi_errors() {
    use ads131m08::Error::Spi;
    let e = Err(Spi(FailingSpiError));
    let mut adc = Ads131m08::new(FailingSpi::always_failing());
    assert_eq!(adc.reset(&mut NoopDelay::new()), e);
    assert_eq!(adc.standby(), e);
    assert_eq!(adc.wakeup(), e);
    assert_eq!(adc.read_register(AdcReg::Status), Err(Spi(FailingSpiError)));
    assert_eq!(adc.write_register(AdcReg::Cfg, 0), e);
    assert_eq!(adc.write_register_verified(AdcReg::Cfg, 0), e);
    assert_eq!(adc.check_id(), Err(Spi(FailingSpiError)));
    assert_eq!(adc.set_mode(Mode::PARAGYRO), e);
    assert_eq!(adc.set_clock(Clock::PARAGYRO), e);
    assert_eq!(adc.set_gains([Gain::G1; 8]), e);
    assert_eq!(
        adc.init(&mut NoopDelay::new(), &Config::PARAGYRO),
        Err(Spi(FailingSpiError))
    );
    assert_eq!(adc.read_frame(), Err(Spi(FailingSpiError)));
    // A bus that fails part-way through a multi-frame operation: an error, never a panic.
    for ok in 0..24 {
        let mut adc = Ads131m08::new(FailingSpi::failing_after(ok, 0x00));
        assert!(adc.init(&mut NoopDelay::new(), &Config::PARAGYRO).is_err());
    }
    // The RESET frame itself is not CRC-checked, so a failure on the second frame is Spi.
    let mut adc = Ads131m08::new(FailingSpi::failing_after(1, 0x00));
    assert_eq!(adc.reset(&mut NoopDelay::new()), e);
    assert_eq!(adc.destroy().transactions(), 2);
}

#[test]
fn adc_absent_device_gives_errors_not_panics() {
    for fill in [0x00, 0xFF] {
        let mut adc = Ads131m08::new(FailingSpi::responding(fill));
        assert!(
            matches!(adc.read_frame(), Err(ads131m08::Error::Crc { .. })),
            "fill {fill:#x}"
        );
        assert!(adc.check_id().is_err());
        assert!(adc.init(&mut NoopDelay::new(), &Config::PARAGYRO).is_err());
    }
}

// ------------------------------------------------------------------------------------------
// ADXL355

fn xl_read(cmd: u8, data: Vec<u8>) -> Vec<T<u8>> {
    txn(vec![T::write_vec(vec![cmd]), T::read_vec(data)])
}

fn xl_write(cmd: u8, value: u8) -> Vec<T<u8>> {
    txn(vec![T::write_vec(vec![cmd, value])])
}

#[test]
fn xl_command_bytes() {
    use adxl355::Register as R;
    assert_eq!(R::DevIdAd.read_cmd(), 0x01);
    assert_eq!(R::Status.read_cmd(), 0x09);
    assert_eq!(R::XData3.read_cmd(), 0x11);
    assert_eq!(R::Temp2.read_cmd(), 0x0D);
    assert_eq!(R::Range.write_cmd(), 0x58);
    assert_eq!(R::PowerCtl.write_cmd(), 0x5A);
    assert_eq!(R::Reset.write_cmd(), 0x5E);
    assert_eq!(R::Filter.write_cmd(), 0x50);
    assert_eq!(adxl355::filter_bits(Odr::Hz500, HighPass::Corner2), 0x23);
    assert_eq!(Odr::Hz4000.hz(), 4000.0);
    assert_eq!(Odr::Hz3_906.hz(), 3.906_25);
}

#[test]
fn xl_check_id_transaction() {
    let mut xl = Adxl355::new(Mock::new(&xl_read(0x01, vec![0xAD, 0x1D, 0xED])));
    let id = xl.check_id().unwrap();
    assert!(id.is_adxl355());
    xl.destroy().done();
}

#[test]
fn xl_bad_id_is_reported_with_all_three_bytes() {
    // An ADXL359 (PARTID 0xE9): a different chip, not a missing one.
    let mut xl = Adxl355::new(Mock::new(&xl_read(0x01, vec![0xAD, 0x1D, 0xE9])));
    let err = xl.check_id().unwrap_err();
    assert_eq!(
        err,
        adxl355::Error::BadId {
            ad: 0xAD,
            mst: 0x1D,
            part: 0xE9
        }
    );
    assert!(!err.is_missing_device());
    xl.destroy().done();
}

#[test]
fn xl_missing_accelerometer_is_a_clear_error() {
    for fill in [0xFF, 0x00] {
        let mut xl = Adxl355::new(FailingSpi::responding(fill));
        let err = xl.check_id().unwrap_err();
        assert_eq!(
            err,
            adxl355::Error::BadId {
                ad: fill,
                mst: fill,
                part: fill
            }
        );
        assert!(err.is_missing_device());
        assert!(
            xl.init(Range::G2, Odr::Hz500, HighPass::Off)
                .unwrap_err()
                .is_missing_device()
        );
        // Reading samples from nothing: not ready, never garbage or a panic.
        assert_eq!(xl.read_sample(), Err(adxl355::Error::NotReady));
    }
}

#[test]
fn xl_reset_range_filter_power_transactions() {
    let mut exp = xl_write(0x5E, 0x52);
    exp.extend(xl_write(0x58, 0x82));
    exp.extend(xl_write(0x58, 0x83));
    exp.extend(xl_write(0x50, 0x13));
    exp.extend(xl_write(0x5A, 0x01));
    exp.extend(xl_write(0x5A, 0x00));
    let mut xl = Adxl355::new(Mock::new(&exp));
    xl.reset().unwrap();
    assert_eq!(xl.range(), Range::G2);
    xl.set_range(Range::G4).unwrap();
    assert_eq!(xl.range(), Range::G4);
    xl.set_range(Range::G8).unwrap();
    xl.set_filter(Odr::Hz500, HighPass::Corner1).unwrap();
    xl.standby().unwrap();
    xl.measure().unwrap();
    xl.destroy().done();
}

#[test]
fn xl_status_and_register_transactions() {
    let mut exp = xl_read(0x09, vec![0x11]);
    exp.extend(xl_read(0x07, vec![0x01])); // REVID
    exp.extend(xl_write(0x5A, 0x06));
    let mut xl = Adxl355::new(Mock::new(&exp));
    let st = xl.status().unwrap();
    assert!(st.data_ready() && st.nvm_busy() && !st.fifo_full() && !st.implausible());
    assert_eq!(xl.read_register(adxl355::Register::RevId), Ok(0x01));
    xl.write_register(adxl355::Register::PowerCtl, 0x06)
        .unwrap();
    xl.destroy().done();
}

#[test]
fn xl_init_transactions() {
    let mut exp = xl_read(0x01, vec![0xAD, 0x1D, 0xED]);
    exp.extend(xl_write(0x5A, 0x01));
    exp.extend(xl_write(0x58, 0x81));
    exp.extend(xl_write(0x50, 0x03));
    exp.extend(xl_write(0x5A, 0x00));
    let mut xl = Adxl355::new(Mock::new(&exp));
    xl.init(Range::G2, Odr::Hz500, HighPass::Off).unwrap();
    xl.destroy().done();
}

#[test]
fn xl_read_raw_one_burst() {
    let bytes = vec![0x7F, 0xFF, 0xF0, 0x80, 0x00, 0x00, 0x00, 0x00, 0x1F];
    let mut xl = Adxl355::new(Mock::new(&xl_read(0x11, bytes)));
    let raw = xl.read_raw().unwrap();
    assert_eq!((raw.x, raw.y, raw.z), (524_287, -524_288, 1));
    xl.destroy().done();
}

#[test]
fn xl_read_sample_one_burst_with_data_ready() {
    // STATUS, FIFO_ENTRIES, TEMP2, TEMP1, X, Y, Z. 256410 · 3.9 µg ≈ 1 g on X.
    let x = 256_410i32;
    let xb = ((x as u32) << 4).to_be_bytes(); // [0, b19..12, b11..4, b3..0 << 4]
    let data = vec![
        0x01, 0x00, 0x07, 0x5C, xb[1], xb[2], xb[3], 0xFF, 0xFF, 0xF0, 0, 0, 0,
    ];
    let mut exp = xl_read(0x09, data);
    let mut not_ready = vec![0u8; 13];
    not_ready[4] = 0x12;
    exp.extend(xl_read(0x09, not_ready));
    let mut xl = Adxl355::new(Mock::new(&exp));
    let s = xl.read_sample().unwrap();
    assert_eq!((s.raw.x, s.raw.y, s.raw.z), (256_410, -1, 0));
    // TEMP2, TEMP1 of the same burst: 0x75C = 1884, one code above 25 °C
    assert_eq!(s.temp_raw, 1884);
    assert_close(s.temp_c().into(), 25.0 + 1.0 / 9.05, 1e-5);
    assert_close(s.accel_mps2[0].into(), 256_410.0 * 3.9e-6 * 9.806_65, 1e-4);
    assert_close(s.accel_mps2[0].into(), 9.806_65, 1e-4);
    assert_close(s.accel_mps2[1].into(), -3.9e-6 * 9.806_65, 1e-9);
    assert_eq!(s.accel_mps2[2], 0.0);
    assert_eq!(xl.read_sample(), Err(adxl355::Error::NotReady));
    xl.destroy().done();
}

#[test]
fn xl_20bit_conversion_of_known_codes() {
    assert_eq!(adxl355::raw20_from_bytes([0x7F, 0xFF, 0xF0]), 524_287);
    assert_eq!(adxl355::raw20_from_bytes([0x80, 0x00, 0x00]), -524_288);
    assert_eq!(adxl355::raw20_from_bytes([0xFF, 0xFF, 0xF0]), -1);
    assert_eq!(adxl355::raw20_from_bytes([0x00, 0x00, 0x10]), 1);
    assert_eq!(
        adxl355::raw20_from_bytes([0x00, 0x00, 0x0F]),
        0,
        "reserved low nibble ignored"
    );
    assert_eq!(adxl355::raw20_from_bytes([0x12, 0x34, 0x56]), 0x12345);
    let g = 9.806_65f64;
    let raw = adxl355::RawAccel {
        x: 524_287,
        y: -524_288,
        z: 64_000,
    };
    let a2 = raw.to_mps2(Range::G2);
    assert_close(a2[0].into(), 524_287.0 * 3.9e-6 * g, 1e-4); // +2.045 g
    assert_close(a2[1].into(), -524_288.0 * 3.9e-6 * g, 1e-4);
    let a8 = raw.to_mps2(Range::G8);
    assert_close(a8[2].into(), 0.9984 * g, 1e-4); // 64000 · 15.6 µg
    let a4 = raw.to_mps2(Range::G4);
    assert_close(a4[2].into(), 0.4992 * g, 1e-4);
    assert_close(Range::G4.mps2_per_lsb().into(), 7.8e-6 * g, 1e-10);
}

/// The datasheet's nominal transfer function: 1885 LSB at 25 °C, −9.05 LSB/°C (the code
/// falls as the die warms), from 12 bits (TEMP2's reserved upper nibble ignored).
#[test]
fn xl_temperature_conversion() {
    assert_eq!(adxl355::TEMP_INTERCEPT_CODE, 1885);
    assert_eq!(
        adxl355::temp_c_from_raw(1885),
        25.0,
        "the datasheet's 25 °C point"
    );
    // the sign of the slope: fewer codes, warmer; 9.05 codes per kelvin
    assert_close(adxl355::temp_c_from_raw(1885 - 181).into(), 45.0, 1e-4);
    assert_close(adxl355::temp_c_from_raw(1885 + 362).into(), -15.0, 1e-4);
    assert_close(
        (adxl355::temp_c_from_raw(1000) - adxl355::temp_c_from_raw(1001)).into(),
        1.0 / 9.05,
        1e-5,
    );
    let mut last = f32::INFINITY;
    for code in 0..=0x0FFF {
        let t = adxl355::temp_c_from_raw(code);
        assert!(t < last, "falling at {code}");
        last = t;
    }
    // 12-bit masking: TEMP2 bits 3:0 are bits 11:8, bits 7:4 reserved
    assert_eq!(adxl355::temp_raw12(0x07, 0x5D), 1885);
    assert_eq!(adxl355::temp_raw12(0xF7, 0x5D), 1885);
    assert_eq!(adxl355::temp_raw12(0x0F, 0xFF), 0x0FFF);
    assert_eq!(adxl355::temp_raw12(0xFF, 0xFF), 0x0FFF);
    assert_eq!(adxl355::temp_raw12(0x80, 0x01), 1);
    assert_eq!(adxl355::temp_raw12(0x01, 0x00), 256);
    // the reset value 0 is far out of any plausible range
    assert!(adxl355::temp_c_from_raw(0) > 230.0);
}

#[test]
fn xl_read_temperature_one_burst() {
    // TEMP2 (0x06): read command 0x0D, two bytes (TEMP2, TEMP1) auto-incremented
    let mut exp = xl_read(0x0D, vec![0x07, 0x5D]);
    exp.extend(xl_read(0x0D, vec![0xF6, 0xA8])); // reserved bits set: masked
    exp.extend(xl_read(0x0D, vec![0x07, 0x5D]));
    let mut xl = Adxl355::new(Mock::new(&exp));
    assert_eq!(xl.read_temperature_raw(), Ok(1885));
    assert_eq!(xl.read_temperature_raw(), Ok(0x6A8));
    assert_eq!(xl.read_temperature_c(), Ok(25.0));
    xl.destroy().done();
}

/// `init` leaves POWER_CTL.TEMP_OFF (and STANDBY) clear: the temperature sensor runs.
#[test]
fn xl_init_keeps_the_temperature_sensor_on() {
    assert_eq!(adxl355::POWER_CTL_TEMP_OFF, 0x02);
    assert_eq!(adxl355::POWER_CTL_MEASURE & adxl355::POWER_CTL_TEMP_OFF, 0);
    let mut exp = xl_read(0x01, vec![0xAD, 0x1D, 0xED]);
    exp.extend(xl_write(0x5A, 0x01));
    exp.extend(xl_write(0x58, 0x83));
    exp.extend(xl_write(0x50, 0x03));
    // the last POWER_CTL write: measurement mode, TEMP_OFF (bit 1) clear
    exp.extend(xl_write(0x5A, adxl355::POWER_CTL_MEASURE));
    let mut xl = Adxl355::new(Mock::new(&exp));
    xl.init(Range::G8, Odr::Hz500, HighPass::Off).unwrap();
    xl.destroy().done();
}

#[test]
fn xl_every_operation_reports_spi_errors() {
    use adxl355::Error::Spi;
    let mut xl = Adxl355::new(FailingSpi::always_failing());
    assert_eq!(xl.read_id(), Err(Spi(FailingSpiError)));
    assert_eq!(xl.check_id(), Err(Spi(FailingSpiError)));
    assert_eq!(xl.reset(), Err(Spi(FailingSpiError)));
    assert_eq!(xl.set_range(Range::G8), Err(Spi(FailingSpiError)));
    assert_eq!(
        xl.range(),
        Range::G2,
        "range unchanged when the write failed"
    );
    assert_eq!(
        xl.set_filter(Odr::Hz1000, HighPass::Off),
        Err(Spi(FailingSpiError))
    );
    assert_eq!(xl.measure(), Err(Spi(FailingSpiError)));
    assert_eq!(xl.standby(), Err(Spi(FailingSpiError)));
    assert_eq!(xl.status(), Err(Spi(FailingSpiError)));
    assert_eq!(
        xl.read_register(adxl355::Register::RevId),
        Err(Spi(FailingSpiError))
    );
    assert_eq!(
        xl.write_register(adxl355::Register::PowerCtl, 0),
        Err(Spi(FailingSpiError))
    );
    assert_eq!(
        xl.init(Range::G2, Odr::Hz500, HighPass::Off),
        Err(Spi(FailingSpiError))
    );
    assert_eq!(xl.read_raw(), Err(Spi(FailingSpiError)));
    assert_eq!(xl.read_sample(), Err(Spi(FailingSpiError)));
    assert_eq!(xl.read_temperature_raw(), Err(Spi(FailingSpiError)));
    assert_eq!(xl.read_temperature_c(), Err(Spi(FailingSpiError)));
}

// ------------------------------------------------------------------------------------------
// AD9959

const SYSCLK: f64 = 500e6;
/// One FTW step at 500 MHz, Hz.
const STEP_HZ: f64 = SYSCLK / 4_294_967_296.0;

fn dds_write(instr: u8, data: Vec<u8>) -> Vec<T<u8>> {
    txn(vec![T::write_vec(vec![instr]), T::write_vec(data)])
}

/// CSR selecting one channel, 3-wire, MSB first.
fn dds_select(ch: Channel) -> Vec<T<u8>> {
    dds_write(0x00, vec![ch.csr_enable() | 0x02])
}

/// One frame: CSR selecting `ch`, then the register's cycle.
fn dds_channel_write(ch: Channel, instr: u8, data: Vec<u8>) -> Vec<T<u8>> {
    txn(vec![
        T::write_vec(vec![0x00, ch.csr_enable() | 0x02, instr]),
        T::write_vec(data),
    ])
}

/// The cycles of a plan's three tuning words (pump, reference, 3Ω), each after its select.
fn plan_cycles(ftws: [u32; 3]) -> Vec<u8> {
    let chans = [Channel::PUMP, Channel::REFERENCE, Channel::THIRD];
    let mut v = Vec::new();
    for (ch, w) in chans.into_iter().zip(ftws) {
        v.extend([0x00, ch.csr_enable() | 0x02, 0x04]);
        v.extend(w.to_be_bytes());
    }
    v
}

#[test]
fn dds_ftw_for_21_9_khz_at_500_mhz() {
    let ftw = ad9959::ftw_from_hz(21_900.0, SYSCLK).unwrap();
    assert_eq!(ftw, 188_120); // round(21900 · 2^32 / 5e8) = round(188119.5676)
    let f = ad9959::hz_from_ftw(ftw, SYSCLK);
    assert_close(f, 21_900.050_342_082_977, 1e-9);
    assert!((f - 21_900.0).abs() < 0.12);
    const _: () = assert!(STEP_HZ < 0.12);
}

#[test]
fn dds_reference_channels_exactly_half_and_three_halves_of_pump() {
    let plan = PumpPlan::new(21_900.0, SYSCLK).unwrap();
    assert_eq!(plan.pump_ftw(), 188_120);
    assert_eq!(plan.pump_ftw() % 2, 0);
    assert_eq!(plan.reference_ftw(), 94_060);
    assert_eq!(plan.third_ftw(), 282_180);
    assert_eq!(plan.reference_ftw() * 2, plan.pump_ftw());
    assert_eq!(plan.third_ftw() * 2, 3 * plan.pump_ftw());
    assert!((plan.pump_hz() - 21_900.0).abs() < 0.12);
    assert_eq!(plan.reference_hz() * 2.0, plan.pump_hz());
    assert_eq!(plan.third_hz(), 3.0 * plan.reference_hz());
    // Over a sweep (odd raw FTWs included): ratios exact, pump within one step (0.1164 Hz).
    let mut f = 1_000.0;
    while f < 200_000.0 {
        let p = PumpPlan::new(f, SYSCLK).unwrap();
        assert_eq!(p.pump_ftw(), 2 * p.reference_ftw());
        assert_eq!(p.third_ftw(), 3 * p.reference_ftw());
        assert!((p.pump_hz() - f).abs() <= STEP_HZ * (1.0 + 1e-9), "{f}");
        assert!((p.pump_hz() - f).abs() < 0.12);
        f += 1_234.567_8;
    }
    // Another SYSCLK.
    let p = PumpPlan::new(21_900.0, 400e6).unwrap();
    assert_eq!(p.pump_ftw(), 2 * p.reference_ftw());
    assert_eq!(p.sysclk_hz(), 400e6);
}

#[test]
fn dds_frequency_out_of_range() {
    use ad9959::ftw_from_hz;
    assert_eq!(ftw_from_hz(-1.0, SYSCLK), Err(FrequencyOutOfRange));
    assert_eq!(ftw_from_hz(f64::NAN, SYSCLK), Err(FrequencyOutOfRange));
    assert_eq!(ftw_from_hz(f64::INFINITY, SYSCLK), Err(FrequencyOutOfRange));
    assert_eq!(ftw_from_hz(250e6, SYSCLK), Err(FrequencyOutOfRange));
    assert_eq!(ftw_from_hz(1e3, 0.0), Err(FrequencyOutOfRange));
    assert_eq!(ftw_from_hz(1e3, 600e6), Err(FrequencyOutOfRange));
    assert_eq!(ftw_from_hz(1e3, f64::NAN), Err(FrequencyOutOfRange));
    assert_eq!(ftw_from_hz(0.0, SYSCLK), Ok(0));
    assert_eq!(
        ftw_from_hz(250e6 - 0.01, SYSCLK),
        Err(FrequencyOutOfRange),
        "rounds to Nyquist"
    );
    assert!(ftw_from_hz(250e6 - 1.0, SYSCLK).unwrap() < 1 << 31);
    assert_eq!(PumpPlan::new(0.0, SYSCLK), Err(FrequencyOutOfRange));
    assert_eq!(PumpPlan::new(-5.0, SYSCLK), Err(FrequencyOutOfRange));
    assert_eq!(
        PumpPlan::new(0.01, SYSCLK),
        Err(FrequencyOutOfRange),
        "reference word 0"
    );
    assert_eq!(
        PumpPlan::new(170e6, SYSCLK),
        Err(FrequencyOutOfRange),
        "3Ω above Nyquist"
    );
    assert!(PumpPlan::new(160e6, SYSCLK).is_ok());
}

#[test]
fn dds_amplitude_words() {
    assert_eq!(AmplitudeWord::from_scale(1.0).get(), 1023);
    assert_eq!(AmplitudeWord::from_scale(0.81).get(), 921); // round(1023 · 0.9) = 921
    assert_eq!(AmplitudeWord::from_scale(0.0).get(), 0);
    assert_eq!(AmplitudeWord::from_scale(1.5).get(), 1023);
    assert_eq!(AmplitudeWord::from_scale(-0.1).get(), 0);
    assert_eq!(AmplitudeWord::from_scale(f32::NAN).get(), 0);
    assert_eq!(AmplitudeWord::from_scale(0.25).get(), 512); // 511.5 rounds up
    assert_eq!(AmplitudeWord::new(5000), AmplitudeWord::FULL);
    assert_eq!(
        AmplitudeWord::from_scale(0.81).acr_bytes(),
        [0x00, 0x13, 0x99]
    );
    assert_eq!(AmplitudeWord::FULL.acr_bytes(), [0x00, 0x13, 0xFF]);
    assert_eq!(AmplitudeWord::ZERO.acr_bytes(), [0x00, 0x10, 0x00]);
    assert_close(AmplitudeWord::from_scale(0.81).scale().into(), 0.81, 1e-3);
    // Amplitude ∝ √s to within half a step, monotonic.
    let mut last = 0;
    for i in 0..=10_000 {
        let s = i as f32 / 10_000.0;
        let w = AmplitudeWord::from_scale(s).get();
        assert!(w >= last);
        last = w;
        assert!(
            (f64::from(w) - 1023.0 * f64::from(s).sqrt()).abs() <= 0.5 + 1e-6,
            "s = {s}"
        );
    }
}

#[test]
fn dds_phase_words() {
    assert_eq!(PhaseWord::from_turns(0.25).get(), 4096);
    assert_eq!(PhaseWord::from_turns(-0.25).get(), 12_288);
    assert_eq!(PhaseWord::from_turns(1.0).get(), 0);
    assert_eq!(PhaseWord::from_turns(2.5).get(), 8192);
    assert_eq!(PhaseWord::from_radians(std::f64::consts::PI).get(), 8192);
    assert_eq!(PhaseWord::from_turns(f64::NAN).get(), 0);
    assert_eq!(PhaseWord::new(0xFFFF).get(), 0x3FFF);
    assert_eq!(PhaseWord::new(4096).turns(), 0.25);
}

#[test]
fn dds_init_selects_all_channels_3_wire() {
    let mut dds = Ad9959::new(Mock::new(&dds_write(0x00, vec![0xF2])), SYSCLK);
    dds.init().unwrap();
    assert_eq!(dds.take_io_update(), None, "CSR acts immediately");
    dds.destroy().done();
}

#[test]
fn dds_set_frequency_transactions() {
    let mut exp = dds_channel_write(Channel::Ch3, 0x04, vec![0x00, 0x02, 0xDE, 0xD8]);
    exp.extend(dds_channel_write(
        Channel::Ch1,
        0x04,
        vec![0x00, 0x02, 0xDE, 0xD8],
    ));
    let mut dds = Ad9959::new(Mock::new(&exp), SYSCLK);
    dds.set_frequency_word(Channel::SPARE, 188_120).unwrap();
    let f = dds.set_frequency(Channel::Ch1, 21_900.0).unwrap();
    assert!((f - 21_900.0).abs() < 0.12);
    assert_eq!(
        dds.take_io_update(),
        Some(IoUpdate {
            channels: 0b1010,
            function_registers: false
        })
    );
    dds.destroy().done();
}

#[test]
fn dds_set_pump_frequency_writes_three_coherent_words() {
    // one frame: 188 120, 94 060 (0x00016F6C), 282 180 (0x00044E44)
    let exp = txn(vec![T::write_vec(plan_cycles([188_120, 94_060, 282_180]))]);
    assert_eq!(
        plan_cycles([188_120, 94_060, 282_180])[10..14],
        [0x00, 0x01, 0x6F, 0x6C]
    );
    let mut dds = Ad9959::new(Mock::new(&exp), SYSCLK);
    let plan = dds.set_pump_frequency(21_900.0).unwrap();
    assert_eq!(plan.pump_ftw(), 188_120);
    let up = dds.take_io_update().expect("an I/O update is pending");
    assert_eq!(up.channels, 0b0111);
    assert!(!up.function_registers);
    assert_eq!(dds.take_io_update(), None);
    dds.destroy().done();
}

#[test]
fn dds_write_pump_is_one_frame_of_what_is_given() {
    let plan = PumpPlan::new(21_900.0, SYSCLK).unwrap();
    // CSR(pump) then ACR: s = 0.81
    let acr = vec![
        0x00,
        Channel::PUMP.csr_enable() | 0x02,
        0x06,
        0x00,
        0x13,
        0x99,
    ];
    // the words and the amplitude in one frame, then the amplitude alone
    let mut exp = txn(vec![
        T::write_vec(plan_cycles([188_120, 94_060, 282_180])),
        T::write_vec(acr.clone()),
    ]);
    exp.extend(txn(vec![T::write_vec(acr)]));
    let mut dds = Ad9959::new(Mock::new(&exp), SYSCLK);
    let asf = AmplitudeWord::from_scale(0.81);
    dds.write_pump(Some(&plan), Some(asf)).unwrap();
    assert_eq!(dds.take_io_update().map(|u| u.channels), Some(0b0111));
    dds.write_pump(None, Some(asf)).unwrap();
    assert_eq!(dds.take_io_update().map(|u| u.channels), Some(0b0001));
    // nothing given: no frame, nothing to update
    dds.write_pump(None, None).unwrap();
    assert_eq!(dds.take_io_update(), None);
    dds.destroy().done();
}

#[test]
fn dds_phase_and_amplitude_transactions() {
    let mut exp = dds_channel_write(Channel::Ch1, 0x05, vec![0x10, 0x00]); // quarter turn
    exp.extend(dds_channel_write(
        Channel::Ch0,
        0x06,
        vec![0x00, 0x13, 0x99],
    )); // s = 0.81
    exp.extend(dds_channel_write(
        Channel::Ch2,
        0x06,
        vec![0x00, 0x10, 0x00],
    ));
    let mut dds = Ad9959::new(Mock::new(&exp), SYSCLK);
    dds.set_phase(Channel::Ch1, PhaseWord::from_turns(0.25))
        .unwrap();
    assert_eq!(dds.set_pump_scale(0.81), Ok(AmplitudeWord::new(921)));
    dds.set_amplitude(Channel::Ch2, AmplitudeWord::ZERO)
        .unwrap();
    assert_eq!(dds.take_io_update().map(|u| u.channels), Some(0b0111));
    dds.destroy().done();
}

#[test]
fn dds_pll_transactions_and_validation() {
    // 25 MHz × 20 = 500 MHz: VCO gain high, divider 20 → FR1 = D0 00 00.
    let mut exp = dds_write(0x01, vec![0xD0, 0x00, 0x00]);
    // 20 MHz × 5 = 100 MHz: low VCO range → 14 00 00.
    exp.extend(dds_write(0x01, vec![0x14, 0x00, 0x00]));
    // Bypass: 400 MHz reference, multiplier 1 → 00 00 00.
    exp.extend(dds_write(0x01, vec![0x00, 0x00, 0x00]));
    let mut dds = Ad9959::new(Mock::new(&exp), 1.0);
    assert_eq!(dds.set_pll(25e6, 20), Ok(500e6));
    assert_eq!(dds.sysclk_hz(), 500e6);
    assert_eq!(
        dds.take_io_update(),
        Some(IoUpdate {
            channels: 0,
            function_registers: true
        })
    );
    assert_eq!(dds.set_pll(20e6, 5), Ok(100e6));
    assert_eq!(dds.set_pll(400e6, 1), Ok(400e6));
    // Rejected before any bus traffic: bad multiplier, VCO gap, above 500 MHz.
    let e = Err(ad9959::Error::FrequencyOutOfRange);
    assert_eq!(dds.set_pll(25e6, 3), e);
    assert_eq!(dds.set_pll(25e6, 21), e);
    assert_eq!(dds.set_pll(10e6, 20), e);
    assert_eq!(dds.set_pll(30e6, 20), e);
    assert_eq!(dds.set_pll(f64::NAN, 10), e);
    assert_eq!(dds.sysclk_hz(), 400e6);
    dds.destroy().done();
}

#[test]
fn dds_phase_alignment_transactions() {
    let mut exp = dds_write(0x02, vec![0x20, 0x00]);
    exp.extend(dds_write(0x02, vec![0x00, 0x00]));
    let mut dds = Ad9959::new(Mock::new(&exp), SYSCLK);
    dds.begin_phase_alignment().unwrap();
    assert_eq!(
        dds.take_io_update().map(|u| u.function_registers),
        Some(true)
    );
    dds.end_phase_alignment().unwrap();
    assert!(dds.take_io_update().is_some());
    dds.destroy().done();
}

#[test]
fn dds_read_frequency_word_transaction() {
    let mut exp = dds_select(Channel::Ch2);
    exp.extend(txn(vec![
        T::write_vec(vec![0x84]),
        T::read_vec(vec![0x00, 0x04, 0x4E, 0x44]),
    ]));
    let mut dds = Ad9959::new(Mock::new(&exp), SYSCLK);
    assert_eq!(dds.read_frequency_word(Channel::Ch2), Ok(282_180));
    dds.destroy().done();
}

#[test]
fn dds_out_of_range_requests_touch_no_bus() {
    let mut dds = Ad9959::new(Mock::new(&[]), SYSCLK);
    let e = Err(ad9959::Error::FrequencyOutOfRange);
    assert_eq!(dds.set_frequency(Channel::Ch0, 300e6), e);
    assert_eq!(dds.set_frequency(Channel::Ch0, -1.0), e);
    assert!(matches!(
        dds.set_pump_frequency(f64::NAN),
        Err(ad9959::Error::FrequencyOutOfRange)
    ));
    assert_eq!(dds.take_io_update(), None);
    dds.destroy().done();
}

#[test]
fn dds_every_operation_reports_spi_errors() {
    use ad9959::Error::Spi;
    let mut dds = Ad9959::new(FailingSpi::always_failing(), SYSCLK);
    assert_eq!(dds.init(), Err(Spi(FailingSpiError)));
    assert_eq!(dds.set_pll(25e6, 20), Err(Spi(FailingSpiError)));
    assert_eq!(dds.sysclk_hz(), SYSCLK);
    assert_eq!(
        dds.set_frequency_word(Channel::Ch0, 1),
        Err(Spi(FailingSpiError))
    );
    assert_eq!(
        dds.set_frequency(Channel::Ch0, 1e3),
        Err(Spi(FailingSpiError))
    );
    let plan = PumpPlan::new(21_900.0, SYSCLK).unwrap();
    assert_eq!(dds.apply_plan(&plan), Err(Spi(FailingSpiError)));
    assert_eq!(dds.set_pump_frequency(21_900.0), Err(Spi(FailingSpiError)));
    assert_eq!(
        dds.set_phase(Channel::Ch1, PhaseWord::new(1)),
        Err(Spi(FailingSpiError))
    );
    assert_eq!(
        dds.set_amplitude(Channel::Ch1, AmplitudeWord::FULL),
        Err(Spi(FailingSpiError))
    );
    assert_eq!(dds.set_pump_scale(0.5), Err(Spi(FailingSpiError)));
    assert_eq!(dds.begin_phase_alignment(), Err(Spi(FailingSpiError)));
    assert_eq!(dds.end_phase_alignment(), Err(Spi(FailingSpiError)));
    assert_eq!(
        dds.read_frequency_word(Channel::Ch0),
        Err(Spi(FailingSpiError))
    );
    assert_eq!(dds.take_io_update(), None, "nothing was written");
    // The pump update is one frame: one failed transaction fails it, nothing pending.
    let mut dds = Ad9959::new(FailingSpi::failing_after(0, 0), SYSCLK);
    assert_eq!(dds.set_pump_frequency(21_900.0), Err(Spi(FailingSpiError)));
    assert_eq!(dds.take_io_update(), None);
    // An absent DDS reads back all-ones or zeros.
    let mut dds = Ad9959::new(FailingSpi::responding(0xFF), SYSCLK);
    assert_eq!(dds.read_frequency_word(Channel::Ch0), Ok(0xFFFF_FFFF));
}

// ------------------------------------------------------------------------------------------
// FailingSpi itself

#[test]
fn failing_spi_fails_on_command() {
    let mut spi = FailingSpi::failing_after(2, 0x5A);
    let mut buf = [0u8; 3];
    spi.read(&mut buf).unwrap();
    assert_eq!(buf, [0x5A; 3]);
    spi.write(&[1, 2]).unwrap();
    assert_eq!(spi.transfer_in_place(&mut buf), Err(FailingSpiError));
    assert_eq!(spi.transactions(), 3);

    let mut spi = FailingSpi::responding(0x00);
    let mut read = [0xEEu8; 2];
    spi.transfer(&mut read, &[1, 2]).unwrap();
    assert_eq!(read, [0, 0]);
    spi.fail_now();
    assert_eq!(spi.write(&[0]), Err(FailingSpiError));

    let mut spi = FailingSpi::always_failing();
    assert_eq!(spi.write(&[0]), Err(FailingSpiError));
    use embedded_hal::spi::Error as _;
    assert_eq!(FailingSpiError.kind(), embedded_hal::spi::ErrorKind::Other);
}
