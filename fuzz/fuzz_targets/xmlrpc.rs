#![no_main]
//! cargo-fuzz target: see polymap::fuzz::xmlrpc.
libfuzzer_sys::fuzz_target!(|data: &[u8]| polymap::fuzz::xmlrpc(data));
