//! `weather.csv`: one row of weather-sensor readings per recording.
//!
//! Every column is kept. `recording` and `timestamp` are required; the
//! sensor columns of the campaign contract (and every column a rule set reads)
//! are typed and range-checked; every further column is a scan-level
//! covariate, numeric when each non-empty cell parses as a number and
//! categorical otherwise. An empty cell is a sensor outage (`None`).
//!
//! The file is read with the `csv` crate rather than polars because the csv
//! reader reports the line of every record, and every error here must name
//! its line; polars' CSV errors do not carry one.

use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use chrono::{DateTime, Utc};
use murk_types::PointFormat;
use serde::Serialize;

use crate::error::{CampaignError, Location};
use crate::rules::RuleSet;
use crate::suggest;
use crate::vocabulary::{Cell, Covariate, KNOWN_SENSOR_COLUMNS, SensorKind, columns};

/// What a column of `weather.csv` is to murk.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ColumnRole {
    /// A sensor column of the campaign contract, or a column the rule set
    /// reads.
    Sensor(SensorKind),
    /// Any further column: a scan-level covariate.
    Covariate,
}

/// One column of `weather.csv` other than `recording` and `timestamp`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Column {
    /// The header, exactly as written (trimmed).
    pub name: String,
    /// 1-based column number in the file.
    pub number: usize,
    /// Sensor or covariate.
    pub role: ColumnRole,
    /// True when every cell is numeric.
    pub numeric: bool,
}

/// The columns of a campaign, shared by its recordings.
#[derive(Debug, Default)]
pub(crate) struct Columns {
    pub(crate) list: Vec<Column>,
    index: HashMap<String, usize>,
}

impl Columns {
    pub(crate) fn position(&self, name: &str) -> Option<usize> {
        self.index.get(name).copied()
    }
}

/// A point-cloud file of a recording.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct LidarFile {
    /// Path of the file (campaign folder joined with `lidar/<name>`).
    pub path: PathBuf,
    /// Its format, from the extension.
    pub format: PointFormat,
}

/// The row of `review.csv` about a recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Review {
    /// The camera check kept the recording.
    pub keep: bool,
    /// The reviewer's reason, when given.
    pub reason: Option<String>,
    /// 1-based line in `review.csv`.
    pub line: usize,
}

/// One recording: its row of `weather.csv`, its files and its review.
#[derive(Debug, Clone)]
pub struct Recording {
    pub(crate) id: String,
    pub(crate) line: usize,
    pub(crate) timestamp: DateTime<Utc>,
    pub(crate) columns: Arc<Columns>,
    pub(crate) cells: Vec<Option<Cell>>,
    pub(crate) lidar: LidarFile,
    pub(crate) radar: Option<PathBuf>,
    pub(crate) review: Option<Review>,
}

impl Recording {
    /// The recording id (file stem).
    pub fn id(&self) -> &str {
        &self.id
    }

    /// 1-based line of the recording in `weather.csv`.
    pub fn line(&self) -> usize {
        self.line
    }

    /// Time of the recording, UTC.
    pub fn timestamp(&self) -> DateTime<Utc> {
        self.timestamp
    }

    /// The cell of `column` (exact header), or `None` when the column does
    /// not exist or the cell is empty (a sensor outage).
    pub fn value(&self, column: &str) -> Option<&Cell> {
        let i = self.columns.position(column)?;
        self.cells[i].as_ref()
    }

    /// The number in `column`, when the column exists, the cell is not empty
    /// and it is numeric.
    pub fn number(&self, column: &str) -> Option<f64> {
        self.value(column).and_then(Cell::as_f64)
    }

    /// The scan-level covariates of this recording, in header order, `None`
    /// for an empty cell.
    pub fn covariates(&self) -> impl Iterator<Item = (&str, Option<&Covariate>)> {
        self.columns
            .list
            .iter()
            .zip(&self.cells)
            .filter(|(c, _)| c.role == ColumnRole::Covariate)
            .map(|(c, v)| (c.name.as_str(), v.as_ref()))
    }

    /// Every weather column of this recording (sensors and covariates), in
    /// header order, `None` for an empty cell.
    pub fn values(&self) -> impl Iterator<Item = (&str, Option<&Cell>)> {
        self.columns
            .list
            .iter()
            .zip(&self.cells)
            .map(|(c, v)| (c.name.as_str(), v.as_ref()))
    }

    /// The point-cloud file.
    pub fn lidar(&self) -> &LidarFile {
        &self.lidar
    }

    /// The radar file, when `radar/` has one for this recording.
    pub fn radar(&self) -> Option<&Path> {
        self.radar.as_deref()
    }

    /// The row of `review.csv` about this recording, when it has one.
    pub fn review(&self) -> Option<&Review> {
        self.review.as_ref()
    }
}

