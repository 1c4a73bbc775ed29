//! Read throughput per format, points per second, on ~1 M point files.
//!
//! The files are written to a temporary folder before timing starts; the
//! timed code is `read_cloud` on a file in the page cache (one `fs::read` plus
//! decoding). Run with `cargo bench -p murk-io --bench read`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use murk_io::{PcdData, ReadOptions, WriteOptions, read_cloud, write_cloud_with};
use murk_types::PointFormat;

#[path = "../tests/common/mod.rs"]
mod common;

/// Points per benchmark file.
const POINTS: usize = 1 << 20;

fn read(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("temp dir");
    let cloud = common::synthetic(POINTS, true);
    let mut cases = vec![
        ("pcd-binary", PointFormat::Pcd, PcdData::Binary),
        (
            "pcd-binary_compressed",
            PointFormat::Pcd,
            PcdData::BinaryCompressed,
        ),
        ("pcd-ascii", PointFormat::Pcd, PcdData::Ascii),
        ("kitti-bin", PointFormat::KittiBin, PcdData::Binary),
        ("nuscenes-bin", PointFormat::NuscenesBin, PcdData::Binary),
        ("csv", PointFormat::Csv, PcdData::Binary),
    ];
    if cfg!(feature = "parquet") {
        cases.push(("parquet", PointFormat::Parquet, PcdData::Binary));
    }
    let mut group = c.benchmark_group("read");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(3))
        .throughput(Throughput::Elements(POINTS as u64));
    for (name, format, pcd_data) in cases {
        let path = dir.path().join(format!("{name}.{}", format.extension()));
        write_cloud_with(&path, &cloud, &WriteOptions { format, pcd_data }).expect("write");
        let opts = ReadOptions::default();
        // Fail loudly rather than time a reader that errors.
        assert_eq!(read_cloud(&path, &opts).expect("read").len(), POINTS);
        group.bench_function(name, |b| {
            b.iter(|| black_box(read_cloud(black_box(&path), &opts).expect("read")))
        });
    }
    group.finish();
}

criterion_group!(benches, read);
criterion_main!(benches);
