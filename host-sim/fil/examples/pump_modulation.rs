//! How the fast rate reads a pump-scale modulation the core is told exactly.
//!
//! ```text
//! cargo run --release -p paragyro-fil --example pump_modulation -- [SEED [LOCKIN_ORDER]]
//! ```
//!
//! The host-only closed loop of `rate-step` (the boards' two frequency steps per sample,
//! noise-free) with the plant's pump scale and the sample's reported scale both multiplied
//! by `1 + 1e-3·sin(2π f_m t)` (held over each interval: the board's amplitude is one step
//! per sample), against the same run without. Told exactly, the modulation is known to the
//! core, so an exact estimator's rate would not move. Printed: the rate's difference over
//! the last 2 s, its amplitude at `f_m` and its rms, at the boards' 500 Hz samples and, as
//! a probe of the sampling, with the core and the plant at 1 000 Hz (not a validated
//! configuration: the other settings are the 500 Hz ones). `LOCKIN_ORDER` (default: the
//! scenario's, 4) sets the lock-in low-pass's order in the plant and the core alike: a
//! higher order folds less of what lies above 250 Hz into the band. Prints Markdown.

use paragyro_core::Estimator;
use paragyro_fil::session::{BoardPump, core_config};
use paragyro_simulator::{plant::PlantInputs, runner};

/// Relative amplitude of the modulation.
const AMP: f64 = 1e-3;

/// The hooks: the plant's scale and the reported one modulated alike.
struct Modulate {
    fm_hz: f64,
    fs_hz: f64,
}

impl runner::LoopHooks<f32> for Modulate {
    fn inputs(
        &mut self,
        k: u64,
        _u0: &mut PlantInputs,
        u1: &mut PlantInputs,
        next: &mut (f64, f64),
    ) {
        if self.fm_hz > 0.0 && next.1 > 0.0 {
            let t = (k + 1) as f64 / self.fs_hz;
            let f = 1.0 + AMP * (2.0 * std::f64::consts::PI * self.fm_hz * t).sin();
            u1.s *= f;
            next.1 *= f;
        }
    }
}

/// The fast rate of every sample of `rate-step`, noise-free, at `fs_hz`, modulated at `fm_hz`
/// (0: not).
fn run(seed: u64, fm_hz: f64, fs_hz: f64, order: Option<usize>) -> anyhow::Result<Vec<f64>> {
    let mut sc = paragyro_fil::rate_step()?.scenario;
    sc.sim.noise_pm_rthz = 0.0;
    if let Some(o) = order {
        sc.sim.lockin_lpf_order = o;
    }
    let pump = BoardPump::HalfSteps;
    sc.sim.pump_profile = pump.sim_profile();
    let mut cfg = core_config(&sc, pump.core_profile());
    cfg.fs_hz = fs_hz;
    let mut est: Estimator<f32> = cfg
        .build()
        .map_err(|e| anyhow::anyhow!("core configuration at {fs_hz} Hz: {e}"))?;
    let mut hooks = Modulate { fm_hz, fs_hz };
    let mut rates = Vec::new();
    runner::closed_loop_hooked(
        &sc,
        seed,
        &runner::Device::default(),
        &mut est,
        &mut hooks,
        |_| {},
        |ls| rates.push(ls.out.rate.rate_dps),
    )?;
    Ok(rates)
}

/// Amplitude at `fm_hz` and rms of `a − b` over the last 2 s.
fn response(a: &[f64], b: &[f64], fm_hz: f64, fs_hz: f64) -> (f64, f64) {
    let m = (2.0 * fs_hz) as usize;
    let n = a.len().min(b.len());
    let (mut c, mut s, mut p) = (0.0, 0.0, 0.0);
    for k in n - m..n {
        let d = a[k] - b[k];
        let w = 2.0 * std::f64::consts::PI * fm_hz * (k + 1) as f64 / fs_hz;
        c += d * w.cos();
        s += d * w.sin();
        p += d * d;
    }
    (2.0 * c.hypot(s) / m as f64, (p / m as f64).sqrt())
}

fn main() -> anyhow::Result<()> {
    let arg = |i: usize| std::env::args().nth(i);
    let seed: u64 = match arg(1) {
        Some(s) => s.parse().map_err(|e| anyhow::anyhow!("seed {s:?}: {e}"))?,
        None => 1,
    };
    let order: Option<usize> = match arg(2) {
        Some(s) => Some(
            s.parse()
                .map_err(|e| anyhow::anyhow!("lock-in order {s:?}: {e}"))?,
        ),
        None => None,
    };
    let fms = [10.0, 30.0, 60.0, 80.0, 100.0, 150.0];
    let rates = [500.0, 1000.0];
    let mut rows = vec![Vec::new(); fms.len()];
    for fs in rates {
        eprintln!("{fs} Hz: reference");
        let base = run(seed, 0.0, fs, order)?;
        for (i, fm) in fms.iter().enumerate() {
            eprintln!("{fs} Hz: f_m = {fm} Hz");
            let r = run(seed, *fm, fs, order)?;
            rows[i].push(response(&r, &base, *fm, fs));
        }
    }
    println!(
        "# The fast rate under a told pump-scale modulation of {AMP} (`rate-step`, seed {seed}, noise-free, lock-in order {}, last 2 s)\n",
        order.map_or("of the scenario".to_string(), |o| o.to_string())
    );
    println!(
        "| f_m, Hz | 500 Hz: rate at f_m, °/s | 500 Hz: rms, °/s | 1 000 Hz: rate at f_m, °/s | 1 000 Hz: rms, °/s |"
    );
    println!("|---|---|---|---|---|");
    for (fm, row) in fms.iter().zip(&rows) {
        println!(
            "| {fm} | {:.4} | {:.4} | {:.4} | {:.4} |",
            row[0].0, row[0].1, row[1].0, row[1].1
        );
    }
    Ok(())
}
