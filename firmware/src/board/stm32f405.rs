//! The real board: an STM32F405RG at 168 MHz (8 MHz HSE) through `stm32f4xx-hal`.
//!
//! | chip | bus | pins |
//! |---|---|---|
//! | ADS131M08, drive axis (X0, A1..A3) | SPI1, mode 1, 8 MHz | SCK PA5, MISO PA6, MOSI PA7, CS PA4 |
//! | ADS131M08, sense axis (Y0, B1..B3) | SPI1 (shared) | CS PC4 |
//! | both ADCs' DRDY (one CLKIN, simultaneous conversions) | | PB0 (input, active low) |
//! | ADXL355 | SPI2, mode 0, 5 MHz | SCK PB13, MISO PB14, MOSI PB15, CS PB12 |
//! | AD9959 (25 MHz reference, PLL ×5 = 125 MHz) | SPI3, mode 0, 10 MHz | SCK PC10, SDIO_2 → MISO PC11, SDIO_0 ← MOSI PC12, CS PA15 |
//! | AD9959 IO_UPDATE | | PB1 (output) |
//!
//! The pin map is this firmware's; a PCB that differs changes this table and the code
//! below, nothing else. The chips are initialised by their drivers, then the main loop
//! waits for DRDY (polled: the tick is the only work, so no interrupt is needed; a DRDY
//! missing for 4 ms is counted and the tick runs anyway, so the ADC's "not ready" reaches
//! the core, which flags and holds) and runs [`App::tick`]. The cycles of every tick are
//! counted with DWT CYCCNT (real cycles here, unlike QEMU) and reported with the 10 Hz
//! telemetry. With the `capture` feature every tick's inputs are streamed as `CAP` lines
//! (`paragyro-fw-replay capture` turns the log into a record).
//!
//! Build, flash and run (defmt over RTT; firmware/README.md): `cargo fw-stm32-run` (probe-rs
//! as the runner, flip-link as the linker), or `cargo fw-stm32` and then
//! `probe-rs run --chip STM32F405RGTx target/thumbv7em-none-eabihf/release/paragyro-firmware`.
//!
//! **Calibration.** [`CAL_X_UM_PER_VOLT`] and [`CAL_Y_UM_PER_VOLT`] are the analog
//! front end's design scale (the values the replay table uses); a built board replaces
//! them by its bench calibration. **Pump profile**: the configuration is `Config::table2()`
//! (`pump_profile = Linear`) with the App's two DDS steps per sample
//! ([`App::set_half_steps`]): each tick writes and pulses the first step, buffers the
//! second, and the loop pulses IO_UPDATE again [`HALF_PERIOD_CYCLES`] after the tick
//! began (DWT-timed; the board polls DRDY and has nothing else to do). Compile-checked in
//! CI only: no board has run it yet; the `fil` board runs the same App logic in the loop.
//!
//! [`App::set_half_steps`]: paragyro_firmware::app::App::set_half_steps
//!
//! [`App::tick`]: paragyro_firmware::app::App::tick

use cortex_m::peripheral::DWT;
use cortex_m_rt::entry;
use defmt_rtt as _;
use embedded_hal::delay::DelayNs;
use embedded_hal::spi::SpiDevice;
use embedded_hal_bus::spi::{AtomicDevice, ExclusiveDevice};
use embedded_hal_bus::util::AtomicCell;
use paragyro_core::Config;
use paragyro_firmware::app::{App, Chips, IoUpdate, PinIoUpdate, PumpAmplitude, PumpGuard};
use paragyro_firmware::drivers::ad9959::{self, Ad9959};
use paragyro_firmware::drivers::ads131m08::{self, Ads131m08};
use paragyro_firmware::drivers::adxl355::{Adxl355, HighPass, Odr, Range};
use paragyro_firmware::run::calibration;
use stm32f4xx_hal::pac;
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::rcc::Config as RccConfig;
use stm32f4xx_hal::spi::{Mode, Phase, Polarity, Spi};

