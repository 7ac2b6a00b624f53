//! The sim-to-real diagnosis on fixed seeds: one record per case of the `characterise`
//! scenario (20 s, rate table, die temperature +4 K), diagnosed from the record alone.
//! Seeds and sizes are fixed here; they are not the blind benchmark's.

use paragyro_diagnose::diagnose::{Candidate, Options, Report, diagnose};
use paragyro_simulator::effects::{Effect, EffectSpec};
use paragyro_simulator::record::{RecordOptions, simulate_record_with};
use paragyro_simulator::scenario::Scenario;

fn diagnosed(effects: &[&str], seed: u64) -> (String, Report) {
    let sc = Scenario::load("characterise").unwrap();
    let opts = RecordOptions {
        seed: Some(seed),
        effects: effects
            .iter()
            .map(|e| e.parse::<EffectSpec>().unwrap())
            .collect(),
        rate_table: true,
        temp: Some((25.0, 4.0)),
    };
    let (rec, _truth) = simulate_record_with(&sc, &opts, &mut |_| {}).unwrap();
    let d = diagnose(&rec, &Options::default()).unwrap();
    // report.json round-trips through serde
    let v = serde_json::to_value(&d.report).unwrap();
    assert_eq!(serde_json::from_value::<Report>(v).unwrap(), d.report);
    (d.report.verdict.to_string(), d.report)
}

fn candidate<'a>(j: &'a Report, effect: &str) -> &'a Candidate {
    let e: Effect = effect.parse().unwrap();
    j.ranking.iter().find(|c| c.effect == e).unwrap()
}

fn size_of(j: &Report, effect: &str) -> (f64, f64) {
    let c = candidate(j, effect);
    (c.size.unwrap(), c.size_sigma.unwrap())
}

/// The verdict, the fitted size within 5 % (and 5σ) of the truth, and a held-out output
/// error that shrinks by more than half once the effect is added.
fn check(effect: &str, size: f64, seed: u64) {
    check_spec(effect, size, "", 0.05, seed)
}

/// [`check`] with a `@PARAM` suffix on the spec and a relative size tolerance.
fn check_spec(effect: &str, size: f64, suffix: &str, tol: f64, seed: u64) {
    let spec = format!("{effect}={size}{suffix}");
    let (v, j) = diagnosed(&[&spec], seed);
    let (fit, sig) = size_of(&j, effect);
    let oe = j.output_error.as_ref().unwrap().closure;
    println!("{spec}: verdict {v}, fitted {fit:.4e} ± {sig:.1e}, OE closure {oe:.3}");
    assert_eq!(v, effect, "{:?}", j.ranking);
    assert!(
        (fit - size).abs() <= tol * size.abs(),
        "fitted {fit} vs true {size}"
    );
    assert!(oe > 0.5, "output-error closure {oe}");
    assert!(j.gap_closure > 0.8);
}

#[test]
fn clean_record_has_no_gap() {
    let (v, j) = diagnosed(&[], 11);
    assert_eq!(v, "none", "{:?}", j.ranking);
    // a clean record still has a small systematic residual (2.9 % of the held-out
    // energy on this seed, 0.5–3.2 % on the development records): under the 5 % gate
    let g = j.gap_fraction_of_baseline;
    assert!(g < paragyro_diagnose::diagnose::GAP_MIN, "{g}");
}

#[test]
fn nonlinear_damping() {
    check("nonlinear_damping", 1e-6, 12);
}

/// The softening driven by the pump (`@1`): the pump-amplitude steps move ωy² with s.
/// (A fixed-bias softening is a tolerance of ωy² and αy to this record: tests/calibrate.rs.)
/// Its size comes out 5.7 % low on this seed (9.43e-7): the structural column is linear
/// about a calibration that absorbed κ·s̄.
#[test]
fn electrostatic_softening() {
    check_spec("electrostatic_softening", 1e-6, "@1", 0.1, 13);
}

/// Anisodamping moves (θ14 − θ24)/4 away from the rate table: the calibration (the
/// parameter face) names it, with d within 2σ.
#[test]
fn anisodamping_on_the_parameter_face() {
    let (v, j) = diagnosed(&["anisodamping=3e-7"], 19);
    assert_eq!(v, "anisodamping", "{:?}", j.parameter_face.hypotheses);
    let h = j
        .parameter_face
        .hypotheses
        .iter()
        .find(|h| h.name == "anisodamping")
        .unwrap();
    let (d, s) = (h.size.unwrap(), h.sigma.unwrap());
    assert!((d - 3e-7).abs() < 2.0 * s, "{d} ± {s}");
}

#[test]
fn thermal_drift() {
    check("thermal_drift", -20.0, 14);
}

#[test]
fn force_leak() {
    check("force_leak", 1e-4, 15);
}

#[test]
fn feedthrough_is_found_where_it_lives() {
    let (v, j) = diagnosed(&["feedthrough=3e-3"], 16);
    assert_eq!(v, "feedthrough", "{:?}", j.ranking);
    let (fit, _) = size_of(&j, "feedthrough");
    assert!((fit - 3e-3).abs() < 0.1 * 3e-3, "{fit}");
    // the feedthrough is a DC offset of the sense pick-off: the gap lives on the sense DC row
    let dc = j.location.channel["sense/DC"];
    assert!(dc > 0.5, "sense DC share {dc}");
}

/// (At 10 °/s the beat is found, 2.308 Hz, and the size, 9.2 ± 0.8 °/s, but it closes only
/// 1.5 % of the held-out baseline energy, under the 2 % gap threshold: the verdict is
/// `none`. The vibration's detection limit is above 10 °/s on this excitation.)
#[test]
fn angular_vibration_beat_is_found() {
    let (v, j) = diagnosed(&["angular_vibration=30@2.3"], 17);
    assert_eq!(v, "angular_vibration", "{:?}", j.ranking);
    let c = candidate(&j, "angular_vibration");
    let beat = c.beat_hz.unwrap();
    assert!((beat - 2.3).abs() < 0.05, "beat {beat}");
    let size = c.size.unwrap();
    assert!((size - 30.0).abs() < 3.0, "{size}");
}

/// A pick-off gain error rescales the sense rows: to the calibration it is a set of θ
/// deviations (αy −0.6 %, and (θ14 − θ24)/4 off the rate table, which reads as
/// anisodamping). It is not `none`; it is not an honest test of `unknown` either (issue 11:
/// a rescaling of θ), which is why the blind benchmark does not draw it.
#[test]
fn readout_gain_is_a_departure_of_the_parameters() {
    let (v, j) = diagnosed(&["readout_gain=3e-3"], 18);
    assert_ne!(v, "none", "{:?}", j.ranking);
    let ay = j
        .parameter_face
        .parameters
        .iter()
        .find(|p| p.name == "alpha_y")
        .unwrap();
    assert!(ay.t.abs() > 100.0, "{ay:?}");
}

/// A quadratic stiffness (outside the library) on the statically deflected mass looks, to
/// first order, like a stiffness tolerance: the calibration absorbs most of it, and what
/// is left is above the record's own noise but explained by no library effect.
#[test]
fn quadratic_stiffness_is_unknown() {
    let (v, j) = diagnosed(&["quadratic_stiffness=-3e-6"], 103);
    assert_eq!(v, "unknown", "{:?}", j.ranking);
    assert!(j.residual_over_noise > paragyro_diagnose::diagnose::NONE_NOISE_MAX);
}
