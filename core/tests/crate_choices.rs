//! Why the core does not use `micromath` (core/docs/design-notes.md "The specified crates"): its `f32`
//! approximations are far coarser than what the estimator's decisions need. Measured here
//! on the one function the core calls on the chip every tick, the square root (|A1| of the
//! drive-lock check and the retune target 2·√ω̂y²):
//! `cargo test -p paragyro-core --test crate_choices -- --nocapture`.

use micromath::F32Ext;

/// (max, mean) relative error of micromath's `sqrt` against `libm::sqrtf` over 1e-6..1e6
/// (log-spaced), and the fraction of inputs where the two agree bit for bit.
fn sqrt_error() -> (f64, f64, f64) {
    let n = 100_000;
    let (mut max, mut sum, mut same) = (0.0f64, 0.0f64, 0usize);
    for i in 0..n {
        let x = 10f64.powf(-6.0 + 12.0 * i as f64 / (n - 1) as f64) as f32;
        let exact = libm::sqrtf(x);
        let approx = F32Ext::sqrt(x);
        let e = ((approx - exact) / exact).abs() as f64;
        max = max.max(e);
        sum += e;
        same += usize::from(approx.to_bits() == exact.to_bits());
    }
    (max, sum / n as f64, same as f64 / n as f64)
}

#[test]
fn micromath_sqrt_is_too_coarse_for_the_retune() {
    let (max, mean, same) = sqrt_error();
    println!(
        "micromath sqrt vs libm sqrtf over 1e-6..1e6: max relative error {:.2} %, mean {:.2} %, bit-identical on {:.2} % of inputs",
        100.0 * max,
        100.0 * mean,
        100.0 * same
    );
    // The retune target is 2·√ω̂y²·f0 ≈ 21.9 kHz and must land within a few Hz (the QEMU
    // check's tolerance is 3.7 Hz, i.e. 1.7e-4 relative): an approximation off by more than
    // that cannot be used there, and the firmware's output must stay bit for bit the host's.
    assert!(
        max > 1.7e-4,
        "micromath's sqrt is now accurate enough: revisit the choice"
    );
    assert!(same < 0.5);
}
