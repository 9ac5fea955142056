#![no_main]
//! cargo-fuzz target: see polymap::fuzz::sequence.
libfuzzer_sys::fuzz_target!(|data: &[u8]| polymap::fuzz::sequence(data));
