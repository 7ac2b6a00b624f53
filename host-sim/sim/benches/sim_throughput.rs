//! Throughput of the full-rate simulated gyro (eq. 6, RK4 at 128 steps per carrier
//! period, 14-channel lock-in, 1 pm/√Hz noise on both axes).
//!
//! Run: `cargo bench -p paragyro-simulator --bench sim_throughput`. Besides criterion's timing
//! of "simulate 0.1 s (50 samples)" it prints the simulated seconds per wall-clock second
//! of a plain timed run (target ≥ 10, ARCHITECTURE.md §5).

use criterion::{Criterion, black_box, criterion_group, criterion_main};
use paragyro_simulator::lockin::LockinExt;
use paragyro_simulator::plant::{GyroSim, PlantInputs, SimConfig, Theta};
use std::time::Instant;

/// Simulates `n` samples at the nominal operating point; returns |A1| (kept alive).
fn simulate(sim: &mut GyroSim, th: &Theta, u: &PlantInputs, n: usize) -> f64 {
    for _ in 0..n {
        sim.advance(th, u, u);
    }
    sim.lockin().x_abs(1)
}

fn bench(c: &mut Criterion) {
    let cfg = SimConfig::default(); // 128 steps/period at ω ≤ 1.05, noise 1e-6, LPF 4/150 Hz
    let th = Theta::table2();
    let u = PlantInputs::nominal();
    let mut sim = GyroSim::new(&cfg, [0.01, 0.0, 0.0, 0.0]).expect("default config is valid");
    // settle onto the steady state first, so that the timed work is the operating regime
    simulate(&mut sim, &th, &u, 100);

    let samples = 50; // 0.1 s at 500 Hz
    let sim_s = samples as f64 / cfg.fs_hz;
    c.bench_function(
        "simulate 0.1 s (50 samples) at 128 steps/period with lock-in and noise",
        |b| b.iter(|| black_box(simulate(&mut sim, black_box(&th), black_box(&u), samples))),
    );

    // plain wall-clock measurement: best of 5 runs of 1 simulated second each (the best
    // run is the least disturbed by other load on the machine)
    let n = 500;
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        let t0 = Instant::now();
        black_box(simulate(&mut sim, &th, &u, n));
        best = best.min(t0.elapsed().as_secs_f64());
    }
    let steps = (n * sim.steps_per_sample()) as f64;
    println!(
        "sim_throughput: {:.1} simulated s per wall s ({} RK4 steps/sample, {:.1} ns per step incl. lock-in and noise; 0.1 s takes {:.2} ms)",
        n as f64 / cfg.fs_hz / best,
        sim.steps_per_sample(),
        best / steps * 1e9,
        best / (n as f64 / cfg.fs_hz) * sim_s * 1e3,
    );
    // and without noise (the deterministic configuration)
    let cfg0 = SimConfig {
        noise_density: 0.0,
        ..cfg.clone()
    };
    let mut sim0 = GyroSim::new(&cfg0, [0.01, 0.0, 0.0, 0.0]).expect("valid");
    simulate(&mut sim0, &th, &u, 100);
    let mut dt = f64::INFINITY;
    for _ in 0..5 {
        let t0 = Instant::now();
        black_box(simulate(&mut sim0, &th, &u, n));
        dt = dt.min(t0.elapsed().as_secs_f64());
    }
    println!(
        "sim_throughput (noise off): {:.1} simulated s per wall s ({:.1} ns per step)",
        n as f64 / cfg.fs_hz / dt,
        dt / steps * 1e9
    );
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
