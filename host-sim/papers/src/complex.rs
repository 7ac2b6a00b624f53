//! What the slow flows need of complex numbers beyond the core's [`Cplx`]: a division and
//! an overflow-safe modulus. The papers use `Cplx<f64>` (one complex type in the project);
//! these two live here because the core, a `no_std` crate for the chip, has no use for them.

use paragyro_core::Cplx;

/// Division and the `hypot` modulus for `Cplx<f64>`.
pub trait CplxExt: Sized {
    /// `self / o`, scaled by `max(|o.re|, |o.im|)` so that a large `|o|` does not overflow.
    fn div(self, o: Self) -> Self;
    /// `|z|` as `hypot(re, im)`: no overflow or underflow in the squares (the core's
    /// [`Cplx::abs`] is `√(re² + im²)`, which may differ in the last bit).
    fn modulus(self) -> f64;
}

impl CplxExt for Cplx<f64> {
    fn div(self, o: Self) -> Self {
        let s = o.re.abs().max(o.im.abs());
        let (a, b) = (o.re / s, o.im / s);
        let d = a * a + b * b;
        Cplx::new(
            (self.re * a + self.im * b) / (d * s),
            (self.im * a - self.re * b) / (d * s),
        )
    }

    fn modulus(self) -> f64 {
        self.re.hypot(self.im)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn division_inverts_multiplication_and_survives_large_divisors() {
        let a = Cplx::new(1.5, -2.0);
        let b = Cplx::new(-0.25, 3.0);
        let q = (a * b).div(b);
        assert!((q - a).modulus() < 1e-15, "{q:?}");
        // |o|² would overflow: 1e200² = inf
        let big = Cplx::new(1e200, 1e200);
        let q = Cplx::new(2e200, 0.0).div(big);
        assert!((q - Cplx::new(1.0, -1.0)).modulus() < 1e-15, "{q:?}");
        // the squares overflow in √(re² + im²), not in hypot
        let z = Cplx::new(3e200_f64, 4e200);
        assert!(z.abs().is_infinite());
        assert!((z.modulus() / 5e200 - 1.0).abs() < 1e-15, "{}", z.modulus());
    }
}
