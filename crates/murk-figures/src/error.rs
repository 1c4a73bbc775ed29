//! The error type of this crate.

use std::path::PathBuf;

/// Errors raised while drawing or writing a figure.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FigureError {
    /// The figure file could not be written.
    #[error("{path}: {reason}: {source}")]
    Io {
        /// The figure file.
        path: PathBuf,
        /// What murk was doing.
        reason: String,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A value that cannot be plotted (non-finite), by series and index.
    #[error("{path}: series `{series}`, value {index}: {reason}")]
    BadData {
        /// The figure file that was to be written.
        path: PathBuf,
        /// Label of the series.
        series: String,
        /// 0-based index of the value in its series.
        index: usize,
        /// Why it cannot be plotted.
        reason: String,
    },
    /// An output path whose extension is not `.png` or `.svg`.
    #[error("{path}: unsupported figure format {ext:?}; expected .png or .svg")]
    UnsupportedFormat {
        /// The output path.
        path: PathBuf,
        /// Its extension as seen.
        ext: String,
    },
    /// plotters failed to draw.
    #[error("{path}: cannot draw the figure: {reason}")]
    Render {
        /// The figure file.
        path: PathBuf,
        /// plotters' explanation.
        reason: String,
    },
}
