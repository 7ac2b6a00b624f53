//! Doubles to DDS words with integer operations: on the chip an `as u32` cast of a double
//! is a library conversion plus two soft-float comparisons, and `x + 0.5` a soft-float
//! addition (≈ 100 instructions); the tick rounds the pump's word from the bits instead.

/// `y as u32` (saturating: NaN and negatives give 0, ≥ 2^32 gives `u32::MAX`) from the
/// bits, with integer operations only: `floor(y)` of a double in [1, 2^32) is its 53-bit
/// significand shifted right by `1075 − exponent` (on the chip the `as` cast is a library
/// conversion plus two soft-float comparisons).
pub(super) fn f64_as_u32(y: f64) -> u32 {
    let b = y.to_bits();
    if b >> 63 != 0 {
        return 0; // negative (→ 0 when > −1, saturated to 0 below) or a negative NaN
    }
    let exp = (b >> 52) as u32; // biased, sign bit clear
    if exp < 1023 {
        return 0; // [0, 1)
    }
    if exp >= 1023 + 32 {
        // ≥ 2^32 or ∞ → MAX; NaN → 0
        return if exp == 0x7FF && b & ((1 << 52) - 1) != 0 {
            0
        } else {
            u32::MAX
        };
    }
    let sig = (b & ((1 << 52) - 1)) | (1 << 52);
    // exp − 1023 ∈ [0, 31]: shift ∈ [21, 52]
    let shift = 1075u32.saturating_sub(exp);
    u32::try_from(sig.checked_shr(shift).unwrap_or(0)).unwrap_or(u32::MAX)
}

/// `f64_as_u32(x + 0.5)`, the nearest word (halves up), with integer operations on the
/// tick path: for `x` in [0.5, 2^32) the double sum `x + 0.5` rounds no bit that reaches
/// its integer part, so adding half a unit of the result to the significand and shifting
/// gives the same word (tested); anything else takes the double sum (one soft-float
/// addition ≈ 100 instructions on the chip).
pub(super) fn f64_round_u32(x: f64) -> u32 {
    let b = x.to_bits();
    let exp = (b >> 52) as u32; // with the sign bit: negatives are ≥ 2048
    if (1022..1023 + 32).contains(&exp) {
        let sig = (b & ((1 << 52) - 1)) | (1 << 52);
        // exp − 1023 ∈ [−1, 31]: shift ∈ [21, 53], and sig + 2^(shift−1) < 2^54
        let shift = 1075u32.wrapping_sub(exp);
        let half = 1u64.wrapping_shl(shift.wrapping_sub(1));
        let r = sig.wrapping_add(half).wrapping_shr(shift);
        return u32::try_from(r).unwrap_or(u32::MAX);
    }
    f64_as_u32(x + 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Doubles every conversion is probed at: the largest, the infinities, both NaNs, −½.
    const SPECIAL: [f64; 6] = [
        f64::MAX,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NAN,
        -f64::NAN,
        -0.5,
    ];

    /// The next xorshift state's bits as a double, and a double in [0, 2^32) from them.
    fn random_doubles(x: &mut u64) -> [f64; 2] {
        *x ^= *x << 13;
        *x ^= *x >> 7;
        *x ^= *x << 17;
        [f64::from_bits(*x), (*x >> 11) as f64 / (1u64 << 21) as f64]
    }

    /// `f64_as_u32` is the saturating `as u32` cast.
    #[test]
    fn f64_as_u32_equals_the_cast() {
        let mut probes = vec![
            0.0,
            -0.0,
            0.5,
            0.999_999_999,
            1.0,
            1.5,
            2.0,
            4_294_967_295.0,
            4_294_967_295.5,
            4_294_967_296.0,
            1e300,
            -1.0,
            -1e300,
            f64::MIN_POSITIVE,
            5e-324,
        ];
        probes.extend(SPECIAL);
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        for _ in 0..200_000 {
            probes.extend(random_doubles(&mut x));
        }
        for e in 0..=33 {
            let p = (1u64 << e) as f64;
            for b in [p.to_bits() - 1, p.to_bits(), p.to_bits() + 1] {
                probes.push(f64::from_bits(b));
            }
        }
        for y in probes {
            assert_eq!(f64_as_u32(y), y as u32, "{y:e} ({:#x})", y.to_bits());
        }
    }

    /// `f64_round_u32(x)` is `f64_as_u32(x + 0.5)` bit for bit: random doubles, words with
    /// random fractions, and the neighbours of every half and of every power of two up to
    /// 2^33.
    #[test]
    fn f64_round_u32_equals_the_double_sum() {
        let mut probes = vec![
            0.0,
            -0.0,
            0.5,
            0.499_999_999_999_999_94,
            0.5 + f64::EPSILON / 2.0,
            4_294_967_294.5,
            4_294_967_295.499_999,
            4_294_967_295.5,
            5e-324,
        ];
        probes.extend(SPECIAL);
        let mut x = 0x2545_F491_4F6C_DD1Du64;
        for _ in 0..200_000 {
            probes.extend(random_doubles(&mut x));
            // a pump's words: 2^25..2^27 with a random fraction, and near a half
            let w = ((x >> 37) | (1 << 25)) as f64;
            let h = (w + 0.5).to_bits();
            probes.extend([w + (x & 0xFFFF) as f64 / 65536.0, f64::from_bits(h - 1)]);
            probes.extend([f64::from_bits(h), f64::from_bits(h + 1)]);
        }
        for e in -2..=33 {
            let p = 2f64.powi(e);
            for b in [p.to_bits() - 1, p.to_bits(), p.to_bits() + 1] {
                let y = f64::from_bits(b);
                probes.extend([y, y - 0.5, y + 0.5]);
            }
        }
        for y in probes {
            assert_eq!(
                f64_round_u32(y),
                f64_as_u32(y + 0.5),
                "{y:e} ({:#x})",
                y.to_bits()
            );
        }
    }
}
