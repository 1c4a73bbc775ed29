//! Figures of a diagnosis: a residual profile against a covariate (points
//! with interval bars, on a numeric or a categorical axis), and a
//! bird's-eye view of clear / simulated / measured clouds side by side (the
//! seed report's Figure 30 style) with metre axes and a colour key.

use std::path::Path;

use plotters::coord::Shift;
use plotters::coord::ranged1d::SegmentValue;
use plotters::prelude::*;

use crate::fit::render;
use crate::legend::{Entry, Swatch, draw_legend, legend_height, short};
use crate::{FONT, FigureError, ImageFormat, register_fonts};

const BLUE: RGBColor = RGBColor(0, 114, 178);
const GREY: RGBColor = RGBColor(110, 110, 110);

/// One bin of a residual profile.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfilePoint {
    /// The bin's name (a range or a category), used on a categorical axis.
    pub label: String,
    /// Position on a numeric axis (mean covariate of the bin); `None` for a
    /// category. The axis is numeric only when every point has one.
    pub x: Option<f64>,
    /// Mean residual of the bin.
    pub mean: f64,
    /// Interval of the mean `(low, high)`, drawn as a bar; `None` when the
    /// bin has too little data for one.
    pub interval: Option<(f64, f64)>,
}

/// One residual profile.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileFigure<'a> {
    /// Title (observable vs covariate).
    pub title: &'a str,
    /// x-axis label.
    pub x_label: &'a str,
    /// y-axis label.
    pub y_label: &'a str,
    /// Bins, in axis order.
    pub points: &'a [ProfilePoint],
    /// Relevance threshold drawn as ±band.
    pub threshold: f64,
    /// What the bars are (`95 % interval across recordings`).
    pub interval_label: &'a str,
}

impl ProfileFigure<'_> {
    /// True when the bins are drawn on a numeric axis (every point has an
    /// `x`), false for a categorical axis.
    pub fn numeric(&self) -> bool {
        !self.points.is_empty() && self.points.iter().all(|p| p.x.is_some_and(f64::is_finite))
    }

    fn legend(&self) -> Vec<Entry> {
        let mut out = vec![
            Entry::new(
                format!("mean residual per bin; bar: {}", self.interval_label),
                Swatch::Line {
                    colour: BLUE,
                    dashed: false,
                    marker: Some(true),
                },
            ),
            Entry::new(
                format!(
                    "± relevance threshold ({}); black: no residual",
                    short(self.threshold)
                ),
                Swatch::Line {
                    colour: GREY,
                    dashed: true,
                    marker: None,
                },
            ),
        ];
        if self.points.iter().any(|p| p.interval.is_none()) {
            out.push(Entry::note(
                "no bar: too few recordings in the bin for an interval",
            ));
        }
        out
    }

    /// The legend's lines and notes, as drawn.
    pub fn legend_labels(&self) -> Vec<String> {
        self.legend().into_iter().map(|e| e.label).collect()
    }
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

fn y_span(f: &ProfileFigure<'_>) -> (f64, f64) {
    span(
        f.points
            .iter()
            .flat_map(|p| {
                let (a, b) = p.interval.unwrap_or((p.mean, p.mean));
                [p.mean, a, b]
            })
            .chain([f.threshold, -f.threshold, 0.0]),
    )
}

