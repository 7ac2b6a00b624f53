//! The pump's two mappings the board sets: the frequency window every command is clamped
//! to ([`PumpGuard`]) and the core's pump scale to the DDS amplitude word
//! ([`PumpAmplitude`]).

use paragyro_core::ConfigError;

use crate::drivers::ad9959::{self, AmplitudeWord, FTW_SCALE, PumpPlan};

#[cfg(doc)]
use super::App;
#[cfg(doc)]
use paragyro_core::Sample;

/// The last line of defence on the pump frequency: every command is clamped to
/// `[min_hz, max_hz]` (the drive's parametric band with margin).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PumpGuard {
    /// Lowest pump frequency ever commanded, Hz.
    pub min_hz: f64,
    /// Highest pump frequency ever commanded, Hz.
    pub max_hz: f64,
}

impl PumpGuard {
    /// The window `[min_hz, max_hz]` (validated by [`App::new`]).
    pub const fn new(min_hz: f64, max_hz: f64) -> Self {
        Self { min_hz, max_hz }
    }

    /// `centre_hz ± half_width_hz`.
    pub fn around(centre_hz: f64, half_width_hz: f64) -> Self {
        Self {
            min_hz: centre_hz - half_width_hz,
            max_hz: centre_hz + half_width_hz,
        }
    }

    /// `min_hz ≤ hz ≤ max_hz` (false for NaN).
    pub fn contains(&self, hz: f64) -> bool {
        hz >= self.min_hz && hz <= self.max_hz
    }

    /// `hz` clamped to the window (never panics; NaN gives `min_hz`).
    pub fn clamp(&self, hz: f64) -> f64 {
        hz.max(self.min_hz).min(self.max_hz)
    }

    /// The middle of the window.
    pub fn midpoint(&self) -> f64 {
        0.5 * (self.min_hz + self.max_hz)
    }

    /// The DDS plan for `hz` clamped to the window, with a realised pump inside the
    /// window: if rounding to the word grid would leave it, the next word inwards. `None`
    /// if no pump word fits (window narrower than a step) or the DDS cannot make it.
    ///
    /// The word is `k = round(f/2 · 2^32 / f_SYSCLK)` as [`PumpPlan::new`] rounds it (the
    /// same quotient, rounded once: `f / (2·f_SYSCLK/2^32)`), stepped in whole words, so
    /// the image needs neither `PumpPlan::new` nor a second rounding (flash budget).
    pub fn plan(&self, hz: f64, sysclk_hz: f64) -> Option<PumpPlan> {
        // 0 < f_SYSCLK ≤ 500 MHz, finite: positive doubles order like their bits (−0,
        // negatives, ∞ and NaN fall outside), no soft-float comparisons
        if !(1..=ad9959::MAX_SYSCLK_HZ.to_bits()).contains(&sysclk_hz.to_bits()) {
            return None;
        }
        // one pump step: the pump word 2k moves by 2
        let step = 2.0 * sysclk_hz / FTW_SCALE;
        // saturating: NaN and negatives give 0 (no plan), huge values u32::MAX (none)
        let k = (self.clamp(hz) / step + 0.5) as u32;
        let plan = PumpPlan::from_reference_ftw(k, sysclk_hz)?;
        let realised = plan.pump_hz();
        let plan = if realised > self.max_hz {
            // k > 0 (a plan): no wrap
            PumpPlan::from_reference_ftw(k.wrapping_sub(1), sysclk_hz)?
        } else if realised < self.min_hz {
            // 3k < 2^31 (a plan): no wrap
            PumpPlan::from_reference_ftw(k.wrapping_add(1), sysclk_hz)?
        } else {
            plan
        };
        self.contains(plan.pump_hz()).then_some(plan)
    }

    pub(super) fn validate(&self, sysclk_hz: f64, initial_hz: f64) -> Result<(), ConfigError> {
        let err = |reason| ConfigError {
            field: "guard",
            reason,
        };
        if !(self.min_hz.is_finite() && self.max_hz.is_finite() && self.min_hz > 0.0) {
            return Err(err("min_hz and max_hz must be finite and > 0"));
        }
        if self.min_hz >= self.max_hz {
            return Err(err("min_hz must be below max_hz"));
        }
        if self.plan(self.min_hz, sysclk_hz).is_none()
            || self.plan(self.max_hz, sysclk_hz).is_none()
        {
            return Err(err(
                "the DDS cannot make a pump inside the window (too narrow, or 3Ω at Nyquist)",
            ));
        }
        if !self.contains(initial_hz) {
            return Err(err("the configured pump centre is outside the window"));
        }
        Ok(())
    }
}

/// How the core's pump scale `s = (V/V_A0)²` maps to the DDS amplitude word.
///
/// The word commanded for the core's multiplier `m` (`StepOutput::pump_scale_next`) is
/// `AmplitudeWord::from_scale(m · base_scale / full_scale)`, and the scale in effect that
/// the next [`Sample`] carries is `word.scale() · full_scale`. The DDS clips at the full
/// word: with `full_scale < base_scale · (1 + dither.scale_frac)` the top of the amplitude
/// dither is clipped (the core is told the clipped value, so the estimate stays
/// consistent; only the amplitude excitation shrinks).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PumpAmplitude {
    /// Operating pump scale `s_base = (V_base/V_A0)²` (1: the configured `pump_amp_ref_v`).
    pub base_scale: f32,
    /// `s` of the full DDS word (ASF 1023) after the board's analog gain, `(V_full/V_A0)²`.
    pub full_scale: f32,
}

