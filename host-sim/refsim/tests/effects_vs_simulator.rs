//! Each effect is the project's effect: for every effect this generator shares with the
//! project (the nine library effects, the simulator's two out-of-library ones, the blind
//! benchmark's four hook types), a noise-free record of the project's simulator with the
//! effect at 10× its detection limit, and this generator's record of the same device with
//! the same inputs and the same effect, agree far better than the effect moves the record.

mod common;

use paragyro_diagnose::blind::outside::Outside as SimOutside;
use paragyro_refsim::device::DeviceDraw;
use paragyro_refsim::effects::{EffectSizes, EffectSpec, OutsideSpec};
use paragyro_refsim::protocol::Protocol;
use paragyro_refsim::sim::{FrontEnd, simulate};
use paragyro_simulator::lockin::LockinExt;
use paragyro_simulator::record::{Record, RecordOptions, simulate_record_ext};
use paragyro_simulator::scenario::Scenario;

const DURATION_S: f64 = 0.6;

fn scenario() -> Scenario {
    let mut sc = Scenario::load("characterise").unwrap();
    sc.duration_s = DURATION_S;
    sc.sim.noise_pm_rthz = 0.0;
    sc.sim.steps_per_period = 256;
    sc
}

/// The simulator's record with `effects` (names and sizes) or a hook type.
fn theirs(effects: &[&str], hook: Option<(SimOutside, f64)>) -> Record {
    let sc = scenario();
    let opts = RecordOptions {
        seed: Some(1),
        effects: effects.iter().map(|e| e.parse().unwrap()).collect(),
        rate_table: true,
        temp: Some((25.0, 5.0)),
    };
    let wy2 = sc.plant_at(0.0).phys[4];
    let hook = hook.map(|(k, size)| k.hook(size, wy2, sc.omega0_rad_s()));
    simulate_record_ext(&sc, &opts, hook, &mut |_| {})
        .unwrap()
        .0
}

/// This generator's record of the same device with the inputs of `rec`.
fn mine(rec: &Record, effects: &[&str], outside: Option<OutsideSpec>) -> Vec<[f64; 14]> {
    let sc = scenario();
    let specs: Vec<EffectSpec> = effects
        .iter()
        .map(|e| {
            // the simulator's spec, as JSON, is this generator's spec: the same names
            let s: paragyro_simulator::effects::EffectSpec = e.parse().unwrap();
            serde_json::from_value(serde_json::to_value(s).unwrap()).unwrap()
        })
        .collect();
    let table = common::inputs_of(rec);
    let mut proto = Protocol::plain(DURATION_S, table.pump_hz[0], sc.plant.rate_dps, [0.0; 2]);
    proto.table = Some(table);
    proto.temp_rise_k = 5.0;
    let fe = FrontEnd {
        noise_pm_rthz: 0.0,
        x0_m: sc.plant.initial_x_um * 1e-6,
        ..FrontEnd::default()
    };
    let dev = DeviceDraw::nominal(sc.plant.rate_dps).si();
    let fx = EffectSizes::of(&specs, outside);
    let s = simulate(&dev, &fx, &proto, &fe).unwrap();
    s.rows.iter().map(|r| r.lockin_um).collect()
}

fn largest(a: &[[f64; 14]], b: &[[f64; 14]]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| x.iter().zip(y).map(|(p, q)| (p - q).abs()))
        .fold(0.0f64, f64::max)
}

fn channels(rec: &Record) -> Vec<[f64; 14]> {
    rec.rows.iter().map(|r| r.lockin.to_channels()).collect()
}

/// `name`: |mine − theirs| and how far the effect moves their record.
fn check(name: &str, effects: &[&str], hook: Option<(SimOutside, f64)>, out: Option<OutsideSpec>) {
    let clean = channels(&theirs(&[], None));
    let rec = theirs(effects, hook);
    let with = channels(&rec);
    let moved = largest(&with, &clean);
    let gap = largest(&mine(&rec, effects, out), &with);
    eprintln!(
        "{name}: the effect moves the record by {moved:.3e} µm; refsim differs by {gap:.3e} µm"
    );
    assert!(
        moved > 1e-5,
        "{name}: the effect is invisible ({moved:.3e} µm)"
    );
    assert!(
        gap < 1e-5_f64.max(0.02 * moved),
        "{name}: {gap:.3e} µm against an effect of {moved:.3e} µm"
    );
}

#[test]
fn library_effects_are_the_simulators() {
    for e in [
        "geometric_nonlinearity=1e-6",
        "angular_vibration=40@1.5",
        "electrostatic_softening=1e-6@1",
        "feedthrough=1e-3",
        "nonlinear_damping=1e-6",
        "anisodamping=1e-6",
        "force_leak=1e-4",
        "thermal_drift=-20",
        "lockin_mismatch=1e-2",
    ] {
        check(e, &[e], None, None);
    }
}

#[test]
fn outside_effects_are_the_simulators() {
    for e in ["quadratic_stiffness=1e-5", "readout_gain=1e-2"] {
        check(e, &[e], None, None);
    }
    use paragyro_refsim::effects::Outside;
    for (theirs_kind, kind, size) in [
        (SimOutside::CoulombFriction, Outside::CoulombFriction, 1e-6),
        (SimOutside::SpuriousMode, Outside::SpuriousMode, 3e-4),
        (SimOutside::ChargingDrift, Outside::ChargingDrift, 3e-6),
        (SimOutside::PickoffLag, Outside::PickoffLag, 1e-3),
    ] {
        let spec = OutsideSpec { kind, size };
        check(kind.name(), &[], Some((theirs_kind, size)), Some(spec));
    }
}
