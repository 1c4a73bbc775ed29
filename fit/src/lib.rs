//! murk-fit: the seed report's LiDAR and radar method (D3.3 §3.4, §4.3), done
//! right, as a re-derivable coefficient table.
//!
//! Point it at a campaign folder and it returns the
//! [`CoefficientTable`](murk_types::CoefficientTable)
//! (`weather-noise-coefficients/1`) that `murk apply` uses:
//!
//! - **vanishing slopes** per weather and reflectivity band, as the maximum
//!   likelihood edge of a survival boundary ([`fit_survival`]) — the value
//!   appliers use — with the seed's quantile estimate beside it
//!   (module `quantile_slope`), per-MOR-bin quantiles, censored bins and reasons;
//! - the **rain conversion** `MOR = a·R + b` and its validity range;
//! - **ghost and ring** laws (truncated-normal maximum likelihood, module
//!   `stats::truncnorm`) and their **count per scan** as a power law of MOR;
//! - **no-change rates** for LiDAR and radar per weather with bootstrap
//!   uncertainties;
//! - **provenance**: tool, every parameter, SHA-256 of every input file.
//!
//! The crate follows linfa's shape: [`FitParams`] (hyperparameters with
//! defaults) → [`FitParams::check`] → [`FitValidParams::fit`] → a
//! [`FittedTable`] (the table and the data of its figures).
//!
//! **Architecture invariant:** statistics do no I/O. The private modules
//! `reference`, `pairing`, `survival`, `quantile_slope`, `radar` and `stats`
//! work on in-memory values and are unit-tested against known answers; only
//! `driver` reads files (through `murk-io`) and streams recordings, keeping
//! per-cell and per-bin statistics, never the points of a campaign.
//!
//! **Map and merge.** The same table can be fitted in pieces on many
//! machines: [`FitValidParams::fit_partial`] maps a [`Selection`] of
//! recordings into a serialisable [`FitState`], [`FitState::merge`] merges
//! states in any order, [`FitState::finish`] gives the table, byte for byte
//! the one [`FitValidParams::fit`] gives (which is map over everything, then
//! finish). See the `state` module's example.
//!
//! **One door.** Besides the fit itself, the crate's public surface is
//! [`observe`]: the campaign's inputs, the clear reference, the measured
//! firing geometry and the pairing of one recording, exactly as the fit
//! sees them. `murk-diagnose` uses that module and nothing else of the
//! fit's internals.
//!
//! **Errors in variables.** A recording's MOR is the mean of its
//! visibility columns, a reading, not the truth; reflectivity is noisy too.
//! What each estimator does with that:
//!
//! - *ML vanishing slope* (`survival`): fits the edge in `r / MOR'`. A
//!   multiplicative reading error `MOR' = MOR·(1 + ε)` moves a recording's
//!   edge to `s / (1 + ε)`, whose mean is `s·(1 + σ²)`: a bias of order σ²,
//!   not corrected — it is a fraction of a campaign's statistical error
//!   (~1.5 % at 28 recordings), and a correction would have to take the
//!   two visibility sensors' disagreement for noise rather than calibration
//!   (the rain conversion below does so where the bias is not small). Measured on generated
//!   fog, ~28 recordings: +0.57 % / +0.24 % (two bands, 40 seeds) at 7.5 %
//!   noise per sensor, +0.03 % / −0.26 % with exact readings, +1.4 % /
//!   +1.0 % (6 seeds) at 10 % with 5 % reflectivity noise. The scatter the
//!   readings add between recordings is in the intervals, which are over
//!   recordings (leave one recording out): they cover the truth in 90 % of
//!   40 seeds at 7.5 % noise (`tests/intervals.rs`).
//! - *Edge width* (`survival`): a recording's edge moving with its reading
//!   error widens the edge the fit sees to `√(w² + v)` (`v` the variance
//!   of a reading's error in ln MOR): +18 % at 7.5 % noise per sensor.
//!   Corrected: the visibility sensors' disagreement estimates `v`
//!   (`mor_reading_noise`) and the table gives `edge_width_corrected`
//!   beside the fitted width, its interval carrying the jackknife error of
//!   `v`: it covers the truth in 39 of 40 seeds where the fitted width's
//!   covers it in 6 (`tests/intervals.rs`). Error the sensors share is not
//!   seen. `murk apply` uses the fitted width — the edge over MOR readings,
//!   which is what a reading of the user's MOR sees.
//! - *Quantile slope* (`quantile_slope`): a noisy MOR moves a recording to
//!   a neighbouring MOR bin; the delete-a-group jackknife over bins carries
//!   that spread into its interval.
//! - *Bending law and count laws* (exponents of MOR): noise in `ln MOR`
//!   attenuates an exponent by the reliability
//!   `var(ln MOR) / (var(ln MOR) + σ²)` — about 1 % for the generated fog
//!   (σ of ln MOR 0.55) read by two sensors with 7.5 % noise; not
//!   corrected.
//! - *Rain conversion*: corrected. The gauges' disagreement estimates each
//!   recording's rate noise, and the slope is the method-of-moments one
//!   (`Sxy / (Sxx − Σ vᵢ)`), which OLS on noisy rates would dilute.
//! - *Reflectivity near band edges*: a return's band is its cell's
//!   reference reflectivity, the median over the clear recordings, so one
//!   return's noise does not move it; what noise remains mixes a little of
//!   the neighbouring band's slope in (one slope in both bands changes the
//!   low band's bias from +0.57 % to +0.55 %).
//!
//! ```
//! use murk_fit::FitParams;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! // A tiny campaign: one ring of 36 directions, a wall at 4–39 m, two clear
//! // recordings and two foggy ones in which everything beyond 0.3·MOR is gone.
//! let dir = tempfile::tempdir()?;
//! let d = dir.path();
//! std::fs::write(d.join("campaign.toml"), "\
//! name = \"demo\"\nrules = \"pdd-2022-2023\"\n[lidar]\nmodel = \"toy\"\n\
//! elevation_deg = [0.0]\nazimuth_resolution_deg = 10.0\n")?;
//! std::fs::write(d.join("weather.csv"), "\
//! recording,timestamp,PWD12_Weather Type,PWD12_Rain intensity (mm/h),PWD12_MOR (m),VS2K_MOR (m),WXT530_Rain intensity (mm/h)
//! c1,2023-01-14T05:00:00Z,Clear,0,2500,2500,0
//! c2,2023-01-14T06:00:00Z,Clear,0,2500,2500,0
//! f1,2023-01-14T07:00:00Z,Fog,0,50,50,0
//! f2,2023-01-14T08:00:00Z,Fog,0,100,100,0
//! ")?;
//! std::fs::create_dir(d.join("lidar"))?;
//! for (id, mor) in [("c1", 1e9), ("c2", 1e9), ("f1", 50.0), ("f2", 100.0)] {
//!     let mut csv = String::from("x,y,z,intensity,ring\n");
//!     for k in 0..36 {
//!         let (az, r) = ((k as f64 * 10.0 + 5.0).to_radians(), 4.0 + k as f64);
//!         if r < 0.3 * mor {
//!             csv += &format!("{},{},0,20,0\n", r * az.cos(), r * az.sin());
//!         }
//!     }
//!     std::fs::write(d.join("lidar").join(format!("{id}.csv")), csv)?;
//! }
//!
//! let campaign = murk_campaign::Campaign::open(d)?;
//! let params = FitParams::default().min_points_per_bin(1).bootstrap_replicates(0).check()?;
//! let fitted = params.fit(&campaign)?;
//! let fog = &fitted.table().weathers[&murk_types::WeatherClass::Fog];
//! assert_eq!(fog.recordings, 2);
//! // f1 keeps the 11 returns closer than 15 m, f2 the 26 closer than 30 m.
//! assert_eq!(fog.no_change_rate, Some((11.0 + 26.0) / 72.0));
//! assert!(fitted.table().absent.contains_key(&murk_types::WeatherClass::Snow));
//! # Ok(())
//! # }
//! ```

