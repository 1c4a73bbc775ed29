//! Pairing off murk's own grid (issue #12): the firing geometry is measured
//! from the clear recordings, so clear recordings pair whether the firings
//! sit on multiples of the declared step (phase-locked), at another phase,
//! free-running with jitter, or at a step other than the declared one; a
//! declared step the recordings contradict is warned with both values.
//!
//! Truth sources: murk-fixtures' generator with the firing settings of its
//! `[sensor]` (on-grid, phase, free-running, jitter), and the semi-real
//! source (the real VLP-16 capture of `../shared/data/real` as the clear
//! scene, weathered by the ground-truth model; skipped with a message when
//! the data folder is absent).

// These tests edit campaign.toml on disk: fit/clippy.toml keeps I/O out of
// the library's statistics, not out of its tests.
#![allow(clippy::disallowed_methods, clippy::disallowed_types)]

use std::path::{Path, PathBuf};

use murk_campaign::Campaign;
use murk_fit::{FitParams, FittedTable};
use murk_fixtures::semi_real::{self, SemiRealConfig};
use murk_fixtures::{Generator, GeneratorConfig, OutputOptions, Preset};
use murk_types::WeatherClass;

fn fit(path: &Path) -> FittedTable {
    let campaign = Campaign::open(path).unwrap();
    FitParams::default()
        .bootstrap_replicates(0)
        .check()
        .unwrap()
        .fit(&campaign)
        .unwrap()
}

fn clear_rate(t: &FittedTable) -> f64 {
    t.table().clear.as_ref().unwrap().no_change_rate.unwrap()
}

fn generated(seed: u64, edit: impl Fn(&mut GeneratorConfig)) -> (tempfile::TempDir, PathBuf) {
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = 40;
    edit(&mut c);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign");
    Generator::new(c)
        .unwrap()
        .write_campaign(seed, &OutputOptions::new(&path))
        .unwrap();
    (dir, path)
}

