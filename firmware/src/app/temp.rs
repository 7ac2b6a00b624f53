//! The die temperature the tick takes from the accelerometer's burst: the accelerometer's
//! die, the TEMP2/TEMP1 bytes of the same burst (no extra transaction), taken every
//! [`TEMP_EVERY`]-th tick and held between. It is an optional input: a failed or stuck
//! accelerometer read on a tick that takes it, or a code outside [`TEMP_PLAUSIBLE_C`],
//! gives `temp_c: None` (held until the next such tick) without a fault bit of its own.

use embedded_hal::spi::SpiDevice;

use crate::drivers::adxl355;

/// Die temperatures outside this window, °C, are taken for a bad read (e.g. the sensor's
/// reset code 0, ≈ 233 °C, before its first conversion or with TEMP_OFF set) and give
/// `temp_c: None`.
pub const TEMP_PLAUSIBLE_C: (f32, f32) = (-60.0, 150.0);

/// The tick takes the die temperature from every this many sample bursts (10 Hz at
/// 500 Hz; the first tick after `App::configure` is one) and holds it between: the die
/// warms by millikelvins in 0.1 s, below one code (0.11 K), and the conversion then costs
/// the tick a countdown, not a conversion and a store every sample.
pub const TEMP_EVERY: u8 = 50;

/// [`TEMP_PLAUSIBLE_C`] as ADXL355 temperature codes (the code falls as the die warms):
/// 754 ≈ 149.97 °C, 2654 ≈ −59.97 °C (`adxl355::temp_c_from_raw`; the unit test checks
/// every code). The code is tested, not the temperature: one integer range test instead
/// of two floating-point comparisons.
const TEMP_PLAUSIBLE_CODES: (u16, u16) = (754, 2654);

/// The ADXL355's temperature code in °C, `None` outside [`TEMP_PLAUSIBLE_C`].
pub fn plausible_temp_c(raw12: u16) -> Option<f32> {
    let (lo, hi) = TEMP_PLAUSIBLE_CODES;
    (lo..=hi)
        .contains(&raw12)
        .then(|| adxl355::temp_c_from_raw(raw12))
}

impl<AX, AY, XL, DDS> super::App<AX, AY, XL, DDS>
where
    AX: SpiDevice,
    AY: SpiDevice,
    XL: SpiDevice,
    DDS: SpiDevice,
{
    /// The accelerometer's die temperature, °C, read now in its own transaction (TEMP2,
    /// TEMP1): for the boot, before the core's warm start. `None` on a bus error or a code
    /// outside [`TEMP_PLAUSIBLE_C`] (e.g. the sensor's reset code before its first
    /// conversion). The ticks take the temperature from their sample burst instead.
    pub fn read_temperature_c(&mut self) -> Option<f32> {
        self.chips
            .accel
            .read_temperature_raw()
            .ok()
            .and_then(plausible_temp_c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The code window is the temperature window, code by code.
    #[test]
    fn the_temperature_code_window_is_the_celsius_window() {
        let (lo, hi) = TEMP_PLAUSIBLE_C;
        let mut inside = 0;
        for code in 0..=0x0FFF {
            let t = adxl355::temp_c_from_raw(code);
            let want = (lo..=hi).contains(&t).then_some(t);
            assert_eq!(plausible_temp_c(code), want, "code {code}: {t} °C");
            inside += usize::from(want.is_some());
        }
        assert_eq!(inside, 2654 - 754 + 1);
    }
}
