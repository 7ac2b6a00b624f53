//! Run-time dispatch of the simulator's hot loop to an AVX2 + FMA build.
//!
//! [`GyroSim::advance`](crate::plant::GyroSim::advance) (the RK4 steps and the lock-in's
//! running sums, `BlockLpf`) is compiled twice on x86-64: for the baseline target and with
//! `#[target_feature(enable = "avx2,fma")]`; it takes the second where the CPU has both
//! ([`avx2_fma`], detected once and cached). The two builds do the same `f64` operations
//! in the same order (Rust never contracts `a * b + c` into an FMA, and the vectorizer
//! does not reassociate floating-point sums), so a run is bit for bit the same on either:
//! `plant::tests::the_avx2_build_is_bit_for_bit_the_portable_one` holds them to it. The
//! wider vectors carry the lock-in's 14 channels × 4 running sums per RK4 step four at a
//! time instead of two (host-sim/docs/benchmarks.md).

/// Whether runs take the AVX2 + FMA build: on x86-64 where the CPU has both, unless the
/// environment sets `PARAGYRO_SIMD=off` (the portable build; for A/B timing and for checking
/// a result on the baseline code). Read once per process.
pub fn avx2_fma() -> bool {
    static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ON.get_or_init(|| {
        let off = std::env::var("PARAGYRO_SIMD").is_ok_and(|v| v.eq_ignore_ascii_case("off"));
        !off && cpu_has_avx2_fma()
    })
}

#[cfg(target_arch = "x86_64")]
fn cpu_has_avx2_fma() -> bool {
    std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
}

#[cfg(not(target_arch = "x86_64"))]
fn cpu_has_avx2_fma() -> bool {
    false
}
