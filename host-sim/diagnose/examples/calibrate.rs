//! A device that is not the model, diagnosed: `cargo run --release -p paragyro-diagnose
//! --example calibrate -- [wy2=1.0275] [mu=1.05e-3] [effect=NAME=SIZE[@P]] [seed=N] [noise=PM] [tol=SEED]`
//! prints the parameter face, the verdict and the residual against the record's noise.

use paragyro_diagnose::diagnose::calibrate::describe;
use paragyro_diagnose::diagnose::{Options, diagnose};
use paragyro_simulator::record::{RecordOptions, simulate_record_with};
use paragyro_simulator::scenario::Scenario;

fn main() -> anyhow::Result<()> {
    let mut sc = Scenario::load("characterise")?;
    let mut opts = RecordOptions {
        seed: Some(21),
        rate_table: true,
        temp: Some((25.0, 4.0)),
        ..RecordOptions::default()
    };
    for a in std::env::args().skip(1) {
        let (k, v) = a.split_once('=').unwrap_or((a.as_str(), ""));
        match k {
            "wy2" => {
                sc.plant.wy2 = v.parse()?;
                sc.estimator.pump_centre_hz = Some(2.0 * sc.plant.wy2.sqrt() * sc.sim.f0_hz);
            }
            "mu" => {
                sc.plant.mu_x = v.parse()?;
                sc.plant.mu_y = v.parse()?;
            }
            "tol" => {
                use rand::SeedableRng;
                let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(v.parse()?);
                let dev = paragyro_diagnose::blind::device::DeviceDraw::draw(&mut rng);
                println!("device: {dev:?}");
                sc = dev.apply(&sc);
            }
            "seed" => opts.seed = Some(v.parse()?),
            "noise" => sc.sim.noise_pm_rthz = v.parse()?,
            "effect" => opts.effects.push(v.parse().map_err(anyhow::Error::msg)?),
            _ => anyhow::bail!("unknown argument {a}"),
        }
    }
    let (rec, _) = simulate_record_with(&sc, &opts, &mut |_| {})?;
    if std::env::var("CMP").is_ok() {
        let o2 = RecordOptions {
            effects: Vec::new(),
            ..opts.clone()
        };
        let (r2, _) = simulate_record_with(&sc, &o2, &mut |_| {})?;
        let mut m = 0.0f64;
        for (a, b) in rec.rows.iter().zip(&r2.rows) {
            m = m.max((a.lockin.y_um[0].re - b.lockin.y_um[0].re).abs());
        }
        println!("max |Δ y1.re| with/without the effects: {m:.3e} µm");
    }
    let d = diagnose(
        &rec,
        &Options {
            resimulate: std::env::var("NORESIM").is_err(),
            ..Options::default()
        },
    )?;
    let r = &d.report;
    for p in &r.parameter_face.parameters {
        println!(
            "{:<40} t = {:+9.2}  device {:.9e} ± {:.2e}",
            describe(p),
            p.t,
            p.device,
            p.sigma
        );
    }
    for h in &r.parameter_face.hypotheses {
        println!("[{}] {}: {}", h.status, h.name, h.detail);
    }
    println!(
        "noise ratio {:.3}, residual/noise {:.3}, gap fraction {:.4}, unexplained {:.3} {:?}, verdict {} (closest {}), {:.2} s",
        r.parameter_face.noise_energy_ratio,
        r.residual_over_noise,
        r.gap_fraction_of_baseline,
        r.unexplained_above_noise,
        r.unexplained_rows,
        r.verdict,
        r.closest_library_effect,
        r.seconds
    );
    for c in r
        .ranking
        .iter()
        .take(if std::env::var("ALL").is_ok() { 20 } else { 3 })
    {
        println!(
            "  {} {:?} ± {:?} closure {:.3} sig {}",
            c.effect, c.size, c.size_sigma, c.gap_closure, c.significant
        );
    }
    for c in &r.confirmation {
        println!(
            "  re-simulated {}: unexplained {:.3}, rows {:?}, residual {:.2} × the noise, confirmed {}",
            c.effect, c.unexplained, c.unexplained_rows, c.residual_over_noise, c.confirmed
        );
    }
    println!(
        "beat {:.3} Hz; {:?}",
        r.vibration_beat_scan.best_hz, r.timing_s
    );
    Ok(())
}
