//! # paragyro-core
//!
//! The `no_std`, allocation-free signal chain of a parametrically excited MEMS rate
//! gyroscope (the model of *Parameter identification of a parametrically excited rate
//! micro-gyroscope using recursive least squares method*, eq. 6): at every 500 Hz sample of
//! the lock-in outputs it updates an 8×8 (drive) and a 6×6 (sense) recursive least squares
//! estimate of the paper's θ1, θ2,
//! recovers the physical parameters (damping, natural frequencies, nonlinear stiffness,
//! parametric excitation, coupling, angular rate) and retunes the pump so that it sits at
//! twice the sense-mode natural frequency. The design and the derivation (with the
//! paper's errata) are in the crate's `README.md` and `docs/derivation.md`.
//!
//! One concept per module; `lib.rs` only re-exports. [`config::Config::build`] validates
//! the SI settings once and returns the runtime [`estimator::Estimator`] (a design built
//! once plus a small state), whose [`estimator::Estimator::step`] cannot fail. The same
//! code runs in `f32` on the chip and in `f64` on the host.
//!
//! | module | what |
//! |---|---|
//! | [`config`] | SI settings, validation ([`ValidConfig`]) |
//! | [`sample`] | one sample's inputs ([`Sample`], [`Lockin`]) |
//! | [`physics`] | Table 2, ω0, L0, θ ↔ physical parameters, rate |
//! | [`lpf`], [`harmonics`], [`svf`], [`rows`] | replica low-pass, projections, slow filters, regression rows |
//! | [`rls`] | Bierman-UD recursive least squares |
//! | [`drift`] | the natural frequencies' drift through temperature: prediction, process noise, lead |
//! | [`monitor`] | input checks, change detector, excitation, settle test |
//! | [`excitation`], [`retune`] | pump scheduler (dither, ramps), retune supervisor |
//! | [`rate`] | the fast rate channel (every sample, given the slow parameters), quadrature |
//! | [`health`], [`output`] | [`Health`], [`Counters`], [`StepOutput`] and its events |
//! | [`persist`] | warm start: the converged estimate as a versioned, CRC-checked snapshot |
//! | [`estimator`] | the design, the state and the one `step()` that ties the stages |
//!
//! ## Example
//!
//! Configure (here the paper's Table 2 defaults), validate and build once, then step once
//! per 500 Hz sample with the lock-in outputs, the accelerometer and the pump in effect;
//! each step returns the pump to command next and the health, and the estimator gives the
//! rate and the physical parameters at any time. A real caller feeds its front end's
//! lock-in outputs (the firmware: the ADS131M08 frames; the host: the simulated gyro or a
//! record); the constant sample below only shows the calls.
//!
//! ```
//! use paragyro_core::{Config, Cplx, Estimator, Lockin, Sample};
//!
//! let mut cfg = Config::table2();
//! cfg.retune.enabled = false; // identify only, leave the pump where it is
//! let mut est: Estimator<f32> = cfg.build().expect("a valid configuration");
//!
//! let mut pump_hz = est.initial_pump_hz();
//! let mut pump_scale = 1.0;
//! for _ in 0..50 {
//!     let sample = Sample {
//!         lockin: Lockin {
//!             x_um: [Cplx::new(1.0, 0.0), Cplx::new(0.0, 0.0), Cplx::new(0.0, 0.0)],
//!             ..Lockin::default()
//!         },
//!         accel_mps2: [0.0, 0.0],
//!         pump_hz,
//!         pump_scale,
//!         temp_c: None,
//!     };
//!     let out = est.step(&sample);
//!     // command these to the pump (the DDS) for the next sample instant
//!     pump_hz = out.pump_hz_next;
//!     pump_scale = out.pump_scale_next as f32;
//!     if !out.health.inputs_valid {
//!         // a refused sample: counted, the estimate held
//!     }
//! }
//! assert_eq!(est.samples(), 50);
//! let health = est.health();
//! let rate_dps = est.rate_dps(); // the identified angular rate, °/s
//! let fast = est.rate_output(); // the fast rate channel: every sample, with its validity
//! assert!(rate_dps.is_finite() && pump_hz.is_finite());
//! // act on an estimate only when its health says so: not on this made-up input
//! assert!(!health.actionable() && !fast.valid);
//! ```
#![no_std]
#![deny(unsafe_code)]
#![warn(missing_docs)]
// Index loops over small fixed matrices read like the math they implement.
#![allow(clippy::needless_range_loop)]

pub mod complex;
pub mod config;
pub mod drift;
pub mod estimator;
pub mod excitation;
pub mod harmonics;
pub mod health;
pub mod lpf;
pub mod monitor;
pub mod output;
pub mod persist;
pub mod physics;
pub mod rate;
pub mod real;
pub mod retune;
pub mod rls;
pub mod rows;
pub mod sample;
pub mod svf;
pub mod thermal;

pub use complex::Cplx;
pub use config::{Config, ConfigError, ValidConfig};
pub use estimator::{Estimator, ThermalEstimate};
pub use health::{Counters, Health};
pub use output::StepOutput;
pub use physics::Physical;
pub use real::Real;
pub use sample::{Lockin, Sample};
