//! Wall time of the sim-to-real diagnosis of a 60 s record (target: under 10 s on this
//! machine), with the re-simulations (the model over the record, the effect over the
//! held-out span); and of the longest path there is, four whole-record runs (the
//! calibration's two and [`CONFIRM_RUNS`] more: [`CONFIRM_BUDGET_S`] of a 60 s record,
//! `Options::confirm_runs_for`; a shorter record re-simulates fewer seconds), on a 60 s
//! record ([`slowest_path_record`]): the confirmation by re-simulation of two candidates,
//! both rejected.
//!
//! Run: `cargo bench -p paragyro-diagnose --bench diagnose`.

use criterion::{Criterion, criterion_group, criterion_main};
use paragyro_diagnose::blind::outside::slowest_path_record;
use paragyro_diagnose::diagnose::confirm::{CONFIRM_BUDGET_S, CONFIRM_MAX, CONFIRM_RUNS};
use paragyro_diagnose::diagnose::{CALIBRATION_RESIMULATIONS, Options, Report, diagnose};
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

/// The report took the path of [`slowest_path_record`]: the calibration converged in its
/// usual two steps, the linear test left `unknown`, the confirmation ran on [`CONFIRM_MAX`]
/// candidates, the force leak then the pump-driven softening, one run each (the budget's
/// [`CONFIRM_RUNS`] on a 60 s record), neither passing, and the verdict stays `unknown`:
/// four whole-record runs.
fn assert_slowest_path(r: &Report) {
    assert_eq!((CONFIRM_MAX, CONFIRM_RUNS), (2, 2));
    assert_eq!(Options::default().confirm_runs_for(60.0), CONFIRM_RUNS);
    assert_eq!(CONFIRM_BUDGET_S, 120.0);
    assert_eq!(
        r.parameter_face.resimulations,
        1 + CALIBRATION_RESIMULATIONS
    );
    let tested: Vec<(&str, bool, usize)> = r
        .confirmation
        .iter()
        .map(|c| {
            (
                c.effect.split('=').next().unwrap_or(""),
                c.confirmed,
                c.runs.len(),
            )
        })
        .collect();
    assert_eq!(
        tested,
        [
            ("force_leak", false, 1),
            ("electrostatic_softening", false, 1)
        ],
        "{:?}",
        r.confirmation
    );
    assert!(r.timing_s.contains_key("resimulate_to_confirm"));
    assert_eq!(r.verdict.to_string(), "unknown");
}

fn bench_slowest_path(c: &mut Criterion) {
    let rec = slowest_path_record().expect("simulates");
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10).measurement_time(Duration::from_secs(60));
    g.bench_function(
        "diagnose a 60 s record, two candidates through the confirmation",
        |b| {
            b.iter(|| {
                let d = diagnose(&rec, &Options::default()).expect("diagnoses");
                assert_slowest_path(&d.report);
            })
        },
    );
    g.finish();
}

criterion_group!(benches, bench, bench_slowest_path);
criterion_main!(benches);
