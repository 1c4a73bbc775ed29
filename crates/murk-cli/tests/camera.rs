//! `murk camera` and `murk rain --generator` end to end with the committed
//! tiny generator (`infer/tests/data/gan/`): folders and files in, names
//! kept, the library's bytes out, the reference images matched; GAN+PBR
//! equals translating and then rendering rain by hand; bad flags refused.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use image::{ImageBuffer, Luma, Rgb, RgbImage};
use murk_infer::camera::Generator;

fn murk(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_murk"))
        .args(args)
        .output()
        .expect("murk runs")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn gan_data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../infer/tests/data/gan")
        .join(name)
}

fn pixels(p: &Path) -> RgbImage {
    image::open(p).unwrap().to_rgb8()
}

fn street(w: u32, h: u32) -> RgbImage {
    RgbImage::from_fn(w, h, |x, y| {
        if y < h / 3 {
            Rgb([200, 210, 230])
        } else {
            Rgb([(60 + x % 50) as u8, 70, (80 + y % 30) as u8])
        }
    })
}

fn ok(o: &Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A refused run: exit code 1 (murk's errors) and the message.
fn fails(o: &Output) -> String {
    fails_with(o, 1)
}

/// A refused run with the given exit code (clap's flag errors are 2).
fn fails_with(o: &Output, code: i32) -> String {
    assert_eq!(
        o.status.code(),
        Some(code),
        "should fail: {}",
        String::from_utf8_lossy(&o.stdout)
    );
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn camera_translates_files_and_folders_like_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("clear");
    std::fs::create_dir_all(&folder).unwrap();
    street(64, 40).save(folder.join("a.png")).unwrap();
    street(30, 21).save(folder.join("b.png")).unwrap();
    std::fs::write(folder.join("notes.txt"), "not an image").unwrap();
    let single = dir.path().join("odd.png");
    std::fs::copy(gan_data("input_odd.png"), &single).unwrap();
    let out = dir.path().join("out");
    let generator = gan_data("tiny_generator.onnx");
    let stdout = ok(&murk(&[
        "camera",
        "--generator",
        s(&generator),
        s(&folder),
        s(&single),
        "--out",
        s(&out),
    ]));
    assert!(stdout.starts_with("3 images through"), "{stdout}");
    assert!(stdout.contains("tract"), "{stdout}");
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(names, ["a.png", "b.png", "odd.png"]);

    let mut g = Generator::load(&generator).unwrap();
    for (input, name) in [
        (folder.join("a.png"), "a.png"),
        (folder.join("b.png"), "b.png"),
        (single.clone(), "odd.png"),
    ] {
        let want = g.translate(&pixels(&input)).unwrap();
        assert_eq!(pixels(&out.join(name)), want, "{name}");
    }
    // And the independent reference (numpy), within one level.
    let got = pixels(&out.join("odd.png"));
    let reference = pixels(&gan_data("output_odd.png"));
    let worst = got
        .as_raw()
        .iter()
        .zip(reference.as_raw())
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap();
    assert!(worst <= 1, "differs from the numpy reference by {worst}");
}

#[test]
fn gan_plus_pbr_is_translate_then_rain() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    std::fs::create_dir_all(&input).unwrap();
    let image = input.join("street.png");
    street(120, 72).save(&image).unwrap();
    let depth: ImageBuffer<Luma<u16>, Vec<u16>> =
        ImageBuffer::from_fn(120, 72, |_, y| Luma([if y < 24 { 0 } else { 15 * 256 }]));
    let depth_path = dir.path().join("depth.png");
    depth.save(&depth_path).unwrap();
    let generator = gan_data("tiny_generator.onnx");

    // By hand: translate, then rain on the translation.
    let translated = dir.path().join("translated");
    ok(&murk(&[
        "camera",
        "--generator",
        s(&generator),
        s(&image),
        "--out",
        s(&translated),
    ]));
    let by_hand = dir.path().join("by-hand");
    let rain = |img: &Path, out: &Path, extra: &[&str]| {
        let mut args = vec![
            "rain",
            "--rate",
            "60",
            s(img),
            "--depth",
            s(&depth_path),
            "--out",
            s(out),
            "--seed",
            "5",
        ];
        args.extend_from_slice(extra);
        murk(&args)
    };
    ok(&rain(&translated.join("street.png"), &by_hand, &[]));
    // In one go.
    let hybrid = dir.path().join("hybrid");
    let stdout = ok(&rain(&image, &hybrid, &["--generator", s(&generator)]));
    assert!(stdout.contains("on the translations of"), "{stdout}");
    let got = pixels(&hybrid.join("street.png"));
    assert_eq!(got, pixels(&by_hand.join("street.png")));
    // It is neither the translation alone nor rain on the clear image.
    assert_ne!(got, pixels(&translated.join("street.png")));
    let plain = dir.path().join("plain");
    ok(&rain(&image, &plain, &[]));
    assert_ne!(got, pixels(&plain.join("street.png")));
}

#[test]
fn camera_refuses_bad_inputs_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let generator = gan_data("tiny_generator.onnx");
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    std::fs::create_dir_all(&a).unwrap();
    std::fs::create_dir_all(&b).unwrap();
    street(16, 16).save(a.join("x.png")).unwrap();
    street(16, 16).save(b.join("x.png")).unwrap();
    let out = dir.path().join("out");
    let g = s(&generator);

    let err = fails(&murk(&[
        "camera",
        "--generator",
        g,
        s(&a),
        s(&b),
        "--out",
        s(&out),
    ]));
    assert!(err.contains("would both be written to"), "{err}");
    let err = fails(&murk(&["camera", "--generator", g, s(&a), "--out", s(&a)]));
    assert!(
        err.contains("the output folder is the image's own folder"),
        "{err}"
    );
    let txt = dir.path().join("notes.txt");
    std::fs::write(&txt, "x").unwrap();
    let err = fails(&murk(&[
        "camera",
        "--generator",
        g,
        s(&txt),
        "--out",
        s(&out),
    ]));
    assert!(err.contains("notes.txt: not an image"), "{err}");
    let err = fails(&murk(&[
        "camera",
        "--generator",
        s(&txt),
        s(&a),
        "--out",
        s(&out),
    ]));
    assert!(err.contains("notes.txt: not a usable ONNX model"), "{err}");
    let bad = gan_data("bad_gray.onnx");
    let err = fails(&murk(&[
        "camera",
        "--generator",
        s(&bad),
        s(&a),
        "--out",
        s(&out),
    ]));
    assert!(
        err.contains("bad_gray.onnx: input `input` has shape"),
        "{err}"
    );
    let err = fails_with(
        &murk(&[
            "camera",
            "--generator",
            g,
            s(&a),
            "--out",
            s(&out),
            "--work-size",
            "448by256",
        ]),
        2,
    );
    assert!(err.contains("expected WIDTHxHEIGHT"), "{err}");
    #[cfg(feature = "tract")]
    {
        let err = fails(&murk(&[
            "camera",
            "--generator",
            g,
            s(&a),
            "--out",
            s(&out),
            "--ort-lib",
            "/nowhere/libonnxruntime.so",
        ]));
        assert!(err.contains("--features native"), "{err}");
    }
    assert!(!out.exists(), "nothing written when refused");
}

