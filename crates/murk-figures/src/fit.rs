//! The figures of a fit: range vs MOR by class with the quantiles and the
//! fitted lines (the seed's Figure 26), slope vs reflectivity (Figure 27) and
//! the ghost / ring histograms with their fitted Gaussians (Figure 29).
//!
//! Like every figure of this crate they take plain data; `murk fit` fills it
//! from its fitted table.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::legend::{Entry, Swatch, draw_legend, legend_height, short};
use crate::output::{write_png, write_svg};
use crate::{FONT, FigureError, FigureOptions, ImageFormat, register_fonts};

const KEPT: RGBColor = RGBColor(0, 158, 115);
const LOST: RGBColor = RGBColor(213, 94, 0);
const LAW: RGBColor = RGBColor(213, 94, 0);

/// Colours of line groups (reflectivity bands): dark, far from the orange
/// and green of the counts, distinct for colour-blind readers.
const GROUPS: [RGBColor; 5] = [
    RGBColor(0, 70, 160),
    RGBColor(150, 30, 120),
    RGBColor(0, 0, 0),
    RGBColor(120, 90, 0),
    RGBColor(90, 170, 230),
];

/// The colour of line group `g`.
fn group_colour(g: usize) -> RGBColor {
    GROUPS[g % GROUPS.len()]
}

/// Width of the legend strip right of a chart, pixels.
const LEGEND_W: u32 = 330;

/// A curve through the origin, `range = slope · MOR^exponent`: a line
/// (`exponent` 1) or a band's bent law `a·MOR^b`.
#[derive(Debug, Clone, PartialEq)]
pub struct SlopeLine {
    /// Legend label, as the table names the value
    /// (`vanishing_slope [0, 10) = 0.3`).
    pub label: String,
    /// Slope (range per metre of MOR, range scale included), or the bent
    /// law's coefficient `a` times the range scale.
    pub slope: f64,
    /// Exponent of MOR: 1 for a line, `b` for a bent law.
    pub exponent: f64,
    /// Colour group (one per reflectivity band); the markers of the same
    /// group share its colour.
    pub group: usize,
    /// True for the seed's estimate (dashed), false for the
    /// maximum-likelihood one (solid).
    pub seed: bool,
}

/// One MOR bin's quantile marker.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuantileMarker {
    /// MOR, metres.
    pub mor: f64,
    /// Quantile of the clear range of no-change returns, metres.
    pub range: f64,
    /// True when the bin entered the regression (filled marker); hollow
    /// otherwise (censored or too few points).
    pub used: bool,
    /// Colour group, as in [`SlopeLine::group`].
    pub group: usize,
}

/// Data of the range-vs-MOR figure (Figure 26) of one weather.
#[derive(Debug, Clone, PartialEq)]
pub struct RangeMorFigure<'a> {
    /// Weather name for the caption.
    pub weather: &'a str,
    /// MOR of each bin, metres.
    pub mor: &'a [f64],
    /// Width of a MOR bin, metres.
    pub mor_bin_width: f64,
    /// Range step of the counts, metres.
    pub range_step: f64,
    /// `kept[bin][k]`: no-change returns with clear range in step `k`.
    pub kept: &'a [Vec<u64>],
    /// `lost[bin][k]`: disappeared returns with clear range in step `k`.
    pub lost: &'a [Vec<u64>],
    /// Quantile per bin.
    pub quantiles: &'a [QuantileMarker],
    /// Fitted lines.
    pub lines: &'a [SlopeLine],
    /// What the figure must say in words: values the table leaves null (a
    /// law the data cannot pin down is said, not drawn), how lines are
    /// scaled. Shown under the legend.
    pub notes: &'a [String],
}

