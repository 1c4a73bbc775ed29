//! Renders every figure of this crate from hand-built data into a folder
//! (first argument, default `target/figures-example`), to look at them:
//! `cargo run -p murk-figures --example render_all -- DIR`.

mod common;

use murk_figures::table::{SweepData, noise_laws, range_mor_lines, sweep_series};
use murk_figures::*;

fn main() -> Result<(), FigureError> {
    let dir = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "target/figures-example".into());
    let dir = std::path::PathBuf::from(dir);
    std::fs::create_dir_all(&dir).expect("the output folder can be made");
    let fog = common::fog();
    let rain = common::rain();
    let opts = FigureOptions::default();

    let (kept, lost) = common::counts(0.3);
    let l = range_mor_lines(&fog, 1.0);
    let fig = RangeMorFigure {
        weather: "fog",
        mor: &common::MORS,
        mor_bin_width: 10.0,
        range_step: 0.5,
        kept: &kept,
        lost: &lost,
        quantiles: &l.quantiles,
        lines: &l.lines,
        notes: &l.notes,
    };
    range_vs_mor(&fig, &opts, &dir.join("range-vs-mor-fog.png"))?;

    let SweepData {
        series,
        names,
        notes,
    } = sweep_series(&[("fog", &fog), ("rain", &rain)]);
    let sweep = SweepFigure {
        series: &series,
        group_names: &names,
        notes: &notes,
    };
    slope_vs_reflectivity(&sweep, &opts, &dir.join("slope-vs-reflectivity.png"))?;

    let mut panels = Vec::new();
    for (name, law, reason) in [
        ("ghost", fog.ghost.as_ref(), None),
        ("ring", fog.ring.as_ref(), None),
        (
            "ring (rain)",
            rain.ring.as_ref(),
            rain.ring_reason.as_deref(),
        ),
    ] {
        let [d, r] = noise_laws(name, law, reason);
        let (lo, step, counts) = common::histogram(0.0, 0.25, 5.0, 1.7, 44);
        panels.push(GaussianPanel {
            title: format!("{name} distance (m)"),
            lo,
            step,
            counts,
            law: d.0,
            truncation: d.1,
        });
        let (lo, step, counts) = common::histogram(0.0, 1.0, 0.0, 4.0, 20);
        panels.push(GaussianPanel {
            title: format!("{name} reflectivity"),
            lo,
            step,
            counts,
            law: r.0,
            truncation: r.1,
        });
    }
    let o = FigureOptions {
        title: Some("fog: ghost and ring returns".into()),
        ..FigureOptions::default()
    };
    gaussian_histograms(&panels, &o, &dir.join("noise-fog.png"))?;

    let cats = [
        ProfilePoint {
            label: "dry".into(),
            x: None,
            mean: -0.05,
            interval: Some((-0.07, -0.03)),
        },
        ProfilePoint {
            label: "wet".into(),
            x: None,
            mean: 0.08,
            interval: Some((0.05, 0.11)),
        },
        ProfilePoint {
            label: "snow-covered".into(),
            x: None,
            mean: 0.01,
            interval: None,
        },
    ];
    let f = ProfileFigure {
        title: "survival residual vs road_state (strength 2.1)",
        x_label: "road_state",
        y_label: "survival residual",
        points: &cats,
        threshold: 0.02,
        interval_label: "95 % interval across recordings",
    };
    residual_profile(&f, &dir.join("residual-categorical.png"))?;
    let nums: Vec<ProfilePoint> = (0..8)
        .map(|i| {
            let m = 0.01 * i as f64 - 0.035;
            ProfilePoint {
                label: format!("bin {i}"),
                x: Some(5.0 * i as f64 + 2.0),
                mean: m,
                interval: Some((m - 0.01, m + 0.012)),
            }
        })
        .collect();
    let f = ProfileFigure {
        title: "range residual vs range (strength 1.4)",
        x_label: "range",
        y_label: "range residual (m)",
        points: &nums,
        ..f
    };
    residual_profile(&f, &dir.join("residual-numeric.png"))?;

    let clear = common::rings(40.0);
    let sim = common::rings(20.0);
    let bev = BevFigure {
        title: "fog-003 (fog, MOR 62 m): clear, simulated, measured".into(),
        panels: &[("clear", &clear), ("simulated", &sim), ("measured", &sim)],
        half_extent_m: 40.0,
    };
    bev_panels(&bev, &dir.join("bev.png"))?;
    println!("written to {}", dir.display());
    Ok(())
}
