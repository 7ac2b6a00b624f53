//! Host tests of the application layer (`app`) over the replay devices (`replay`):
//! the firmware path against the bare estimator bit for bit, every fault path, the pump
//! guard, and the replay devices themselves through the real drivers.

use embedded_hal::spi::{Operation, SpiDevice as _};
use embedded_hal_mock::eh1::delay::NoopDelay;
use paragyro_core::estimator::event;
use paragyro_core::{Config, Counters, Cplx, Estimator, Lockin, Sample, StepOutput};
use paragyro_firmware::app::{
    App, Chips, FwCounters, IoUpdate, PumpAmplitude, PumpGuard, TEMP_EVERY, TEMP_PLAUSIBLE_C,
    TickReport, fault, plausible_temp_c,
};
use paragyro_firmware::drivers::ad9959::{
    self, Ad9959, AmplitudeWord, Channel, DEFAULT_SYSCLK_HZ, PumpPlan,
};
use paragyro_firmware::drivers::ads131m08::{
    self, Ads131m08, Gain, LOCKIN_CHANNELS, LockinCalibration, RawCode,
};
use paragyro_firmware::drivers::adxl355::{self, Adxl355, HighPass, Odr, Range, RawAccel};
use paragyro_firmware::replay::{
    AdcFaults, CaptureDds, DdsCapture, NoIoUpdate, ReplayAccel, ReplayAdc, ReplayError, Span,
    accel_bytes, encode_accel, encode_lockin, encode_temp, encode_um, temp_bytes,
};

const SYSCLK: f64 = DEFAULT_SYSCLK_HZ;
/// One pump step of the DDS (pump word 2k), Hz.
const PUMP_STEP_HZ: f64 = 2.0 * SYSCLK / ad9959::FTW_SCALE;
/// Faults are injected at this sample (tick) index: past the start-up gate (0.5 s) and
/// the dither onset (1 s), so the RLS updates and the pump moves every tick.
const F: usize = 600;
/// The ADXL355 temperature code the clean rig serves: ≈ 31.4 °C.
const TEMP_CODE: u16 = 1827;

type TestApp<'a> = App<ReplayAdc<'a>, ReplayAdc<'a>, ReplayAccel<'a>, CaptureDds<'a>>;

// ------------------------------------------------------------------------------------------
// data and rig

/// Drive axis: ±12 µm over the ADC's ±1.2 V (below the core's 20 µm full scale, so a
/// clipped code must be *made* saturated by the firmware), with zero-motion offsets.
fn cal_x() -> LockinCalibration {
    LockinCalibration::from_um_per_volt(
        [12.0 / 1.2; LOCKIN_CHANNELS],
        [Gain::G1; LOCKIN_CHANNELS],
        [120, -75, 33, 0, -1, 250, -300],
    )
}

/// Sense axis: ±10 µm, one channel wired inverted.
fn cal_y() -> LockinCalibration {
    let mut c = LockinCalibration::from_um_per_volt(
        [10.0 / 1.2; LOCKIN_CHANNELS],
        [Gain::G1; LOCKIN_CHANNELS],
        [-40, 17, 0, 900, -900, 5, 64],
    );
    c.um_per_code[2] = -c.um_per_code[2];
    c
}

/// Lock-in values like the core's own tests (`estimator.rs`, `sample()`): a plausible
/// steady state of the Table 2 gyro where every channel moves a little (real data always
/// carries noise; a constant channel would rightly be flagged as stuck).
fn lockin_um(k: usize) -> ([f32; LOCKIN_CHANNELS], [f32; LOCKIN_CHANNELS]) {
    let d = |i: usize| (((k + 3 * i) * 7919) % 13) as f32 * 1e-5;
    let x = [
        0.0204 + d(0),
        1.2 + d(1),
        -1.27 + d(2),
        1e-4 + d(3),
        d(4),
        0.001 + d(5),
        0.002 + d(6),
    ];
    let y = [
        0.0207 - d(7),
        0.9 + d(8),
        1.2 - d(9),
        d(10),
        1e-4 + d(11),
        0.0005 + d(12),
        -0.001 + d(13),
    ];
    (x, y)
}

struct Data {
    x: Vec<[f32; LOCKIN_CHANNELS]>,
    y: Vec<[f32; LOCKIN_CHANNELS]>,
    acc: Vec<[f32; 2]>,
}

fn data(n: usize) -> Data {
    let (x, y) = (0..n).map(lockin_um).unzip();
    // a small, varying frame acceleration (well inside the ADXL355's ±2 g)
    let acc = (0..n)
        .map(|k| [0.02 * (k % 7) as f32 - 0.05, 0.3 - 0.01 * (k % 5) as f32])
        .collect();
    Data { x, y, acc }
}

fn guard(cfg: &Config) -> PumpGuard {
    PumpGuard::around(cfg.pump_centre_hz, 400.0)
}

fn chips<'a>(
    adc_x: ReplayAdc<'a>,
    adc_y: ReplayAdc<'a>,
    accel: ReplayAccel<'a>,
    cap: &'a DdsCapture,
) -> Chips<ReplayAdc<'a>, ReplayAdc<'a>, ReplayAccel<'a>, CaptureDds<'a>> {
    Chips {
        adc_x: Ads131m08::new(adc_x),
        adc_y: Ads131m08::new(adc_y),
        accel: Adxl355::new(accel),
        dds: Ad9959::new(cap.spi(), SYSCLK),
    }
}

fn build<'a>(
    adc_x: ReplayAdc<'a>,
    adc_y: ReplayAdc<'a>,
    accel: ReplayAccel<'a>,
    cap: &'a DdsCapture,
) -> TestApp<'a> {
    let cfg = Config::table2();
    App::new(
        chips(adc_x, adc_y, accel, cap),
        &cfg,
        cal_x(),
        cal_y(),
        guard(&cfg),
    )
    .unwrap()
}

fn clean<'a>(d: &'a Data, cap: &'a DdsCapture) -> TestApp<'a> {
    build(
        ReplayAdc::new(&d.x, cal_x()),
        ReplayAdc::new(&d.y, cal_y()),
        ReplayAccel::new(&d.acc).with_temp_raw(TEMP_CODE),
        cap,
    )
}

/// Invariants of every tick: the pump in effect is inside the guard, is what the DDS
/// model actually runs, and the references stay phase-locked to it.
fn check_tick(app: &TestApp<'_>, cap: &DdsCapture, r: &TickReport) {
    let g = app.guard();
    assert!(g.contains(r.pump_hz), "pump {} outside {g:?}", r.pump_hz);
    assert_eq!(r.pump_hz.to_bits(), cap.active_pump_hz().to_bits());
    assert_eq!(r.pump_hz.to_bits(), app.pump_hz().to_bits());
    let asf = cap.active().asf_of(Channel::PUMP);
    assert_eq!(
        r.pump_scale.to_bits(),
        app.pump_amplitude().realised(asf).to_bits()
    );
    assert!(cap.active().phase_locked(), "{:?}", cap.active());
    assert!(r.out.pump_hz_next.is_finite());
}

/// The estimator alone, fed the values the firmware decodes from the replayed codes
/// (computed here with the drivers' public conversions, not through `App`).
struct Reference {
    est: Estimator<f32>,
    cx: LockinCalibration,
    cy: LockinCalibration,
}

impl Reference {
    fn new() -> Self {
        Self {
            est: Config::table2().build::<f32>().unwrap(),
            cx: cal_x(),
            cy: cal_y(),
        }
    }

