//! `paragyro-sim faults --ticks N --out DIR`: the fault campaign (paragyro_simulator::faults):
//! every fault class injected into the closed loop of the f32 core, scored; writes
//! DIR/faults.json and DIR/faults.md (the table of host-sim/docs/reliability.md "Fault campaign"), progress on stderr.

use std::path::PathBuf;
use std::sync::Mutex;

use super::{Ctx, EXIT_LOAD, EXIT_RUN, Failure, fail, note, write_report};
use paragyro_simulator::faults::{CampaignOptions, FaultClass, run_campaign};

/// Run the fault campaign; write faults.json and faults.md.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Ticks (500 Hz samples) per class.
    #[arg(long, default_value_t = 100_000)]
    pub ticks: u64,
    /// Output directory (created if needed).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Seed of the fault times, sizes and the plant noise.
    #[arg(long, default_value_t = 13)]
    pub seed: u64,
    /// Only these classes (comma-separated names, see faults.json); all by default.
    #[arg(long, value_delimiter = ',')]
    pub class: Vec<String>,
    /// Clean ticks before the first episode.
    #[arg(long, default_value_t = 5000)]
    pub warmup: u64,
    /// Ticks per episode slot (the episode, then its recovery).
    #[arg(long, default_value_t = 5000)]
    pub slot: u64,
}

/// Runs the campaign and writes its report.
pub fn exec(a: Args, ctx: &mut Ctx) -> Result<(), Failure> {
    let mut opts = CampaignOptions::new(a.ticks, a.seed);
    opts.warmup = a.warmup;
    opts.slot = a.slot;
    if !a.class.is_empty() {
        opts.classes = a
            .class
            .iter()
            .map(|n| {
                FaultClass::from_name(n).ok_or_else(|| Failure {
                    code: EXIT_LOAD,
                    error: anyhow::anyhow!(
                        "unknown fault class '{n}' (expected one of: {})",
                        FaultClass::ALL.map(|c| c.name()).join(", ")
                    ),
                })
            })
            .collect::<Result<_, _>>()?;
    }
    note(&format!(
        "faults: {} classes × {} ticks (f32 core), seed {}",
        opts.classes.len(),
        opts.ticks,
        opts.seed
    ));
    let done = Mutex::new(0usize);
    let total = opts.classes.len();
    let progress = |c: FaultClass, f: f64| {
        if f >= 1.0 {
            let mut d = done.lock().unwrap_or_else(|e| e.into_inner());
            *d += 1;
            note(&format!("faults: {} done ({}/{total})", c.name(), *d));
        } else {
            note(&format!("faults: {} {:.0} %", c.name(), 100.0 * f));
        }
    };
    let rep = run_campaign(&opts, &progress).map_err(fail(EXIT_RUN))?;
    let table = rep.table_md();
    write_report(ctx, &a.out, "faults", &rep, &table)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_class_and_short_run_are_refused_before_any_work() {
        let dir = std::env::temp_dir().join(format!("paragyro-faults-{}", std::process::id()));
        let args = |class: Vec<String>, ticks| Args {
            ticks,
            out: dir.clone(),
            seed: 1,
            class,
            warmup: 5000,
            slot: 5000,
        };
        let mut out = Vec::new();
        let mut ctx = Ctx {
            out: &mut out,
            progress_ok: false,
        };
        let e = exec(args(vec!["nan".into(), "bogus".into()], 100_000), &mut ctx)
            .err()
            .unwrap();
        assert_eq!(e.code, EXIT_LOAD);
        assert!(format!("{:#}", e.error).contains("unknown fault class 'bogus'"));
        let e = exec(args(vec![], 6000), &mut ctx).err().unwrap();
        assert_eq!(e.code, EXIT_RUN);
        assert!(format!("{:#}", e.error).contains("shorter than the warm-up"));
        assert!(!dir.exists(), "nothing written on an error");
    }
}
