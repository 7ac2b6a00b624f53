//! What the core reads at one 500 Hz sample: the lock-in outputs ([`Lockin`]), the
//! accelerometer and the pump in effect ([`Sample`]).
//!
//! Units are those of the front end (µm, m/s², Hz); the estimator converts them to the
//! paper's non-dimensional units once per sample (`estimator`, "condition").

use crate::complex::Cplx;
use crate::real::Real;

/// Number of real lock-in channels: X0, A1..A3 (re, im), Y0, B1..B3 (re, im).
pub const N_LOCKIN_CH: usize = 14;

/// Lock-in outputs of one sample, in µm (peak complex amplitudes against e^{−ikψ}).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Lockin<T> {
    /// Low-passed DC level of the drive displacement, µm.
    pub x0_um: T,
    /// Drive harmonics 1, 2, 3 (complex amplitude), µm.
    pub x_um: [Cplx<T>; 3],
    /// DC level of the sense displacement, µm.
    pub y0_um: T,
    /// Sense harmonics 1, 2, 3, µm.
    pub y_um: [Cplx<T>; 3],
}

impl<T: Real> Lockin<T> {
    /// From a front end that reports amplitude and phase (rad) per harmonic:
    /// `amp·e^{i·phase}`.
    pub fn from_polar(
        x0_um: T,
        x_amp_um: [T; 3],
        x_phase_rad: [T; 3],
        y0_um: T,
        y_amp_um: [T; 3],
        y_phase_rad: [T; 3],
    ) -> Self {
        let p = |a: T, ph: T| {
            let ph = ph.to_f64();
            Cplx::new(
                a * T::from_f64(libm::cos(ph)),
                a * T::from_f64(libm::sin(ph)),
            )
        };
        Lockin {
            x0_um,
            x_um: [
                p(x_amp_um[0], x_phase_rad[0]),
                p(x_amp_um[1], x_phase_rad[1]),
                p(x_amp_um[2], x_phase_rad[2]),
            ],
            y0_um,
            y_um: [
                p(y_amp_um[0], y_phase_rad[0]),
                p(y_amp_um[1], y_phase_rad[1]),
                p(y_amp_um[2], y_phase_rad[2]),
            ],
        }
    }

    /// The 14 real channels in the order of [`N_LOCKIN_CH`]: X0, A1 re, A1 im, …, Y0,
    /// B1 re, B1 im, … (what the input check and the stuck detector see).
    pub fn channels(&self) -> [T; N_LOCKIN_CH] {
        // one array, not zeroed and then filled (that cost a `memclr` call a tick on the chip)
        let [a1, a2, a3] = self.x_um;
        let [b1, b2, b3] = self.y_um;
        [
            self.x0_um, a1.re, a1.im, a2.re, a2.im, a3.re, a3.im, //
            self.y0_um, b1.re, b1.im, b2.re, b2.im, b3.re, b3.im,
        ]
    }
}

/// Everything the core needs at one 500 Hz sample.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample<T> {
    /// Lock-in outputs at the sample instant.
    pub lockin: Lockin<T>,
    /// Accelerometer (x = drive axis, y = sense axis), m/s².
    pub accel_mps2: [T; 2],
    /// Pump frequency 2Ω/2π in effect at the sample instant, Hz (f64: 1e-7 relative
    /// matters here).
    pub pump_hz: f64,
    /// Pump voltage scale s = (V_A/V_A0)².
    pub pump_scale: T,
    /// Die temperature at the sample instant, °C (the ADXL355's sensor on the board),
    /// `None` where there is no sensor. With it the core learns each mode's temperature
    /// coefficient and predicts the drift from it ([`crate::thermal`]); without
    /// it the drift is followed as a random walk alone. A non-finite value counts as
    /// absent.
    pub temp_c: Option<T>,
}

impl<T: Real> Sample<T> {
    /// s = (V_A/V_A0)² from the pump voltage amplitude and its reference.
    pub fn pump_scale_from_volts(v: f64, v_ref: f64) -> T {
        T::from_f64((v / v_ref) * (v / v_ref))
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    #[test]
    fn amplitude_phase_front_end_is_converted() {
        // A = |A|·e^{iφ}: (2, 0.3 rad) → (2cos0.3, 2sin0.3); DC levels pass through
        let l = Lockin::<f64>::from_polar(
            0.02,
            [2.0, 0.1, 0.003],
            [0.3, -1.0, 2.5],
            -0.01,
            [1.5, 0.0, 0.001],
            [-0.7, 0.0, 3.1],
        );
        let close = |z: Cplx<f64>, a: f64, ph: f64| {
            (z.re - a * libm::cos(ph)).abs() < 1e-15 && (z.im - a * libm::sin(ph)).abs() < 1e-15
        };
        assert!(
            close(l.x_um[0], 2.0, 0.3)
                && close(l.x_um[1], 0.1, -1.0)
                && close(l.x_um[2], 0.003, 2.5)
        );
        assert!(close(l.y_um[0], 1.5, -0.7) && close(l.y_um[2], 0.001, 3.1));
        assert_eq!((l.x0_um, l.y0_um), (0.02, -0.01));
        assert!((l.x_um[0].abs() - 2.0).abs() < 1e-15);
    }

    #[test]
    fn channels_are_in_the_documented_order() {
        let l = Lockin {
            x0_um: 1.0f32,
            x_um: [
                Cplx::new(2.0, 3.0),
                Cplx::new(4.0, 5.0),
                Cplx::new(6.0, 7.0),
            ],
            y0_um: 8.0,
            y_um: [
                Cplx::new(9.0, 10.0),
                Cplx::new(11.0, 12.0),
                Cplx::new(13.0, 14.0),
            ],
        };
        let c = l.channels();
        for (i, v) in c.iter().enumerate() {
            assert_eq!(*v, (i + 1) as f32);
        }
    }
}
