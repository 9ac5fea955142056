#![no_main]
//! cargo-fuzz target: see polymap::fuzz::odometry.
libfuzzer_sys::fuzz_target!(|data: &[u8]| polymap::fuzz::odometry(data));
