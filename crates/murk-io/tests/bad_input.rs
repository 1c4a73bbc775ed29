//! One test per kind of bad input: each must fail with an error that names
//! the file and where in it the problem is.

mod common;

use std::path::Path;

use common::{f32s, file, synthetic};
use murk_io::{IoError, PcdData, ReadOptions, WriteOptions, encode_cloud, read_cloud, write_cloud};
use murk_types::{LidarSpec, PointCloud, PointFormat};

/// Reads `bytes` saved as `name` and returns the error and its message.
fn read_err(name: &str, bytes: &[u8]) -> (IoError, String) {
    read_err_with(name, bytes, &ReadOptions::default())
}

fn read_err_with(name: &str, bytes: &[u8], opts: &ReadOptions) -> (IoError, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = file(dir.path(), name, bytes);
    let e = read_cloud(&path, opts).expect_err("bad input must be refused");
    let msg = e.to_string();
    assert!(msg.contains(name), "message must name the file: {msg}");
    (e, msg)
}

fn assert_has(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "{msg:?} lacks {p:?}");
    }
}

/// A PCD header for `fields` (name, size, type) with `n` points.
fn pcd_header(fields: &[(&str, usize, char)], n: usize, data: &str) -> String {
    let names: Vec<_> = fields.iter().map(|f| f.0.to_string()).collect();
    let sizes: Vec<_> = fields.iter().map(|f| f.1.to_string()).collect();
    let types: Vec<_> = fields.iter().map(|f| f.2.to_string()).collect();
    let counts: Vec<_> = fields.iter().map(|_| "1".to_string()).collect();
    format!(
        "VERSION 0.7\nFIELDS {}\nSIZE {}\nTYPE {}\nCOUNT {}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n",
        names.join(" "),
        sizes.join(" "),
        types.join(" "),
        counts.join(" ")
    )
}

const XYZI: [(&str, usize, char); 4] = [
    ("x", 4, 'F'),
    ("y", 4, 'F'),
    ("z", 4, 'F'),
    ("intensity", 4, 'F'),
];

fn pcd_binary(points: &[[f32; 4]]) -> Vec<u8> {
    let mut b = pcd_header(&XYZI, points.len(), "binary").into_bytes();
    for p in points {
        b.extend(f32s(p));
    }
    b
}

// ---------------------------------------------------------------- empty files

#[test]
fn empty_pcd_is_an_empty_file_error() {
    let (e, msg) = read_err("a.pcd", b"");
    assert!(matches!(e, IoError::Empty { .. }));
    assert_has(&msg, &["empty file"]);
}

#[test]
fn empty_kitti_bin_is_an_empty_file_error() {
    let (e, _) = read_err("a.bin", b"");
    assert!(matches!(e, IoError::Empty { .. }));
}

#[test]
fn empty_nuscenes_bin_is_an_empty_file_error() {
    let (e, _) = read_err("a.pcd.bin", b"");
    assert!(matches!(e, IoError::Empty { .. }));
}

#[test]
fn empty_csv_is_an_empty_file_error() {
    let (e, _) = read_err("a.csv", b"");
    assert!(matches!(e, IoError::Empty { .. }));
}

#[cfg(feature = "parquet")]
#[test]
fn empty_parquet_is_an_empty_file_error() {
    let (e, _) = read_err("a.parquet", b"");
    assert!(matches!(e, IoError::Empty { .. }));
}

// ---------------------------------------------------------------- KITTI / nuScenes

#[test]
fn kitti_size_not_a_multiple_of_16_names_size_and_trailing_bytes() {
    let mut b = f32s(&[1.0, 2.0, 3.0, 0.5, 4.0, 5.0, 6.0, 0.25]);
    b.extend([0u8; 5]);
    let (e, msg) = read_err("000001.bin", &b);
    assert!(matches!(
        e,
        IoError::TrailingBytes {
            size: 37,
            trailing: 5,
            points: 2,
            record: 16,
            ..
        }
    ));
    assert_has(&msg, &["37 bytes", "16-byte", "5 trailing bytes"]);
}

