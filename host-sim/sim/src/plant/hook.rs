//! The plant's external-term hook: a module outside the simulator adds a force to the
//! right-hand side of eq. (6), integrates states of its own with the same RK4 steps, and
//! adds an offset to the pick-off, without the simulator knowing what the term is.
//!
//! The blind benchmark's out-of-library effects (`paragyro_diagnose::blind::outside`) come
//! in this way: the simulator's effect library ([`crate::effects::Effect`]) does not list
//! them, and the diagnosis does not import the module that defines them.
//!
//! A hook is `Copy` (a name, [`HOOK_PARAMS`] numbers and two function pointers), so it
//! travels in [`crate::effects::Effects::hook`] through the runner and the record path
//! unchanged. With no hook (`None`, the default) the integrator runs exactly the code it
//! ran before the hook existed (the hooked variant is a separate monomorphisation), so every
//! existing result is bit-identical.
//!
//! Order of operations per RK4 step of length `h` (τ units): the four stages evaluate
//! `rhs_fx` (eq. (6) with the library effects) plus the hook's force on the drive and the
//! sense axis, and the hook's own state derivative, on the state `[X, X', Y, Y', w0, w1]`;
//! the measurement at every lock-in sample is the library's plus the hook's offset.

use std::fmt;

/// Extra states a hook integrates (initially 0).
pub const HOOK_STATES: usize = 2;

/// Parameters a hook carries.
pub const HOOK_PARAMS: usize = 6;

/// What an external term sees at one instant (non-dimensional, τ = ω0·t, L0 = 1 µm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HookAt {
    /// Time since the start of the run, τ.
    pub tau: f64,
    /// The plant state `[X, X', Y, Y']`.
    pub z: [f64; 4],
    /// The hook's own states.
    pub w: [f64; HOOK_STATES],
    /// cos 2ψ (the pump's phase).
    pub cos2psi: f64,
    /// The pump voltage scale s.
    pub s: f64,
    /// The accelerations ãx, ãy.
    pub accel: [f64; 2],
}

impl HookAt {
    /// The hook's view at time `tau` of plant state `z`, its own states `w` and the drive.
    pub(super) fn at(tau: f64, z: &[f64; 4], w: &[f64; HOOK_STATES], d: &super::Drive) -> Self {
        HookAt {
            tau,
            z: *z,
            w: *w,
            cos2psi: d.cos2psi,
            s: d.s,
            accel: [d.ax, d.ay],
        }
    }
}

/// The hook's right-hand side: `(force on [drive, sense], d/dτ of its states)`.
pub type HookRhs = fn(&[f64; HOOK_PARAMS], &HookAt) -> ([f64; 2], [f64; HOOK_STATES]);

/// The hook's measurement: an offset added to the measured `[Xm, Ym]`.
pub type HookMeasure = fn(&[f64; HOOK_PARAMS], &HookAt) -> [f64; 2];

/// An external term of the plant (see the module docs).
#[derive(Clone, Copy)]
pub struct PlantHook {
    /// A label for the truth file and debugging (`name(p0, p1, …)`).
    pub name: &'static str,
    /// Its parameters.
    pub p: [f64; HOOK_PARAMS],
    /// Its force and state derivative.
    pub rhs: HookRhs,
    /// Its pick-off offset.
    pub measure: HookMeasure,
}

impl PlantHook {
    /// The force and the state derivative at `at`.
    #[inline(always)]
    pub fn eval(&self, at: &HookAt) -> ([f64; 2], [f64; HOOK_STATES]) {
        (self.rhs)(&self.p, at)
    }

    /// The pick-off offset at `at`.
    #[inline(always)]
    pub fn offset(&self, at: &HookAt) -> [f64; 2] {
        (self.measure)(&self.p, at)
    }

    /// A hook adding no measurement offset (for [`PlantHook::measure`]).
    pub fn no_offset(_: &[f64; HOOK_PARAMS], _: &HookAt) -> [f64; 2] {
        [0.0; 2]
    }
}