impl RangeMorFigure<'_> {
    fn legend(&self) -> Vec<Entry> {
        let mut out = vec![
            Entry::new("disappeared returns", Swatch::Fill(LOST)),
            Entry::new(
                "no-change returns (darker: more returns)",
                Swatch::Fill(KEPT),
            ),
        ];
        for l in self.lines {
            out.push(Entry::new(
                l.label.clone(),
                Swatch::Line {
                    colour: group_colour(l.group),
                    dashed: l.seed,
                    marker: None,
                },
            ));
        }
        let mut groups: Vec<usize> = self.quantiles.iter().map(|q| q.group).collect();
        groups.dedup();
        if !self.quantiles.is_empty() {
            out.push(Entry::new(
                "quantile per MOR bin, colour of its band (dashed line: their regression)",
                Swatch::Marker {
                    colour: group_colour(groups.first().copied().unwrap_or(0)),
                    filled: true,
                },
            ));
        }
        if self.quantiles.iter().any(|q| !q.used) {
            out.push(Entry::new(
                "MOR bin left out of the regression",
                Swatch::Marker {
                    colour: group_colour(groups.first().copied().unwrap_or(0)),
                    filled: false,
                },
            ));
        }
        out.extend(self.notes.iter().map(|n| Entry::note(n.clone())));
        out
    }

    /// The legend's lines and notes, top to bottom, as drawn.
    pub fn legend_labels(&self) -> Vec<String> {
        self.legend().into_iter().map(|e| e.label).collect()
    }
}

fn prepare(path: &Path) -> Result<ImageFormat, FigureError> {
    let format = ImageFormat::from_path(path)?;
    register_fonts().map_err(|reason| FigureError::Render {
        path: path.to_path_buf(),
        reason,
    })?;
    Ok(format)
}

fn bad(path: &Path, series: &str, index: usize, reason: String) -> FigureError {
    FigureError::BadData {
        path: path.to_path_buf(),
        series: series.to_string(),
        index,
        reason,
    }
}