/// Core clock, Hz.
const SYSCLK_HZ: u32 = 168_000_000;
/// The AD9959's reference clock and PLL multiplier (SYSCLK 125 MHz, `DEFAULT_SYSCLK_HZ`).
const DDS_REF_HZ: f64 = 25e6;
const DDS_PLL: u8 = 5;
/// Drive-axis lock-in scale, µm per volt at the ADC input (design value).
pub const CAL_X_UM_PER_VOLT: f32 = 8.0;
/// Sense-axis lock-in scale, µm per volt at the ADC input (design value).
pub const CAL_Y_UM_PER_VOLT: f32 = 4.0;
/// Half-width of the pump guard around the configured centre, Hz.
const GUARD_HALF_WIDTH_HZ: f64 = 400.0;
/// A DRDY missing for this many cycles (4 ms, two periods) is counted as a timeout.
const DRDY_TIMEOUT_CYCLES: u32 = SYSCLK_HZ / 250;
/// Half a 500 Hz sample period in core cycles: the second IO_UPDATE of the two DDS steps.
const HALF_PERIOD_CYCLES: u32 = SYSCLK_HZ / 1000;

/// IO_UPDATE's high time, ns (the AD9959's SYNC_CLK at this board's SYSCLK, with margin).
const IO_UPDATE_HOLD_NS: u32 = ad9959::io_update_hold_ns(DDS_REF_HZ * DDS_PLL as f64);

/// IO_UPDATE now, or armed for the main loop to pulse half a period after the tick began.
struct HalfPeriodIo<P> {
    pin: PinIoUpdate<P, CycleDelay, IO_UPDATE_HOLD_NS>,
    armed: bool,
}

impl<P: embedded_hal::digital::OutputPin> HalfPeriodIo<P> {
    /// On the IO_UPDATE pin, nothing armed.
    fn on(pin: P) -> Self {
        HalfPeriodIo {
            pin: PinIoUpdate {
                pin,
                delay: CycleDelay,
            },
            armed: false,
        }
    }

    /// The second step: if the tick armed it (its words are buffered in the DDS), waits
    /// until [`HALF_PERIOD_CYCLES`] after `c0` (the tick's start, just after DRDY) and
    /// pulses IO_UPDATE.
    fn finish_period(&mut self, c0: u32) {
        if core::mem::take(&mut self.armed) {
            while DWT::cycle_count().wrapping_sub(c0) < HALF_PERIOD_CYCLES {}
            self.pulse_now();
        }
    }

    /// One pulse now (two callers, one copy: flash).
    #[inline(never)]
    fn pulse_now(&mut self) {
        self.pin.pulse();
    }
}

/// `Config::table2()` with the pump profile of this board's DDS: two frequency steps per
/// sample, the amplitude one (`PumpProfile::HalfSteps`, with `App::set_half_steps`). The
/// AD9959's linear-sweep mode cannot sweep as slowly as the core commands (app.rs); one
/// step per sample with the ZOH replica reads the rate +1.2 % high on `identify`
/// (firmware/docs/notes.md "Pump profile"; two steps: +0.009 %).
fn board_config() -> Config {
    let mut cfg = Config::table2();
    cfg.pump_profile = paragyro_core::config::PumpProfile::HalfSteps;
    cfg
}

impl<P: embedded_hal::digital::OutputPin> IoUpdate for HalfPeriodIo<P> {
    fn pulse(&mut self) {
        self.pulse_now();
    }

    fn pulse_at_half_period(&mut self) -> bool {
        self.armed = true;
        true
    }
}

/// The warm start on this board (always built in; firmware/README.md "Warm start on the
/// stm32f405 board").
///
/// The store is sectors 10 and 11 (128 KiB each; the `STORE` region of memory.x,
/// outside the image's `FLASH` region). At boot the newest record goes into the
/// estimator (or the boot is cold, and the reason is logged), and the spare sector is
/// erased if it was used: the run's only erase, before the loop starts (1–4 s, the
/// flash stalls). In the loop, [`Saver::poll`] programs at most 8 bytes per tick after
/// the tick's work ([`SavePolicy::BOARD`]); its cycles (flash stalls included) are
/// reported beside the tick's.
mod warm {
    use cortex_m::peripheral::DWT;
    use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
    use paragyro_core::Estimator;
    use paragyro_firmware::persist::{self, Boot, SaveEvent, SavePolicy, Saver, Store};
    use stm32f4xx_hal::flash::{Error, FlashExt, LockedFlash};
    use stm32f4xx_hal::pac::FLASH;

