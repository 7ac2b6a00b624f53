//! The bench's second function once, with its stages' wall times: `cargo run --release -p
//! paragyro-diagnose --example slowest` diagnoses its record
//! (`paragyro_diagnose::blind::outside::slowest_path_record`: 60 s, the linear test
//! `unknown`, two candidates through the confirmation) and prints the verdict, each
//! candidate's runs (report.json's `confirmation`) and `timing_s`.

use paragyro_diagnose::blind::outside::slowest_path_record;
use paragyro_diagnose::diagnose::{Options, diagnose};

fn main() -> anyhow::Result<()> {
    let rec = slowest_path_record()?;
    let t = std::time::Instant::now();
    let d = diagnose(&rec, &Options::default())?;
    let r = &d.report;
    println!(
        "verdict {} in {:.2} s",
        r.verdict,
        t.elapsed().as_secs_f64()
    );
    for c in &r.confirmation {
        println!("{} confirmed {}", c.effect, c.confirmed);
        for run in &c.runs {
            println!("  {run:?}");
        }
    }
    for (k, v) in &r.timing_s {
        println!("{k:>32} {v:7.3} s");
    }
    Ok(())
}
