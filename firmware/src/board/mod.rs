//! The boards (one per feature) and what they share: the telemetry and capture lines.

#[cfg(feature = "fil")]
pub mod fil;
#[cfg(feature = "qemu")]
pub mod qemu;
#[cfg(any(feature = "qemu", feature = "fil"))]
mod stack;
#[cfg(feature = "stm32f405")]
pub mod stm32f405;

use embedded_hal::spi::SpiDevice;
#[cfg(feature = "capture")]
use paragyro_core::Config;
use paragyro_firmware::app::{App, TickReport};

/// Telemetry every this many ticks (10 Hz at 500 Hz).
#[cfg_attr(feature = "fil", allow(dead_code))]
pub const TELEMETRY_EVERY: u32 = 50;

/// The 10 Hz telemetry line: time, health bits, ω̂y², rate, pump in effect and commanded,
/// and the firmware's fault counters when any is non-zero.
#[cfg_attr(feature = "fil", allow(dead_code))]
pub fn telemetry<AX, AY, XL, DDS>(k: u32, fs_hz: f64, app: &App<AX, AY, XL, DDS>, r: &TickReport)
where
    AX: SpiDevice,
    AY: SpiDevice,
    XL: SpiDevice,
    DDS: SpiDevice,
{
    let est = app.estimator();
    defmt::info!(
        "t={=f64}s health={=u32:08b} wy2={=f64} rate={=f64}dps rate_valid={=bool} pump={=f64}Hz cmd={=f64}Hz faults={=u8:b}",
        f64::from(k) / fs_hz,
        r.out.health.bits(),
        est.wy2(),
        r.out.rate.rate_dps,
        r.out.rate.valid,
        r.pump_hz,
        r.out.pump_hz_next,
        r.faults
    );
    let f = app.counters();
    if f.adc_spi_errors
        | f.adc_crc_errors
        | f.adc_not_ready
        | f.adc_saturated
        | f.accel_errors
        | f.accel_saturated
        | f.accel_stuck
        | f.dds_errors
        | f.guard_clamps
        != 0
    {
        defmt::warn!(
            "faults: adc spi {} crc {} not-ready {} saturated {}, accel {} saturated {} stuck {}, dds {}, guard {}",
            f.adc_spi_errors,
            f.adc_crc_errors,
            f.adc_not_ready,
            f.adc_saturated,
            f.accel_errors,
            f.accel_saturated,
            f.accel_stuck,
            f.dds_errors,
            f.guard_clamps
        );
    }
}

/// The capture header: the record header's settings (`paragyro-fw-replay capture`).
#[cfg(feature = "capture")]
pub fn capture_header(cfg: &Config) {
    defmt::info!(
        "CAPHDR f0_hz={=f64} fs_hz={=f64} l0_um={=f64} lpf_order={=u32} lpf_hz={=f64} vref={=f64}",
        cfg.f0_hz,
        cfg.fs_hz,
        cfg.l0_um,
        cfg.lockin_lpf_order as u32,
        cfg.lockin_lpf_hz,
        cfg.pump_amp_ref_v
    );
}

/// One capture line: the inputs the core was given at tick `k` (one record row).
#[cfg(feature = "capture")]
pub fn capture_tick<AX, AY, XL, DDS>(k: u32, app: &App<AX, AY, XL, DDS>)
where
    AX: SpiDevice,
    AY: SpiDevice,
    XL: SpiDevice,
    DDS: SpiDevice,
{
    let s = app.last_sample();
    let l = &s.lockin;
    let x = [
        l.x0_um,
        l.x_um[0].re,
        l.x_um[0].im,
        l.x_um[1].re,
        l.x_um[1].im,
        l.x_um[2].re,
        l.x_um[2].im,
    ];
    let y = [
        l.y0_um,
        l.y_um[0].re,
        l.y_um[0].im,
        l.y_um[1].re,
        l.y_um[1].im,
        l.y_um[2].re,
        l.y_um[2].im,
    ];
    defmt::info!(
        "CAP k={=u32} pump_hz={=f64} s={=f32} a={} x={} y={}",
        k,
        s.pump_hz,
        s.pump_scale,
        s.accel_mps2,
        x,
        y
    );
}
