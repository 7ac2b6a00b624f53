//! The blind benchmark without the CLI: `cargo run --profile test -p paragyro-diagnose
//! --example blind -- N SEED DIR` (same files as `paragyro-sim blind --n N --seed SEED
//! --out DIR`).

use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [n, seed, dir] = args.as_slice() else {
        anyhow::bail!("usage: blind N SEED DIR");
    };
    let (n, seed): (usize, u64) = (n.parse()?, seed.parse()?);
    let dir = PathBuf::from(dir);
    let s = paragyro_diagnose::blind::run(n, seed, &dir, &|m| eprintln!("{m}"))?;
    let p = |v: Option<f64>| v.map_or("–".into(), |x| format!("{:.0} %", 100.0 * x));
    println!(
        "Blind benchmark, N = {n}, seed {seed}:\n  top-1 (single, above limit) {}\n  unknown on out-of-library {}\n  unknown on out-of-library outside the span, above the limit {} ({} records)\n  false alarms on clean {}\n  median closure / oracle {}\nWrote {}/score.md and score.json",
        p(s.top1_single_above_limit),
        p(s.unknown_on_outside),
        p(s.unknown_on_outside_span_above_limit),
        s.outside_span_above_limit_records,
        p(s.false_alarms_on_clean),
        p(s.median_closure_over_oracle),
        dir.display()
    );
    Ok(())
}
