//! Applying the rules and the review: one class per recording, and the
//! campaign's summary (the seed's Tables 3 and 6, outages, ambiguity and the
//! MOR distribution of Figure 24).

use std::path::Path;

use murk_types::WeatherClass;
use serde::{Deserialize, Serialize};

use crate::rules::{Classification, RuleSet};
use crate::vocabulary::{Cell, Covariate};
use crate::weather::{LidarFile, Recording};

/// Reason recorded for a recording that `review.csv` does not list.
pub const NOT_REVIEWED: &str = "not listed in review.csv";

/// The decision about one recording.
#[derive(Debug, Clone)]
pub struct SelectedRecording {
    recording: Recording,
    classification: Classification,
    kept: bool,
    exclusion: Option<String>,
    mor: Option<f64>,
    rain_rate: Option<f64>,
}

impl SelectedRecording {
    /// The recording id.
    pub fn id(&self) -> &str {
        self.recording.id()
    }

    /// The recording itself (weather row, files, review row).
    pub fn recording(&self) -> &Recording {
        &self.recording
    }

    /// The class the rules decided, before the review; `None` when no class
    /// matched.
    pub fn class(&self) -> Option<WeatherClass> {
        self.classification.class
    }

    /// Every class whose rules held, in priority order.
    pub fn matched_classes(&self) -> &[WeatherClass] {
        &self.classification.matched
    }

    /// True when several classes matched and `priority` chose.
    pub fn is_ambiguous(&self) -> bool {
        self.classification.is_ambiguous()
    }

    /// Classes this recording failed only because of empty cells, with the
    /// empty columns.
    pub fn outages(&self) -> &[(WeatherClass, Vec<String>)] {
        &self.classification.outages
    }

    /// True when the recording is unclassified and lost to an outage for at
    /// least one class.
    pub fn lost_to_outage(&self) -> bool {
        self.classification.class.is_none() && !self.classification.outages.is_empty()
    }

    /// True when the recording has a class and passed the review (or the
    /// campaign has no review).
    pub fn kept(&self) -> bool {
        self.kept
    }

    /// Why the review left the recording out (the reviewer's reason, or
    /// [`NOT_REVIEWED`]); `None` when it was kept or the campaign has no
    /// review.
    pub fn exclusion_reason(&self) -> Option<&str> {
        self.exclusion.as_deref()
    }

    /// The recording's MOR, metres: mean of the rule set's visibility columns
    /// that are not empty.
    pub fn mor(&self) -> Option<f64> {
        self.mor
    }

    /// The recording's rain rate, mm/h: the first non-empty rain-rate column
    /// of the rule set.
    pub fn rain_rate(&self) -> Option<f64> {
        self.rain_rate
    }

    /// The point-cloud file.
    pub fn lidar(&self) -> &LidarFile {
        self.recording.lidar()
    }

    /// The radar file, when there is one.
    pub fn radar(&self) -> Option<&Path> {
        self.recording.radar()
    }

    /// The scan-level covariates, in header order (`None`: empty cell).
    pub fn covariates(&self) -> impl Iterator<Item = (&str, Option<&Covariate>)> {
        self.recording.covariates()
    }

    /// The cell of any `weather.csv` column.
    pub fn value(&self, column: &str) -> Option<&Cell> {
        self.recording.value(column)
    }
}

/// Every recording's decision and the campaign summary.
#[derive(Debug, Clone)]
pub struct Selection {
    recordings: Vec<SelectedRecording>,
    summary: Summary,
}

impl Selection {
    /// Every recording, in `weather.csv` order.
    pub fn recordings(&self) -> &[SelectedRecording] {
        &self.recordings
    }

    /// The recordings of `class` that passed the review.
    pub fn kept(&self, class: WeatherClass) -> impl Iterator<Item = &SelectedRecording> {
        self.recordings
            .iter()
            .filter(move |r| r.kept && r.class() == Some(class))
    }

    /// The summary.
    pub fn summary(&self) -> &Summary {
        &self.summary
    }

