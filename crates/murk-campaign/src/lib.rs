//! Campaign folders: ingest, checks and the selection rules that decide which
//! recordings are clear, fog, rain or snow.
//!
//! A *campaign* is one folder of field recordings (`campaign.toml`,
//! `weather.csv`, `lidar/`, optional `radar/` and `review.csv`; see
//! `campaign-format.md`). This crate reads the metadata, pairs recording ids
//! with their files and applies the campaign's rules; it never reads a point
//! cloud. Three types carry the work:
//!
//! - [`Campaign`]: an opened, checked folder. [`Campaign::open`] fails on the
//!   first inconsistency with a [`CampaignError`] naming the file, line (and
//!   column) and reason.
//! - [`RuleSet`]: the selection rules, a small TOML vocabulary (see the
//!   [`rules`] module). The seed report's two Puy-de-Dôme rule sets are
//!   built-in presets (`pdd-2022-2023`, `pdd-2023-2024`) whose thresholds are
//!   [`PddParams`].
//! - [`Selection`]: what [`Campaign::select`] makes of every recording (class,
//!   review, MOR, rain rate, files, covariates) and its [`Summary`] (counts per
//!   class before and after review, outages, ambiguity, MOR distribution),
//!   which prints as a table and serializes to JSON.
//!
//! **How the recordings are read.** Besides the sensor geometry, `[lidar]`
//! says how murk-io reads the campaign's files (`fit` and `diagnose` pass
//! it on; see `murk_types::LidarSpec`):
//!
//! | key | values | default |
//! |---|---|---|
//! | `intensity_scale` | `calibrated`, `kitti`, `six-bit`, `{ gain = G, offset = O }` | the format's (KITTI `.bin`: `kitti`; others `calibrated`) |
//! | `bin_layout` | `xyzi` (KITTI), `xyzir` (Seeing Through Fog, nuScenes), `xyzit` | `.bin`: `xyzi` when the file size fits only it; a size that fits several layouts is refused |
//! | `csv_columns` | e.g. `["x", "y", "z", "intensity", "ring"]` | none: CSV files start with a header line |
//! | `min_range_m` | metres, e.g. `1.0`: nearer points are not returns (no-return firings kept as points at the origin, the vehicle's body) | none: every point is a return |
//! | `pcap_return` | `strongest`, `last`: the return of each firing read from dual-return `.pcap` recordings | as recorded; fit and diagnose refuse a dual-return recording until told |
//!
//! ```
//! use murk_campaign::Campaign;
//! use murk_types::WeatherClass;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let dir = tempfile::tempdir()?;
//! let d = dir.path();
//! std::fs::write(d.join("campaign.toml"), r#"
//! name  = "demo"
//! rules = "pdd-2022-2023"
//! [lidar]
//! model = "VLP16"
//! elevation_deg = [-15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0,
//!                  -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0]
//! "#)?;
//! std::fs::write(d.join("weather.csv"), "\
//! recording,timestamp,PWD12_Weather Type,PWD12_Rain intensity (mm/h),PWD12_MOR (m),VS2K_MOR (m),WXT530_Rain intensity (mm/h),wind (m/s)
//! a,2023-01-14T05:00:00Z,Clear,0,2500,2400,0,3.5
//! b,2023-01-14T06:00:00Z,Fog,0,120,150,0,1.0
//! c,2023-01-14T07:00:00Z,Rain,1.2,900,800,1.0,
//! ")?;
//! std::fs::create_dir(d.join("lidar"))?;
//! for id in ["a", "b", "c"] {
//!     std::fs::write(d.join("lidar").join(format!("{id}.pcd")), "")?;
//! }
//!
//! let campaign = Campaign::open(d)?;
//! assert_eq!(campaign.covariate_columns(), ["wind (m/s)"]);
//! let selection = campaign.select();
//! let b = &selection.recordings()[1];
//! assert_eq!(b.class(), Some(WeatherClass::Fog));
//! assert_eq!(b.mor(), Some(135.0)); // mean of the two visibility sensors
//! assert_eq!(selection.recordings()[2].rain_rate(), Some(1.2));
//! let summary = selection.summary();
//! assert_eq!(summary.class(WeatherClass::Clear).unwrap().before_review, 1);
//! println!("{summary}");
//! # Ok(())
//! # }
//! ```

mod campaign;
mod error;
pub mod rules;
mod select;
mod suggest;
mod vocabulary;
mod weather;

pub use campaign::{Campaign, RadarSpec, layout};
pub use error::{CampaignError, Location};
pub use rules::{
    Classification, Condition, Op, Operand, Outcome, PDD_2022_2023, PDD_2023_2024, PddParams,
    RuleSet, RuleValue,
};
pub use select::{
    ClassSummary, HistogramBin, MorStats, NOT_REVIEWED, SelectedRecording, Selection, Summary,
};
pub use vocabulary::{Cell, Covariate, KNOWN_SENSOR_COLUMNS, SensorKind, columns};
pub use weather::{Column, ColumnRole, LidarFile, Recording, Review};
