//! `paragyro-fil` (`cargo fw-loop`): runs the firmware in the loop and exits 0 only when
//! the scenario's verdict holds; writes `target/fil/summary.json`.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, ValueEnum};
use paragyro_core::config::PumpProfile;

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Profile {
    /// The DDS steps at IO_UPDATE (what the board's AD9959 does): ZOH replica.
    Staircase,
    /// The core assumes a linear sweep between samples (FOH replica).
    Linear,
}

/// Firmware in the loop: QEMU runs the firmware, this process plays the chips.
#[derive(Parser, Debug)]
#[command(name = "paragyro-fil")]
struct Cli {
    /// The loop scenario: drift-retune, startup, rate-step, spi-faults.
    #[arg(default_value = "drift-retune")]
    scenario: String,
    /// Output directory (summary.json, logs, pipes).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Plant noise seed (default: the scenario's).
    #[arg(long)]
    seed: Option<u64>,
    /// Pump profile the core is configured with.
    #[arg(long, value_enum, default_value = "staircase")]
    core_profile: Profile,
    /// Use this `fil` image instead of building one.
    #[arg(long)]
    elf: Option<PathBuf>,
}

fn main() -> ExitCode {
    match run() {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("paragyro-fil: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run() -> anyhow::Result<bool> {
    let cli = Cli::parse();
    let ls = paragyro_fil::by_name(&cli.scenario)?;
    let out = cli.out.unwrap_or_else(|| {
        let d = paragyro_fil::default_out();
        if ls.name == "drift-retune" {
            d
        } else {
            d.join(&ls.name)
        }
    });
    let elf = match cli.elf {
        Some(e) => e,
        None => {
            eprintln!("paragyro-fil: building the fil firmware");
            let fil = paragyro_fil::default_out();
            paragyro_fil::build::firmware(&fil.join("build"), &fil)?
        }
    };
    let plugin = paragyro_fil::build::plugin(&out)?;
    let profile = match cli.core_profile {
        Profile::Staircase => PumpProfile::Staircase,
        Profile::Linear => PumpProfile::Linear,
    };
    eprintln!("paragyro-fil: running `{}` in the loop", ls.name);
    let s = paragyro_fil::run(&ls, &elf, &plugin, &out, cli.seed, profile)?;
    println!("{}", serde_json::to_string_pretty(&s)?);
    eprintln!(
        "paragyro-fil: {} ({} written)",
        if s.pass { "PASS" } else { "FAIL" },
        out.join("summary.json").display()
    );
    for f in &s.failures {
        eprintln!("  failed: {f}");
    }
    Ok(s.pass)
}
