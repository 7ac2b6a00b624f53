//! `paragyro-fil` (`cargo fw-loop`): runs the firmware in the loop and exits 0 only when
//! the scenario's verdict holds; writes `target/fil/summary.json`.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, ValueEnum};
use paragyro_fil::BoardPump;

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Pump {
    /// Two DDS steps per sample (IO_UPDATE at the tick and half a period after DRDY),
    /// the core's linear replica: the boards' configuration.
    HalfSteps,
    /// One DDS step per sample at the tick, the core's ZOH replica (`Staircase`).
    Staircase,
    /// One DDS step per sample, the core told `Linear` (a mismatch, for measurement).
    StaircaseLinear,
}

/// Firmware in the loop: QEMU runs the firmware, this process plays the chips.
#[derive(Parser, Debug)]
#[command(name = "paragyro-fil")]
struct Cli {
    /// The loop scenario: drift-retune, startup, rate-step, rate-ramp, spi-faults, out-of-band,
    /// warm-up.
    #[arg(default_value = "drift-retune")]
    scenario: String,
    /// Output directory (summary.json, logs, pipes).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Plant noise seed (default: the scenario's).
    #[arg(long)]
    seed: Option<u64>,
    /// How the board's DDS moves the pump between commands (and the core's replica).
    #[arg(long, value_enum, default_value = "half-steps")]
    pump: Pump,
    /// Use this `fil` image instead of building one.
    #[arg(long)]
    elf: Option<PathBuf>,
    /// Round the host-only loop's pump amplitude to the AD9959's 10-bit words, as the
    /// board's are (`summary.json` `rate_error` then shows what those words cost the rate;
    /// a measurement: the verdict's comparisons with the host-only loop assume it off).
    #[arg(long)]
    host_amplitude_words: bool,
    /// Round the host-only loop's pump frequency to the AD9959's words as the board does
    /// with two steps per sample (whole words with error feedback, the core told the sweep
    /// whose half means they are); `--pump half-steps` only. A measurement, as
    /// `--host-amplitude-words`.
    #[arg(long)]
    host_frequency_words: bool,
    /// `warm-up` only: stretch the ramp to this many seconds, the run ending 2 s after it
    /// (as `paragyro-sim thermal --ramp-s`).
    #[arg(long, value_name = "S")]
    ramp_s: Option<f64>,
    /// `warm-up` only: the ramp's rise, K.
    #[arg(long, value_name = "K")]
    rise_k: Option<f64>,
    /// `warm-up` only: the modes' frequency TCFs, drive and sense, ppm/K.
    #[arg(
        long,
        value_name = "DRIVE,SENSE",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    tcf_ppm_k: Option<Vec<f64>>,
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

/// `paragyro-fil budget STM32F405_ELF [SUMMARY_JSON]`: the budgets (budget.rs).
fn budget(args: &[String]) -> anyhow::Result<bool> {
    let [elf, rest @ ..] = args else {
        anyhow::bail!("usage: paragyro-fil budget STM32F405_ELF [SUMMARY_JSON]");
    };
    let image = std::fs::read(elf).map_err(|e| {
        anyhow::anyhow!("{elf}: {e} (the stm32f405 image: `cargo fw-stm32` builds it)")
    })?;
    let summary_path = rest
        .first()
        .map(PathBuf::from)
        .unwrap_or_else(|| paragyro_fil::default_out().join("summary.json"));
    let text = std::fs::read_to_string(&summary_path).map_err(|e| {
        anyhow::anyhow!(
            "{}: {e} (run `cargo fw-loop` first)",
            summary_path.display()
        )
    })?;
    let summary: paragyro_fil::Summary = serde_json::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{}: {e}", summary_path.display()))?;
    let b = paragyro_fil::budget::check(&image, &summary)?;
    use paragyro_fil::budget as bu;
    println!(
        "flash {} B (budget {} B); static RAM {} B + stack peak {} B = {} B (budget {} B)",
        b.flash,
        bu::FLASH_BUDGET,
        b.ram_static,
        b.stack_peak,
        b.ram_static + b.stack_peak,
        bu::RAM_BUDGET
    );
    println!(
        "tick: mean {:.0}, max {} instructions (exact, no fake chips); budget {} / {}",
        b.instr_mean,
        b.instr_max,
        bu::TICK_MEAN_TARGET,
        bu::TICK_MAX_TARGET,
    );
    for f in &b.failures {
        eprintln!("  over budget: {f}");
    }
    Ok(b.failures.is_empty())
}

fn run() -> anyhow::Result<bool> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("budget") {
        return budget(&args[1..]);
    }
    let cli = Cli::parse();
    let shape = paragyro_fil::WarmUpShape {
        ramp_s: cli.ramp_s,
        rise_k: cli.rise_k,
        tcf_ppm_k: cli.tcf_ppm_k.clone(),
    };
    let mut ls = if shape == paragyro_fil::WarmUpShape::default() {
        paragyro_fil::by_name(&cli.scenario)?
    } else if cli.scenario == "warm-up" {
        paragyro_fil::warm_up_shaped(&shape)?
    } else {
        anyhow::bail!("--ramp-s, --rise-k and --tcf-ppm-k reshape `warm-up` only");
    };
    ls.host_words = paragyro_fil::verdict::HostWords {
        amplitude: cli.host_amplitude_words,
        frequency: cli.host_frequency_words,
    };
    if ls.host_words.frequency && !matches!(cli.pump, Pump::HalfSteps) {
        anyhow::bail!("--host-frequency-words needs --pump half-steps (the board's two steps)");
    }
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
    let profile = match cli.pump {
        Pump::HalfSteps => BoardPump::HalfSteps,
        Pump::Staircase => BoardPump::Staircase,
        Pump::StaircaseLinear => BoardPump::StaircaseLinear,
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
