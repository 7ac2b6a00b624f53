//! libFuzzer entry point of [`paragyro_fuzz::scenario_parser`].
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| paragyro_fuzz::scenario_parser(data));
