//! `paragyro-sim check <scenario|file.toml>`: load and validate a scenario, print the
//! resolved settings.

use super::{Ctx, Failure, load};
use paragyro_simulator::scenario::Scenario;

/// Load and validate a scenario (built-in name or TOML file) without running it.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Built-in scenario name or path to a scenario TOML file.
    pub scenario: String,
}

/// Loads the scenario and prints what it resolves to.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    let sc = load(&a.scenario)?;
    ctx.say(&describe(&sc))
}

/// The resolved settings of a scenario.
fn describe(sc: &Scenario) -> String {
    let mut s = format!(
        "ok: '{}' from {}\n  {}\n  duration {} s, seed {}, f0 {:.3} Hz, {} steps/period, noise {} pm/√Hz, lock-in {} Hz order {}\n",
        sc.name,
        sc.source,
        sc.description,
        sc.duration_s,
        sc.seed,
        sc.sim.f0_hz,
        sc.sim.steps_per_period,
        sc.sim.noise_pm_rthz,
        sc.sim.lockin_lpf_hz,
        sc.sim.lockin_lpf_order
    );
    let e = &sc.estimator;
    s.push_str(&format!(
        "  pump centre {:.3} Hz, dither ±{} Hz at {} Hz from {} s, gate {} s, retune {}, forgetting {}\n",
        sc.pump_centre_hz(),
        e.dither_pump_hz,
        e.dither_freq_hz,
        e.dither_start_s,
        e.gate_startup_s,
        e.retune,
        e.forgetting
    ));
    s.push_str(&format!(
        "  plant: wy2 {}, rate {} °/s, accel {} / {} m/s²\n",
        sc.plant.wy2, sc.plant.rate_dps, sc.plant.accel_x_mps2, sc.plant.accel_y_mps2
    ));
    for ev in &sc.events {
        let what = match sc.pump_jump_centre_hz(ev) {
            Some(c) => format!("{} ({c:.3} Hz)", ev.kind),
            None => ev.kind.to_string(),
        };
        s.push_str(&format!("  event t = {} s: {what}\n", ev.t_s));
    }
    for m in &sc.measures {
        s.push_str(&format!(
            "  measure '{}': {:?} run, {}–{} s\n",
            m.name, m.run, m.from_s, m.to_s
        ));
    }
    if let Some(t) = sc.twin_scenario() {
        s.push_str(&format!(
            "  twin: retune {}, wy2 {}\n",
            t.estimator.retune, t.plant.wy2
        ));
    }
    s
}