#[test]
fn nuscenes_size_not_a_multiple_of_20_names_size_and_trailing_bytes() {
    let b = f32s(&[1.0, 2.0, 3.0, 10.0, 4.0, 9.0]);
    let (e, msg) = read_err("lidar.pcd.bin", &b);
    assert!(matches!(e, IoError::TrailingBytes { trailing: 4, .. }));
    assert_has(&msg, &["24 bytes", "20-byte", "4 trailing"]);
}

#[test]
fn kitti_non_finite_coordinate_names_the_point() {
    let b = f32s(&[1.0, 2.0, 3.0, 0.5, 4.0, f32::NAN, 6.0, 0.25]);
    let (e, msg) = read_err("000002.bin", &b);
    assert!(matches!(
        e,
        IoError::NonFinite {
            point: 1,
            field: "y",
            ..
        }
    ));
    assert_has(&msg, &["point 1", "y is NaN"]);
}

#[test]
fn kitti_non_finite_intensity_far_into_the_file_names_the_point() {
    // Beyond the first decode block, to check indices across blocks. 9,999
    // points: a size that 20-byte records do not fit (10,000 equal points
    // would fit `xyzir` too, with whole "ring ids", and be refused as
    // ambiguous).
    let mut pts = vec![1.0f32; 4 * 9_999];
    pts[4 * 9_001 + 3] = f32::INFINITY;
    let (e, _) = read_err("000003.bin", &f32s(&pts));
    assert!(matches!(
        e,
        IoError::NonFinite {
            point: 9_001,
            field: "intensity",
            ..
        }
    ));
}

#[test]
fn the_first_bad_point_is_named_when_later_pieces_are_bad_too() {
    // 300k points: several parallel decode pieces. Bad values in a later
    // piece (x), an earlier one (ring, z) and the same point twice: the error
    // is the first bad value in file order, whatever the thread count.
    let n = 300_000;
    let mut pts: Vec<f32> = (0..5 * n)
        .map(|i| if i % 5 == 4 { 3.0 } else { 1.0 })
        .collect();
    pts[5 * 250_000] = f32::NAN;
    pts[5 * 70_001 + 4] = 2.5;
    pts[5 * 70_001 + 2] = f32::INFINITY;
    pts[5 * 70_002 + 3] = f32::NAN;
    let bytes = f32s(&pts);
    for threads in [1, 2, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let (e, msg) = pool.install(|| read_err("far.pcd.bin", &bytes));
        assert!(
            matches!(
                e,
                IoError::NonFinite {
                    point: 70_001,
                    field: "z",
                    ..
                }
            ),
            "{threads} threads: {msg}"
        );
    }
    // Only the fractional ring left: it is named.
    pts[5 * 70_001 + 2] = 1.0;
    let (e, msg) = read_err("far.pcd.bin", &f32s(&pts));
    assert!(
        matches!(
            e,
            IoError::BadValue {
                point: 70_001,
                field: "ring",
                ..
            }
        ),
        "{msg}"
    );
}

#[test]
fn nuscenes_fractional_ring_index_is_refused() {
    let b = f32s(&[1.0, 2.0, 3.0, 10.0, 4.0, 1.0, 2.0, 3.0, 10.0, 4.5]);
    let (e, msg) = read_err("lidar.pcd.bin", &b);
    assert!(matches!(
        e,
        IoError::BadValue {
            point: 1,
            field: "ring",
            ..
        }
    ));
    assert_has(&msg, &["point 1", "4.5"]);
}

#[test]
fn nuscenes_negative_ring_index_is_refused() {
    let b = f32s(&[1.0, 2.0, 3.0, 10.0, -1.0]);
    let (e, _) = read_err("lidar.pcd.bin", &b);
    assert!(matches!(e, IoError::BadValue { point: 0, .. }));
}

// ---------------------------------------------------------------- PCD header

#[test]
fn pcd_points_differing_from_width_times_height_is_refused() {
    let h = "FIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nWIDTH 10\nHEIGHT 2\nPOINTS 19\nDATA ascii\n";
    let (e, msg) = read_err("a.pcd", h.as_bytes());
    assert!(matches!(e, IoError::Header { line: 6, .. }));
    assert_has(&msg, &["line 6", "POINTS 19", "WIDTH 10 × HEIGHT 2 = 20"]);
}

