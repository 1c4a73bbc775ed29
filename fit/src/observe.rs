//! The one door through which other crates look at a campaign the way the
//! fit does: its inputs, the clear reference, the measured firing geometry
//! and the pairing of one recording against that reference.
//!
//! `murk-diagnose` simulates and compares recordings cell by cell; it must
//! see exactly the cells and classes the fit saw, so it uses these items and
//! nothing else of fit's internals (everything else of the crate is private,
//! so a change inside the fit cannot silently change what diagnose sees).
//! `murk campaign summary` uses [`measure_geometry`] to print the firing
//! grid.
//!
//! ```no_run
//! use murk_fit::observe::{FitInputs, measure_geometry};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let campaign = murk_campaign::Campaign::open("fixtures/default-campaign")?;
//! let inputs = FitInputs::from_campaign(&campaign);
//! let (geometry, warnings) = measure_geometry(&inputs)?;
//! println!("{} scans measured, {} warnings", geometry.frames, warnings.len());
//! # Ok(())
//! # }
//! ```

pub use crate::driver::{
    FitInputs, RecordingInput, measure_geometry, read_lidar, read_lidar_frames, read_scans,
};
pub use crate::geometry::declared;
pub use crate::pairing::{Pair, RecordingTally, pair_frames, pair_frames_detailed};
pub use crate::reference::{CellGrid, CellImage, CellPoint, ClearReference, cell_points};
