//! Figures of murk, drawn with plotters as PNG and SVG.
//!
//! Every figure takes plain data (slices of numbers with labels), never a
//! campaign or model type, so this crate depends on no other murk crate and
//! any tool can draw with it. Text is set in DejaVu Sans, embedded in the
//! binary and registered with plotters on first use, so figures render the
//! same on a machine with no system fonts. Files are written atomically
//! (temporary file in the same folder, then rename) and identical data gives
//! byte-identical files.
//!
//! Figures so far:
//! - [`mor_histogram`]: the MOR of the recordings of each weather class, one
//!   panel per class on a shared axis (the seed report's Figure 24).
//! - [`range_vs_mor`], [`slope_vs_reflectivity`], [`gaussian_histograms`]:
//!   the figures of a fit (the seed's Figures 26, 27 and 29).
//! - [`residual_profile`], [`bev_panels`]: the figures of a diagnosis.
//!
//! ```
//! use murk_figures::{FigureOptions, mor_histogram};
//!
//! # fn main() -> Result<(), murk_figures::FigureError> {
//! let dir = tempfile::tempdir().unwrap();
//! let fog = [52.0, 61.0, 75.0, 90.0, 130.0];
//! let rain = [80.0, 120.0, 150.0, 170.0];
//! let series: [(&str, &[f64]); 2] = [("fog", &fog), ("rain", &rain)];
//! let png = dir.path().join("mor-histogram.png");
//! mor_histogram(&series, &FigureOptions::default(), &png)?;
//! assert!(std::fs::metadata(&png).unwrap().len() > 0);
//! # Ok(())
//! # }
//! ```

mod diagnosis;
mod error;
mod fit;
mod histogram;
mod legend;
mod output;
pub mod table;

pub use diagnosis::{BevFigure, ProfileFigure, ProfilePoint, bev_panels, residual_profile};
pub use error::FigureError;
pub use fit::{
    GaussianPanel, PanelLaw, QuantileMarker, RangeMorFigure, SlopeLine, SweepFigure, SweepSeries,
    Truncation, gaussian_histograms, range_vs_mor, slope_vs_reflectivity,
};
pub use histogram::{Bins, mor_histogram, shared_bins, write_mor_histograms};
pub use legend::short;
pub use output::ImageFormat;

/// Size and look of a figure.
///
/// | Name | Default | Purpose | Range |
/// |---|---|---|---|
/// | `width` | 900 px | image width | ≥ 200 |
/// | `panel_height` | 260 px | height of one panel (one class) | ≥ 100 |
/// | `title` | none | line above the panels | any text |
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FigureOptions {
    /// Image width, pixels.
    pub width: u32,
    /// Height of one panel, pixels.
    pub panel_height: u32,
    /// Optional title above the panels.
    pub title: Option<String>,
}

impl Default for FigureOptions {
    fn default() -> Self {
        FigureOptions {
            width: 900,
            panel_height: 260,
            title: None,
        }
    }
}

/// The font family name figures are drawn with (DejaVu Sans, registered
/// under this name).
pub const FONT: &str = "sans-serif";

/// Registers DejaVu Sans with plotters once per process.
pub(crate) fn register_fonts() -> Result<(), String> {
    use plotters::style::{FontStyle, register_font};
    static RESULT: std::sync::OnceLock<Result<(), String>> = std::sync::OnceLock::new();
    RESULT
        .get_or_init(|| {
            let fonts = [
                (FontStyle::Normal, dejavu::sans::regular()),
                (FontStyle::Bold, dejavu::sans::bold()),
                (FontStyle::Italic, dejavu::sans::oblique()),
                (FontStyle::Oblique, dejavu::sans::oblique()),
            ];
            for (style, bytes) in fonts {
                register_font(FONT, style, bytes)
                    .map_err(|_| "the embedded DejaVu Sans font does not load".to_string())?;
            }
            Ok(())
        })
        .clone()
}