pub(crate) fn render(
    path: &Path,
    format: ImageFormat,
    size: (u32, u32),
    draw_png: impl FnOnce(DrawingArea<BitMapBackend<'_>, Shift>) -> Result<(), String>,
    draw_svg: impl FnOnce(DrawingArea<SVGBackend<'_>, Shift>) -> Result<(), String>,
) -> Result<(), FigureError> {
    match format {
        ImageFormat::Png => write_png(path, size, draw_png),
        ImageFormat::Svg => write_svg(path, size, draw_svg),
    }
}

/// Draws range vs MOR: per MOR bin, the clear ranges of disappeared returns
/// (left half of the bin, orange) and of no-change returns (right half,
/// green), shaded by count; the per-bin quantiles and the fitted lines, one
/// colour per band (solid: maximum likelihood, dashed: the seed's quantile
/// regression). The legend and the notes stand right of the chart. Written
/// to `path` (`.png` or `.svg`).
pub fn range_vs_mor(
    data: &RangeMorFigure<'_>,
    opts: &FigureOptions,
    path: &Path,
) -> Result<(), FigureError> {
    let format = prepare(path)?;
    if data.kept.len() != data.mor.len() || data.lost.len() != data.mor.len() {
        return Err(bad(
            path,
            "kept/lost",
            0,
            format!(
                "{} MOR bins but {} kept and {} lost rows",
                data.mor.len(),
                data.kept.len(),
                data.lost.len()
            ),
        ));
    }
    if let Some((i, m)) = data.mor.iter().enumerate().find(|(_, m)| !m.is_finite()) {
        return Err(bad(path, "mor", i, format!("MOR {m} is not finite")));
    }
    if let Some((i, l)) = data
        .lines
        .iter()
        .enumerate()
        .find(|(_, l)| !l.slope.is_finite())
    {
        return Err(bad(
            path,
            &l.label,
            i,
            format!("slope {} is not finite", l.slope),
        ));
    }
    if !(data.mor_bin_width > 0.0 && data.range_step > 0.0) {
        return Err(bad(
            path,
            "steps",
            0,
            "bin width and range step must be > 0".into(),
        ));
    }
    let width = opts.width.max(200) + LEGEND_W;
    let legend_h = legend_height(&data.legend(), LEGEND_W, 13) + 60;
    let size = (
        width,
        (opts.panel_height.max(100) * 2).max(460).max(legend_h),
    );
    render(
        path,
        format,
        size,
        |root| draw_range_mor(root, data, opts),
        |root| draw_range_mor(root, data, opts),
    )
}

/// The points of `y = slope · x^exponent` over `[x0, x1]` that stay below
/// `ymax` (a curve leaving the chart ends at its edge instead of running
/// along it).
fn clipped_line(slope: f64, exponent: f64, x0: f64, x1: f64, ymax: f64) -> Vec<(f64, f64)> {
    let end = if slope > 0.0 && exponent > 0.0 {
        x1.min((ymax / slope).powf(1.0 / exponent))
    } else {
        x1
    };
    if end <= x0 {
        return Vec::new();
    }
    (0..=50)
        .map(|k| {
            let x = x0 + (end - x0) * k as f64 / 50.0;
            (x, slope * x.max(0.0).powf(exponent))
        })
        .collect()
}

fn draw_range_mor<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    d: &RangeMorFigure<'_>,
    opts: &FigureOptions,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let caption = opts
        .title
        .clone()
        .unwrap_or_else(|| format!("{}: clear range of returns vs MOR", d.weather));
    let body = root.titled(&caption, (FONT, 20)).map_err(e)?;
    let (w, _) = body.dim_in_pixel();
    let (plot, side) = body.split_horizontally(w.saturating_sub(LEGEND_W));
    let half = d.mor_bin_width / 2.0;
    let x0 = d.mor.iter().copied().fold(f64::INFINITY, f64::min) - half;
    let x1 = d.mor.iter().copied().fold(f64::NEG_INFINITY, f64::max) + half;
    let (x0, x1) = if x0.is_finite() {
        (x0.max(0.0), x1)
    } else {
        (0.0, 1.0)
    };
    let top = |rows: &[Vec<u64>]| {
        rows.iter()
            .filter_map(|r| r.iter().rposition(|c| *c > 0))
            .max()
            .map_or(0.0, |k| (k + 1) as f64 * d.range_step)
    };
    let qmax = d.quantiles.iter().map(|q| q.range).fold(0.0, f64::max);
    let ymax = top(d.kept).max(top(d.lost)).max(qmax).max(1.0) * 1.05;
    let mut chart = ChartBuilder::on(&plot)
        .margin(14)
        .x_label_area_size(44)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, 0.0..ymax)
        .map_err(e)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_desc("MOR (m)")
        .y_desc("clear range (m)")
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 15))
        .draw()
        .map_err(e)?;
    let peak = d
        .kept
        .iter()
        .chain(d.lost)
        .flat_map(|r| r.iter().copied())
        .max()
        .unwrap_or(1)
        .max(1) as f64;
    // Light enough for the lines and markers on top to stay readable.
    let shade = |c: u64| 0.12 + 0.6 * ((c as f64).ln_1p() / peak.ln_1p());
    for (i, &m) in d.mor.iter().enumerate() {
        let w = 0.45 * half;
        for (rows, colour, left) in [(d.lost, LOST, true), (d.kept, KEPT, false)] {
            let (a, b) = if left {
                (m - w * 2.0, m)
            } else {
                (m, m + w * 2.0)
            };
            chart
                .draw_series(
                    rows[i]
                        .iter()
                        .enumerate()
                        .filter(|(_, c)| **c > 0)
                        .map(|(k, &c)| {
                            let y = k as f64 * d.range_step;
                            Rectangle::new(
                                [(a, y), (b, y + d.range_step)],
                                colour.mix(shade(c)).filled(),
                            )
                        }),
                )
                .map_err(e)?;
        }
    }
    for l in d.lines {
        let colour = group_colour(l.group);
        let pts = clipped_line(l.slope, l.exponent, x0, x1, ymax);
        if l.seed {
            chart
                .draw_series(DashedLineSeries::new(pts, 8, 5, colour.stroke_width(2)))
                .map_err(e)?;
        } else {
            chart
                .draw_series(LineSeries::new(pts, colour.stroke_width(2)))
                .map_err(e)?;
        }
    }
    chart
        .draw_series(d.quantiles.iter().map(|q| {
            let c = group_colour(q.group);
            let style = if q.used {
                c.filled()
            } else {
                c.stroke_width(2)
            };
            Circle::new((q.mor, q.range), 4, style)
        }))
        .map_err(e)?;
    let legend = side.margin(30, 0, 4, 4);
    draw_legend(&legend, &d.legend(), 13)?;
    root.present().map_err(e)
}