    /// The MORs of the kept recordings of each class that has any, in class
    /// order: the data of the MOR histogram.
    pub fn kept_mor(&self, classes: &[WeatherClass]) -> Vec<(WeatherClass, Vec<f64>)> {
        classes
            .iter()
            .map(|&c| (c, self.kept(c).filter_map(|r| r.mor).collect()))
            .collect()
    }
}

/// One bin of a MOR histogram: `[from_m, to_m)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HistogramBin {
    /// Lower edge, metres (inclusive).
    pub from_m: f64,
    /// Upper edge, metres (exclusive).
    pub to_m: f64,
    /// Recordings in the bin.
    pub count: usize,
}

/// Distribution of the MOR of a class's kept recordings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MorStats {
    /// Recordings with a MOR.
    pub recordings: usize,
    /// Smallest MOR, metres.
    pub min: f64,
    /// First quartile, metres (linear interpolation between order
    /// statistics).
    pub q1: f64,
    /// Median, metres.
    pub median: f64,
    /// Third quartile, metres.
    pub q3: f64,
    /// Largest MOR, metres.
    pub max: f64,
    /// Width of the histogram bins, metres (1, 2, 2.5 or 5 × 10ᵏ, chosen for
    /// at most about ten bins).
    pub bin_width_m: f64,
    /// Histogram, bins aligned to multiples of `bin_width_m`.
    pub histogram: Vec<HistogramBin>,
}

impl MorStats {
    /// Statistics of `values` (finite), `None` when empty.
    pub fn from_values(values: &[f64]) -> Option<MorStats> {
        if values.is_empty() {
            return None;
        }
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        let (min, max) = (v[0], v[v.len() - 1]);
        let width = murk_types::nice_step((max - min) / 10.0);
        let start = (min / width).floor() * width;
        let bins = (((max - start) / width).floor() as usize + 1).max(1);
        let mut histogram: Vec<HistogramBin> = (0..bins)
            .map(|k| HistogramBin {
                from_m: start + k as f64 * width,
                to_m: start + (k + 1) as f64 * width,
                count: 0,
            })
            .collect();
        for x in &v {
            let k = (((x - start) / width).floor() as usize).min(bins - 1);
            histogram[k].count += 1;
        }
        Some(MorStats {
            recordings: v.len(),
            min,
            q1: quantile(&v, 0.25),
            median: quantile(&v, 0.5),
            q3: quantile(&v, 0.75),
            max,
            bin_width_m: width,
            histogram,
        })
    }
}

/// Quantile `p` of sorted `v` by linear interpolation (Hyndman–Fan type 7).
fn quantile(v: &[f64], p: f64) -> f64 {
    let h = (v.len() - 1) as f64 * p;
    let lo = h.floor() as usize;
    let hi = h.ceil() as usize;
    v[lo] + (h - lo as f64) * (v[hi] - v[lo])
}

/// Counts of one weather class.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClassSummary {
    /// The class.
    pub class: WeatherClass,
    /// Recordings the rules put in this class (Tables 3 and 6, "before video
    /// filter").
    pub before_review: usize,
    /// Of those, recordings the review kept (equal to `before_review` when
    /// the campaign has no review).
    pub after_review: usize,
    /// Unclassified recordings whose conditions for this class held except
    /// for empty cells.
    pub lost_to_outage: usize,
    /// Kept recordings with no MOR (every visibility column empty).
    pub kept_without_mor: usize,
    /// MOR distribution of the kept recordings; `null` when none has a MOR.
    pub mor: Option<MorStats>,
}