    fn sample(&self, d: &Data, k: usize, pump_hz: f64, pump_scale: f32) -> Sample<f32> {
        let ux = self.cx.to_um(&encode_lockin(&self.cx, &d.x[k]));
        let uy = self.cy.to_um(&encode_lockin(&self.cy, &d.y[k]));
        let c = |re: [f32; 3], im: [f32; 3]| {
            [
                Cplx::new(re[0], im[0]),
                Cplx::new(re[1], im[1]),
                Cplx::new(re[2], im[2]),
            ]
        };
        let [ax, ay] = d.acc[k];
        let raw = RawAccel {
            x: encode_accel(ax, Range::G2),
            y: encode_accel(ay, Range::G2),
            z: 0,
        };
        let [ax, ay, _] = raw.to_mps2(Range::G2);
        Sample {
            lockin: Lockin {
                x0_um: ux.x0_um,
                x_um: c(ux.re_um, ux.im_um),
                y0_um: uy.x0_um,
                y_um: c(uy.re_um, uy.im_um),
            },
            accel_mps2: [ax, ay],
            pump_hz,
            pump_scale,
            temp_c: Some(adxl355::temp_c_from_raw(TEMP_CODE)),
        }
    }
}

fn same_output(a: &StepOutput, b: &StepOutput, k: usize) {
    assert_eq!(
        a.pump_hz_next.to_bits(),
        b.pump_hz_next.to_bits(),
        "pump at {k}"
    );
    assert_eq!(
        a.pump_scale_next.to_bits(),
        b.pump_scale_next.to_bits(),
        "scale at {k}"
    );
    assert_eq!(a.health, b.health, "health at {k}");
    assert_eq!(a.events, b.events, "events at {k}");
    assert_eq!(a.updated, b.updated, "updated at {k}");
}

/// Ticks `n` times checking the invariants and that every sample was good.
fn run_good(app: &mut TestApp<'_>, cap: &DdsCapture, n: usize) -> TickReport {
    let mut io = cap.io_update();
    let mut last = None;
    for _ in 0..n {
        let r = app.tick(&mut io);
        check_tick(app, cap, &r);
        assert!(r.sample_ok && r.out.health.inputs_valid, "{r:?}");
        last = Some(r);
    }
    last.unwrap()
}

// ------------------------------------------------------------------------------------------
// (1) the firmware path adds nothing but quantisation

#[test]
fn firmware_path_is_the_estimator_on_the_decoded_values_bit_for_bit() {
    let n = 1500;
    let d = data(n);
    let cap = DdsCapture::new(SYSCLK);
    let mut io = cap.io_update();
    let mut app = clean(&d, &cap);
    let mut reference = Reference::new();

    let plan = app.start(&mut io).unwrap();
    // the known pump of sample 0: the realised initial pump, full scale word
    let mut pump = PumpPlan::new(reference.est.initial_pump_hz(), SYSCLK)
        .unwrap()
        .pump_hz();
    let mut scale = AmplitudeWord::from_scale(1.0).scale();
    assert_eq!(plan.pump_hz().to_bits(), pump.to_bits());
    assert_eq!(cap.active_pump_hz().to_bits(), pump.to_bits());
    assert_eq!(cap.pulses(), 1);
    assert!((pump - reference.est.initial_pump_hz()).abs() <= PUMP_STEP_HZ / 2.0);

    let mut pulses = cap.pulses();
    let mut pump_moves = 0;
    let mut scale_moves = 0;
    for k in 0..n {
        let r = app.tick(&mut io);
        let out = reference.est.step(&reference.sample(&d, k, pump, scale));
        same_output(&r.out, &out, k);
        assert!(r.sample_ok && r.faults == 0, "tick {k}: {r:?}");

        // the realised DDS frequency and amplitude become the next sample's known pump
        let next = PumpPlan::new(out.pump_hz_next, SYSCLK).unwrap().pump_hz();
        let next_scale = AmplitudeWord::from_scale(out.pump_scale_next as f32).scale();
        assert_eq!(r.pump_hz.to_bits(), next.to_bits(), "tick {k}");
        assert_eq!(r.pump_scale.to_bits(), next_scale.to_bits(), "tick {k}");
        check_tick(&app, &cap, &r);
        // one IO_UPDATE exactly when a word changed
        let changed = next != pump || next_scale != scale;
        pump_moves += usize::from(next != pump);
        scale_moves += usize::from(next_scale != scale);
        pulses += u32::from(changed);
        assert_eq!(cap.pulses(), pulses, "tick {k}");
        pump = next;
        scale = next_scale;
    }
    // not vacuous: the RLS ran, the dither moved the pump, the amplitude dither the scale
    let c = app.estimator().counters();
    assert!(c.updates > 1000, "{c:?}");
    assert_eq!(c.bad_samples, 0);
    assert!(pump_moves > 400, "pump moved {pump_moves} times");
    assert!(scale_moves > 100, "scale moved {scale_moves} times");
    assert_eq!(app.estimator().theta(), reference.est.theta());
    assert_eq!(app.estimator().counters(), reference.est.counters());
    assert_eq!(
        app.counters(),
        FwCounters {
            ticks: n as u32,
            ..FwCounters::default()
        }
    );
    let (chips, _) = app.release();
    assert_eq!(chips.adc_x.destroy().samples_served(), n);
    assert_eq!(chips.adc_y.destroy().samples_served(), n);
    assert_eq!(chips.accel.destroy().samples_served(), n);
}

#[test]
fn quantisation_is_at_most_half_a_code() {
    let d = data(200);
    for (cal, rows) in [(cal_x(), &d.x), (cal_y(), &d.y)] {
        for row in rows.iter() {
            let back = cal.to_um(&encode_lockin(&cal, row));
            let back = [
                back.x0_um,
                back.re_um[0],
                back.im_um[0],
                back.re_um[1],
                back.im_um[1],
                back.re_um[2],
                back.im_um[2],
            ];
            for ((b, v), s) in back.iter().zip(row).zip(cal.um_per_code) {
                assert!((b - v).abs() <= 0.5 * s.abs() * 1.001 + 1e-6 * v.abs());
            }
        }
    }
}

// ------------------------------------------------------------------------------------------
// (2) faults: flagged, estimate held, the right counter, no panic, pump inside the guard

/// Runs `app` to tick `F`, checking that the RLS updates just before it, then runs the
/// faulty tick `F` and checks the common fault behaviour; `check` sees the counters
/// before and after. Then runs on until the estimator updates again.
fn fault_case(
    name: &str,
    mut app: TestApp<'_>,
    cap: &DdsCapture,
    check: impl Fn(&FwCounters, &FwCounters, &Counters, &Counters, &TickReport),
) {
    let mut io = cap.io_update();
    app.start(&mut io).unwrap();
    run_good(&mut app, cap, F - 1);
    let th0 = app.estimator().theta();
    let r = run_good(&mut app, cap, 1); // tick F − 1
    assert!(
        r.out.updated,
        "{name}: the RLS does not update before the fault"
    );
    let th = app.estimator().theta();
    assert_ne!(th, th0, "{name}: θ̂ does not move on a good tick");
    let (fw0, c0) = (app.counters(), app.estimator().counters());

    let r = app.tick(&mut io); // tick F: the fault
    check_tick(&app, cap, &r);
    let (fw1, c1) = (app.counters(), app.estimator().counters());
    assert!(
        !r.sample_ok || !r.out.health.inputs_valid,
        "{name}: not flagged"
    );
    assert!(!r.out.health.inputs_valid, "{name}: the core took it");
    assert!(!r.out.updated, "{name}: the RLS used it");
    assert!(r.out.events & event::BAD_INPUT != 0, "{name}: no event");
    assert_eq!(app.estimator().theta(), th, "{name}: estimate not held");
    assert_eq!(c1.bad_samples, c0.bad_samples + 1, "{name}: core counter");
    assert_eq!(fw1.ticks, fw0.ticks + 1);
    check(&fw0, &fw1, &c0, &c1, &r);

    // recovery: gated for bad_input_gate_s, then updating again
    let mut recovered = false;
    for _ in 0..200 {
        let r = app.tick(&mut io);
        check_tick(&app, cap, &r);
        assert!(r.sample_ok && r.out.health.inputs_valid, "{name}: {r:?}");
        recovered |= r.out.updated;
    }
    assert!(recovered, "{name}: never recovered");
    assert_eq!(app.estimator().counters().bad_samples, c1.bad_samples);
}