/// One series of the slope-vs-reflectivity figure.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepSeries {
    /// Legend label, as the table names the values (`fog: slope`,
    /// `fog: slope_q99`).
    pub label: String,
    /// `(reflectivity, slope)` per band (band centres); a null slope breaks
    /// the line there.
    pub points: Vec<(f64, Option<f64>)>,
    /// Colour group (one per weather).
    pub group: usize,
    /// True for the seed's estimate (dashed, hollow markers).
    pub seed: bool,
}

/// Data of the slope-vs-reflectivity figure (Figure 27).
#[derive(Debug, Clone, PartialEq)]
pub struct SweepFigure<'a> {
    /// One line per weather and estimator.
    pub series: &'a [SweepSeries],
    /// Colour of each group (`(name, colour index)` is up to the caller; a
    /// name listed here picks the weather colour of [`crate::mor_histogram`]).
    pub group_names: &'a [String],
    /// What the figure must say in words (null bands, where an unbounded
    /// band is drawn).
    pub notes: &'a [String],
}

impl SweepFigure<'_> {
    fn colour(&self, g: usize) -> RGBColor {
        match self.group_names.get(g) {
            Some(name) => crate::histogram::colour(name, g),
            None => group_colour(g),
        }
    }

    fn legend(&self) -> Vec<Entry> {
        let mut out: Vec<Entry> = self
            .series
            .iter()
            .map(|s| {
                Entry::new(
                    s.label.clone(),
                    Swatch::Line {
                        colour: self.colour(s.group),
                        dashed: s.seed,
                        marker: Some(!s.seed),
                    },
                )
            })
            .collect();
        if self.series.iter().any(|s| s.seed) && self.series.iter().any(|s| !s.seed) {
            out.push(Entry::note(
                "solid, filled: maximum-likelihood slope (vanishing_slope); dashed, hollow: the seed's quantile regression (vanishing_slope_q99)",
            ));
        }
        out.extend(self.notes.iter().map(|n| Entry::note(n.clone())));
        out
    }

    /// The legend's lines and notes, top to bottom, as drawn.
    pub fn legend_labels(&self) -> Vec<String> {
        self.legend().into_iter().map(|e| e.label).collect()
    }
}

/// Splits a series at its null values into runs of points.
fn runs(points: &[(f64, Option<f64>)]) -> Vec<Vec<(f64, f64)>> {
    let mut out = vec![Vec::new()];
    for &(x, y) in points {
        match y {
            Some(y) => out.last_mut().expect("never empty").push((x, y)),
            None => out.push(Vec::new()),
        }
    }
    out.retain(|r| !r.is_empty());
    out
}

/// Draws vanishing slope vs reflectivity (Figure 27), one line per series
/// (solid: maximum likelihood, dashed: the seed's estimate), with its legend
/// right of the chart, to `path` (`.png` or `.svg`).
pub fn slope_vs_reflectivity(
    fig: &SweepFigure<'_>,
    opts: &FigureOptions,
    path: &Path,
) -> Result<(), FigureError> {
    let format = prepare(path)?;
    for s in fig.series {
        if let Some((i, p)) = s
            .points
            .iter()
            .enumerate()
            .find(|(_, p)| !(p.0.is_finite() && p.1.is_none_or(f64::is_finite)))
        {
            return Err(bad(path, &s.label, i, format!("point {p:?} is not finite")));
        }
    }
    let legend_h = legend_height(&fig.legend(), LEGEND_W, 13) + 60;
    let size = (
        opts.width.max(200) + LEGEND_W,
        (opts.panel_height.max(100) * 2).max(420).max(legend_h),
    );
    render(
        path,
        format,
        size,
        |root| draw_sweep(root, fig, opts),
        |root| draw_sweep(root, fig, opts),
    )
}