/// What the rules and the review made of a campaign.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub struct Summary {
    /// Campaign name.
    pub campaign: String,
    /// Rule set name.
    pub rules: String,
    /// Rule parameters in force.
    pub rule_params: std::collections::BTreeMap<String, f64>,
    /// Recordings in `weather.csv`.
    pub recordings: usize,
    /// True when the campaign has a `review.csv`.
    pub reviewed: bool,
    /// One entry per class the rules define, in clear, fog, rain, snow order.
    pub classes: Vec<ClassSummary>,
    /// Recordings no class matched.
    pub unclassified: usize,
    /// Unclassified recordings lost to an outage for at least one class.
    pub lost_to_outage: usize,
    /// Recordings several classes matched (resolved by `priority`).
    pub ambiguous: usize,
    /// Class order used to resolve ambiguity.
    pub priority: Vec<WeatherClass>,
    /// Classified recordings that the review left out.
    pub excluded_by_review: usize,
}

impl Summary {
    /// The entry of `class`, when the rules define it.
    pub fn class(&self, class: WeatherClass) -> Option<&ClassSummary> {
        self.classes.iter().find(|c| c.class == class)
    }
}

/// Classifies `recordings` of campaign `name` with `rules` and applies the
/// review (an allowlist when `reviewed`, i.e. the campaign has a
/// `review.csv`).
pub(crate) fn select(
    name: &str,
    rules: &RuleSet,
    recordings: &[Recording],
    reviewed: bool,
) -> Selection {
    let recordings: Vec<SelectedRecording> = recordings
        .iter()
        .map(|r| {
            let get = |c: &str| r.value(c);
            let classification = rules.classify(get);
            let (passes_review, exclusion) = match (reviewed, r.review()) {
                (false, _) => (true, None),
                (true, None) => (false, Some(NOT_REVIEWED.to_string())),
                (true, Some(rv)) if rv.keep => (true, None),
                (true, Some(rv)) => (
                    false,
                    Some(
                        rv.reason
                            .clone()
                            .unwrap_or_else(|| "keep = false in review.csv".to_string()),
                    ),
                ),
            };
            SelectedRecording {
                kept: passes_review && classification.class.is_some(),
                exclusion,
                mor: rules.mor(get),
                rain_rate: rules.rain_rate_of(get),
                classification,
                recording: r.clone(),
            }
        })
        .collect();

    let classes = WeatherClass::ALL
        .into_iter()
        .filter(|c| rules.class(*c).is_some())
        .map(|class| {
            let of_class = || recordings.iter().filter(move |r| r.class() == Some(class));
            let kept_mor: Vec<f64> = of_class()
                .filter(|r| r.kept)
                .filter_map(|r| r.mor)
                .collect();
            ClassSummary {
                class,
                before_review: of_class().count(),
                after_review: of_class().filter(|r| r.kept).count(),
                lost_to_outage: recordings
                    .iter()
                    .filter(|r| r.lost_to_outage() && r.outages().iter().any(|(c, _)| *c == class))
                    .count(),
                kept_without_mor: of_class().filter(|r| r.kept && r.mor.is_none()).count(),
                mor: MorStats::from_values(&kept_mor),
            }
        })
        .collect();

    let summary = Summary {
        campaign: name.to_string(),
        rules: rules.name().to_string(),
        rule_params: rules.params().clone(),
        recordings: recordings.len(),
        reviewed,
        classes,
        unclassified: recordings.iter().filter(|r| r.class().is_none()).count(),
        lost_to_outage: recordings.iter().filter(|r| r.lost_to_outage()).count(),
        ambiguous: recordings.iter().filter(|r| r.is_ambiguous()).count(),
        priority: rules.priority().to_vec(),
        excluded_by_review: recordings
            .iter()
            .filter(|r| r.class().is_some() && !r.kept)
            .count(),
    };
    Selection {
        recordings,
        summary,
    }
}