impl fmt::Debug for PlantHook {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}{:?}", self.name, self.p)
    }
}

impl fmt::Display for PlantHook {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p: Vec<String> = self.p.iter().map(|v| format!("{v:e}")).collect();
        write!(f, "{}({})", self.name, p.join(", "))
    }
}

/// Two hooks are equal when they have the same name and parameters (function pointers are
/// not compared: their addresses are not meaningful).
impl PartialEq for PlantHook {
    fn eq(&self, o: &Self) -> bool {
        self.name == o.name && self.p == o.p
    }
}

/// One RK4 step of the state `z` with the hook's states `w` from time `tau`:
/// [`super::rhs_fx`] plus the hook's force, and the hook's derivative (same stages, same
/// inputs as `rk4_step_g`).
#[inline(always)]
pub(super) fn rk4_step_hooked(
    th: &super::Theta,
    (z, w): (&[f64; 4], &[f64; HOOK_STATES]),
    h: f64,
    ds: [&super::Drive; 3],
    tau: f64,
    fx: &crate::effects::Effects,
    hook: &PlantHook,
) -> ([f64; 4], [f64; HOOK_STATES]) {
    let f = |z: &[f64; 4], w: &[f64; HOOK_STATES], d: &super::Drive, tau: f64| {
        let b = super::rhs_fx(th, z, d, &super::Forcing::of(th, d), fx);
        let at = HookAt::at(tau, z, w, d);
        let (force, dw) = hook.eval(&at);
        ([b[0], b[1] + force[0], b[2], b[3] + force[1]], dw)
    };
    let [da, dh, de] = ds;
    let add = |z: &[f64; 4], w: &[f64; HOOK_STATES], k: &([f64; 4], [f64; 2]), c: f64| {
        (
            [
                z[0] + c * k.0[0],
                z[1] + c * k.0[1],
                z[2] + c * k.0[2],
                z[3] + c * k.0[3],
            ],
            [w[0] + c * k.1[0], w[1] + c * k.1[1]],
        )
    };
    let hh = 0.5 * h;
    let k1 = f(z, w, da, tau);
    let (z2, w2) = add(z, w, &k1, hh);
    let k2 = f(&z2, &w2, dh, tau + hh);
    let (z3, w3) = add(z, w, &k2, hh);
    let k3 = f(&z3, &w3, dh, tau + hh);
    let (z4, w4) = add(z, w, &k3, h);
    let k4 = f(&z4, &w4, de, tau + h);
    let h6 = h / 6.0;
    let mut zo = [0.0; 4];
    for i in 0..4 {
        zo[i] = (z[i] + h6 * (k1.0[i] + 2.0 * (k2.0[i] + k3.0[i]))) + h6 * k4.0[i];
    }
    let mut wo = [0.0; HOOK_STATES];
    for i in 0..HOOK_STATES {
        wo[i] = (w[i] + h6 * (k1.1[i] + 2.0 * (k2.1[i] + k3.1[i]))) + h6 * k4.1[i];
    }
    (zo, wo)
}

#[cfg(test)]
mod tests {
    use super::super::*;
    use super::*;
    use crate::effects::Effects;

    fn quiet() -> SimConfig {
        SimConfig {
            noise_density: 0.0,
            ..SimConfig::default()
        }
    }

    fn run_with(fx: Effects, n: usize) -> (GyroSim, Vec<LockinOut>) {
        let mut sim = GyroSim::new(&quiet(), [0.01, 0.0, 0.0, 0.0]).unwrap();
        sim.set_effects(fx, 0.0);
        let (th, u) = (Theta::table2(), PlantInputs::nominal());
        let mut out = Vec::new();
        for _ in 0..n {
            sim.advance(&th, &u, &u);
            out.push(sim.lockin());
        }
        (sim, out)
    }

    fn zero_force(_: &[f64; HOOK_PARAMS], _: &HookAt) -> ([f64; 2], [f64; 2]) {
        ([0.0; 2], [0.0; 2])
    }

