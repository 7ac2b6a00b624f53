//! `paragyro-sim replay FILE.csv --out DIR`: the core open-loop on a record (a simulated
//! one or a real device's): estimates.csv and summary.json.

use std::path::PathBuf;

use super::{Ctx, EXIT_RUN, Failure, PrecisionArg, fail, file_list, read_record_warn};
use paragyro_simulator::record::write_replay;

/// Run the core open-loop on a record; write estimates.csv and summary.json.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The record (CSV, host-sim/sim/record-format.md).
    pub record: PathBuf,
    /// Output directory (created if needed).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Precision of the core.
    #[arg(long, value_enum, default_value_t = PrecisionArg::F32)]
    pub precision: PrecisionArg,
}

/// Replays the record and lists what it wrote.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    let rec = read_record_warn(&a.record)?;
    let source = a.record.display().to_string();
    let res = write_replay(&rec, &source, &a.out, a.precision.into()).map_err(fail(EXIT_RUN))?;
    let mut text = res.text;
    text.push_str(&format!(
        "Wrote {} files to {}:\n",
        res.files.len(),
        a.out.display()
    ));
    text.push_str(&file_list(&res.files));
    ctx.say(&text)
}