/// A parsed `weather.csv` before its recordings are paired with files.
pub(crate) struct WeatherTable {
    pub(crate) columns: Arc<Columns>,
    pub(crate) rows: Vec<WeatherRow>,
}

/// One parsed row.
pub(crate) struct WeatherRow {
    pub(crate) id: String,
    pub(crate) line: usize,
    pub(crate) timestamp: DateTime<Utc>,
    pub(crate) cells: Vec<Option<Cell>>,
}

/// Maps a `csv` error to ours, with the line it happened on.
pub(crate) fn csv_error(path: &Path, e: &csv::Error) -> CampaignError {
    let line = e.position().map_or(0, |p| p.line() as usize);
    let reason = match e.kind() {
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => format!("row has {len} fields, the header has {expected_len}"),
        csv::ErrorKind::Utf8 { err, .. } => format!("invalid UTF-8 in field {}", err.field() + 1),
        csv::ErrorKind::Io(io) => io.to_string(),
        _ => e.to_string(),
    };
    CampaignError::Csv {
        path: path.to_path_buf(),
        line,
        reason,
    }
}

/// Reads the header of a CSV file: trimmed names, no duplicates.
pub(crate) fn read_header(
    path: &Path,
    reader: &mut csv::Reader<&[u8]>,
) -> Result<Vec<String>, CampaignError> {
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| csv_error(path, &e))?
        .iter()
        .map(|h| h.trim().to_string())
        .collect();
    let mut seen: HashMap<&str, usize> = HashMap::new();
    for (i, h) in header.iter().enumerate() {
        if let Some(first) = seen.insert(h, i + 1) {
            return Err(CampaignError::DuplicateColumn {
                path: path.to_path_buf(),
                header: h.clone(),
                first,
                second: i + 1,
            });
        }
    }
    Ok(header)
}

/// Finds a required column, suggesting a near miss when it is absent.
pub(crate) fn require_column(
    path: &Path,
    header: &[String],
    wanted: &str,
    needed_by: &str,
) -> Result<usize, CampaignError> {
    if let Some(i) = header.iter().position(|h| h == wanted) {
        return Ok(i);
    }
    let suggestion = suggest::nearest(wanted, header.iter().map(String::as_str).enumerate())
        .map(|(i, h)| (i + 1, h.to_string()));
    Err(CampaignError::MissingColumn {
        path: path.to_path_buf(),
        column: wanted.to_string(),
        needed_by: needed_by.to_string(),
        suggestion,
    })
}

/// A CSV reader over `bytes` that trims fields and reports lines.
pub(crate) fn csv_reader(bytes: &[u8]) -> csv::Reader<&[u8]> {
    csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .from_reader(bytes)
}

