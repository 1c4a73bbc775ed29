//! The figures of a fit and a diagnosis, built from a hand-made table: the
//! labels are the table's own names and numbers, null or unpinned laws are
//! said and not drawn, bands get their own colours, and the keys are there.

#[path = "../examples/common/mod.rs"]
mod common;

use murk_figures::table::{SweepData, law_not_pinned, noise_laws, range_mor_lines, sweep_series};
use murk_figures::*;
use murk_types::Gaussian;

fn svg_of_range_mor(c: &murk_types::WeatherCoefficients) -> (Vec<String>, String) {
    let dir = tempfile::tempdir().unwrap();
    let (kept, lost) = common::counts(0.3);
    let l = range_mor_lines(c, 1.0);
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
    let path = dir.path().join("r.svg");
    range_vs_mor(&fig, &FigureOptions::default(), &path).unwrap();
    (fig.legend_labels(), std::fs::read_to_string(path).unwrap())
}

#[test]
fn range_vs_mor_names_lines_as_the_table_does_and_says_nulls() {
    let fog = common::fog();
    let l = range_mor_lines(&fog, 1.0);
    let labels: Vec<&str> = l.lines.iter().map(|l| l.label.as_str()).collect();
    assert_eq!(
        labels,
        [
            "vanishing_slope [0, 10) = 0.3",
            "vanishing_slope_q99 [0, 10) = 0.29",
            "vanishing_slope [10, ∞) = 0.34",
        ]
    );
    // One colour per band, shared by its two estimates and its markers.
    let groups: Vec<(usize, bool)> = l.lines.iter().map(|l| (l.group, l.seed)).collect();
    assert_eq!(groups, [(0, false), (0, true), (1, false)]);
    assert_eq!(l.quantiles.len(), common::MORS.len());
    assert!(l.quantiles.iter().all(|q| q.group == 0));
    assert_eq!(l.quantiles.iter().filter(|q| !q.used).count(), 2);
    // The null q99 of the upper band is said, with the table's reason.
    assert_eq!(l.notes.len(), 1, "{:?}", l.notes);
    assert!(
        l.notes[0].starts_with("vanishing_slope_q99 [10, ∞): null")
            && l.notes[0].contains("no MOR bin with 50 no-change returns"),
        "{}",
        l.notes[0]
    );

    let (legend, svg) = svg_of_range_mor(&fog);
    for label in labels.iter().chain(
        l.notes
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>()
            .iter(),
    ) {
        assert!(
            legend.iter().any(|x| x == label),
            "{label} not in {legend:?}"
        );
    }
    assert!(!svg.contains("seed q99 (all)"));
    assert!(svg.contains("vanishing_slope_q99 [0, 10) = 0.29"));
    // The two bands' lines are drawn in two different colours.
    assert!(
        svg.contains("#0046A0") && svg.contains("#961E78"),
        "band colours"
    );
}

#[test]
fn range_scale_is_drawn_and_said() {
    let fog = common::fog();
    let l = range_mor_lines(&fog, 1.5);
    assert!((l.lines[0].slope - 0.45).abs() < 1e-12);
    // The label keeps the table's number; the note says the scale.
    assert_eq!(l.lines[0].label, "vanishing_slope [0, 10) = 0.3");
    assert!(
        l.notes.iter().any(|n| n.contains("range_scale (1.5)")),
        "{:?}",
        l.notes
    );
}

