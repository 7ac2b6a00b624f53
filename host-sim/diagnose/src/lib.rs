//! paragyro-diagnose: where a record departs from the simulator, which unmodelled effect
//! causes it and how far the gap shrinks once it is added (host-sim/diagnose/README.md), and the
//! blind benchmark that scores it on records whose effect is withheld.
#![forbid(unsafe_code)]
#![allow(clippy::needless_range_loop)]

pub mod blind;
pub mod diagnose;
pub mod diagplot;
