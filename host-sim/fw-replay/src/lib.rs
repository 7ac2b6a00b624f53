//! Host side of the firmware's replay (firmware/README.md): the replay-table generator
//! ([`table`]) and the capture-log converter ([`capture`]). The binary
//! `paragyro-fw-replay` is their command line; `tests/tests/firmware_qemu.rs` uses them
//! as a library.
#![forbid(unsafe_code)]

pub mod capture;
pub mod table;