/// Only `field` of the firmware counters moved (besides `ticks`), by one.
fn only(fw0: &FwCounters, fw1: &FwCounters, field: fn(&mut FwCounters) -> &mut u32) {
    let mut expect = *fw0;
    *field(&mut expect) += 1;
    expect.ticks += 1;
    assert_eq!(*fw1, expect);
}

#[test]
fn adc_crc_error_is_a_lost_frame() {
    let d = data(F + 300);
    let cap = DdsCapture::new(SYSCLK);
    let app = build(
        ReplayAdc::new(&d.x, cal_x()),
        ReplayAdc::new(&d.y, cal_y()).with_crc_error(Span::at(F)),
        ReplayAccel::new(&d.acc),
        &cap,
    );
    fault_case("CRC", app, &cap, |fw0, fw1, c0, c1, r| {
        only(fw0, fw1, |c| &mut c.adc_crc_errors);
        assert_eq!(c1.non_finite, c0.non_finite + 1);
        assert_eq!(r.faults, fault::ADC_Y);
        assert!(!r.sample_ok);
    });
}

#[test]
fn adc_spi_error_is_a_lost_frame() {
    let d = data(F + 300);
    let cap = DdsCapture::new(SYSCLK);
    let app = build(
        ReplayAdc::new(&d.x, cal_x()).with_spi_error(Span::at(F)),
        ReplayAdc::new(&d.y, cal_y()),
        ReplayAccel::new(&d.acc),
        &cap,
    );
    fault_case("SPI", app, &cap, |fw0, fw1, c0, c1, r| {
        only(fw0, fw1, |c| &mut c.adc_spi_errors);
        assert_eq!(c1.non_finite, c0.non_finite + 1);
        assert_eq!(r.faults, fault::ADC_X);
    });
}

#[test]
fn adc_not_ready_is_a_lost_frame() {
    let d = data(F + 300);
    let cap = DdsCapture::new(SYSCLK);
    let app = build(
        ReplayAdc::new(&d.x, cal_x()).with_not_ready(Span::at(F)),
        ReplayAdc::new(&d.y, cal_y()),
        ReplayAccel::new(&d.acc),
        &cap,
    );
    fault_case("NotReady", app, &cap, |fw0, fw1, c0, c1, r| {
        only(fw0, fw1, |c| &mut c.adc_not_ready);
        assert_eq!(c1.non_finite, c0.non_finite + 1);
        assert_eq!(r.faults, fault::ADC_X);
    });
}

#[test]
fn adc_saturated_code_is_saturated_for_the_core() {
    let d = data(F + 300);
    let cap = DdsCapture::new(SYSCLK);
    // X0 clips at the ADC's 12 µm, below the core's 20 µm: the firmware must say so
    let app = build(
        ReplayAdc::new(&d.x, cal_x()).with_saturation(Span::at(F), ads131m08::channel::X0),
        ReplayAdc::new(&d.y, cal_y()),
        ReplayAccel::new(&d.acc),
        &cap,
    );
    fault_case("saturated", app, &cap, |fw0, fw1, c0, c1, r| {
        only(fw0, fw1, |c| &mut c.adc_saturated);
        assert_eq!(c1.saturated, c0.saturated + 1);
        assert_eq!(c1.non_finite, c0.non_finite);
        assert_eq!(r.faults, fault::SATURATED);
    });
}

#[test]
fn stuck_adc_channel_is_flagged_by_the_core() {
    let d = data(F + 300);
    let cap = DdsCapture::new(SYSCLK);
    let limit = Config::table2().monitor.stuck_samples as usize;
    // B1 re holds its code from F − limit to F: the core flags the limit-th repeat (F)
    let app = build(
        ReplayAdc::new(&d.x, cal_x()),
        ReplayAdc::new(&d.y, cal_y()).with_stuck(Span::new(F - limit, F + 1), 1),
        ReplayAccel::new(&d.acc),
        &cap,
    );
    fault_case("stuck", app, &cap, |fw0, fw1, c0, c1, r| {
        // every chip answered: the firmware's sample is fine, the core's verdict is not
        assert!(r.sample_ok && r.faults == 0);
        assert_eq!(
            *fw1,
            FwCounters {
                ticks: fw0.ticks + 1,
                ..*fw0
            }
        );
        assert_eq!(c1.stuck, c0.stuck + 1);
    });
}

#[test]
fn missing_accelerometer_is_a_lost_sample() {
    let d = data(F + 300);
    let cap = DdsCapture::new(SYSCLK);
    let app = build(
        ReplayAdc::new(&d.x, cal_x()),
        ReplayAdc::new(&d.y, cal_y()),
        ReplayAccel::new(&d.acc).with_missing(Span::at(F)),
        &cap,
    );
    fault_case("accel missing", app, &cap, |fw0, fw1, c0, c1, r| {
        only(fw0, fw1, |c| &mut c.accel_errors);
        assert_eq!(c1.non_finite, c0.non_finite + 1);
        assert_eq!(r.faults, fault::ACCEL);
    });
}

#[test]
fn accelerometer_spi_error_is_a_lost_sample() {
    let d = data(F + 300);
    let cap = DdsCapture::new(SYSCLK);
    let app = build(
        ReplayAdc::new(&d.x, cal_x()),
        ReplayAdc::new(&d.y, cal_y()),
        ReplayAccel::new(&d.acc).with_spi_error(Span::at(F)),
        &cap,
    );
    fault_case("accel SPI", app, &cap, |fw0, fw1, _, _, r| {
        only(fw0, fw1, |c| &mut c.accel_errors);
        assert_eq!(r.faults, fault::ACCEL);
    });
}

#[test]
fn clipped_accelerometer_is_saturated_for_the_core() {
    let mut d = data(F + 300);
    d.acc[F][1] = -30.0; // beyond ±2 g: the ADXL355 code clips
    let cap = DdsCapture::new(SYSCLK);
    let app = clean(&d, &cap);
    fault_case("accel clipped", app, &cap, |fw0, fw1, c0, c1, r| {
        only(fw0, fw1, |c| &mut c.accel_saturated);
        assert_eq!(c1.saturated, c0.saturated + 1);
        assert_eq!(r.faults, fault::SATURATED);
    });
}

/// Every tick's sample carries the ADXL355's die temperature from the TEMP2/TEMP1 bytes
/// of its burst, in °C by the driver's transfer function; the boot read gives the same.
#[test]
fn the_sample_carries_the_accelerometer_temperature() {
    let d = data(20);
    for (code, want) in [
        (1885, 25.0f32),
        (1704, 45.0),
        (2337, -24.945),
        (754, 149.97),
    ] {
        let cap = DdsCapture::new(SYSCLK);
        let mut io = cap.io_update();
        let mut app = build(
            ReplayAdc::new(&d.x, cal_x()),
            ReplayAdc::new(&d.y, cal_y()),
            ReplayAccel::new(&d.acc).with_temp_raw(code),
            &cap,
        );
        assert_eq!(app.last_sample().temp_c, None, "no sample yet");
        let boot = app.read_temperature_c().unwrap();
        assert!((boot - want).abs() < 0.01, "code {code}: {boot} °C at boot");
        app.start(&mut io).unwrap();
        for _ in 0..10 {
            let r = app.tick(&mut io);
            assert!(r.sample_ok && r.faults == 0, "{r:?}");
            let t = app.last_sample().temp_c.unwrap();
            assert_eq!(t.to_bits(), boot.to_bits(), "code {code}");
        }
        assert_eq!(
            app.counters(),
            FwCounters {
                ticks: 10,
                ..FwCounters::default()
            }
        );
    }
}