/// The real VLP-16 capture beside the checkout, or `None` (after saying
/// `skipping: …`) when `../shared/data/real` is absent.
fn capture() -> Option<PathBuf> {
    semi_real::vlp16_capture(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn on_grid_firings_pair() {
    // The generator fires exactly on multiples of the declared 1° step: the
    // old grid's bin edges, where jitter-free rounding split every direction
    // between two cells (0.70).
    for seed in [1, 2, 3] {
        let (_d, path) = generated(seed, |_| {});
        let t = fit(&path);
        let r = clear_rate(&t);
        eprintln!("on-grid seed {seed}: clear no-change {r:.4}");
        assert!(r >= 0.97, "seed {seed}: clear no-change {r}");
        assert!(
            t.table().lidar.warnings.is_empty(),
            "{:?}",
            t.table().lidar.warnings
        );
        let g = t.table().lidar.geometry.as_ref().unwrap();
        assert_eq!(g.source, "measured");
        assert!(
            (g.azimuth_step_deg - 1.0).abs() < 1e-9,
            "{}",
            g.azimuth_step_deg
        );
    }
}

#[test]
fn phased_jittered_firings_pair() {
    // Phase-locked at 0.37° (the old grid's edges cut every cell at a third)
    // with a Gaussian azimuth jitter of σ 0.05° (5 % of the step).
    for seed in [4, 5, 6] {
        let (_d, path) = generated(seed, |c| {
            c.sensor.azimuth_phase_deg = 0.37;
            c.sensor.azimuth_jitter_deg = 0.05;
        });
        let t = fit(&path);
        let r = clear_rate(&t);
        eprintln!("phase 0.37°, jitter 0.05° seed {seed}: clear no-change {r:.4}");
        assert!(r >= 0.97, "seed {seed}: clear no-change {r}");
        let g = t.table().lidar.geometry.as_ref().unwrap();
        for ring in &g.rings {
            assert!(
                (ring.azimuth_phase_deg - 0.37).abs() < 0.01 && ring.phase_locking > 0.9,
                "{ring:?}"
            );
        }
    }
    // Phase-locked half a step off: the cells move onto the firings.
    let (_d, path) = generated(7, |c| c.sensor.azimuth_phase_deg = 0.5);
    let t = fit(&path);
    let r = clear_rate(&t);
    eprintln!("phase 0.5°: clear no-change {r:.4}");
    assert!(r >= 0.97, "clear no-change {r}");
    let g = t.table().lidar.geometry.as_ref().unwrap();
    for ring in &g.rings {
        assert!(
            (ring.azimuth_phase_deg - 0.5).abs() < 0.01 && ring.phase_locking > 0.95,
            "{ring:?}"
        );
    }
}

/// A free-running unit of the generator: every revolution starts at its own
/// phase, and each firing is cast at the azimuth it fires at, so a cell on
/// a depth edge sees the near surface in some revolutions and the far one
/// in others, and a cell on a surface seen at a grazing angle reads a range
/// that moves with where in the cell it fired. The measured step is right
/// (1°, locking ≈ 0.2–0.35). The clear leave-one-out pairs the way
/// degraded recordings do (own cell, else an azimuth neighbour) and takes
/// the best pairing of each ring (a chain of shifts, not a loss at every
/// range edge); cells whose clear ranges disagree in more than a fifth of
/// the recordings are not reference cells (`reference_min_agreement`); a
/// cell's tolerance widens by the range its firings read as they wander
/// across it (the ring's gradient times the wander its phase locking
/// implies, at most the tolerance: `ClearReference::tolerance`).
///
/// Measured (40 recordings, seeds 4–16, 4–11 clear recordings each): with
/// the agreement rule alone 0.9612–0.9883 (seed 9, 4 clear recordings,
/// below 0.97); with the wander 0.9841–0.9906, seed 9 0.9853. Slopes
/// within 2.2 % of the truth (fog, rain, snow) except seed 9's fog low
/// band (−3.3 %; −3.8 % before), which is estimation, not bias: 0.2930
/// against 0.3029 with a standard error over recordings of 0.0044 (2.3
/// of them), the 95 % interval 0.2833–0.3031 covering the truth.
#[test]
fn free_running_firings_pair() {
    for seed in [4, 5, 6, 7, 9, 11, 14] {
        let (_d, path) = generated(seed, |c| {
            c.sensor.azimuth_phase_deg = 0.37;
            c.sensor.free_running = true;
            c.sensor.azimuth_jitter_deg = 0.01;
        });
        let t = fit(&path);
        let r = clear_rate(&t);
        eprintln!("free-running jittered seed {seed}: clear no-change {r:.4}");
        let g = t.table().lidar.geometry.as_ref().unwrap();
        assert!((g.azimuth_step_deg - 1.0).abs() < 1e-9);
        assert!(r >= 0.97, "seed {seed}: clear no-change {r}");
    }
}

#[test]
fn a_wrong_declared_step_is_warned_and_the_measured_one_pairs() {
    let (_d, path) = generated(8, |_| {});
    let toml = path.join("campaign.toml");
    let text = std::fs::read_to_string(&toml).unwrap();
    assert!(text.contains("azimuth_resolution_deg = 1.0"), "{text}");
    std::fs::write(
        &toml,
        text.replace(
            "azimuth_resolution_deg = 1.0",
            "azimuth_resolution_deg = 0.5",
        ),
    )
    .unwrap();
    let t = fit(&path);
    let w = &t.table().lidar.warnings;
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].contains("azimuth_resolution_deg = 0.5") && w[0].contains("every 1.0000°"),
        "{}",
        w[0]
    );
    assert!(
        t.summary().contains("warning: azimuth step"),
        "{}",
        t.summary()
    );
    let r = clear_rate(&t);
    assert!(r >= 0.97, "clear no-change {r}");
    // Told to pair on the declared grid, it does, and still warns.
    let campaign = Campaign::open(&path).unwrap();
    let declared = FitParams::default()
        .bootstrap_replicates(0)
        .declared_geometry(true)
        .check()
        .unwrap()
        .fit(&campaign)
        .unwrap();
    assert_eq!(declared.table().lidar.warnings, *w);
    let g = declared.table().lidar.geometry.as_ref().unwrap();
    assert_eq!(g.source, "declared");
    assert!((g.azimuth_step_deg - 0.5).abs() < 1e-9);
}

#[test]
fn sixty_four_declared_elevations_for_sixteen_rings_are_warned() {
    // A campaign.toml copied from a 64-ring unit for 16-ring recordings:
    // the first 16 elevations are the VLP-16's (the points carry their
    // ring), the other 48 no recording uses.
    let (_d, path) = generated(9, |_| {});
    let toml = path.join("campaign.toml");
    let text = std::fs::read_to_string(&toml).unwrap();
    let line = text
        .lines()
        .find(|l| l.starts_with("elevation_deg"))
        .unwrap()
        .to_string();
    let inner = line
        .trim_start_matches("elevation_deg = [")
        .trim_end_matches(']');
    let extra: Vec<String> = (0..48)
        .map(|k| format!("{}", -24.0 + k as f64 * 0.5))
        .collect();
    let longer = format!("elevation_deg = [{inner}, {}]", extra.join(", "));
    std::fs::write(&toml, text.replace(&line, &longer)).unwrap();
    let t = fit(&path);
    let w = &t.table().lidar.warnings;
    assert!(
        w.iter()
            .any(|w| w.contains("declares 64 ring elevations") && w.contains("rings 0–15")),
        "{w:?}"
    );
    assert!(t.summary().contains("declares 64 ring elevations"));
    let r = clear_rate(&t);
    assert!(r >= 0.97, "clear no-change {r}");
}

