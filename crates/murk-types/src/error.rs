//! The error type of this crate.

/// Errors raised while validating or parsing shared types.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TypesError {
    /// An intensity-scale name or table that murk does not know.
    #[error(
        "unknown intensity scale {0:?}: expected one of calibrated, vlp16, kitti, unit, nuscenes, byte, six-bit, or {{ gain = G, offset = O }}"
    )]
    UnknownIntensityScale(String),
    /// A weather class name that is not clear, fog, rain or snow.
    #[error("unknown weather class {0:?}: expected clear, fog, rain or snow")]
    UnknownWeather(String),
    /// A folder of inputs that cannot be listed or resolved.
    #[error("{}: cannot {action} folder: {source}", .path.display())]
    Folder {
        /// The folder.
        path: std::path::PathBuf,
        /// What failed: "list" or "resolve".
        action: &'static str,
        /// The system's error.
        source: std::io::Error,
    },
    /// A file extension that no reader handles.
    #[error(
        "{path}: unknown point-cloud format (extension {ext:?}); expected .pcd, .bin, .pcd.bin, .csv, .parquet or .pcap"
    )]
    UnknownFormat {
        /// The offending path.
        path: String,
        /// Its extension as seen.
        ext: String,
    },
    /// A sensor description that cannot be used.
    #[error("invalid lidar description: {0}")]
    InvalidLidar(String),
    /// Columns of a point cloud with different lengths.
    #[error("point cloud columns disagree: {0}")]
    RaggedCloud(String),
    /// A coefficient table that cannot be parsed or fails validation.
    #[error("{path}: coefficient table, {location}: {reason}")]
    Table {
        /// The table file (`<memory>` when parsed from a string).
        path: String,
        /// Where: a field path (`weathers.fog.vanishing_slope[1].slope`) or
        /// `line L column C` for syntax errors.
        location: String,
        /// What is wrong.
        reason: String,
    },
}
