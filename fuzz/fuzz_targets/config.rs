#![no_main]
//! cargo-fuzz target: see polymap::fuzz::config.
libfuzzer_sys::fuzz_target!(|data: &[u8]| polymap::fuzz::config(data));