fn draw_sweep<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    fig: &SweepFigure<'_>,
    opts: &FigureOptions,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let caption = opts
        .title
        .clone()
        .unwrap_or_else(|| "vanishing slope vs reflectivity".to_string());
    let body = root.titled(&caption, (FONT, 20)).map_err(e)?;
    let (w, _) = body.dim_in_pixel();
    let (plot, side) = body.split_horizontally(w.saturating_sub(LEGEND_W));
    let pts = fig
        .series
        .iter()
        .flat_map(|s| s.points.iter().filter_map(|p| Some((p.0, p.1?))));
    let (xmax, ymax) = pts.fold((1.0f64, 0.1f64), |(a, b), p| (a.max(p.0), b.max(p.1)));
    let mut chart = ChartBuilder::on(&plot)
        .margin(14)
        .x_label_area_size(44)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..xmax * 1.05, 0.0..ymax * 1.15)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("clear reflectivity (band centre)")
        .y_desc("vanishing slope")
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 15))
        .draw()
        .map_err(e)?;
    for s in fig.series {
        let c = fig.colour(s.group);
        for run in runs(&s.points) {
            if s.seed {
                chart
                    .draw_series(DashedLineSeries::new(run.clone(), 6, 4, c.stroke_width(2)))
                    .map_err(e)?;
            } else {
                chart
                    .draw_series(LineSeries::new(run.clone(), c.stroke_width(2)))
                    .map_err(e)?;
            }
            let seed = s.seed;
            chart
                .draw_series(run.into_iter().map(|p| {
                    let style = if seed { c.stroke_width(2) } else { c.filled() };
                    Circle::new(p, 4, style)
                }))
                .map_err(e)?;
        }
    }
    let legend = side.margin(30, 0, 4, 4);
    draw_legend(&legend, &fig.legend(), 13)?;
    root.present().map_err(e)
}

/// The law drawn over a histogram, or why none is.
#[derive(Debug, Clone, PartialEq)]
pub enum PanelLaw {
    /// A fitted (truncated) normal law: drawn as a curve, its numbers in the
    /// label.
    Fitted {
        /// Mean of the untruncated normal.
        mean: f64,
        /// Its standard deviation (> 0).
        std: f64,
        /// Standard error of `mean`, when known.
        mean_std_error: Option<f64>,
        /// Standard error of `std`, when known.
        std_std_error: Option<f64>,
    },
    /// No law to draw (the table holds none, or one the data cannot pin
    /// down): the text is said in the panel instead of a curve.
    Unknown(String),
}

/// A truncation interval `[lower, upper)`; `None`: unbounded on that side.
pub type Truncation = (Option<f64>, Option<f64>);

/// One histogram with its fitted (truncated) Gaussian.
#[derive(Debug, Clone, PartialEq)]
pub struct GaussianPanel {
    /// Panel caption (`ghost distance (m)`).
    pub title: String,
    /// Lower edge of the first bin.
    pub lo: f64,
    /// Bin width.
    pub step: f64,
    /// Counts per bin.
    pub counts: Vec<u64>,
    /// The law, or why there is none.
    pub law: PanelLaw,
    /// Truncation interval of the law.
    pub truncation: Truncation,
}