#[test]
fn pcd_without_x_is_a_missing_field_error() {
    let h = pcd_header(
        &[("y", 4, 'F'), ("z", 4, 'F'), ("intensity", 4, 'F')],
        0,
        "ascii",
    );
    let (e, msg) = read_err("a.pcd", h.as_bytes());
    assert!(matches!(e, IoError::MissingField { field: "x", .. }));
    assert_has(&msg, &["no x field", "y, z, intensity"]);
}

#[test]
fn pcd_without_intensity_is_a_missing_field_error() {
    let h = pcd_header(
        &[("x", 4, 'F'), ("y", 4, 'F'), ("z", 4, 'F'), ("rgb", 4, 'U')],
        0,
        "ascii",
    );
    let (e, _) = read_err("a.pcd", h.as_bytes());
    assert!(matches!(
        e,
        IoError::MissingField {
            field: "intensity",
            ..
        }
    ));
}

#[test]
fn pcd_float_of_two_bytes_for_a_read_field_is_a_type_error() {
    let h = pcd_header(
        &[
            ("x", 2, 'F'),
            ("y", 4, 'F'),
            ("z", 4, 'F'),
            ("intensity", 4, 'F'),
        ],
        0,
        "binary",
    );
    let (e, msg) = read_err("a.pcd", h.as_bytes());
    assert!(matches!(e, IoError::Header { .. }));
    assert_has(&msg, &["field x", "SIZE 2"]);
}

#[test]
fn pcd_unknown_type_letter_is_a_header_error() {
    let h = "FIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F Q F\nWIDTH 0\nDATA ascii\n";
    let (_, msg) = read_err("a.pcd", h.as_bytes());
    assert_has(&msg, &["line 3", "field z", "TYPE Q"]);
}

#[test]
fn pcd_count_above_one_for_a_read_field_is_refused() {
    let h = "FIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 3 1\nWIDTH 0\nHEIGHT 1\nDATA ascii\n";
    let (_, msg) = read_err("a.pcd", h.as_bytes());
    assert_has(&msg, &["field z has COUNT 3"]);
}

#[test]
fn pcd_size_list_shorter_than_fields_is_refused() {
    let h = "FIELDS x y z intensity\nSIZE 4 4 4\nTYPE F F F F\nWIDTH 0\nDATA ascii\n";
    let (_, msg) = read_err("a.pcd", h.as_bytes());
    assert_has(&msg, &["line 2", "SIZE has 3 values for 4 FIELDS"]);
}

#[test]
fn pcd_field_listed_twice_is_refused() {
    let h = "FIELDS x y z x intensity\nSIZE 4 4 4 4 4\nTYPE F F F F F\nWIDTH 0\nDATA ascii\n";
    let (_, msg) = read_err("a.pcd", h.as_bytes());
    assert_has(&msg, &["line 1", "field x is listed twice"]);
}

#[test]
fn pcd_without_data_line_is_refused() {
    let h = "FIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nWIDTH 0\n";
    let (_, msg) = read_err("a.pcd", h.as_bytes());
    assert_has(&msg, &["ends before its DATA line"]);
}

#[test]
fn pcd_unknown_data_encoding_is_refused() {
    let h = pcd_header(&XYZI, 0, "binary_zstd");
    let (_, msg) = read_err("a.pcd", h.as_bytes());
    assert_has(&msg, &["line 10", "binary_zstd"]);
}

#[test]
fn pcd_unknown_keyword_is_refused() {
    let h = "FIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOLOUR red\nWIDTH 0\nDATA ascii\n";
    let (_, msg) = read_err("a.pcd", h.as_bytes());
    assert_has(&msg, &["line 4", "unknown header keyword \"COLOUR\""]);
}

#[test]
fn pcd_keyword_given_twice_is_refused() {
    let h = "FIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nWIDTH 0\nWIDTH 0\nDATA ascii\n";
    let (_, msg) = read_err("a.pcd", h.as_bytes());
    assert_has(&msg, &["line 5", "WIDTH appears twice (first on line 4)"]);
}

#[test]
fn pcd_non_numeric_width_is_refused() {
    let h = "FIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nWIDTH many\nDATA ascii\n";
    let (_, msg) = read_err("a.pcd", h.as_bytes());
    assert_has(&msg, &["line 4", "WIDTH value \"many\""]);
}

