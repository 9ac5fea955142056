#![no_main]
//! cargo-fuzz target: see polymap::fuzz::bag.
libfuzzer_sys::fuzz_target!(|data: &[u8]| polymap::fuzz::bag(data));
