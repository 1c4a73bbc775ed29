//! CycleGAN weather generators run through ONNX (D3.3 §2, seed 003 §3.2):
//! a clear image in, the foggy / rainy / snowy translation out.
//!
//! The generators are pytorch-CycleGAN-and-pix2pix `resnet_9blocks`
//! (instance norm, reflect padding, 3→3 channels, tanh output) exported to
//! ONNX with a dynamic height and width (`scripts/pth_to_onnx.py` turns a
//! `latest_net_G_A.pth` into one). [`GeneratorParams`] →
//! [`GeneratorParams::load`] → [`Generator`];
//! [`Generator::translate`] maps an [`RgbImage`] to an image of the same
//! size.
//!
//! **Pre- and post-processing are the training code's test mode:** RGB
//! bytes `x` → `x / 127.5 − 1` (its `ToTensor` + `Normalize(0.5, 0.5)`), NCHW
//! `f32`, batch 1; the tanh output `y` → `(y + 1) / 2 · 255`, **rounded** and
//! clamped to `0..=255` ([`preprocess`], [`postprocess`]). The training
//! code's `tensor2im` truncates instead of rounding (`astype(uint8)`), which
//! darkens every channel by half a level on average; murk rounds.
//!
//! **Full resolution, reflect-padded to multiples of 4** (the network's two
//! stride-2 convolutions need them), cropped back afterwards, so the output
//! has the input's size and its pixels are the network's, not a resampling.
//! Why not the alternatives:
//! - *tiling* would change the result: instance norm normalises every
//!   feature map by its statistics over the whole image, so each tile would
//!   be normalised differently and seams would show. The network is fully
//!   convolutional and a whole 1600×900 image fits in memory (ngf 64: the
//!   largest activations are 64 × 1600 × 900 `f32`, 0.37 GB), so tiling buys
//!   nothing;
//! - *resizing to multiples of 4* (the training code's `--preprocess none`
//!   rounds the size by a bicubic resize) resamples every pixel for a change
//!   of at most 3 rows and columns; padding at the bottom and right edges
//!   with the image's mirror, as the network's own `ReflectionPad2d` does,
//!   leaves the image's pixels untouched.
//!
//! A generator trained at a lower resolution (the rain paper's 448×256)
//! sees its features at another scale on a full-size image; for that case
//! [`GeneratorParams::work_size`] runs the network at a given size (bicubic
//! resize, as the training code loads images) and resizes the output back
//! to the input's size, which is the paper's GAN+PBR recipe (§3.3:
//! "upsampling the output of the GAN to the image original size").
//!
//! **Backends** (cargo features of murk-infer, exactly one):
//! - `tract` (default): [`ort`] over the pure-Rust tract engine
//!   (`ort-tract`); nothing to install, single-threaded;
//! - `native`: ONNX Runtime's own shared library, loaded at run time (ort's
//!   `load-dynamic`), faster and multi-threaded. Build with
//!   `cargo build --release -p murk-cli --no-default-features --features native`,
//!   get the library from PyPI (`pip install "onnxruntime>=1.24"`, it is
//!   `onnxruntime/capi/libonnxruntime.so.1.*`), and point
//!   [`GeneratorParams::ort_lib`] (the CLI's `--ort-lib`) or `ORT_DYLIB_PATH`
//!   at it.
//!
//! The tests (`tests/camera_gan.rs`) run on either backend; a `native` build
//! needs `ORT_DYLIB_PATH` set for them.
//!
//! Both cannot live in one build: the tract backend replaces ort's API table
//! for the whole process (ort's `alternative-backend`), and choosing the
//! native library at run time next to it would need murk to fetch that table
//! from the loaded library itself, i.e. `unsafe` FFI, which murk does not
//! write.
//!
//! ```
//! use image::{Rgb, RgbImage};
//! use murk_infer::camera::{GeneratorParams, padded_size};
//!
//! // The repository's tiny test generator (ngf 4, 2 residual blocks).
//! let model = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/gan/tiny_generator.onnx");
//! let mut generator = GeneratorParams::new().load(model.as_ref())?;
//! let clear = RgbImage::from_pixel(50, 38, Rgb([90, 120, 160]));
//! let translated = generator.translate(&clear)?;
//! assert_eq!(translated.dimensions(), (50, 38)); // run at 52×40, cropped back
//! assert_eq!(padded_size(50, 38), (52, 40));
//! # Ok::<(), murk_infer::InferError>(())
//! ```

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use image::RgbImage;
use image::imageops::{FilterType, resize};
use ort::session::Session;
use ort::session::builder::GraphOptimizationLevel;
use ort::value::Tensor;

