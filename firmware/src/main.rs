//! paragyro-firmware: the 500 Hz estimator on a board.
//!
//! Boards are modules behind features (exactly one on the target):
//!
//! * `qemu` (default, CI): QEMU's `netduinoplus2` (the STM32F405's core and memory map)
//!   has no SPI chips, so the board replaces them with replay devices
//!   ([`paragyro_firmware::replay`]) serving the frames of a simulated record
//!   (`firmware/replay/fw-drift-retune.bin`, written by `paragyro-fw-replay table`), and a
//!   capture of what the firmware writes to the DDS. The real drivers and
//!   [`paragyro_firmware::app::App::tick`] run on top; the run exits through semihosting
//!   with 0 only if the estimate converged and the retune happened ([`board::qemu`]).
//! * `fil`: QEMU's `netduinoplus2` in the loop with the host process `paragyro-fil`,
//!   which plays the chips every tick from the simulated plant over semihosting pipes
//!   (`cargo fw-loop`; [`paragyro_firmware::fil`], `board::fil`).
//! * `stm32f405`: the real board (SPI1: the two ADS131M08s, SPI2: the ADXL355, SPI3:
//!   the AD9959, DRDY on PB0) through `stm32f4xx-hal`; defmt over RTT, linked with
//!   flip-link, flashed and run with probe-rs (`cargo fw-stm32-run`; [`board::stm32f405`]).
//!
//! On the host this builds a stub (the library is what the host tests use).
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "paragyro-firmware: build with --target thumbv7em-none-eabihf (see firmware/README.md)"
    );
}

#[cfg(all(
    target_os = "none",
    any(
        all(feature = "qemu", feature = "stm32f405"),
        all(feature = "qemu", feature = "fil"),
        all(feature = "fil", feature = "stm32f405")
    )
))]
compile_error!(
    "choose one board: `--features qemu` (the default), `--no-default-features --features fil` or `--no-default-features --features stm32f405`"
);

#[cfg(all(
    target_os = "none",
    not(any(feature = "qemu", feature = "stm32f405", feature = "fil"))
))]
compile_error!(
    "no board: build with `--features qemu` (the default), `--no-default-features --features fil` or `--no-default-features --features stm32f405`"
);

#[cfg(target_os = "none")]
mod board;
