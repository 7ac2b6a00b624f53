//! The small blind run of CI on its fixed seed (toleranced devices, labels sealed before
//! the diagnoses): the build fails when it falls below the thresholds stated in
//! host-sim/diagnose/blind-benchmark.md (fixed before the scored run).
//!
//! The `unknown` share on out-of-library records is printed, not gated: the only
//! out-of-library type drawn, the quadratic stiffness, is a stiffness shift on a statically
//! deflected mass, which the calibration absorbs on a toleranced device (on this seed it
//! reads `none`); it cannot test `unknown` honestly, and the out-of-library types
//! outside the calibration's and the catch-all's span were not built (issue 11, not met).
//! This gate was dropped after the development run of this seed, before the scored run.

use paragyro_diagnose::blind;

#[test]
fn small_blind_run_meets_its_thresholds() {
    let dir = std::env::temp_dir().join(format!("paragyro-blind-ci-{}", std::process::id()));
    let sm = blind::run(8, 7, &dir, &|m| println!("{m}")).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    println!("{sm:#?}");
    let at_least = |v: Option<f64>, min: f64, what: &str| {
        if let Some(v) = v {
            assert!(v >= min, "{what}: {v} < {min}");
        }
    };
    // clean devices read `none`
    at_least(
        sm.false_alarms_on_clean.map(|f| 1.0 - f),
        0.9,
        "clean `none`",
    );
    at_least(sm.top1_single_above_limit, 0.9, "top-1 above the limit");
    println!(
        "unknown on out-of-library (not gated): {:?}",
        sm.unknown_on_outside
    );
    // every category of this seed is present
    assert!(
        sm.clean_records > 0 && sm.single_above_limit_records > 0,
        "{sm:?}"
    );
}
