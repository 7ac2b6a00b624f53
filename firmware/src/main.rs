//! paragyro-firmware: placeholder until the firmware issue binds the core to the chips.
//!
//! On the host this builds a stub. On `thumbv7em-none-eabihf` it boots (STM32F405 map,
//! QEMU `netduinoplus2`), builds the `f32` estimator from the Table 2 configuration,
//! runs it for 1000 ticks on a steady synthetic lock-in sample, checks that every tick
//! returned a finite pump command and sane health, reports the SysTick-derived
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
    use paragyro_core::{Config, Cplx, Lockin, Sample};

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

    fn self_check(syst: &mut SYST) -> bool {
        let cfg = Config::table2();
        let Ok(mut est) = cfg.build::<f32>() else {
            defmt::error!("configuration rejected");
            return false;
        };
        // steady state of the Table 2 gyro at the tuned pump (FINDINGS §1)
        let sample = Sample {
            lockin: Lockin {
                x0_um: 0.0204,
                x_um: [
                    Cplx::new(1.2, -1.27),
                    Cplx::new(0.0, 0.0),
                    Cplx::new(0.001, 0.002),
                ],
                y0_um: 0.0207,
                y_um: [
                    Cplx::new(0.9, 1.2),
                    Cplx::new(0.0, 0.0),
                    Cplx::new(0.0005, -0.001),
                ],
            },
            accel_mps2: [98.0665, 98.0665],
            pump_hz: est.initial_pump_hz(),
            pump_scale: 1.0,
        };
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(0x00FF_FFFF);
        syst.clear_current();
        syst.enable_counter();
        let n = 1000u32;
        let mut ok = true;
        let mut s = sample;
        let mut total: u64 = 0;
        for i in 0..n {
            let t0 = SYST::get_current();
            let out = est.step(&s);
            let t1 = SYST::get_current();
            total += ((t0.wrapping_sub(t1)) & 0x00FF_FFFF) as u64;
            // every channel moves a little, as real data with noise does (a constant
            // channel would rightly be flagged as a stuck ADC)
            let d = |j: u32| (((i + 3 * j) * 7919) % 13) as f32 * 1e-5;
            s.lockin.x0_um = sample.lockin.x0_um + d(0);
            s.lockin.y0_um = sample.lockin.y0_um + d(1);
            for h in 0..3 {
                let j = 2 + 4 * h as u32;
                s.lockin.x_um[h].re = sample.lockin.x_um[h].re + d(j);
                s.lockin.x_um[h].im = sample.lockin.x_um[h].im + d(j + 1);
                s.lockin.y_um[h].re = sample.lockin.y_um[h].re + d(j + 2);
                s.lockin.y_um[h].im = sample.lockin.y_um[h].im + d(j + 3);
            }
            s.pump_hz = out.pump_hz_next;
            s.pump_scale = out.pump_scale_next as f32;
            if !(out.pump_hz_next.is_finite() && out.pump_hz_next > 0.0) || !out.health.inputs_valid
            {
                ok = false;
            }
        }
        let instr_per_tick = total * 1_000_000_000 / SYSTICK_HZ / n as u64;
        defmt::info!(
            "ticks: {}, approx. instructions per tick: {}",
            n,
            instr_per_tick
        );
        let c = est.counters();
        defmt::info!("counters: {}", c);
        ok && c.samples == n && c.bad_samples == 0
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
