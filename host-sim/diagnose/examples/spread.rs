//! The calibrated model's prediction spread on a record, beside the record's departure from
//! the model: `cargo run --profile test -p paragyro-diagnose --example spread -- RECORD.csv
//! [DRAWS] [WINDOW_S]` calibrates as the diagnosis does, re-simulates DRAWS twins (3 unless
//! given) of the calibrated model, each with its θ moved by a draw from their covariance
//! ([`paragyro_diagnose::diagnose::spread`]), and prints per held-out window (0.5 s unless
//! given) the record's departure from the model and the twins' spread (rms and largest, the
//! drive's 1st harmonic |Δx1|, µm), then where the record departs most and the spread there.
//! docs/notes.md, "The model's prediction spread at the drive's regrowths".

use paragyro_diagnose::diagnose::Options;
use paragyro_diagnose::diagnose::spread::prediction_spread;
use paragyro_simulator::record::read_record;
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        anyhow::bail!("usage: spread RECORD.csv [DRAWS] [WINDOW_S]");
    };
    let draws: usize = args.get(1).map_or(Ok(3), |v| v.parse())?;
    let window_s: f64 = args.get(2).map_or(Ok(0.5), |v| v.parse())?;
    anyhow::ensure!(window_s > 0.0, "WINDOW_S must be > 0");
    let rec = read_record(Path::new(path))?;
    let ps = prediction_spread(&rec, &Options::default(), draws, 7)?;
    let hold: Vec<usize> = (0..ps.t.len())
        .filter(|&i| ps.t[i] >= ps.hold_start_s)
        .collect();
    anyhow::ensure!(!hold.is_empty(), "the record has no held-out span");
    println!(
        "{} twins; the drive's working amplitude {:.4} µm; held-out span from {:.2} s",
        ps.draws, ps.working_um, ps.hold_start_s
    );
    println!("| t0, s | departure rms |Δx1| | departure max | spread rms |Δx1| | spread max |");
    println!("|---|---|---|---|---|");
    let mut w0 = 0;
    while w0 < hold.len() {
        let t0 = ps.t[hold[w0]];
        let w1 = (w0..hold.len())
            .find(|&j| ps.t[hold[j]] >= t0 + window_s)
            .unwrap_or(hold.len());
        let win = &hold[w0..w1];
        let rms = |f: &dyn Fn(usize) -> f64| {
            (win.iter().map(|&i| f(i).powi(2)).sum::<f64>() / win.len() as f64).sqrt()
        };
        let max = |f: &dyn Fn(usize) -> f64| win.iter().map(|&i| f(i)).fold(0.0, f64::max);
        let dep = |i: usize| ps.departure[i][0];
        let spr = |i: usize| ps.spread[i][0];
        println!(
            "| {t0:.2} | {:.3e} | {:.3e} | {:.3e} | {:.3e} |",
            rms(&dep),
            max(&dep),
            rms(&spr),
            max(&spr)
        );
        w0 = w1;
    }
    let worst = hold
        .iter()
        .copied()
        .max_by(|&a, &b| ps.departure[a][0].total_cmp(&ps.departure[b][0]))
        .unwrap_or(hold[0]);
    let widest = hold
        .iter()
        .copied()
        .max_by(|&a, &b| ps.spread[a][0].total_cmp(&ps.spread[b][0]))
        .unwrap_or(hold[0]);
    println!(
        "the record departs most at {:.3} s: |Δx1| {:.3e} µm, the spread there {:.3e} µm ({:.1}×); the spread is widest at {:.3} s ({:.3e} µm)",
        ps.t[worst],
        ps.departure[worst][0],
        ps.spread[worst][0],
        ps.departure[worst][0] / ps.spread[worst][0],
        ps.t[widest],
        ps.spread[widest][0]
    );
    let e = |f: &dyn Fn(usize) -> f64| hold.iter().map(|&i| f(i).powi(2)).sum::<f64>();
    println!(
        "held-out rms |Δx1|: the record's departure {:.3e} µm, the spread {:.3e} µm",
        (e(&|i| ps.departure[i][0]) / hold.len() as f64).sqrt(),
        (e(&|i| ps.spread[i][0]) / hold.len() as f64).sqrt()
    );
    Ok(())
}
