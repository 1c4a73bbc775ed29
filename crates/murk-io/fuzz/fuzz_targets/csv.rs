//! Fuzz target: arbitrary bytes into `murk_io::parse_csv` must give `Ok` or
//! `Err`, never a panic, and an `Ok` must satisfy `common::check` (the body
//! is `common::run`, shared with the stable corpus replay test).
#![no_main]

mod common;

use libfuzzer_sys::fuzz_target;
use murk_types::PointFormat;

fuzz_target!(|data: &[u8]| common::run(PointFormat::Csv, data));