/// The real capture's revolutions, declared at the datasheet's 0.2° and at
/// the unit's 0.4°: both pair, and 0.2° is warned.
#[test]
fn real_capture_pairs_whatever_step_is_declared() {
    let Some(capture) = capture() else { return };
    for declared in [0.2, 0.4] {
        let dir = tempfile::tempdir().unwrap();
        let cfg = SemiRealConfig {
            clear: 30,
            degraded: 10,
            null_weather: true,
            declared_azimuth_deg: declared,
            ..SemiRealConfig::default()
        };
        semi_real::vlp16_campaign(&capture, dir.path(), &cfg, 1).unwrap();
        let t = fit(dir.path());
        let r = clear_rate(&t);
        let fog = t.table().weathers[&WeatherClass::Fog]
            .no_change_rate
            .unwrap();
        eprintln!(
            "real capture, declared {declared}°: clear no-change {r:.4}, null 'fog' no-change {fog:.4}; warnings {:?}",
            t.table().lidar.warnings
        );
        assert!(r >= 0.97, "declared {declared}: clear no-change {r}");
        assert!(fog >= 0.97, "declared {declared}: null fog no-change {fog}");
        let g = t.table().lidar.geometry.as_ref().unwrap();
        assert!(
            (g.azimuth_step_deg - 0.4).abs() < 0.01,
            "{}",
            g.azimuth_step_deg
        );
        let warned = t
            .table()
            .lidar
            .warnings
            .iter()
            .any(|w| w.contains("azimuth_resolution_deg = 0.2"));
        assert_eq!(warned, declared == 0.2, "{:?}", t.table().lidar.warnings);
    }
}

/// Slopes of the seed's fog on the real scene, and on recordings of
/// different lengths (clear `.pcap`s of many revolutions, fog of one).
fn semi_real_slopes(cfg: &SemiRealConfig, seeds: &[u64], label: &str) -> Vec<(f64, f64)> {
    let Some(capture) = capture() else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for &seed in seeds {
        let dir = tempfile::tempdir().unwrap();
        let truth = semi_real::vlp16_campaign(&capture, dir.path(), cfg, seed).unwrap();
        let t = fit(dir.path());
        let fog = &t.table().weathers[&WeatherClass::Fog];
        eprintln!("{label} seed {seed}: clear no-change {:.4}", clear_rate(&t));
        assert!(clear_rate(&t) >= 0.97, "{label}: clear {}", clear_rate(&t));
        for b in &fog.vanishing_slope {
            let want = truth.model.slope_at(b.reflectivity_min + 1e-9);
            let got = b.slope.unwrap_or(f64::NAN);
            if b.slope.is_none() {
                eprintln!(
                    "{label} seed {seed}: null: {:?} {:?}",
                    b.reason, b.edge_test
                );
            }
            eprintln!(
                "{label} seed {seed}: band [{}, {:?}) ML slope {got:.4} truth {want:.4} ({:+.1} %)",
                b.reflectivity_min,
                b.reflectivity_max,
                (got / want - 1.0) * 100.0
            );
            out.push((got, want));
        }
    }
    out
}

/// The seed's fog on the real scene (the real firing grid, jitter, dropouts
/// and reflectivities): the maximum-likelihood slopes within 3 % of the
/// truth (measured: within 0.8 % on seeds 1–3).
#[test]
fn semi_real_slopes_within_three_percent() {
    let got = semi_real_slopes(&SemiRealConfig::default(), &[1, 2, 3], "semi-real");
    for (g, w) in got {
        assert!((g / w - 1.0).abs() < 0.03, "slope {g} vs truth {w}");
    }
}

