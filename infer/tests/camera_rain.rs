//! Physics-based rain on camera images (`murk_infer::camera`): attenuation
//! laws, identity at R = 0, growth of streaks with R, determinism, mean
//! luminosity, KITTI projection, bad inputs, and a smoke test on the real
//! KITTI frame 000008 when it is present.

use std::path::{Path, PathBuf};

use image::{Rgb, RgbImage};
use murk_infer::InferError;
use murk_infer::PointCloud;
use murk_infer::camera::physics::{terminal_velocity_m_s, transmittance};
use murk_infer::camera::{Densify, DepthMap, Intrinsics, KittiCalib, RainParams};

/// A synthetic street: a bright sky gradient in the top third, a textured
/// middle band and a darker road; depth 500 m in the sky, 30 m in the
/// middle, 5–30 m on the road.
fn scene(w: u32, h: u32) -> (RgbImage, DepthMap) {
    let img = RgbImage::from_fn(w, h, |x, y| {
        if y < h / 3 {
            let v = 200 + (y * 40 / (h / 3).max(1)) as u8;
            Rgb([v - 20, v - 10, v.min(250)])
        } else if y < h / 2 {
            let c = if (x / 8 + y / 8) % 2 == 0 { 60 } else { 160 };
            Rgb([c, c + 10, c - 20])
        } else {
            let v = 70 + ((x * 7 + y * 3) % 30) as u8;
            Rgb([v, v, v + 5])
        }
    });
    let metres: Vec<f32> = (0..h)
        .flat_map(|y| {
            (0..w).map(move |_| {
                if y < h / 3 {
                    500.0
                } else if y < h / 2 {
                    30.0
                } else {
                    let t = (y - h / 2) as f32 / (h - h / 2) as f32;
                    30.0 - 25.0 * t
                }
            })
        })
        .collect();
    (img, DepthMap::from_metres(w, h, metres, "scene").unwrap())
}

fn channel_means(img: &RgbImage) -> [f64; 3] {
    let mut s = [0f64; 3];
    for p in img.pixels() {
        for j in 0..3 {
            s[j] += f64::from(p[j]);
        }
    }
    let n = f64::from(img.width() * img.height());
    s.map(|v| v / n)
}

/// Michelson contrast of a two-level checkerboard after rendering.
fn checker_contrast(rate: f64, depth_m: f32) -> f64 {
    let img = RgbImage::from_fn(64, 48, |x, y| {
        if (x / 4 + y / 4) % 2 == 0 {
            Rgb([40, 40, 40])
        } else {
            Rgb([200, 200, 200])
        }
    });
    let depth = DepthMap::constant(64, 48, depth_m).unwrap();
    // Fog only: no drop can image on a million pixels.
    let r = RainParams::new(rate).min_drop_px(1e6).check().unwrap();
    let out = r.render(&img, &depth).unwrap();
    let lum: Vec<f64> = out.pixels().map(|p| f64::from(p[1])).collect();
    let max = lum.iter().cloned().fold(f64::MIN, f64::max);
    let min = lum.iter().cloned().fold(f64::MAX, f64::min);
    (max - min) / (max + min)
}

#[test]
fn transmittance_is_monotone_in_depth_and_rate() {
    // Known answer: β(100 mm/h) = 0.312·100^0.67 = 6.8258 /km → 100 m
    // transmits e^−0.68258 = 0.50531.
    assert!((transmittance(100.0, 100.0) - 0.505_31).abs() < 1e-5);
    assert_eq!(transmittance(50.0, 0.0), 1.0);
    assert_eq!(transmittance(0.0, 1000.0), 1.0);
    let depths = [1.0, 10.0, 50.0, 200.0, 1000.0];
    let rates = [1.0, 5.0, 25.0, 100.0, 200.0];
    for r in rates {
        for w in depths.windows(2) {
            assert!(transmittance(r, w[1]) < transmittance(r, w[0]));
        }
    }
    for d in depths {
        for w in rates.windows(2) {
            assert!(transmittance(w[1], d) < transmittance(w[0], d));
        }
    }
}