    /// A constant force p0 on the sense axis.
    fn sense_push(p: &[f64; HOOK_PARAMS], _: &HookAt) -> ([f64; 2], [f64; 2]) {
        ([0.0, p[0]], [0.0; 2])
    }

    /// w0' = 1 (w0 = τ) and the pick-off reads Y + p1·w0; the force is 0.
    fn clock(_: &[f64; HOOK_PARAMS], _: &HookAt) -> ([f64; 2], [f64; 2]) {
        ([0.0; 2], [1.0, 0.0])
    }
    fn clock_offset(p: &[f64; HOOK_PARAMS], at: &HookAt) -> [f64; 2] {
        [0.0, p[1] * at.w[0]]
    }

    fn hooked(name: &'static str, p0: f64, rhs: HookRhs, measure: HookMeasure) -> Effects {
        Effects {
            hook: Some(PlantHook {
                name,
                p: [p0, 1e-3, 0.0, 0.0, 0.0, 0.0],
                rhs,
                measure,
            }),
            ..Effects::default()
        }
    }

    /// A hook that adds nothing gives the nominal run (the hooked integrator is the same
    /// RK4 to rounding), and a hook that pushes the sense axis moves it by F/ωy² at DC.
    #[test]
    fn a_null_hook_is_the_nominal_plant_and_a_force_moves_it() {
        let n = 40;
        let (a, la) = run_with(Effects::default(), n);
        let (b, lb) = run_with(hooked("zero", 0.0, zero_force, PlantHook::no_offset), n);
        for (x, y) in a.state().iter().zip(b.state()) {
            assert!((x - y).abs() <= 1e-12 * (1.0 + x.abs()), "{x} vs {y}");
        }
        let (ya, yb) = (la[n - 1].y0_um, lb[n - 1].y0_um);
        assert!((ya - yb).abs() < 1e-12, "{ya} {yb}");
        // a constant sense force F: static deflection F/ωy² on the sense DC channel
        let f = 1e-3;
        let (_, lc) = run_with(hooked("push", f, sense_push, PlantHook::no_offset), n);
        let dy = lc[n - 1].y0_um - la[n - 1].y0_um;
        let want = f / Theta::table2().sense[1].abs();
        assert!((dy - want).abs() < 0.02 * want, "{dy} vs {want}");
    }

    /// The hook's state is integrated with the plant (w0' = 1 gives w0 = τ exactly) and its
    /// measurement offset reaches the lock-in (the sense DC moves by p1·τ, a slow ramp).
    #[test]
    fn hook_states_are_integrated_and_measured() {
        let n = 20;
        let (a, la) = run_with(Effects::default(), n);
        let (b, lb) = run_with(hooked("clock", 0.0, clock, clock_offset), n);
        let t = n as f64 * b.sample_period_tau();
        let w0 = b.hook_states()[0];
        // (58 240 RK4 steps of h summed: rounding only)
        assert!((w0 - t).abs() < 1e-11 * t, "{w0} vs {t}");
        // the lock-in's DC of a ramp p1·τ lags it by the low-pass's group delay; it must
        // be within two sample periods of p1·τ (150 Hz 4th-order: ~2.8 ms, 1.4 samples)
        let dy = lb[n - 1].y0_um - la[n - 1].y0_um;
        let tau = a.time_tau();
        let ts = a.sample_period_tau();
        assert!(
            dy < 1e-3 * (tau - ts) && dy > 1e-3 * (tau - 2.0 * ts),
            "{dy} vs {}",
            1e-3 * tau
        );
    }

    #[test]
    fn hooks_compare_by_name_and_parameters() {
        let a = hooked("push", 1.0, sense_push, PlantHook::no_offset).hook;
        let b = hooked("push", 1.0, zero_force, PlantHook::no_offset).hook;
        let c = hooked("push", 2.0, sense_push, PlantHook::no_offset).hook;
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert!(a.unwrap().to_string().starts_with("push(1e0, 1e-3"));
        assert!(Effects::default().hook.is_none());
        assert!(hooked("zero", 0.0, zero_force, PlantHook::no_offset).plant_active());
    }
}