#[test]
fn a_bent_law_is_drawn_as_the_law_and_the_line_is_said() {
    let mut fog = common::fog();
    fog.vanishing_slope[0].law = Some(murk_types::VanishingLaw::Power {
        a: 1.5,
        b: 0.7,
        reflectivity: None,
    });
    fog.law_choice = Some(murk_types::LawChoice {
        chosen: "power".into(),
        exponents: vec![Some(0.7), None],
        exponent_ci95: vec![],
        gain_nats_per_recording: 3.0,
        recordings_better: 20,
        recordings: 24,
        p_value: 0.001,
        alpha: 0.01,
        folds: 5,
        reason: None,
        reflectivity: None,
    });
    let l = range_mor_lines(&fog, 1.0);
    let bent = l
        .lines
        .iter()
        .find(|x| x.label == "law [0, 10) = 1.5·MOR^0.7")
        .unwrap_or_else(|| panic!("{:?}", l.lines));
    assert_eq!(
        (bent.slope, bent.exponent, bent.group, bent.seed),
        (1.5, 0.7, 0, false)
    );
    // The band's line is not drawn beside its law, but said.
    assert!(
        !l.lines
            .iter()
            .any(|x| x.label == "vanishing_slope [0, 10) = 0.3")
    );
    assert!(
        l.notes
            .iter()
            .any(|n| n.starts_with("vanishing_slope [0, 10) = 0.3: the line, not drawn")),
        "{:?}",
        l.notes
    );
    // The other band keeps its line.
    assert!(
        l.lines
            .iter()
            .any(|x| x.label == "vanishing_slope [10, ∞) = 0.34" && x.exponent == 1.0)
    );
    let (legend, _) = svg_of_range_mor(&fog);
    assert!(
        legend.iter().any(|x| x == "law [0, 10) = 1.5·MOR^0.7"),
        "{legend:?}"
    );

    // A bend compared but not applied is said with its interval.
    fog.vanishing_slope[0].law = None;
    let choice = fog.law_choice.as_mut().unwrap();
    choice.chosen = "linear".into();
    choice.exponent_ci95 = vec![
        Some(murk_types::Interval {
            low: 0.6,
            high: 0.8,
            level: 0.95,
            method: "grouped jackknife".into(),
        }),
        None,
    ];
    let l = range_mor_lines(&fog, 1.0);
    assert!(l.lines.iter().all(|x| x.exponent == 1.0));
    assert!(
        l.notes
            .iter()
            .any(|n| n.contains("law_choice: linear") && n.contains("[0, 10) b = 0.7 [0.6, 0.8]")),
        "{:?}",
        l.notes
    );
}

#[test]
fn markers_fall_back_to_the_all_reflectivity_bins_and_say_so() {
    let mut fog = common::fog();
    for b in &mut fog.vanishing_slope_q99 {
        b.mor_bins.clear();
    }
    let l = range_mor_lines(&fog, 1.0);
    assert_eq!(l.quantiles.len(), common::MORS.len());
    assert!(
        l.quantiles.iter().all(|q| q.group == 2),
        "a group of its own"
    );
    assert!(
        l.notes
            .iter()
            .any(|n| n.contains("mor_bins, all reflectivities"))
    );
}