#[test]
fn rendered_contrast_drops_with_depth_and_rate() {
    // Gain restoration rescales but keeps the Michelson contrast, which the
    // airlight lowers: strictly decreasing in depth and in rate.
    let by_depth: Vec<f64> = [20.0, 100.0, 400.0, 1500.0]
        .iter()
        .map(|&d| checker_contrast(50.0, d))
        .collect();
    for w in by_depth.windows(2) {
        assert!(w[1] < w[0], "by depth: {by_depth:?}");
    }
    let by_rate: Vec<f64> = [5.0, 25.0, 100.0, 300.0]
        .iter()
        .map(|&r| checker_contrast(r, 300.0))
        .collect();
    for w in by_rate.windows(2) {
        assert!(w[1] < w[0], "by rate: {by_rate:?}");
    }
}

#[test]
fn zero_rate_is_the_identity() {
    let (img, depth) = scene(200, 120);
    let out = RainParams::new(0.0)
        .ego_speed_m_s(20.0)
        .seed(3)
        .check()
        .unwrap()
        .render(&img, &depth)
        .unwrap();
    assert_eq!(out.as_raw(), img.as_raw());
}

#[test]
fn streak_count_and_coverage_grow_with_rate() {
    let (img, depth) = scene(640, 360);
    let mut last = (0usize, 0.0f64);
    for rate in [5.0, 25.0, 100.0, 200.0] {
        let (_, st) = RainParams::new(rate)
            .seed(5)
            .check()
            .unwrap()
            .render_with_stats(&img, &depth)
            .unwrap();
        assert!(
            st.streaks > last.0 && st.covered_share > last.1,
            "rate {rate}: {} streaks, share {} after {last:?}",
            st.streaks,
            st.covered_share
        );
        last = (st.streaks, st.covered_share);
    }
    assert!(last.1 < 0.5, "coverage {} is implausible", last.1);
}

#[test]
fn streaks_change_pixels_beyond_the_fog() {
    // The same image with and without streaks (fog identical) differs.
    let (img, depth) = scene(320, 180);
    let fog = RainParams::new(100.0).min_drop_px(1e6).check().unwrap();
    let full = RainParams::new(100.0).check().unwrap();
    let a = fog.render(&img, &depth).unwrap();
    let b = full.render(&img, &depth).unwrap();
    let changed = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .filter(|(x, y)| x != y)
        .count();
    assert!(changed > 100, "{changed} bytes changed");
}

#[test]
fn same_seed_same_bytes_any_thread_count() {
    let (img, depth) = scene(400, 240);
    let r = RainParams::new(100.0)
        .ego_speed_m_s(15.0)
        .seed(42)
        .check()
        .unwrap();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| r.render(&img, &depth).unwrap());
    let four = rayon::ThreadPoolBuilder::new()
        .num_threads(4)
        .build()
        .unwrap()
        .install(|| r.render(&img, &depth).unwrap());
    assert_eq!(one.as_raw(), four.as_raw());
    assert_eq!(r.render(&img, &depth).unwrap().as_raw(), one.as_raw());
    let other = r.with_seed(43).render(&img, &depth).unwrap();
    assert_ne!(other.as_raw(), one.as_raw());
}

#[test]
fn mean_luminosity_is_preserved_per_channel() {
    // Stated tolerance: 0.5 of an 8-bit level per channel.
    let (img, depth) = scene(480, 270);
    let before = channel_means(&img);
    for rate in [10.0, 100.0, 200.0] {
        let out = RainParams::new(rate)
            .ego_speed_m_s(10.0)
            .check()
            .unwrap()
            .render(&img, &depth)
            .unwrap();
        let after = channel_means(&out);
        for j in 0..3 {
            assert!(
                (after[j] - before[j]).abs() <= 0.5,
                "rate {rate} channel {j}: {} vs {}",
                after[j],
                before[j]
            );
        }
        assert_ne!(out.as_raw(), img.as_raw());
    }
}

#[test]
fn ego_motion_lengthens_streaks() {
    // Moving forward adds radial motion: the covered share grows.
    let (img, depth) = scene(480, 270);
    let share = |v: f64| {
        RainParams::new(100.0)
            .ego_speed_m_s(v)
            .seed(9)
            .check()
            .unwrap()
            .render_with_stats(&img, &depth)
            .unwrap()
            .1
            .covered_share
    };
    let (still, fast) = (share(0.0), share(30.0));
    assert!(fast > still, "{fast} vs {still}");
}