impl GaussianPanel {
    /// The line said above the histogram: the law with its numbers, or the
    /// reason there is no curve.
    pub fn law_label(&self) -> String {
        match &self.law {
            PanelLaw::Fitted {
                mean,
                std,
                mean_std_error,
                std_std_error,
            } => {
                let pm = |x: f64, se: Option<f64>| match se {
                    Some(se) => format!("{} ± {}", short(x), short(se)),
                    None => short(x),
                };
                let cut = match self.truncation {
                    (None, None) => String::new(),
                    (a, b) => format!(", cut to {}", crate::legend::window(a, b)),
                };
                format!(
                    "fitted normal: mean {}, std {}{cut}",
                    pm(*mean, *mean_std_error),
                    pm(*std, *std_std_error)
                )
            }
            PanelLaw::Unknown(why) => format!("no law drawn: {why}"),
        }
    }
}

fn normal_cdf(z: f64) -> f64 {
    // Abramowitz–Stegun 7.1.26 is enough to draw a curve (1e-7).
    let t = 1.0 / (1.0 + 0.327_591_1 * z.abs() / std::f64::consts::SQRT_2);
    let y = 1.0
        - (((((1.061_405_429 * t - 1.453_152_027) * t) + 1.421_413_741) * t - 0.284_496_736) * t
            + 0.254_829_592)
            * t
            * (-(z * z) / 2.0).exp();
    if z >= 0.0 {
        0.5 * (1.0 + y)
    } else {
        0.5 * (1.0 - y)
    }
}

/// Height of the text strip above each histogram, pixels.
fn law_strip(panels: &[GaussianPanel], panel_w: u32) -> u32 {
    let lines = panels
        .iter()
        .map(|p| {
            crate::legend::wrap(&p.law_label(), crate::legend::chars_in(panel_w - 50, 12)).len()
        })
        .max()
        .unwrap_or(1) as u32;
    lines * 16 + 6
}

/// Draws histograms with their fitted Gaussians (Figure 29), one panel each
/// in a grid of two columns, to `path` (`.png` or `.svg`). Each panel says
/// its law above the bars (never over them); a panel whose law is
/// [`PanelLaw::Unknown`] says why and draws no curve.
pub fn gaussian_histograms(
    panels: &[GaussianPanel],
    opts: &FigureOptions,
    path: &Path,
) -> Result<(), FigureError> {
    let format = prepare(path)?;
    for p in panels {
        if !(p.step > 0.0 && p.lo.is_finite()) {
            return Err(bad(path, &p.title, 0, "bin width must be > 0".into()));
        }
        if let PanelLaw::Fitted { mean, std, .. } = p.law
            && !(mean.is_finite() && std > 0.0 && std.is_finite())
        {
            return Err(bad(
                path,
                &p.title,
                0,
                format!("law ({mean}, {std}) is not usable"),
            ));
        }
    }
    let rows = panels.len().div_ceil(2).max(1) as u32;
    let title_h = if opts.title.is_some() { 40 } else { 0 };
    let width = opts.width.max(200);
    let strip = law_strip(panels, width / 2);
    let size = (width, (opts.panel_height.max(100) + strip) * rows + title_h);
    render(
        path,
        format,
        size,
        |root| draw_gaussians(root, panels, opts, strip),
        |root| draw_gaussians(root, panels, opts, strip),
    )
}

