//! Opening a campaign folder: `campaign.toml`, `weather.csv`, `review.csv`
//! and the listings of `lidar/` and `radar/`.
//!
//! **Architecture invariant:** this module pairs recording ids with file
//! paths and never opens a point cloud; reading points is `murk-io`'s job.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use murk_types::{LidarSpec, PointFormat};
use serde::{Deserialize, Serialize};
use toml::Spanned;

use crate::error::{CampaignError, Location};
use crate::rules::{PddParams, RuleSet, line_of, toml_error};
use crate::select::{self, Selection};
use crate::weather::{self, Column, ColumnRole, Columns, LidarFile, Recording, Review};

/// File and folder names of the campaign layout.
pub mod layout {
    /// Sensor and site metadata.
    pub const CAMPAIGN_TOML: &str = "campaign.toml";
    /// One row of weather readings per recording.
    pub const WEATHER_CSV: &str = "weather.csv";
    /// Optional camera-based review.
    pub const REVIEW_CSV: &str = "review.csv";
    /// Point-cloud files, one per recording.
    pub const LIDAR_DIR: &str = "lidar";
    /// Optional radar files, one per recording.
    pub const RADAR_DIR: &str = "radar";
}

/// The `[radar]` section of `campaign.toml`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RadarSpec {
    /// Free-text model name (`ZF ProWave`).
    pub model: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCampaign {
    name: String,
    rules: Spanned<String>,
    #[serde(default)]
    rule_params: BTreeMap<Spanned<String>, Spanned<f64>>,
    lidar: Spanned<LidarSpec>,
    radar: Option<RadarSpec>,
}

/// An opened, checked campaign folder.
///
/// Opening reads the metadata and CSV files and lists the recording folders;
/// it fails on the first inconsistency with the file, line and reason.
#[derive(Debug, Clone)]
pub struct Campaign {
    dir: PathBuf,
    name: String,
    lidar: LidarSpec,
    radar: Option<RadarSpec>,
    rules: RuleSet,
    rules_source: String,
    columns: Arc<Columns>,
    recordings: Vec<Recording>,
    index: HashMap<String, usize>,
    review: Option<PathBuf>,
}

fn io(path: &Path, reason: &str) -> impl FnOnce(std::io::Error) -> CampaignError {
    let path = path.to_path_buf();
    let reason = reason.to_string();
    move |source| CampaignError::Io {
        path,
        reason,
        source,
    }
}

impl Campaign {
    /// Opens the campaign folder `dir` and checks it against the campaign
    /// format.
    pub fn open(dir: impl AsRef<Path>) -> Result<Campaign, CampaignError> {
        let dir = dir.as_ref().to_path_buf();
        let toml_path = dir.join(layout::CAMPAIGN_TOML);
        let text = std::fs::read_to_string(&toml_path)
            .map_err(io(&toml_path, "cannot read campaign metadata"))?;
        let raw: RawCampaign =
            toml::from_str(&text).map_err(|e| toml_error(&toml_path, &text, &e))?;
        let lidar_line = line_of(&text, raw.lidar.span().start);
        let lidar = raw.lidar.into_inner();
        lidar.validate().map_err(|e| CampaignError::Lidar {
            path: toml_path.clone(),
            line: lidar_line,
            reason: e.to_string(),
        })?;

        let rules_source = raw.rules.get_ref().trim().to_string();
        let rules_line = line_of(&text, raw.rules.span().start);
        let mut rules = if RuleSet::PRESETS.contains(&rules_source.as_str()) {
            RuleSet::preset(&rules_source, &PddParams::default())?
        } else {
            let path = dir.join(&rules_source);
            if !path.is_file() {
                return Err(CampaignError::Toml {
                    path: toml_path,
                    line: rules_line,
                    reason: format!(
                        "rules = \"{rules_source}\" is neither a built-in rule set ({}) nor a file ({} not found)",
                        RuleSet::PRESETS.join(", "),
                        path.display()
                    ),
                });
            }
            RuleSet::from_file(&path)?
        };
        for (k, v) in &raw.rule_params {
            rules
                .set_param(k.get_ref(), *v.get_ref())
                .map_err(|reason| CampaignError::Rules {
                    path: toml_path.clone(),
                    line: line_of(&text, k.span().start),
                    reason: format!("[rule_params]: {reason}"),
                })?;
        }

        let weather_path = dir.join(layout::WEATHER_CSV);
        let bytes =
            std::fs::read(&weather_path).map_err(io(&weather_path, "cannot read weather table"))?;
        let table = weather::parse(&weather_path, &bytes, &rules)?;

        let lidar_dir = dir.join(layout::LIDAR_DIR);
        let mut lidar_files = list_lidar(&lidar_dir)?;
        let radar_dir = dir.join(layout::RADAR_DIR);
        let mut radar_files = if radar_dir.is_dir() {
            list_radar(&radar_dir)?
        } else {
            BTreeMap::new()
        };

        let mut recordings = Vec::with_capacity(table.rows.len());
        let mut index = HashMap::with_capacity(table.rows.len());
        for row in table.rows {
            let Some(lidar_file) = lidar_files.remove(&row.id) else {
                return Err(CampaignError::MissingLidar {
                    path: weather_path,
                    line: row.line,
                    id: row.id,
                    dir: lidar_dir,
                });
            };
            let radar = radar_files.remove(&row.id);
            index.insert(row.id.clone(), recordings.len());
            recordings.push(Recording {
                id: row.id,
                line: row.line,
                timestamp: row.timestamp,
                columns: Arc::clone(&table.columns),
                cells: row.cells,
                lidar: lidar_file,
                radar,
                review: None,
            });
        }
        if let Some((stem, f)) = lidar_files.into_iter().next() {
            return Err(CampaignError::OrphanFile {
                path: f.path,
                stem,
                weather: weather_path,
            });
        }
        if let Some((stem, path)) = radar_files.into_iter().next() {
            return Err(CampaignError::OrphanFile {
                path,
                stem,
                weather: weather_path,
            });
        }

        let review_path = dir.join(layout::REVIEW_CSV);
        let review = if review_path.is_file() {
            let bytes =
                std::fs::read(&review_path).map_err(io(&review_path, "cannot read review"))?;
            for (id, r) in parse_review(&review_path, &bytes, &index, &weather_path)? {
                recordings[index[&id]].review = Some(r);
            }
            Some(review_path)
        } else {
            None
        };

        Ok(Campaign {
            dir,
            name: raw.name,
            lidar,
            radar: raw.radar,
            rules,
            rules_source,
            columns: table.columns,
            recordings,
            index,
            review,
        })
    }