#![deny(missing_docs)]

mod accumulate;
// File I/O is allowed here, in `driver`, `images` and `state` only
// (fit/clippy.toml).
#[allow(clippy::disallowed_methods, clippy::disallowed_types)]
mod algorithm;
mod assemble;
mod bend;
pub mod diagnostics;
#[allow(clippy::disallowed_methods, clippy::disallowed_types)]
mod driver;
mod error;
mod geometry;
mod hyperparams;
// Spills clear images to a temporary file (fit/clippy.toml).
#[allow(clippy::disallowed_methods, clippy::disallowed_types)]
mod images;
pub mod observe;
mod occlusion;
mod pairing;
mod quantile_slope;
mod radar;
mod reference;
// Reads and writes state files (fit/clippy.toml).
#[allow(clippy::disallowed_methods, clippy::disallowed_types)]
pub mod state;
mod stats;
mod survival;

pub use accumulate::{RecordingRow, WeatherAcc};
pub use algorithm::{FittedTable, TOOL, write_atomic};
pub use assemble::{RainSample, rain_conversion};
pub use diagnostics::{
    Diagnostics, NoiseHistograms, PlotHistogram, RangeMorDensity, WeatherDiagnostics,
};
pub use driver::{FitInputs, RecordingInput};
pub use error::FitError;
pub use hyperparams::{
    Band, DEFAULT_REFLECTIVITY_LAW_EDGES, EdgeShape, FitParams, FitValidParams, parse_edge,
};
pub use images::{
    DEFAULT_CLEAR_IMAGE_MEMORY, clear_image_dir, clear_image_memory, set_clear_image_dir,
    set_clear_image_memory, set_clear_image_memory_mb,
};
pub use state::{ClearPart, FitState, STATE_FORMAT, Selection};
/// The one-dimensional bounded minimiser (Brent's method) that profiles the
/// bending law's exponent, shared with the diagnosis's extension terms.
pub use stats::optim::minimize_scalar;
/// The maximum-likelihood survival fit on its own (a benchmark target and a
/// building block for other estimators; `fit` calls it per band).
pub use survival::{Obs, SurvivalOptions, fit_survival};
