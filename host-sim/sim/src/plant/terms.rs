//! Which effect terms the integrator carries (its `FX` parameter): none (eq. (6) alone),
//! every term of [`rhs_fx`](super::rhs_fx), or the terms of one plant effect alone
//! ([`rhs_fx_one`]). The one-effect paths are the diagnosis's re-simulations.

use super::forcing::Forcing;
use super::{Drive, Theta, rhs, rhs_fx};
use crate::effects::{ES_C3, Effects};

/// Eq. (6) alone, [`super::measure`].
pub(super) const NONE: u8 = 0;
/// Every term of [`super::rhs_fx`], [`super::measure_fx`].
pub(super) const ALL: u8 = 1;
/// The pump feedthrough or the pick-off gain alone: eq. (6), [`super::measure_fx`].
pub(super) const MEASUREMENT: u8 = 2;
/// The geometric nonlinearity alone.
pub(super) const GEOMETRIC: u8 = 3;
/// The electrostatic softening alone.
pub(super) const ELECTROSTATIC: u8 = 4;
/// The nonlinear damping alone.
pub(super) const NL_DAMPING: u8 = 5;
/// The anisodamping alone.
pub(super) const ANISODAMPING: u8 = 6;
/// The force leak alone.
pub(super) const FORCE_LEAK: u8 = 7;

/// The terms of `fx` as one of [this module](self): the plant terms of one effect alone (with at most
/// the measurement effects, the runner's thermal drift and lock-in mismatch beside it),
/// else [`ALL`]. Decided by equality with that one effect's [`Effects`](super::Effects), so an
/// effect added to [`rhs_fx`](super::rhs_fx) later (a field of its own) runs the general path until it is
/// given a variant here.
pub(super) fn terms_of(fx: &Effects) -> u8 {
    if !fx.plant_active() {
        return NONE;
    }
    let base = Effects {
        vib_beat_hz: fx.vib_beat_hz,
        vib_phase0: fx.vib_phase0,
        es_pump: fx.es_pump,
        feedthrough: fx.feedthrough,
        tcf_ppm_k: fx.tcf_ppm_k,
        lockin_mismatch: fx.lockin_mismatch,
        readout_gain: fx.readout_gain,
        ..Effects::default()
    };
    if *fx == base {
        return MEASUREMENT;
    }
    let one = [
        (
            Effects {
                geometric: fx.geometric,
                ..base
            },
            GEOMETRIC,
        ),
        (
            Effects {
                electrostatic: fx.electrostatic,
                ..base
            },
            ELECTROSTATIC,
        ),
        (
            Effects {
                nl_damping: fx.nl_damping,
                ..base
            },
            NL_DAMPING,
        ),
        (
            Effects {
                anisodamping: fx.anisodamping,
                ..base
            },
            ANISODAMPING,
        ),
        (
            Effects {
                force_leak: fx.force_leak,
                ..base
            },
            FORCE_LEAK,
        ),
    ];
    one.iter().find(|(e, _)| e == fx).map_or(ALL, |(_, t)| *t)
}

/// [`rhs_fx`](super::rhs_fx) when `fx` carries the plant terms of one effect alone (`T`, [`terms_of`];
/// the angular vibration off, so γv = γv' = 0): the same result, bit for bit. Each term of
/// [`rhs_fx`](super::rhs_fx) whose size is zero is ±0, and adding ±0 to a sum leaves it as it was (up to
/// the sign of an exact zero, which no later sum or product turns into a different
/// non-zero value), so the effect's own term, computed with the same operations, is what
/// [`rhs_fx`](super::rhs_fx) adds to eq. (6) (the anisodamping's `2γv − d/2` is `−(d/2)`, its
/// `d/2 − 2γv` is `d/2`). Without the zero terms the sums are shorter: this is where the
/// diagnosis's re-simulations of one effect spent ~25 % of their time (tests:
/// `rhs_fx_one_is_rhs_fx_bit_for_bit`, `one_effect_runs_as_the_general_path`).
#[inline(always)]
pub(super) fn rhs_fx_one<const T: u8>(
    th: &Theta,
    z: &[f64; 4],
    d: &Drive,
    f: &Forcing,
    fx: &Effects,
) -> [f64; 4] {
    let [x, xd, y, yd] = *z;
    let [_, xdd, _, ydd] = rhs(th, z, f);
    match T {
        GEOMETRIC => [
            xd,
            xdd + -fx.geometric * y * (x * y + 2.0 * xd * yd),
            yd,
            ydd + fx.geometric * y * xd * xd,
        ],
        ELECTROSTATIC => [
            xd,
            xdd,
            yd,
            ydd - fx.electrostatic
                * (if fx.es_pump { d.s } else { 1.0 })
                * y
                * (1.0 + ES_C3 * (y * y)),
        ],
        NL_DAMPING => [
            xd,
            xdd - fx.nl_damping * (x * x) * xd,
            yd,
            ydd - fx.nl_damping * (y * y) * yd,
        ],
        ANISODAMPING => [
            xd,
            xdd + -(0.5 * fx.anisodamping) * yd,
            yd,
            ydd + (0.5 * fx.anisodamping) * xd,
        ],
        FORCE_LEAK => {
            let pump = d.s * (1.0 + d.cos2psi);
            [
                xd,
                xdd,
                yd,
                ydd + fx.force_leak * pump * x * (th.drive[5] + th.drive[6] * (x * x)),
            ]
        }
        // the measurement effects alone: eq. (6)
        MEASUREMENT => [xd, xdd, yd, ydd],
        _ => rhs_fx(th, z, d, f, fx),
    }
}
