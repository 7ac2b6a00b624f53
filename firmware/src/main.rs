//! paragyro-firmware: the self-check that QEMU CI runs, until the board binding lands.
//!
//! On the host this builds a stub. On `thumbv7em-none-eabihf` it boots (STM32F405 map,
//! QEMU `netduinoplus2`), builds the application (`paragyro_firmware::app::App`: the
//! chips' drivers, the `f32` core, the pump guard) over replay devices that speak the
//! chips' SPI protocols (ADS131M08 frames with CRC, ADXL355 bursts, AD9959 writes
//! captured), runs 1200 ticks of a steady synthetic lock-in stream, checks that every
//! sample was valid and every pump command inside the guard, reports the SysTick-derived
//! instruction count per tick (exact under `-icount shift=0`), and exits through
//! semihosting with the verdict (0 pass, 1 fail/panic/HardFault).
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("paragyro-firmware: build with --target thumbv7em-none-eabihf (see README)");
}

#[cfg(target_os = "none")]
mod fw {
    use cortex_m::peripheral::{SYST, syst::SystClkSource};
    use cortex_m_rt::{entry, exception};
    use cortex_m_semihosting::debug;
    #[cfg(feature = "qemu")]
    use defmt_semihosting as _;
    use paragyro_core::Config;
    use paragyro_firmware::app::{App, Chips, PumpAmplitude, PumpGuard};
    use paragyro_firmware::drivers::ad9959::{Ad9959, DEFAULT_SYSCLK_HZ};
    use paragyro_firmware::drivers::ads131m08::{
        Ads131m08, Gain, LOCKIN_CHANNELS, LockinCalibration,
    };
    use paragyro_firmware::drivers::adxl355::Adxl355;
    use paragyro_firmware::replay::{DdsCapture, ReplayAccel, ReplayAdc};

    /// SysTick runs at the core clock (168 MHz on netduinoplus2); with `-icount shift=0`
    /// QEMU advances 1 ns per instruction, so instructions = ticks · 1e9 / 168e6.
    const SYSTICK_HZ: u64 = 168_000_000;

    #[entry]
    fn main() -> ! {
        defmt::info!("paragyro-firmware placeholder: core self-check");
        let mut cp = cortex_m::Peripherals::take().unwrap();
        let ok = self_check(&mut cp.SYST);
        defmt::info!("{}", if ok { "PASS" } else { "FAIL" });
        debug::exit(if ok {
            debug::EXIT_SUCCESS
        } else {
            debug::EXIT_FAILURE
        });
        #[allow(clippy::empty_loop)]
        loop {}
    }

    /// Ticks of the self-check (2.4 s: past the 0.5 s gate and the 1 s dither onset).
    const N: usize = 1200;

    /// A plausible steady lock-in stream of the Table 2 gyro, every channel moving a
    /// little (a constant channel would rightly be flagged as a stuck ADC): the same
    /// generator as the core's and the application's host tests, as tables in flash.
    const fn d(k: usize, i: usize) -> f32 {
        (((k + 3 * i) * 7919) % 13) as f32 * 1e-5
    }
    const fn lockin_table(axis: usize) -> [[f32; 7]; N] {
        let base: [[f32; 7]; 2] = [
            [0.0204, 1.2, -1.27, 1e-4, 0.0, 0.001, 0.002],
            [0.0207, 0.9, 1.2, 0.0, 1e-4, 0.0005, -0.001],
        ];
        let mut t = [[0.0f32; 7]; N];
        let mut k = 0;
        while k < N {
            let mut i = 0;
            while i < 7 {
                t[k][i] = base[axis][i] + d(k, i + 7 * axis);
                i += 1;
            }
            k += 1;
        }
        t
    }
    const fn accel_table() -> [[f32; 2]; N] {
        let mut t = [[0.0f32; 2]; N];
        let mut k = 0;
        while k < N {
            t[k] = [0.02 * (k % 7) as f32 - 0.05, 0.3 - 0.01 * (k % 5) as f32];
            k += 1;
        }
        t
    }
    static LOCKIN_X: [[f32; 7]; N] = lockin_table(0);
    static LOCKIN_Y: [[f32; 7]; N] = lockin_table(1);
    static ACCEL: [[f32; 2]; N] = accel_table();

