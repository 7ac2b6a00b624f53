//! A minimal complex number for lock-in envelopes (no allocation, `Copy`).

use crate::real::Real;
use core::ops::{Add, AddAssign, Mul, Neg, Sub};

/// `re + i·im`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cplx<T> {
    /// Real (in-phase) part.
    pub re: T,
    /// Imaginary (quadrature) part.
    pub im: T,
}

impl<T: Real> Cplx<T> {
    /// Zero.
    pub const ZERO: Self = Cplx {
        re: T::ZERO,
        im: T::ZERO,
    };
    /// From parts.
    #[inline]
    pub fn new(re: T, im: T) -> Self {
        Cplx { re, im }
    }
    /// Complex conjugate.
    #[inline]
    pub fn conj(self) -> Self {
        Cplx {
            re: self.re,
            im: -self.im,
        }
    }
    /// |z|².
    #[inline]
    pub fn norm_sqr(self) -> T {
        self.re * self.re + self.im * self.im
    }
    /// |z|.
    #[inline]
    pub fn abs(self) -> T {
        self.norm_sqr().sqrt()
    }
    /// z · r for real r.
    #[inline]
    pub fn scale(self, r: T) -> Self {
        Cplx {
            re: self.re * r,
            im: self.im * r,
        }
    }
    /// i·z.
    #[inline]
    pub fn mul_i(self) -> Self {
        Cplx {
            re: -self.im,
            im: self.re,
        }
    }
    /// Both parts finite.
    #[inline]
    pub fn is_finite(self) -> bool {
        self.re.is_finite() && self.im.is_finite()
    }
    /// Conversion between precisions.
    #[inline]
    pub fn cast<U: Real>(self) -> Cplx<U> {
        Cplx {
            re: U::from_f64(self.re.to_f64()),
            im: U::from_f64(self.im.to_f64()),
        }
    }
}

impl<T: Real> Add for Cplx<T> {
    type Output = Self;
    #[inline]
    fn add(self, o: Self) -> Self {
        Cplx {
            re: self.re + o.re,
            im: self.im + o.im,
        }
    }
}
impl<T: Real> AddAssign for Cplx<T> {
    #[inline]
    fn add_assign(&mut self, o: Self) {
        self.re += o.re;
        self.im += o.im;
    }
}
impl<T: Real> Sub for Cplx<T> {
    type Output = Self;
    #[inline]
    fn sub(self, o: Self) -> Self {
        Cplx {
            re: self.re - o.re,
            im: self.im - o.im,
        }
    }
}
impl<T: Real> Neg for Cplx<T> {
    type Output = Self;
    #[inline]
    fn neg(self) -> Self {
        Cplx {
            re: -self.re,
            im: -self.im,
        }
    }
}
impl<T: Real> Mul for Cplx<T> {
    type Output = Self;
    #[inline]
    fn mul(self, o: Self) -> Self {
        Cplx {
            re: self.re * o.re - self.im * o.im,
            im: self.re * o.im + self.im * o.re,
        }
    }
}
