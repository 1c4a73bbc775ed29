//! The error type of this crate: every variant names the file and where in it
//! the problem is (line, point index, column or byte offset) and why.

use std::path::PathBuf;

/// Errors raised while reading or writing a point-cloud file.
///
/// Each variant carries the file it concerns and the place in that file
/// (a line, a point index, a column or a byte count) so that a message alone
/// lets a user find the bad byte. Line numbers and point indices count from 1
/// and 0 respectively, as editors and arrays do.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IoError {
    /// The operating system refused to read or write the file.
    #[error("{path}: {action}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being attempted (`read`, `create temporary file`, …).
        action: &'static str,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The file has no bytes at all.
    #[error("{path}: empty file")]
    Empty {
        /// The file.
        path: PathBuf,
    },
    /// A PCD header line that cannot be used.
    #[error("{path}: line {line}: {reason}")]
    Header {
        /// The file.
        path: PathBuf,
        /// 1-based line number of the header line.
        line: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// A text value (CSV cell, PCD ascii token) that cannot be parsed.
    #[error("{path}: line {line}, column {column}: {reason}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: u64,
        /// Column name (or 1-based index when the file has no header).
        column: String,
        /// What is wrong with the value.
        reason: String,
    },
    /// A coordinate, intensity or time that is NaN or infinite.
    #[error("{path}: point {point}: {field} is {value:e} (not a finite 32-bit float)")]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// 0-based point index.
        point: usize,
        /// The field (`x`, `y`, `z`, `intensity`, `time`).
        field: &'static str,
        /// The value as read.
        value: f64,
    },
    /// A value of the right type but outside what the field allows (a ring
    /// id that is negative or fractional, a null in a Parquet column, …).
    #[error("{path}: point {point}: {field}: {reason}")]
    BadValue {
        /// The file.
        path: PathBuf,
        /// 0-based point index.
        point: usize,
        /// The field.
        field: &'static str,
        /// Why the value is refused.
        reason: String,
    },
    /// The data section does not have the size the header announces
    /// (truncated file, trailing bytes, bad compressed sizes).
    #[error("{path}: {reason}: expected {expected} bytes of data, found {found}")]
    DataSize {
        /// The file.
        path: PathBuf,
        /// Bytes the header implies.
        expected: u64,
        /// Bytes present.
        found: u64,
        /// What the sizes describe.
        reason: String,
    },
    /// A text data section with more or fewer points than its header says.
    #[error("{path}: line {line}: the header announces {expected} points, the data holds {found}")]
    PointCount {
        /// The file.
        path: PathBuf,
        /// 1-based line where the count went wrong (the first extra line, or
        /// the end of the file for too few points).
        line: usize,
        /// Points the header announces.
        expected: u64,
        /// Points found (so far, for too many).
        found: u64,
    },
    /// A file of fixed-size records whose size is not a multiple of the
    /// record size (KITTI `.bin`, nuScenes `.pcd.bin`).
    #[error(
        "{path}: size {size} bytes is not a multiple of the {record}-byte record: {trailing} trailing bytes after point {points}"
    )]
    TrailingBytes {
        /// The file.
        path: PathBuf,
        /// File size in bytes.
        size: u64,
        /// Record size in bytes.
        record: usize,
        /// Bytes left after the last whole record.
        trailing: usize,
        /// Whole records in the file.
        points: u64,
    },
    /// A headerless binary file whose layout the reader cannot tell from its
    /// size and was not told (`--bin-layout`, `bin_layout` in
    /// `campaign.toml`).
    #[error(
        "{path}: size {size} bytes fits {fits}: {why}; say which with --bin-layout xyzi|xyzir|xyzit (bin_layout in campaign.toml [lidar])"
    )]
    AmbiguousLayout {
        /// The file.
        path: PathBuf,
        /// File size in bytes.
        size: u64,
        /// The layouts the size fits, in words.
        fits: String,
        /// Why none of them was taken.
        why: String,
    },
    /// A CSV file whose first line is numbers, not column names, read
    /// without declared columns.
    #[error(
        "{path}: line 1 ({first_line}) is data, not a header: give the columns with --columns, e.g. --columns x,y,z,intensity,ring (csv_columns in campaign.toml [lidar])"
    )]
    NoHeader {
        /// The file.
        path: PathBuf,
        /// The first line's cells, comma separated.
        first_line: String,
    },
    /// A field (PCD) or column (CSV, Parquet) the reader needs is absent.
    #[error("{path}: no {field} field/column (found: {found})")]
    MissingField {
        /// The file.
        path: PathBuf,
        /// The missing field.
        field: &'static str,
        /// The fields or columns present, comma separated.
        found: String,
    },
    /// A column whose type cannot hold the field (Parquet string column, …).
    #[error("{path}: column {column}: {reason}")]
    ColumnType {
        /// The file.
        path: PathBuf,
        /// The column.
        column: String,
        /// Why its type is refused.
        reason: String,
    },
    /// LZF compression or decompression failed (PCD `binary_compressed`).
    #[error("{path}: byte {offset}: LZF: {reason}")]
    Compression {
        /// The file.
        path: PathBuf,
        /// Byte offset of the compressed block in the file.
        offset: usize,
        /// What failed.
        reason: String,
    },
    /// Parquet decoding or encoding failed.
    #[error("{path}: parquet: {reason}")]
    Parquet {
        /// The file.
        path: PathBuf,
        /// The library's message.
        reason: String,
    },
    /// A Velodyne capture could not be decoded (the decoder's error names
    /// the file, the packet index and its byte offset).
    ///
    /// The decoder's error is the message, not a `source`: an error chain
    /// printer (`anyhow`'s `{:#}`) would otherwise print it twice.
    #[error("{reason}")]
    Pcap {
        /// The file.
        path: PathBuf,
        /// What the decoder reported.
        reason: murk_velodyne::VelodyneError,
    },
    /// The format is unknown, or murk cannot write it (pcap).
    #[error("{path}: {reason}")]
    Format {
        /// The file.
        path: PathBuf,
        /// Why the format cannot be used.
        reason: String,
    },
    /// The sensor description given to derive rings is unusable.
    #[error("{path}: cannot derive rings from elevation: {reason}")]
    Lidar {
        /// The file being read.
        path: PathBuf,
        /// Why the sensor description is refused.
        reason: String,
    },
    /// A cloud handed to a writer cannot be written faithfully (ragged
    /// columns, a non-finite value, more points than the format can count).
    #[error("{path}: cannot write point {point}: {reason}")]
    InvalidCloud {
        /// The file being written.
        path: PathBuf,
        /// The first offending point (0 when the whole cloud is at fault).
        point: usize,
        /// Why.
        reason: String,
    },
}
