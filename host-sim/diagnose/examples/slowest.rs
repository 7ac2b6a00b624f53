//! The bench's two slowest-path functions once each, with their stages' wall times: `cargo
//! run --release -p paragyro-diagnose --example slowest` diagnoses their record
//! (`paragyro_diagnose::blind::outside::slowest_path_record`: 60 s, the linear test
//! `unknown`) with the calibration held to its two steps (two candidates through the
//! confirmation) and with the defaults (the calibration's further steps, where it has not
//! converged, take the confirmation's runs), and prints each verdict, the calibration's
//! passes, each candidate's runs (report.json's `confirmation`) and `timing_s`; first, which
//! build of the simulator's hot loop runs (host-sim/docs/benchmarks.md, "Build settings").

use paragyro_diagnose::blind::outside::slowest_path_record;
use paragyro_diagnose::diagnose::{CALIBRATION_RESIMULATIONS, Options, diagnose};

fn main() -> anyhow::Result<()> {
    let rec = slowest_path_record()?;
    // which build of the simulator's hot loop runs here (`PARAGYRO_SIMD=off`: the portable)
    let build = if paragyro_simulator::simd::avx2_fma() {
        "AVX2 + FMA"
    } else {
        "portable"
    };
    println!("the simulator's {build} build");
    let two_steps = Options {
        calibration_steps: CALIBRATION_RESIMULATIONS,
        ..Options::default()
    };
    for (name, opts) in [
        ("the calibration's two steps", two_steps),
        ("the defaults", Options::default()),
    ] {
        let t = std::time::Instant::now();
        let d = diagnose(&rec, &opts)?;
        let r = &d.report;
        println!(
            "{name}: verdict {} in {:.2} s, {} calibration passes",
            r.verdict,
            t.elapsed().as_secs_f64(),
            r.parameter_face.resimulations
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
    }
    Ok(())
}
