//! Fuzz target: `decode_pcap` must return `Ok` or `Err` on any input, never
//! panic, and its `Ok` must be self-consistent (the body is `common::pcap`,
//! shared with the stable corpus replay test).
#![no_main]

mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| common::pcap(data));
