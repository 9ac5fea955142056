#![no_main]
//! cargo-fuzz target: see polymap::fuzz::tcpros_header.
libfuzzer_sys::fuzz_target!(|data: &[u8]| polymap::fuzz::tcpros_header(data));
