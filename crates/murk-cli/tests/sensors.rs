//! Data murk has not generated, end to end (issue #12): `murk fit` →
//! `murk apply` → `murk diagnose` on
//!
//! - a campaign whose reflectivities are all ≥ 24 (the band [0, 10) is
//!   empty, as on an HDL-64 with calibrated intensities),
//! - an HDL-64-like sensor (64 rings of its own elevations, its own step),
//!   written as PCD and as Seeing Through Fog's five-column `.bin`,
//! - an Ouster-like sensor in its driver's organised layout (beam by beam,
//!   clockwise, a per-beam azimuth offset, no-return firings at the origin),
//! - `.pcap` recordings of many revolutions in `lidar/` beside fog
//!   recordings of one (the semi-real source),
//! - a narrow MOR range (304–378 m) on the semi-real source, whose edge
//!   lies beyond the scene: said in the table, refused by apply.
//!
//! The semi-real cases need `../shared/data/real`; they skip with a message
//! when it is absent.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use murk_fixtures::semi_real::{self, SemiRealConfig};
use murk_fixtures::{Generator, GeneratorConfig, OutputOptions, Preset};
use murk_types::{CoefficientTable, PointFormat};

fn murk(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_murk"))
        .args(args)
        .output()
        .expect("murk runs")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn ok(o: &Output, what: &str) -> String {
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(
        o.status.success(),
        "{what} failed: {err}\n{}",
        String::from_utf8_lossy(&o.stdout)
    );
    format!("{}{err}", String::from_utf8_lossy(&o.stdout))
}

/// fit → apply (one clear recording at MOR 60 m, with near-range returns)
/// → diagnose; returns the table, the apply output and the report.
fn fit_apply_diagnose(camp: &Path, work: &Path) -> (CoefficientTable, String, serde_json::Value) {
    fit_apply_diagnose_with(camp, work, "pcd", &[])
}

/// [`fit_apply_diagnose`] on the campaign's files of extension `ext`, with
/// `apply_args` added to `murk apply`.
fn fit_apply_diagnose_with(
    camp: &Path,
    work: &Path,
    ext: &str,
    apply_args: &[&str],
) -> (CoefficientTable, String, serde_json::Value) {
    let table = work.join("table.json");
    let out = murk(&["fit", s(camp), "--out", s(&table)]);
    ok(&out, "fit");
    let t = CoefficientTable::read(&table).unwrap();
    let clear = std::fs::read_dir(camp.join("lidar"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == ext))
        .min()
        .unwrap();
    let applied = work.join("applied");
    let a = murk(
        &[
            &["apply"],
            apply_args,
            &[
                "--coefficients",
                s(&table),
                "--weather",
                "fog",
                "--mor",
                "60",
                "--near-range",
                s(&clear),
                "--out",
                s(&applied),
            ],
        ]
        .concat(),
    );
    let apply_text = ok(&a, "apply");
    assert!(
        std::fs::read_dir(&applied).unwrap().count() == 1,
        "apply wrote no output"
    );
    let report = work.join("report.json");
    let d = murk(&[
        "diagnose",
        s(camp),
        "--weather",
        "fog",
        "--coefficients",
        s(&table),
        "--permutations",
        "99",
        "--sims",
        "1",
        "--out",
        s(&report),
    ]);
    ok(&d, "diagnose");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(r["format"], "weather-noise-diagnosis/1");
    (t, apply_text, r)
}

fn generated(edit: impl Fn(&mut GeneratorConfig)) -> (tempfile::TempDir, PathBuf) {
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = 40;
    c.weather.mix.clear = 0.3;
    c.weather.mix.fog = 0.7;
    c.weather.mix.rain = 0.0;
    c.weather.mix.snow = 0.0;
    edit(&mut c);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("campaign");
    Generator::new(c)
        .unwrap()
        .write_campaign(3, &OutputOptions::new(&path))
        .unwrap();
    (dir, path)
}

#[test]
fn an_empty_band_works_end_to_end() {
    let (dir, camp) = generated(|_| {});
    // Every return of every recording at reflectivity ≥ 24.
    for e in std::fs::read_dir(camp.join("lidar")).unwrap() {
        let p = e.unwrap().path();
        let opts = murk_io::ReadOptions::default();
        let mut c = murk_io::read_cloud(&p, &opts).unwrap();
        for v in &mut c.intensity {
            *v = v.max(24.0);
        }
        murk_io::write_cloud(&p, &c, PointFormat::Pcd).unwrap();
    }
    let (t, apply, _) = fit_apply_diagnose(&camp, dir.path());
    let fog = &t.weathers[&murk_types::WeatherClass::Fog];
    let low = &fog.vanishing_slope[0];
    assert_eq!(
        (low.reflectivity_min, low.points, low.slope),
        (0.0, 0, None)
    );
    assert!(fog.vanishing_slope[1].slope.is_some());
    assert!(
        apply.contains("had no clear return in the campaign"),
        "{apply}"
    );
}

#[test]
fn an_hdl64_like_sensor_works_end_to_end() {
    let (dir, camp) = generated(|c| hdl64(c, "pcd"));
    let (t, _, _) = fit_apply_diagnose(&camp, dir.path());
    check_hdl64(&t);
}

/// An HDL-64-like sensor written in `format`: 64 rings, +2° to −8.33° by
/// 1/3°, then −8.83° to −24.33° by 1/2° (the HDL-64E's two blocks), fired
/// every 0.8° at a 0.13° phase, 24 recordings.
fn hdl64(c: &mut GeneratorConfig, format: &str) {
    c.lidar.model = "HDL64".into();
    c.lidar.elevation_deg = semi_real::hdl64e_elevation_deg();
    c.lidar.azimuth_resolution_deg = 0.8;
    c.sensor.azimuth_phase_deg = 0.13;
    c.campaign.recordings = 24;
    c.campaign.format = format.into();
}

/// The table of [`hdl64`]'s campaign: its 64 rings and step measured, no
/// warning, clear no-change ≥ 0.97.
fn check_hdl64(t: &CoefficientTable) {
    let g = t.lidar.geometry.as_ref().unwrap();
    assert_eq!(g.rings.len(), 64);
    assert!(
        (g.azimuth_step_deg - 0.8).abs() < 1e-9,
        "{}",
        g.azimuth_step_deg
    );
    assert!(t.lidar.warnings.is_empty(), "{:?}", t.lidar.warnings);
    let clear = t.clear.as_ref().unwrap().no_change_rate.unwrap();
    assert!(clear >= 0.97, "clear no-change {clear}");
}

/// The HDL-64-like sensor written as Seeing Through Fog writes its scans:
/// five-float `.bin` records (x, y, z, intensity, ring), the layout
/// declared in `campaign.toml` (`bin_layout = "xyzir"`) and given to
/// `murk apply` (`--bin-layout xyzir`), since the bytes alone fit several.
#[test]
fn a_five_column_bin_hdl64_works_end_to_end() {
    let (dir, camp) = generated(|c| hdl64(c, "pcd.bin"));
    // nuScenes' `.pcd.bin` holds the same five floats: rename to `.bin`
    // and declare the layout.
    for e in std::fs::read_dir(camp.join("lidar")).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_str().unwrap().to_string();
        let id = name.strip_suffix(".pcd.bin").expect("a .pcd.bin file");
        std::fs::rename(&p, p.with_file_name(format!("{id}.bin"))).unwrap();
    }
    let toml = std::fs::read_to_string(camp.join("campaign.toml")).unwrap();
    assert!(toml.contains("[lidar]"), "{toml}");
    let toml = toml.replacen("[lidar]", "[lidar]\nbin_layout = \"xyzir\"", 1);
    std::fs::write(camp.join("campaign.toml"), toml).unwrap();
    let (t, _, r) = fit_apply_diagnose_with(&camp, dir.path(), "bin", &["--bin-layout", "xyzir"]);
    check_hdl64(&t);
    let fog = &t.weathers[&murk_types::WeatherClass::Fog];
    assert!(
        fog.vanishing_slope.iter().any(|b| b.slope.is_some()),
        "no fog slope from the .bin campaign"
    );
    // The diagnosis read the `.bin` recordings: it held some out.
    let held = r["heldout_recordings"].as_u64().unwrap();
    assert!(held > 0, "diagnose held out {held} recordings");
}

