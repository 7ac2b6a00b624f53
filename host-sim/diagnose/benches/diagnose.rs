//! Wall time of the sim-to-real diagnosis of a 60 s record (target: under 10 s on this
//! machine), with the re-simulations (the model over the record, the effect over the
//! held-out span).
//!
//! Run: `cargo bench -p paragyro-diagnose --bench diagnose`.

use criterion::{Criterion, criterion_group, criterion_main};
use paragyro_diagnose::diagnose::{Options, diagnose};
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

criterion_group!(benches, bench);
criterion_main!(benches);
