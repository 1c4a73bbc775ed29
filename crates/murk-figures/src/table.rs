//! Figure data from a coefficient table: which lines, markers and notes a
//! fit's figures show, named as the table names them.
//!
//! A figure only shows numbers the table holds, labelled with the table's
//! field names (`vanishing_slope`, `vanishing_slope_q99`, `slope_q99`), so a
//! reader can find every number of a figure in the table. A value the table
//! leaves null, and a law the data cannot pin down, is said in a note
//! instead of drawn.

use murk_types::{Gaussian, NoiseLaw, SlopeBand, WeatherCoefficients};

use crate::legend::short;
use crate::{PanelLaw, QuantileMarker, SlopeLine, SweepSeries, Truncation};

/// `[min, max)` of a reflectivity band, `∞` when unbounded.
pub fn band_label(min: f64, max: Option<f64>) -> String {
    match max {
        Some(m) => format!("[{}, {})", short(min), short(m)),
        None => format!("[{}, ∞)", short(min)),
    }
}

fn null_note(field: &str, band: &SlopeBand) -> String {
    format!(
        "{field} {}: null in the table ({}); no line drawn",
        band_label(band.reflectivity_min, band.reflectivity_max),
        band.reason.as_deref().unwrap_or("no reason given")
    )
}

/// What the range-vs-MOR figure shows of one weather's coefficients.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RangeMorLines {
    /// One solid line per band with a `vanishing_slope`, one dashed line per
    /// band with a `vanishing_slope_q99`; colour group = band index.
    pub lines: Vec<SlopeLine>,
    /// The per-MOR-bin quantiles of each band (`vanishing_slope_q99[b].mor_bins`),
    /// or, when no band has them, the all-reflectivity `mor_bins`.
    pub quantiles: Vec<QuantileMarker>,
    /// Null values and how the lines are scaled.
    pub notes: Vec<String>,
}

