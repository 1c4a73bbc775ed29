//! The errors of murk-diagnose.

use std::path::PathBuf;

/// Everything that can stop a diagnosis.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    /// A parameter is out of range.
    #[error("invalid parameter {name} = {value}: {reason}")]
    InvalidParam {
        /// Parameter name.
        name: &'static str,
        /// Its value.
        value: String,
        /// Why it is refused.
        reason: String,
    },
    /// The campaign cannot be diagnosed for this weather.
    #[error("cannot diagnose {weather}: {reason}")]
    Campaign {
        /// The weather asked for.
        weather: String,
        /// Why.
        reason: String,
    },
    /// Fitting the baseline failed.
    #[error("fitting the baseline on {what}: {source}")]
    Fit {
        /// Which fit (fold).
        what: String,
        /// The fit's error.
        #[source]
        source: Box<murk_fit::FitError>,
    },
    /// Building or applying the model failed.
    #[error("simulating with the {what} model: {source}")]
    Infer {
        /// Which model.
        what: String,
        /// The applier's error.
        #[source]
        source: Box<murk_infer::InferError>,
    },
    /// A recording cannot be read.
    #[error("{}: {reason}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// The coefficient table given does not fit the campaign.
    #[error("coefficient table: {0}")]
    Table(String),
}