const AXIS_CALIB: &str = "# synthetic\n\
P0: 1 0 0 0 0 1 0 0 0 0 1 0\n\
P2: 700 0 50.5 0 0 700 30.5 0 0 0 1 0\n\
R0_rect: 1 0 0 0 1 0 0 0 1\n\
Tr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 0 0\n";

#[test]
fn kitti_projection_known_answer() {
    let calib = KittiCalib::parse(AXIS_CALIB, Path::new("axis.txt")).unwrap();
    // On the optical axis (velodyne +x) at 10 m: principal point, depth 10.
    let (u, v, d) = calib.project(10.0, 0.0, 0.0).unwrap();
    assert!((u - 50.5).abs() < 1e-12 && (v - 30.5).abs() < 1e-12 && (d - 10.0).abs() < 1e-12);
    assert_eq!(
        calib.intrinsics(),
        Intrinsics {
            fx: 700.0,
            fy: 700.0,
            cx: 50.5,
            cy: 30.5
        }
    );
    // Through the depth map: pixel (50, 30) holds 10 m; a nearer point on the
    // same pixel wins; the column above is sky, below is filled.
    let mut cloud = PointCloud::with_capacity(3);
    cloud.push(10.0, 0.0, 0.0, 0.0, 0);
    cloud.push(12.0, 0.0, 0.0, 0.0, 0);
    cloud.push(-3.0, 0.0, 0.0, 0.0, 0); // behind: ignored
    let dense = Densify {
        max_row_gap_px: 8,
        above_scan_m: Some(777.0),
        ..Densify::default()
    };
    let dm = DepthMap::from_lidar(&cloud, &calib, 100, 60, &dense, "axis").unwrap();
    assert_eq!(dm.get(50, 30), 10.0);
    assert_eq!(dm.get(50, 29), 777.0);
    assert_eq!(dm.get(50, 59), 10.0);
    assert_eq!(dm.get(0, 45), 10.0);
}

fn calib_err(text: &str) -> (PathBuf, usize, String) {
    match KittiCalib::parse(text, Path::new("calib/000001.txt")) {
        Err(InferError::Calib { path, line, reason }) => (path, line, reason),
        other => panic!("expected a calib error, got {other:?}"),
    }
}

#[test]
fn calib_bad_number_names_file_and_line() {
    let text = AXIS_CALIB.replace("R0_rect: 1 0 0", "R0_rect: 1 zero 0");
    let (path, line, reason) = calib_err(&text);
    assert_eq!(path, Path::new("calib/000001.txt"));
    assert_eq!(line, 4);
    assert!(
        reason.contains("R0_rect") && reason.contains("value 2"),
        "{reason}"
    );
}

#[test]
fn calib_wrong_count_names_file_and_line() {
    let text = AXIS_CALIB.replace("P2: 700 0 50.5 0 ", "P2: 700 0 50.5 ");
    let (_, line, reason) = calib_err(&text);
    assert_eq!(line, 3);
    assert!(reason.contains("expected 12 numbers, found 11"), "{reason}");
}

#[test]
fn calib_missing_entry_names_the_entry() {
    let text: String = AXIS_CALIB
        .lines()
        .filter(|l| !l.starts_with("Tr_velo"))
        .map(|l| format!("{l}\n"))
        .collect();
    let (_, line, reason) = calib_err(&text);
    assert_eq!(line, 4);
    assert!(reason.contains("no Tr_velo_to_cam"), "{reason}");
}

#[test]
fn calib_line_without_colon_is_refused() {
    let text = format!("{AXIS_CALIB}garbage line\n");
    let (_, line, reason) = calib_err(&text);
    assert_eq!(line, 6);
    assert!(reason.contains("KEY: numbers"), "{reason}");
}

#[test]
fn calib_missing_file_names_the_file() {
    let err = KittiCalib::from_file(Path::new("/nonexistent/calib.txt")).unwrap_err();
    assert!(err.to_string().contains("/nonexistent/calib.txt"), "{err}");
}

