//! A device that is not the model, diagnosed: `cargo run --release -p paragyro-diagnose
//! --example calibrate -- [wy2=1.0275] [mu=1.05e-3] [effect=NAME=SIZE[@P]] [seed=N] [noise=PM]`
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
            "seed" => opts.seed = Some(v.parse()?),
            "noise" => sc.sim.noise_pm_rthz = v.parse()?,
            "effect" => opts.effects.push(v.parse().map_err(anyhow::Error::msg)?),
            _ => anyhow::bail!("unknown argument {a}"),
        }
    }
    let (rec, _) = simulate_record_with(&sc, &opts, &mut |_| {})?;
    let d = diagnose(&rec, &Options::default())?;
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
        "noise ratio {:.3}, residual/noise {:.3}, gap fraction {:.4}, verdict {} (closest {}), {:.2} s",
        r.parameter_face.noise_energy_ratio,
        r.residual_over_noise,
        r.gap_fraction_of_baseline,
        r.verdict,
        r.closest_library_effect,
        r.seconds
    );
    for c in r.ranking.iter().take(3) {
        println!(
            "  {} {:?} ± {:?} closure {:.3} sig {}",
            c.effect, c.size, c.size_sigma, c.gap_closure, c.significant
        );
    }
    println!("{:?}", r.timing_s);
    Ok(())
}
