//! ONNX CycleGAN generators (`murk_infer::camera::gan`) against the
//! independent references of `scripts/make_test_generator.py`: a tiny
//! resnet generator (ngf 4, 2 residual blocks, same op set as
//! resnet_9blocks) exported by `scripts/pth_to_onnx.py` from a torch-format
//! checkpoint, and its outputs from a float64 numpy forward pass (checked in
//! the script against Python onnxruntime to 1e-4, and checked there to move
//! by far more than that when one weight is perturbed). No Python is needed
//! here: the model and the references are committed in `tests/data/gan/`.

#![cfg(any(feature = "tract", feature = "native"))]

use std::path::{Path, PathBuf};

use image::{Rgb, RgbImage};
use murk_infer::InferError;
use murk_infer::camera::{Generator, GeneratorParams, Planar, padded_size, preprocess};
use serde_json::Value;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/gan")
        .join(name)
}

fn reference() -> Value {
    serde_json::from_slice(&std::fs::read(data("reference.json")).unwrap()).unwrap()
}

fn rgb(name: &str) -> RgbImage {
    image::open(data(name)).unwrap().to_rgb8()
}

fn tiny() -> Generator {
    Generator::load(&data("tiny_generator.onnx")).expect("the tiny generator loads")
}

#[test]
fn network_output_matches_the_numpy_forward_pass_to_1e_4() {
    let meta = reference();
    let tol = meta["float_tolerance"].as_f64().unwrap() as f32;
    assert_eq!(tol, 1e-4);
    let odd = &meta["images"]["odd"];
    let img = rgb(odd["input"].as_str().unwrap());
    let input = preprocess(&img);
    assert_eq!(
        (input.width, input.height),
        (
            odd["padded_width"].as_u64().unwrap() as u32,
            odd["padded_height"].as_u64().unwrap() as u32
        )
    );
    let out = tiny().run(input).unwrap();
    let want: Vec<f32> = std::fs::read(data(odd["padded_output"].as_str().unwrap()))
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    assert_eq!(out.data.len(), want.len());
    let (worst, at) = out
        .data
        .iter()
        .zip(&want)
        .map(|(a, b)| (a - b).abs())
        .enumerate()
        .fold(
            (0.0f32, 0),
            |(m, i), (j, d)| if d > m { (d, j) } else { (m, i) },
        );
    eprintln!("max |murk - numpy| = {worst:e} over {} values", want.len());
    assert!(
        worst <= tol,
        "max |murk - numpy| = {worst:e} at value {at} (tolerance {tol:e})"
    );
    // The reference is not trivial: it spans the tanh range.
    let spread = want.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(spread > 0.9, "reference output only reaches {spread}");
}

/// Byte comparison: within 1 everywhere (a value within 1e-4 of a .5 step
/// may round either way) and at most 1 % of bytes off by one.
fn assert_close(got: &RgbImage, want: &RgbImage, what: &str) {
    assert_eq!(got.dimensions(), want.dimensions(), "{what}: size");
    let mut off = 0usize;
    for (i, (a, b)) in got.as_raw().iter().zip(want.as_raw()).enumerate() {
        let d = a.abs_diff(*b);
        assert!(d <= 1, "{what}: byte {i} is {a}, reference {b}");
        off += usize::from(d == 1);
    }
    let share = off as f64 / got.as_raw().len() as f64;
    assert!(
        share <= 0.01,
        "{what}: {:.2} % of bytes off by one",
        100.0 * share
    );
}

#[test]
fn translation_matches_the_reference_images_at_both_sizes() {
    let meta = reference();
    let mut g = tiny();
    for tag in ["odd", "even", "odd"] {
        let m = &meta["images"][tag];
        let input = rgb(m["input"].as_str().unwrap());
        let want = rgb(m["output"].as_str().unwrap());
        let got = g.translate(&input).unwrap();
        assert_close(&got, &want, tag);
        // Not the identity: the generator changes the picture a lot.
        let moved: f64 = got
            .as_raw()
            .iter()
            .zip(input.as_raw())
            .map(|(a, b)| f64::from(a.abs_diff(*b)))
            .sum::<f64>()
            / got.as_raw().len() as f64;
        assert!(moved > 20.0, "{tag}: mean change {moved}");
    }
}

