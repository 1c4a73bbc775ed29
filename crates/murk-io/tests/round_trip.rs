//! Every writer read back by its reader gives the same points; writes are
//! atomic and byte-identical.

mod common;

use common::{same_points, synthetic};
use murk_io::{
    PcdData, ReadOptions, WriteOptions, encode_cloud, read_cloud, write_cloud, write_cloud_with,
};
use murk_types::{IntensityScale, PointCloud, PointFormat};
use proptest::prelude::*;

const PCD_DATA: [PcdData; 3] = [PcdData::Ascii, PcdData::Binary, PcdData::BinaryCompressed];

/// True when the crate is built with Parquet support.
fn has_parquet() -> bool {
    cfg!(feature = "parquet")
}

/// Writes `cloud` as `opts` into a temp dir and reads it back.
fn round_trip(cloud: &PointCloud, opts: &WriteOptions) -> PointCloud {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(format!("scan.{}", opts.format.extension()));
    write_cloud_with(&path, cloud, opts).unwrap();
    read_cloud(&path, &ReadOptions::default()).unwrap()
}

#[test]
fn pcd_round_trips_in_every_encoding_with_and_without_time() {
    for timed in [false, true] {
        let cloud = synthetic(5_000, timed);
        for data in PCD_DATA {
            let opts = WriteOptions {
                format: PointFormat::Pcd,
                pcd_data: data,
            };
            let back = round_trip(&cloud, &opts);
            assert_eq!(back, cloud, "{data} timed={timed}");
        }
    }
}

#[test]
fn csv_round_trips_with_and_without_time() {
    for timed in [false, true] {
        let cloud = synthetic(2_000, timed);
        let back = round_trip(&cloud, &WriteOptions::new(PointFormat::Csv));
        assert_eq!(back, cloud, "timed={timed}");
    }
}

#[cfg(feature = "parquet")]
#[test]
fn parquet_round_trips_with_and_without_time() {
    for timed in [false, true] {
        let cloud = synthetic(3_000, timed);
        let back = round_trip(&cloud, &WriteOptions::new(PointFormat::Parquet));
        assert_eq!(back, cloud, "timed={timed}");
    }
}

#[test]
fn kitti_round_trips_points_and_recovers_rings_from_elevation() {
    let cloud = synthetic(4_000, true);
    let back = round_trip(&cloud, &WriteOptions::new(PointFormat::KittiBin));
    // KITTI stores no ring and no time: the ring comes back from elevation
    // (the synthetic points lie on the VLP-16 rings), the time is gone, and
    // the cloud is labelled with KITTI's scale (the values are untouched).
    same_points(&back, &cloud);
    assert_eq!(back.time, None);
    assert_eq!(back.intensity_scale, IntensityScale::KITTI);
}

#[test]
fn large_files_round_trip_and_read_identically_on_any_thread_count() {
    // 200k points: several parallel decode pieces and a partial last one.
    let cloud = synthetic(200_003, true);
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (PointFormat::Pcd, PcdData::Binary),
        (PointFormat::Pcd, PcdData::BinaryCompressed),
        (PointFormat::KittiBin, PcdData::Binary),
        (PointFormat::NuscenesBin, PcdData::Binary),
    ];
    for (format, pcd_data) in cases {
        let path = dir
            .path()
            .join(format!("{pcd_data}.{}", format.extension()));
        write_cloud_with(&path, &cloud, &WriteOptions { format, pcd_data }).unwrap();
        let read_on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| read_cloud(&path, &ReadOptions::default()).unwrap())
        };
        let one = read_on(1);
        // Rings derived from elevation (KITTI) equal the written ones.
        same_points(&one, &cloud);
        if format == PointFormat::Pcd {
            assert_eq!(one, cloud, "{format:?} {pcd_data}");
        }
        assert_eq!(read_on(2), one, "{format:?} {pcd_data}");
        assert_eq!(read_on(3), one, "{format:?} {pcd_data}");
    }
}