impl PumpAmplitude {
    /// `s_base = 1` and the full DDS word makes `V_A0`.
    pub const UNITY: PumpAmplitude = PumpAmplitude {
        base_scale: 1.0,
        full_scale: 1.0,
    };

    /// The word for the core's scale multiplier `m`.
    pub fn word_for(&self, multiplier: f64) -> AmplitudeWord {
        AmplitudeWord::from_scale(multiplier as f32 * self.base_scale / self.full_scale)
    }

    /// The pump scale `s` a word realises.
    pub fn realised(&self, word: AmplitudeWord) -> f32 {
        word.scale() * self.full_scale
    }

    pub(super) fn validate(&self) -> Result<(), ConfigError> {
        let ok = |v: f32| v.is_finite() && v > 0.0;
        if ok(self.base_scale) && ok(self.full_scale) {
            Ok(())
        } else {
            Err(ConfigError {
                field: "pump_amplitude",
                reason: "base_scale and full_scale must be finite and > 0",
            })
        }
    }
}

/// The two DDS frequency steps of one sample interval ([`App::set_half_steps`]), from
/// the last command's reference word `node` towards this one's, `command`: the means of
/// the linear sweep `node → command` over the two halves of the interval,
/// `(3·node + command)/4` and `(node + 3·command)/4`, quarter words, each rounded to a
/// whole word less the rounding error the step before left (first-order error feedback,
/// `residual` in quarter words, in `(−2, 2]`), so the rounding errors do not add up: over
/// any run of steps their sum is the residual, at most half a word (the DDS's phase stays
/// within half a word times half a sample period of the sweeps'), and a steady command
/// gives steady words (no DDS traffic). Returns the first step, the second and the
/// residual to carry to the next interval.
///
/// The core is told the steps exactly: the next sample's pump is the end of the sweep
/// whose half means they are, `(3B − A)/2`, and that sweep's move over the interval,
/// `2·(B − A)`, goes to `Estimator::set_pump_sweep_hz`, so that the replica
/// (`PumpProfile::HalfSteps`) holds what the DDS does, rounding and all. Telling one value
/// per sample would leave the replica a pattern it cannot see. Steps that are *exact* half
/// means of a sweep between told nodes confine the told pump to a grid of four words
/// (`p' − p = 4·(A − p)`, 0.93 Hz at 500 MHz SYSCLK), which biases the rate's scale factor
/// while the dither moves the pump. The command's word told with these steps would differ
/// from the told sweep's half means on every tie (`command − node ≡ 2 mod 4`, each tick at
/// the dither's steepest): the first step ½ word up and the second ½ word down, the pump's
/// slope within the interval one word short of the told sweep's whichever way it moves;
/// the rate row reads that through the ω′ term (the replica's derivative) as a rate offset
/// following the dither, and after a rate step the narrow channel is not still enough for
/// the slow RLS's hand-over.
///
/// Inputs below 2^28 (every sum here then stays below 2^31); the caller checks the
/// steps against the guard.
pub fn half_steps(node: i32, command: i32, residual: i32) -> (i32, i32, i32) {
    let w = |k: i32, x: i32| k.wrapping_mul(x);
    // u − e in quarter words; the step is round(u/4) (half up), its error 4·step − u
    let ua = w(3, node).wrapping_add(command).wrapping_sub(residual);
    let a = ua.wrapping_add(2) >> 2;
    let ea = w(4, a).wrapping_sub(ua);
    let ub = node.wrapping_add(w(3, command)).wrapping_sub(ea);
    let b = ub.wrapping_add(2) >> 2;
    (a, b, w(4, b).wrapping_sub(ub))
}

#[cfg(test)]
mod tests {
    use super::half_steps;

    #[test]
    fn half_steps_hold_a_steady_command_and_carry_their_rounding_error() {
        // a steady command: its word over both halves, the residual kept (no traffic)
        for r in -1..=2 {
            assert_eq!(half_steps(94_151, 94_151, r), (94_151, 94_151, r));
        }
        // commands moving by up to ±6 words a tick: each step within a word of its half
        // mean, and the errors so far add up to the residual (never more than half a word)
        let (mut node, mut residual, mut sum) = (94_151, 0, 0);
        let mut x = 0x2545_F491u32;
        for _ in 0..100_000 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            let command = node + (x % 13) as i32 - 6;
            let (a, b, r) = half_steps(node, command, residual);
            // errors in quarter words against the means (3·node + command)/4 and
            // (node + 3·command)/4
            let ea = 4 * a - (3 * node + command);
            let eb = 4 * b - (node + 3 * command);
            assert!(ea.abs() < 4 && eb.abs() < 4, "{ea} {eb}");
            sum += ea + eb;
            assert_eq!(sum, r);
            assert!((-1..=2).contains(&r));
            (node, residual) = (command, r);
        }
    }
}