/// The lines, markers and notes of the range-vs-MOR figure of `c`, drawn
/// in metres of range (`range_scale` multiplies every slope).
pub fn range_mor_lines(c: &WeatherCoefficients, range_scale: f64) -> RangeMorLines {
    let mut out = RangeMorLines::default();
    let q_field = "vanishing_slope_q99";
    if (c.quantile - 0.99).abs() > 1e-12 {
        out.notes.push(format!(
            "vanishing_slope_q99 is fitted here on quantile {} (the table's quantile)",
            short(c.quantile)
        ));
    }
    let group_of = |b: &SlopeBand| {
        c.vanishing_slope
            .iter()
            .position(|m| {
                m.reflectivity_min == b.reflectivity_min && m.reflectivity_max == b.reflectivity_max
            })
            .unwrap_or(c.vanishing_slope.len())
    };
    for (g, b) in c.vanishing_slope.iter().enumerate() {
        let band = band_label(b.reflectivity_min, b.reflectivity_max);
        match (b.slope, b.law) {
            // A band with a bent law: the law apply uses is drawn; the
            // line's slope, kept in the table, is said.
            (
                Some(s),
                Some(murk_types::VanishingLaw::Power {
                    a,
                    b: e,
                    reflectivity,
                }),
            ) => {
                out.lines.push(SlopeLine {
                    label: match reflectivity {
                        None => format!("law {band} = {}·MOR^{}", short(a), short(e)),
                        // Drawn at the reference reflectivity.
                        Some(r) => format!(
                            "law {band} = {}·MOR^{}·(x/{})^{}",
                            short(a),
                            short(e),
                            short(r.reference),
                            short(r.exponent)
                        ),
                    },
                    slope: a * range_scale,
                    exponent: e,
                    group: g,
                    seed: false,
                });
                out.notes.push(format!(
                    "vanishing_slope {band} = {}: the line, not drawn; apply uses the band's law (law_choice: {})",
                    short(s),
                    c.law_choice.as_ref().map_or("power", |l| l.chosen.as_str())
                ));
            }
            (Some(s), _) => out.lines.push(SlopeLine {
                label: format!("vanishing_slope {band} = {}", short(s)),
                slope: s * range_scale,
                exponent: 1.0,
                group: g,
                seed: false,
            }),
            (None, _) => out.notes.push(null_note("vanishing_slope", b)),
        }
        let Some(q) = c.vanishing_slope_q99.iter().find(|q| group_of(q) == g) else {
            continue;
        };
        match q.slope {
            Some(s) => out.lines.push(SlopeLine {
                label: format!("{q_field} {band} = {}", short(s)),
                slope: s * range_scale,
                exponent: 1.0,
                group: g,
                seed: true,
            }),
            None => out.notes.push(null_note(q_field, q)),
        }
    }
    for q in &c.vanishing_slope_q99 {
        let g = group_of(q);
        out.quantiles.extend(q.mor_bins.iter().filter_map(|m| {
            Some(QuantileMarker {
                mor: m.mor_m,
                range: m.q99_range_m?,
                used: m.used,
                group: g,
            })
        }));
    }
    if out.quantiles.is_empty() && !c.mor_bins.is_empty() {
        let g = c.vanishing_slope.len();
        out.quantiles.extend(c.mor_bins.iter().filter_map(|m| {
            Some(QuantileMarker {
                mor: m.mor_m,
                range: m.q99_range_m?,
                used: m.used,
                group: g,
            })
        }));
        out.notes.push(
            "markers: the table's mor_bins, all reflectivities together (no band lists its own)"
                .into(),
        );
    }
    if let Some(l) = c.law_choice.as_ref().filter(|l| l.chosen != "power") {
        // The bend was compared but is not drawn: say what it found.
        let bends: Vec<String> = c
            .vanishing_slope
            .iter()
            .zip(&l.exponents)
            .enumerate()
            .filter_map(|(i, (b, e))| {
                let e = (*e)?;
                let ci = l
                    .exponent_ci95
                    .get(i)
                    .and_then(|c| c.as_ref())
                    .map_or(String::new(), |c| {
                        format!(" [{}, {}]", short(c.low), short(c.high))
                    });
                Some(format!(
                    "{} b = {}{ci}",
                    band_label(b.reflectivity_min, b.reflectivity_max),
                    short(e)
                ))
            })
            .collect();
        if !bends.is_empty() {
            out.notes.push(format!(
                "law_choice: linear (bent law a·MOR^b not applied; {}; held-out p {})",
                bends.join(", "),
                short(l.p_value)
            ));
        }
    }
    if range_scale != 1.0 {
        out.notes.push(format!(
            "lines: clear range = slope × range_scale ({}) × MOR",
            short(range_scale)
        ));
    }
    out
}

/// What the slope-vs-reflectivity figure shows of several weathers.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SweepData {
    /// Two series per weather (`slope`, `slope_q99` of `reflectivity_sweep`).
    pub series: Vec<SweepSeries>,
    /// Weather names, by colour group.
    pub names: Vec<String>,
    /// Null bands, where an unbounded band is drawn.
    pub notes: Vec<String>,
}