use crate::error::InferError;

#[cfg(all(feature = "tract", feature = "native"))]
compile_error!(
    "murk-infer: the features `tract` and `native` exclude each other (ort's API table is either tract's or the \
     native library's); build with `--no-default-features --features native` for the native ONNX Runtime"
);

/// The smallest image side the generator accepts: after two stride-2
/// convolutions the residual blocks' 1-pixel reflect padding needs 2 pixels.
pub const MIN_SIDE: u32 = 8;

/// Which ONNX backend this build runs generators on.
pub fn backend() -> &'static str {
    if cfg!(feature = "native") {
        "ONNX Runtime (native library)"
    } else {
        "tract (pure Rust)"
    }
}

/// Height and width the network runs at for an image of `width × height`:
/// each rounded up to a multiple of 4.
pub fn padded_size(width: u32, height: u32) -> (u32, u32) {
    (width.div_ceil(4) * 4, height.div_ceil(4) * 4)
}

/// A 3-channel planar (NCHW, batch 1) `f32` image: what the generator reads
/// and writes.
#[derive(Debug, Clone, PartialEq)]
pub struct Planar {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// `3 × height × width` values, channel-major (R plane, G plane, B plane).
    pub data: Vec<f32>,
}

/// Index in `0..n` of position `i` in `0..n + pad` when the row or column is
/// extended past its end by its mirror image without repeating the edge
/// (`…, n-2, n-1, n-2, n-3, …`, as `ReflectionPad2d` / ONNX `Pad` reflect).
fn reflect(i: usize, n: usize) -> usize {
    if i < n { i } else { 2 * (n - 1) - i }
}

/// RGB bytes → the network's input: `x / 127.5 − 1` per channel, planar,
/// reflect-padded at the bottom and right to [`padded_size`].
///
/// Needs sides of at least [`MIN_SIDE`] pixels (checked by
/// [`Generator::translate`]; here a side below 4 panics on the reflection).
pub fn preprocess(img: &RgbImage) -> Planar {
    let (w, h) = img.dimensions();
    let (pw, ph) = padded_size(w, h);
    let (w, h, pw, ph) = (w as usize, h as usize, pw as usize, ph as usize);
    let raw = img.as_raw();
    let mut data = vec![0.0f32; 3 * pw * ph];
    let plane = pw * ph;
    for y in 0..ph {
        let sy = reflect(y, h);
        for x in 0..pw {
            let sx = reflect(x, w);
            let px = &raw[3 * (sy * w + sx)..3 * (sy * w + sx) + 3];
            for (c, &v) in px.iter().enumerate() {
                data[c * plane + y * pw + x] = f32::from(v) / 127.5 - 1.0;
            }
        }
    }
    Planar {
        width: pw as u32,
        height: ph as u32,
        data,
    }
}

/// The network's tanh output → RGB bytes: the top-left `width × height`
/// crop, `(y + 1) / 2 · 255` rounded (half away from zero) and clamped to
/// `0..=255`.
///
/// Returns the first non-finite value's position (x, y, channel) as an
/// error instead of writing it.
pub fn postprocess(out: &Planar, width: u32, height: u32) -> Result<RgbImage, (u32, u32, usize)> {
    let (pw, plane) = (out.width as usize, (out.width * out.height) as usize);
    let mut img = RgbImage::new(width, height);
    for (x, y, px) in img.enumerate_pixels_mut() {
        for c in 0..3 {
            let v = out.data[c * plane + y as usize * pw + x as usize];
            if !v.is_finite() {
                return Err((x, y, c));
            }
            px.0[c] = ((v + 1.0) * 127.5).round().clamp(0.0, 255.0) as u8;
        }
    }
    Ok(img)
}

