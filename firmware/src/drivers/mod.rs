//! SPI drivers for the three chips of the board, platform-agnostic (embedded-hal 1.0).
//!
//! Each driver follows the eldruin (`ad983x`, `lsm303agr`) style: generic over
//! [`embedded_hal::spi::SpiDevice`] (chip select belongs to the `SpiDevice`, e.g. from
//! `embedded-hal-bus`), `new(spi)` / `destroy()`, an `Error<E>` whose `Spi(E)` variant
//! carries the bus error, typed register values, no allocation and no panics. Every bus
//! transaction is checked with `embedded-hal-mock` in `tests/drivers.rs`; error paths use
//! [`failing::FailingSpi`].
//!
//! | module | chip | role |
//! |---|---|---|
//! | [`ads131m08`] | TI ADS131M08 8-ch 24-bit ΔΣ ADC | lock-in outputs of one axis (7 channels) |
//! | [`adxl355`] | ADI ADXL355 3-axis accelerometer | frame acceleration |
//! | [`ad9959`] | ADI AD9959 4-ch DDS | pump (2Ω) and phase-coherent references (Ω, 3Ω) |

pub mod ad9959;
pub mod ads131m08;
pub mod adxl355;
pub mod failing;