/// The series of the slope-vs-reflectivity figure of several weathers
/// (`reflectivity_sweep`), with the weather names (colour groups) and notes.
pub fn sweep_series(weathers: &[(&str, &WeatherCoefficients)]) -> SweepData {
    let mut series = Vec::new();
    let mut names = Vec::new();
    let mut notes = Vec::new();
    let centre = |min: f64, max: Option<f64>| max.map_or(min * 1.25, |m| 0.5 * (min + m));
    for (g, (w, c)) in weathers.iter().enumerate() {
        names.push(w.to_string());
        if c.reflectivity_sweep.is_empty() {
            notes.push(format!("{w}: the table has no reflectivity_sweep"));
            continue;
        }
        for (field, seed) in [("slope", false), ("slope_q99", true)] {
            let points: Vec<(f64, Option<f64>)> = c
                .reflectivity_sweep
                .iter()
                .map(|b| {
                    let v = if seed { b.slope_q99 } else { b.slope };
                    (centre(b.reflectivity_min, b.reflectivity_max), v)
                })
                .collect();
            let nulls: Vec<String> = c
                .reflectivity_sweep
                .iter()
                .filter(|b| if seed { b.slope_q99 } else { b.slope }.is_none())
                .map(|b| band_label(b.reflectivity_min, b.reflectivity_max))
                .collect();
            if !nulls.is_empty() {
                notes.push(format!(
                    "{w}: reflectivity_sweep {field} null in {} (line broken there)",
                    nulls.join(", ")
                ));
            }
            series.push(SweepSeries {
                label: format!("{w}: reflectivity_sweep {field}"),
                points,
                group: g,
                seed,
            });
        }
    }
    let unbounded: Vec<f64> = weathers
        .iter()
        .flat_map(|(_, c)| c.reflectivity_sweep.iter())
        .filter(|b| b.reflectivity_max.is_none())
        .map(|b| b.reflectivity_min)
        .collect();
    if let Some(min) = unbounded.first() {
        notes.push(format!(
            "the unbounded band [{}, ∞) is drawn at {}",
            short(*min),
            short(min * 1.25)
        ));
    }
    SweepData {
        series,
        names,
        notes,
    }
}

/// Why the data cannot pin `g` down, if they cannot: its mean lies outside
/// the window its returns were taken in (they then show only a tail, which
/// a wide range of means and spreads fit alike), or a standard error is not
/// a finite positive number, or exceeds the spread itself.
pub fn law_not_pinned(g: &Gaussian) -> Option<String> {
    let window = crate::legend::window(g.lower, g.upper);
    if g.lower.is_some_and(|a| g.mean < a) || g.upper.is_some_and(|b| g.mean > b) {
        return Some(format!(
            "the fitted mean {} lies outside the window {window} of the returns, which show only a tail of the law: its mean and spread are not pinned down",
            short(g.mean)
        ));
    }
    for (what, se) in [("mean", g.mean_std_error), ("std", g.std_std_error)] {
        if let Some(se) = se
            && !(se.is_finite() && se > 0.0 && se < g.std)
        {
            return Some(format!(
                "the standard error of its {what} ({}) says the data do not pin it down",
                short(se)
            ));
        }
    }
    None
}

/// The law to draw for a table Gaussian: fitted, or a note why not.
///
/// The fit's own verdict (`reason` on the Gaussian) comes first; tables
/// written before it existed are judged by [`law_not_pinned`].
pub fn panel_law(g: &Gaussian) -> PanelLaw {
    let fitted = g.reason.as_ref().map(|r| {
        format!(
            "{r}; the returns' own mean {}, std {}",
            short(g.mean),
            short(g.std)
        )
    });
    match fitted.or_else(|| law_not_pinned(g)) {
        Some(why) => PanelLaw::Unknown(why),
        None => PanelLaw::Fitted {
            mean: g.mean,
            std: g.std,
            mean_std_error: g.mean_std_error,
            std_std_error: g.std_std_error,
        },
    }
}

/// The distance and reflectivity laws of a ghost or ring entry (`law`
/// null: `reason`, the table's `…_reason`), with their truncation.
pub fn noise_laws(
    name: &str,
    law: Option<&NoiseLaw>,
    reason: Option<&str>,
) -> [(PanelLaw, Truncation); 2] {
    match law {
        Some(l) => [&l.distance_m, &l.reflectivity].map(|g| (panel_law(g), (g.lower, g.upper))),
        None => {
            let why = format!(
                "{name} is null in the table ({})",
                reason.unwrap_or("no reason given")
            );
            [
                (PanelLaw::Unknown(why.clone()), (None, None)),
                (PanelLaw::Unknown(why), (None, None)),
            ]
        }
    }
}