/// The seed's fog on the real KITTI scan (an HDL-64E, its reflectance in
/// 0–1, rings derived from the declared elevations), MOR readings with 5 %
/// noise: clear no-change ≥ 0.97 and slopes within 3 %. Measured (seeds
/// 1–3): clear 0.994–0.995; low band 0.3064–0.3082 against 0.3029
/// (+1.2 to +1.8 %), high band 0.3437–0.3465 against 0.3463 (−0.8 to
/// +0.05 %). (Before the semi-real source converted the scan's reflectance
/// to calibrated reflectivity, it weathered every KITTI return as the low
/// band's: the fit then read 0.302 for the high band, which was the truth
/// of those recordings.)
#[test]
fn kitti_scan_slopes_within_three_percent() {
    let Some((cloud, lidar)) = semi_real::kitti_scan(env!("CARGO_MANIFEST_DIR")) else {
        return;
    };
    let cfg = SemiRealConfig {
        declared_azimuth_deg: lidar.azimuth_resolution_deg,
        mor_noise_rel: 0.05,
        ..SemiRealConfig::default()
    };
    for seed in [1u64, 2, 3] {
        let dir = tempfile::tempdir().unwrap();
        let truth = semi_real::scan_campaign(&cloud, &lidar, dir.path(), &cfg, seed).unwrap();
        let t = fit(dir.path());
        assert!(
            t.table().lidar.warnings.is_empty(),
            "{:?}",
            t.table().lidar.warnings
        );
        let clear = clear_rate(&t);
        eprintln!("KITTI seed {seed}: clear no-change {clear:.4}");
        assert!(clear >= 0.97, "KITTI seed {seed}: clear {clear}");
        for b in &t.table().weathers[&WeatherClass::Fog].vanishing_slope {
            let want = truth.model.slope_at(b.reflectivity_min + 1e-9);
            let got = b.slope.expect("a slope");
            eprintln!(
                "KITTI seed {seed}: band {} slope {got:.4} truth {want:.4} ({:+.1} %)",
                b.reflectivity_min,
                (got / want - 1.0) * 100.0
            );
            assert!(
                (got / want - 1.0).abs() < 0.03,
                "seed {seed}: {got} vs {want}"
            );
        }
    }
}

/// Clear `.pcap` recordings of many revolutions beside fog recordings of
/// one: on the old per-recording pairing the slopes came out near 0.001
/// (every clear cell expected a whole capture's returns of each fog
/// revolution); per scan they are within 3 % (measured: within 1.9 % on
/// seeds 2 and 3).
#[test]
fn recordings_of_different_lengths_give_the_slopes() {
    let cfg = SemiRealConfig {
        clear_pcap_parts: 3,
        degraded: 24,
        ..SemiRealConfig::default()
    };
    let got = semi_real_slopes(&cfg, &[2, 3], "pcap clear, 1-revolution fog");
    for (g, w) in got {
        assert!((g / w - 1.0).abs() < 0.03, "slope {g} vs truth {w}");
    }
}

/// Clear recordings as HDL-32E and VLP-32C captures (`.pcap` of packets
/// tagged 0x21 at the HDL-32E's 553 µs period, and 0x28, written field by
/// field by `murk_velodyne::synth`): murk decodes them on each sensor's 32
/// lasers and the fit measures the unit's own step (0.166° and 0.199° at
/// 600 rpm) and each laser's elevation — the VLP-32C's lasers also sit at
/// horizontal offsets of ±1.4° and ±4.2°, which each ring's phase takes.
/// The same recordings with the elevations declared in ascending order,
/// not by laser id (a datasheet's table copied as it is printed), are
/// warned.
#[test]
fn hdl32e_and_vlp32c_pcap_recordings_are_measured_on_their_own_lasers() {
    use murk_velodyne::SensorModel;
    for (model, spec) in [
        (SensorModel::Hdl32e, murk_types::LidarSpec::hdl32e()),
        (SensorModel::Vlp32c, murk_types::LidarSpec::vlp32c()),
    ] {
        pcap_recordings_are_measured_on_their_own_lasers(model, &spec);
    }
}

/// A campaign of three clear `.pcap` recordings, `sweep` turned by 40° from
/// one to the next, whose `[lidar]` declares `spec`'s model, `elevations`
/// and step and then `extra` lines; the geometry fit measures on it.
fn pcap_geometry(
    spec: &murk_types::LidarSpec,
    elevations: &[f64],
    extra: &str,
    sweep: &murk_velodyne::synth::Sweep,
) -> (
    tempfile::TempDir,
    Result<(murk_types::SensorGeometry, Vec<String>), murk_fit::FitError>,
) {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir_all(d.join("lidar")).unwrap();
    let el: Vec<String> = elevations.iter().map(|e| format!("{e}")).collect();
    std::fs::write(
        d.join("campaign.toml"),
        format!(
            "name = \"pcap\"\nrules = \"pdd-2022-2023\"\n[lidar]\nmodel = \"{}\"\nelevation_deg = [{}]\nazimuth_resolution_deg = {}\n{extra}",
            spec.model,
            el.join(", "),
            spec.azimuth_resolution_deg
        ),
    )
    .unwrap();
    let mut csv = String::from(
        "recording,timestamp,PWD12_Weather Type,PWD12_Rain intensity (mm/h),PWD12_MOR (m),PWD12_Temperature (°C),VS2K_MOR (m),WXT530_Rain intensity (mm/h)\n",
    );
    for k in 0..3u32 {
        let turned = murk_velodyne::synth::Sweep {
            start_azimuth_deg: 40.0 * f64::from(k),
            ..sweep.clone()
        };
        std::fs::write(d.join("lidar").join(format!("r{k}.pcap")), turned.to_pcap()).unwrap();
        csv.push_str(&format!(
            "r{k},2023-01-14T0{k}:00:00Z,Clear,0,20000,2.0,20000,0\n"
        ));
    }
    std::fs::write(d.join("weather.csv"), csv).unwrap();
    let campaign = Campaign::open(d).unwrap();
    let inputs = murk_fit::observe::FitInputs::from_campaign(&campaign);
    let got = murk_fit::observe::measure_geometry(&inputs);
    (dir, got)
}

