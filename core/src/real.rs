//! The scalar type of the estimator: `f32` on the chip, `f64` on the host.
//!
//! The same generic code is instantiated in both precisions so the simulator can run
//! them side by side. Transcendentals go through `libm`, so the host and the
//! Cortex-M4F compute bit-identical `f32` results (std's inherent `f32::sqrt` would
//! otherwise shadow a `no_std` implementation on the host, TOOLCHAIN.md pitfall 1).

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// The FPU's square root on a hard-float Arm core (the Cortex-M4F): VSQRT.F32 is IEEE 754
/// correctly rounded, as `libm::sqrtf` is, so the chip and the host keep bit-identical
/// results; `libm` has no Arm path and its software `sqrtf` costs ≈ 480 B of flash (code
/// and table, `llvm-nm -S` on the image) and ≈ 29 instructions a tick on average (`cargo
/// fw-loop`). A two-instruction function, not inline `asm!`: the
/// `sreg` operands need the `vfp2` target feature, which stable Rust does not let the crate
/// enable (the thumbv7em-none-eabihf target has the FPU, its assembler takes the instruction).
#[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
#[allow(unsafe_code)] // the crate's only unsafe: `lib.rs` denies it everywhere else
mod vsqrt {
    core::arch::global_asm!(
        ".section .text.paragyro_vsqrtf,\"ax\",%progbits",
        ".global paragyro_vsqrtf",
        ".type paragyro_vsqrtf,%function",
        ".fpu fpv4-sp-d16",
        ".thumb_func",
        "paragyro_vsqrtf:",
        "vsqrt.f32 s0, s0",
        "bx lr",
        ".size paragyro_vsqrtf, . - paragyro_vsqrtf",
    );
    // SAFETY: the function above reads s0 and writes s0, as the AAPCS-VFP `extern "C"`
    // call of an `f32 -> f32` function expects, and touches no memory: safe for any `x`.
    unsafe extern "C" {
        /// √x in s0 → s0 (AAPCS-VFP).
        pub safe fn paragyro_vsqrtf(x: f32) -> f32;
    }
}