    /// The firmware's 500 Hz tick (`App::tick`: two ADC frames with CRC, the
    /// accelerometer burst, the core's `step`, the DDS plan and writes) over the replay
    /// devices, as in QEMU CI until the board binding replays simulator records.
    fn self_check(syst: &mut SYST) -> bool {
        let cfg = Config::table2();
        let cal = |um: f32| {
            LockinCalibration::from_um_per_volt(
                [um / 1.2; LOCKIN_CHANNELS],
                [Gain::G1; LOCKIN_CHANNELS],
                [0; LOCKIN_CHANNELS],
            )
        };
        let cap = DdsCapture::new(DEFAULT_SYSCLK_HZ);
        let chips = Chips {
            adc_x: Ads131m08::new(ReplayAdc::new(&LOCKIN_X, cal(12.0))),
            adc_y: Ads131m08::new(ReplayAdc::new(&LOCKIN_Y, cal(10.0))),
            accel: Adxl355::new(ReplayAccel::new(&ACCEL)),
            dds: Ad9959::new(cap.spi(), DEFAULT_SYSCLK_HZ),
        };
        let guard = PumpGuard::around(cfg.pump_centre_hz, 400.0);
        let Ok(mut app) = App::new(chips, &cfg, cal(12.0), cal(10.0), guard) else {
            defmt::error!("configuration rejected");
            return false;
        };
        // room above s = 1 for the +10 % amplitude dither
        let amp = PumpAmplitude {
            base_scale: 1.0,
            full_scale: 1.5625,
        };
        if app.set_pump_amplitude(amp).is_err() {
            return false;
        }
        let mut io = cap.io_update();
        if app.start(&mut io).is_err() {
            defmt::error!("DDS start failed");
            return false;
        }
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(0x00FF_FFFF);
        syst.clear_current();
        syst.enable_counter();
        let mut ok = true;
        let mut total: u64 = 0;
        let mut worst: u32 = 0;
        for _ in 0..N {
            let t0 = SYST::get_current();
            let r = app.tick(&mut io);
            let t1 = SYST::get_current();
            let dt = t0.wrapping_sub(t1) & 0x00FF_FFFF;
            total += dt as u64;
            worst = worst.max(dt);
            if !(r.sample_ok && r.out.health.inputs_valid && app.guard().contains(r.pump_hz)) {
                ok = false;
            }
        }
        let per_tick = total * 1_000_000_000 / SYSTICK_HZ / N as u64;
        let worst_instr = worst as u64 * 1_000_000_000 / SYSTICK_HZ;
        defmt::info!(
            "App::tick over the replay devices: {} ticks, ≈ {} instructions per tick (mean), ≈ {} (max)",
            N,
            per_tick,
            worst_instr
        );
        let c = app.estimator().counters();
        let f = app.counters();
        defmt::info!("core counters: {}", c);
        defmt::info!(
            "firmware: adc spi {} crc {} not-ready {} saturated {}, accel {}, dds {}, guard clamps {}",
            f.adc_spi_errors,
            f.adc_crc_errors,
            f.adc_not_ready,
            f.adc_saturated,
            f.accel_errors,
            f.dds_errors,
            f.guard_clamps
        );
        ok && c.samples as usize == N
            && c.bad_samples == 0
            && c.updates > 0
            && f.adc_crc_errors == 0
            && f.dds_errors == 0
    }

    #[exception]
    unsafe fn HardFault(_ef: &cortex_m_rt::ExceptionFrame) -> ! {
        debug::exit(debug::EXIT_FAILURE);
        #[allow(clippy::empty_loop)]
        loop {}
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        defmt::error!("panic: {}", defmt::Display2Format(info));
        debug::exit(debug::EXIT_FAILURE);
        #[allow(clippy::empty_loop)]
        loop {}
    }
}
