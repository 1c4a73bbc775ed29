//! Applies fitted LiDAR weather noise models to clear-weather point clouds,
//! one scan or thousands of files at a time.
//!
//! The model is the seed report's (§3.2, §3.4.3–3.4.5): each return of a
//! clear scan either stays unchanged or **vanishes** when its range exceeds
//! its vanishing distance `slope(band) × MOR × range_scale`, where the slope
//! depends on the band of the return's calibrated reflectivity (fog and rain
//! vanish low-reflectivity returns sooner). Optional extras, each off by
//! default and named in the summary: **near-range** ghost and ring returns
//! placed on the sensor's rays (replacing the return of their ray when
//! closer, seed 004 §4.2 step 3), Gaussian **range noise**, and two-way
//! **intensity attenuation**.
//!
//! The crate reads one thing from fitting: the [`CoefficientTable`]
//! (`murk_types`). **Architecture invariant:** murk-infer does not depend on
//! murk-fit.
//!
//! Three types do the work, linfa style (checked parameters → a value that
//! applies):
//!
//! - [`ApplyParams`]: weather, severity (MOR or rain rate) and options,
//!   checked once against a table by [`ApplyParams::build`];
//! - [`Applier`]: the checked model; [`Applier::apply`] turns one
//!   [`PointCloud`] into its degraded version and an [`ApplySummary`];
//! - [`batch`]: [`batch::plan`] maps input files and folders to outputs,
//!   [`batch::run`] reads, applies and writes them in parallel and returns a
//!   [`BatchReport`].
//! - [`camera`]: physics-based rain on camera images (seed 003 §3.1),
//!   [`camera::RainParams`] → [`camera::RainRenderer`]; CycleGAN weather
//!   generators through ONNX, `camera::GeneratorParams` →
//!   `camera::Generator` (backend: cargo feature `tract`, the default, or
//!   `native`; with neither, murk-infer builds without ONNX and without
//!   the `camera::gan` module, which is what LiDAR-only users such as
//!   murk-diagnose get).
//!
//! **Reflectivity bands are calibrated VLP-16 reflectivity**, whatever the
//! input's [`murk_types::IntensityScale`]: a KITTI return stored as 0.03
//! (calibrated 7.65) is in the `< 10` band like a VLP-16 return of 7.65.
//!
//! **Reproducible:** every random draw is seeded by (seed, scan key) and
//! drawn per fixed-size chunk, so outputs are byte-identical for any thread
//! count. Clear weather (MOR ≥ the clear threshold, 2000 m by default) is the
//! identity.
//!
//! ```
//! use murk_infer::{ApplyParams, CoefficientTable, PointCloud, Severity};
//! use murk_types::WeatherClass;
//!
//! // A table with the seed's fog slopes (Table 4): 0.3029 below
//! // reflectivity 10, 0.3463 from 10 up.
//! let table = CoefficientTable::from_json(r#"{
//!   "format": "weather-noise-coefficients/1", "campaign": "doc",
//!   "lidar": { "model": "VLP16", "range_scale": 1.0 },
//!   "weathers": { "fog": {
//!     "recordings": 28, "quantile": 0.99, "no_change_rate": 0.38,
//!     "vanishing_slope": [
//!       { "reflectivity_min": 0,  "reflectivity_max": 10,   "slope": 0.30286536, "points": 1 },
//!       { "reflectivity_min": 10, "reflectivity_max": null, "slope": 0.34634364, "points": 1 } ],
//!     "ghost": null, "ring": null } },
//!   "provenance": { "tool": "doc", "inputs_sha256": "", "parameters": {} }
//! }"#)?;
//!
//! // Fog at MOR 100 m: low-reflectivity returns vanish beyond 30.29 m,
//! // the others beyond 34.63 m.
//! let applier = ApplyParams::new(WeatherClass::Fog, Severity::Mor(100.0)).build(&table)?;
//! let mut scan = PointCloud::with_capacity(3);
//! scan.push(32.0, 0.0, 0.0, 5.0, 0);  // low reflectivity, between the two distances: vanishes
//! scan.push(32.0, 0.0, 0.0, 50.0, 0); // high reflectivity at the same range: stays
//! scan.push(40.0, 0.0, 0.0, 50.0, 0); // beyond both: vanishes
//! let (out, summary) = applier.apply(&scan, "doc-scan")?;
//! assert_eq!(out.intensity, vec![50.0]);
//! assert_eq!((summary.points_in, summary.points_out, summary.vanished), (3, 1, 2));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod applier;
pub mod batch;
pub mod camera;
mod error;
mod extension;
mod hyperparams;
mod kernel;
mod model;
mod near;
mod sampling;
mod summary;

pub use applier::Applier;
pub use batch::{BatchOptions, BatchReport, FileReport, Job, Plan, Skipped};
pub use error::InferError;
pub use hyperparams::{ApplyParams, DEFAULT_AZIMUTH_RESOLUTION_DEG, DEFAULT_CLEAR_MOR_M, Severity};
pub use model::{BandRule, BandSummaryRule, ModelSummary, SlopeSource};
pub use near::NearRangeCounts;
pub use summary::{ApplySummary, BandSummary, SUMMARY_FORMAT};

#[doc(no_inline)]
pub use murk_types::{CoefficientTable, PointCloud};
