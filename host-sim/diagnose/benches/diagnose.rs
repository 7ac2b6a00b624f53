//! Wall time of the sim-to-real diagnosis of a 60 s record (target: under 10 s on this
//! machine), with the re-simulations (the model over the record, the effect over the
//! held-out span); and of the two longest paths there are, four whole-record runs each
//! (the calibration's two and [`CONFIRM_RUNS`] more: [`CONFIRM_BUDGET_S`] of a 60 s
//! record, `Options::confirm_runs_for`; a shorter record re-simulates fewer seconds), on a 60 s
//! record ([`slowest_path_record`]): the confirmation by re-simulation of two candidates,
//! both rejected (the calibration held to its two steps), and by default the calibration's
//! further steps while it has not converged, which take the whole budget.
//!
//! Run: `cargo bench -p paragyro-diagnose --bench diagnose`.

use criterion::{Criterion, criterion_group, criterion_main};
use paragyro_diagnose::blind::outside::slowest_path_record;
use paragyro_diagnose::diagnose::confirm::{
    CONFIRM_BUDGET_S, CONFIRM_MAX, CONFIRM_RUNS, HOPELESS_UNEXPLAINED,
};
use paragyro_diagnose::diagnose::{
    CALIBRATION_MAX_RESIMULATIONS, CALIBRATION_RESIMULATIONS, Options, Report, diagnose,
};
use paragyro_simulator::record::{RecordOptions, simulate_record_with};
use paragyro_simulator::scenario::Scenario;
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let mut sc = Scenario::load("characterise").expect("built-in");
    sc.duration_s = 60.0;
    let opts = RecordOptions {
        seed: Some(5),
        effects: vec!["nonlinear_damping=1e-6".parse().expect("valid")],
        rate_table: true,
        temp: Some((25.0, 4.0)),
    };
    let (rec, _) = simulate_record_with(&sc, &opts, &mut |_| {}).expect("simulates");
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10).measurement_time(Duration::from_secs(60));
    g.bench_function("diagnose a 60 s record (re-simulation included)", |b| {
        b.iter(|| {
            let d = diagnose(&rec, &Options::default()).expect("diagnoses");
            assert_eq!(d.report.verdict.to_string(), "nonlinear_damping");
        })
    });
    g.finish();
}

/// The report took the path of [`slowest_path_record`]: the linear test left `unknown`,
/// the confirmation ran on [`CONFIRM_MAX`] candidates, the force leak then the pump-driven
/// softening, and rejected both after their first re-simulation (each left more of the gap
/// than the calibrated model without it, and its first Gauss–Newton step reversed its
/// size: `diagnose::confirm::hopeless`), the budget's [`CONFIRM_RUNS`] runs spent, and the
/// verdict stays `unknown`.
fn assert_slowest_path(r: &Report) {
    assert_eq!((CONFIRM_MAX, CONFIRM_RUNS), (2, 2));
    assert_eq!(Options::default().confirm_runs_for(60.0), CONFIRM_RUNS);
    assert_eq!(CONFIRM_BUDGET_S, 120.0);
    for c in &r.confirmation {
        assert_eq!(c.runs.len(), 1, "{c:?}");
        assert!(c.runs[0].unexplained > HOPELESS_UNEXPLAINED, "{c:?}");
    }
    let tested: Vec<(&str, bool)> = r
        .confirmation
        .iter()
        .map(|c| (c.effect.split('=').next().unwrap_or(""), c.confirmed))
        .collect();
    assert_eq!(
        tested,
        [("force_leak", false), ("electrostatic_softening", false)],
        "{:?}",
        r.confirmation
    );
    assert!(r.timing_s.contains_key("resimulate_to_confirm"));
    assert_eq!(r.parameter_face.resimulations, 3);
    assert_eq!(r.verdict.to_string(), "unknown");
}

/// The report took the default path of [`slowest_path_record`]: the calibration had not
/// converged after its two steps and took two more, the confirmation's budget, so the
/// confirmation made no run; the verdict stays `unknown`.
fn assert_calibration_path(r: &Report) {
    assert_eq!(
        r.parameter_face.resimulations,
        1 + CALIBRATION_MAX_RESIMULATIONS
    );
    assert!(r.confirmation.is_empty(), "{:?}", r.confirmation);
    assert_eq!(r.verdict.to_string(), "unknown");
}

fn bench_slowest_path(c: &mut Criterion) {
    let rec = slowest_path_record().expect("simulates");
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10).measurement_time(Duration::from_secs(60));
    let two_steps = Options {
        calibration_steps: CALIBRATION_RESIMULATIONS,
        ..Options::default()
    };
    g.bench_function(
        "diagnose a 60 s record, two candidates through the confirmation",
        |b| {
            b.iter(|| {
                let d = diagnose(&rec, &two_steps).expect("diagnoses");
                assert_slowest_path(&d.report);
            })
        },
    );
    g.bench_function(
        "diagnose a 60 s record, the calibration's four steps",
        |b| {
            b.iter(|| {
                let d = diagnose(&rec, &Options::default()).expect("diagnoses");
                assert_calibration_path(&d.report);
            })
        },
    );
    g.finish();
}

criterion_group!(benches, bench, bench_slowest_path);
criterion_main!(benches);