fn draw_profile<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    f: &ProfileFigure<'_>,
    legend_h: u32,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let body = root.titled(f.title, (FONT, 20)).map_err(e)?;
    let (_, h) = body.dim_in_pixel();
    let (plot, foot) = body.split_vertically(h.saturating_sub(legend_h));
    let (y0, y1) = y_span(f);
    if f.numeric() {
        let (x0, x1) = span(f.points.iter().filter_map(|p| p.x));
        let mut chart = ChartBuilder::on(&plot)
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
        for y in [f.threshold, -f.threshold] {
            chart
                .draw_series(DashedLineSeries::new(
                    [(x0, y), (x1, y)],
                    6,
                    4,
                    GREY.stroke_width(1),
                ))
                .map_err(e)?;
        }
        chart
            .draw_series(LineSeries::new(
                [(x0, 0.0), (x1, 0.0)],
                BLACK.stroke_width(1),
            ))
            .map_err(e)?;
        let pts: Vec<(f64, &ProfilePoint)> =
            f.points.iter().filter_map(|p| Some((p.x?, p))).collect();
        chart
            .draw_series(LineSeries::new(
                pts.iter().map(|(x, p)| (*x, p.mean)),
                BLUE.mix(0.5).stroke_width(1),
            ))
            .map_err(e)?;
        chart
            .draw_series(pts.iter().filter_map(|(x, p)| {
                let (a, b) = p.interval?;
                Some(ErrorBar::new_vertical(
                    *x,
                    a,
                    p.mean,
                    b,
                    BLUE.stroke_width(2),
                    10,
                ))
            }))
            .map_err(e)?;
        chart
            .draw_series(
                pts.iter()
                    .map(|(x, p)| Circle::new((*x, p.mean), 4, BLUE.filled())),
            )
            .map_err(e)?;
    } else {
        let n = f.points.len().max(1) as i32;
        let names: Vec<&str> = f.points.iter().map(|p| p.label.as_str()).collect();
        let label = |v: &SegmentValue<i32>| match v {
            SegmentValue::CenterOf(i) | SegmentValue::Exact(i) => names
                .get(*i as usize)
                .map_or(String::new(), |s| s.to_string()),
            SegmentValue::Last => String::new(),
        };
        let mut chart = ChartBuilder::on(&plot)
            .margin(14)
            .x_label_area_size(42)
            .y_label_area_size(64)
            .build_cartesian_2d((0..n - 1).into_segmented(), y0..y1)
            .map_err(e)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_desc(f.x_label)
            .y_desc(f.y_label)
            .x_labels(n as usize)
            .x_label_formatter(&label)
            .label_style((FONT, 14))
            .axis_desc_style((FONT, 15))
            .draw()
            .map_err(e)?;
        // An i32 range holds its end: 0..n−1 gives the n segments.
        let ends = [SegmentValue::Exact(0), SegmentValue::Last];
        for y in [f.threshold, -f.threshold] {
            chart
                .draw_series(DashedLineSeries::new(
                    ends.iter().map(|x| (x.clone(), y)),
                    6,
                    4,
                    GREY.stroke_width(1),
                ))
                .map_err(e)?;
        }
        chart
            .draw_series(LineSeries::new(
                ends.iter().map(|x| (x.clone(), 0.0)),
                BLACK.stroke_width(1),
            ))
            .map_err(e)?;
        let at = |i: usize| SegmentValue::CenterOf(i as i32);
        chart
            .draw_series(f.points.iter().enumerate().filter_map(|(i, p)| {
                let (a, b) = p.interval?;
                Some(ErrorBar::new_vertical(
                    at(i),
                    a,
                    p.mean,
                    b,
                    BLUE.stroke_width(2),
                    14,
                ))
            }))
            .map_err(e)?;
        chart
            .draw_series(
                f.points
                    .iter()
                    .enumerate()
                    .map(|(i, p)| Circle::new((at(i), p.mean), 5, BLUE.filled())),
            )
            .map_err(e)?;
    }
    draw_legend(&foot.margin(0, 0, 70, 10), &f.legend(), 13)?;
    root.present().map_err(e)
}

/// Draws a residual profile to `path` (`.png` or `.svg`), atomically:
/// numeric covariates as points on their axis joined by a faint line,
/// categories as points on a categorical axis; every bin with its interval
/// bar, the ± relevance threshold, and a key under the chart.
pub fn residual_profile(f: &ProfileFigure<'_>, path: &Path) -> Result<(), FigureError> {
    let format = ImageFormat::from_path(path)?;
    register_fonts().map_err(|reason| FigureError::Render {
        path: path.to_path_buf(),
        reason,
    })?;
    for (i, p) in f.points.iter().enumerate() {
        let ok = p.mean.is_finite()
            && p.x.is_none_or(f64::is_finite)
            && p.interval
                .is_none_or(|(a, b)| a.is_finite() && b.is_finite());
        if !ok {
            return Err(FigureError::BadData {
                path: path.to_path_buf(),
                series: p.label.clone(),
                index: i,
                reason: format!("bin {p:?} is not finite"),
            });
        }
    }
    let legend_h = legend_height(&f.legend(), 800 - 80, 13) + 6;
    let size = (800, 480 + legend_h);
    render(
        path,
        format,
        size,
        |root| draw_profile(root, f, legend_h),
        |root| draw_profile(root, f, legend_h),
    )
}

/// Data of the bird's-eye figure.
#[derive(Debug, Clone, PartialEq)]
pub struct BevFigure<'a> {
    /// Title above the panels (recording, weather, MOR).
    pub title: String,
    /// `(name, points)` per panel, points `[x, y, z]` in metres.
    pub panels: &'a [(&'a str, &'a [[f32; 3]])],
    /// Half width of the square drawn around the sensor, metres.
    pub half_extent_m: f64,
}

