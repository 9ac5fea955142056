#![no_main]
//! cargo-fuzz target: see polymap::fuzz::ros1_message.
libfuzzer_sys::fuzz_target!(|data: &[u8]| polymap::fuzz::ros1_message(data));