/// An Ouster-like sensor as its ROS driver writes a scan: 64 beams from
/// +16.6° to −16.6°, 1,024 columns a turn (0.3516°), each beam at its own
/// azimuth offset (+3.16°, +1.05°, −1.05°, −3.16° by beam, repeating), the
/// cloud organised beam by beam with the columns in firing order — the
/// sensor turns clockwise, so the azimuth falls along a beam — and every
/// firing without a return written as a point at the origin. The same
/// generated campaign in this layout must fit as in the generator's own
/// (the weather does not care how a file is ordered), once `min_range_m`
/// says the origin's points are not returns; without it the fit warns.
///
/// Measured (seed 3, 24 recordings; 973,302 returns and 599,562 firings
/// without one): step 0.3516° measured on all 64 beams, clear no-change
/// 0.9896 in both layouts, fog slopes 0.3058 / 0.3471 in both (truth, the
/// seed's Table 4: 0.3029 / 0.3463). Undeclared, 0.3055 / 0.3468: this
/// generator's weather puts few returns on the open rays, so the origin's
/// points rarely read as lost — the nuScenes physics fog, whose echo shows
/// on every open ray, is where they break the fit
/// (`fit/tests/occlusion.rs`).
#[test]
fn an_ouster_like_sensor_works_end_to_end() {
    const COLUMNS: usize = 1024;
    let step = 360.0 / COLUMNS as f64;
    let (dir, camp) = generated(|c| {
        c.lidar.model = "OS1-64".into();
        c.lidar.elevation_deg = (0..64).map(|k| 16.6 - k as f64 * 33.2 / 63.0).collect();
        c.lidar.azimuth_resolution_deg = step;
        c.sensor.azimuth_jitter_deg = 0.02;
        c.campaign.recordings = 24;
    });
    let plain = dir.path().join("plain");
    ok(
        &murk(&["fit", s(&camp), "--out", s(&plain)]),
        "fit in the generator's layout",
    );
    let offsets: [f64; 4] = [3.164, 1.055, -1.055, -3.164];
    let (mut zeros, mut points) = (0usize, 0usize);
    for e in std::fs::read_dir(camp.join("lidar")).unwrap() {
        let p = e.unwrap().path();
        let c = murk_io::read_cloud(&p, &murk_io::ReadOptions::default()).unwrap();
        // One slot per (beam, column): the nearest point of each firing.
        let mut slots: Vec<Option<usize>> = vec![None; 64 * COLUMNS];
        for i in 0..c.len() {
            let az = (c.y[i] as f64).atan2(c.x[i] as f64).to_degrees();
            let k = (az / step).round().rem_euclid(COLUMNS as f64) as usize;
            let column = (COLUMNS - k) % COLUMNS;
            let slot = &mut slots[c.ring[i] as usize * COLUMNS + column];
            if slot.is_none_or(|j| c.range(i) < c.range(j)) {
                *slot = Some(i);
            }
        }
        let mut out = murk_types::PointCloud::with_capacity(slots.len());
        for (n, slot) in slots.iter().enumerate() {
            let beam = (n / COLUMNS) as u16;
            match *slot {
                Some(i) => {
                    let turn = offsets[beam as usize % 4].to_radians() as f32;
                    let (sin, cos) = turn.sin_cos();
                    let (x, y) = (c.x[i], c.y[i]);
                    out.push(
                        x * cos - y * sin,
                        x * sin + y * cos,
                        c.z[i],
                        c.intensity[i],
                        beam,
                    );
                    points += 1;
                }
                None => {
                    out.push(0.0, 0.0, 0.0, 0.0, beam);
                    zeros += 1;
                }
            }
        }
        murk_io::write_cloud(&p, &out, PointFormat::Pcd).unwrap();
    }
    eprintln!("{points} returns, {zeros} firings without one");
    assert!(zeros > 100_000 && points > 100_000);

    let undeclared = dir.path().join("undeclared");
    ok(
        &murk(&["fit", s(&camp), "--out", s(&undeclared)]),
        "fit without min_range_m",
    );
    let u = CoefficientTable::read(&undeclared).unwrap();
    for b in &u.weathers[&murk_types::WeatherClass::Fog].vanishing_slope {
        eprintln!(
            "without min_range_m, band {}: slope {:?} ({:?})",
            b.reflectivity_min, b.slope, b.reason
        );
    }
    assert!(
        u.lidar.warnings.iter().any(|w| w.contains("min_range_m")),
        "{:?}",
        u.lidar.warnings
    );
    // `murk campaign summary` says it before any fit.
    let summary = ok(
        &murk(&["campaign", "summary", s(&camp)]),
        "campaign summary",
    );
    assert!(
        summary.contains("within 0.3 m") && summary.contains("min_range_m"),
        "{summary}"
    );
    let toml = std::fs::read_to_string(camp.join("campaign.toml")).unwrap();
    let toml = toml.replacen("[lidar]", "[lidar]\nmin_range_m = 0.3", 1);
    std::fs::write(camp.join("campaign.toml"), toml).unwrap();
    let work = dir.path().join("work");
    std::fs::create_dir(&work).unwrap();
    let (t, apply, _) = fit_apply_diagnose_with(&camp, &work, "pcd", &["--campaign", s(&camp)]);
    assert!(apply.contains("not returns"), "{apply}");
    let g = t.lidar.geometry.as_ref().unwrap();
    assert_eq!(g.rings.len(), 64);
    assert!(
        ((g.azimuth_step_deg - step) / step).abs() < 1e-6,
        "{}",
        g.azimuth_step_deg
    );
    assert!(t.lidar.warnings.is_empty(), "{:?}", t.lidar.warnings);
    let plain = CoefficientTable::read(&plain).unwrap();
    for (table, what) in [(&t, "Ouster layout"), (&plain, "generator's layout")] {
        let clear = table.clear.as_ref().unwrap().no_change_rate.unwrap();
        eprintln!("{what}: clear no-change {clear:.4}");
        assert!(clear >= 0.97, "{what}: clear no-change {clear}");
    }
    let fog = |t: &CoefficientTable| t.weathers[&murk_types::WeatherClass::Fog].clone();
    for (a, b) in fog(&t)
        .vanishing_slope
        .iter()
        .zip(&fog(&plain).vanishing_slope)
    {
        let (sa, sb) = (a.slope.unwrap(), b.slope.unwrap());
        eprintln!(
            "band {}: slope {sa:.4} in the Ouster layout, {sb:.4} in the generator's",
            a.reflectivity_min
        );
        assert!((sa / sb - 1.0).abs() < 0.01, "band {}", a.reflectivity_min);
    }
}