fn pcap_recordings_are_measured_on_their_own_lasers(
    model: murk_velodyne::SensorModel,
    spec: &murk_types::LidarSpec,
) {
    let sweep = murk_velodyne::synth::Sweep {
        rpm: 600.0,
        packets: (400.0 * 46.08 / model.block_period_us()).round() as usize,
        model,
        ..murk_velodyne::synth::Sweep::default()
    };
    let write = |elevations: &[f64]| {
        let (dir, got) = pcap_geometry(spec, elevations, "", &sweep);
        (dir, got.unwrap())
    };
    let name = model.name();
    let (_d, (g, warnings)) = write(&spec.elevation_deg);
    eprintln!(
        "{name}: step {:.4}°, phases {:?}",
        g.azimuth_step_deg,
        g.rings
            .iter()
            .map(|r| (r.azimuth_phase_deg * 1000.0).round() / 1000.0)
            .collect::<Vec<_>>()
    );
    assert!(warnings.is_empty(), "{name}: {warnings:?}");
    assert_eq!(g.source, "measured");
    assert_eq!(g.rings.len(), 32);
    let step = 360.0 / (360.0 / (10.0f64 * 360.0 * model.block_period_us() * 1e-6)).round();
    assert!(
        (g.azimuth_step_deg / step - 1.0).abs() < 0.005,
        "{name}: step {} against {step}",
        g.azimuth_step_deg
    );
    for r in &g.rings {
        let want = spec.elevation_deg[r.ring as usize];
        let e = r.elevation_deg.expect("measured");
        assert!(
            (e - want).abs() < 0.01,
            "{name} ring {}: {e} against {want}",
            r.ring
        );
    }
    let mut sorted = spec.elevation_deg.clone();
    sorted.sort_by(f64::total_cmp);
    let (_d, (_, warnings)) = write(&sorted);
    assert!(
        warnings.iter().any(|w| w.starts_with("ring elevations")),
        "{name}: {warnings:?}"
    );
}

/// A dual-return `.pcap` holds two returns of many firings (strongest and
/// last, at one ring and azimuth); murk's model has one. Until the
/// campaign says which to read, fit (here its geometry, which every fit,
/// diagnosis and campaign summary measures first) refuses the recording,
/// naming it and the key; with `pcap_return` it reads that return.
#[test]
fn dual_return_pcap_recordings_are_refused_until_the_campaign_names_a_return() {
    let spec = murk_types::LidarSpec::vlp16();
    let sweep = murk_velodyne::synth::Sweep {
        packets: 600,
        mode: murk_velodyne::ReturnMode::Dual,
        ..murk_velodyne::synth::Sweep::default()
    };
    let write = |extra: &str| pcap_geometry(&spec, &spec.elevation_deg, extra, &sweep);
    let (_d, got) = write("");
    let e = got.expect_err("both returns refused").to_string();
    assert!(
        e.contains("r0.pcap") && e.contains("dual-return") && e.contains("pcap_return"),
        "{e}"
    );
    for r in ["strongest", "last"] {
        let (_d, got) = write(&format!("pcap_return = \"{r}\"\n"));
        let (g, warnings) = got.unwrap_or_else(|e| panic!("{r}: {e}"));
        assert_eq!(g.source, "measured", "{r}");
        assert_eq!(g.rings.len(), 16, "{r}");
        assert!(
            (g.azimuth_step_deg / 0.1991 - 1.0).abs() < 0.005,
            "{r}: step {}",
            g.azimuth_step_deg
        );
        assert!(warnings.is_empty(), "{r}: {warnings:?}");
    }
}
