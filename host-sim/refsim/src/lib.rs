//! An independent reference generator of paragyro records (`paragyro-record 1`): a plant
//! written in SI units as a first-order state space, integrated with an adaptive
//! Dormand–Prince 5(4) pair together with a lock-in whose Butterworth low-passes are LC
//! ladders, driven by its own protocol, with per-record device tolerances and effects.
//! It shares no code with the project's simulator, diagnosis or core (see README.md).

pub mod device;
pub mod dopri;
pub mod effects;
pub mod format;
pub mod generate;
pub mod ladder;
pub mod plant;
pub mod protocol;
pub mod sim;
