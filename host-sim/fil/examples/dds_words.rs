//! What each of the DDS's words adds to the fast rate, and what a finer DDS would leave.
//!
//! ```text
//! cargo run --release -p paragyro-fil --example dds_words -- [SCENARIO] [SEED ...]
//! ```
//!
//! The host-only closed loop (`verdict::host_only_on`: the same scenario, core and plant as
//! `paragyro-fil`'s, with the board's two frequency steps per sample) is run with its pump
//! rounded to a grid of words ([`WordGrid`]) and without, on the same noise seed; the rate's
//! difference over the last [`ERR_SPAN_S`] (a constant truth there) is what the words add.
//! Grids: the board's AD9959, its 10-bit amplitude and its 0.058 Hz pump word (125 MHz
//! SYSCLK), and others (12 and 14 bits; a 500 MHz SYSCLK's 0.233 Hz word, the board's
//! before, and a 31.25 MHz one), with the core's pump-scale dither on (the configuration's)
//! and off. For the first seed it also gives where in frequency the
//! difference lies, in 25 Hz bands, for the rate and for the drive's lock-in amplitude |x1|.
//! Defaults: `rate-step`, seeds 1 2 3. Prints Markdown.

use paragyro_fil::session::BoardPump;
use paragyro_fil::verdict::{ERR_SPAN_S, LoopNumbers, WordGrid, host_only_on};

/// A grid's row: its name, its words, and whether the core's pump-scale dither runs.
struct Variant {
    name: &'static str,
    grid: WordGrid,
    scale_dither: bool,
}

fn grid(amplitude_bits: Option<u32>, frequency_sysclk_mhz: Option<f64>) -> WordGrid {
    WordGrid {
        amplitude_bits,
        frequency_sysclk_hz: frequency_sysclk_mhz.map(|f| f * 1e6),
    }
}

fn variants() -> Vec<Variant> {
    let v = |name, grid, scale_dither| Variant {
        name,
        grid,
        scale_dither,
    };
    vec![
        v(
            "board: amplitude 10 bit + frequency 125 MHz",
            grid(Some(10), Some(125.0)),
            true,
        ),
        v(
            "amplitude 10 bit + frequency 500 MHz",
            grid(Some(10), Some(500.0)),
            true,
        ),
        v("amplitude 10 bit (the board's)", grid(Some(10), None), true),
        v("amplitude 12 bit", grid(Some(12), None), true),
        v("amplitude 14 bit", grid(Some(14), None), true),
        v("frequency 500 MHz", grid(None, Some(500.0)), true),
        v(
            "frequency 125 MHz (the board's)",
            grid(None, Some(125.0)),
            true,
        ),
        v("frequency 31.25 MHz", grid(None, Some(31.25)), true),
        v(
            "board words, scale dither off",
            grid(Some(10), Some(125.0)),
            false,
        ),
        v(
            "amplitude 10 bit + frequency 500 MHz, scale dither off",
            grid(Some(10), Some(500.0)),
            false,
        ),
    ]
}

/// The last [`ERR_SPAN_S`] of a run, in samples.
fn tail(n: usize, fs_hz: f64) -> std::ops::Range<usize> {
    let len = (ERR_SPAN_S * fs_hz).round() as usize;
    n.saturating_sub(len)..n
}

/// Mean and rms about it of `a − b` over `span`.
fn diff_stats(a: &[f64], b: &[f64], span: std::ops::Range<usize>) -> (f64, f64) {
    let d: Vec<f64> = span.map(|k| a[k] - b[k]).collect();
    let m = d.iter().sum::<f64>() / d.len() as f64;
    let r = (d.iter().map(|x| (x - m).powi(2)).sum::<f64>() / d.len() as f64).sqrt();
    (m, r)
}

/// The rms of `a − b` over `span` in 25 Hz bands from 0 to `fs/2` (one-sided periodogram).
fn bands(a: &[f64], b: &[f64], span: std::ops::Range<usize>, fs_hz: f64) -> Vec<f64> {
    let d: Vec<f64> = span.map(|k| a[k] - b[k]).collect();
    let n = d.len();
    let m = d.iter().sum::<f64>() / n as f64;
    let df = fs_hz / n as f64;
    let nb = (fs_hz / 2.0 / 25.0).round() as usize;
    let mut out = vec![0.0; nb];
    for bin in 1..n / 2 {
        let w = 2.0 * std::f64::consts::PI * bin as f64 / n as f64;
        let (mut re, mut im) = (0.0, 0.0);
        for (i, x) in d.iter().enumerate() {
            let (s, c) = (w * i as f64).sin_cos();
            re += (x - m) * c;
            im += (x - m) * s;
        }
        let band = ((bin as f64 * df) / 25.0) as usize;
        if let Some(o) = out.get_mut(band) {
            *o += 2.0 * (re * re + im * im) / (n * n) as f64;
        }
    }
    out.iter().map(|p| p.sqrt()).collect()
}