/// A real floating-point scalar (`f32` or `f64`).
pub trait Real:
    Copy
    + Default
    + PartialOrd
    + Debug
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + DivAssign
    + 'static
{
    /// 0
    const ZERO: Self;
    /// 1
    const ONE: Self;
    /// Largest finite value.
    const MAX: Self;
    /// Short name for reports ("f32" / "f64").
    const NAME: &'static str;
    /// Conversion from `f64` (rounds for `f32`).
    fn from_f64(v: f64) -> Self;
    /// Conversion to `f64` (exact).
    fn to_f64(self) -> f64;
    /// `from_f64(a − b)`, the same value; for `f32`, where `a` and `b` share a sign and a
    /// binade (the pump against its reference), from the bits with integer operations
    /// (on the chip the double subtraction and conversion are ≈ 120 instructions of soft
    /// float).
    #[inline]
    fn from_f64_diff(a: f64, b: f64) -> Self {
        Self::from_f64(a - b)
    }
    /// `c + o.to_f64()`, the same double; for `f32`, where `o`'s bits lie on `c`'s grid
    /// (the pump's dither on its centre), from the bits with integer operations (on the
    /// chip the widening and the double addition are ≈ 110 instructions of soft float).
    #[inline]
    fn add_to_f64(c: f64, o: Self) -> f64 {
        c + o.to_f64()
    }
    /// Square root (libm).
    fn sqrt(self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// Neither NaN nor infinite.
    fn is_finite(self) -> bool;
    /// `self < o` for two values that are `+0.0`, positive or `+∞` (not NaN, not
    /// negative), compared as integers: their bit patterns order as their values, and
    /// the chip's float comparison needs a status transfer besides the compare.
    fn lt_nonneg(self, o: Self) -> bool;
    /// Sine (libm).
    fn sin(self) -> Self;
    /// Cosine (libm).
    fn cos(self) -> Self;
    /// The larger of two values (NaN-free inputs).
    #[inline]
    fn max(self, o: Self) -> Self {
        if self > o { self } else { o }
    }
    /// The smaller of two values (NaN-free inputs).
    #[inline]
    fn min(self, o: Self) -> Self {
        if self < o { self } else { o }
    }
    /// (cos a, sin a) in `f64` of a design-time angle (|a| < 1e6) for a design in this
    /// precision. `f64`: libm, as always. `f32`: a compact evaluation (fdlibm's kernels
    /// after a two-part π/2 reduction, within ~1 `f64` ulp), which rounds to the same
    /// `f32` design as libm (tested) without linking libm's `f64` trigonometry (≈ 6.5 KB
    /// with its large-argument reduction) into the firmware.
    fn design_cos_sin_f64(a: f64) -> (f64, f64);
    /// e^x in `f64` for a design in this precision (as `design_cos_sin_f64`: libm for
    /// `f64`, a compact evaluation for `f32` that rounds to the same `f32` design).
    fn design_exp_f64(x: f64) -> f64;
    /// [`Real::design_cos_sin_f64`] rounded to `Self`.
    #[inline]
    fn design_cos_sin(a: f64) -> (Self, Self) {
        let (c, s) = Self::design_cos_sin_f64(a);
        (Self::from_f64(c), Self::from_f64(s))
    }
    /// The raised-cosine weight `0.5 − 0.5·cos(πx)` for `x` in [0, 1] (ramps, tapers).
    /// `f64`: with libm's `cos`, as always; `f32`: `sin²(πx/2)` by its series in `f32`
    /// (within a few `f32` ulps; libm's `cosf` evaluates in `f64`, soft-float on the M4F).
    fn half_cos(x: Self) -> Self;
    /// `num / den` in `Self` (`den` > 0; counts below 2²⁴ are exact in `f32`).
    fn ratio(num: u64, den: u64) -> Self;
}

/// `(a − b) as f32` for two normal doubles with the same sign and exponent, `None`
/// otherwise. Their difference is exact in `f64` (Sterbenz): `±(s_a − s_b)·2^(e − 1075)`
/// with `s` the significands' stored bits, here rounded to `f32` once, to nearest, ties
/// to even, as the conversion rounds it.
#[inline]
fn same_binade_diff_f32(a: f64, b: f64) -> Option<f32> {
    let (ba, bb) = (a.to_bits(), b.to_bits());
    let se = ba >> 52; // sign and biased exponent
    let e = (se & 0x7FF) as i32;
    if se != bb >> 52 || e == 0 || e == 0x7FF {
        return None;
    }
    let m = (1u64 << 52) - 1;
    let d = (ba & m) as i64 - (bb & m) as i64; // |d| < 2^52
    let neg = (d < 0) != (se >> 11 != 0);
    let u = d.unsigned_abs();
    if u == 0 {
        return Some(0.0);
    }
    // u·2^k, |u| < 2^52: to 24 bits, to nearest, ties to even
    let mut k = e - 1075;
    let n = 64 - u.leading_zeros() as i32;
    let q = if n > 24 {
        let s = (n - 24) as u32;
        let q = u >> s;
        let rem = u & ((1u64 << s) - 1);
        let half = 1u64 << (s - 1);
        k += s as i32;
        q + u64::from(rem > half || (rem == half && q & 1 == 1))
    } else {
        u
    };
    // q ≤ 2^24 is exact in f32, and 2^k a normal f32 scaling a normal result exactly
    if !(-126..=127 - 25).contains(&k) {
        return None;
    }
    let scale = f32::from_bits(((k + 127) as u32) << 23);
    let v = q as u32 as f32 * scale;
    Some(if neg { -v } else { v })
}

/// `c + o as f64` for a positive normal `c` and a normal `o` whose last bit lies on `c`'s
/// grid and whose size is below 2^51 of `c`'s units (half the bottom of `c`'s binade), or
/// `o` = ±0; `None` otherwise. The exact sum is then an
/// integer number of `c`'s units between 2^51 and 2^53 + 2^51: exact below 2^53, above it
/// one bit dropped, to nearest, ties to even, as the addition rounds it.
#[inline]
fn f32_on_grid_sum(c: f64, o: f32) -> Option<f64> {
    let bc = c.to_bits();
    let ec = (bc >> 52) as i32; // with the sign bit: a negative c is ≥ 2048
    if !(2..0x7FE).contains(&ec) {
        return None;
    }
    let bo = o.to_bits();
    if bo & 0x7FFF_FFFF == 0 {
        return Some(c);
    }
    let eo = ((bo >> 23) & 0xFF) as i32;
    // o = mo·2^(eo − 150), c = mc·2^(ec − 1075): o's unit in c's units is 2^sh
    let sh = (eo - 150) - (ec - 1075);
    if eo == 0 || eo == 0xFF || !(0..=27).contains(&sh) {
        return None;
    }
    let mo = i64::from((bo & 0x7F_FFFF) | 0x80_0000) << sh; // < 2^51
    let mc = ((bc & ((1 << 52) - 1)) | (1 << 52)) as i64;
    let m = if bo >> 31 != 0 { mc - mo } else { mc + mo };
    let (m, e) = if m >= 1 << 53 {
        // one bit dropped, exactly half a unit when set: up to even (m < 2^53 + 2^51, so
        // the rounded significand stays below 2^53)
        let r = m >> 1;
        (r + (m & r & 1), ec + 1)
    } else if m < 1 << 52 {
        (m << 1, ec - 1)
    } else {
        (m, ec)
    };
    Some(f64::from_bits(
        ((e as u64) << 52) | (m as u64 & ((1 << 52) - 1)),
    ))
}

/// e^x in `f64`: x = n·ln2 + r with a two-part ln2 (|r| ≤ ln2/2), a Taylor series of
/// e^r to r¹⁶ (truncation < 1e-17), scaled by 2ⁿ. Within a few `f64` ulps.
#[allow(clippy::excessive_precision)] // fdlibm's constants, as published
fn exp_f64(x: f64) -> f64 {
    const LN2_HI: f64 = 6.931_471_803_691_238_164_90e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_700_02e-10;
    if x.is_nan() {
        return x;
    }
    if x > 709.0 {
        return f64::INFINITY;
    }
    if x < -745.0 {
        return 0.0;
    }
    let n = libm::round(x * core::f64::consts::LOG2_E);
    let r = (x - n * LN2_HI) - n * LN2_LO;
    let mut sum = 1.0;
    let mut term = 1.0;
    for k in 1..=16 {
        term *= r / k as f64;
        sum += term;
    }
    // 2ⁿ in two steps (n down to −1075 would underflow a single power)
    let n = n as i64;
    let (n1, n2) = (n / 2, n - n / 2);
    let p = |m: i64| f64::from_bits(((m + 1023) as u64) << 52);
    sum * p(n1) * p(n2)
}

/// (cos x, sin x) in `f64` for moderate |x| (< 1e6): x = nπ/2 + r with a two-part π/2,
/// then fdlibm's `__kernel_cos`/`__kernel_sin` polynomials on |r| ≤ π/4.
#[allow(clippy::excessive_precision)] // fdlibm's constants, as published
pub(crate) fn cos_sin_f64(x: f64) -> (f64, f64) {
    const PIO2_HI: f64 = 1.570_796_326_734_125_614_17e0;
    const PIO2_LO: f64 = 6.077_100_506_506_192_249_32e-11;
    const S: [f64; 6] = [
        -1.666_666_666_666_663_243_48e-1,
        8.333_333_333_322_489_461_24e-3,
        -1.984_126_982_985_794_931_34e-4,
        2.755_731_370_707_006_767_89e-6,
        -2.505_076_025_340_686_341_95e-8,
        1.589_690_995_211_550_102_21e-10,
    ];
    const C: [f64; 6] = [
        4.166_666_666_666_660_190_37e-2,
        -1.388_888_888_887_410_957_49e-3,
        2.480_158_728_947_672_941_78e-5,
        -2.755_731_435_139_066_330_35e-7,
        2.087_572_321_298_174_827_90e-9,
        -1.135_964_755_778_819_482_65e-11,
    ];
    let n = libm::round(x * core::f64::consts::FRAC_2_PI);
    let r = (x - n * PIO2_HI) - n * PIO2_LO;
    let z = r * r;
    let ps = S[1] + z * (S[2] + z * (S[3] + z * (S[4] + z * S[5])));
    let sin_r = r + r * z * (S[0] + z * ps);
    let pc = C[0] + z * (C[1] + z * (C[2] + z * (C[3] + z * (C[4] + z * C[5]))));
    let hz = 0.5 * z;
    let w = 1.0 - hz;
    let cos_r = w + (((1.0 - w) - hz) + z * z * pc);
    match (n as i64) & 3 {
        0 => (cos_r, sin_r),
        1 => (-sin_r, cos_r),
        2 => (-cos_r, -sin_r),
        _ => (sin_r, -cos_r),
    }
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const MAX: Self = f32::MAX;
    const NAME: &'static str = "f32";
    #[inline]
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    #[inline]
    fn add_to_f64(c: f64, o: Self) -> f64 {
        // lazily: the double addition is what the bits avoid
        match f32_on_grid_sum(c, o) {
            Some(v) => v,
            None => c + o as f64,
        }
    }
    #[inline]
    fn from_f64_diff(a: f64, b: f64) -> Self {
        // lazily: the double subtraction is what the bits avoid
        match same_binade_diff_f32(a, b) {
            Some(v) => v,
            None => (a - b) as f32,
        }
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline]
    fn sqrt(self) -> Self {
        #[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
        {
            vsqrt::paragyro_vsqrtf(self)
        }
        #[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
        libm::sqrtf(self)
    }
    #[inline]
    fn abs(self) -> Self {
        libm::fabsf(self)
    }
    #[inline]
    fn is_finite(self) -> bool {
        // one float comparison: `f32::is_finite` became integer class tests on the chip
        // (≈ 70 instructions a firmware tick, `cargo fw-loop`); the same answer (test)
        libm::fabsf(self) <= f32::MAX
    }
    #[inline]
    fn lt_nonneg(self, o: Self) -> bool {
        self.to_bits() < o.to_bits()
    }
    #[inline]
    fn sin(self) -> Self {
        libm::sinf(self)
    }
    #[inline]
    fn cos(self) -> Self {
        libm::cosf(self)
    }
    fn design_cos_sin_f64(a: f64) -> (f64, f64) {
        cos_sin_f64(a)
    }
    fn design_exp_f64(x: f64) -> f64 {
        exp_f64(x)
    }
    #[inline]
    fn half_cos(x: Self) -> Self {
        // exact at the ends (and for x outside [0, 1], NaN → 0)
        if x >= 1.0 {
            return 1.0;
        }
        let x = if x > 0.0 { x } else { 0.0 };
        // sin(t), t = πx/2 in [0, π/2]: Taylor series to t¹⁵ (truncation < 1e-9)
        let t = core::f32::consts::FRAC_PI_2 * x;
        let z = t * t;
        let p = 1.0 / 1_307_674_368_000.0;
        let p = p * z - 1.0 / 6_227_020_800.0;
        let p = p * z + 1.0 / 39_916_800.0;
        let p = p * z - 1.0 / 362_880.0;
        let p = p * z + 1.0 / 5_040.0;
        let p = p * z - 1.0 / 120.0;
        let p = p * z + 1.0 / 6.0;
        let s = t - t * z * p;
        s * s
    }
    #[inline]
    fn ratio(num: u64, den: u64) -> Self {
        match (u32::try_from(num), u32::try_from(den)) {
            (Ok(n), Ok(d)) => n as f32 / d as f32,
            _ => (num as f64 / den as f64) as f32,
        }
    }
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const MAX: Self = f64::MAX;
    const NAME: &'static str = "f64";
    #[inline]
    fn from_f64(v: f64) -> Self {
        v
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn sqrt(self) -> Self {
        libm::sqrt(self)
    }
    #[inline]
    fn abs(self) -> Self {
        libm::fabs(self)
    }
    #[inline]
    fn is_finite(self) -> bool {
        f64::is_finite(self)
    }
    #[inline]
    fn lt_nonneg(self, o: Self) -> bool {
        self.to_bits() < o.to_bits()
    }
    #[inline]
    fn sin(self) -> Self {
        libm::sin(self)
    }
    #[inline]
    fn cos(self) -> Self {
        libm::cos(self)
    }
    fn design_cos_sin_f64(a: f64) -> (f64, f64) {
        (libm::cos(a), libm::sin(a))
    }
    fn design_exp_f64(x: f64) -> f64 {
        libm::exp(x)
    }
    #[inline]
    fn half_cos(x: Self) -> Self {
        0.5 - 0.5 * libm::cos(core::f64::consts::PI * x)
    }
    #[inline]
    fn ratio(num: u64, den: u64) -> Self {
        num as f64 / den as f64
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// The next state of a xorshift generator (the tests' random bits).
    fn xorshift(x: &mut u64) -> u64 {
        *x ^= *x << 13;
        *x ^= *x >> 7;
        *x ^= *x << 17;
        *x
    }

    /// `f32::add_to_f64(c, o)` is `c + o as f64` bit for bit: dithers on pump centres, and
    /// random doubles and floats of every exponent and sign.
    #[test]
    fn the_f32_sum_on_the_grid_is_the_rounded_double_sum() {
        let mut x = 0x2545_F491_4F6C_DD1Du64;
        let mut next = || xorshift(&mut x);
        let mut pairs = std::vec![
            (21_883.952_6, 0.0f32),
            (21_883.952_6, -0.0),
            (21_883.952_6, f32::NAN),
            (21_883.952_6, f32::INFINITY),
            (21_883.952_6, 1e-40),
            (1.0, -0.75),
            (1.0, 0.999_999_9),
            (f64::MAX, 1e38),
            (f64::MIN_POSITIVE, 1e-30),
            (-3.0, 1.0),
        ];
        for _ in 0..300_000 {
            let r = next();
            let centre = 16_000.0 + (r >> 40) as f64 / 1024.0;
            let dither = ((next() >> 40) as f32 / (1u32 << 24) as f32 - 0.5) * 60.0;
            pairs.push((centre, dither));
            let c = f64::from_bits(next() >> 1);
            let o = f32::from_bits(next() as u32);
            pairs.push((c, o));
            // an o near c's scale and grid: the carries and ties
            let c = 1.0 + (next() >> 12) as f64 / (1u64 << 52) as f64;
            let o = (((next() >> 40) as f32) / (1u32 << 24) as f32 - 0.5) * 0.5;
            pairs.push((
                c * 2f64.powi((r % 64) as i32 - 32),
                o * 2f32.powi((r % 64) as i32 - 32),
            ));
        }
        for (c, o) in pairs {
            let got = <f32 as Real>::add_to_f64(c, o);
            let want = c + o as f64;
            assert!(
                got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                "{c:e} + {o:e}: {got:e} against {want:e}"
            );
        }
    }

    /// `f32::from_f64_diff(a, b)` is `(a − b) as f32` bit for bit: pumps within ±100 Hz of
    /// a reference, random doubles of one binade (either sign), and the other cases.
    #[test]
    fn the_f32_difference_from_the_bits_is_the_rounded_double_difference() {
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || xorshift(&mut x);
        let mut pairs = std::vec![
            (21_883.952_6, 21_883.952_6),
            (0.0, 0.0),
            (-0.0, 0.0),
            (1.0, f64::NAN),
            (f64::INFINITY, 1.0),
            (3.0, 1.5),
            (f64::MIN_POSITIVE, 5e-324),
            (1e300, -1e300),
        ];
        for _ in 0..300_000 {
            let r = next();
            let reference = 21_000.0 + (r >> 40) as f64 / 16.0;
            let off = ((next() >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 200.0;
            pairs.push((reference + off, reference));
            let (a, b) = (next(), next());
            // the same sign and exponent, random significands
            let b = (a & !((1u64 << 52) - 1)) | (b & ((1u64 << 52) - 1));
            pairs.push((f64::from_bits(a), f64::from_bits(b)));
        }
        for (a, b) in pairs {
            let got = <f32 as Real>::from_f64_diff(a, b);
            let want = (a - b) as f32;
            assert!(
                got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                "{a:e} − {b:e}: {got:e} against {want:e}"
            );
        }
    }

    #[test]
    fn f32_is_finite_equals_the_std_test() {
        let mut v = std::vec![
            0.0f32,
            -0.0,
            f32::MIN_POSITIVE,
            f32::from_bits(1),
            1.0,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
            f32::from_bits(0x7FC0_0001),
            f32::from_bits(0xFF80_0001),
        ];
        v.extend((0..1000u32).map(|i| f32::from_bits(i.wrapping_mul(0x9E37_79B9))));
        for x in v {
            assert_eq!(
                Real::is_finite(x),
                f32::is_finite(x),
                "{x:e} ({:#x})",
                x.to_bits()
            );
        }
    }

    #[test]
    fn lt_nonneg_is_less_than_on_non_negative_values() {
        let v64 = [
            0.0,
            f64::from_bits(1),
            f64::MIN_POSITIVE,
            1e-30,
            1e-30 * (1.0 + f64::EPSILON),
            0.5,
            1.0,
            3.0e38,
            f64::MAX,
            f64::INFINITY,
        ];
        for &a in &v64 {
            for &b in &v64 {
                assert_eq!(a.lt_nonneg(b), a < b, "{a:e} < {b:e} (f64)");
                let (a, b) = (a as f32, b as f32);
                assert_eq!(a.lt_nonneg(b), a < b, "{a:e} < {b:e} (f32)");
            }
        }
    }

    #[test]
    fn compact_design_trig_rounds_like_libm() {
        // every design angle of the core (synthesis tables, Butterworth poles, dither
        // rotations) and a dense sweep: the f32 design equals libm's rounded to f32
        let mut n = 0;
        let mut worst: f64 = 0.0;
        for i in -200_000..=200_000 {
            let a = i as f64 * 1e-4;
            let (c, s) = cos_sin_f64(a);
            worst = worst
                .max((c - libm::cos(a)).abs())
                .max((s - libm::sin(a)).abs());
            if c as f32 != libm::cos(a) as f32 || s as f32 != libm::sin(a) as f32 {
                n += 1;
            }
        }
        assert!(worst < 4.5e-16, "f64 error {worst}");
        assert_eq!(n, 0, "{n} angles round differently");
        for j in 0..32 {
            for m in 1..=3 {
                let a = m as f64 * 2.0 * core::f64::consts::PI * j as f64 / 32.0;
                assert_eq!(
                    f32::design_cos_sin(a),
                    (libm::cos(a) as f32, libm::sin(a) as f32)
                );
            }
        }
        for order in 1..=8usize {
            for k in 1..=order / 2 {
                let a = core::f64::consts::PI * (2 * k - 1) as f64 / (2 * order) as f64;
                assert_eq!(f32::design_cos_sin_f64(a).1 as f32, libm::sin(a) as f32);
            }
        }
    }

    #[test]
    fn compact_design_exp_rounds_like_libm() {
        let mut worst: f64 = 0.0;
        for i in -100_000..=100_000 {
            let x = i as f64 * 1e-4;
            let e = exp_f64(x);
            worst = worst.max(((e - libm::exp(x)) / libm::exp(x)).abs());
            assert_eq!(e as f32, libm::exp(x) as f32, "x = {x}");
        }
        assert!(worst < 1e-15, "{worst}");
        // the SVF corners 2π·svf_hz/fs_hz up to the largest allowed, fs/10
        for i in 1..=1000 {
            let h = -2.0 * core::f64::consts::PI * (i as f64 / 10_000.0);
            assert_eq!(exp_f64(h) as f32, libm::exp(h) as f32);
        }
        assert_eq!(exp_f64(0.0), 1.0);
        assert_eq!(exp_f64(-800.0), 0.0);
        assert!(exp_f64(800.0).is_infinite() && exp_f64(f64::NAN).is_nan());
        assert!((exp_f64(-700.0) / libm::exp(-700.0) - 1.0).abs() < 1e-14);
    }

    #[test]
    fn half_cos_f32_is_the_raised_cosine() {
        let mut worst: f64 = 0.0;
        for i in 0..=10_000u64 {
            let x = f32::ratio(i, 10_000);
            let want = f64::half_cos(x as f64);
            worst = worst.max((f32::half_cos(x) as f64 - want).abs());
        }
        assert!(worst < 2e-7, "{worst}");
        assert_eq!(f32::half_cos(0.0), 0.0);
        assert_eq!(f32::half_cos(1.0), 1.0);
        assert_eq!(f32::half_cos(-1.0), 0.0);
        assert_eq!(f32::half_cos(2.0), 1.0);
        assert_eq!(f64::ratio(1, 3), 1.0 / 3.0);
    }
}