/// Settings of a generator: the size it runs at and, for the native
/// backend, where the ONNX Runtime library is.
#[derive(Debug, Clone, Default)]
pub struct GeneratorParams {
    work_size: Option<(u32, u32)>,
    ort_lib: Option<PathBuf>,
    threads: Option<usize>,
}

impl GeneratorParams {
    /// Full resolution (reflect-padded to multiples of 4), the backend's
    /// default library and threads.
    pub fn new() -> Self {
        Self::default()
    }

    /// Runs the network at `width × height` (bicubic resize in and back
    /// out) instead of at the image's own size; both at least
    /// [`MIN_SIDE`].
    pub fn work_size(mut self, width: u32, height: u32) -> Self {
        self.work_size = Some((width, height));
        self
    }

    /// The ONNX Runtime shared library (`libonnxruntime.so.1.*`, ≥ 1.24) for
    /// the `native` backend; without it `ORT_DYLIB_PATH`, then the system's
    /// `libonnxruntime.so`. The library is loaded once per process, by the
    /// first generator loaded. A build with the `tract` backend refuses it.
    pub fn ort_lib(mut self, path: impl Into<PathBuf>) -> Self {
        self.ort_lib = Some(path.into());
        self
    }

    /// Intra-op threads of the native backend (its default: all cores).
    /// tract runs on one thread whatever this says.
    pub fn threads(mut self, threads: usize) -> Self {
        self.threads = Some(threads);
        self
    }

    /// Loads the generator at `path` and checks that it has one
    /// 4-dimensional 3-channel `f32` input and output.
    pub fn load(&self, path: &Path) -> Result<Generator, InferError> {
        let fail = |reason: String| InferError::Generator {
            path: path.to_path_buf(),
            reason,
        };
        if let Some((w, h)) = self.work_size
            && (w < MIN_SIDE || h < MIN_SIDE)
        {
            return Err(InferError::InvalidParam {
                name: "work_size",
                value: format!("{w}x{h}"),
                reason: format!("both sides must be at least {MIN_SIDE} pixels"),
            });
        }
        if self.threads == Some(0) {
            return Err(InferError::InvalidParam {
                name: "threads",
                value: "0".into(),
                reason: "at least 1".into(),
            });
        }
        if !path.is_file() {
            return Err(fail("no such file".into()));
        }
        let environment = self.environment()?;
        let mut builder = Session::builder(&environment)
            .and_then(|b| Ok(b.with_optimization_level(GraphOptimizationLevel::Level3)?))
            .map_err(|e| fail(format!("cannot set up a session: {e}")))?;
        if let Some(n) = self.threads.filter(|_| cfg!(feature = "native")) {
            builder = builder
                .with_intra_threads(n)
                .map_err(|e| fail(format!("cannot set {n} threads: {e}")))?;
        }
        let session = builder
            .commit_from_file(path)
            .map_err(|e| fail(format!("not a usable ONNX model: {e}")))?;
        let (inputs, outputs) = (session.inputs(), session.outputs());
        if inputs.len() != 1 || outputs.len() != 1 {
            return Err(fail(format!(
                "has {} inputs and {} outputs; a generator has one image in and one out",
                inputs.len(),
                outputs.len()
            )));
        }
        for (what, outlet) in [("input", &inputs[0]), ("output", &outputs[0])] {
            let ty = outlet.dtype();
            if ty.tensor_type() != Some(ort::value::TensorElementType::Float32) {
                return Err(fail(format!(
                    "{what} `{}` is {ty}, expected a float32 tensor",
                    outlet.name()
                )));
            }
            if let Some(shape) = ty.tensor_shape() {
                let dims: &[i64] = shape;
                let bad_batch = dims.first().is_some_and(|&b| b > 1);
                if dims.len() != 4 || bad_batch || dims[1] > 0 && dims[1] != 3 {
                    return Err(fail(format!(
                        "{what} `{}` has shape {dims:?}; expected [1, 3, H, W] (an RGB generator, batch 1)",
                        outlet.name()
                    )));
                }
            }
        }
        let input_name = inputs[0].name().to_string();
        let output_name = outputs[0].name().to_string();
        Ok(Generator {
            session,
            _environment: environment,
            path: path.to_path_buf(),
            input_name,
            output_name,
            work_size: self.work_size,
        })
    }