fn run(
    ls: &paragyro_fil::LoopScenario,
    seed: u64,
    g: WordGrid,
    scale_dither: bool,
) -> anyhow::Result<LoopNumbers> {
    let mut sc = ls.scenario.clone();
    if !scale_dither {
        sc.estimator.dither_scale_frac = 0.0;
    }
    host_only_on(&sc, seed, BoardPump::HalfSteps, None, g)
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let name = args.first().map_or("rate-step", String::as_str);
    let seeds: Vec<u64> = if args.len() > 1 {
        args[1..]
            .iter()
            .map(|s| s.parse().map_err(|e| anyhow::anyhow!("seed {s:?}: {e}")))
            .collect::<anyhow::Result<_>>()?
    } else {
        vec![1, 2, 3]
    };
    let ls = paragyro_fil::by_name(name)?;
    let fs =
        paragyro_fil::session::core_config(&ls.scenario, BoardPump::HalfSteps.core_profile()).fs_hz;
    let vs = variants();
    // per variant, per seed: (mean, rms) of the difference
    let mut table = vec![Vec::new(); vs.len()];
    let mut host = Vec::new();
    let mut spectra: Vec<(&str, Vec<f64>, Vec<f64>)> = Vec::new();
    for (si, &seed) in seeds.iter().enumerate() {
        eprintln!("seed {seed}: references");
        let reference = [
            run(&ls, seed, WordGrid::default(), true)?,
            run(&ls, seed, WordGrid::default(), false)?,
        ];
        host.push(
            reference
                .iter()
                .map(|r| r.rate_error.map_or(f64::NAN, |e| e.rms_dps))
                .collect::<Vec<_>>(),
        );
        for (vi, v) in vs.iter().enumerate() {
            eprintln!("seed {seed}: {}", v.name);
            let r = run(&ls, seed, v.grid, v.scale_dither)?;
            let base = &reference[usize::from(!v.scale_dither)];
            anyhow::ensure!(
                r.rates.len() == base.rates.len(),
                "{}: {} samples against {}",
                v.name,
                r.rates.len(),
                base.rates.len()
            );
            let span = tail(r.rates.len(), fs);
            table[vi].push(diff_stats(&r.rates, &base.rates, span.clone()));
            if si == 0 && matches!(vi, 0 | 1 | 2 | 5 | 6) {
                spectra.push((
                    v.name,
                    bands(&r.rates, &base.rates, span.clone(), fs),
                    bands(&r.drive_amps, &base.drive_amps, span, fs),
                ));
            }
        }
    }
    println!(
        "# What the DDS's words add to the fast rate (`{name}`, host-only loop, last {ERR_SPAN_S} s)\n"
    );
    println!(
        "The host-only loop's own rate error (rms against the truth), seeds {seeds:?}: scale dither on {}, off {} °/s.\n",
        host.iter()
            .map(|h| format!("{:.3}", h[0]))
            .collect::<Vec<_>>()
            .join(" / "),
        host.iter()
            .map(|h| format!("{:.3}", h[1]))
            .collect::<Vec<_>>()
            .join(" / ")
    );
    let seed_cols: String = seeds.iter().map(|s| format!(" seed {s} |")).collect();
    println!("| words | rms of the rate's difference, °/s:{seed_cols} mean difference, °/s |");
    println!(
        "|---|{}---|",
        seeds.iter().map(|_| "---|").collect::<String>()
    );
    for (v, row) in vs.iter().zip(&table) {
        let rms: String = row.iter().map(|(_, r)| format!(" {r:.3} |")).collect();
        let means = row
            .iter()
            .map(|(m, _)| format!("{m:+.3}"))
            .collect::<Vec<_>>()
            .join(" / ");
        println!("| {} |{rms} {means} |", v.name);
    }
    if let Some(seed) = seeds.first() {
        println!(
            "\nWhere the difference lies, seed {seed}: rms per 25 Hz band (0–25, 25–50, … Hz)\n"
        );
        let hdr: String = (0..(fs / 50.0).round() as usize)
            .map(|b| format!(" {}–{} |", 25 * b, 25 * (b + 1)))
            .collect();
        println!("| words, signal |{hdr}");
        println!(
            "|---|{}",
            (0..(fs / 50.0).round() as usize)
                .map(|_| "---|")
                .collect::<String>()
        );
        for (n, rate, amp) in &spectra {
            let r: String = rate.iter().map(|x| format!(" {x:.3} |")).collect();
            let a: String = amp.iter().map(|x| format!(" {:.2} |", x * 1e3)).collect();
            println!("| {n}, rate °/s |{r}");
            println!("| {n}, drive \\|x1\\| nm |{a}");
        }
    }
    Ok(())
}
