#![no_main]
//! cargo-fuzz target: see polymap::fuzz::mcap.
libfuzzer_sys::fuzz_target!(|data: &[u8]| polymap::fuzz::mcap(data));