#[test]
fn depth_with_nan_names_the_pixel() {
    let mut m = vec![5.0f32; 12];
    m[7] = f32::NAN;
    match DepthMap::from_metres(4, 3, m, "d.png") {
        Err(InferError::Depth {
            source_name, x, y, ..
        }) => {
            assert_eq!((source_name.as_str(), x, y), ("d.png", 3, 1));
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn depth_of_the_wrong_length_is_refused() {
    assert!(matches!(
        DepthMap::from_metres(4, 3, vec![1.0; 11], "d"),
        Err(InferError::Depth { .. })
    ));
}

#[test]
fn image_and_depth_size_mismatch_is_refused() {
    let img = RgbImage::new(10, 8);
    let depth = DepthMap::constant(10, 9, 5.0).unwrap();
    let err = RainParams::new(10.0)
        .check()
        .unwrap()
        .render(&img, &depth)
        .unwrap_err();
    assert!(
        matches!(
            err,
            InferError::SizeMismatch {
                image_h: 8,
                depth_h: 9,
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn lidar_outside_the_image_is_an_error_not_a_blank_map() {
    let calib = KittiCalib::parse(AXIS_CALIB, Path::new("axis.txt")).unwrap();
    let mut cloud = PointCloud::with_capacity(1);
    cloud.push(-10.0, 0.0, 0.0, 0.0, 0);
    let err =
        DepthMap::from_lidar(&cloud, &calib, 100, 60, &Densify::default(), "scan.bin").unwrap_err();
    assert!(err.to_string().contains("scan.bin"), "{err}");
}

#[test]
fn bad_parameters_are_refused_by_name() {
    let cases: Vec<(RainParams, &str)> = vec![
        (RainParams::new(-1.0), "rate_mm_h"),
        (RainParams::new(f64::NAN), "rate_mm_h"),
        (RainParams::new(10.0).exposure_s(0.0), "exposure_s"),
        (RainParams::new(10.0).ego_speed_m_s(-1.0), "ego_speed_m_s"),
        (RainParams::new(10.0).lens(0.006, 0.0), "f_number"),
        (RainParams::new(10.0).focus_m(0.001), "focus_m"),
        (
            RainParams::new(10.0).drop_diameter_m(0.004, 0.002),
            "drop_diameter_m",
        ),
        (RainParams::new(10.0).phase_g(1.0), "phase_g"),
        (
            RainParams::new(10.0).sun_direction([0.0; 3]),
            "sun_direction",
        ),
        (RainParams::new(10.0).oscillation(1.5), "oscillation"),
        (
            RainParams::new(10.0).intrinsics(Intrinsics {
                fx: 0.0,
                fy: 1.0,
                cx: 0.0,
                cy: 0.0,
            }),
            "intrinsics",
        ),
    ];
    for (p, name) in cases {
        match p.check() {
            Err(InferError::InvalidParam { name: n, .. }) => assert_eq!(n, name),
            other => panic!("{name}: {other:?}"),
        }
    }
}

#[test]
fn terminal_velocity_grows_with_size() {
    let v: Vec<f64> = [1.0, 2.0, 3.0, 5.0]
        .iter()
        .map(|&d| terminal_velocity_m_s(d))
        .collect();
    for w in v.windows(2) {
        assert!(w[1] > w[0]);
    }
}

fn real(name: &str) -> Option<PathBuf> {
    murk_types::real_data::real_data_file(env!("CARGO_MANIFEST_DIR"), name)
}

#[test]
fn kitti_000008_with_lidar_depth() {
    let (Some(png), Some(bin), Some(cal)) = (
        real("kitti-000008.png"),
        real("kitti-000008.bin"),
        real("kitti-000008-calib.txt"),
    ) else {
        return;
    };
    let img = image::open(&png).unwrap().to_rgb8();
    let (w, h) = img.dimensions();
    let calib = KittiCalib::from_file(&cal).unwrap();
    let cloud = murk_io::read_cloud(&bin, &murk_io::ReadOptions::default()).unwrap();
    let depth = DepthMap::from_lidar(
        &cloud,
        &calib,
        w,
        h,
        &Densify::default(),
        "kitti-000008.bin",
    )
    .unwrap();
    // The bottom row is road a few metres ahead; the LiDAR sees it.
    let bottom = depth.get(w / 2, h - 1);
    assert!(
        (2.0..20.0).contains(&bottom),
        "bottom-centre depth {bottom}"
    );
    let before = channel_means(&img);
    let gray = |im: &RgbImage| -> Vec<f64> { im.pixels().map(|p| f64::from(p[1])).collect() };
    let std = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64).sqrt()
    };
    let mut last_std = std(&gray(&img));
    for rate in [25.0, 200.0] {
        let r = RainParams::new(rate)
            .intrinsics(calib.intrinsics())
            .exposure_s(0.002)
            .ego_speed_m_s(10.0)
            .seed(1)
            .check()
            .unwrap();
        let (out, st) = r.render_with_stats(&img, &depth).unwrap();
        assert!(st.streaks > 0);
        let after = channel_means(&out);
        for j in 0..3 {
            assert!(
                (after[j] - before[j]).abs() <= 0.5,
                "{rate}: {after:?} vs {before:?}"
            );
        }
        // Fog-like rain lowers the contrast (green-channel std), more with R.
        let s = std(&gray(&out));
        assert!(s < last_std, "rate {rate}: std {s} not below {last_std}");
        last_std = s;
    }
}

#[test]
fn image_write_read_round_trip_is_exact_for_png() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.png");
    let (img, _) = scene(40, 30);
    murk_infer::camera::write_rgb_atomic(&path, &img).unwrap();
    assert_eq!(murk_infer::camera::read_rgb(&path).unwrap(), img);
    // No temporary file left behind.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn image_write_with_unknown_extension_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.tiff");
    let err = murk_infer::camera::write_rgb_atomic(&path, &RgbImage::new(2, 2)).unwrap_err();
    assert!(err.to_string().contains("out.tiff"), "{err}");
}

#[test]
fn unreadable_image_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("broken.png");
    std::fs::write(&path, b"not a png").unwrap();
    let err = murk_infer::camera::read_rgb(&path).unwrap_err();
    assert!(err.to_string().contains("broken.png"), "{err}");
}

#[test]
fn depth_png16_reads_metres_and_fills_zeros() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("depth.png");
    // KITTI convention: value / 256 = metres; 0 = no measurement.
    let raw: Vec<u16> = vec![0, 0, 2560, 0, 5120, 0];
    image::ImageBuffer::<image::Luma<u16>, _>::from_raw(3, 2, raw)
        .unwrap()
        .save(&path)
        .unwrap();
    let d = DepthMap::from_png16(&path, 1.0 / 256.0, &Densify::default()).unwrap();
    // Column 1 extends its 20 m upwards, column 2 its 10 m downwards, and
    // the empty column 0 copies its nearest column, 1.
    assert_eq!(d.as_slice(), &[20.0, 20.0, 10.0, 20.0, 20.0, 10.0]);
}

#[test]
fn depth_png_of_8_bits_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("depth8.png");
    image::GrayImage::new(3, 2).save(&path).unwrap();
    let err = DepthMap::from_png16(&path, 1.0 / 256.0, &Densify::default()).unwrap_err();
    assert!(
        err.to_string().contains("depth8.png") && err.to_string().contains("16-bit"),
        "{err}"
    );
}

#[test]
fn streaks_behind_a_near_wall_are_hidden() {
    // A wall 0.15 m away hides every drop (drops start at 0.2 m): the image
    // equals the fog-only render; without occlusion the streaks show.
    let img = RgbImage::from_pixel(160, 90, Rgb([90, 110, 130]));
    let depth = DepthMap::constant(160, 90, 0.15).unwrap();
    let fog = RainParams::new(200.0).min_drop_px(1e6).check().unwrap();
    let hidden = RainParams::new(200.0).check().unwrap();
    let shown = RainParams::new(200.0).occlusion(false).check().unwrap();
    let (h, st) = hidden.render_with_stats(&img, &depth).unwrap();
    assert!(st.streaks > 0);
    assert_eq!(st.covered_pixels, 0);
    assert_eq!(h.as_raw(), fog.render(&img, &depth).unwrap().as_raw());
    assert_ne!(shown.render(&img, &depth).unwrap().as_raw(), h.as_raw());
}

#[test]
fn defocus_spreads_and_dims_out_of_focus_streaks() {
    // A wide aperture (f/0.5) has a circle of confusion 32× that of f/16:
    // out-of-focus streaks widen (their peak alpha drops, but stays above
    // 1/255 over a wider band), so the covered share grows.
    let (img, depth) = scene(320, 180);
    let share = |n: f64| {
        RainParams::new(100.0)
            .lens(0.006, n)
            .seed(4)
            .check()
            .unwrap()
            .render_with_stats(&img, &depth)
            .unwrap()
            .1
            .covered_share
    };
    let (sharp, blurred) = (share(16.0), share(0.5));
    assert!(blurred > sharp, "f/0.5 {blurred} vs f/16 {sharp}");
}
