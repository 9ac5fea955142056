#![no_main]
//! cargo-fuzz target: see polymap::fuzz::snapshot.
libfuzzer_sys::fuzz_target!(|data: &[u8]| polymap::fuzz::snapshot(data));