    /// The process's ONNX environment: ort allows one per process, so the
    /// first generator loaded creates it (and, on the native backend, loads
    /// the library it names) and later ones share it.
    fn environment(&self) -> Result<ort::environment::Environment, InferError> {
        static ENVIRONMENT: Mutex<Option<ort::environment::Environment>> = Mutex::new(None);
        #[cfg(feature = "tract")]
        if let Some(lib) = &self.ort_lib {
            return Err(InferError::Generator {
                path: lib.clone(),
                reason: "this murk runs generators on the pure-Rust tract backend; a native ONNX Runtime \
                         library needs a build with `--no-default-features --features native`"
                    .into(),
            });
        }
        let mut env = ENVIRONMENT
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        if let Some(e) = env.as_ref() {
            return Ok(e.clone());
        }
        let e = self.new_environment()?;
        *env = Some(e.clone());
        Ok(e)
    }

    #[cfg(feature = "tract")]
    fn new_environment(&self) -> Result<ort::environment::Environment, InferError> {
        // Installs tract's API table for the process (a no-op if set).
        ort::set_api(ort_tract::api());
        ort::init().build().map_err(|e| InferError::Generator {
            path: PathBuf::from("<tract>"),
            reason: format!("cannot start the tract backend: {e}"),
        })
    }

    #[cfg(all(feature = "native", not(feature = "tract")))]
    fn new_environment(&self) -> Result<ort::environment::Environment, InferError> {
        let lib = self
            .ort_lib
            .clone()
            .or_else(|| {
                std::env::var_os("ORT_DYLIB_PATH")
                    .filter(|s| !s.is_empty())
                    .map(PathBuf::from)
            })
            .unwrap_or_else(|| PathBuf::from("libonnxruntime.so"));
        let fail = |reason: String| InferError::Generator {
            path: lib.clone(),
            reason,
        };
        ort::init_from(&lib)
            .map_err(|e| {
                fail(format!(
                    "cannot load the ONNX Runtime library ({e}); `pip install \"onnxruntime>=1.24\"` and pass \
                     --ort-lib …/site-packages/onnxruntime/capi/libonnxruntime.so.1.* (or set ORT_DYLIB_PATH)"
                ))
            })?
            .build()
            .map_err(|e| fail(format!("cannot start ONNX Runtime: {e}")))
    }
}

/// Where a translation's time went.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TranslateTimes {
    /// Resizing (with a work size), scaling and padding the input.
    pub pre: Duration,
    /// The ONNX session run.
    pub run: Duration,
    /// Cropping, scaling and rounding the output (and resizing it back).
    pub post: Duration,
}

impl TranslateTimes {
    /// Share of the total spent outside the session run.
    pub fn outside_share(&self) -> f64 {
        let outside = (self.pre + self.post).as_secs_f64();
        let total = outside + self.run.as_secs_f64();
        if total > 0.0 { outside / total } else { 0.0 }
    }
}

impl std::ops::AddAssign for TranslateTimes {
    fn add_assign(&mut self, other: Self) {
        self.pre += other.pre;
        self.run += other.run;
        self.post += other.post;
    }
}

/// A loaded generator ([`GeneratorParams::load`]).
pub struct Generator {
    session: Session,
    // Kept alive for the session's sake.
    _environment: ort::environment::Environment,
    path: PathBuf,
    input_name: String,
    output_name: String,
    work_size: Option<(u32, u32)>,
}

impl std::fmt::Debug for Generator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Generator")
            .field("path", &self.path)
            .field("input", &self.input_name)
            .field("output", &self.output_name)
            .field("work_size", &self.work_size)
            .field("backend", &backend())
            .finish()
    }
}