    /// Offsets (from 0x0800_0000) of sectors 10 and 11, and their size.
    const SLOT_A: u32 = 0x000C_0000;
    const SLOT_B: u32 = 0x000E_0000;
    const SLOT_LEN: u32 = 128 * 1024;

    /// The HAL's flash as a [`NorFlash`], unlocked for each erase or write only (the
    /// HAL's `UnlockedFlash` locks it again when dropped). The HAL erases and programs
    /// with 8-bit parallelism (any supply voltage; a byte per program operation).
    pub struct BoardFlash(LockedFlash);

    impl ErrorType for BoardFlash {
        type Error = Error;
    }

    impl ReadNorFlash for BoardFlash {
        const READ_SIZE: usize = 1;
        fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Error> {
            ReadNorFlash::read(&mut self.0, offset, bytes)
        }
        fn capacity(&self) -> usize {
            ReadNorFlash::capacity(&self.0)
        }
    }

    impl NorFlash for BoardFlash {
        const WRITE_SIZE: usize = 1;
        const ERASE_SIZE: usize = 128 * 1024;
        #[inline(never)]
        fn erase(&mut self, from: u32, to: u32) -> Result<(), Error> {
            NorFlash::erase(&mut self.0.unlocked(), from, to)
        }
        #[inline(never)]
        fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Error> {
            NorFlash::write(&mut self.0.unlocked(), offset, bytes)
        }
    }

    /// The store, the save logic and what the boot did.
    pub struct Warm {
        store: Store<BoardFlash>,
        saver: Saver,
        boot: Boot,
        /// Most cycles of one [`Saver::poll`] since the last report.
        poll_max: u32,
    }

    impl Warm {
        /// The boot: warm or cold (logged with the reason), then the spare erased.
        #[inline(never)]
        pub fn boot(flash: FLASH, est: &mut Estimator<f32>, temp_c: Option<f32>) -> Warm {
            let Ok(mut store) = Store::new(
                BoardFlash(LockedFlash::new(flash)),
                SLOT_A,
                SLOT_B,
                SLOT_LEN,
            ) else {
                super::fail("flash store layout")
            };
            let boot = persist::boot(&mut store, est, temp_c);
            defmt::info!("start: {} (spare prepared: {})", boot.start, boot.prepared);
            Warm {
                store,
                saver: Saver::new(SavePolicy::BOARD),
                boot,
                poll_max: 0,
            }
        }

        /// One tick of the save logic (tick `k`, after its work), and the 10 Hz line.
        #[inline(never)]
        pub fn tick(&mut self, k: u32, est: &Estimator<f32>) {
            let c0 = DWT::cycle_count();
            let ev = self.saver.poll(&mut self.store, k, est);
            self.poll_max = self.poll_max.max(DWT::cycle_count().wrapping_sub(c0));
            if ev != SaveEvent::Idle {
                defmt::info!("warm-start record: {}", ev);
            }
            if k.wrapping_add(1)
                .is_multiple_of(super::super::TELEMETRY_EVERY)
            {
                self.report();
            }
        }

        /// The 10 Hz line: how the run started and what the saves did.
        #[inline(never)]
        fn report(&mut self) {
            defmt::info!(
                "start {}, records {=u32} failed {=u32} full {=bool}, save poll max {=u32} cycles",
                self.boot.start,
                self.saver.written,
                self.saver.failures,
                self.saver.full,
                self.poll_max
            );
            self.poll_max = 0;
        }
    }
}

/// Busy-wait delay on the core clock (driver init only).
struct CycleDelay;

impl DelayNs for CycleDelay {
    fn delay_ns(&mut self, ns: u32) {
        // floor(ns · 168 / 1000) in 32 bits (exact: the whole microseconds times 168 are
        // an integer), no 64-bit division routine
        const PER_US: u32 = SYSCLK_HZ / 1_000_000;
        let cycles = (ns / 1_000)
            .saturating_mul(PER_US)
            .saturating_add((ns % 1_000) * PER_US / 1_000);
        cortex_m::asm::delay(cycles.max(1));
    }
}

