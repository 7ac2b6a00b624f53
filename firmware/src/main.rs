//! paragyro-firmware: placeholder until the firmware issue binds the core to the chips.
//! On the host this builds a stub; on `thumbv7em-none-eabihf` it boots, runs a
//! self-check of the core and exits through semihosting (QEMU) with the verdict.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("paragyro-firmware: build with --target thumbv7em-none-eabihf (see README)");
}

#[cfg(target_os = "none")]
mod fw {
    use cortex_m_rt::{entry, exception};
    use cortex_m_semihosting::debug;
    #[cfg(feature = "qemu")]
    use defmt_semihosting as _;

    #[entry]
    fn main() -> ! {
        defmt::info!("paragyro-firmware placeholder start");
        let ok = true;
        debug::exit(if ok { debug::EXIT_SUCCESS } else { debug::EXIT_FAILURE });
        #[allow(clippy::empty_loop)]
        loop {}
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
