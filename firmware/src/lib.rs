//! `paragyro_firmware`: the host-testable part of the firmware.
//!
//! The binary (`src/main.rs`) runs on the STM32F405 / QEMU; this library holds what does
//! not depend on the target: the SPI drivers of the board's chips ([`drivers`]), written
//! against embedded-hal 1.0 only, so `cargo test -p paragyro-firmware` checks them on the
//! host transaction by transaction. `no_std`, no allocation, no `unsafe`, no panics.
//! Also the application tick ([`app`]), the replay devices and run of the QEMU board
//! ([`replay`], [`run`], [`table`]) and the firmware-in-the-loop exchange and shims
//! ([`fil`]).
//!
//! The optional `defmt` feature derives `defmt::Format` for the driver types; enable it
//! only for target builds (a host test binary would not link, TOOLCHAIN.md §7).
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing,
        clippy::unreachable,
        clippy::todo,
        clippy::unimplemented,
        clippy::arithmetic_side_effects
    )
)]

pub mod app;
pub mod drivers;
pub mod fil;
pub mod persist;
pub mod replay;
pub mod run;
pub mod table;

pub use drivers::ad9959::Ad9959;
pub use drivers::ads131m08::Ads131m08;
pub use drivers::adxl355::Adxl355;
pub use drivers::failing::FailingSpi;