/// Stops with a defmt error (probe-rs shows it; the debugger halts at the breakpoint).
fn fail(what: &str) -> ! {
    defmt::error!("{=str}", what);
    loop {
        cortex_m::asm::bkpt();
    }
}

/// An initialised ADS131M08 (the board stops if it does not answer).
fn init_adc<D: SpiDevice>(dev: D, delay: &mut CycleDelay) -> Ads131m08<D> {
    let mut adc = Ads131m08::new(dev);
    if adc.init(delay, &ads131m08::Config::PARAGYRO).is_err() {
        fail("ADS131M08 init failed");
    }
    adc
}

/// An initialised ADXL355: ±8 g, 500 Hz, no high-pass.
fn init_accel<D: SpiDevice>(dev: D) -> Adxl355<D> {
    let mut accel = Adxl355::new(dev);
    if accel.init(Range::G8, Odr::Hz500, HighPass::Off).is_err() {
        fail("ADXL355 init failed");
    }
    accel
}

/// An initialised AD9959 with its PLL set.
fn init_dds<D: SpiDevice>(dev: D) -> Ad9959<D> {
    let mut dds = Ad9959::new(dev, DDS_REF_HZ * f64::from(DDS_PLL));
    if dds.init().is_err() || dds.set_pll(DDS_REF_HZ, DDS_PLL).is_err() {
        fail("AD9959 init failed");
    }
    dds
}