/// Formats a MOR for the table: whole metres, `-` when absent.
fn metres(v: Option<f64>) -> String {
    v.map_or_else(|| "-".to_string(), |v| format!("{v:.0}"))
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "campaign {}: {} recordings, rules {}, review.csv {}",
            self.campaign,
            self.recordings,
            self.rules,
            if self.reviewed { "applied" } else { "absent" }
        )?;
        writeln!(f)?;
        let header = [
            "class",
            "before review",
            "after review",
            "lost to outage",
            "kept, no MOR",
            "MOR min",
            "q1",
            "median",
            "q3",
            "max (m)",
        ];
        let mut rows: Vec<Vec<String>> = Vec::new();
        for c in &self.classes {
            let m = c.mor.as_ref();
            rows.push(vec![
                c.class.to_string(),
                c.before_review.to_string(),
                c.after_review.to_string(),
                c.lost_to_outage.to_string(),
                c.kept_without_mor.to_string(),
                metres(m.map(|m| m.min)),
                metres(m.map(|m| m.q1)),
                metres(m.map(|m| m.median)),
                metres(m.map(|m| m.q3)),
                metres(m.map(|m| m.max)),
            ]);
        }
        let mut widths: Vec<usize> = header.iter().map(|h| h.chars().count()).collect();
        for row in &rows {
            for (w, cell) in widths.iter_mut().zip(row) {
                *w = (*w).max(cell.chars().count());
            }
        }
        let line = |f: &mut std::fmt::Formatter<'_>, cells: &[String]| -> std::fmt::Result {
            for (i, (cell, w)) in cells.iter().zip(&widths).enumerate() {
                if i == 0 {
                    write!(f, "{cell:<w$}")?;
                } else {
                    write!(f, "  {cell:>w$}")?;
                }
            }
            writeln!(f)
        };
        line(f, &header.map(String::from))?;
        for row in &rows {
            line(f, row)?;
        }
        writeln!(f)?;
        writeln!(
            f,
            "unclassified: {} ({} lost to sensor outages)",
            self.unclassified, self.lost_to_outage
        )?;
        let order: Vec<&str> = self.priority.iter().map(|c| c.name()).collect();
        writeln!(
            f,
            "ambiguous: {} (resolved by priority {})",
            self.ambiguous,
            order.join(" > ")
        )?;
        if self.reviewed {
            writeln!(f, "left out by review: {}", self.excluded_by_review)?;
        }
        for c in &self.classes {
            let Some(m) = &c.mor else { continue };
            let bins: Vec<String> = m
                .histogram
                .iter()
                .map(|b| format!("{}–{}: {}", b.from_m, b.to_m, b.count))
                .collect();
            writeln!(f, "{} MOR histogram (m): {}", c.class, bins.join(", "))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quartiles_known_answers() {
        // 1..=5: type-7 quartiles are 2, 3, 4.
        let s = MorStats::from_values(&[5.0, 1.0, 4.0, 2.0, 3.0]).unwrap();
        assert_eq!(
            (s.min, s.q1, s.median, s.q3, s.max),
            (1.0, 2.0, 3.0, 4.0, 5.0)
        );
        // 1..=4: 1.75, 2.5, 3.25.
        let s = MorStats::from_values(&[1.0, 2.0, 3.0, 4.0]).unwrap();
        assert_eq!((s.q1, s.median, s.q3), (1.75, 2.5, 3.25));
        assert!(MorStats::from_values(&[]).is_none());
    }

    #[test]
    fn histogram_bins_cover_every_value_once() {
        let v = [52.0, 60.0, 75.0, 99.9, 100.0, 175.0];
        let s = MorStats::from_values(&v).unwrap();
        // (175 - 52) / 10 = 12.3 → 20 m bins from 40 m.
        assert_eq!(s.bin_width_m, 20.0);
        assert_eq!(s.histogram[0].from_m, 40.0);
        assert_eq!(s.histogram.iter().map(|b| b.count).sum::<usize>(), v.len());
        let last = s.histogram.last().unwrap();
        assert!(last.from_m <= 175.0 && 175.0 < last.to_m);
        // 100 falls in [100, 120), not [80, 100).
        let b = s.histogram.iter().find(|b| b.from_m == 100.0).unwrap();
        assert_eq!(b.count, 1);
    }

    #[test]
    fn one_value_gives_one_bin() {
        let s = MorStats::from_values(&[123.0]).unwrap();
        assert_eq!(s.histogram.len(), 1);
        assert_eq!(s.histogram[0].count, 1);
        assert_eq!(s.median, 123.0);
    }
}
