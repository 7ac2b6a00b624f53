//! Detection limits measured on development devices (`paragyro_diagnose::blind::lod`):
//! `cargo run --profile test -p paragyro-diagnose --example lod -- K SEED DIR [POINTS
//! [ONLY]]` writes DIR/lod.md and DIR/lod.json (POINTS sizes per effect, default 5; ONLY
//! keeps the effects whose name contains it), and keeps the missed records in
//! DIR/records/ (with their truth) to be diagnosed again (`paragyro-sim diagnose`).

use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (k, seed, dir, points, only) = match args.as_slice() {
        [k, seed, dir] => (k, seed, dir, 5, None),
        [k, seed, dir, p] => (k, seed, dir, p.parse()?, None),
        [k, seed, dir, p, only] => (k, seed, dir, p.parse()?, Some(only.as_str())),
        _ => anyhow::bail!("usage: lod K SEED DIR [POINTS [ONLY]]"),
    };
    let (k, seed): (usize, u64) = (k.parse()?, seed.parse()?);
    let dir = PathBuf::from(dir);
    let rows =
        paragyro_diagnose::blind::lod::sweep(k, seed, points, only, &dir, &|m| eprintln!("{m}"))?;
    println!(
        "{} sizes swept; wrote {}/lod.md and lod.json",
        rows.len(),
        dir.display()
    );
    print!("{}", std::fs::read_to_string(dir.join("lod.md"))?);
    Ok(())
}
