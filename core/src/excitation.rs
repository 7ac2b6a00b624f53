//! The pump scheduler: centre frequency, the sinusoidal frequency dither, and
//! phase-continuous raised-cosine ramps of the centre.
//!
//! Everything is kept as a deviation from a fixed reference ω_ref (the configured
//! centre, non-dimensional ω = Ω/ω0), so `f32` keeps ~1e-10 absolute precision on the
//! commanded frequency; the absolute pump frequency in Hz is formed in `f64` at the
//! edge. The DDS integrates the frequency, so every command is phase-continuous; the
//! lock-in reference ψ is half the pump phase.
//!
//! The dither (±1e-3 of ω0 at 2 Hz by default) is what makes all 14 parameters
//! identifiable (FINDINGS §3.3); steps and PRBS are not used because 500 Hz samples
//! cannot resolve the ~100 Hz drive-envelope mode they excite.

use crate::real::Real;

/// A raised-cosine move of the centre from `from` to `to` over `len` samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ramp {
    /// Start value (deviation from ω_ref).
    pub from: f64,
    /// End value.
    pub to: f64,
    /// Sample index at the start.
    pub k0: u64,
    /// Length in samples (≥ 1).
    pub len: u64,
}

impl Ramp {
    /// Value at sample `k`.
    pub fn at(&self, k: u64) -> f64 {
        if k <= self.k0 {
            return self.from;
        }
        let i = k - self.k0;
        if i >= self.len {
            return self.to;
        }
        let w = f64::half_cos(f64::ratio(i, self.len));
        self.from + (self.to - self.from) * w
    }

    /// [`Ramp::at`] with the raised-cosine weight in `T` (the scheduler's precision:
    /// in `f32` the weight needs no soft-float `f64` cosine; the centre stays `f64`).
    /// Equal to `at` for `f64`.
    #[inline]
    pub fn at_in<T: Real>(&self, k: u64) -> f64 {
        if k <= self.k0 {
            return self.from;
        }
        let i = k - self.k0;
        if i >= self.len {
            return self.to;
        }
        let w = T::half_cos(T::ratio(i, self.len)).to_f64();
        self.from + (self.to - self.from) * w
    }
    /// Finished at sample `k`.
    pub fn done(&self, k: u64) -> bool {
        k >= self.k0 + self.len
    }
}

/// Pump scheduler state (`Default`: centre 0, no dither, no ramp, until built by
/// [`Scheduler::new`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct Scheduler<T> {
    /// Reference ω (non-dimensional), f64.
    pub om_ref: f64,
    centre: f64,
    ramp: Option<Ramp>,
    dither_amp: T,
    /// Unit phasor of the frequency dither (cos, sin) and its per-sample rotation.
    dither_z: (T, T),
    dither_rot: (T, T),
    dither_on: bool,
    /// Dither envelope 0..1 (raised-cosine taper).
    env: T,
    env_step: T,
    dither_start_k: u64,
    scale_amp: T,
    scale_z: (T, T),
    scale_rot: (T, T),
    scale_cmd: T,
}

/// (cos, sin) of `a` (design time).
fn rot<T: Real>(a: f64) -> (T, T) {
    T::design_cos_sin(a)
}

/// Rotates the unit phasor `z` by `r` and renormalises it to first order (a sine
/// generator without transcendentals on the tick path: libm's `sinf` works in `f64`,
/// which is soft-float on a Cortex-M4F).
#[inline]
fn advance<T: Real>(z: (T, T), r: (T, T)) -> (T, T) {
    let (c, s) = (z.0 * r.0 - z.1 * r.1, z.0 * r.1 + z.1 * r.0);
    let g = (T::from_f64(3.0) - (c * c + s * s)) * T::from_f64(0.5);
    (c * g, s * g)
}

impl<T: Real> Scheduler<T> {
    /// `om_ref` the reference ω; dither amplitude (ω units), frequency (cycles per
    /// sample), taper length (samples), start sample, enabled.
    #[inline(never)] // set-up only: its own frame (the chip's stack)
    pub fn new(
        om_ref: f64,
        dither_amp: f64,
        dither_cycles_per_sample: f64,
        taper_samples: f64,
        start_k: u64,
        enabled: bool,
    ) -> Self {
        Scheduler {
            om_ref,
            centre: 0.0,
            ramp: None,
            dither_amp: T::from_f64(dither_amp),
            dither_z: (T::ONE, T::ZERO),
            dither_rot: rot(2.0 * core::f64::consts::PI * dither_cycles_per_sample),
            dither_on: enabled,
            env: T::ZERO,
            env_step: T::from_f64(if taper_samples >= 1.0 {
                1.0 / taper_samples
            } else {
                1.0
            }),
            dither_start_k: start_k,
            scale_amp: T::ZERO,
            scale_z: (T::ONE, T::ZERO),
            scale_rot: (T::ONE, T::ZERO),
            scale_cmd: T::ONE,
        }
    }