/// A real KITTI frame (1242 × 375: reflect-padded to 1244 × 376 for the
/// network) at full resolution and at the generator's training size: the
/// output keeps the original size, equals the library's translation, and
/// is not the input. Skips, saying so, when the shared data is absent.
#[test]
fn camera_keeps_the_size_of_a_real_kitti_frame() {
    let Some(png) =
        murk_types::real_data::real_data_file(env!("CARGO_MANIFEST_DIR"), "kitti-000008.png")
    else {
        return;
    };
    let png = png.as_path();
    let dir = tempfile::tempdir().unwrap();
    let generator = gan_data("tiny_generator.onnx");
    let input = pixels(png);
    assert_eq!(input.dimensions(), (1242, 375));
    let mut g = Generator::load(&generator).unwrap();
    for work in [None, Some("448x256")] {
        let out = dir.path().join(work.unwrap_or("full"));
        let mut args = vec![
            "camera",
            "--generator",
            s(&generator),
            s(png),
            "--out",
            s(&out),
        ];
        if let Some(w) = work {
            args.extend(["--work-size", w]);
        }
        let stdout = ok(&murk(&args));
        assert!(stdout.starts_with("1 image through"), "{stdout}");
        let got = pixels(&out.join("kitti-000008.png"));
        assert_eq!(got.dimensions(), (1242, 375), "{work:?}");
        assert_ne!(got, input, "{work:?}: the generator changed nothing");
        if work.is_none() {
            assert_eq!(got, g.translate(&input).unwrap());
        }
    }
}
