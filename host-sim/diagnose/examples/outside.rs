//! Development runs of the out-of-library effects (how their detection limits were stated,
//! before the scored run): `cargo run --profile test -p paragyro-diagnose --example outside
//! -- SEED [MULTIPLES…]` records one toleranced device per (type, size = multiple × the
//! stated limit) — devices drawn from SEED as the blind benchmark draws them — and prints the
//! diagnosis's verdict, the held-out residual over the record's noise and the explainable
//! gap fraction. Default multiples: 0.3 1 3 10.

use paragyro_diagnose::blind::device::DeviceDraw;
use paragyro_diagnose::blind::outside::Outside;
use paragyro_diagnose::diagnose::{Options, diagnose};
use paragyro_simulator::record::{RecordOptions, simulate_record_ext};
use paragyro_simulator::scenario::Scenario;
use rand::SeedableRng;
use rayon::prelude::*;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let seed: u64 = args.first().map_or(Ok(1), |s| s.parse())?;
    let mults: Vec<f64> = if args.len() > 1 {
        args[1..]
            .iter()
            .map(|s| s.parse())
            .collect::<Result<_, _>>()?
    } else {
        vec![0.3, 1.0, 3.0, 10.0]
    };
    let sc = Scenario::load("characterise").map_err(anyhow::Error::new)?;
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut jobs = Vec::new();
    for kind in Outside::ALL {
        for &m in &mults {
            let dev = DeviceDraw::draw(&mut rng);
            jobs.push((kind, m, dev, jobs.len() as u64 + 100 * seed));
        }
    }
    let lines: Vec<String> = jobs
        .par_iter()
        .map(|(kind, m, dev, nseed)| {
            let size = m * kind.size_range().limit;
            let dsc = dev.apply(&sc);
            let hook = kind.hook(size, dev.physical(&sc).wy2, sc.omega0_rad_s());
            let opts = RecordOptions {
                seed: Some(*nseed),
                rate_table: true,
                temp: Some((25.0, 4.0)),
                ..RecordOptions::default()
            };
            let run = || -> anyhow::Result<String> {
                let (rec, _) = simulate_record_ext(&dsc, &opts, Some(hook), &mut |_| {})?;
                let r = diagnose(&rec, &Options::default())?.report;
                Ok(format!(
                    "{kind:<17} {m:>6} × limit = {size:>10.3e}  rate {:>7.1} °/s  → {:<24} residual/noise {:>8.3}  gap fraction {:.4}  closest {}",
                    dev.rate_dps,
                    r.verdict.to_string(),
                    r.residual_over_noise,
                    r.gap_fraction_of_baseline,
                    r.closest_library_effect
                ))
            };
            run().unwrap_or_else(|e| format!("{kind} {m}: error {e:#}"))
        })
        .collect();
    for l in lines {
        println!("{l}");
    }
    Ok(())
}