/// A temperature code outside −60…+150 °C (the reset value 0, all-ones, one code past
/// either end) gives `temp_c: None`, and only that: the acceleration and the sample are
/// good, no fault bit, no counter. The boot read says the same.
#[test]
fn an_implausible_temperature_code_is_none_and_the_sample_stays_good() {
    let (lo, hi) = TEMP_PLAUSIBLE_C;
    // the window's ends in codes: 754 (≈ 149.97 °C) and 2654 (≈ −59.97 °C) are inside
    assert!(plausible_temp_c(754).is_some() && plausible_temp_c(2654).is_some());
    assert_eq!(plausible_temp_c(753), None);
    assert_eq!(plausible_temp_c(2655), None);
    assert!(adxl355::temp_c_from_raw(753) > hi && adxl355::temp_c_from_raw(2655) < lo);
    let d = data(20);
    for code in [0, 0x0FFF, 753, 2655] {
        let cap = DdsCapture::new(SYSCLK);
        let mut io = cap.io_update();
        let mut app = build(
            ReplayAdc::new(&d.x, cal_x()),
            ReplayAdc::new(&d.y, cal_y()),
            ReplayAccel::new(&d.acc).with_temp_raw(code),
            &cap,
        );
        assert_eq!(app.read_temperature_c(), None, "boot read of code {code}");
        app.start(&mut io).unwrap();
        for _ in 0..10 {
            let r = app.tick(&mut io);
            assert!(r.sample_ok && r.faults == 0, "code {code}: {r:?}");
            assert!(r.out.health.inputs_valid);
            let s = app.last_sample();
            assert_eq!(s.temp_c, None, "code {code}");
            assert!(s.accel_mps2.iter().all(|a| a.is_finite()));
        }
        assert_eq!(
            app.counters(),
            FwCounters {
                ticks: 10,
                ..FwCounters::default()
            }
        );
    }
    // a replayed record carries no temperature: the replay's default code is 0
    let cap = DdsCapture::new(SYSCLK);
    let mut io = cap.io_update();
    let mut app = build(
        ReplayAdc::new(&d.x, cal_x()),
        ReplayAdc::new(&d.y, cal_y()),
        ReplayAccel::new(&d.acc),
        &cap,
    );
    app.start(&mut io).unwrap();
    assert!(app.tick(&mut io).sample_ok);
    assert_eq!(app.last_sample().temp_c, None);
}

/// The temperature is taken from every `TEMP_EVERY`-th burst, the first tick's included,
/// and held between: a failed accelerometer read (bus error, absent device, stuck codes)
/// on a reading tick gives `None` until the next reading tick; on any other tick the held
/// temperature stays.
#[test]
fn the_temperature_is_read_every_temp_every_ticks_and_held_between() {
    let every = usize::from(TEMP_EVERY);
    assert_eq!(every, 50, "10 Hz at 500 Hz");
    let n = 2 * every + 5;
    let d = data(n);
    let want = Some(adxl355::temp_c_from_raw(TEMP_CODE));
    let cap = DdsCapture::new(SYSCLK);
    let mut io = cap.io_update();
    let mut app = build(
        ReplayAdc::new(&d.x, cal_x()),
        ReplayAdc::new(&d.y, cal_y()),
        ReplayAccel::new(&d.acc)
            .with_temp_raw(TEMP_CODE)
            .with_spi_error(Span::at(3))
            .with_missing(Span::at(every)),
        &cap,
    );
    app.start(&mut io).unwrap();
    for k in 0..n {
        let r = app.tick(&mut io);
        let bad = k == 3 || k == every;
        assert_eq!(r.faults, if bad { fault::ACCEL } else { 0 }, "tick {k}");
        let lost = (every..2 * every).contains(&k);
        let t = app.last_sample().temp_c;
        assert_eq!(t, if lost { None } else { want }, "tick {k}");
    }
    assert_eq!(app.counters().accel_errors, 2);
    // `configure` starts over: the next tick reads
    let cfg = Config::table2();
    app.configure(&cfg, cal_x(), cal_y(), guard(&cfg)).unwrap();
    assert_eq!(app.last_sample().temp_c, None);

    // stuck X and Y codes: refused, and the next reading tick has no temperature
    let mut d = data(2 * every);
    d.acc.fill([0.1, -0.2]);
    let cap = DdsCapture::new(SYSCLK);
    let mut io = cap.io_update();
    let mut app = clean(&d, &cap);
    app.set_accel_stuck_limit(3);
    app.start(&mut io).unwrap();
    for k in 0..2 * every {
        let r = app.tick(&mut io);
        assert_eq!(r.faults, if k >= 2 { fault::ACCEL } else { 0 }, "tick {k}");
        let t = app.last_sample().temp_c;
        assert_eq!(t, if k >= every { None } else { want }, "tick {k}");
    }

    // the boot read fails on an absent device (all-ones: code 0xFFF)
    let d = data(4);
    let cap = DdsCapture::new(SYSCLK);
    let mut app = build(
        ReplayAdc::new(&d.x, cal_x()),
        ReplayAdc::new(&d.y, cal_y()),
        ReplayAccel::new(&d.acc)
            .with_temp_raw(TEMP_CODE)
            .with_missing(Span::new(0, 1)),
        &cap,
    );
    assert_eq!(app.read_temperature_c(), None);
}

#[test]
fn several_faults_in_one_tick_are_all_counted() {
    let d = data(F + 300);
    let cap = DdsCapture::new(SYSCLK);
    let app = build(
        ReplayAdc::new(&d.x, cal_x()).with_faults(AdcFaults {
            crc: Span::at(F),
            ..AdcFaults::default()
        }),
        ReplayAdc::new(&d.y, cal_y()).with_saturation(Span::at(F), 6),
        ReplayAccel::new(&d.acc).with_missing(Span::at(F)),
        &cap,
    );
    fault_case("several", app, &cap, |fw0, fw1, _, _, r| {
        assert_eq!(fw1.adc_crc_errors, fw0.adc_crc_errors + 1);
        assert_eq!(fw1.adc_saturated, fw0.adc_saturated + 1);
        assert_eq!(fw1.accel_errors, fw0.accel_errors + 1);
        assert_eq!(r.faults, fault::ADC_X | fault::SATURATED | fault::ACCEL);
    });
}