#[entry]
fn main() -> ! {
    let Some(dp) = pac::Peripherals::take() else {
        fail("device peripherals taken twice")
    };
    let Some(mut cp) = cortex_m::Peripherals::take() else {
        fail("core peripherals taken twice")
    };
    let mut rcc = dp.RCC.freeze(
        RccConfig::hse(8.MHz())
            .sysclk(SYSCLK_HZ.Hz())
            .pclk1(42.MHz())
            .pclk2(84.MHz()),
    );
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();
    let gpioa = dp.GPIOA.split(&mut rcc);
    let gpiob = dp.GPIOB.split(&mut rcc);
    let gpioc = dp.GPIOC.split(&mut rcc);

    let mode0 = Mode {
        polarity: Polarity::IdleLow,
        phase: Phase::CaptureOnFirstTransition,
    };
    let mode1 = Mode {
        polarity: Polarity::IdleLow,
        phase: Phase::CaptureOnSecondTransition,
    };
    let spi1 = Spi::new(
        dp.SPI1,
        (Some(gpioa.pa5), Some(gpioa.pa6), Some(gpioa.pa7)),
        mode1,
        8.MHz(),
        &mut rcc,
    );
    let spi2 = Spi::new(
        dp.SPI2,
        (Some(gpiob.pb13), Some(gpiob.pb14), Some(gpiob.pb15)),
        mode0,
        5.MHz(),
        &mut rcc,
    );
    let spi3 = Spi::new(
        dp.SPI3,
        (Some(gpioc.pc10), Some(gpioc.pc11), Some(gpioc.pc12)),
        mode0,
        10.MHz(),
        &mut rcc,
    );
    // the ADCs share SPI1: `AtomicDevice` answers a nested use with `Busy` (no panic path)
    let adc_bus = AtomicCell::new(spi1);
    // GPIO writes are infallible on the STM32F4 (the error type is `Infallible`)
    let Ok(adc_x_dev) = AtomicDevice::new_no_delay(&adc_bus, gpioa.pa4.into_push_pull_output());
    let Ok(adc_y_dev) = AtomicDevice::new_no_delay(&adc_bus, gpioc.pc4.into_push_pull_output());
    let Ok(accel_dev) = ExclusiveDevice::new_no_delay(spi2, gpiob.pb12.into_push_pull_output());
    let Ok(dds_dev) = ExclusiveDevice::new_no_delay(spi3, gpioa.pa15.into_push_pull_output());
    let drdy = gpiob.pb0.into_pull_up_input();
    let mut io = HalfPeriodIo::on(gpiob.pb1.into_push_pull_output());

    let mut delay = CycleDelay;
    let adc_x = init_adc(adc_x_dev, &mut delay);
    let adc_y = init_adc(adc_y_dev, &mut delay);
    let accel = init_accel(accel_dev);
    let mut dds = init_dds(dds_dev);
    if dds.take_io_update().is_some() {
        io.pulse();
    }

    let cfg = board_config();
    let chips = Chips {
        adc_x,
        adc_y,
        accel,
        dds,
    };
    let guard = PumpGuard::around(cfg.pump_centre_hz, GUARD_HALF_WIDTH_HZ);
    // the App is built in its final place (blank estimator, every field a constant) and
    // the estimator designed into it: no estimator- or App-sized temporary on the stack
    let mut app = App::unconfigured(chips);
    app.set_half_steps(true);
    if app
        .configure(
            &cfg,
            calibration(CAL_X_UM_PER_VOLT),
            calibration(CAL_Y_UM_PER_VOLT),
            guard,
        )
        .is_err()
    {
        fail("configuration rejected")
    }
    // the die temperature at boot: the warm start moves the record and the pump to it
    // (None: no plausible code yet, the record restored as taken)
    let boot_temp_c = app.read_temperature_c();
    defmt::info!("die temperature at boot: {} degC", boot_temp_c);
    let mut warm = warm::Warm::boot(dp.FLASH, app.estimator_mut(), boot_temp_c);
    let app = &mut app;
    // a real ADXL355 is noisy: 8 identical X and Y codes in a row mean a stuck device
    app.set_accel_stuck_limit(paragyro_firmware::fil::ACCEL_STUCK_READS);
    if app
        .set_pump_amplitude(PumpAmplitude {
            base_scale: 1.0,
            full_scale: 1.5625,
        })
        .is_err()
        || app.start(&mut io).is_err()
    {
        fail("pump start failed");
    }
    defmt::info!("paragyro-firmware, stm32f405 board: running at 500 Hz (DRDY on PB0)");
    #[cfg(feature = "capture")]
    super::capture_header(&cfg);

    let mut k: u32 = 0;
    let mut drdy_timeouts: u32 = 0;
    // u32 (50 ticks of ≤ 2 ms are ≤ 16.8 M cycles): no 64-bit division in the image
    let mut cycles_sum: u32 = 0;
    let mut cycles_max: u32 = 0;
    loop {
        // DRDY is active low; it returns high when the frame is read
        let wait0 = DWT::cycle_count();
        while drdy.is_high() {
            if DWT::cycle_count().wrapping_sub(wait0) > DRDY_TIMEOUT_CYCLES {
                drdy_timeouts = drdy_timeouts.saturating_add(1);
                break;
            }
        }
        let c0 = DWT::cycle_count();
        let r = app.tick(&mut io);
        let dt = DWT::cycle_count().wrapping_sub(c0);
        io.finish_period(c0);
        cycles_sum = cycles_sum.saturating_add(dt);
        cycles_max = cycles_max.max(dt);
        #[cfg(feature = "capture")]
        super::capture_tick(k, app);
        warm.tick(k, app.estimator());
        k = k.wrapping_add(1);
        if k.is_multiple_of(super::TELEMETRY_EVERY) {
            super::telemetry(k, cfg.fs_hz, app, &r);
            defmt::info!(
                "tick cycles: mean {=u32} max {=u32} (last {=u32} ticks), DRDY timeouts {=u32}",
                cycles_sum / super::TELEMETRY_EVERY,
                cycles_max,
                super::TELEMETRY_EVERY,
                drdy_timeouts
            );
            cycles_sum = 0;
            cycles_max = 0;
        }
    }
}

/// Panics print their location over defmt and stop at a `udf` (the probe reports the
/// fault and a backtrace), as panic-probe does, but without formatting the message:
/// `core::fmt` and the panic messages would be ≈ 1.5 KB of the image. The library
/// is linted free of panics; what is left (HAL, indexing proven in range) should not fire.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    match info.location() {
        Some(l) => defmt::error!("panic at {=str}:{=u32}", l.file(), l.line()),
        None => defmt::error!("panic"),
    }
    cortex_m::asm::udf()
}