#[test]
fn pcd_bad_viewpoint_is_refused() {
    let h = "FIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nWIDTH 0\nVIEWPOINT 0 0 0 1\nDATA ascii\n";
    let (_, msg) = read_err("a.pcd", h.as_bytes());
    assert_has(&msg, &["line 5", "VIEWPOINT needs 7 numbers"]);
}

#[test]
fn pcd_binary_header_line_that_is_not_text_is_refused() {
    let mut b = b"FIELDS x y z intensity\n".to_vec();
    b.extend([0xFF, 0xFE, b'\n']);
    let (_, msg) = read_err("a.pcd", &b);
    assert_has(&msg, &["line 2", "not UTF-8"]);
}

// ---------------------------------------------------------------- PCD data

#[test]
fn pcd_binary_truncated_data_is_a_size_error() {
    let mut b = pcd_binary(&[[1.0, 2.0, 3.0, 4.0], [5.0, 6.0, 7.0, 8.0]]);
    b.truncate(b.len() - 3);
    let (e, msg) = read_err("a.pcd", &b);
    assert!(matches!(
        e,
        IoError::DataSize {
            expected: 32,
            found: 29,
            ..
        }
    ));
    assert_has(
        &msg,
        &["2 points of 16 bytes", "expected 32 bytes", "found 29"],
    );
}

#[test]
fn pcd_binary_with_trailing_bytes_is_a_size_error() {
    let mut b = pcd_binary(&[[1.0, 2.0, 3.0, 4.0]]);
    b.extend([0u8; 4]);
    let (e, _) = read_err("a.pcd", &b);
    assert!(matches!(
        e,
        IoError::DataSize {
            expected: 16,
            found: 20,
            ..
        }
    ));
}

#[test]
fn pcd_binary_non_finite_value_names_the_point_and_field() {
    let b = pcd_binary(&[[1.0, 2.0, 3.0, 4.0], [5.0, 6.0, f32::NEG_INFINITY, 8.0]]);
    let (e, msg) = read_err("a.pcd", &b);
    assert!(matches!(
        e,
        IoError::NonFinite {
            point: 1,
            field: "z",
            ..
        }
    ));
    assert_has(&msg, &["point 1", "z is -inf"]);
}

#[test]
fn pcd_negative_ring_is_refused() {
    let fields = [
        ("x", 4, 'F'),
        ("y", 4, 'F'),
        ("z", 4, 'F'),
        ("intensity", 4, 'F'),
        ("ring", 2, 'I'),
    ];
    let mut b = pcd_header(&fields, 1, "binary").into_bytes();
    b.extend(f32s(&[1.0, 2.0, 3.0, 4.0]));
    b.extend((-3i16).to_le_bytes());
    let (e, msg) = read_err("a.pcd", &b);
    assert!(matches!(
        e,
        IoError::BadValue {
            point: 0,
            field: "ring",
            ..
        }
    ));
    assert_has(&msg, &["-3 is not a ring id"]);
}

#[test]
fn pcd_fractional_float_ring_is_refused() {
    let fields = [
        ("x", 4, 'F'),
        ("y", 4, 'F'),
        ("z", 4, 'F'),
        ("intensity", 4, 'F'),
        ("ring", 4, 'F'),
    ];
    let mut b = pcd_header(&fields, 1, "binary").into_bytes();
    b.extend(f32s(&[1.0, 2.0, 3.0, 4.0, 2.5]));
    let (_, msg) = read_err("a.pcd", &b);
    assert_has(&msg, &["point 0", "ring", "2.5"]);
}

#[test]
fn pcd_ascii_with_fewer_lines_than_points_is_refused() {
    let mut t = pcd_header(&XYZI, 3, "ascii");
    t.push_str("1 2 3 4\n5 6 7 8\n");
    let (e, msg) = read_err("a.pcd", t.as_bytes());
    assert!(matches!(
        e,
        IoError::PointCount {
            expected: 3,
            found: 2,
            ..
        }
    ));
    assert_has(&msg, &["announces 3 points", "holds 2"]);
}

#[test]
fn pcd_ascii_with_more_lines_than_points_is_refused() {
    let mut t = pcd_header(&XYZI, 1, "ascii");
    t.push_str("1 2 3 4\n5 6 7 8\n9 9 9 9\n");
    let (e, msg) = read_err("a.pcd", t.as_bytes());
    assert!(matches!(
        e,
        IoError::PointCount {
            line: 12,
            expected: 1,
            found: 3,
            ..
        }
    ));
    assert_has(&msg, &["line 12"]);
}

