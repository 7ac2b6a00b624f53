//! `paragyro-fw-replay`: host side of the firmware's replay and capture (firmware/README.md).
//!
//! * `table`: simulate a scenario (closed loop with the f64 core, as `paragyro-sim record`)
//!   and write the firmware's replay table (`firmware/replay/fw-drift-retune.bin` by
//!   default), which the QEMU board serves through its replay SPI devices.
//! * `capture`: turn a device's capture log (the defmt output of a firmware built with the
//!   `capture` feature, decoded by `defmt-print`) into a `paragyro-record 1` CSV.

use paragyro_fw_replay::{capture, table};

use std::path::PathBuf;

use anyhow::Context;
use clap::{Parser, Subcommand};
use paragyro_simulator::scenario::Scenario;

#[derive(Parser)]
#[command(
    version,
    about = "Firmware replay tables and capture logs (firmware/README.md)"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Simulate a scenario and write the firmware's replay table.
    Table {
        /// Scenario name or TOML file.
        #[arg(default_value = "host-sim/scenarios/fw-drift-retune.toml")]
        scenario: String,
        /// Output file.
        #[arg(long, default_value = "firmware/replay/fw-drift-retune.bin")]
        out: PathBuf,
        /// Noise seed (default: the scenario's).
        #[arg(long)]
        seed: Option<u64>,
        /// Also write the simulated record (CSV) here.
        #[arg(long)]
        record: Option<PathBuf>,
    },
    /// Convert a capture log (defmt-print output) into a paragyro-record 1 CSV.
    Capture {
        /// The log (text lines from defmt-print; other lines are ignored).
        log: PathBuf,
        /// Output record.
        #[arg(long)]
        out: PathBuf,
    },
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().cmd {
        Cmd::Table {
            scenario,
            out,
            seed,
            record,
        } => {
            let sc = Scenario::load(&scenario).map_err(|e| anyhow::anyhow!("{e}"))?;
            let t = table::build(&sc, seed)?;
            if let Some(dir) = out.parent() {
                std::fs::create_dir_all(dir)?;
            }
            std::fs::write(&out, &t.bytes).with_context(|| format!("writing {}", out.display()))?;
            if let Some(csv) = record {
                paragyro_simulator::record::write_record(&csv, &t.record)?;
            }
            println!(
                "Wrote {} ({} bytes): {} samples of '{}' ({} s), µm/V drive {} sense {}, FNV-1a 64 {:016x}",
                out.display(),
                t.bytes.len(),
                t.record.rows.len(),
                sc.name,
                sc.duration_s,
                t.um_per_volt[0],
                t.um_per_volt[1],
                paragyro_firmware::table::fnv1a64(
                    &t.bytes[paragyro_firmware::table::HEADER_BYTES..]
                ),
            );
            println!(
                "core: pump centre {:.4} Hz, nominal ωy² {}; truth: ωy² {} → {}, sense resonance at the end {:.4} Hz, record pump at the end {:.4} Hz",
                t.config.pump_centre_hz,
                t.config.nominal.wy2,
                t.truth[0],
                t.truth[1],
                t.truth[4],
                t.truth[7]
            );
            Ok(())
        }
        Cmd::Capture { log, out } => {
            let text = std::fs::read_to_string(&log)
                .with_context(|| format!("reading {}", log.display()))?;
            let rec = capture::parse_capture(&text, &log.display().to_string())?;
            paragyro_simulator::record::write_record(&out, &rec)?;
            println!(
                "Wrote {} ({} samples, {:.3} s)",
                out.display(),
                rec.rows.len(),
                rec.duration_s()
            );
            Ok(())
        }
    }
}