#[test]
fn nuscenes_round_trips_points_and_rings() {
    let cloud = synthetic(4_000, true);
    let back = round_trip(&cloud, &WriteOptions::new(PointFormat::NuscenesBin));
    same_points(&back, &cloud);
    assert_eq!(back.time, None);
    assert_eq!(back.intensity_scale, IntensityScale::Calibrated);
}

#[test]
fn empty_clouds_round_trip_where_the_format_has_a_header() {
    let empty = PointCloud::default();
    for data in PCD_DATA {
        let opts = WriteOptions {
            format: PointFormat::Pcd,
            pcd_data: data,
        };
        assert_eq!(round_trip(&empty, &opts), empty, "{data}");
    }
    let tables = [PointFormat::Csv, PointFormat::Parquet];
    for f in tables
        .into_iter()
        .filter(|&f| has_parquet() || f != PointFormat::Parquet)
    {
        assert_eq!(round_trip(&empty, &WriteOptions::new(f)), empty, "{f:?}");
    }
}

#[test]
fn identical_clouds_give_byte_identical_files_in_every_format() {
    let cloud = synthetic(1_000, true);
    let dir = tempfile::tempdir().unwrap();
    let writable = PointFormat::ALL.into_iter().filter(|f| f.writable());
    for format in writable.filter(|&f| has_parquet() || f != PointFormat::Parquet) {
        for data in PCD_DATA {
            let opts = WriteOptions {
                format,
                pcd_data: data,
            };
            let a = dir.path().join(format!("a.{}", format.extension()));
            let b = dir.path().join(format!("b.{}", format.extension()));
            write_cloud_with(&a, &cloud, &opts).unwrap();
            write_cloud_with(&b, &cloud.clone(), &opts).unwrap();
            let (a, b) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
            assert_eq!(a, b, "{format:?} {data}");
            assert_eq!(a, encode_cloud(&cloud, &opts, dir.path()).unwrap());
        }
    }
}

#[test]
fn a_write_replaces_the_file_and_leaves_no_temporary_behind() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scan.pcd");
    std::fs::write(&path, b"old contents").unwrap();
    let cloud = synthetic(100, false);
    write_cloud(&path, &cloud, PointFormat::Pcd).unwrap();
    assert_eq!(read_cloud(&path, &ReadOptions::default()).unwrap(), cloud);
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert_eq!(names, vec!["scan.pcd".to_string()]);
}

#[cfg(unix)]
#[test]
fn written_files_are_not_private_temporary_files() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scan.csv");
    write_cloud(&path, &synthetic(3, false), PointFormat::Csv).unwrap();
    let mode = std::fs::metadata(&path).unwrap().permissions().mode();
    // Readable by the group and others (unless the umask forbids it), as
    // a file created with `File::create` would be.
    let plain = dir.path().join("plain");
    std::fs::File::create(&plain).unwrap();
    let plain_mode = std::fs::metadata(&plain).unwrap().permissions().mode();
    assert_eq!(mode & 0o777, plain_mode & 0o777);
}

#[test]
fn binary_compressed_is_smaller_than_binary_on_a_structured_scan() {
    // Integer intensities and a ring column that cycles compress well.
    let mut cloud = synthetic(10_000, false);
    for v in &mut cloud.intensity {
        *v = v.round();
    }
    let enc = |d| {
        encode_cloud(
            &cloud,
            &WriteOptions {
                format: PointFormat::Pcd,
                pcd_data: d,
            },
            std::path::Path::new("x.pcd"),
        )
        .unwrap()
        .len()
    };
    let (bin, comp) = (enc(PcdData::Binary), enc(PcdData::BinaryCompressed));
    assert!(comp < bin, "compressed {comp} ≥ binary {bin}");
}

