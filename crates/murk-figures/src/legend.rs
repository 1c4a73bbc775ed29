//! Legends and notes drawn in their own strip beside a chart, never over its
//! data, and the short number format of every figure label.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::FONT;

/// How a legend entry is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Swatch {
    /// A filled box.
    Fill(RGBColor),
    /// A line, solid or dashed, with an optional marker (`Some(true)`:
    /// filled).
    Line {
        colour: RGBColor,
        dashed: bool,
        marker: Option<bool>,
    },
    /// A marker alone (filled or hollow).
    Marker { colour: RGBColor, filled: bool },
    /// Text only: a note.
    Note,
}

/// One line of a legend.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Entry {
    pub label: String,
    pub swatch: Swatch,
}

impl Entry {
    pub(crate) fn new(label: impl Into<String>, swatch: Swatch) -> Entry {
        Entry {
            label: label.into(),
            swatch,
        }
    }

    pub(crate) fn note(label: impl Into<String>) -> Entry {
        Entry::new(label, Swatch::Note)
    }
}

/// Splits `text` into lines of at most `max` characters at spaces (a word
/// longer than `max` gets a line of its own).
pub(crate) fn wrap(text: &str, max: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        let len = line.chars().count();
        if len > 0 && len + 1 + word.chars().count() > max {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() || lines.is_empty() {
        lines.push(line);
    }
    lines
}

/// Characters of `font_px` text that fit in `width_px` (DejaVu Sans averages
/// a little over half its size per character).
pub(crate) fn chars_in(width_px: u32, font_px: u32) -> usize {
    ((width_px as f64) / (font_px as f64 * 0.58)).max(8.0) as usize
}

fn draw_swatch<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    swatch: Swatch,
    (x, y): (i32, i32),
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    match swatch {
        Swatch::Fill(c) => area.draw(&Rectangle::new([(x, y - 6), (x + 22, y + 6)], c.filled())),
        Swatch::Line {
            colour,
            dashed,
            marker,
        } => {
            if dashed {
                for k in 0..3 {
                    let a = x + k * 9;
                    area.draw(&PathElement::new(
                        vec![(a, y), (a + 5, y)],
                        colour.stroke_width(2),
                    ))?;
                }
            } else {
                area.draw(&PathElement::new(
                    vec![(x, y), (x + 24, y)],
                    colour.stroke_width(2),
                ))?;
            }
            match marker {
                Some(true) => area.draw(&Circle::new((x + 12, y), 4, colour.filled())),
                Some(false) => area.draw(&Circle::new((x + 12, y), 4, colour.stroke_width(1))),
                None => Ok(()),
            }
        }
        Swatch::Marker { colour, filled } => {
            let style = if filled {
                colour.filled()
            } else {
                colour.stroke_width(1)
            };
            area.draw(&Circle::new((x + 12, y), 4, style))
        }
        Swatch::Note => Ok(()),
    }
}

/// Draws `entries` top to bottom in `area`, wrapping long labels; returns
/// the height used, pixels.
pub(crate) fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[Entry],
    font_px: u32,
) -> Result<i32, String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let (w, _) = area.dim_in_pixel();
    let line_h = font_px as i32 + 4;
    let mut y = 6;
    for entry in entries {
        let indent = if entry.swatch == Swatch::Note { 6 } else { 36 };
        let max = chars_in(w.saturating_sub(indent as u32 + 6), font_px);
        let colour = if entry.swatch == Swatch::Note {
            RGBColor(60, 60, 60)
        } else {
            BLACK
        };
        draw_swatch(area, entry.swatch, (6, y + line_h / 2)).map_err(e)?;
        let lines = wrap(&entry.label, max);
        for line in &lines {
            area.draw(&Text::new(
                line.clone(),
                (indent, y),
                (FONT, font_px).into_font().color(&colour),
            ))
            .map_err(e)?;
            y += line_h;
        }
        y += 4;
    }
    Ok(y)
}

/// Height `entries` take in a strip `width_px` wide, pixels.
pub(crate) fn legend_height(entries: &[Entry], width_px: u32, font_px: u32) -> u32 {
    let line_h = font_px + 4;
    6 + entries
        .iter()
        .map(|entry| {
            let indent = if entry.swatch == Swatch::Note { 6 } else { 36 };
            let max = chars_in(width_px.saturating_sub(indent + 6), font_px);
            wrap(&entry.label, max).len() as u32 * line_h + 4
        })
        .sum::<u32>()
}

/// A number in at most four significant digits, without trailing zeros
/// (`0.3012`, `28660`, `1.2e-7`), for labels.
pub fn short(x: f64) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == 0.0 {
        return "0".into();
    }
    let mag = x.abs().log10().floor() as i32;
    if !(-4..6).contains(&mag) {
        let s = format!("{x:.3e}");
        let (m, exp) = s.split_once('e').unwrap_or((&s, "0"));
        let m = m.trim_end_matches('0').trim_end_matches('.');
        return format!("{m}e{exp}");
    }
    let decimals = (3 - mag).max(0) as usize;
    let s = format!("{x:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// `[lower, upper)` with `−∞` / `∞` for a missing bound.
pub(crate) fn window(lower: Option<f64>, upper: Option<f64>) -> String {
    format!(
        "[{}, {})",
        lower.map_or("−∞".into(), short),
        upper.map_or("∞".into(), short)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_keeps_words_and_limits() {
        let w = wrap("the band [10, ∞) has no clear return in it", 16);
        assert!(w.iter().all(|l| l.chars().count() <= 16), "{w:?}");
        assert_eq!(w.join(" "), "the band [10, ∞) has no clear return in it");
        assert_eq!(wrap("", 10), vec![String::new()]);
    }

    #[test]
    fn short_numbers() {
        assert_eq!(short(0.301234), "0.3012");
        assert_eq!(short(28658.0), "28658");
        assert_eq!(short(0.0000000772), "7.72e-8");
        assert_eq!(short(-36.6), "-36.6");
        assert_eq!(short(10.0), "10");
        assert_eq!(short(0.1 + 0.2), "0.3");
    }
}
