//! paragyro-simulator: the simulated gyro (full-rate eq. 6 + lock-in + sim-to-real
//! effects), scenarios, records, the closed-loop runner that drives the core, and the
//! plotting kit. No command-line crates: the CLI is `paragyro-sim` (host-sim/cli).
// `unsafe` only to call the AVX2 builds of the plant's hot loop where the CPU has AVX2 and
// FMA (`simd`): each call carries `#[allow(unsafe_code)]` and its SAFETY note
#![deny(unsafe_code)]
// Index loops over small fixed arrays read like the math they implement.
#![allow(clippy::needless_range_loop)]

pub mod effects;
pub mod faults;
pub mod located;
pub mod lockin;
pub mod par;
pub mod plant;
pub mod plot;
pub mod rate_response;
pub mod record;
pub mod report;
pub mod results;
pub mod runner;
pub mod scenario;
pub mod simd;
pub mod summary;
pub mod thermal;
pub mod trace;