#[test]
fn dds_write_error_keeps_the_pump_in_effect_and_rewrites_everything() {
    let n = F + 300;
    let d = data(n);
    let cap = DdsCapture::new(SYSCLK);
    let mut io = cap.io_update();
    let mut app = clean(&d, &cap);
    let mut reference = Reference::new();
    app.start(&mut io).unwrap();
    let mut pump = app.pump_hz();
    let mut scale = app.pump_scale();
    let mut fail_from = None;
    for k in 0..n {
        if k == F {
            // this tick's frame (its words and amplitude) fails
            let t = cap.transactions();
            cap.fail_transactions(Span::at(t));
            fail_from = Some(t);
        }
        if k == F + 10 {
            // then ten ticks of a dead bus
            cap.fail_transactions(Span::starting_at(cap.transactions()));
        }
        if k == F + 20 {
            cap.fail_transactions(Span::NEVER);
        }
        let (pulses, dds_errors, t0) =
            (cap.pulses(), app.counters().dds_errors, cap.transactions());
        let r = app.tick(&mut io);
        // the core always gets the pump the DDS really runs
        let out = reference.est.step(&reference.sample(&d, k, pump, scale));
        same_output(&r.out, &out, k);
        check_tick(&app, &cap, &r);
        assert!(r.sample_ok && r.out.health.inputs_valid, "tick {k}");
        let failing = k == F || (F + 10..F + 20).contains(&k);
        if failing {
            assert_eq!(r.faults, fault::DDS, "tick {k}");
            assert_eq!(app.counters().dds_errors, dds_errors + 1);
            assert_eq!(cap.pulses(), pulses, "tick {k}: pulsed after an error");
            assert_eq!(
                r.pump_hz.to_bits(),
                pump.to_bits(),
                "tick {k}: pump not held"
            );
            assert_eq!(r.pump_scale.to_bits(), scale.to_bits());
        } else {
            assert_eq!(r.faults, 0, "tick {k}");
        }
        if k == F {
            assert_eq!(cap.transactions(), fail_from.unwrap() + 1);
            // a frame cut short on a real bus leaves part of it in the buffers: the pump's
            // word alone, next to the old reference word
            let mut spi = cap.spi();
            let ftw = cap.buffered().ftw_of(Channel::PUMP) + 2;
            let [a, b, c, d] = ftw.to_be_bytes();
            spi.write(&[0x00, Channel::PUMP.csr_enable() | 0x02, 0x04, a, b, c, d])
                .unwrap();
            let b = cap.buffered();
            assert!(!b.phase_locked(), "the partial write is in the buffers");
            assert_ne!(cap.buffered_pump_hz(), cap.active_pump_hz());
        }
        if k == F + 1 || k == F + 20 {
            // recovery: every word rewritten in one frame (3 channels' CSR + CFTW0,
            // CSR + ACR), one pulse
            assert_eq!(cap.transactions() - t0, 1, "tick {k}");
            assert_eq!(cap.pulses(), pulses + 1);
            assert_eq!(cap.buffered(), cap.active());
        }
        pump = r.pump_hz;
        scale = r.pump_scale;
    }
    assert_eq!(app.counters().dds_errors, 11);
    assert_eq!(cap.failures(), 1 + 10); // a dead bus fails a tick at its first write
    assert_eq!(app.estimator().theta(), reference.est.theta());
}

// ------------------------------------------------------------------------------------------
// (3) the guard

#[test]
fn guard_clamps_core_commands_outside_the_window() {
    let d = data(F + 400);
    let cap = DdsCapture::new(SYSCLK);
    let mut io = cap.io_update();
    let mut app = clean(&d, &cap);
    app.start(&mut io).unwrap();
    run_good(&mut app, &cap, F);
    let g = app.guard();
    assert_eq!(app.counters().guard_clamps, 0);

    // the core jumps its centre 300 Hz above the window
    app.estimator_mut()
        .command_pump_centre(g.max_hz + 300.0, true);
    let mut clamps = 0;
    for _ in 0..100 {
        let r = app.tick(&mut io);
        check_tick(&app, &cap, &r);
        assert!(
            r.out.pump_hz_next > g.max_hz,
            "the core does command outside"
        );
        assert!(r.faults & fault::GUARD != 0);
        assert!(r.pump_hz <= g.max_hz && r.pump_hz > g.max_hz - PUMP_STEP_HZ);
        clamps += 1;
        assert_eq!(app.counters().guard_clamps, clamps);
    }
    // and below
    app.estimator_mut()
        .command_pump_centre(g.min_hz - 300.0, true);
    for _ in 0..100 {
        let r = app.tick(&mut io);
        check_tick(&app, &cap, &r);
        assert!(r.pump_hz >= g.min_hz && r.pump_hz < g.min_hz + PUMP_STEP_HZ);
        clamps += 1;
    }
    assert_eq!(app.counters().guard_clamps, clamps);
    // back inside: no more clamps
    let centre = Config::table2().pump_centre_hz;
    app.estimator_mut().command_pump_centre(centre, true);
    for _ in 0..100 {
        let r = app.tick(&mut io);
        check_tick(&app, &cap, &r);
        assert_eq!(r.faults & fault::GUARD, 0);
    }
    assert_eq!(app.counters().guard_clamps, clamps);
}

#[test]
fn guard_keeps_the_realised_word_inside() {
    let k = 94_000u64;
    let grid = k as f64 * PUMP_STEP_HZ;
    // an upper edge 0.6 steps above a grid point: the nearest word is outside
    let g = PumpGuard::new(grid - 100.0, grid + 0.6 * PUMP_STEP_HZ);
    let p = g.plan(1e9, SYSCLK).unwrap();
    assert!(g.contains(p.pump_hz()));
    assert_eq!(p.pump_hz(), PumpPlan::new(grid, SYSCLK).unwrap().pump_hz());
    assert!(PumpPlan::new(g.max_hz, SYSCLK).unwrap().pump_hz() > g.max_hz);
    // the same at the lower edge
    let g = PumpGuard::new(grid - 0.6 * PUMP_STEP_HZ, grid + 100.0);
    let p = g.plan(0.0, SYSCLK).unwrap();
    assert!(g.contains(p.pump_hz()));
    assert_eq!(p.pump_hz(), PumpPlan::new(grid, SYSCLK).unwrap().pump_hz());
    // a window between two grid points holds no word
    let g = PumpGuard::new(grid + 0.1 * PUMP_STEP_HZ, grid + 0.9 * PUMP_STEP_HZ);
    assert!(g.plan(grid, SYSCLK).is_none());
    // NaN and infinities never escape
    let g = PumpGuard::new(20_000.0, 22_000.0);
    assert_eq!(g.clamp(f64::NAN), 20_000.0);
    assert_eq!(g.clamp(f64::INFINITY), 22_000.0);
    assert!(g.contains(g.plan(f64::NEG_INFINITY, SYSCLK).unwrap().pump_hz()));
}

// ------------------------------------------------------------------------------------------
// construction, start-up, amplitude

#[test]
fn new_rejects_bad_configurations() {
    let d = data(10);
    let cap = DdsCapture::new(SYSCLK);
    let cfg = Config::table2();
    let c = cfg.pump_centre_hz;
    let try_new = |cfg: &Config, g: PumpGuard| {
        App::new(
            chips(
                ReplayAdc::new(&d.x, cal_x()),
                ReplayAdc::new(&d.y, cal_y()),
                ReplayAccel::new(&d.acc),
                &cap,
            ),
            cfg,
            cal_x(),
            cal_y(),
            g,
        )
        .map(|_| ())
    };
    assert_eq!(try_new(&cfg, guard(&cfg)), Ok(()));
    let field = |cfg: &Config, g| try_new(cfg, g).unwrap_err().field;
    assert_eq!(field(&cfg, PumpGuard::new(c + 10.0, c - 10.0)), "guard");
    assert_eq!(field(&cfg, PumpGuard::new(f64::NAN, c)), "guard");
    assert_eq!(field(&cfg, PumpGuard::new(-1.0, c)), "guard");
    assert_eq!(field(&cfg, PumpGuard::new(c + 1.0, c + 100.0)), "guard");
    assert_eq!(field(&cfg, PumpGuard::new(c, c + 0.01)), "guard");
    // 3Ω at Nyquist: the DDS cannot make the top of the window
    assert_eq!(field(&cfg, PumpGuard::new(c - 1.0, 200e6)), "guard");
    let mut bad = cfg;
    bad.rls.forgetting = 1.5;
    assert_eq!(field(&bad, guard(&cfg)), "rls.forgetting");

    let mut app = clean(&d, &cap);
    let e = app
        .set_pump_amplitude(PumpAmplitude {
            base_scale: 0.0,
            full_scale: 1.0,
        })
        .unwrap_err();
    assert_eq!(e.field, "pump_amplitude");
    assert_eq!(app.pump_amplitude(), PumpAmplitude::UNITY);
}

