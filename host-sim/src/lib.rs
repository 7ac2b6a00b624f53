//! paragyro-sim: the simulated gyro and the tools around the core.
#![forbid(unsafe_code)]

pub mod lockin;
pub mod plant;
pub mod trace;
