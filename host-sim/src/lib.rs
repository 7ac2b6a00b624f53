//! paragyro-sim: the simulated gyro and the tools around the core.
#![forbid(unsafe_code)]
// Index loops over small fixed arrays read like the math they implement.
#![allow(clippy::needless_range_loop)]

pub mod averaged;
pub mod blind;
pub mod claims;
pub mod diagnose;
pub mod diagplot;
pub mod effects;
pub mod lockin;
pub mod paper001;
pub mod paper_raw;
pub mod plant;
pub mod record;
pub mod report;
pub mod results;
pub mod runner;
pub mod scenario;
pub mod trace;