    /// Adds a sinusoidal modulation of the pump voltage scale s (peak fraction `frac`,
    /// `cycles_per_sample`), switched and tapered together with the frequency dither.
    pub fn with_scale_dither(mut self, frac: f64, cycles_per_sample: f64) -> Self {
        self.scale_amp = T::from_f64(frac);
        self.scale_rot = rot(2.0 * core::f64::consts::PI * cycles_per_sample);
        self
    }

    /// Multiplier of the pump voltage scale s at the last commanded sample (1 = none).
    pub fn scale_command(&self) -> f64 {
        self.scale_cmd.to_f64()
    }

    /// Centre deviation (from ω_ref) at the last computed sample.
    pub fn centre(&self) -> f64 {
        self.centre
    }

    /// The active ramp, if any.
    pub fn ramp(&self) -> Option<Ramp> {
        self.ramp
    }

    /// Jumps the centre to `dev` (deviation from ω_ref) at once.
    pub fn jump(&mut self, dev: f64) {
        self.ramp = None;
        self.centre = dev;
    }

    /// Starts a raised-cosine ramp of the centre to `dev` over `len` samples from `k`.
    pub fn ramp_to(&mut self, dev: f64, k: u64, len: u64) {
        self.ramp = Some(Ramp {
            from: self.centre,
            to: dev,
            k0: k,
            len: len.max(1),
        });
    }

    /// Changes the dither amplitude (ω units, ≥ 0).
    pub fn set_dither_amp(&mut self, amp: f64) {
        if amp.is_finite() && amp >= 0.0 {
            self.dither_amp = T::from_f64(amp);
        }
    }

    /// Switches the dither on or off (with the taper).
    pub fn set_dither(&mut self, on: bool) {
        self.dither_on = on;
    }

    /// Dither switched on (it may still be tapering).
    pub fn dither_enabled(&self) -> bool {
        self.dither_on
    }

    /// Dither envelope (0 off … 1 full).
    pub fn dither_envelope(&self) -> f64 {
        self.env.to_f64()
    }

    /// Computes the commanded ω deviation (from ω_ref) for sample `k`, advancing the
    /// dither phase and taper by one sample. Call once per sample, in order.
    pub fn command(&mut self, k: u64) -> f64 {
        let d = self.command_dither(k);
        self.centre + d.to_f64()
    }

    /// [`Scheduler::command`] in its two parts: advances the centre's ramp and the
    /// dither by one sample and returns the dither's deviation in `T`; the centre is
    /// [`Scheduler::centre`] (the caller adds them where it needs the sum: the estimator
    /// in Hz, without a soft-float ω sum on the chip).
    pub fn command_dither(&mut self, k: u64) -> T {
        if let Some(r) = self.ramp {
            self.centre = r.at_in::<T>(k);
            if r.done(k) {
                self.ramp = None;
            }
        }
        let want = self.dither_on && k >= self.dither_start_k;
        if want {
            self.env = (self.env + self.env_step).min(T::ONE);
        } else {
            self.env = (self.env - self.env_step).max(T::ZERO);
        }
        let mut d = T::ZERO;
        self.scale_cmd = T::ONE;
        if self.env > T::ZERO {
            // raised-cosine taper, only while tapering
            let shape = if self.env < T::ONE {
                T::half_cos(self.env)
            } else {
                T::ONE
            };
            d = self.dither_amp * shape * self.dither_z.1;
            self.dither_z = advance(self.dither_z, self.dither_rot);
            self.scale_cmd = T::ONE + self.scale_amp * shape * self.scale_z.1;
            self.scale_z = advance(self.scale_z, self.scale_rot);
        } else {
            self.dither_z = (T::ONE, T::ZERO);
            self.scale_z = (T::ONE, T::ZERO);
        }
        d
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    #[test]
    fn ramp_is_smooth_and_ends_exactly() {
        let r = Ramp {
            from: 0.0,
            to: 1e-3,
            k0: 10,
            len: 250,
        };
        assert_eq!(r.at(5), 0.0);
        assert_eq!(r.at(10 + 250), 1e-3);
        assert!((r.at(10 + 125) - 0.5e-3).abs() < 1e-15);
        // largest step between samples: peak slope π/2·Δ/len
        let mut maxstep: f64 = 0.0;
        for k in 10..260 {
            maxstep = maxstep.max((r.at(k + 1) - r.at(k)).abs());
        }
        assert!(maxstep <= core::f64::consts::FRAC_PI_2 * 1e-3 / 250.0 * 1.0001);
    }

    #[test]
    fn dither_starts_tapered_and_stops() {
        let mut s = Scheduler::<f32>::new(1.0, 1e-3, 2.0 / 500.0, 50.0, 500, true);
        for k in 0..500 {
            assert_eq!(s.command(k), 0.0, "no dither before the start");
        }
        let mut peak: f64 = 0.0;
        for k in 500..1500 {
            let v = s.command(k);
            peak = peak.max(v.abs());
            if k < 510 {
                assert!(v.abs() < 1e-4, "tapered start");
            }
        }
        assert!((peak - 1e-3).abs() < 2e-6, "full amplitude {peak}");
        s.set_dither(false);
        let mut last = 1.0;
        for k in 1500..1600 {
            last = s.command(k);
        }
        assert_eq!(last, 0.0);
    }
}
