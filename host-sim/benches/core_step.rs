//! Cost of one 500 Hz `Estimator::step` on the host, f32 and f64, on real simulated
//! samples (the `identify` scenario, dithered, past the start-up gate: the full path
//! with both RLS updates).
//!
//! `cargo bench -p paragyro-sim --bench core_step`

use criterion::{Criterion, black_box, criterion_group, criterion_main};
use paragyro_core::{Cplx, Estimator, Lockin, Real, Sample};
use paragyro_sim::plant::{GyroSim, PlantInputs, SimConfig, Theta};
use paragyro_sim::runner::core_config;
use paragyro_sim::scenario::Scenario;

/// 1000 samples of the identify scenario from t = 1.5 s (f64), with the pump commands
/// of an f64 core in the loop.
fn record() -> (Vec<Sample<f64>>, Scenario) {
    let sc = Scenario::builtin("identify").expect("built-in");
    let cfg = core_config(&sc);
    let mut est: Estimator<f64> = cfg.build().expect("config");
    let w0 = sc.omega0_rad_s();
    let f0 = sc.sim.f0_hz;
    let simcfg = SimConfig {
        omega0_rad_s: w0,
        noise_density: 1e-6,
        ..SimConfig::default()
    };
    let mut sim = GyroSim::new(&simcfg, [0.01, 0.0, 0.0, 0.0]).expect("sim");
    let mut pump = est.initial_pump_hz();
    let mut scale = 1.0;
    let mut out = Vec::new();
    for k in 0..1750u64 {
        let t = k as f64 / 500.0;
        let pa = sc.plant_at(t);
        let li = sim.lockin();
        let c = |p: (f64, f64)| Cplx::new(p.0, p.1);
        let s = Sample {
            lockin: Lockin {
                x0_um: li.x0,
                x_um: [c(li.x[0]), c(li.x[1]), c(li.x[2])],
                y0_um: li.y0,
                y_um: [c(li.y[0]), c(li.y[1]), c(li.y[2])],
            },
            accel_mps2: [98.0665, 98.0665],
            pump_hz: pump,
            pump_scale: scale,
        };
        let o = est.step(&s);
        if k >= 750 {
            out.push(s);
        }
        let u0 = PlantInputs {
            omega: pump / (2.0 * f0),
            s: scale,
            ax: pa.accel_x,
            ay: pa.accel_y,
        };
        let u1 = PlantInputs {
            omega: o.pump_hz_next / (2.0 * f0),
            s: o.pump_scale_next,
            ax: pa.accel_x,
            ay: pa.accel_y,
        };
        sim.advance(
            &Theta {
                drive: pa.theta_drive,
                sense: pa.theta_sense,
            },
            &u0,
            &u1,
        );
        pump = o.pump_hz_next;
        scale = o.pump_scale_next;
    }
    (out, sc)
}

fn cast<T: Real>(s: &Sample<f64>) -> Sample<T> {
    let c = |z: Cplx<f64>| z.cast::<T>();
    Sample {
        lockin: Lockin {
            x0_um: T::from_f64(s.lockin.x0_um),
            x_um: s.lockin.x_um.map(c),
            y0_um: T::from_f64(s.lockin.y0_um),
            y_um: s.lockin.y_um.map(c),
        },
        accel_mps2: s.accel_mps2.map(T::from_f64),
        pump_hz: s.pump_hz,
        pump_scale: T::from_f64(s.pump_scale),
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