#[test]
fn sweep_has_a_key_for_solid_and_dashed_and_says_null_bands() {
    let fog = common::fog();
    let rain = common::rain();
    let SweepData {
        series,
        names,
        notes,
    } = sweep_series(&[("fog", &fog), ("rain", &rain)]);
    assert_eq!(names, ["fog", "rain"]);
    let labels: Vec<(&str, bool)> = series.iter().map(|s| (s.label.as_str(), s.seed)).collect();
    assert_eq!(
        labels,
        [
            ("fog: reflectivity_sweep slope", false),
            ("fog: reflectivity_sweep slope_q99", true),
            ("rain: reflectivity_sweep slope", false),
            ("rain: reflectivity_sweep slope_q99", true),
        ]
    );
    // Band [20, 40) of fog has no q99 slope: a gap, not a made-up point.
    assert_eq!(series[1].points[3], (30.0, None));
    assert!(
        notes
            .iter()
            .any(|n| n == "fog: reflectivity_sweep slope_q99 null in [20, 40) (line broken there)"),
        "{notes:?}"
    );
    assert!(notes.iter().any(|n| n.contains("[40, ∞) is drawn at 50")));
    let fig = SweepFigure {
        series: &series,
        group_names: &names,
        notes: &notes,
    };
    let legend = fig.legend_labels();
    assert!(
        legend
            .iter()
            .any(|l| l.starts_with("solid, filled: maximum-likelihood"))
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.svg");
    slope_vs_reflectivity(&fig, &FigureOptions::default(), &path).unwrap();
    let svg = std::fs::read_to_string(path).unwrap();
    assert!(svg.contains("dashed, hollow"));
    assert!(svg.contains("fog: reflectivity_sweep slope_q99"));
}

/// The texts of an SVG written by plotters (one `<text …>` element each).
fn texts(svg: &str) -> Vec<&str> {
    svg.split("<text")
        .skip(1)
        .filter_map(|t| Some(t.split_once('>')?.1.split_once("</text>")?.0.trim()))
        .collect()
}

fn g(mean: f64, std: f64, lower: Option<f64>, upper: Option<f64>) -> Gaussian {
    Gaussian {
        mean,
        std,
        lower,
        upper,
        mean_std_error: None,
        std_std_error: None,
        reason: None,
    }
}

#[test]
fn the_fits_own_verdict_is_shown() {
    let mut flagged = g(6.7, 2.1, Some(3.0), Some(10.0));
    flagged.reason =
        Some("not identifiable: ML mean 2.8659e4 puts 1.0e-300 of its mass in the window".into());
    match murk_figures::table::panel_law(&flagged) {
        PanelLaw::Unknown(why) => assert!(
            why.starts_with("not identifiable") && why.contains("own mean 6.7"),
            "{why}"
        ),
        other => panic!("{other:?}"),
    }
}

#[test]
fn laws_the_data_cannot_pin_down_are_named() {
    assert_eq!(law_not_pinned(&g(5.0, 1.7, Some(3.0), Some(10.0))), None);
    assert_eq!(law_not_pinned(&g(-3.0, 8.0, None, None)), None);
    // The seed campaign's snow ghost distance: mean far beyond the window.
    let why = law_not_pinned(&g(28658.0, 774.0, Some(3.0), Some(10.0))).unwrap();
    assert!(why.contains("28658") && why.contains("[3, 10)"), "{why}");
    // Real frames: a ring reflectivity mean far below its floor.
    assert!(law_not_pinned(&g(-985.0, 20.8, Some(0.0), None)).is_some());
    let mut loose = g(5.0, 1.0, Some(3.0), Some(10.0));
    loose.mean_std_error = Some(3.0);
    assert!(
        law_not_pinned(&loose)
            .unwrap()
            .contains("standard error of its mean")
    );
    loose.mean_std_error = Some(f64::NAN);
    assert!(law_not_pinned(&loose).is_some());
    loose.mean_std_error = Some(0.05);
    assert_eq!(law_not_pinned(&loose), None);
}

#[test]
fn a_null_or_unpinned_law_is_said_not_drawn() {
    let fog = common::fog();
    let rain = common::rain();
    let [gd, gr] = noise_laws("ghost", fog.ghost.as_ref(), None);
    assert!(matches!(gd.0, PanelLaw::Fitted { .. }) && matches!(gr.0, PanelLaw::Fitted { .. }));
    let [rd, rr] = noise_laws("ring", fog.ring.as_ref(), None);
    assert!(matches!(rd.0, PanelLaw::Fitted { .. }));
    let PanelLaw::Unknown(why) = &rr.0 else {
        panic!("{rr:?}")
    };
    assert!(why.contains("-985"), "{why}");
    let [nd, _] = noise_laws("ring", rain.ring.as_ref(), rain.ring_reason.as_deref());
    let PanelLaw::Unknown(why) = &nd.0 else {
        panic!("{nd:?}")
    };
    assert_eq!(why, "ring is null in the table (no ring returns found)");

    let dir = tempfile::tempdir().unwrap();
    let (lo, step, counts) = common::histogram(0.0, 1.0, 0.0, 4.0, 20);
    let panel = |law: PanelLaw| GaussianPanel {
        title: "ring reflectivity".into(),
        lo,
        step,
        counts: counts.clone(),
        law,
        truncation: rr.1,
    };
    let path = dir.path().join("unknown.svg");
    gaussian_histograms(&[panel(rr.0.clone())], &FigureOptions::default(), &path).unwrap();
    let svg = std::fs::read_to_string(&path).unwrap();
    assert!(svg.contains("no law drawn"), "the reason is said");
    assert!(
        !svg.contains("-985 ±") && !svg.contains("#D55E00"),
        "and no curve drawn"
    );
    // The same panel with a fitted law draws its curve and its numbers.
    let fitted = PanelLaw::Fitted {
        mean: 1.0,
        std: 4.0,
        mean_std_error: Some(0.1),
        std_std_error: None,
    };
    let path = dir.path().join("fitted.svg");
    gaussian_histograms(&[panel(fitted)], &FigureOptions::default(), &path).unwrap();
    let svg = std::fs::read_to_string(&path).unwrap();
    assert!(svg.contains("#D55E00") && svg.contains("mean 1 ± 0.1, std 4"));
}

#[test]
fn categorical_profiles_get_a_categorical_axis_and_bars() {
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
            interval: None,
        },
    ];
    let f = ProfileFigure {
        title: "survival residual vs road_state",
        x_label: "road_state",
        y_label: "survival residual",
        points: &cats,
        threshold: 0.02,
        interval_label: "95 % interval across recordings",
    };
    assert!(!f.numeric());
    let legend = f.legend_labels();
    assert!(legend[0].contains("95 % interval across recordings"));
    assert!(legend.iter().any(|l| l.starts_with("no bar")));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p.svg");
    residual_profile(&f, &path).unwrap();
    let svg = std::fs::read_to_string(&path).unwrap();
    // The categories are the tick labels; no 0–1 numeric axis.
    let t = texts(&svg);
    assert!(
        t.contains(&"dry") && t.contains(&"wet"),
        "category ticks: {t:?}"
    );
    assert!(!t.contains(&"0.5") && !t.contains(&"1.0"), "{t:?}");
    // A numeric profile stays numeric.
    let nums: Vec<ProfilePoint> = cats
        .iter()
        .enumerate()
        .map(|(i, p)| ProfilePoint {
            x: Some(i as f64 * 10.0),
            ..p.clone()
        })
        .collect();
    assert!(ProfileFigure { points: &nums, ..f }.numeric());
}

#[test]
fn bev_has_units_a_colour_key_and_its_title() {
    let clear = common::rings(40.0);
    let sim = common::rings(20.0);
    let fig = BevFigure {
        title: "fog-003 (fog, MOR 62 m)".into(),
        panels: &[("clear", &clear), ("simulated", &sim)],
        half_extent_m: 40.0,
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("b.svg");
    bev_panels(&fig, &path).unwrap();
    let svg = std::fs::read_to_string(&path).unwrap();
    for text in [
        "fog-003 (fog, MOR 62 m)",
        "x (m)",
        "y (m)",
        "range from sensor (m)",
    ] {
        assert!(svg.contains(text), "{text}");
    }
    let png = dir.path().join("b.png");
    bev_panels(&fig, &png).unwrap();
    let img = image::open(&png).unwrap().to_rgb8();
    // The key runs from dark violet (near) to green (far) at the right edge.
    let right: Vec<[u8; 3]> = (0..img.height())
        .map(|y| img.get_pixel(img.width() - 86, y).0)
        .collect();
    assert!(
        right.iter().any(|p| p[0] < 80 && p[1] < 30 && p[2] > 70),
        "near end"
    );
    assert!(right.iter().any(|p| p[1] > 180 && p[2] < 120), "far end");
}
