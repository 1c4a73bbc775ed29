//! Fuzz target: arbitrary bytes into `murk_io::parse_kitti` must give `Ok` or
//! `Err`, never a panic, and an `Ok` must satisfy `common::check`.
#![no_main]

mod common;

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use murk_types::PointFormat;

fuzz_target!(|data: &[u8]| {
    let (opts, bytes) = common::options(data);
    if let Ok(cloud) = murk_io::parse_kitti(bytes, Path::new("fuzz"), &opts) {
        common::check(&cloud, PointFormat::KittiBin);
    }
});