#[test]
fn pcd_ascii_bad_number_names_line_and_field() {
    let mut t = pcd_header(&XYZI, 2, "ascii");
    t.push_str("1 2 3 4\n5 six 7 8\n");
    let (e, msg) = read_err("a.pcd", t.as_bytes());
    assert!(matches!(e, IoError::Parse { line: 12, .. }));
    assert_has(&msg, &["line 12", "column y", "\"six\""]);
}

#[test]
fn pcd_ascii_wrong_value_count_names_the_line() {
    let mut t = pcd_header(&XYZI, 2, "ascii");
    t.push_str("1 2 3 4\n5 6 7\n");
    let (_, msg) = read_err("a.pcd", t.as_bytes());
    assert_has(&msg, &["line 12", "3 values for 4 fields"]);
}

#[test]
fn pcd_ascii_nan_names_the_point() {
    let mut t = pcd_header(&XYZI, 2, "ascii");
    t.push_str("1 2 3 4\nnan 6 7 8\n");
    let (e, _) = read_err("a.pcd", t.as_bytes());
    assert!(matches!(
        e,
        IoError::NonFinite {
            point: 1,
            field: "x",
            ..
        }
    ));
}

#[test]
fn pcd_time_beyond_f32_is_refused() {
    let fields = [
        ("x", 4, 'F'),
        ("y", 4, 'F'),
        ("z", 4, 'F'),
        ("intensity", 4, 'F'),
        ("time", 8, 'F'),
    ];
    let mut t = pcd_header(&fields, 2, "ascii");
    t.push_str("1 2 3 4 0.5\n1 2 3 4 1e300\n");
    let (e, msg) = read_err("a.pcd", t.as_bytes());
    assert!(
        matches!(
            e,
            IoError::NonFinite {
                point: 1,
                field: "time",
                ..
            }
        ),
        "{msg}"
    );
    assert_has(&msg, &["time is 1e300"]);
}

/// A valid binary_compressed file of 2 points, for the corruption tests.
fn compressed_pcd() -> (Vec<u8>, usize) {
    let cloud = synthetic(2, false);
    let opts = WriteOptions {
        format: PointFormat::Pcd,
        pcd_data: PcdData::BinaryCompressed,
    };
    let b = encode_cloud(&cloud, &opts, Path::new("x.pcd")).unwrap();
    let data = b
        .windows(23)
        .position(|w| w == b"DATA binary_compressed\n")
        .unwrap()
        + 23;
    (b, data)
}

#[test]
fn pcd_compressed_size_word_disagreeing_with_the_file_is_refused() {
    let (mut b, d) = compressed_pcd();
    let comp = u32::from_le_bytes(b[d..d + 4].try_into().unwrap());
    b[d..d + 4].copy_from_slice(&(comp + 10).to_le_bytes());
    let (e, msg) = read_err("a.pcd", &b);
    assert!(matches!(e, IoError::DataSize { .. }));
    assert_has(
        &msg,
        &[&format!("announcing {} compressed bytes", comp + 10)],
    );
}

#[test]
fn pcd_uncompressed_size_word_disagreeing_with_the_header_is_refused() {
    let (mut b, d) = compressed_pcd();
    b[d + 4..d + 8].copy_from_slice(&1000u32.to_le_bytes());
    let (e, msg) = read_err("a.pcd", &b);
    assert!(matches!(
        e,
        IoError::DataSize {
            expected: 36,
            found: 1000,
            ..
        }
    ));
    assert_has(&msg, &["uncompressed size word"]);
}

#[test]
fn pcd_corrupted_lzf_stream_is_a_compression_error() {
    let (mut b, d) = compressed_pcd();
    // A back reference before the start of the output.
    b[d + 8] = 0xE0;
    let (e, msg) = read_err("a.pcd", &b);
    assert!(matches!(e, IoError::Compression { .. }));
    assert_has(&msg, &["LZF"]);
}