#[test]
fn ticks_before_start_are_flagged_until_the_dds_is_written() {
    let d = data(50);
    let cap = DdsCapture::new(SYSCLK);
    let mut app = clean(&d, &cap);
    assert!(app.pump_hz().is_nan() && app.pump_plan().is_none());
    // a board without IO_UPDATE modelling: the no-op line
    let r = app.tick(&mut NoIoUpdate);
    assert_eq!(r.faults, fault::PUMP_UNKNOWN);
    assert!(!r.sample_ok && !r.out.health.inputs_valid);
    assert_eq!(app.estimator().counters().non_finite, 1);
    // the tick commanded the core's pump anyway: it is known from now on
    assert!(app.guard().contains(r.pump_hz));
    assert_eq!(r.pump_hz, app.pump_plan().unwrap().pump_hz());
    let r = app.tick(&mut NoIoUpdate);
    assert!(r.sample_ok && r.out.health.inputs_valid);
    assert_eq!(cap.pulses(), 0, "NoIoUpdate pulses nothing");
}

#[test]
fn failed_start_is_reported_and_retried() {
    let d = data(10);
    let cap = DdsCapture::new(SYSCLK);
    let mut io = cap.io_update();
    let mut app = clean(&d, &cap);
    // start's one frame: the three words and the amplitude
    cap.fail_transactions(Span::at(cap.transactions()));
    assert_eq!(app.start(&mut io), Err(ad9959::Error::Spi(ReplayError)));
    assert_eq!(app.counters().dds_errors, 1);
    assert!(app.pump_hz().is_nan());
    assert_eq!(cap.pulses(), 0);
    let plan = app.start(&mut io).unwrap();
    assert_eq!(app.pump_hz(), plan.pump_hz());
    assert_eq!(cap.active_pump_hz(), plan.pump_hz());
    assert_eq!(cap.active().asf_of(Channel::PUMP), AmplitudeWord::FULL);
}

#[test]
fn io_update_can_be_a_closure() {
    let d = data(10);
    let cap = DdsCapture::new(SYSCLK);
    let mut app = clean(&d, &cap);
    let mut pulses = 0;
    let mut io = || pulses += 1;
    app.start(&mut io).unwrap();
    app.tick(&mut io);
    assert_eq!(pulses, 1, "start pulses; an unchanged pump does not");
    fn takes(_: &mut impl IoUpdate) {}
    takes(&mut NoIoUpdate);
}

#[test]
fn amplitude_mapping_with_headroom_keeps_the_dither_unclipped() {
    let n = 1500;
    let d = data(n);
    let max_scale = |amp: Option<PumpAmplitude>| {
        let cap = DdsCapture::new(SYSCLK);
        let mut io = cap.io_update();
        let mut app = clean(&d, &cap);
        if let Some(a) = amp {
            app.set_pump_amplitude(a).unwrap();
        }
        app.start(&mut io).unwrap();
        let mut hi = 0.0f32;
        for _ in 0..n {
            let r = app.tick(&mut io);
            check_tick(&app, &cap, &r);
            let a = app.pump_amplitude();
            // the scale in effect is what the word realises through the analog gain
            assert_eq!(r.pump_scale, a.realised(cap.active().asf_of(Channel::PUMP)));
            let s = a.realised(a.word_for(r.out.pump_scale_next));
            assert_eq!(r.pump_scale, s);
            hi = hi.max(r.pump_scale);
        }
        hi
    };
    // full DDS word = 1.25 V_A0: the +10 % amplitude dither fits
    let headroom = max_scale(Some(PumpAmplitude {
        base_scale: 1.0,
        full_scale: 1.5625,
    }));
    assert!(headroom > 1.08, "{headroom}");
    // UNITY: the top of the dither is clipped at the full word, and the core is told so
    assert_eq!(max_scale(None), 1.0);
}

// ------------------------------------------------------------------------------------------
// the replay devices through the real drivers

#[test]
fn replay_adc_runs_the_driver_init_and_serves_frames() {
    let d = data(5);
    let cal = cal_x();
    let mut adc = Ads131m08::new(ReplayAdc::new(&d.x, cal));
    let id = adc
        .init(&mut NoopDelay::new(), &ads131m08::Config::PARAGYRO)
        .unwrap();
    assert_eq!(id >> 8, u16::from(ads131m08::ID_UPPER_BYTE));
    assert_eq!(adc.check_id().unwrap(), id);
    for k in 0..5 {
        let frame = adc.read_frame().unwrap();
        assert!(frame.status().lockin_ready() && !frame.status().reset_flag());
        assert_eq!(frame.lockin_codes(), encode_lockin(&cal, &d.x[k]));
        assert_eq!(frame.codes[ads131m08::channel::SPARE], RawCode::default());
    }
    // after the table: no new data
    assert_eq!(adc.read_frame(), Err(ads131m08::Error::NotReady));
    let dev = adc.destroy();
    assert_eq!(dev.samples_served(), 6, "init frames are not data frames");
    // looping
    let mut adc = Ads131m08::new(ReplayAdc::new(&d.x, cal).looping());
    for k in 0..12 {
        let f = adc.read_frame().unwrap();
        assert_eq!(f.lockin_codes(), encode_lockin(&cal, &d.x[k % 5]));
    }
}

#[test]
fn replay_adc_faults_give_the_driver_errors() {
    let d = data(20);
    let cal = cal_y();
    let dev = ReplayAdc::new(&d.y, cal)
        .with_crc_error(Span::at(1))
        .with_spi_error(Span::at(2))
        .with_not_ready(Span::at(3))
        .with_saturation(Span::at(4), 5)
        .with_stuck(Span::new(6, 10), 3);
    let mut adc = Ads131m08::new(dev);
    assert!(adc.read_frame().is_ok());
    assert!(matches!(
        adc.read_frame(),
        Err(ads131m08::Error::Crc { .. })
    ));
    assert_eq!(adc.read_frame(), Err(ads131m08::Error::Spi(ReplayError)));
    assert_eq!(adc.read_frame(), Err(ads131m08::Error::NotReady));
    let f = adc.read_frame().unwrap();
    assert!(f.lockin_saturated());
    assert_eq!(f.saturated_mask(), 1 << 5);
    assert_eq!(f.codes[5], RawCode::POSITIVE_FULL_SCALE);
    let held = encode_lockin(&cal, &d.y[6])[3];
    for k in 5..12 {
        let f = adc.read_frame().unwrap();
        let natural = encode_lockin(&cal, &d.y[k])[3];
        let want = if (6..10).contains(&k) { held } else { natural };
        assert_eq!(f.codes[3], want, "sample {k}");
        assert_eq!(f.codes[2], encode_lockin(&cal, &d.y[k])[2]);
    }
}

