//! libFuzzer entry point of [`paragyro_fuzz::estimator_step`].
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| paragyro_fuzz::estimator_step(data));
