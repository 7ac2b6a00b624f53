//! Development records from the blind benchmark's draw, without diagnosing them:
//! `cargo run --profile test -p paragyro-diagnose --example draws -- DIR CATEGORY SEED...`
//! writes, for each seed, the records of that category (`none`, `single`, `double`,
//! `outside`) of its 100-record draw as `DIR/s{SEED}-{ID}.csv` (truth beside each), and
//! prints each one's effects; `paragyro-sim diagnose` then reads them one at a time. For
//! development seeds only: a scored run's records are written by `blind` after its
//! statement.

use std::path::PathBuf;

use anyhow::Context;
use paragyro_diagnose::blind::{Category, draw};
use paragyro_simulator::scenario::Scenario;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [dir, category, seeds @ ..] = args.as_slice() else {
        anyhow::bail!("usage: draws DIR none|single|double|outside SEED...");
    };
    let category = match category.as_str() {
        "none" => Category::None,
        "single" => Category::Single,
        "double" => Category::Double,
        "outside" => Category::Outside,
        c => anyhow::bail!("unknown category `{c}` (none, single, double, outside)"),
    };
    anyhow::ensure!(!seeds.is_empty(), "no seed given");
    let dir = PathBuf::from(dir);
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let sc = Scenario::load("characterise").map_err(anyhow::Error::new)?;
    for s in seeds {
        let seed: u64 = s.parse().with_context(|| format!("seed `{s}`"))?;
        for d in draw(100, seed)
            .into_iter()
            .filter(|d| d.category == category)
        {
            let path = dir.join(format!("s{seed}-{}.csv", d.id));
            let effects: Vec<String> = d.effects.iter().map(|e| e.to_string()).collect();
            let outside = d
                .outside
                .map(|o| format!(" outside {o:?}"))
                .unwrap_or_default();
            println!("{} {}{outside}", path.display(), effects.join(" "));
            d.write_record(&sc, &path)?;
        }
    }
    Ok(())
}
