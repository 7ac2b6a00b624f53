//! libFuzzer entry point of [`paragyro_fuzz::ads131m08_frame`].
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| paragyro_fuzz::ads131m08_frame(data));