/// Any finite cloud.
fn any_cloud() -> impl Strategy<Value = PointCloud> {
    let point = (
        any::<f32>().prop_filter("finite", |v| v.is_finite()),
        any::<f32>().prop_filter("finite", |v| v.is_finite()),
        any::<f32>().prop_filter("finite", |v| v.is_finite()),
        any::<f32>().prop_filter("finite", |v| v.is_finite()),
        any::<u16>(),
        -1e4f32..1e4,
    );
    (proptest::collection::vec(point, 0..200), any::<bool>()).prop_map(|(pts, timed)| {
        let mut c = PointCloud::with_capacity(pts.len());
        for (x, y, z, i, r, t) in pts {
            if timed {
                c.push_timed(x, y, z, i, r, t);
            } else {
                c.push(x, y, z, i, r);
            }
        }
        c
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn any_finite_cloud_round_trips_exactly_through_pcd_and_csv(cloud in any_cloud()) {
        for data in PCD_DATA {
            let opts = WriteOptions { format: PointFormat::Pcd, pcd_data: data };
            let bytes = encode_cloud(&cloud, &opts, std::path::Path::new("p.pcd")).unwrap();
            let back = murk_io::parse_pcd(&bytes, std::path::Path::new("p.pcd"), &ReadOptions::default()).unwrap();
            prop_assert_eq!(&back, &cloud);
        }
        let opts = WriteOptions::new(PointFormat::Csv);
        let bytes = encode_cloud(&cloud, &opts, std::path::Path::new("p.csv")).unwrap();
        let back = murk_io::parse_csv(&bytes, std::path::Path::new("p.csv"), &ReadOptions::default()).unwrap();
        prop_assert_eq!(&back, &cloud);
    }
}

/// Reads reuse a per-thread buffer, and a read nested inside another file's
/// parallel decode (rayon work stealing) must take its own: files of several
/// sizes and formats read concurrently, many times, give exactly what a
/// sequential read gives, and a small or empty file read after a large one
/// sees none of the large one's bytes.
#[test]
fn concurrent_reads_equal_sequential_reads() {
    use rayon::prelude::*;
    let dir = tempfile::tempdir().unwrap();
    let mut paths = Vec::new();
    for (k, n) in [150_000usize, 70_000, 3_000, 200_000]
        .into_iter()
        .enumerate()
    {
        let cloud = synthetic(n, k % 2 == 0);
        for (format, data) in [
            (PointFormat::Pcd, PcdData::Binary),
            (PointFormat::Pcd, PcdData::BinaryCompressed),
            (PointFormat::KittiBin, PcdData::Binary),
            (PointFormat::NuscenesBin, PcdData::Binary),
        ] {
            let path = dir
                .path()
                .join(format!("scan{k}-{data}.{}", format.extension()));
            write_cloud_with(
                &path,
                &cloud,
                &WriteOptions {
                    format,
                    pcd_data: data,
                },
            )
            .unwrap();
            paths.push(path);
        }
    }
    let opts = ReadOptions::default();
    let sequential: Vec<PointCloud> = paths
        .iter()
        .map(|p| read_cloud(p, &opts).unwrap())
        .collect();
    for _ in 0..4 {
        let parallel: Vec<PointCloud> = paths
            .par_iter()
            .map(|p| read_cloud(p, &opts).unwrap())
            .collect();
        assert_eq!(parallel, sequential);
    }
    // Largest file first, then a short one and an empty one on this thread.
    let big = read_cloud(&paths[12], &opts).unwrap();
    assert_eq!(big.len(), 200_000);
    let short = dir.path().join("short.bin");
    std::fs::write(&short, [0u8; 17]).unwrap();
    let err = read_cloud(&short, &opts).unwrap_err().to_string();
    assert!(
        err.contains("short.bin") && err.contains("1 trailing"),
        "{err}"
    );
    let empty = dir.path().join("empty.bin");
    std::fs::write(&empty, []).unwrap();
    let err = read_cloud(&empty, &opts).unwrap_err().to_string();
    assert!(err.contains("empty.bin") && err.contains("empty"), "{err}");
    assert_eq!(read_cloud(&paths[10], &opts).unwrap(), sequential[10]);
}
