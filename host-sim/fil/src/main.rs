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
    /// The loop scenario.
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
    let ls = match cli.scenario.as_str() {
        "drift-retune" => paragyro_fil::drift_retune()?,
        other => anyhow::bail!("unknown loop scenario `{other}` (known: drift-retune)"),
    };
    let out = cli.out.unwrap_or_else(paragyro_fil::default_out);
    let elf = match cli.elf {
        Some(e) => e,
        None => {
            eprintln!("paragyro-fil: building the fil firmware");
            paragyro_fil::build::firmware(&out.join("build"), &out)?
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
