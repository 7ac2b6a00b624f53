//! paragyro-sim: the simulated gyro and the tools around the core.
#![forbid(unsafe_code)]

pub mod lockin;
pub mod plant;
pub mod report;
pub mod runner;
pub mod scenario;
pub mod trace;