impl Generator {
    /// Loads `path` with default settings ([`GeneratorParams::new`]).
    pub fn load(path: &Path) -> Result<Self, InferError> {
        GeneratorParams::new().load(path)
    }

    /// The model file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Translates `img`; the output has `img`'s size.
    pub fn translate(&mut self, img: &RgbImage) -> Result<RgbImage, InferError> {
        self.translate_timed(img).map(|(out, _)| out)
    }

    /// [`Generator::translate`], also saying where the time went.
    pub fn translate_timed(
        &mut self,
        img: &RgbImage,
    ) -> Result<(RgbImage, TranslateTimes), InferError> {
        let (w, h) = img.dimensions();
        let t0 = Instant::now();
        let (rw, rh) = self.work_size.unwrap_or((w, h));
        if w < MIN_SIDE || h < MIN_SIDE {
            return Err(InferError::Generator {
                path: self.path.clone(),
                reason: format!(
                    "image is {w}x{h}; the generator needs at least {MIN_SIDE}x{MIN_SIDE} pixels"
                ),
            });
        }
        let resized;
        let work = if (rw, rh) == (w, h) {
            img
        } else {
            resized = resize(img, rw, rh, FilterType::CatmullRom);
            &resized
        };
        let input = preprocess(work);
        let t1 = Instant::now();
        let output = self.run(input)?;
        let t2 = Instant::now();
        let mut out = postprocess(&output, rw, rh).map_err(|(x, y, c)| InferError::Generator {
            path: self.path.clone(),
            reason: format!("output is not finite at pixel (x {x}, y {y}), channel {c}"),
        })?;
        if (rw, rh) != (w, h) {
            out = resize(&out, w, h, FilterType::CatmullRom);
        }
        let t3 = Instant::now();
        Ok((
            out,
            TranslateTimes {
                pre: t1 - t0,
                run: t2 - t1,
                post: t3 - t2,
            },
        ))
    }

