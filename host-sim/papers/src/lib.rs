//! paragyro-papers: reproductions of the source papers (docs/paper-reproduction.md).
//! Research code: it uses the simulator and the core; no product crate depends on it.
#![forbid(unsafe_code)]
#![allow(clippy::needless_range_loop)]

pub mod averaged;
pub mod claims;
pub mod paper001;
pub mod paper_raw;
