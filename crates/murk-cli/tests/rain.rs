//! `murk rain` end to end: rain is drawn, R = 0 is the identity, a batch is
//! reproducible, and bad flags are refused with the reason.

use std::path::Path;
use std::process::{Command, Output};

use image::{ImageBuffer, Luma, Rgb, RgbImage};

fn murk(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_murk"))
        .args(args)
        .output()
        .expect("murk runs")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A 200×120 street-like image (bright sky, darker ground) and its depth
/// (20 m, 0 = unknown in the top rows) in `dir/in/`.
fn setup(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let input = dir.join("in");
    std::fs::create_dir_all(&input).unwrap();
    let img = RgbImage::from_fn(200, 120, |x, y| {
        if y < 40 {
            Rgb([200, 210, 230])
        } else {
            Rgb([(60 + x % 50) as u8, 70, (80 + y % 30) as u8])
        }
    });
    let image = input.join("street.png");
    img.save(&image).unwrap();
    let depth: ImageBuffer<Luma<u16>, Vec<u16>> =
        ImageBuffer::from_fn(200, 120, |_, y| Luma([if y < 40 { 0 } else { 20 * 256 }]));
    let depth_path = dir.join("street-depth.png");
    depth.save(&depth_path).unwrap();
    (image, depth_path)
}

fn pixels(p: &Path) -> RgbImage {
    image::open(p).unwrap().to_rgb8()
}

#[test]
fn rain_is_drawn_and_reproducible_and_zero_rain_is_the_identity() {
    let dir = tempfile::tempdir().unwrap();
    let (image, depth) = setup(dir.path());
    let run = |rate: &str, out: &str, seed: &str| {
        let out = dir.path().join(out);
        let o = murk(&[
            "rain",
            "--rate",
            rate,
            s(&image),
            "--depth",
            s(&depth),
            "--out",
            s(&out),
            "--seed",
            seed,
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        pixels(&out.join("street.png"))
    };
    let original = pixels(&image);
    let wet = run("80", "a", "1");
    assert_eq!(wet.dimensions(), original.dimensions());
    let changed = wet
        .pixels()
        .zip(original.pixels())
        .filter(|(a, b)| a != b)
        .count();
    assert!(changed > 200, "only {changed} pixels changed at 80 mm/h");
    assert_eq!(run("80", "b", "1"), wet, "same seed, same pixels");
    assert_ne!(run("80", "c", "2"), wet, "another seed, other drops");
    assert_eq!(run("0", "d", "1"), original, "R = 0 is the identity");
}

#[test]
fn missing_or_mismatched_depth_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (image, depth) = setup(dir.path());
    let out = dir.path().join("out");
    let o = murk(&["rain", "--rate", "10", s(&image), "--out", s(&out)]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("no depth"));
    let o = murk(&[
        "rain",
        "--rate",
        "10",
        s(&image),
        s(&image),
        "--depth",
        s(&depth),
        "--out",
        s(&out),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("2 images but 1 --depth"));
    let o = murk(&[
        "rain",
        "--rate",
        "-5",
        s(&image),
        "--depth",
        s(&depth),
        "--out",
        s(&out),
    ]);
    assert!(!o.status.success(), "a negative rate is refused");
}

/// An image's drops come from `--seed` and its file name, not from where it
/// stands in the list: the same image gets the same pixels first or second
/// in a batch (it used to be seeded by its position).
#[test]
fn an_image_gets_the_same_drops_wherever_it_stands_in_the_batch() {
    let dir = tempfile::tempdir().unwrap();
    let (image, depth) = setup(dir.path());
    let other = dir.path().join("in").join("other.png");
    std::fs::copy(&image, &other).unwrap();
    let run = |images: [&Path; 2], out: &str| {
        let out = dir.path().join(out);
        let o = murk(&[
            "rain",
            "--rate",
            "80",
            s(images[0]),
            s(images[1]),
            "--depth",
            s(&depth),
            s(&depth),
            "--out",
            s(&out),
            "--seed",
            "3",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (
            pixels(&out.join("street.png")),
            pixels(&out.join("other.png")),
        )
    };
    let (street_first, other_second) = run([&image, &other], "a");
    let (street_second, other_first) = run([&other, &image], "b");
    assert_eq!(street_first, street_second, "street.png keeps its drops");
    assert_eq!(other_first, other_second, "other.png keeps its drops");
    assert_ne!(street_first, other_first, "two names, two drop fields");
}

#[test]
fn two_images_with_the_same_file_name_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (image, depth) = setup(dir.path());
    let twin_dir = dir.path().join("twin");
    std::fs::create_dir_all(&twin_dir).unwrap();
    let twin = twin_dir.join("street.png");
    std::fs::copy(&image, &twin).unwrap();
    let out = dir.path().join("out");
    let o = murk(&[
        "rain",
        "--rate",
        "10",
        s(&image),
        s(&twin),
        "--depth",
        s(&depth),
        s(&depth),
        "--out",
        s(&out),
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("same file name"), "{e}");
}