/// Parses a number the way every numeric column is parsed: finite decimal.
pub(crate) fn parse_number(s: &str) -> Option<f64> {
    s.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// Parses `weather.csv` given the rule set that will read it.
pub(crate) fn parse(
    path: &Path,
    bytes: &[u8],
    rules: &RuleSet,
) -> Result<WeatherTable, CampaignError> {
    let mut reader = csv_reader(bytes);
    let header = read_header(path, &mut reader)?;
    let id_col = require_column(
        path,
        &header,
        columns::RECORDING,
        "required by the campaign format",
    )?;
    let ts_col = require_column(
        path,
        &header,
        columns::TIMESTAMP,
        "required by the campaign format",
    )?;
    let rule_needed_by = format!("read by rule set `{}`", rules.name());
    for (col, _) in rules.columns() {
        require_column(path, &header, col, &rule_needed_by)?;
    }
    let roles = column_roles(path, &header, rules)?;

    let mut records = Vec::new();
    for rec in reader.records() {
        let rec = rec.map_err(|e| csv_error(path, &e))?;
        let line = rec.position().map_or(0, |p| p.line() as usize);
        records.push((line, rec));
    }

    let mut list = Vec::new();
    let mut kept_fields = Vec::new();
    for (i, name) in header.iter().enumerate() {
        if i == id_col || i == ts_col {
            continue;
        }
        let role = roles[i];
        let numeric = match role {
            ColumnRole::Sensor(SensorKind::WeatherType | SensorKind::Text) => false,
            ColumnRole::Sensor(_) => true,
            ColumnRole::Covariate => {
                records.iter().any(|(_, r)| !r[i].is_empty())
                    && records
                        .iter()
                        .all(|(_, r)| r[i].is_empty() || parse_number(&r[i]).is_some())
            }
        };
        list.push(Column {
            name: name.clone(),
            number: i + 1,
            role,
            numeric,
        });
        kept_fields.push(i);
    }
    let index = list
        .iter()
        .enumerate()
        .map(|(k, c)| (c.name.clone(), k))
        .collect();
    let columns = Arc::new(Columns { list, index });

    let mut rows = Vec::with_capacity(records.len());
    let mut first_line: HashMap<String, usize> = HashMap::new();
    for (line, rec) in &records {
        let line = *line;
        let id = rec[id_col].to_string();
        if id.is_empty() {
            return Err(bad(path, line, id_col, &header, "", "empty recording id"));
        }
        if let Some(first) = first_line.insert(id.clone(), line) {
            return Err(CampaignError::DuplicateRecording {
                path: path.to_path_buf(),
                id,
                first_line: first,
                second_line: line,
            });
        }
        let ts_text = &rec[ts_col];
        let timestamp = DateTime::parse_from_rfc3339(ts_text)
            .map_err(|e| {
                bad(
                    path,
                    line,
                    ts_col,
                    &header,
                    ts_text,
                    &format!(
                        "timestamp `{ts_text}` is not RFC 3339 (e.g. 2023-01-14T05:00:00Z): {e}"
                    ),
                )
            })?
            .with_timezone(&Utc);
        let mut cells = Vec::with_capacity(kept_fields.len());
        for (col, &i) in columns.list.iter().zip(&kept_fields) {
            cells.push(parse_cell(path, line, i, &header, &rec[i], col)?);
        }
        rows.push(WeatherRow {
            id,
            line,
            timestamp,
            cells,
        });
    }
    Ok(WeatherTable { columns, rows })
}

/// The role of every header column; also rejects headers that look like a
/// misspelling of a known sensor column the file lacks.
fn column_roles(
    path: &Path,
    header: &[String],
    rules: &RuleSet,
) -> Result<Vec<ColumnRole>, CampaignError> {
    let mut known: HashMap<&str, SensorKind> = KNOWN_SENSOR_COLUMNS.iter().copied().collect();
    for name in rules.intensity() {
        known.insert(name, SensorKind::Mor);
    }
    for name in rules.rain_rate() {
        known.entry(name).or_insert(SensorKind::RainRate);
    }
    for (name, numeric) in rules.columns() {
        let kind = if numeric {
            SensorKind::Number
        } else {
            SensorKind::Text
        };
        known.entry(name).or_insert(kind);
    }
    let present: BTreeSet<&str> = header.iter().map(String::as_str).collect();
    let mut roles = Vec::with_capacity(header.len());
    for (i, h) in header.iter().enumerate() {
        if let Some(kind) = known.get(h.as_str()) {
            roles.push(ColumnRole::Sensor(*kind));
            continue;
        }
        let mut near: Vec<&str> = known
            .keys()
            .chain([columns::RECORDING, columns::TIMESTAMP].iter())
            .copied()
            .filter(|k| !present.contains(k) && suggest::is_close(h, k))
            .collect();
        near.sort_by_key(|k| suggest::levenshtein(&suggest::normalize(h), &suggest::normalize(k)));
        if let Some(expected) = near.first() {
            return Err(CampaignError::MisspeltColumn {
                path: path.to_path_buf(),
                column: i + 1,
                found: h.clone(),
                expected: expected.to_string(),
            });
        }
        roles.push(ColumnRole::Covariate);
    }
    Ok(roles)
}

fn bad(
    path: &Path,
    line: usize,
    i: usize,
    header: &[String],
    value: &str,
    reason: &str,
) -> CampaignError {
    CampaignError::BadValue {
        path: path.to_path_buf(),
        at: Location::cell(line, i + 1, header[i].clone()),
        value: value.to_string(),
        reason: reason.to_string(),
    }
}

fn parse_cell(
    path: &Path,
    line: usize,
    i: usize,
    header: &[String],
    text: &str,
    col: &Column,
) -> Result<Option<Cell>, CampaignError> {
    if text.is_empty() {
        return Ok(None);
    }
    let fail = |reason: String| Err(bad(path, line, i, header, text, &reason));
    let kind = match col.role {
        ColumnRole::Sensor(k) => Some(k),
        ColumnRole::Covariate => None,
    };
    if kind == Some(SensorKind::WeatherType) {
        return match columns::WEATHER_TYPES
            .iter()
            .find(|w| w.eq_ignore_ascii_case(text))
        {
            Some(_) => Ok(Some(Cell::Categorical(text.to_string()))),
            None => fail(format!(
                "`{text}` is not a weather type; expected one of {}",
                columns::WEATHER_TYPES.join(", ")
            )),
        };
    }
    if !col.numeric {
        return Ok(Some(Cell::Categorical(text.to_string())));
    }
    let Some(v) = parse_number(text) else {
        return fail(format!("`{text}` is not a number (numeric column)"));
    };
    match kind {
        Some(SensorKind::RainRate) if v < 0.0 => fail(format!("negative rain rate {v} mm/h")),
        Some(SensorKind::Mor) if v <= 0.0 => fail(format!(
            "MOR {v} m is not positive (a meteorological optical range is > 0)"
        )),
        _ => Ok(Some(Cell::Numeric(v))),
    }
}
