//! The figures of a fit: range vs MOR by class with the quantiles and the
//! fitted lines (the seed's Figure 26), slope vs reflectivity (Figure 27) and
//! the ghost / ring histograms with their fitted Gaussians (Figure 29).
//!
//! Like every figure of this crate they take plain data; `murk fit` fills it
//! from its fitted table.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::output::{write_png, write_svg};
use crate::{FONT, FigureError, FigureOptions, ImageFormat, register_fonts};

const KEPT: RGBColor = RGBColor(0, 158, 115);
const LOST: RGBColor = RGBColor(213, 94, 0);
const QUANT: RGBColor = RGBColor(0, 0, 0);
const ML: RGBColor = RGBColor(0, 114, 178);
const SEED: RGBColor = RGBColor(120, 120, 120);

/// A line through the origin, `range = slope · MOR`.
#[derive(Debug, Clone, PartialEq)]
pub struct SlopeLine {
    /// Legend label.
    pub label: String,
    /// Slope (range per metre of MOR, range scale included).
    pub slope: f64,
    /// True for the seed's estimate (drawn dashed grey), false for the
    /// maximum-likelihood one (solid blue).
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

fn render(
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
/// green), shaded by count; the per-bin quantiles (black, hollow when not
/// used) and the fitted lines. Written to `path` (`.png` or `.svg`).
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
    if !(data.mor_bin_width > 0.0 && data.range_step > 0.0) {
        return Err(bad(
            path,
            "steps",
            0,
            "bin width and range step must be > 0".into(),
        ));
    }
    let size = (
        opts.width.max(200),
        (opts.panel_height.max(100) * 2).max(420),
    );
    render(
        path,
        format,
        size,
        |root| draw_range_mor(root, data, opts),
        |root| draw_range_mor(root, data, opts),
    )
}

fn draw_range_mor<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    d: &RangeMorFigure<'_>,
    opts: &FigureOptions,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
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
    let ymax = top(d.kept).max(top(d.lost)).max(1.0) * 1.05;
    let caption = opts
        .title
        .clone()
        .unwrap_or_else(|| format!("{}: clear range of returns vs MOR", d.weather));
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, (FONT, 20))
        .margin(14)
        .x_label_area_size(44)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, 0.0..ymax)
        .map_err(e)?;
    chart
        .configure_mesh()
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
    let shade = |c: u64| 0.15 + 0.85 * ((c as f64).ln_1p() / peak.ln_1p());
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
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(x0, 0.0), (x0, 0.0)],
            LOST.filled(),
        )))
        .map_err(e)?
        .label("disappeared")
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], LOST.filled()));
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(x0, 0.0), (x0, 0.0)],
            KEPT.filled(),
        )))
        .map_err(e)?
        .label("no change")
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], KEPT.filled()));
    chart
        .draw_series(d.quantiles.iter().map(|q| {
            let style = if q.used {
                QUANT.filled()
            } else {
                QUANT.stroke_width(1)
            };
            Circle::new((q.mor, q.range), 4, style)
        }))
        .map_err(e)?
        .label("quantile per MOR bin (hollow: not used)")
        .legend(|(x, y)| Circle::new((x + 6, y), 4, QUANT.filled()));
    for l in d.lines {
        let colour = if l.seed { SEED } else { ML };
        let pts = (0..=50).map(|k| {
            let x = x0 + (x1 - x0) * k as f64 / 50.0;
            (x, l.slope * x)
        });
        let series = if l.seed {
            chart.draw_series(DashedLineSeries::new(pts, 8, 5, colour.stroke_width(2)))
        } else {
            chart.draw_series(LineSeries::new(pts, colour.stroke_width(2)))
        };
        series
            .map_err(e)?
            .label(l.label.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, 13))
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(e)?;
    root.present().map_err(e)
}

/// One series of the slope-vs-reflectivity figure.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepSeries {
    /// Legend label (`fog ML`, `fog q99`, …).
    pub label: String,
    /// `(reflectivity, slope)` points (band centres).
    pub points: Vec<(f64, f64)>,
    /// True for the seed's estimate (dashed, hollow markers).
    pub seed: bool,
}

fn series_colour(label: &str, i: usize) -> RGBColor {
    let l = label.to_ascii_lowercase();
    if l.starts_with("fog") {
        RGBColor(90, 90, 90)
    } else if l.starts_with("rain") {
        RGBColor(0, 114, 178)
    } else if l.starts_with("snow") {
        RGBColor(86, 180, 233)
    } else {
        [
            RGBColor(0, 158, 115),
            RGBColor(213, 94, 0),
            RGBColor(204, 121, 167),
        ][i % 3]
    }
}

/// Draws vanishing slope vs reflectivity (Figure 27), one line per series,
/// to `path` (`.png` or `.svg`).
pub fn slope_vs_reflectivity(
    series: &[SweepSeries],
    opts: &FigureOptions,
    path: &Path,
) -> Result<(), FigureError> {
    let format = prepare(path)?;
    for s in series {
        if let Some((i, p)) = s
            .points
            .iter()
            .enumerate()
            .find(|(_, p)| !(p.0.is_finite() && p.1.is_finite()))
        {
            return Err(bad(path, &s.label, i, format!("point {p:?} is not finite")));
        }
    }
    let size = (
        opts.width.max(200),
        (opts.panel_height.max(100) * 2).max(400),
    );
    render(
        path,
        format,
        size,
        |root| draw_sweep(root, series, opts),
        |root| draw_sweep(root, series, opts),
    )
}

