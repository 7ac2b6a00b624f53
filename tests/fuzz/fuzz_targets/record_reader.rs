//! libFuzzer entry point of [`paragyro_fuzz::record_reader`].
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| paragyro_fuzz::record_reader(data));
