//! Drives the core with the simulated gyro, scenario by scenario. (Being written.)

use crate::scenario::Scenario;
use crate::trace::RunResult;

/// Precision of the core instantiation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    /// `Estimator<f32>`: what runs on the chip.
    F32,
    /// `Estimator<f64>`: host reference.
    F64,
}

/// Options of one run.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Core precision.
    pub precision: Precision,
    /// Overrides the scenario's seed.
    pub seed: Option<u64>,
}

/// Runs a scenario; `progress` is called with the fraction done (0..=1) now and then.
pub fn run(
    _scenario: &Scenario,
    _opts: &RunOptions,
    _progress: &mut dyn FnMut(f64),
) -> anyhow::Result<RunResult> {
    anyhow::bail!("runner not implemented yet")
}
