//! # paragyro-core
//!
//! The `no_std`, allocation-free signal chain of a parametrically excited MEMS rate
//! gyroscope (seed 000): at every 500 Hz sample of the lock-in outputs it updates an
//! 8×8 (drive) and a 6×6 (sense) recursive least squares estimate of the paper's θ1, θ2,
//! recovers the physical parameters (damping, natural frequencies, nonlinear stiffness,
//! parametric excitation, coupling, angular rate) and retunes the pump so that it sits at
//! twice the sense-mode natural frequency.
//!
//! One algorithm per module; [`config::Config::build`] validates the SI settings once and
//! returns the runtime [`estimator::Estimator`], whose [`estimator::Estimator::step`]
//! cannot fail. The same code runs in `f32` on the chip and in `f64` on the host.
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]
// Index loops over small fixed matrices read like the math they implement.
#![allow(clippy::needless_range_loop)]

pub mod complex;
pub mod config;
pub mod estimator;
pub mod excitation;
pub mod harmonics;
pub mod lpf;
pub mod monitor;
pub mod physics;
pub mod real;
pub mod retune;
pub mod rls;
pub mod rows;
pub mod svf;

pub use complex::Cplx;
pub use config::{Config, ConfigError, ValidConfig};
pub use estimator::{Counters, Estimator, Health, Lockin, Sample, StepOutput};
pub use physics::Physical;
pub use real::Real;
