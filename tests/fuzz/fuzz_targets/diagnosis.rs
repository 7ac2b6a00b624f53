//! libFuzzer entry point of [`paragyro_fuzz::diagnosis`].
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| paragyro_fuzz::diagnosis(data));
