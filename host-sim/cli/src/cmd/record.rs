//! `paragyro-sim record <scenario> --out FILE.csv`: a simulated record (host-sim/sim/record-format.md)
//! and its truth beside it, optionally with sim-to-real effects, a temperature ramp and a
//! rate table.

use std::path::PathBuf;

use anyhow::Context;

use super::{Ctx, EXIT_RUN, Failure, fail, load};
use paragyro_simulator::effects::EffectSpec;
use paragyro_simulator::record::{RecordOptions, write_simulated_record};

/// Simulate a scenario as a record (CSV at 500 Hz, host-sim/sim/record-format.md); its truth
/// goes to FILE.truth.json beside it.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Built-in scenario name or path to a scenario TOML file.
    pub scenario: String,
    /// The record to write (the truth goes to FILE.truth.json).
    #[arg(long, value_name = "FILE.csv")]
    pub out: PathBuf,
    /// Override the scenario's noise seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Add an effect to the simulated device: NAME=SIZE (angular_vibration=SIZE@BEAT_HZ);
    /// repeatable. Names and units: `paragyro-sim effects`.
    #[arg(long = "effect", value_name = "NAME=SIZE")]
    pub effects: Vec<EffectSpec>,
    /// Die temperature START_C:RISE_K (linear over the run), written as temp_c.
    #[arg(long, value_name = "START_C:RISE_K", value_parser = parse_temp)]
    pub temp: Option<(f64, f64)>,
    /// A rate table is present: write the true rate as rate_ref_dps.
    #[arg(long)]
    pub rate_table: bool,
}

/// `START_C:RISE_K` → (start, rise).
fn parse_temp(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("'{s}': expected START_C:RISE_K, e.g. 25:5"))?;
    let num = |v: &str| {
        v.trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("'{v}' is not a finite number"))
    };
    Ok((num(a)?, num(b)?))
}

/// Simulates and writes the record and its truth.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    let sc = load(&a.scenario)?;
    let opts = RecordOptions {
        seed: a.seed,
        effects: a.effects,
        temp: a.temp,
        rate_table: a.rate_table,
    };
    let (files, rec) = write_simulated_record(&sc, &a.out, &opts, &mut |_| {})
        .with_context(|| format!("cannot record scenario '{}'", sc.name))
        .map_err(fail(EXIT_RUN))?;
    ctx.say(&format!(
        "Wrote {} ({} samples, {} s at {} Hz) and its truth {}\n",
        files.csv.display(),
        rec.rows.len(),
        rec.duration_s(),
        rec.header.fs_hz,
        files.truth.display()
    ))
}

#[cfg(test)]
mod tests {
    use super::parse_temp;

    #[test]
    fn temperature_argument() {
        assert_eq!(parse_temp("25:4"), Ok((25.0, 4.0)));
        assert!(parse_temp("25").unwrap_err().contains("START_C:RISE_K"));
        assert!(parse_temp("a:4").unwrap_err().contains("'a'"));
        assert!(parse_temp("25:inf").is_err());
    }
}