/// The real VLP-16 capture beside the checkout, or `None` (after saying
/// `skipping: …`) when `../shared/data/real` is absent.
fn capture() -> Option<PathBuf> {
    semi_real::vlp16_capture(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn pcap_recordings_in_lidar_work_end_to_end() {
    let Some(capture) = capture() else { return };
    let dir = tempfile::tempdir().unwrap();
    let camp = dir.path().join("campaign");
    // 24 fog recordings: the edge test (one-sided sign flips over
    // recordings at 1 %) needs at least seven that carry the edge, and on 16
    // this seed's low-MOR recordings were too few once recordings paired
    // across shifted firings (p 0.014; gain 165 nats per recording).
    let cfg = SemiRealConfig {
        clear_pcap_parts: 3,
        degraded: 24,
        ..SemiRealConfig::default()
    };
    semi_real::vlp16_campaign(&capture, &camp, &cfg, 4).unwrap();
    let (t, _, _) = fit_apply_diagnose(&camp, dir.path());
    assert_eq!(t.lidar.count_unit, murk_types::CountUnit::PerRevolution);
    let clear = t.clear.as_ref().unwrap().no_change_rate.unwrap();
    assert!(clear >= 0.97, "clear no-change {clear}");
    let fog = &t.weathers[&murk_types::WeatherClass::Fog];
    for b in &fog.vanishing_slope {
        let s = b.slope.unwrap();
        assert!(
            s > 0.2 && s < 0.45,
            "band {}: slope {s}",
            b.reflectivity_min
        );
    }
}

/// Fog of 304–378 m MOR on the real scene: its vanishing distances (over
/// 100 m) lie beyond the scene's returns, so no band sees its edge. The fit
/// must still write a table, saying so per band, and apply must refuse such
/// a band naming it, not apply a slope nobody measured.
#[test]
fn a_narrow_mor_range_beyond_the_scene_is_said() {
    let Some(capture) = capture() else { return };
    let dir = tempfile::tempdir().unwrap();
    let camp = dir.path().join("campaign");
    let cfg = SemiRealConfig {
        mor_m: [304.0, 378.0],
        degraded: 16,
        ..SemiRealConfig::default()
    };
    semi_real::vlp16_campaign(&capture, &camp, &cfg, 5).unwrap();
    let table = dir.path().join("table.json");
    ok(&murk(&["fit", s(&camp), "--out", s(&table)]), "fit");
    let t = CoefficientTable::read(&table).unwrap();
    let fog = &t.weathers[&murk_types::WeatherClass::Fog];
    assert_eq!(fog.recordings, 16);
    let censored: Vec<_> = fog
        .vanishing_slope
        .iter()
        .filter(|b| b.slope.is_none())
        .collect();
    assert!(!censored.is_empty(), "{:?}", fog.vanishing_slope);
    for b in &censored {
        let why = b.reason.as_deref().unwrap_or("");
        // Censored by the scene's far end, or turned down by the held-out
        // edge test (now on by default): either way said.
        assert!(
            why.contains("the edge is not seen") || why.starts_with("no edge"),
            "{why}"
        );
    }
    let clear = std::fs::read_dir(camp.join("lidar"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .min()
        .unwrap();
    let a = murk(&[
        "apply",
        "--coefficients",
        s(&table),
        "--weather",
        "fog",
        "--mor",
        "340",
        s(&clear),
        "--out",
        s(&dir.path().join("applied")),
    ]);
    assert!(!a.status.success());
    let err = String::from_utf8_lossy(&a.stderr);
    assert!(
        err.contains("vanishing_slope[") && err.contains("cannot be applied"),
        "{err}"
    );
}
