//! The figures of `murk diagnose --figures DIR`: the residual profile of
//! each significant finding (up to four) and a bird's-eye view of clear,
//! simulated and measured clouds of one held-out recording.

use std::path::Path;

use anyhow::Context as _;
use murk_diagnose::Diagnosis;
use murk_figures::{BevFigure, ProfileFigure, ProfilePoint, bev_panels, residual_profile};

fn slug(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '-'
            }
        })
        .collect::<String>()
        .split('-')
        .filter(|p| !p.is_empty())
        .collect::<Vec<_>>()
        .join("-")
}

/// Writes the figures of `d` into `dir` (PNG and SVG).
pub fn write(d: &Diagnosis, dir: &Path) -> anyhow::Result<()> {
    for f in d.report.findings.iter().filter(|f| f.significant).take(4) {
        // Categories keep their names on the axis; numeric bins sit at
        // their mean. The report holds no per-bin interval yet, so none is
        // drawn (the figure says so rather than inventing one).
        let points: Vec<ProfilePoint> = f
            .profile
            .iter()
            .map(|b| ProfilePoint {
                label: b.label.clone(),
                x: b.center,
                mean: b.mean_residual,
                interval: None,
            })
            .collect();
        let title = format!(
            "{} residual vs {} (strength {:.1})",
            f.observable, f.covariate, f.strength
        );
        let y = format!("{} residual", f.observable);
        let fig = ProfileFigure {
            title: &title,
            x_label: &f.covariate,
            y_label: &y,
            points: &points,
            threshold: f.relevance_threshold,
            interval_label: "no interval in the report",
        };
        for ext in ["png", "svg"] {
            let p = dir.join(format!(
                "residual-{}-{}.{ext}",
                f.observable,
                slug(&f.covariate)
            ));
            residual_profile(&fig, &p).with_context(|| format!("drawing {}", p.display()))?;
        }
    }
    let fd = &d.figures;
    let panels: [(&str, &[[f32; 3]]); 3] = [
        ("clear", &fd.clear),
        ("simulated", &fd.simulated),
        ("measured", &fd.measured),
    ];
    for ext in ["png", "svg"] {
        let p = dir.join(format!("bev-{}.{ext}", slug(&fd.recording)));
        let fig = BevFigure {
            title: format!(
                "{} ({}, MOR {:.0} m): clear, simulated at that MOR, measured",
                fd.recording, d.report.weather, fd.mor_m
            ),
            panels: &panels,
            half_extent_m: 40.0,
        };
        bev_panels(&fig, &p).with_context(|| format!("drawing {}", p.display()))?;
    }
    Ok(())
}