    /// The campaign folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The campaign's name (`name` in `campaign.toml`).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The LiDAR of the campaign.
    pub fn lidar(&self) -> &LidarSpec {
        &self.lidar
    }

    /// The radar of the campaign, when `campaign.toml` declares one.
    pub fn radar(&self) -> Option<&RadarSpec> {
        self.radar.as_ref()
    }

    /// The selection rules, with `[rule_params]` applied.
    pub fn rules(&self) -> &RuleSet {
        &self.rules
    }

    /// `rules` as written in `campaign.toml`: a preset name or a path.
    pub fn rules_source(&self) -> &str {
        &self.rules_source
    }

    /// The recordings, in `weather.csv` order.
    pub fn recordings(&self) -> &[Recording] {
        &self.recordings
    }

    /// The recording with this id.
    pub fn recording(&self, id: &str) -> Option<&Recording> {
        self.index.get(id).map(|&i| &self.recordings[i])
    }

    /// Every column of `weather.csv` except `recording` and `timestamp`, in
    /// header order.
    pub fn columns(&self) -> &[Column] {
        &self.columns.list
    }

    /// The scan-level covariate columns (those that are neither a sensor
    /// column of the campaign format nor read by the rules), in header order.
    pub fn covariate_columns(&self) -> Vec<&str> {
        self.columns
            .list
            .iter()
            .filter(|c| c.role == ColumnRole::Covariate)
            .map(|c| c.name.as_str())
            .collect()
    }

    /// The `review.csv` that was read, when the campaign has one.
    pub fn review_file(&self) -> Option<&Path> {
        self.review.as_deref()
    }

    /// Applies the rules and the review to every recording.
    pub fn select(&self) -> Selection {
        select::select(
            self.name(),
            self.rules(),
            self.recordings(),
            self.review_file().is_some(),
        )
    }
}

/// Lists `lidar/`: recording id → file, checking extensions and stems.
fn list_lidar(dir: &Path) -> Result<BTreeMap<String, LidarFile>, CampaignError> {
    let mut out: BTreeMap<String, LidarFile> = BTreeMap::new();
    for path in list_dir(dir)? {
        let format = PointFormat::from_path(&path).map_err(|e| CampaignError::UnexpectedFile {
            path: path.clone(),
            reason: format!("not a recording file: {e}"),
        })?;
        let stem = stem_of(&path, format)?;
        if let Some(first) = out.get(&stem) {
            return Err(CampaignError::DuplicateStem {
                first: first.path.clone(),
                second: path,
                stem,
            });
        }
        out.insert(stem, LidarFile { path, format });
    }
    Ok(out)
}