    /// Runs the network on a planar input (values in [-1, 1], sides
    /// multiples of 4) and returns its planar output, checked to have the
    /// input's size.
    pub fn run(&mut self, input: Planar) -> Result<Planar, InferError> {
        let fail = |reason: String| InferError::Generator {
            path: self.path.clone(),
            reason,
        };
        let (w, h) = (input.width, input.height);
        if input.data.len() != 3 * (w * h) as usize {
            return Err(fail(format!(
                "planar input of {w}x{h} has {} values, expected {}",
                input.data.len(),
                3 * w * h
            )));
        }
        let tensor = Tensor::from_array((
            [1usize, 3, h as usize, w as usize],
            input.data.into_boxed_slice(),
        ))
        .map_err(|e| fail(format!("cannot make the input tensor: {e}")))?;
        let outputs = self
            .session
            .run(ort::inputs![self.input_name.as_str() => tensor])
            .map_err(|e| fail(format!("run on a {w}x{h} input failed: {e}")))?;
        let value = outputs
            .get(&self.output_name)
            .ok_or_else(|| fail(format!("the run returned no `{}`", self.output_name)))?;
        let (shape, data) = value.try_extract_tensor::<f32>().map_err(|e| {
            fail(format!(
                "output `{}` is not a float32 tensor: {e}",
                self.output_name
            ))
        })?;
        let dims: &[i64] = shape;
        if dims != [1, 3, i64::from(h), i64::from(w)] {
            return Err(fail(format!(
                "output shape {dims:?} for a {w}x{h} input; expected [1, 3, {h}, {w}] (a generator keeps the size)"
            )));
        }
        Ok(Planar {
            width: w,
            height: h,
            data: data.to_vec(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;

    #[test]
    fn padded_size_rounds_up_to_multiples_of_four() {
        assert_eq!(padded_size(8, 8), (8, 8));
        assert_eq!(padded_size(50, 38), (52, 40));
        assert_eq!(padded_size(1242, 375), (1244, 376));
        assert_eq!(padded_size(1600, 900), (1600, 900));
        assert_eq!(padded_size(9, 13), (12, 16));
    }

    #[test]
    fn reflect_mirrors_without_repeating_the_edge() {
        // n = 5: 0 1 2 3 4 | 3 2 1
        let got: Vec<usize> = (0..8).map(|i| reflect(i, 5)).collect();
        assert_eq!(got, vec![0, 1, 2, 3, 4, 3, 2, 1]);
    }

    #[test]
    fn preprocess_known_answers() {
        // 5×4 image: pixel (x, y) = (10x + y, 0, 255); padded to 8×4.
        let img = RgbImage::from_fn(5, 4, |x, y| Rgb([(10 * x + y) as u8, 0, 255]));
        let p = preprocess(&img);
        assert_eq!((p.width, p.height, p.data.len()), (8, 4, 3 * 8 * 4));
        let at = |c: usize, x: usize, y: usize| p.data[c * 32 + y * 8 + x];
        // 0 → -1, 255 → +1 exactly; 127.5 would be 0.
        assert_eq!(at(1, 0, 0), -1.0);
        assert_eq!(at(2, 3, 2), 1.0);
        // R of (2, 1) = 21 → 21/127.5 - 1.
        assert_eq!(at(0, 2, 1), 21.0 / 127.5 - 1.0);
        // Padded columns 5, 6, 7 mirror columns 3, 2, 1.
        for y in 0..4 {
            for (px, src) in [(5, 3), (6, 2), (7, 1)] {
                assert_eq!(at(0, px, y), at(0, src, y), "column {px} row {y}");
            }
        }
    }

    #[test]
    fn preprocess_pads_rows_by_reflection_too() {
        let img = RgbImage::from_fn(8, 9, |_, y| Rgb([y as u8 * 20, 0, 0]));
        let p = preprocess(&img);
        assert_eq!((p.width, p.height), (8, 12));
        // Rows 9, 10, 11 mirror rows 7, 6, 5.
        for (row, src) in [(9, 7), (10, 6), (11, 5)] {
            assert_eq!(p.data[row * 8], f32::from(src as u8 * 20) / 127.5 - 1.0);
        }
    }

    #[test]
    fn postprocess_known_answers() {
        // 4×4 planar output cropped to 3×2.
        let mut data = vec![0.0f32; 3 * 16];
        data[0] = -1.0; // R (0,0) → 0
        data[1] = 1.0; // R (1,0) → 255
        data[2] = 0.0; // R (2,0) → 127.5 → 128 (half away from zero)
        data[4] = -1.5; // R (0,1) → clamped to 0
        data[5] = 2.0; // R (1,1) → clamped to 255
        data[16 + 6] = 0.5; // G (2,1) → 191.25 → 191
        data[32 + 4 + 2] = -0.6; // B (2,1) → 51.0 → 51
        data[3] = f32::NAN; // column 3 is cropped away
        let out = Planar {
            width: 4,
            height: 4,
            data,
        };
        let img = postprocess(&out, 3, 2).expect("finite");
        assert_eq!(img.dimensions(), (3, 2));
        assert_eq!(img.get_pixel(0, 0).0, [0, 128, 128]);
        assert_eq!(img.get_pixel(1, 0).0, [255, 128, 128]);
        assert_eq!(img.get_pixel(2, 0).0[0], 128);
        assert_eq!(img.get_pixel(0, 1).0[0], 0);
        assert_eq!(img.get_pixel(1, 1).0[0], 255);
        assert_eq!(img.get_pixel(2, 1).0, [128, 191, 51]);
    }

    #[test]
    fn postprocess_reports_non_finite_values() {
        let mut data = vec![0.0f32; 3 * 64];
        data[64 + 8 * 2 + 5] = f32::INFINITY; // G at (5, 2)
        let out = Planar {
            width: 8,
            height: 8,
            data,
        };
        assert_eq!(postprocess(&out, 8, 8), Err((5, 2, 1)));
    }

    #[test]
    fn pre_then_post_is_the_identity_on_bytes() {
        let img = RgbImage::from_fn(13, 9, |x, y| {
            Rgb([(x * 19 + y) as u8, (y * 27) as u8, (x * y) as u8])
        });
        let p = preprocess(&img);
        assert_eq!(postprocess(&p, 13, 9).expect("finite"), img);
    }
}
