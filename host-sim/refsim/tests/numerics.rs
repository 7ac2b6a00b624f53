//! The integrator's tolerance: a drawn record (device, protocol, effect) at the default
//! tolerance against the same record at a much tighter one.

use paragyro_refsim::generate::draw;
use paragyro_refsim::sim::{FrontEnd, simulate};

fn run(duration_s: f64, rtol: f64, control_lockin: bool) -> (Vec<[f64; 14]>, u64, f64) {
    let d = &draw(1, 3, duration_s, 0.4)[0];
    let fe = FrontEnd {
        noise_pm_rthz: 0.0,
        rtol,
        control_lockin,
        ..FrontEnd::default()
    };
    let t = std::time::Instant::now();
    let s = simulate(&d.device.si(), &d.sizes(), &d.protocol, &fe).unwrap();
    let secs = t.elapsed().as_secs_f64();
    (
        s.rows.iter().map(|r| r.lockin_um).collect(),
        s.stats.accepted,
        secs,
    )
}

fn largest_difference(a: &[[f64; 14]], b: &[[f64; 14]]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| x.iter().zip(y).map(|(p, q)| (p - q).abs()))
        .fold(0.0f64, f64::max)
}

/// 0.5 s (the drive's build-up from 10 nm, the most sensitive part of a record): the
/// default tolerance is within 3e-6 µm of one 100× tighter that also controls the
/// lock-in's ladders (a quarter of one sample's noise at 1 pm/√Hz).
#[test]
fn the_default_tolerance_is_converged() {
    let (reference, _, _) = run(0.5, 1e-11, true);
    let (rows, _, _) = run(0.5, FrontEnd::default().rtol, false);
    let d = largest_difference(&rows, &reference);
    eprintln!("default tolerance: {d:.3e} µm from the reference");
    assert!(d < 3e-6, "{d:.3e} µm");
}

/// The numbers of the README (`cargo test -p paragyro-refsim --test numerics --
/// --ignored --nocapture`).
#[test]
#[ignore]
fn tolerance_scan() {
    let (reference, steps, secs) = run(1.0, 1e-11, true);
    eprintln!("reference rtol 1e-11 (ladders controlled): {steps} steps, {secs:.2} s");
    for rtol in [1e-7, 1e-8, 1e-9, 1e-10] {
        let (rows, steps, secs) = run(1.0, rtol, false);
        let d = largest_difference(&rows, &reference);
        eprintln!("rtol {rtol:e}: {steps} steps, {secs:.2} s, largest difference {d:.3e} µm");
    }
}
