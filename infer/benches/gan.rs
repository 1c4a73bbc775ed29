//! Speed of ONNX generators (`murk_infer::camera::gan`): images per second
//! at 256×256 and at nuScenes size 1600×900, and the share of time spent
//! outside the session run (pre- and post-processing).
//!
//! Per size three timings: `translate` (the whole call: scale, reflect-pad,
//! run, crop, round), `run` (the session alone, on a prepared input) and
//! `pre_post` (scale + pad + crop + round alone); the share outside the run
//! is `pre_post / translate`.
//!
//! Models: the committed tiny generator (ngf 4, 2 residual blocks) always;
//! a full-size resnet_9blocks ngf 64 (random weights, ~45 MB, not committed)
//! when `MURK_GAN_MODEL` names it, at 256×256 only (a 1600×900 image takes
//! tens of seconds on tract; time it with `murk camera`, which prints
//! images/s and the share outside the run):
//!
//! ```text
//! python3 scripts/make_test_generator.py --full /tmp/resnet9_ngf64.onnx
//! MURK_GAN_MODEL=/tmp/resnet9_ngf64.onnx cargo bench -p murk-infer --bench gan
//! ```
//!
//! The default build runs tract (pure Rust, one thread).

#[cfg(not(any(feature = "tract", feature = "native")))]
fn main() {
    eprintln!("gan bench: murk-infer was built without an ONNX backend (feature tract or native)");
}

#[cfg(any(feature = "tract", feature = "native"))]
criterion::criterion_main!(with_backend::benches);

#[cfg(any(feature = "tract", feature = "native"))]
mod with_backend {
    use std::hint::black_box;
    use std::path::{Path, PathBuf};

    use criterion::{BenchmarkId, Criterion, Throughput, criterion_group};
    use image::{Rgb, RgbImage};
    use murk_infer::camera::{Generator, postprocess, preprocess};

    fn street(w: u32, h: u32) -> RgbImage {
        RgbImage::from_fn(w, h, |x, y| {
            if y < h / 3 {
                Rgb([200, 210, 230])
            } else {
                let v = 70 + ((x * 7 + y * 3) % 30) as u8;
                Rgb([v, v + (x % 40) as u8, v + 5])
            }
        })
    }

    fn bench_model(c: &mut Criterion, label: &str, model: &Path, sizes: &[(u32, u32)]) {
        let mut generator = Generator::load(model).expect("generator loads");
        let mut g = c.benchmark_group(format!("gan_{label}"));
        g.sample_size(10);
        g.throughput(Throughput::Elements(1)); // elements = images
        for &(w, h) in sizes {
            let img = street(w, h);
            let id = format!("{w}x{h}");
            g.bench_function(BenchmarkId::new("translate", &id), |b| {
                b.iter(|| generator.translate(black_box(&img)).expect("translate"))
            });
            let input = preprocess(&img);
            g.bench_function(BenchmarkId::new("run", &id), |b| {
                b.iter(|| generator.run(black_box(input.clone())).expect("run"))
            });
            let output = generator.run(input.clone()).expect("run");
            g.bench_function(BenchmarkId::new("pre_post", &id), |b| {
                b.iter(|| {
                    let p = preprocess(black_box(&img));
                    black_box(p);
                    postprocess(black_box(&output), w, h).expect("finite")
                })
            });
        }
        g.finish();
    }

    fn bench(c: &mut Criterion) {
        let tiny = PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/gan/tiny_generator.onnx"
        ));
        bench_model(c, "tiny", &tiny, &[(256, 256), (1600, 900)]);
        match std::env::var_os("MURK_GAN_MODEL") {
            Some(p) => bench_model(c, "resnet9_ngf64", &PathBuf::from(p), &[(256, 256)]),
            None => eprintln!(
                "gan bench: MURK_GAN_MODEL not set, skipping the full-size generator \
             (python3 scripts/make_test_generator.py --full /tmp/resnet9_ngf64.onnx)"
            ),
        }
    }

    criterion_group!(benches, bench);
}