#[test]
fn same_input_same_bytes_across_sizes_and_generators() {
    let img = rgb("input_odd.png");
    let mut g = tiny();
    let first = g.translate(&img).unwrap();
    let _ = g.translate(&rgb("input_even.png")).unwrap();
    assert_eq!(g.translate(&img).unwrap(), first);
    assert_eq!(tiny().translate(&img).unwrap(), first);
}

#[test]
fn translate_is_preprocess_run_crop_postprocess() {
    let img = rgb("input_odd.png");
    let mut g = tiny();
    let out = g.run(preprocess(&img)).unwrap();
    assert_eq!((out.width, out.height), padded_size(50, 38));
    let by_hand = murk_infer::camera::postprocess(&out, 50, 38).unwrap();
    let (translated, times) = g.translate_timed(&img).unwrap();
    assert_eq!(translated, by_hand);
    assert!(times.run > std::time::Duration::ZERO);
    assert!((0.0..1.0).contains(&times.outside_share()));
}

#[test]
fn work_size_runs_smaller_and_keeps_the_size() {
    let img = rgb("input_odd.png");
    let full = tiny().translate(&img).unwrap();
    // Its own size as work size: the same as full resolution.
    let same = GeneratorParams::new()
        .work_size(50, 38)
        .load(&data("tiny_generator.onnx"))
        .unwrap()
        .translate(&img)
        .unwrap();
    assert_eq!(same, full);
    let small = GeneratorParams::new()
        .work_size(24, 16)
        .load(&data("tiny_generator.onnx"))
        .unwrap()
        .translate(&img)
        .unwrap();
    assert_eq!(small.dimensions(), (50, 38));
    assert_ne!(small, full);
    let err = GeneratorParams::new()
        .work_size(6, 16)
        .load(&data("tiny_generator.onnx"))
        .unwrap_err();
    assert!(err.to_string().contains("at least 8"), "{err}");
}

fn load_err(path: &Path) -> String {
    let err = Generator::load(path).unwrap_err();
    assert!(matches!(err, InferError::Generator { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(
        msg.starts_with(&path.display().to_string()),
        "names the file: {msg}"
    );
    msg
}

#[test]
fn bad_models_are_refused_with_the_file_and_reason() {
    let missing = data("no-such-generator.onnx");
    assert!(load_err(&missing).contains("no such file"));
    let not_onnx = data("input_odd.png");
    assert!(load_err(&not_onnx).contains("not a usable ONNX model"));
    let gray = data("bad_gray.onnx");
    let msg = load_err(&gray);
    assert!(msg.contains("[1, 3, H, W]"), "{msg}");

    let mut shrinks = Generator::load(&data("bad_shrinks.onnx")).unwrap();
    let err = shrinks
        .translate(&RgbImage::from_pixel(16, 12, Rgb([1, 2, 3])))
        .unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("bad_shrinks.onnx"), "{msg}");
    assert!(msg.contains("output shape [1, 3, 6, 8]"), "{msg}");
}

#[test]
fn bad_inputs_are_refused() {
    let mut g = tiny();
    let err = g
        .translate(&RgbImage::from_pixel(7, 30, Rgb([0, 0, 0])))
        .unwrap_err();
    assert!(err.to_string().contains("image is 7x30"), "{err}");
    let err = g
        .run(Planar {
            width: 8,
            height: 8,
            data: vec![0.0; 10],
        })
        .unwrap_err();
    assert!(err.to_string().contains("has 10 values"), "{err}");
}

#[cfg(feature = "tract")]
#[test]
fn the_tract_build_refuses_a_native_library() {
    let err = GeneratorParams::new()
        .ort_lib("/opt/libonnxruntime.so")
        .load(&data("tiny_generator.onnx"))
        .unwrap_err();
    let msg = err.to_string();
    assert!(msg.starts_with("/opt/libonnxruntime.so: "), "{msg}");
    assert!(msg.contains("--features native"), "{msg}");
}
