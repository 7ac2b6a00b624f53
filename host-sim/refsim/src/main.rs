//! `paragyro-refsim`: the independent reference generator of paragyro records.

use std::path::PathBuf;

use clap::{Parser, Subcommand};
use paragyro_refsim::generate::{self, Category, GenOptions};

#[derive(Parser)]
#[command(
    name = "paragyro-refsim",
    version,
    about = "Independent reference records for the diagnosis's blind benchmark"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Draws N records (devices, protocols, effects), writes DIR/NNNN.csv, then
    /// DIR/labels.json with their truth.
    Gen {
        /// Number of records.
        #[arg(long)]
        n: usize,
        /// Seed of the draw.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
        /// Duration of each record, s.
        #[arg(long, default_value_t = 20.0)]
        duration_s: f64,
        /// Lock-in low-pass order (header `lockin_lpf_order`, 1–8).
        #[arg(long, default_value_t = 4)]
        lpf_order: usize,
        /// Lock-in low-pass cut-off, Hz (header `lockin_lpf_hz`).
        #[arg(long, default_value_t = 150.0)]
        lpf_hz: f64,
        /// V_A0, the pump amplitude at which s = 1 (header `pump_amp_ref_v`), V.
        #[arg(long, default_value_t = 1.0)]
        pump_amp_ref_v: f64,
        /// Relative tolerance of the integrator (1e-9: ~1e-6 µm, a tenth of one sample's
        /// noise; the cost goes as rtol^(-1/5)).
        #[arg(long, default_value_t = 1e-9)]
        rtol: f64,
        /// Share of the records with a rate-table reversal.
        #[arg(long, default_value_t = 0.4)]
        reversal_share: f64,
        /// Worker threads (0: all cores).
        #[arg(long, default_value_t = 0)]
        jobs: usize,
        /// Write only these of the N drawn records (ids, comma-separated: `0039,0079`), the
        /// same bytes as in the full run; labels.json holds only them.
        #[arg(long, value_delimiter = ',')]
        only: Vec<String>,
        /// Write only the drawn records of this category (none, single, double, outside):
        /// a development set of one kind.
        #[arg(long, value_parser = parse_category)]
        category: Option<Category>,
    },
}

/// A category by its labels.json name (`Category`'s serde names).
fn parse_category(s: &str) -> Result<Category, String> {
    serde_json::from_value(serde_json::Value::String(s.into()))
        .map_err(|_| format!("`{s}` is not a category (none, single, double, outside)"))
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.cmd {
        Cmd::Gen {
            n,
            seed,
            out,
            duration_s,
            lpf_order,
            lpf_hz,
            pump_amp_ref_v,
            rtol,
            reversal_share,
            jobs,
            only,
            category,
        } => {
            anyhow::ensure!(
                (1..=8).contains(&lpf_order),
                "--lpf-order {lpf_order} must be 1..=8"
            );
            anyhow::ensure!(
                lpf_hz.is_finite() && lpf_hz > 0.0 && lpf_hz < 250.0,
                "--lpf-hz {lpf_hz} must be in (0, 250) Hz (below the 500 Hz sampling's Nyquist)"
            );
            anyhow::ensure!(
                pump_amp_ref_v.is_finite() && pump_amp_ref_v > 0.0,
                "--pump-amp-ref-v {pump_amp_ref_v} must be positive"
            );
            if jobs > 0 {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(jobs)
                    .build_global()
                    .map_err(|e| anyhow::anyhow!("--jobs {jobs}: {e}"))?;
            }
            let opts = GenOptions {
                n,
                seed,
                duration_s,
                lpf: (lpf_order, lpf_hz),
                pump_amp_ref_v,
                rtol,
                reversal_share,
                only,
                category,
            };
            let rep = generate::generate(&opts, &out, &|m| eprintln!("{m}"))?;
            eprintln!(
                "wrote {} records and {} in {:.1} s ({:.2} s of simulation per record)",
                rep.records.len(),
                rep.labels.display(),
                rep.seconds,
                rep.cpu_seconds / rep.records.len() as f64
            );
            Ok(())
        }
    }
}

fn main() {
    if let Err(e) = run(Cli::parse()) {
        eprintln!("paragyro-refsim: error: {e:#}");
        std::process::exit(1);
    }
}
