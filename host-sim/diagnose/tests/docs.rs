//! The worked examples of `host-sim/diagnose/docs/diagnosis.md`, from its scenario files in
//! `docs/examples/`, recorded and diagnosed as the page's commands do (`paragyro-sim record
//! FILE --rate-table --temp 25:4 --seed 21 [--effect …]`, then `paragyro-sim diagnose`):
//! the verdicts and the figures the page quotes.

use paragyro_core::physics::PHYSICAL_NAMES;
use paragyro_diagnose::diagnose::calibrate::T_PARAM;
use paragyro_diagnose::diagnose::{Model, Options, Report, diagnose};
use paragyro_simulator::record::{RecordOptions, simulate_record_with};
use paragyro_simulator::scenario::Scenario;

fn example(file: &str, effects: &[&str]) -> (Scenario, Report) {
    let path = format!("{}/docs/examples/{file}", env!("CARGO_MANIFEST_DIR"));
    let sc = Scenario::load(&path).unwrap();
    let opts = RecordOptions {
        seed: Some(21),
        effects: effects.iter().map(|e| e.parse().unwrap()).collect(),
        rate_table: true,
        temp: Some((25.0, 4.0)),
    };
    let (rec, _truth) = simulate_record_with(&sc, &opts, &mut |_| {}).unwrap();
    let r = diagnose(&rec, &Options::default()).unwrap().report;
    (sc, r)
}

/// z of each of the device's ten parameters (the scenario file's plant) against the truth.
fn z_of(sc: &Scenario, r: &Report) -> Vec<(&'static str, f64)> {
    let truth = Model::from_scenario(sc).phys.as_array();
    PHYSICAL_NAMES[..10]
        .iter()
        .zip(truth)
        .map(|(&n, v)| {
            let p = r.parameter_face.parameter(n).unwrap();
            (n, (p.device - v) / p.sigma)
        })
        .collect()
}

#[test]
fn docs_examples_read_as_documented() {
    // the three records made and diagnosed side by side (each simulation one thread)
    let (ex1, ex2, ex3) = std::thread::scope(|s| {
        let ex1 = s.spawn(|| example("dev-wy2.toml", &[]));
        let ex2 = s.spawn(|| example("dev-toleranced.toml", &["nonlinear_damping=1e-6"]));
        let ex3 = example("dev-toleranced.toml", &[]);
        (ex1.join().unwrap(), ex2.join().unwrap(), ex3)
    });

    // example 1: ωy² +0.1 %, `none`, ωy² the one deviation at 3σ, found within 2σ
    let (sc, r) = ex1;
    assert_eq!(r.verdict.to_string(), "none");
    let z = z_of(&sc, &r);
    println!("dev-wy2: {z:?}, residual {:.3}", r.residual_over_noise);
    assert!(z.iter().all(|(_, z)| z.abs() < 2.0), "{z:?}");
    let at3: Vec<&str> = r
        .parameter_face
        .parameters
        .iter()
        .filter(|p| p.t.abs() >= T_PARAM)
        .map(|p| p.name.as_str())
        .collect();
    assert_eq!(at3, ["wy2"]);
    let es = r
        .parameter_face
        .hypotheses
        .iter()
        .find(|h| h.name == "electrostatic_softening")
        .unwrap();
    assert_eq!(es.status, "rejected", "{es:?}");
    assert!(r.residual_over_noise < 1.1, "{}", r.residual_over_noise);

    // example 2: a toleranced device with nonlinear damping 1e-6: named, within 3σ, the
    // output error mostly closed; the ten tolerances found (within 3σ of the truth)
    let (sc, r) = ex2;
    assert_eq!(r.verdict.to_string(), "nonlinear_damping");
    let c = &r.ranking[0];
    let (size, sd) = (c.size.unwrap(), c.size_sigma.unwrap());
    println!(
        "dev-nld: {size:e} ± {sd:e}, residual {:.1}",
        r.residual_over_noise
    );
    assert!((size - 1e-6).abs() < 3.0 * sd, "{size} ± {sd}");
    assert!(r.residual_over_noise > 10.0, "{}", r.residual_over_noise);
    let oe = r.output_error.as_ref().unwrap();
    assert!(oe.closure > 0.9, "{}", oe.closure);
    let z = z_of(&sc, &r);
    println!("dev-nld: {z:?}");
    assert!(z.iter().all(|(_, z)| z.abs() < 3.0), "{z:?}");

    // the same device without the effect: `none`, at its noise
    let (_, r) = ex3;
    assert_eq!(r.verdict.to_string(), "none");
    assert!(r.residual_over_noise < 1.1, "{}", r.residual_over_noise);
}
