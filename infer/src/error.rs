//! The error type of murk-infer.
//!
//! Every variant says *where* (the table and field, the scan and point index,
//! or the file) and *why*, so that a message alone is enough to fix the input.

use std::path::PathBuf;

/// Errors raised while checking parameters, applying a model or running a
/// batch.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum InferError {
    /// The coefficient table file could not be read or failed validation.
    #[error(transparent)]
    Table(#[from] murk_types::TypesError),

    /// The requested weather is not in the table.
    #[error("{table}: weathers.{weather}: not in the table ({reason}); the table has: {available}")]
    WeatherAbsent {
        /// Which table (its file, or its campaign when built in memory).
        table: String,
        /// The weather asked for.
        weather: String,
        /// Why the table lacks it (its `absent` entry), or `not fitted`.
        reason: String,
        /// The weathers the table does have, comma separated.
        available: String,
    },

    /// A coefficient the chosen options need is null or missing in the table.
    #[error("{table}: {field}: {reason}")]
    MissingCoefficient {
        /// Which table.
        table: String,
        /// JSON path of the field (`weathers.fog.vanishing_slope[0].slope`).
        field: String,
        /// Why it is needed and why it is absent.
        reason: String,
    },

    /// A parameter value outside its range.
    #[error("parameter {name} = {value}: {reason}")]
    InvalidParam {
        /// Parameter name as in the [`crate::ApplyParams`] table.
        name: &'static str,
        /// The value given.
        value: String,
        /// The allowed range.
        reason: String,
    },

    /// A rain rate outside the validity range of the table's rate → MOR
    /// conversion (and `clamp` not set).
    #[error(
        "{table}: weathers.rain.mor_from_rain_rate: rain rate {rate} mm/h is outside the conversion's validity [{min}, {max}] mm/h ({reason}); pass a rate inside it, give a MOR instead, or clamp it into the range (`--clamp` in murk apply, `clamp_rain_rate` in ApplyParams)"
    )]
    RainRateOutOfRange {
        /// Which table.
        table: String,
        /// The rate asked for, mm/h.
        rate: f64,
        /// Lowest valid rate, mm/h, as printed (rounded up to 4 significant
        /// digits, so that the rate printed is inside the range).
        min: String,
        /// Highest valid rate, mm/h (`inf` when unbounded), as printed
        /// (rounded down to 4 significant digits).
        max: String,
        /// Where the range comes from.
        reason: String,
    },

    /// Two settings that cannot be combined.
    #[error("conflicting settings: {0}")]
    Conflict(String),

    /// A point cloud whose columns disagree.
    #[error("scan {scan}: {reason}")]
    BadCloud {
        /// The scan's key (its relative path in a batch).
        scan: String,
        /// What is wrong.
        reason: String,
    },

    /// A ring id that the given sensor description does not have.
    #[error(
        "scan {scan}: point {point}: ring {ring} is not a ring of the sensor description ({rings} rings): give the sensor's description or leave it out to take ring elevations from the scan"
    )]
    RingOutsideSpec {
        /// The scan's key.
        scan: String,
        /// 0-based point index.
        point: usize,
        /// The ring id found.
        ring: u16,
        /// Number of rings in the description.
        rings: usize,
    },

    /// Reading or writing a point-cloud file failed.
    #[error(transparent)]
    Io(#[from] murk_io::IoError),

    /// A batch stopped on request (Ctrl-C) before every file was done.
    #[error(
        "interrupted: {done} of {total} files written (each complete); the others were not started"
    )]
    Interrupted {
        /// Files written and in place.
        done: usize,
        /// Files of the batch.
        total: usize,
    },

    /// A file-system operation on an input or output failed.
    #[error("{path}: {action}: {source}")]
    Fs {
        /// The path.
        path: PathBuf,
        /// What was attempted.
        action: &'static str,
        /// The underlying error.
        source: std::io::Error,
    },

    /// An input argument that cannot be used (unknown format, missing file,
    /// two inputs mapping to the same output, …).
    #[error("{path}: {reason}")]
    Input {
        /// The input path.
        path: PathBuf,
        /// Why it is refused.
        reason: String,
    },

    /// A camera calibration file that cannot be used (bad number, missing
    /// or malformed entry).
    #[error("{path}:{line}: {reason}")]
    Calib {
        /// The calibration file.
        path: PathBuf,
        /// 1-based line of the problem (for a missing entry: the last line).
        line: usize,
        /// What is wrong.
        reason: String,
    },

    /// A depth map value or shape that cannot be used.
    #[error("{source_name}: pixel (x {x}, y {y}): {reason}")]
    Depth {
        /// Where the depth map came from (file path or a description).
        source_name: String,
        /// Column of the offending pixel.
        x: usize,
        /// Row of the offending pixel.
        y: usize,
        /// What is wrong.
        reason: String,
    },

    /// The image and depth map disagree in size.
    #[error(
        "image is {image_w}x{image_h} but its depth map is {depth_w}x{depth_h}: give a depth map of the image's size"
    )]
    SizeMismatch {
        /// Image width, pixels.
        image_w: u32,
        /// Image height, pixels.
        image_h: u32,
        /// Depth map width, pixels.
        depth_w: u32,
        /// Depth map height, pixels.
        depth_h: u32,
    },

    /// An ONNX generator that cannot be loaded or run (bad model, wrong
    /// input/output shape, not 3 channels, runtime library missing, …).
    #[error("{path}: {reason}")]
    Generator {
        /// The model file (or the ONNX Runtime library when that is the
        /// problem).
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },

    /// An output would overwrite one of the inputs.
    #[error("{output}: refusing to overwrite the input {input}; choose another --out")]
    OutputIsInput {
        /// The output path that was planned.
        output: PathBuf,
        /// The input it coincides with.
        input: PathBuf,
    },
}
