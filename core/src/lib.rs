//! paragyro-core: see README.
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod complex;
pub mod real;
pub mod rls;
pub mod physics;

pub use complex::Cplx;
pub use real::Real;