fn draw_gaussians<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    panels: &[GaussianPanel],
    opts: &FigureOptions,
    strip: u32,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let body = match &opts.title {
        Some(t) => root.titled(t, (FONT, 22)).map_err(e)?,
        None => root.clone(),
    };
    let areas = body.split_evenly((panels.len().div_ceil(2).max(1), 2));
    for (area, p) in areas.iter().zip(panels) {
        let n: u64 = p.counts.iter().sum();
        let caption = format!("{} (n = {n})", p.title);
        let area = area.titled(&caption, (FONT, 16)).map_err(e)?;
        let (text, area) = area.split_vertically(strip);
        let swatch = match p.law {
            PanelLaw::Fitted { .. } => Swatch::Line {
                colour: LAW,
                dashed: false,
                marker: None,
            },
            PanelLaw::Unknown(_) => Swatch::Note,
        };
        draw_legend(
            &text.margin(0, 0, 40, 4),
            &[Entry::new(p.law_label(), swatch)],
            12,
        )?;
        let x1 = p.lo + p.step * p.counts.len().max(1) as f64;
        let ymax = p.counts.iter().copied().max().unwrap_or(0).max(1) as f64 * 1.15;
        let mut chart = ChartBuilder::on(&area)
            .margin(10)
            .x_label_area_size(36)
            .y_label_area_size(50)
            .build_cartesian_2d(p.lo..x1, 0.0..ymax)
            .map_err(e)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .y_desc("returns")
            .label_style((FONT, 12))
            .axis_desc_style((FONT, 12))
            .draw()
            .map_err(e)?;
        chart
            .draw_series(
                p.counts
                    .iter()
                    .enumerate()
                    .filter(|(_, c)| **c > 0)
                    .map(|(k, &c)| {
                        let a = p.lo + k as f64 * p.step;
                        Rectangle::new(
                            [(a, 0.0), (a + p.step, c as f64)],
                            RGBColor(0, 114, 178).mix(0.6).filled(),
                        )
                    }),
            )
            .map_err(e)?;
        if let PanelLaw::Fitted {
            mean: m, std: s, ..
        } = p.law
        {
            let lo = p.truncation.0.map_or(0.0, |a| normal_cdf((a - m) / s));
            let hi = p.truncation.1.map_or(1.0, |b| normal_cdf((b - m) / s));
            let z = (hi - lo).max(1e-12);
            let scale = n as f64 * p.step / (s * (2.0 * std::f64::consts::PI).sqrt() * z);
            // The curve is drawn where the law lives (inside its truncation),
            // and ends at the top of the chart rather than running along it.
            let mut run = Vec::new();
            let mut runs_out = Vec::new();
            for k in 0..=200 {
                let x = p.lo + (x1 - p.lo) * k as f64 / 200.0;
                let inside =
                    p.truncation.0.is_none_or(|a| x >= a) && p.truncation.1.is_none_or(|b| x < b);
                let y = scale * (-0.5 * ((x - m) / s).powi(2)).exp();
                if inside && y <= ymax {
                    run.push((x, y));
                } else if !run.is_empty() {
                    runs_out.push(std::mem::take(&mut run));
                }
            }
            runs_out.push(run);
            for r in runs_out.into_iter().filter(|r| r.len() > 1) {
                chart
                    .draw_series(LineSeries::new(r, LAW.stroke_width(2)))
                    .map_err(e)?;
            }
        }
    }
    root.present().map_err(e)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_are_written_and_reproducible() {
        let dir = tempfile::tempdir().unwrap();
        let kept = vec![vec![5, 9, 3, 0], vec![6, 2, 0, 0]];
        let lost = vec![vec![0, 1, 4, 7], vec![0, 3, 8, 9]];
        let q = [
            QuantileMarker {
                mor: 50.0,
                range: 1.4,
                used: true,
                group: 0,
            },
            QuantileMarker {
                mor: 100.0,
                range: 0.9,
                used: false,
                group: 0,
            },
        ];
        let lines = [
            SlopeLine {
                label: "vanishing_slope [0, ∞) = 0.03".into(),
                slope: 0.03,
                exponent: 1.0,
                group: 0,
                seed: false,
            },
            SlopeLine {
                label: "vanishing_slope_q99 [0, ∞) = 0.02".into(),
                slope: 0.02,
                exponent: 1.0,
                group: 0,
                seed: true,
            },
        ];
        let fig = RangeMorFigure {
            weather: "fog",
            mor: &[50.0, 100.0],
            mor_bin_width: 10.0,
            range_step: 0.5,
            kept: &kept,
            lost: &lost,
            quantiles: &q,
            lines: &lines,
            notes: &[],
        };
        let a = dir.path().join("a.png");
        let b = dir.path().join("b.png");
        range_vs_mor(&fig, &FigureOptions::default(), &a).unwrap();
        range_vs_mor(&fig, &FigureOptions::default(), &b).unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
        range_vs_mor(&fig, &FigureOptions::default(), &dir.path().join("a.svg")).unwrap();

        let s = [SweepSeries {
            label: "fog: reflectivity_sweep slope".into(),
            points: vec![(2.5, Some(0.3)), (7.5, None), (15.0, Some(0.35))],
            group: 0,
            seed: false,
        }];
        let sweep = SweepFigure {
            series: &s,
            group_names: &["fog".to_string()],
            notes: &[],
        };
        slope_vs_reflectivity(&sweep, &FigureOptions::default(), &dir.path().join("s.png"))
            .unwrap();

        let p = [GaussianPanel {
            title: "ghost distance (m)".into(),
            lo: 3.0,
            step: 0.5,
            counts: vec![10, 20, 25, 18, 9, 4, 2, 1, 0, 1, 0, 0, 0, 1],
            law: PanelLaw::Fitted {
                mean: 5.0,
                std: 1.7,
                mean_std_error: None,
                std_std_error: None,
            },
            truncation: (Some(3.0), Some(10.0)),
        }];
        gaussian_histograms(&p, &FigureOptions::default(), &dir.path().join("g.png")).unwrap();
        assert!(std::fs::metadata(dir.path().join("g.png")).unwrap().len() > 1000);
    }

    #[test]
    fn ragged_rows_are_rejected() {
        let dir = tempfile::tempdir().unwrap();
        let fig = RangeMorFigure {
            weather: "fog",
            mor: &[50.0, 100.0],
            mor_bin_width: 10.0,
            range_step: 0.5,
            kept: &[vec![1]],
            lost: &[vec![1], vec![2]],
            quantiles: &[],
            lines: &[],
            notes: &[],
        };
        let e = range_vs_mor(&fig, &FigureOptions::default(), &dir.path().join("x.png"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("2 MOR bins but 1 kept"), "{e}");
    }

    #[test]
    fn lines_end_at_the_top_of_the_chart() {
        let pts = clipped_line(0.5, 1.0, 0.0, 100.0, 20.0);
        let last = *pts.last().unwrap();
        assert!(
            (last.0 - 40.0).abs() < 1e-9 && (last.1 - 20.0).abs() < 1e-9,
            "{last:?}"
        );
        assert!(pts.iter().all(|p| p.1 <= 20.0 + 1e-9));
        assert_eq!(
            clipped_line(0.1, 1.0, 0.0, 100.0, 20.0).last(),
            Some(&(100.0, 10.0))
        );
        // A bent law 2·x^0.5 meets the top (20) at x = 100 and is a curve:
        // at x = 25 it is 10, not the chord's 5.
        let bent = clipped_line(2.0, 0.5, 0.0, 400.0, 20.0);
        let last = *bent.last().unwrap();
        assert!(
            (last.0 - 100.0).abs() < 1e-9 && (last.1 - 20.0).abs() < 1e-9,
            "{last:?}"
        );
        let quarter = bent.iter().find(|p| (p.0 - 26.0).abs() < 1e-9).unwrap();
        assert!((quarter.1 - 2.0 * 26f64.sqrt()).abs() < 1e-9, "{quarter:?}");
    }

    #[test]
    fn null_values_break_a_series() {
        let r = runs(&[
            (1.0, Some(1.0)),
            (2.0, Some(2.0)),
            (3.0, None),
            (4.0, Some(4.0)),
        ]);
        assert_eq!(r, vec![vec![(1.0, 1.0), (2.0, 2.0)], vec![(4.0, 4.0)]]);
        assert!(runs(&[(1.0, None)]).is_empty());
    }

    #[test]
    fn cdf_approximation_is_close() {
        assert!((normal_cdf(0.0) - 0.5).abs() < 1e-7);
        assert!((normal_cdf(1.959_964) - 0.975).abs() < 1e-6);
        assert!((normal_cdf(-1.0) - 0.158_655_25).abs() < 1e-6);
    }
}