#[test]
fn pcd_compressed_block_missing_its_size_words_is_refused() {
    let h = pcd_header(&XYZI, 1, "binary_compressed");
    let mut b = h.into_bytes();
    b.extend([1, 2, 3]);
    let (e, _) = read_err("a.pcd", &b);
    assert!(matches!(
        e,
        IoError::DataSize {
            expected: 8,
            found: 3,
            ..
        }
    ));
}

#[test]
fn pcd_compressed_size_beyond_what_lzf_can_expand_is_refused_before_allocating() {
    let h = pcd_header(&XYZI, 100_000_000, "binary_compressed");
    let mut b = h.into_bytes();
    b.extend(4u32.to_le_bytes());
    b.extend(1_600_000_000u32.to_le_bytes());
    b.extend([0, 0, 0, 0]);
    let (e, msg) = read_err("a.pcd", &b);
    assert!(matches!(e, IoError::Compression { .. }));
    assert_has(&msg, &["cannot expand"]);
}

// ---------------------------------------------------------------- CSV

#[test]
fn csv_without_intensity_column_is_a_missing_field_error() {
    let (e, msg) = read_err("a.csv", b"x,y,z,ring\n1,2,3,4\n");
    assert!(matches!(
        e,
        IoError::MissingField {
            field: "intensity",
            ..
        }
    ));
    assert_has(&msg, &["x, y, z, ring"]);
}

#[test]
fn csv_bad_number_names_line_and_column() {
    let (e, msg) = read_err(
        "a.csv",
        b"x,y,z,intensity,ring\n1,2,3,4,5\n1,2,3,bright,5\n",
    );
    assert!(matches!(e, IoError::Parse { line: 3, .. }));
    assert_has(&msg, &["line 3", "column intensity", "\"bright\""]);
}

#[test]
fn csv_non_finite_coordinate_names_the_point() {
    let (e, _) = read_err("a.csv", b"x,y,z,intensity\n1,2,3,4\n1,inf,3,4\n");
    assert!(matches!(
        e,
        IoError::NonFinite {
            point: 1,
            field: "y",
            ..
        }
    ));
}

#[test]
fn csv_row_with_a_missing_cell_names_the_line() {
    let (e, msg) = read_err("a.csv", b"x,y,z,intensity\n1,2,3,4\n1,2,3\n");
    assert!(matches!(e, IoError::Parse { line: 3, .. }));
    assert_has(&msg, &["line 3"]);
}

#[test]
fn csv_empty_cell_names_line_and_column() {
    let (_, msg) = read_err("a.csv", b"x,y,z,intensity\n1,,3,4\n");
    assert_has(&msg, &["line 2", "column y", "empty cell"]);
}

#[test]
fn csv_two_columns_for_one_field_are_refused() {
    let (_, msg) = read_err("a.csv", b"x,y,X,z,intensity\n1,1,2,3,4\n");
    assert_has(&msg, &["line 1", "column 1 and column 3 both give x"]);
}

#[test]
fn csv_negative_laser_id_is_refused() {
    let (e, _) = read_err("a.csv", b"x,y,z,intensity,laser_id\n1,2,3,4,-2\n");
    assert!(matches!(
        e,
        IoError::BadValue {
            point: 0,
            field: "ring",
            ..
        }
    ));
}

// ---------------------------------------------------------------- Parquet

#[cfg(feature = "parquet")]
#[test]
fn parquet_that_is_not_parquet_is_refused() {
    let (e, _) = read_err("a.parquet", b"this is not a parquet file at all");
    assert!(matches!(e, IoError::Parquet { .. }));
}

#[cfg(feature = "parquet")]
#[test]
fn parquet_without_z_column_is_a_missing_field_error() {
    use polars::prelude::*;
    let mut df = df!("x" => [1.0f32], "y" => [2.0f32], "intensity" => [3.0f32]).unwrap();
    let mut bytes = Vec::new();
    ParquetWriter::new(&mut bytes).finish(&mut df).unwrap();
    let (e, _) = read_err("a.parquet", &bytes);
    assert!(matches!(e, IoError::MissingField { field: "z", .. }));
}

#[cfg(feature = "parquet")]
#[test]
fn parquet_string_column_is_a_type_error() {
    use polars::prelude::*;
    let mut df = df!("x" => ["1"], "y" => [2.0f64], "z" => [3i32], "intensity" => [3i64]).unwrap();
    let mut bytes = Vec::new();
    ParquetWriter::new(&mut bytes).finish(&mut df).unwrap();
    let (e, msg) = read_err("a.parquet", &bytes);
    assert!(matches!(e, IoError::ColumnType { .. }));
    assert_has(&msg, &["column x"]);
}