/// Viridis at `t` in `[0, 1]` (five anchors of matplotlib's map,
/// interpolated; plotters' colormaps feature is not worth a dependency
/// change for one key).
fn viridis(t: f64) -> RGBColor {
    const A: [(f64, f64, f64); 5] = [
        (68.0, 1.0, 84.0),
        (59.0, 82.0, 139.0),
        (33.0, 145.0, 140.0),
        (94.0, 201.0, 98.0),
        (253.0, 231.0, 37.0),
    ];
    let t = t.clamp(0.0, 1.0) * 4.0;
    let k = (t.floor() as usize).min(3);
    let u = t - k as f64;
    let (a, b) = (A[k], A[k + 1]);
    let mix = |x: f64, y: f64| (x + (y - x) * u).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

const BEV_PANEL: u32 = 440;
/// Width of the colour key strip; its bar is 20 px wide, 76 px from the
/// right edge.
const BEV_KEY: u32 = 110;
const BEV_CAPTION: u32 = 28;

fn draw_bev<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    fig: &BevFigure<'_>,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let body = root.titled(&fig.title, (FONT, 20)).map_err(e)?;
    let half = fig.half_extent_m;
    let (w, _) = body.dim_in_pixel();
    let (panels, key) = body.split_horizontally(w.saturating_sub(BEV_KEY));
    let areas = panels.split_evenly((1, fig.panels.len().max(1)));
    for (area, (name, pts)) in areas.iter().zip(fig.panels) {
        let (cap, area) = area.split_vertically(BEV_CAPTION);
        cap.draw(&Text::new(
            format!("{name} ({} points)", pts.len()),
            (60, 4),
            (FONT, 16).into_font().color(&BLACK),
        ))
        .map_err(e)?;
        // Square plot: width BEV_PANEL − 2·8 − 50 = height − 2·8 − 40.
        let mut chart = ChartBuilder::on(&area)
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(-half..half, -half..half)
            .map_err(e)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("x (m)")
            .y_desc("y (m)")
            .label_style((FONT, 12))
            .axis_desc_style((FONT, 13))
            .draw()
            .map_err(e)?;
        let inside = pts
            .iter()
            .filter(|p| (p[0] as f64).abs() < half && (p[1] as f64).abs() < half);
        chart
            .draw_series(inside.map(|p| {
                let r = (p[0] as f64).hypot(p[1] as f64);
                // Pale yellow is left out: it vanishes on white.
                Pixel::new((p[0] as f64, p[1] as f64), viridis(0.85 * r / half))
            }))
            .map_err(e)?;
        chart
            .draw_series(std::iter::once(Cross::new(
                (0.0, 0.0),
                5,
                RED.stroke_width(2),
            )))
            .map_err(e)?;
    }
    // The colour key: range from the sensor.
    let (_, key_area) = key.split_vertically(BEV_CAPTION);
    let mut bar = ChartBuilder::on(&key_area)
        .margin_top(8)
        .margin_bottom(48)
        .margin_left(14)
        .margin_right(30)
        .y_label_area_size(0)
        .right_y_label_area_size(46)
        .build_cartesian_2d(0.0..1.0, 0.0..half)
        .map_err(e)?;
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc("range from sensor (m)")
        .label_style((FONT, 12))
        .axis_desc_style((FONT, 13))
        .draw()
        .map_err(e)?;
    let steps = 100;
    bar.draw_series((0..steps).map(|k| {
        let a = half * k as f64 / steps as f64;
        let b = half * (k + 1) as f64 / steps as f64;
        Rectangle::new(
            [(0.0, a), (1.0, b)],
            viridis(0.85 * (a + b) / (2.0 * half)).filled(),
        )
    }))
    .map_err(e)?;
    root.present().map_err(e)
}

/// Draws bird's-eye views of `fig.panels` side by side within
/// `±half_extent_m` of the sensor (square, metre axes, the sensor as a red
/// cross), coloured by range with a key, to `path`, atomically.
pub fn bev_panels(fig: &BevFigure<'_>, path: &Path) -> Result<(), FigureError> {
    let format = ImageFormat::from_path(path)?;
    register_fonts().map_err(|reason| FigureError::Render {
        path: path.to_path_buf(),
        reason,
    })?;
    if !(fig.half_extent_m.is_finite() && fig.half_extent_m > 0.0) {
        return Err(FigureError::BadData {
            path: path.to_path_buf(),
            series: "half_extent_m".into(),
            index: 0,
            reason: format!("{} is not a positive extent", fig.half_extent_m),
        });
    }
    let plot = BEV_PANEL - 16 - 50;
    let size = (
        BEV_PANEL * fig.panels.len().max(1) as u32 + BEV_KEY,
        // Title strip (about 30 px) + caption + square plot + axis area.
        30 + BEV_CAPTION + plot + 16 + 40,
    );
    render(
        path,
        format,
        size,
        |root| draw_bev(root, fig),
        |root| draw_bev(root, fig),
    )
}