fn draw_sweep<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    series: &[SweepSeries],
    opts: &FigureOptions,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let pts = series.iter().flat_map(|s| s.points.iter());
    let (xmax, ymax) = pts.fold((1.0f64, 0.1f64), |(a, b), p| (a.max(p.0), b.max(p.1)));
    let caption = opts
        .title
        .clone()
        .unwrap_or_else(|| "vanishing slope vs reflectivity".to_string());
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, (FONT, 20))
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
    for (i, s) in series.iter().enumerate() {
        let c = series_colour(&s.label, i);
        let line = if s.seed {
            chart.draw_series(DashedLineSeries::new(
                s.points.iter().copied(),
                6,
                4,
                c.stroke_width(2),
            ))
        } else {
            chart.draw_series(LineSeries::new(s.points.iter().copied(), c.stroke_width(2)))
        };
        line.map_err(e)?
            .label(s.label.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], c.stroke_width(2)));
        let seed = s.seed;
        chart
            .draw_series(s.points.iter().map(|&p| {
                let style = if seed { c.stroke_width(1) } else { c.filled() };
                Circle::new(p, 4, style)
            }))
            .map_err(e)?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, 13))
        .position(SeriesLabelPosition::LowerRight)
        .draw()
        .map_err(e)?;
    root.present().map_err(e)
}

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
    /// Fitted law `(mean, std)`, if any.
    pub law: Option<(f64, f64)>,
    /// Truncation interval of the law (`None`: unbounded on that side).
    pub truncation: (Option<f64>, Option<f64>),
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

/// Draws histograms with their fitted Gaussians (Figure 29), one panel each
/// in a grid of two columns, to `path` (`.png` or `.svg`).
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
        if let Some((m, s)) = p.law
            && !(m.is_finite() && s > 0.0)
        {
            return Err(bad(
                path,
                &p.title,
                0,
                format!("law ({m}, {s}) is not usable"),
            ));
        }
    }
    let rows = panels.len().div_ceil(2).max(1) as u32;
    let title_h = if opts.title.is_some() { 40 } else { 0 };
    let size = (
        opts.width.max(200),
        opts.panel_height.max(100) * rows + title_h,
    );
    render(
        path,
        format,
        size,
        |root| draw_gaussians(root, panels, opts),
        |root| draw_gaussians(root, panels, opts),
    )
}

fn draw_gaussians<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    panels: &[GaussianPanel],
    opts: &FigureOptions,
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
        let x1 = p.lo + p.step * p.counts.len().max(1) as f64;
        let ymax = p.counts.iter().copied().max().unwrap_or(0).max(1) as f64 * 1.15;
        let mut chart = ChartBuilder::on(area)
            .caption(format!("{} (n = {n})", p.title), (FONT, 16))
            .margin(10)
            .x_label_area_size(36)
            .y_label_area_size(50)
            .build_cartesian_2d(p.lo..x1, 0.0..ymax)
            .map_err(e)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .label_style((FONT, 12))
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
        if let Some((m, s)) = p.law {
            let lo = p.truncation.0.map_or(0.0, |a| normal_cdf((a - m) / s));
            let hi = p.truncation.1.map_or(1.0, |b| normal_cdf((b - m) / s));
            let z = (hi - lo).max(1e-12);
            let scale = n as f64 * p.step / (s * (2.0 * std::f64::consts::PI).sqrt() * z);
            let curve = (0..=200).map(|k| {
                let x = p.lo + (x1 - p.lo) * k as f64 / 200.0;
                let inside =
                    p.truncation.0.is_none_or(|a| x >= a) && p.truncation.1.is_none_or(|b| x < b);
                let y = if inside {
                    scale * (-0.5 * ((x - m) / s).powi(2)).exp()
                } else {
                    0.0
                };
                (x, y.min(ymax))
            });
            chart
                .draw_series(LineSeries::new(curve, RGBColor(213, 94, 0).stroke_width(2)))
                .map_err(e)?
                .label(format!("N({m:.3}, {s:.3}²)"))
                .legend(|(x, y)| {
                    PathElement::new(
                        vec![(x, y), (x + 16, y)],
                        RGBColor(213, 94, 0).stroke_width(2),
                    )
                });
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font((FONT, 12))
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(e)?;
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
            },
            QuantileMarker {
                mor: 100.0,
                range: 0.9,
                used: false,
            },
        ];
        let lines = [
            SlopeLine {
                label: "ML".into(),
                slope: 0.03,
                seed: false,
            },
            SlopeLine {
                label: "q99".into(),
                slope: 0.02,
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
        };
        let a = dir.path().join("a.png");
        let b = dir.path().join("b.png");
        range_vs_mor(&fig, &FigureOptions::default(), &a).unwrap();
        range_vs_mor(&fig, &FigureOptions::default(), &b).unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
        range_vs_mor(&fig, &FigureOptions::default(), &dir.path().join("a.svg")).unwrap();

        let s = [SweepSeries {
            label: "fog ML".into(),
            points: vec![(2.5, 0.3), (7.5, 0.31), (15.0, 0.35)],
            seed: false,
        }];
        slope_vs_reflectivity(&s, &FigureOptions::default(), &dir.path().join("s.png")).unwrap();

        let p = [GaussianPanel {
            title: "ghost distance (m)".into(),
            lo: 3.0,
            step: 0.5,
            counts: vec![10, 20, 25, 18, 9, 4, 2, 1, 0, 1, 0, 0, 0, 1],
            law: Some((5.0, 1.7)),
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
        };
        let e = range_vs_mor(&fig, &FigureOptions::default(), &dir.path().join("x.png"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("2 MOR bins but 1 kept"), "{e}");
    }

    #[test]
    fn cdf_approximation_is_close() {
        assert!((normal_cdf(0.0) - 0.5).abs() < 1e-7);
        assert!((normal_cdf(1.959_964) - 0.975).abs() < 1e-6);
        assert!((normal_cdf(-1.0) - 0.158_655_25).abs() < 1e-6);
    }
}
