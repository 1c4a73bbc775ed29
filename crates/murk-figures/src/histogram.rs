//! The MOR histogram per weather class (the seed report's Figure 24).

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::output::{write_png, write_svg};
use crate::{FONT, FigureError, FigureOptions, ImageFormat, register_fonts};

/// Equal-width histogram bins `[start + k·width, start + (k+1)·width)`,
/// `k < count`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bins {
    /// Lower edge of the first bin.
    pub start: f64,
    /// Width of every bin.
    pub width: f64,
    /// Number of bins.
    pub count: usize,
}

impl Bins {
    /// Lower edge of bin `k`.
    pub fn edge(&self, k: usize) -> f64 {
        self.start + k as f64 * self.width
    }

    /// The bin of `x` (values past either end go to the nearest bin).
    pub fn index(&self, x: f64) -> usize {
        let k = ((x - self.start) / self.width).floor();
        if k <= 0.0 {
            0
        } else {
            (k as usize).min(self.count - 1)
        }
    }

    /// How many of `values` fall in each bin.
    pub fn counts(&self, values: &[f64]) -> Vec<u32> {
        let mut out = vec![0u32; self.count];
        for &x in values {
            out[self.index(x)] += 1;
        }
        out
    }
}

/// Bins shared by every series: a round width giving at most about
/// `target` bins over the range of all values, edges on multiples of the
/// width. One unit-wide bin at 0 when there is no value.
pub fn shared_bins(series: &[(&str, &[f64])], target: usize) -> Bins {
    let all = series.iter().flat_map(|(_, v)| v.iter().copied());
    let (min, max) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
        (lo.min(x), hi.max(x))
    });
    if !(min.is_finite() && max.is_finite()) {
        return Bins {
            start: 0.0,
            width: 1.0,
            count: 1,
        };
    }
    let width = murk_types::nice_step((max - min) / target.max(1) as f64);
    let start = (min / width).floor() * width;
    let count = ((max - start) / width).floor() as usize + 1;
    Bins {
        start,
        width,
        count,
    }
}

/// Colour of a series: the weather classes get fixed colours (Okabe–Ito,
/// readable by colour-blind readers); other labels cycle through the rest.
pub(crate) fn colour(label: &str, i: usize) -> RGBColor {
    const OTHERS: [RGBColor; 4] = [
        RGBColor(0, 158, 115),
        RGBColor(213, 94, 0),
        RGBColor(204, 121, 167),
        RGBColor(240, 228, 66),
    ];
    match label.to_ascii_lowercase().as_str() {
        "clear" => RGBColor(230, 159, 0),
        "fog" => RGBColor(110, 110, 110),
        "rain" => RGBColor(0, 114, 178),
        "snow" => RGBColor(86, 180, 233),
        _ => OTHERS[i % OTHERS.len()],
    }
}

fn check_data(path: &Path, series: &[(&str, &[f64])]) -> Result<(), FigureError> {
    for (name, values) in series {
        if let Some((index, v)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(FigureError::BadData {
                path: path.to_path_buf(),
                series: name.to_string(),
                index,
                reason: format!("MOR {v} is not a finite number"),
            });
        }
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    series: &[(&str, &[f64])],
    bins: Bins,
    opts: &FigureOptions,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let body = match &opts.title {
        Some(t) => root.titled(t, (FONT, 22)).map_err(e)?,
        None => root.clone(),
    };
    let panels = body.split_evenly((series.len().max(1), 1));
    let (x0, x1) = (bins.start, bins.edge(bins.count));
    for (i, (panel, (name, values))) in panels.iter().zip(series).enumerate() {
        let counts = bins.counts(values);
        let ymax = counts.iter().copied().max().unwrap_or(0) + 1;
        let fill = colour(name, i);
        let mut chart = ChartBuilder::on(panel)
            .caption(format!("{name} (n = {})", values.len()), (FONT, 18))
            .margin(12)
            .x_label_area_size(42)
            .y_label_area_size(56)
            .build_cartesian_2d(x0..x1, 0u32..ymax)
            .map_err(e)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_desc("MOR (m)")
            .y_desc("recordings")
            .label_style((FONT, 14))
            .axis_desc_style((FONT, 15))
            .y_labels(ymax.min(6) as usize)
            .x_label_formatter(&|x| format!("{x:.0}"))
            .draw()
            .map_err(e)?;
        let bars = counts.iter().enumerate().filter(|(_, c)| **c > 0);
        chart
            .draw_series(bars.clone().map(|(k, &c)| {
                Rectangle::new([(bins.edge(k), 0), (bins.edge(k + 1), c)], fill.filled())
            }))
            .map_err(e)?;
        chart
            .draw_series(bars.map(|(k, &c)| {
                Rectangle::new(
                    [(bins.edge(k), 0), (bins.edge(k + 1), c)],
                    BLACK.stroke_width(1),
                )
            }))
            .map_err(e)?;
        if values.is_empty() {
            let (w, h) = panel.dim_in_pixel();
            panel
                .draw(&Text::new(
                    "no recording",
                    (w as i32 / 2 - 50, h as i32 / 2),
                    (FONT, 16).into_font().color(&BLACK),
                ))
                .map_err(e)?;
        }
    }
    root.present().map_err(e)
}

/// Draws the MOR histogram of each series (label, MORs in metres) as one
/// panel per series on shared bins, and writes it to `path` (`.png` or
/// `.svg`) atomically.
pub fn mor_histogram(
    series: &[(&str, &[f64])],
    opts: &FigureOptions,
    path: &Path,
) -> Result<(), FigureError> {
    let format = ImageFormat::from_path(path)?;
    check_data(path, series)?;
    register_fonts().map_err(|reason| FigureError::Render {
        path: path.to_path_buf(),
        reason,
    })?;
    let bins = shared_bins(series, 20);
    let title_h = if opts.title.is_some() { 40 } else { 0 };
    let size = (
        opts.width.max(200),
        opts.panel_height.max(100) * series.len().max(1) as u32 + title_h,
    );
    match format {
        ImageFormat::Png => write_png(path, size, |root| draw(root, series, bins, opts)),
        ImageFormat::Svg => write_svg(path, size, |root| draw(root, series, bins, opts)),
    }
}

/// Writes `mor-histogram.png` and `mor-histogram.svg` into `dir` (which must
/// exist) and returns their paths.
pub fn write_mor_histograms(
    series: &[(&str, &[f64])],
    opts: &FigureOptions,
    dir: &Path,
) -> Result<[PathBuf; 2], FigureError> {
    let png = dir.join("mor-histogram.png");
    let svg = dir.join("mor-histogram.svg");
    mor_histogram(series, opts, &png)?;
    mor_histogram(series, opts, &svg)?;
    Ok([png, svg])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_bins_cover_all_series() {
        let fog = [52.0, 60.0, 75.0];
        let rain = [150.0, 175.0];
        let bins = shared_bins(&[("fog", &fog), ("rain", &rain)], 20);
        // (175 - 52) / 20 = 6.15 → 10 m bins from 50 m to 180 m.
        assert_eq!((bins.start, bins.width, bins.count), (50.0, 10.0, 13));
        assert_eq!(bins.index(52.0), 0);
        assert_eq!(bins.index(175.0), 12);
        assert_eq!(bins.counts(&fog).iter().sum::<u32>(), 3);
        assert_eq!(bins.counts(&rain)[10], 1);
    }

    #[test]
    fn empty_data_gives_one_bin() {
        let bins = shared_bins(&[("fog", &[])], 20);
        assert_eq!(bins.count, 1);
    }
}
