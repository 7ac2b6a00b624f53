//! Two records of one device on the same inputs, compared window by window: `cargo run
//! --profile test -p paragyro-diagnose --example compare -- A.csv B.csv [WINDOW_S]` prints,
//! per window (0.5 s unless given), the rms and the largest difference of the drive's and
//! the sense's 1st-harmonic phasors (|ΔA1|, |ΔB1|, µm), the drive's smallest |A1| in A
//! against A's working amplitude (its 90th percentile), and the window's rms |ΔA1| over the
//! median window's. Where a small difference between the two (an integrator's tolerance, a
//! parameter within its σ) is amplified by the trajectory, that ratio is large: at the
//! regrowths after the drive's deep collapses (docs/notes.md, "Clean devices through a
//! collapse").

use paragyro_simulator::record::{Record, read_record};
use std::path::Path;

/// The drive's and the sense's 1st-harmonic phasors of each row, µm.
fn phasors(rec: &Record) -> Vec<([f64; 2], [f64; 2])> {
    rec.rows
        .iter()
        .map(|r| {
            let (x, y) = (r.lockin.x_um[0], r.lockin.y_um[0]);
            ([x.re, x.im], [y.re, y.im])
        })
        .collect()
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(pa), Some(pb)) = (args.first(), args.get(1)) else {
        anyhow::bail!("usage: compare A.csv B.csv [WINDOW_S]");
    };
    let window_s: f64 = match args.get(2) {
        Some(w) => w.parse()?,
        None => 0.5,
    };
    anyhow::ensure!(window_s > 0.0, "WINDOW_S must be > 0");
    let a = read_record(Path::new(pa))?;
    let b = read_record(Path::new(pb))?;
    anyhow::ensure!(
        a.rows.len() == b.rows.len(),
        "the records differ in length ({} and {} rows)",
        a.rows.len(),
        b.rows.len()
    );
    let (pa_, pb_) = (phasors(&a), phasors(&b));
    let amp: Vec<f64> = pa_.iter().map(|(x, _)| x[0].hypot(x[1])).collect();
    let working = {
        let mut s = amp.clone();
        s.sort_by(f64::total_cmp);
        s[(0.9 * (s.len() - 1) as f64) as usize]
    };
    anyhow::ensure!(working > 0.0, "record A's drive is zero");
    // rows per window
    let dt = a.duration_s() / (a.rows.len().max(2) - 1) as f64;
    let per = ((window_s / dt).round() as usize).max(1);
    struct Win {
        t0: f64,
        rms_x: f64,
        max_x: f64,
        rms_y: f64,
        max_y: f64,
        depth: f64,
    }
    let mut wins = Vec::new();
    for k0 in (0..a.rows.len()).step_by(per) {
        let chunk = k0..(k0 + per).min(a.rows.len());
        let (mut sx, mut mx, mut sy, mut my, mut depth) = (0.0, 0.0f64, 0.0, 0.0f64, f64::MAX);
        for i in chunk.clone() {
            let dx = dist(pa_[i].0, pb_[i].0);
            let dy = dist(pa_[i].1, pb_[i].1);
            sx += dx * dx;
            sy += dy * dy;
            mx = mx.max(dx);
            my = my.max(dy);
            depth = depth.min(amp[i] / working);
        }
        let n = chunk.len() as f64;
        wins.push(Win {
            t0: a.rows[k0].t_s,
            rms_x: (sx / n).sqrt(),
            max_x: mx,
            rms_y: (sy / n).sqrt(),
            max_y: my,
            depth,
        });
    }
    let median = {
        let mut s: Vec<f64> = wins.iter().map(|w| w.rms_x).collect();
        s.sort_by(f64::total_cmp);
        s[s.len() / 2]
    };
    // against the median window's rms
    let rel = |v: f64| if median > 0.0 { v / median } else { f64::NAN };
    println!("working drive amplitude (A's 90th percentile of |A1|): {working:.4} µm");
    println!(
        "| t0, s | rms |ΔA1| | max |ΔA1| | rms |ΔB1| | max |ΔB1| | min |A1| / working | rms |ΔA1| / median window |"
    );
    println!("|---|---|---|---|---|---|---|");
    for w in &wins {
        println!(
            "| {:.2} | {:.3e} | {:.3e} | {:.3e} | {:.3e} | {:.2e} | {:.1} |",
            w.t0,
            w.rms_x,
            w.max_x,
            w.rms_y,
            w.max_y,
            w.depth,
            rel(w.rms_x)
        );
    }
    if let Some(w) = wins.iter().max_by(|p, q| p.max_x.total_cmp(&q.max_x)) {
        println!(
            "largest |ΔA1|: {:.3e} µm in the window from {:.2} s (its smallest |A1| {:.2e} of the working amplitude), {:.0}× the median window's rms",
            w.max_x,
            w.t0,
            w.depth,
            rel(w.max_x)
        );
    }
    Ok(())
}
