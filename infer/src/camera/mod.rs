//! Camera weather: physics-based rain on images (seed 003 §3.1 and
//! appendices A–B: a rainfall rate in mm/h, an image and its depth in, the
//! rainy image out) and CycleGAN weather generators run through ONNX
//! (`gan`: D3.3 §2 fog/rain/snow translations; seed 003 §3.3's GAN+PBR
//! hybrid is a `Generator::translate` followed by
//! [`RainRenderer::render`]).
//!
//! Pieces, linfa style (checked parameters → a value that renders):
//!
//! - [`RainParams`] (rate, exposure, ego speed, intrinsics, lens, seed, …)
//!   checked once by [`RainParams::check`] into a [`RainRenderer`];
//!   [`RainRenderer::render`] turns an 8-bit [`image::RgbImage`] plus a
//!   [`DepthMap`] into the rainy image ([`RainRenderer::render_with_stats`]
//!   also says how many streaks were drawn and how much they cover);
//! - [`DepthMap`]: dense metres per pixel, from memory, a 16-bit PNG, or a
//!   LiDAR scan projected with a [`KittiCalib`] and densified by
//!   nearest-neighbour fill ([`Densify`]);
//! - [`read_rgb`] / [`write_rgb_atomic`]: image files in and out (atomic
//!   writes);
//! - `GeneratorParams` → `Generator` (module `gan`): an ONNX CycleGAN
//!   generator (pure-Rust tract backend by default, native ONNX Runtime
//!   with the `native` feature; built without either feature, murk-infer
//!   has no `gan` module and needs no ONNX crate), full resolution with
//!   reflect padding to multiples of 4;
//! - [`physics`]: the laws used (extinction, Marshall–Palmer, terminal
//!   velocity, drop oscillation), public so they can be checked.
//!
//! What follows the seed and what does not is written in the [`rain`],
//! [`photometry`], [`physics`] and [`depth`] module docs; in short: fog-like
//! extinction plus Henyey–Greenstein airlight, Marshall–Palmer drops ≥ 1 mm
//! that image on ≥ 1 pixel, streaks over the exposure with ego motion,
//! drop photometry `0.94·F̄ + 0.06·Ē` from an environment map estimated from
//! the image, defocus by the circle of confusion, the τ₁/T blending of eq. 5,
//! and the per-channel mean of the image restored. **The Garg–Nayar streak
//! database is not available, so streaks are parametric capsules** (width
//! from drop size and defocus, alpha from τ₁/T, a brightness ripple at the
//! drop's oscillation frequency).
//!
//! Images are 8-bit sRGB ([`image::RgbImage`]) in and out; the maths runs
//! on linear RGB in `f32`.
//!
//! ```
//! use image::{Rgb, RgbImage};
//! use murk_infer::camera::{DepthMap, RainParams};
//!
//! // A grey 160×90 street 20 m away under 50 mm/h of rain.
//! let img = RgbImage::from_pixel(160, 90, Rgb([120, 120, 120]));
//! let depth = DepthMap::constant(160, 90, 20.0)?;
//! let renderer = RainParams::new(50.0).seed(7).check()?;
//! let (rainy, stats) = renderer.render_with_stats(&img, &depth)?;
//! assert_eq!(rainy.dimensions(), (160, 90));
//! assert!(stats.streaks > 0);
//! // Same seed, same bytes.
//! assert_eq!(renderer.render(&img, &depth)?, rainy);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod calib;
pub mod depth;
#[cfg(any(feature = "tract", feature = "native"))]
pub mod gan;
pub mod io;
pub mod photometry;
pub mod physics;
pub mod rain;

pub use calib::{Intrinsics, KittiCalib};
pub use depth::{Densify, DepthMap};
#[cfg(any(feature = "tract", feature = "native"))]
pub use gan::{
    Generator, GeneratorParams, Planar, TranslateTimes, padded_size, postprocess, preprocess,
};
pub use io::{read_rgb, write_rgb_atomic};
pub use photometry::henyey_greenstein;
pub use rain::{RainParams, RainRenderer, RainStats};
