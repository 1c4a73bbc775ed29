//! The error type of murk-fit.

use std::path::PathBuf;

/// Everything that stops a fit.
///
/// Bad input names the file and the point, packet or line; a value that the
/// data cannot determine (a slope with no usable MOR bin, a Gaussian with no
/// return) is not an error but a `null` with a reason in the table.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FitError {
    /// A hyperparameter outside its range (see [`crate::FitParams`]).
    #[error("invalid fit parameter {name} = {value}: {reason}")]
    InvalidParam {
        /// Parameter name as in the `FitParams` table.
        name: &'static str,
        /// The rejected value.
        value: String,
        /// Why it is rejected.
        reason: String,
    },
    /// The campaign has no usable clear recording, so there is no reference.
    #[error("{path}: no clear reference: {reason}")]
    NoClearReference {
        /// Campaign folder.
        path: PathBuf,
        /// Why (no clear recording selected, or none with a return).
        reason: String,
    },
    /// A point that cannot be placed in the reference grid.
    #[error("{path}: point {point}: {reason}")]
    BadPoint {
        /// The point-cloud file.
        path: PathBuf,
        /// Index of the point in the file's order.
        point: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// A point-cloud file that cannot be read.
    #[error(transparent)]
    Read(#[from] murk_io::IoError),
    /// The campaign folder cannot be used.
    #[error(transparent)]
    Campaign(#[from] murk_campaign::CampaignError),
    /// A radar file that cannot be read.
    #[error("{path}: line {line}: {reason}")]
    Radar {
        /// The radar file.
        path: PathBuf,
        /// 1-based line (0 for the file as a whole).
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A file that cannot be read for hashing or written.
    #[error("{path}: {reason}")]
    File {
        /// The file.
        path: PathBuf,
        /// The operating-system error or other reason.
        reason: String,
    },
    /// The recordings a partial fit is asked to map do not fit the campaign
    /// or the phase.
    #[error("{reason}")]
    Selection {
        /// What is wrong with the selection.
        reason: String,
    },
    /// A fit state that cannot be read (not a state, truncated, corrupted,
    /// of another format or murk version).
    #[error("{state}: {reason}")]
    State {
        /// The state's file (or what it holds, for a state in memory).
        state: String,
        /// What is wrong.
        reason: String,
    },
    /// Two fit states that cannot be merged.
    #[error("{a} and {b} cannot be merged: {reason}")]
    StateMismatch {
        /// The first state.
        a: String,
        /// The second state.
        b: String,
        /// What differs.
        reason: String,
    },
    /// A fit state that lacks recordings asked for a table or a reference.
    #[error("{state} is incomplete: {missing}")]
    Incomplete {
        /// The state.
        state: String,
        /// What it lacks.
        missing: String,
    },
    /// The table failed its own validation (a bug: every value is checked
    /// before it is stored).
    #[error(transparent)]
    Table(#[from] murk_types::TypesError),
}