#[test]
fn encoding_rounds_to_nearest_and_clips_at_full_scale() {
    let s = 1e-3f32;
    assert_eq!(encode_um(0.0014, s, 0).get(), 1);
    assert_eq!(encode_um(0.0016, s, 0).get(), 2);
    assert_eq!(encode_um(-0.0016, s, 10).get(), 8);
    assert_eq!(encode_um(-0.0016, -s, 10).get(), 12);
    assert_eq!(encode_um(1e9, s, 0), RawCode::POSITIVE_FULL_SCALE);
    assert_eq!(encode_um(-1e9, s, 0), RawCode::NEGATIVE_FULL_SCALE);
    assert_eq!(encode_um(f32::INFINITY, s, 0), RawCode::POSITIVE_FULL_SCALE);
    assert_eq!(encode_um(f32::NAN, s, 0), RawCode::POSITIVE_FULL_SCALE);
    assert_eq!(encode_um(8388.7, s, 0), RawCode::POSITIVE_FULL_SCALE);
    assert_eq!(encode_um(8388.0, s, 0).get(), 8_388_000);
    // accelerometer: 20-bit codes and their bytes
    assert_eq!(
        encode_accel(adxl355::STANDARD_GRAVITY_MPS2, Range::G2),
        256_410
    );
    assert_eq!(encode_accel(1e3, Range::G8), 0x7_FFFF);
    assert_eq!(encode_accel(-1e3, Range::G8), -0x8_0000);
    for code in [
        0, 1, -1, 256_410, -256_410, 0x7_FFFF, -0x8_0000, 0x1234, -77,
    ] {
        assert_eq!(adxl355::raw20_from_bytes(accel_bytes(code)), code);
    }
}

#[test]
fn replay_accel_runs_the_driver_init_and_follows_the_range() {
    let acc = [[1.5f32, -2.25], [30.0, 0.5], [0.0, 0.0]];
    let mut xl = Adxl355::new(ReplayAccel::new(&acc).with_z_mps2(0.0));
    xl.init(Range::G8, Odr::Hz500, HighPass::Off).unwrap();
    assert_eq!(xl.range(), Range::G8);
    let s = xl.read_sample().unwrap();
    assert!(s.status.data_ready());
    let lsb = Range::G8.mps2_per_lsb();
    assert!((s.accel_mps2[0] - 1.5).abs() <= lsb / 2.0 * 1.001);
    assert!((s.accel_mps2[1] + 2.25).abs() <= lsb / 2.0 * 1.001);
    assert_eq!(s.accel_mps2[2], 0.0);
    // 30 m/s² fits at ±8 g
    let s = xl.read_sample().unwrap();
    assert!((s.accel_mps2[0] - 30.0).abs() <= lsb);
    xl.read_sample().unwrap();
    assert_eq!(
        xl.read_sample(),
        Err(adxl355::Error::NotReady),
        "end of table"
    );
    // a software reset goes back to ±2 g (driver and device agree)
    xl.reset().unwrap();
    let dev = xl.destroy();
    assert_eq!(dev.range(), Range::G2);
    assert_eq!(dev.samples_served(), 4);

    // faults: absent device, SPI error; Z = g by default
    let dev = ReplayAccel::new(&acc)
        .with_missing(Span::at(1))
        .with_spi_error(Span::at(2))
        .looping();
    let mut xl = Adxl355::new(dev);
    let s = xl.read_sample().unwrap();
    assert!((s.accel_mps2[2] - adxl355::STANDARD_GRAVITY_MPS2).abs() < 1e-4);
    assert!(
        xl.check_id().unwrap_err().is_missing_device(),
        "absent from 1 on"
    );
    assert_eq!(xl.read_sample(), Err(adxl355::Error::NotReady));
    assert_eq!(xl.read_sample(), Err(adxl355::Error::Spi(ReplayError)));
    assert!(xl.check_id().is_ok());
    assert!(xl.read_sample().is_ok()); // sample 3 = table 0 (looping)
}

/// The replayed ADXL355's temperature: `encode_temp` is the nearest code under the
/// driver's transfer function (clamped, NaN → 0), served in the sample burst and by
/// TEMP2/TEMP1 alone; a software reset clears it until the next sample.
#[test]
fn replay_accel_serves_the_temperature_code() {
    assert_eq!(encode_temp(25.0), adxl355::TEMP_INTERCEPT_CODE);
    assert_eq!(encode_temp(f64::NAN), 0);
    assert_eq!(encode_temp(-1e9), 0x0FFF);
    assert_eq!(encode_temp(1e9), 0);
    for i in 0..=200 {
        let t = -50.0 + 0.987 * f64::from(i);
        let back = f64::from(adxl355::temp_c_from_raw(encode_temp(t)));
        assert!((back - t).abs() <= 0.5 / 9.05 + 1e-4, "{t} → {back}");
    }
    assert_eq!(temp_bytes(0x0ABC), [0x0A, 0xBC]);
    assert_eq!(temp_bytes(0xFABC), [0x0A, 0xBC], "12 bits");

    let acc = [[0.0f32, 0.0]; 3];
    let code = encode_temp(41.5);
    let mut xl = Adxl355::new(ReplayAccel::new(&acc).with_temp_raw(code));
    xl.init(Range::G8, Odr::Hz500, HighPass::Off).unwrap();
    assert_eq!(xl.read_temperature_raw(), Ok(code));
    let s = xl.read_sample().unwrap();
    assert_eq!(s.temp_raw, code);
    assert!((s.temp_c() - 41.5).abs() < 0.06);
    xl.reset().unwrap();
    assert_eq!(xl.read_temperature_raw(), Ok(0), "reset value");
    xl.read_sample().unwrap();
    assert_eq!(xl.read_temperature_raw(), Ok(code));
}

#[test]
fn capture_dds_records_buffers_and_applies_them_on_io_update() {
    let cap = DdsCapture::new(SYSCLK);
    let mut io = cap.io_update();
    let mut dds = Ad9959::new(cap.spi(), SYSCLK);
    dds.init().unwrap();
    assert_eq!(cap.csr(), 0xF2);
    // start-up phase alignment
    dds.begin_phase_alignment().unwrap();
    if dds.take_io_update().is_some() {
        io.pulse();
    }
    dds.end_phase_alignment().unwrap();
    if dds.take_io_update().is_some() {
        io.pulse();
    }
    assert_eq!((cap.phase_clears(), cap.fr2()), (1, 0));

    let plan = dds.set_pump_frequency(21_900.0).unwrap();
    let asf = dds.set_pump_scale(0.81).unwrap();
    assert_eq!(cap.buffered().ftw_of(Channel::PUMP), plan.pump_ftw());
    assert_eq!(
        cap.buffered().ftw_of(Channel::REFERENCE),
        plan.reference_ftw()
    );
    assert_eq!(cap.buffered().ftw_of(Channel::THIRD), plan.third_ftw());
    assert_eq!(cap.buffered().asf_of(Channel::PUMP), asf);
    assert_eq!(cap.active().ftw_of(Channel::PUMP), 0, "not applied yet");
    assert_eq!(
        dds.read_frequency_word(Channel::REFERENCE),
        Ok(plan.reference_ftw())
    );
    let upd = dds.take_io_update().unwrap();
    assert_eq!(upd.channels, 0b0111);
    io.pulse();
    assert_eq!(cap.active(), cap.buffered());
    assert!(cap.active().phase_locked());
    assert_eq!(cap.active_pump_hz(), plan.pump_hz());
    assert_eq!(cap.active_pump_scale(), asf.scale());
    assert_eq!(cap.pulses(), 3);

    // injected SPI errors
    let t = cap.transactions();
    cap.fail_transactions(Span::at(t));
    assert_eq!(
        dds.set_pump_scale(0.5),
        Err(ad9959::Error::Spi(ReplayError))
    );
    assert_eq!(cap.failures(), 1);
    assert_eq!(cap.buffered().asf_of(Channel::PUMP), asf);
    let dds = dds.destroy();
    assert_eq!(dds.capture().transactions(), t + 1);
}

// ------------------------------------------------------------------------------------------
// the boards' in-place construction: unconfigured, then configured

