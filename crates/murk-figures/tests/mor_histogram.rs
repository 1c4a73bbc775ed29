//! The MOR histogram files: decodable, right size, not blank, deterministic,
//! and bad data or paths rejected with the file named.

use std::collections::HashSet;

use murk_figures::{FigureError, FigureOptions, mor_histogram, write_mor_histograms};

const FOG: [f64; 8] = [52.0, 55.0, 61.0, 75.0, 80.0, 90.0, 130.0, 160.0];
const RAIN: [f64; 5] = [80.0, 120.0, 150.0, 170.0, 175.0];
const SNOW: [f64; 1] = [110.0];

fn series() -> [(&'static str, &'static [f64]); 3] {
    [("fog", &FOG), ("rain", &RAIN), ("snow", &SNOW)]
}

#[test]
fn png_decodes_with_the_right_size_and_is_not_blank() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.png");
    let opts = FigureOptions {
        width: 640,
        panel_height: 200,
        title: Some("MOR per weather class".into()),
    };
    mor_histogram(&series(), &opts, &path).unwrap();
    let img = image::open(&path).unwrap().to_rgb8();
    // Three panels of 200 px plus a 40 px title.
    assert_eq!(img.dimensions(), (640, 3 * 200 + 40));
    let colours: HashSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    assert!(colours.len() >= 10, "only {} colours", colours.len());
    // The class colours are drawn (bars exist for each class).
    for c in [[110, 110, 110], [0, 114, 178], [86, 180, 233]] {
        assert!(colours.contains(&c), "no bar of colour {c:?}");
    }
    // Mostly white background, but far from all of it.
    let white = img.pixels().filter(|p| p.0 == [255, 255, 255]).count();
    let total = (img.width() * img.height()) as usize;
    assert!(
        white > total / 2 && white < total * 99 / 100,
        "{white}/{total} white"
    );
}

#[test]
fn svg_has_text_and_bars() {
    let dir = tempfile::tempdir().unwrap();
    let [png, svg] =
        write_mor_histograms(&series(), &FigureOptions::default(), dir.path()).unwrap();
    assert!(png.ends_with("mor-histogram.png"));
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg"), "{}", &text[..40]);
    assert!(text.contains("MOR (m)"));
    assert!(text.contains("fog (n = 8)"));
    assert!(text.contains("#0072B2"), "rain colour");
}

#[test]
fn identical_data_gives_identical_bytes_and_leaves_no_temp_file() {
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    for ext in ["png", "svg"] {
        let pa = a.path().join(format!("h.{ext}"));
        let pb = b.path().join(format!("h.{ext}"));
        mor_histogram(&series(), &FigureOptions::default(), &pa).unwrap();
        mor_histogram(&series(), &FigureOptions::default(), &pb).unwrap();
        assert_eq!(
            std::fs::read(&pa).unwrap(),
            std::fs::read(&pb).unwrap(),
            "{ext}"
        );
    }
    let names: Vec<String> = std::fs::read_dir(a.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names.len(), 2, "{names:?}");
}

#[test]
fn an_empty_class_still_draws() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.png");
    let s: [(&str, &[f64]); 2] = [("fog", &FOG), ("snow", &[])];
    mor_histogram(&s, &FigureOptions::default(), &path).unwrap();
    let img = image::open(&path).unwrap();
    assert_eq!(img.height(), 2 * 260);
}

#[test]
fn non_finite_value_is_rejected_with_series_and_index() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.png");
    let bad = [50.0, f64::NAN];
    let e = mor_histogram(
        &[("fog", &FOG), ("rain", &bad)],
        &FigureOptions::default(),
        &path,
    )
    .unwrap_err();
    assert!(matches!(e, FigureError::BadData { index: 1, .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("h.png") && msg.contains("`rain`") && msg.contains("value 1"),
        "{msg}"
    );
    assert!(!path.exists());
}

#[test]
fn unsupported_extension_is_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.jpg");
    let e = mor_histogram(&series(), &FigureOptions::default(), &path).unwrap_err();
    assert!(matches!(e, FigureError::UnsupportedFormat { .. }), "{e:?}");
    assert!(e.to_string().contains("h.jpg"));
}

#[test]
fn missing_folder_is_an_io_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("no").join("h.svg");
    let e = mor_histogram(&series(), &FigureOptions::default(), &path).unwrap_err();
    assert!(matches!(e, FigureError::Io { .. }), "{e:?}");
    assert!(e.to_string().contains("h.svg"), "{e}");
}
