//! Cost of one 500 Hz `Estimator::step` on the host, f32 and f64, on real simulated
//! samples (the `identify` scenario, dithered, past the start-up gate: the full path
//! with both RLS updates).
//!
//! `cargo bench -p paragyro-simulator --bench core_step`

use criterion::{Criterion, black_box, criterion_group, criterion_main};
use paragyro_core::{Estimator, Real, Sample};
use paragyro_simulator::lockin::LockinExt;
use paragyro_simulator::runner::{closed_loop, core_config};
use paragyro_simulator::scenario::Scenario;

/// 1000 samples of the identify scenario from t = 1.5 s, as the f64 core in the closed
/// loop saw them.
fn record() -> (Vec<Sample<f64>>, Scenario) {
    let mut sc = Scenario::builtin("identify").expect("built-in");
    sc.duration_s = 3.5;
    let cfg = core_config(&sc);
    let mut est: Estimator<f64> = cfg.build().expect("config");
    let mut out = Vec::new();
    closed_loop(
        &sc,
        sc.seed,
        &mut est,
        |_| {},
        |ls| {
            if ls.k >= 750 && out.len() < 1000 {
                out.push(*ls.sample);
            }
        },
    )
    .expect("closed loop");
    (out, sc)
}

fn cast<T: Real>(s: &Sample<f64>) -> Sample<T> {
    Sample {
        lockin: s.lockin.to_precision::<T>(),
        accel_mps2: s.accel_mps2.map(T::from_f64),
        pump_hz: s.pump_hz,
        pump_scale: T::from_f64(s.pump_scale),
        temp_c: None,
    }
}

fn bench_precision<T: Real>(c: &mut Criterion, samples: &[Sample<f64>], sc: &Scenario) {
    let cfg = core_config(sc);
    let data: Vec<Sample<T>> = samples.iter().map(cast::<T>).collect();
    // warm the estimator past the start-up gate on the first samples
    let mut warm: Estimator<T> = cfg.build().expect("config");
    for s in data.iter().take(400) {
        warm.step(s);
    }
    c.bench_function(
        &format!("Estimator<{}>::step (full update path)", T::NAME),
        |b| {
            let mut est = warm.clone();
            let mut i = 0usize;
            b.iter(|| {
                let o = est.step(black_box(&data[400 + i % (data.len() - 400)]));
                i += 1;
                black_box(o)
            })
        },
    );
}

fn benches(c: &mut Criterion) {
    let (samples, sc) = record();
    bench_precision::<f32>(c, &samples, &sc);
    bench_precision::<f64>(c, &samples, &sc);
}

criterion_group!(core_step, benches);
criterion_main!(core_step);