#[test]
fn unconfigured_app_cannot_start_and_configured_app_equals_new() {
    let n = 300;
    let d = data(n);
    let cap = DdsCapture::new(SYSCLK);
    let mut io = cap.io_update();
    let mut app = App::unconfigured(chips(
        ReplayAdc::new(&d.x, cal_x()),
        ReplayAdc::new(&d.y, cal_y()),
        ReplayAccel::new(&d.acc),
        &cap,
    ));
    // no pump can be planned before the configuration: nothing reaches the DDS
    assert!(app.start(&mut io).is_err());
    assert_eq!(cap.pulses(), 0);
    let cfg = Config::table2();
    let mut bad = cfg;
    bad.fs_hz = f64::NAN;
    assert_eq!(
        app.configure(&bad, cal_x(), cal_y(), guard(&cfg))
            .unwrap_err()
            .field,
        "fs_hz"
    );
    app.configure(&cfg, cal_x(), cal_y(), guard(&cfg)).unwrap();
    // the same App as App::new: same estimator, same ticks
    let cap2 = DdsCapture::new(SYSCLK);
    let mut io2 = cap2.io_update();
    let mut reference = clean(&d, &cap2);
    assert_eq!(
        format!("{:?}", app.estimator()),
        format!("{:?}", reference.estimator())
    );
    let p1 = app.start(&mut io).unwrap();
    let p2 = reference.start(&mut io2).unwrap();
    assert_eq!(p1.pump_hz().to_bits(), p2.pump_hz().to_bits());
    for k in 0..n {
        let a = app.tick(&mut io);
        let b = reference.tick(&mut io2);
        same_output(&a.out, &b.out, k);
        assert_eq!(a.pump_hz.to_bits(), b.pump_hz.to_bits(), "tick {k}");
    }
    assert_eq!(app.estimator().theta(), reference.estimator().theta());
}

// ------------------------------------------------------------------------------------------
// (5) two DDS steps per sample

/// An IO_UPDATE line that can pulse half a period later: it records the DDS's pump
/// before the half-period pulse (the first half of the interval) and then applies it.
struct HalfIo<'a> {
    cap: &'a DdsCapture,
    first_half: Option<(u32, u16)>,
}

impl IoUpdate for HalfIo<'_> {
    fn pulse(&mut self) {
        self.cap.pulse();
    }

    fn pulse_at_half_period(&mut self) -> bool {
        let a = self.cap.active();
        self.first_half = Some((a.ftw_of(Channel::PUMP), a.asf_of(Channel::PUMP).get()));
        self.cap.pulse();
        true
    }
}

/// The core is told the two steps exactly: the next sample's pump is the end of the
/// sweep whose half means they are, `(3B − A)/2` words, and the sweep over the interval,
/// `2·(B − A)` words, goes to `Estimator::set_pump_sweep_hz` (a bare estimator given
/// those pumps and sweeps gets the same outputs). Telling the command's word instead
/// would put the replica's half means off the steps by up to a word, by ½ word each way
/// (the slope one word short) on every tie at the dither's steepest, and keep the slow RLS
/// gated after a rate step in the loop (`half_steps`). The steps themselves are within a word of the
/// half means of the sweep between the commands' words and their errors do not add up
/// (error feedback: the sum stays within half a word); the references stay phase-locked.
#[test]
fn two_steps_per_sample_are_told_to_the_core_as_the_sweep_they_are_the_half_means_of() {
    let n = F + 300;
    let d = data(n);
    let cap = DdsCapture::new(SYSCLK);
    let mut app = clean(&d, &cap);
    app.set_half_steps(true);
    let mut io = HalfIo {
        cap: &cap,
        first_half: None,
    };
    let mut reference = Reference::new();
    app.start(&mut io).unwrap();
    let (mut pump, mut scale) = (app.pump_hz(), app.pump_scale());
    // pump words (2k) of a told pump, exact: Hz per pump word is a power-of-two scaling
    let words = |hz: f64| hz / PUMP_STEP_HZ;
    let mut command_prev = words(pump);
    let mut two = 0;
    let (mut worst, mut sum, mut worst_sum): (f64, f64, f64) = (0.0, 0.0, 0.0);
    let mut moved = 0;
    let mut sweep = f32::NAN;
    for k in 0..n {
        io.first_half = None;
        let r = app.tick(&mut io);
        reference.est.set_pump_sweep_hz(sweep);
        let out = reference.est.step(&reference.sample(&d, k, pump, scale));
        same_output(&r.out, &out, k);
        assert_eq!(r.faults, 0, "tick {k}");
        assert!(cap.active().phase_locked());
        // the word the guard gives the command this tick executes
        let command = words(
            app.guard()
                .plan(r.out.pump_hz_next, SYSCLK)
                .unwrap()
                .pump_hz(),
        );
        let second = f64::from(cap.active().ftw_of(Channel::PUMP)) / 2.0;
        let first = io.first_half.map_or(second, |(w, _)| f64::from(w) / 2.0);
        sweep = f32::NAN;
        if io.first_half.is_some() {
            assert_eq!(
                words(r.pump_hz),
                1.5 * second - 0.5 * first,
                "tick {k}: the told pump is not the end of the steps' sweep"
            );
            sweep = (2.0 * (second - first) * PUMP_STEP_HZ) as f32;
            let errors = [
                first - (0.75 * command_prev + 0.25 * command),
                second - (0.25 * command_prev + 0.75 * command),
            ];
            for e in errors {
                worst = worst.max(e.abs());
                sum += e;
                worst_sum = worst_sum.max(sum.abs());
            }
            moved += usize::from(command != command_prev);
        }
        two += usize::from(io.first_half.is_some());
        command_prev = command;
        pump = r.pump_hz;
        scale = r.pump_scale;
    }
    // the dither moves the pump by several words a tick once it is on (from 1 s)
    assert!(
        two > 250 && moved > 250,
        "{two} ticks with two steps, {moved} moved"
    );
    assert!(worst < 1.0, "a step {worst} words from its half mean");
    assert!(
        worst_sum <= 0.5,
        "the steps' errors added up to {worst_sum} words"
    );
    assert_eq!(app.counters().dds_errors, 0);
}

#[test]
fn the_dds_model_takes_a_frame_of_cycles_in_order_and_drops_an_incomplete_one() {
    let cap = DdsCapture::new(SYSCLK);
    let mut spi = cap.spi();
    let sel = |ch: Channel| ch.csr_enable() | 0x02;
    // one frame: CSR(ch1), CFTW0, then CSR(ch2), ACR, then a read of CSR, then a CFTW0
    // cut short (three of its four bytes)
    let mut read = [0u8; 1];
    spi.transaction(&mut [
        Operation::Write(&[0x00, sel(Channel::Ch1), 0x04, 0x12, 0x34, 0x56, 0x78]),
        Operation::Write(&[0x00, sel(Channel::Ch2), 0x06, 0x00, 0x13, 0x99]),
        Operation::Write(&[0x80]),
        Operation::Read(&mut read),
        Operation::Write(&[0x04, 0xAA, 0xBB, 0xCC]),
    ])
    .unwrap();
    assert_eq!(cap.transactions(), 1);
    let b = cap.buffered();
    assert_eq!(b.ftw_of(Channel::Ch1), 0x1234_5678);
    assert_eq!(b.ftw_of(Channel::Ch2), 0, "the cut-short word is dropped");
    assert_eq!(b.asf_of(Channel::Ch2), AmplitudeWord::new(0x399));
    assert_eq!(read, [sel(Channel::Ch2)]);
    assert_eq!(cap.csr(), sel(Channel::Ch2));
    // buffered only: nothing active before IO_UPDATE
    assert_eq!(cap.active(), Default::default());
    // the next frame starts with an instruction again (CS high reset the port)
    spi.write(&[0x04, 0xAA, 0xBB, 0xCC, 0xDD]).unwrap();
    assert_eq!(cap.buffered().ftw_of(Channel::Ch2), 0xAABB_CCDD);
}
