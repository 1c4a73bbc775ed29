//! Figures of a diagnosis: a residual profile against a covariate, and a
//! bird's-eye view of clear / simulated / measured clouds side by side (the
//! seed report's Figure 30 style).

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::output::{write_png, write_svg};
use crate::{FONT, FigureError, ImageFormat, register_fonts};

/// One residual profile: `(covariate value, mean residual)` per bin.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileFigure<'a> {
    /// Title (observable vs covariate).
    pub title: &'a str,
    /// x-axis label.
    pub x_label: &'a str,
    /// y-axis label.
    pub y_label: &'a str,
    /// Points, in x order.
    pub points: &'a [(f64, f64)],
    /// Relevance threshold drawn as ±band.
    pub threshold: f64,
}

fn span(v: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let lo = v.clone().fold(f64::INFINITY, f64::min);
    let hi = v.fold(f64::NEG_INFINITY, f64::max);
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.08).max(1e-6);
    (lo - pad, hi + pad)
}

fn draw_profile<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    f: &ProfileFigure<'_>,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let (x0, x1) = span(f.points.iter().map(|p| p.0));
    let (y0, y1) = span(
        f.points
            .iter()
            .map(|p| p.1)
            .chain([f.threshold, -f.threshold, 0.0]),
    );
    let mut chart = ChartBuilder::on(&root)
        .caption(f.title, (FONT, 20))
        .margin(14)
        .x_label_area_size(42)
        .y_label_area_size(64)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(f.x_label)
        .y_desc(f.y_label)
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 15))
        .draw()
        .map_err(e)?;
    let grey = RGBColor(200, 200, 200);
    for y in [f.threshold, -f.threshold] {
        chart
            .draw_series(LineSeries::new([(x0, y), (x1, y)], grey.stroke_width(1)))
            .map_err(e)?;
    }
    chart
        .draw_series(LineSeries::new(
            [(x0, 0.0), (x1, 0.0)],
            BLACK.stroke_width(1),
        ))
        .map_err(e)?;
    let blue = RGBColor(0, 114, 178);
    chart
        .draw_series(LineSeries::new(
            f.points.iter().copied(),
            blue.stroke_width(2),
        ))
        .map_err(e)?;
    chart
        .draw_series(f.points.iter().map(|&p| Circle::new(p, 4, blue.filled())))
        .map_err(e)?;
    root.present().map_err(e)
}

/// Draws a residual profile to `path` (`.png` or `.svg`), atomically.
pub fn residual_profile(f: &ProfileFigure<'_>, path: &Path) -> Result<(), FigureError> {
    let format = ImageFormat::from_path(path)?;
    register_fonts().map_err(|reason| FigureError::Render {
        path: path.to_path_buf(),
        reason,
    })?;
    let size = (800, 480);
    match format {
        ImageFormat::Png => write_png(path, size, |root| draw_profile(root, f)),
        ImageFormat::Svg => write_svg(path, size, |root| draw_profile(root, f)),
    }
}

fn draw_bev<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    panels: &[(&str, &[[f32; 3]])],
    half: f64,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let areas = root.split_evenly((1, panels.len().max(1)));
    for (area, (name, pts)) in areas.iter().zip(panels) {
        let mut chart = ChartBuilder::on(area)
            .caption(format!("{name} ({} points)", pts.len()), (FONT, 16))
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(40)
            .build_cartesian_2d(-half..half, -half..half)
            .map_err(e)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .label_style((FONT, 12))
            .draw()
            .map_err(e)?;
        let inside = pts
            .iter()
            .filter(|p| (p[0] as f64).abs() < half && (p[1] as f64).abs() < half);
        chart
            .draw_series(inside.map(|p| {
                let r = (p[0] as f64).hypot(p[1] as f64);
                // Near returns red, far ones blue.
                let t = (r / half).clamp(0.0, 1.0);
                let c = RGBColor((220.0 * (1.0 - t)) as u8, 60, (220.0 * t) as u8);
                Pixel::new((p[0] as f64, p[1] as f64), c)
            }))
            .map_err(e)?;
    }
    root.present().map_err(e)
}

/// Draws bird's-eye views of `panels` (name, points) side by side within
/// `±half_extent_m` of the sensor to `path`, atomically.
pub fn bev_panels(
    panels: &[(&str, &[[f32; 3]])],
    half_extent_m: f64,
    path: &Path,
) -> Result<(), FigureError> {
    let format = ImageFormat::from_path(path)?;
    register_fonts().map_err(|reason| FigureError::Render {
        path: path.to_path_buf(),
        reason,
    })?;
    let size = (420 * panels.len().max(1) as u32, 460);
    match format {
        ImageFormat::Png => write_png(path, size, |root| draw_bev(root, panels, half_extent_m)),
        ImageFormat::Svg => write_svg(path, size, |root| draw_bev(root, panels, half_extent_m)),
    }
}
