#![no_main]
//! cargo-fuzz target: see polymap::fuzz::service_request.
libfuzzer_sys::fuzz_target!(|data: &[u8]| polymap::fuzz::service_request(data));
