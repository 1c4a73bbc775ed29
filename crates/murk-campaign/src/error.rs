//! The error type of this crate.
//!
//! Every variant names the file it is about and where in it (line, column,
//! the other file involved) and why, so that a user can open the file and
//! fix it without reading murk's source.

use std::path::PathBuf;

/// Where in a file an error sits: a 1-based line and, when known, the
/// 1-based column number and the column's header.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Location {
    /// 1-based line of the file (the header of a CSV file is line 1).
    pub line: usize,
    /// 1-based column number in a CSV row, when the error is about one cell.
    pub column: Option<usize>,
    /// Header of that column, when known.
    pub header: Option<String>,
}

impl Location {
    /// A whole line.
    pub fn line(line: usize) -> Self {
        Location {
            line,
            column: None,
            header: None,
        }
    }

    /// One cell of a CSV file.
    pub fn cell(line: usize, column: usize, header: impl Into<String>) -> Self {
        Location {
            line,
            column: Some(column),
            header: Some(header.into()),
        }
    }
}

impl std::fmt::Display for Location {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "line {}", self.line)?;
        match (self.column, &self.header) {
            (Some(c), Some(h)) => write!(f, ", column {c} (`{h}`)"),
            (Some(c), None) => write!(f, ", column {c}"),
            (None, Some(h)) => write!(f, ", column `{h}`"),
            (None, None) => Ok(()),
        }
    }
}

/// Errors raised while opening a campaign folder or applying its rules.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CampaignError {
    /// A file or folder could not be read.
    #[error("{path}: {reason}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// What murk was doing.
        reason: String,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A TOML file (`campaign.toml` or a rules file) that does not parse or
    /// holds a value murk cannot use.
    #[error("{path}, line {line}: {reason}")]
    Toml {
        /// The file.
        path: PathBuf,
        /// 1-based line of the offending key or value.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A rule set that cannot be used: unknown op, unknown parameter, a class
    /// without conditions, a comparison of text with a number, …
    #[error("{path}, line {line}: {reason}")]
    Rules {
        /// The rules file, or `campaign.toml` for a built-in preset.
        path: PathBuf,
        /// 1-based line of the offending rule (1 when the rule set has no
        /// source text, as for a preset with bad parameters).
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A CSV file whose structure is broken (unequal row lengths, invalid
    /// UTF-8, …).
    #[error("{path}, line {line}: malformed CSV: {reason}")]
    Csv {
        /// The file.
        path: PathBuf,
        /// 1-based line where the reader stopped.
        line: usize,
        /// The CSV reader's explanation.
        reason: String,
    },
    /// A column that must exist is absent from a CSV header.
    #[error("{path}, line 1: missing column `{column}` ({needed_by}){}", suggestion_text(.suggestion, .column))]
    MissingColumn {
        /// The CSV file.
        path: PathBuf,
        /// The column that is needed.
        column: String,
        /// Who needs it (the file format, or the rule set by name).
        needed_by: String,
        /// A header present in the file that looks like a misspelling of
        /// `column`, with its 1-based column number.
        suggestion: Option<(usize, String)>,
    },
    /// A header present in a CSV file that looks like a misspelling of a
    /// column murk knows (`PWD12_MOR(m)` for `PWD12_MOR (m)`).
    #[error(
        "{path}, line 1, column {column} (`{found}`): not a known column; did you mean `{expected}`?"
    )]
    MisspeltColumn {
        /// The CSV file.
        path: PathBuf,
        /// 1-based column number.
        column: usize,
        /// The header as written.
        found: String,
        /// The known name it resembles.
        expected: String,
    },
    /// The same header twice in one CSV file.
    #[error("{path}, line 1: column `{header}` appears twice (columns {first} and {second})")]
    DuplicateColumn {
        /// The CSV file.
        path: PathBuf,
        /// The repeated header.
        header: String,
        /// 1-based column number of the first occurrence.
        first: usize,
        /// 1-based column number of the second occurrence.
        second: usize,
    },
    /// A cell whose value cannot be used: a malformed timestamp, text in a
    /// numeric column, a negative rain rate, a non-positive MOR, a `keep`
    /// that is neither true nor false, an empty recording id, …
    #[error("{path}, {at}: {reason}")]
    BadValue {
        /// The file.
        path: PathBuf,
        /// Line and column of the cell.
        at: Location,
        /// The value as written.
        value: String,
        /// Why it cannot be used.
        reason: String,
    },
    /// The same recording id on two rows of one CSV file.
    #[error("{path}, line {second_line}: recording `{id}` already appears on line {first_line}")]
    DuplicateRecording {
        /// The CSV file (`weather.csv` or `review.csv`).
        path: PathBuf,
        /// The repeated id.
        id: String,
        /// 1-based line of the first row.
        first_line: usize,
        /// 1-based line of the second row.
        second_line: usize,
    },
    /// A recording listed in `weather.csv` without a file in `lidar/`.
    #[error("{path}, line {line}: recording `{id}` has no point-cloud file in {dir}")]
    MissingLidar {
        /// `weather.csv`.
        path: PathBuf,
        /// 1-based line of the recording's row.
        line: usize,
        /// The recording id.
        id: String,
        /// The `lidar/` folder searched.
        dir: PathBuf,
    },
    /// A file in `lidar/` or `radar/` whose stem matches no row of
    /// `weather.csv`.
    #[error("{path}: no row of {weather} has recording `{stem}`")]
    OrphanFile {
        /// The file without a weather row.
        path: PathBuf,
        /// Its stem (the recording id it would have).
        stem: String,
        /// The `weather.csv` searched.
        weather: PathBuf,
    },
    /// Two files of one folder with the same stem (`a.pcd` and `a.bin`).
    #[error("{second}: recording `{stem}` already has the file {first}")]
    DuplicateStem {
        /// The first file, in name order.
        first: PathBuf,
        /// The second file.
        second: PathBuf,
        /// The shared stem.
        stem: String,
    },
    /// A file in `lidar/` or `radar/` that is not a recording file: unknown
    /// extension, sub-folder, non-UTF-8 name.
    #[error("{path}: {reason}")]
    UnexpectedFile {
        /// The file.
        path: PathBuf,
        /// Why it is not accepted.
        reason: String,
    },
    /// A row of `review.csv` naming a recording that `weather.csv` lacks.
    #[error("{path}, line {line}: recording `{id}` is not in {weather}")]
    UnknownReviewRecording {
        /// `review.csv`.
        path: PathBuf,
        /// 1-based line of the row.
        line: usize,
        /// The unknown id.
        id: String,
        /// The `weather.csv` searched.
        weather: PathBuf,
    },
    /// The `[lidar]` section of `campaign.toml` describes a sensor murk
    /// cannot use.
    #[error("{path}, line {line}: [lidar]: {reason}")]
    Lidar {
        /// `campaign.toml`.
        path: PathBuf,
        /// 1-based line of the `[lidar]` header.
        line: usize,
        /// What is wrong.
        reason: String,
    },
}

fn suggestion_text(s: &Option<(usize, String)>, wanted: &str) -> String {
    match s {
        Some((col, found)) => format!("; column {col} is `{found}`: did you mean `{wanted}`?"),
        None => String::new(),
    }
}
