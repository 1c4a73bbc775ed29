//! Shared by the fuzz targets: options from the first input byte, the
//! invariants every successfully parsed cloud must satisfy, and each target's
//! body ([`run`]).
//!
//! The body lives here, not in the `fuzz_target!` files, so that murk-io's
//! stable test `tests/fuzz_corpus.rs` (which includes this file by path)
//! replays the committed seeds through exactly what the fuzzer runs.

use std::path::Path;

use murk_io::{PcdData, ReadOptions, WriteOptions, encode_cloud, parse_cloud};
use murk_types::{IntensityScale, LidarSpec, PointCloud, PointFormat};

/// One fuzz input of the target of `format`: the first byte picks the
/// options, the rest goes to that format's byte parser (`parse_pcd`,
/// `parse_kitti`, `parse_nuscenes`, `parse_csv`), which must return `Ok` or
/// `Err` and never panic; an `Ok` cloud must pass [`check`].
pub fn run(format: PointFormat, data: &[u8]) {
    let (opts, bytes) = options(data);
    let name = Path::new("fuzz");
    let parsed = match format {
        PointFormat::Pcd => murk_io::parse_pcd(bytes, name, &opts),
        PointFormat::KittiBin => murk_io::parse_kitti(bytes, name, &opts),
        PointFormat::NuscenesBin => murk_io::parse_nuscenes(bytes, name, &opts),
        PointFormat::Csv => murk_io::parse_csv(bytes, name, &opts),
        other => panic!("no fuzz target parses {other:?}"),
    };
    if let Ok(cloud) = parsed {
        check(&cloud, format);
    }
}

/// Splits off the first byte and turns it into read options: bit 0–1 pick
/// the sensor used to derive rings (none = VLP-16, a 2-ring sensor, a
/// 40-ring sensor that takes the binary-search path), bit 2 an explicit scale.
pub fn options(data: &[u8]) -> (ReadOptions, &[u8]) {
    let Some((&b, rest)) = data.split_first() else {
        return (ReadOptions::default(), data);
    };
    let lidar = match b & 3 {
        1 => Some(LidarSpec {
            elevation_deg: vec![-2.0, 2.0],
            ..LidarSpec::vlp16()
        }),
        2 => Some(LidarSpec {
            elevation_deg: (0..40).map(|i| -25.0 + 0.9 * f64::from(i)).rev().collect(),
            ..LidarSpec::vlp16()
        }),
        _ => None,
    };
    let opts = ReadOptions {
        lidar,
        intensity_scale: (b & 4 != 0).then_some(IntensityScale::SIX_BIT),
        ..ReadOptions::default()
    };
    (opts, rest)
}

/// What a successful parse promises: equal columns, finite values, and the
/// cloud survives a binary round trip unchanged.
pub fn check(cloud: &PointCloud, format: PointFormat) {
    cloud.check().expect("columns of equal length");
    assert_eq!(cloud.first_non_finite(), None, "non-finite value accepted");
    if let Some(t) = &cloud.time {
        assert!(t.iter().all(|v| v.is_finite()), "non-finite time accepted");
    }
    let path = Path::new("fuzz-round-trip");
    let datas: &[PcdData] = if format == PointFormat::Pcd {
        &[PcdData::Binary, PcdData::BinaryCompressed]
    } else {
        &[PcdData::Binary]
    };
    for &pcd_data in datas {
        let opts = WriteOptions { format, pcd_data };
        let bytes = encode_cloud(cloud, &opts, path).expect("a parsed cloud can be written");
        if bytes.is_empty() {
            continue; // an empty record file reads as "empty file"
        }
        let read = ReadOptions {
            intensity_scale: Some(cloud.intensity_scale),
            ..ReadOptions::default()
        };
        let back = parse_cloud(&bytes, format, path, &read).expect("written cloud reads back");
        assert_eq!(back.x, cloud.x);
        assert_eq!(back.y, cloud.y);
        assert_eq!(back.z, cloud.z);
        assert_eq!(back.intensity, cloud.intensity);
        if format != PointFormat::KittiBin {
            // KITTI re-derives rings (with the default sensor here).
            assert_eq!(back.ring, cloud.ring);
        }
        if format == PointFormat::Pcd {
            assert_eq!(back.time, cloud.time);
        }
    }
}
