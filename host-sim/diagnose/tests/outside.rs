//! The diagnosis on effects outside its library and outside its span (`blind::outside`,
//! through the plant hook): one toleranced device per type, at 10× the type's detection
//! limit, must read `unknown` (not `none`, not a library effect). Fixed seeds, not the
//! blind benchmark's scored ones (host-sim/diagnose/blind-benchmark.md).

use paragyro_diagnose::blind::device::DeviceDraw;
use paragyro_diagnose::blind::outside::Outside;
use paragyro_diagnose::diagnose::{Answer, Options, diagnose};
use paragyro_simulator::record::{RecordOptions, simulate_record_ext};
use paragyro_simulator::scenario::Scenario;
use rand::SeedableRng;

fn verdict_at_ten_times_the_limit(kind: Outside, seed: u64) -> Answer {
    let sc = Scenario::load("characterise").unwrap();
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed);
    let dev = DeviceDraw::draw(&mut rng);
    let size = 10.0 * kind.size_range().limit;
    let hook = kind.hook(size, dev.physical(&sc).wy2, sc.omega0_rad_s());
    let opts = RecordOptions {
        seed: Some(seed),
        rate_table: true,
        temp: Some((25.0, 4.0)),
        ..RecordOptions::default()
    };
    let (rec, _) = simulate_record_ext(&dev.apply(&sc), &opts, Some(hook), &mut |_| {}).unwrap();
    let r = diagnose(&rec, &Options::default()).unwrap().report;
    println!(
        "{kind} {size:e} (rate {:.0} °/s): {} (closest {}), residual/noise {:.2}, gap fraction {:.3}",
        dev.rate_dps,
        r.verdict,
        r.closest_library_effect,
        r.residual_over_noise,
        r.gap_fraction_of_baseline
    );
    r.verdict.answer()
}

#[test]
fn coulomb_friction_reads_unknown() {
    assert_eq!(
        verdict_at_ten_times_the_limit(Outside::CoulombFriction, 31),
        Answer::Unknown
    );
}

#[test]
fn spurious_mode_reads_unknown() {
    assert_eq!(
        verdict_at_ten_times_the_limit(Outside::SpuriousMode, 32),
        Answer::Unknown
    );
}

#[test]
fn charging_drift_reads_unknown() {
    assert_eq!(
        verdict_at_ten_times_the_limit(Outside::ChargingDrift, 33),
        Answer::Unknown
    );
}
