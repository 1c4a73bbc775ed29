//! Shared data types of murk: the values every other crate passes around.
//!
//! murk fits weather noise models for automotive LiDAR from field campaigns
//! and applies them to clear-weather data. The pieces that cross crate
//! boundaries live here so that readers, fitters and appliers agree on them
//! without depending on each other:
//!
//! - [`PointCloud`]: a structure-of-arrays LiDAR scan (x, y, z, intensity,
//!   ring, optional time) in the sensor frame, metres, x forward, y left, z up.
//! - [`IntensityScale`]: how a sensor's raw intensity maps onto calibrated
//!   VLP-16 reflectivity (0–100 diffuse, 101–255 retro-reflective), the scale
//!   in which every reflectivity band of murk is expressed.
//! - [`LidarSpec`]: the sensor metadata of a campaign (ring elevations,
//!   azimuth resolution, range scale), with the ring-from-elevation rule used
//!   for formats that carry no ring.
//! - [`PointFormat`]: the point-cloud file formats murk reads and writes.
//! - [`WeatherClass`]: clear, fog, rain, snow.
//! - [`EdgeShape`]: the soft survival edge law (probit or unit-variance
//!   logistic), fitted by `fit`, applied by `infer`.
//! - [`VanishingLaw`]: the vanishing-distance law (the seed's line or a
//!   power of MOR that bends), fitted by `fit`, applied by `infer`.
//! - [`firing`]: the firing step of a spinning LiDAR measured from its
//!   returns, for fit's sensor geometry and infer's near-range rays.
//! - [`seed`]: the one seed derivation, `(seed, item key, purpose)`, of
//!   every randomised step.
//! - [`CoefficientTable`]: the fitted weather-noise coefficients
//!   (`weather-noise-coefficients/1`), the contract between fit and apply.
//!
//! ```
//! use murk_types::{IntensityScale, LidarSpec, PointCloud};
//!
//! let mut cloud = PointCloud::with_capacity(2);
//! cloud.push(10.0, 0.0, -1.0, 0.5, 0);
//! cloud.push(0.0, 20.0, 0.0, 0.9, 0);
//! cloud.intensity_scale = IntensityScale::KITTI;
//! cloud.to_calibrated();
//! assert_eq!(cloud.intensity, vec![127.5, 229.5]);
//! assert_eq!(cloud.intensity_scale, IntensityScale::Calibrated);
//!
//! let vlp16 = LidarSpec::vlp16();
//! // A point 1° above the horizon belongs to ring 2 of the VLP-16.
//! let ring = vlp16.ring_from_elevation(1.0_f32.to_radians()).unwrap();
//! assert_eq!(vlp16.elevation_deg[ring as usize], 1.0);
//! ```

mod atomic;
mod bins;
mod cloud;
mod edge;
mod error;
mod extension;
pub mod firing;
mod format;
mod intensity;
mod lidar;
pub mod real_data;
pub mod seed;
mod table;
mod vanishing;
mod walk;
mod weather;

pub use atomic::{
    AtomicWriteError, StagedFile, process_ended, remove_stale_temporaries, stage_atomic,
    stage_atomic_with, write_atomic, write_atomic_with,
};
pub use bins::nice_step;
pub use cloud::PointCloud;
pub use edge::{EdgeShape, LOGISTIC_UNIT, deconvolve_edge_width};
pub use error::TypesError;
pub use extension::{
    COUNT_POINT_COVARIATES, COUNT_RAY_COVARIATES, CovariateValue, ExtensionFunction,
    ExtensionObservable, ModelExtension, POINT_COVARIATES, PointCovariates, RANGE_CELLS,
    RangeCells, RayDensity, combine as combine_extensions,
};
pub use format::{BinLayout, PcapReturn, PointFormat};
pub use intensity::IntensityScale;
pub use lidar::{
    HDL32E_ELEVATION_DEG, LidarSpec, NEAR_POINT_M, NEAR_POINT_SHARE, PUCK_HI_RES_ELEVATION_DEG,
    VLP16_ELEVATION_DEG, VLP32C_ELEVATION_DEG, near_point_share,
};
pub use table::{
    ClearCoefficients, CoefficientTable, CountLaw, CountLawChoice, CountUnit, EdgeTest,
    ExcludedRecording, Gaussian, InputDigest, Interval, LackOfFit, LawChoice, MorBin, NoiseLaw,
    OcclusionTest, Provenance, RadarCoefficients, RainConversion, ReflectivityChoice,
    ReflectivityMorChoice, ReturnMoments, RingGeometry, SensorGeometry, SlopeBand, SurvivalBin,
    SurvivalFit, SweepBand, TABLE_FORMAT, TableLidar, Uncertainty, WeatherCoefficients,
};
pub use vanishing::{ReflectivityDependence, VanishingLaw};
pub use walk::{LeftOut, Walk, WalkedFile, walk_folder};
pub use weather::WeatherClass;
