//! paragyro-papers: reproductions of the source papers (host-sim/papers/README.md).
//! Research code: it uses the simulator and the core; no product crate depends on it.
//!
//! * [`averaged`]: the averaged slow flow of seed 000's gyro (steady states, stability,
//!   sweeps with their hysteresis);
//! * [`paper001`]: seed 001's stationary regimes and Figs 3–4;
//! * [`paper_raw`]: seed 000's own estimator on the raw fast signals;
//! * [`claims`]: the readings of the paper's "20 %" claim;
//! * [`numerics`], [`complex`]: what they share (linear algebra, continuation,
//!   complex division; parallel maps are `paragyro_simulator::par`).
#![forbid(unsafe_code)]
#![allow(clippy::needless_range_loop)]

pub mod averaged;
pub mod claims;
pub mod complex;
pub mod numerics;
pub mod paper001;
pub mod paper_raw;

use std::path::Path;

use anyhow::{Context, Result};
use serde::Serialize;

/// Writes `value` as pretty JSON to `path` (with a final newline if `newline`). The value
/// goes through [`serde_json::Value`], whose maps are sorted: the files keep the key
/// order they always had, whatever the order of the struct fields.
pub(crate) fn write_json<T: Serialize>(path: &Path, value: &T, newline: bool) -> Result<()> {
    let v = serde_json::to_value(value)?;
    let mut s = serde_json::to_string_pretty(&v)?;
    if newline {
        s.push('\n');
    }
    std::fs::write(path, s).with_context(|| format!("writing {}", path.display()))
}