#[cfg(feature = "parquet")]
#[test]
fn parquet_null_value_names_the_row() {
    use polars::prelude::*;
    let mut df = df!(
        "x" => [1.0f64, 2.0, 3.0],
        "y" => [2.0f64, 2.0, 2.0],
        "z" => [Some(3.0f64), None, Some(1.0)],
        "intensity" => [3.0f64, 3.0, 3.0],
    )
    .unwrap();
    let mut bytes = Vec::new();
    ParquetWriter::new(&mut bytes).finish(&mut df).unwrap();
    let (e, msg) = read_err("a.parquet", &bytes);
    assert!(matches!(
        e,
        IoError::BadValue {
            point: 1,
            field: "z",
            ..
        }
    ));
    assert_has(&msg, &["point 1", "null"]);
}

#[cfg(feature = "parquet")]
#[test]
fn parquet_non_finite_value_names_the_row() {
    use polars::prelude::*;
    let mut df = df!(
        "x" => [1.0f64, 2.0],
        "y" => [2.0f64, f64::NAN],
        "z" => [3.0f64, 1.0],
        "intensity" => [3.0f64, 3.0],
    )
    .unwrap();
    let mut bytes = Vec::new();
    ParquetWriter::new(&mut bytes).finish(&mut df).unwrap();
    let (e, _) = read_err("a.parquet", &bytes);
    assert!(matches!(
        e,
        IoError::NonFinite {
            point: 1,
            field: "y",
            ..
        }
    ));
}

// ---------------------------------------------------------------- options, writers

#[test]
fn unknown_extension_is_a_format_error() {
    let (e, msg) = read_err("scan.las", b"LASF");
    assert!(matches!(e, IoError::Format { .. }));
    assert_has(&msg, &["las"]);
}

#[test]
fn invalid_lidar_spec_for_ring_derivation_is_refused() {
    let mut spec = LidarSpec::vlp16();
    spec.elevation_deg.clear();
    let opts = ReadOptions {
        lidar: Some(spec),
        ..ReadOptions::default()
    };
    let (e, msg) = read_err_with("000004.bin", &f32s(&[1.0, 2.0, 3.0, 0.5]), &opts);
    assert!(matches!(e, IoError::Lidar { .. }));
    assert_has(&msg, &["elevation_deg is empty"]);
}

#[test]
fn writing_a_pcap_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let e = write_cloud(
        &dir.path().join("a.pcap"),
        &synthetic(3, false),
        PointFormat::Pcap,
    )
    .unwrap_err();
    assert!(matches!(e, IoError::Format { .. }), "{e}");
}

#[test]
fn writing_a_non_finite_cloud_is_refused_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.pcd");
    let mut c = synthetic(10, false);
    c.intensity[7] = f32::NAN;
    let e = write_cloud(&path, &c, PointFormat::Pcd).unwrap_err();
    assert!(matches!(e, IoError::InvalidCloud { point: 7, .. }), "{e}");
    assert!(!path.exists());
}

#[test]
fn writing_a_ragged_cloud_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut c: PointCloud = synthetic(10, false);
    c.ring.pop();
    let e = write_cloud(&dir.path().join("a.csv"), &c, PointFormat::Csv).unwrap_err();
    assert!(e.to_string().contains("ring has 9 values"), "{e}");
}

#[test]
fn writing_into_a_missing_folder_is_an_io_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("no/such/dir/a.pcd");
    let e = write_cloud(&path, &synthetic(3, false), PointFormat::Pcd).unwrap_err();
    assert!(matches!(e, IoError::Io { .. }));
    assert!(e.to_string().contains("a.pcd"), "{e}");
}

#[test]
fn reading_a_missing_file_is_an_io_error_naming_the_file() {
    let e = read_cloud(Path::new("/no/such/scan.pcd"), &ReadOptions::default()).unwrap_err();
    assert!(matches!(e, IoError::Io { .. }));
    assert!(e.to_string().contains("/no/such/scan.pcd"), "{e}");
}
