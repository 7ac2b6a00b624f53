//! The small blind run of CI on its fixed seed (toleranced devices, labels sealed before
//! the diagnoses): the build fails when it falls below the thresholds stated in
//! host-sim/diagnose/blind-benchmark.md (fixed before the scored run).
//!
//! Gated: clean devices `none` ≥ 90 %, top-1 on single library effects above their limit
//! ≥ 90 %, and `unknown` ≥ 80 % on out-of-library records whose type lies outside the
//! diagnosis's span (`blind::outside`: Coulomb friction, a spurious mode, a charging drift,
//! added through the plant hook) and above its detection limit. Run 3 printed the last share
//! without gating it: its only out-of-library type, the quadratic stiffness, lies inside the
//! calibration's span. The in-span control (the pick-off lag) is printed, not gated.
//!
//! The run is left in `target/blind-ci/` (records, sealed labels, diagnoses, score.md and
//! score.json): `.ci/run` prints its score.

use std::path::PathBuf;

use paragyro_diagnose::blind;

/// `target/blind-ci` of the workspace (or of `CARGO_TARGET_DIR`), emptied first.
fn out_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../target")));
    let dir = target.join("blind-ci");
    std::fs::remove_dir_all(&dir).ok();
    dir
}

#[test]
fn small_blind_run_meets_its_thresholds() {
    let dir = out_dir();
    let sm = blind::run(8, 7, &dir, &|m| println!("{m}")).unwrap();
    println!("{sm:#?} ({})", dir.display());
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
    at_least(
        sm.unknown_on_outside_span_above_limit,
        0.8,
        "`unknown` on out-of-library records outside the span, above their limit",
    );
    println!(
        "unknown on every out-of-library record (not gated): {:?}",
        sm.unknown_on_outside
    );
    // every gated category of this seed is present
    assert!(
        sm.clean_records > 0
            && sm.single_above_limit_records > 0
            && sm.outside_span_above_limit_records > 0,
        "{sm:?}"
    );
}
