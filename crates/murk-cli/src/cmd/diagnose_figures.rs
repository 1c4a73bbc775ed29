//! The figures of `murk diagnose --figures DIR`: the residual profile of
//! each significant finding (up to four) and a bird's-eye view of clear,
//! simulated and measured clouds of one held-out recording.

use std::path::Path;

use anyhow::Context as _;
use murk_diagnose::Diagnosis;
use murk_figures::{ProfileFigure, bev_panels, residual_profile};

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
        let points: Vec<(f64, f64)> = f
            .profile
            .iter()
            .enumerate()
            .map(|(i, b)| (b.center.unwrap_or(i as f64), b.mean_residual))
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
        bev_panels(&panels, 40.0, &p).with_context(|| format!("drawing {}", p.display()))?;
    }
    Ok(())
}