/// Lists `radar/`: recording id → `.csv` file.
fn list_radar(dir: &Path) -> Result<BTreeMap<String, PathBuf>, CampaignError> {
    let mut out: BTreeMap<String, PathBuf> = BTreeMap::new();
    for path in list_dir(dir)? {
        let is_csv = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
        if !is_csv {
            return Err(CampaignError::UnexpectedFile {
                path,
                reason: "not a radar file: radar/ holds one .csv per recording".into(),
            });
        }
        let stem = stem_of(&path, PointFormat::Csv)?;
        if let Some(first) = out.get(&stem) {
            return Err(CampaignError::DuplicateStem {
                first: first.clone(),
                second: path,
                stem,
            });
        }
        out.insert(stem, path);
    }
    Ok(out)
}

/// The entries of `dir`, sorted by name; sub-folders and non-UTF-8 names are
/// errors.
fn list_dir(dir: &Path) -> Result<Vec<PathBuf>, CampaignError> {
    let rd = std::fs::read_dir(dir).map_err(io(dir, "cannot list folder"))?;
    let mut paths = Vec::new();
    for entry in rd {
        let entry = entry.map_err(io(dir, "cannot list folder"))?;
        let path = entry.path();
        if entry.file_name().to_str().is_none() {
            return Err(CampaignError::UnexpectedFile {
                path,
                reason: "file name is not valid UTF-8".into(),
            });
        }
        if path.is_dir() {
            return Err(CampaignError::UnexpectedFile {
                path,
                reason: "unexpected folder: recordings are files directly in this folder".into(),
            });
        }
        paths.push(path);
    }
    paths.sort();
    Ok(paths)
}

/// The recording id of a file: its name without the format's extension.
fn stem_of(path: &Path, format: PointFormat) -> Result<String, CampaignError> {
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_default();
    let ext_len = format.extension().len() + 1;
    let stem = &name[..name.len().saturating_sub(ext_len)];
    if stem.is_empty() {
        return Err(CampaignError::UnexpectedFile {
            path: path.to_path_buf(),
            reason: "no recording id before the extension".into(),
        });
    }
    Ok(stem.to_string())
}

/// Parses `review.csv`: recording id → review, checking ids against
/// `weather.csv`.
fn parse_review(
    path: &Path,
    bytes: &[u8],
    index: &HashMap<String, usize>,
    weather_path: &Path,
) -> Result<Vec<(String, Review)>, CampaignError> {
    const KNOWN: [&str; 3] = ["recording", "keep", "reason"];
    let mut reader = weather::csv_reader(bytes);
    let header = weather::read_header(path, &mut reader)?;
    let id_col = weather::require_column(path, &header, "recording", "required by review.csv")?;
    let keep_col = weather::require_column(path, &header, "keep", "required by review.csv")?;
    let reason_col = header.iter().position(|h| h == "reason");
    for (i, h) in header.iter().enumerate() {
        if KNOWN.contains(&h.as_str()) {
            continue;
        }
        if let Some(k) = KNOWN.iter().find(|k| crate::suggest::is_close(h, k)) {
            return Err(CampaignError::MisspeltColumn {
                path: path.to_path_buf(),
                column: i + 1,
                found: h.clone(),
                expected: k.to_string(),
            });
        }
        return Err(CampaignError::BadValue {
            path: path.to_path_buf(),
            at: Location::cell(1, i + 1, h.clone()),
            value: h.clone(),
            reason: "unexpected column: review.csv has recording, keep and an optional reason"
                .into(),
        });
    }
    let mut out = Vec::new();
    let mut first_line: HashMap<String, usize> = HashMap::new();
    for rec in reader.records() {
        let rec = rec.map_err(|e| weather::csv_error(path, &e))?;
        let line = rec.position().map_or(0, |p| p.line() as usize);
        let id = rec[id_col].to_string();
        if !index.contains_key(&id) {
            return Err(CampaignError::UnknownReviewRecording {
                path: path.to_path_buf(),
                line,
                id,
                weather: weather_path.to_path_buf(),
            });
        }
        if let Some(first) = first_line.insert(id.clone(), line) {
            return Err(CampaignError::DuplicateRecording {
                path: path.to_path_buf(),
                id,
                first_line: first,
                second_line: line,
            });
        }
        let keep_text = &rec[keep_col];
        let keep = if keep_text.eq_ignore_ascii_case("true") {
            true
        } else if keep_text.eq_ignore_ascii_case("false") {
            false
        } else {
            return Err(CampaignError::BadValue {
                path: path.to_path_buf(),
                at: Location::cell(line, keep_col + 1, "keep"),
                value: keep_text.to_string(),
                reason: format!("keep must be true or false, got `{keep_text}`"),
            });
        };
        let reason = reason_col
            .map(|i| rec[i].to_string())
            .filter(|r| !r.is_empty());
        out.push((id, Review { keep, reason, line }));
    }
    Ok(out)
}
