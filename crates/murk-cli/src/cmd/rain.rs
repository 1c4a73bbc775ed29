//! `murk rain`: physics-based rain on camera images (seed 003 §3.1), and
//! with `--generator G.onnx` the GAN+PBR hybrid of seed 003 §3.3: each
//! image is first translated by the generator (as `murk camera` does), then
//! the rain layer is rendered on the translation with the image's depth.
//!
//! Glue only: flags → a checked [`murk_infer::camera::RainParams`] → one
//! render per image with its depth (a 16-bit depth PNG, or a LiDAR scan
//! projected through a KITTI calibration) → an atomic write under `--out`
//! with the input's file name. Each image gets its own seed, derived from
//! `--seed` and the image's file name (its output name) by murk's one
//! derivation ([`murk_types::seed::derive`]), so an image gets the same
//! drops wherever it stands in the list and a batch is reproducible.
//!
//! ```text
//! murk rain --rate 50 kitti-000008.png --lidar kitti-000008.bin \
//!           --calib kitti-000008-calib.txt --out rainy/
//! murk rain --rate 50 --generator clear2rain.onnx --work-size 448x256 \
//!           nuscenes.jpg --depth nuscenes-depth.png --out hybrid/
//! ```

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use murk_infer::camera::{Densify, DepthMap, KittiCalib, RainParams, read_rgb, write_rgb_atomic};
use murk_io::{ReadOptions, read_cloud};
use murk_types::seed::{Purpose, derive};

/// Arguments of `murk rain`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Rainfall rate, mm/h (0 leaves the images unchanged).
    #[arg(long)]
    pub rate: f64,
    /// Images (PNG or JPEG).
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
    /// Output folder (created; file names are kept).
    #[arg(long)]
    pub out: PathBuf,
    /// Dense depth per image: 16-bit grayscale PNGs, one per image, in order
    /// (0 = no measurement, filled from neighbours).
    #[arg(long, num_args = 1.., conflicts_with = "lidar")]
    pub depth: Vec<PathBuf>,
    /// Metres per unit of the depth PNGs (KITTI's depth maps: 1/256).
    #[arg(long, default_value_t = 1.0 / 256.0)]
    pub depth_scale: f32,
    /// LiDAR scans, one per image, projected for depth (needs --calib).
    #[arg(long, num_args = 1.., requires = "calib")]
    pub lidar: Vec<PathBuf>,
    /// KITTI calibration files (P2, R0_rect, Tr_velo_to_cam): one for all
    /// images or one per image. Also gives the camera intrinsics.
    #[arg(long, num_args = 1..)]
    pub calib: Vec<PathBuf>,
    /// Exposure time, seconds.
    #[arg(long, default_value_t = 0.005)]
    pub exposure: f64,
    /// Ego speed along the optical axis, m/s.
    #[arg(long, default_value_t = 0.0)]
    pub ego_speed: f64,
    /// Seed of the drops (each image uses a seed derived from this and its
    /// file name).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// GAN+PBR: translate each image with this ONNX generator first (see
    /// `murk camera`), then render the rain on the translation.
    #[arg(long)]
    pub generator: Option<PathBuf>,
    #[command(flatten)]
    pub gen_opts: super::camera::GeneratorOpts,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Runs `murk rain`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let n = args.images.len();
    if !args.depth.is_empty() && args.depth.len() != n {
        bail!(
            "{} images but {} --depth files: give one per image",
            n,
            args.depth.len()
        );
    }
    if !args.lidar.is_empty() && args.lidar.len() != n {
        bail!(
            "{} images but {} --lidar scans: give one per image",
            n,
            args.lidar.len()
        );
    }
    if args.depth.is_empty() && args.lidar.is_empty() {
        bail!("no depth: give --depth PNGs or --lidar scans with --calib");
    }
    if !args.calib.is_empty() && args.calib.len() != 1 && args.calib.len() != n {
        bail!(
            "{} --calib files for {} images: give one for all or one per image",
            args.calib.len(),
            n
        );
    }
    let mut names = std::collections::BTreeMap::new();
    for img in &args.images {
        if let Some(name) = img.file_name()
            && let Some(first) = names.insert(name, img)
        {
            bail!(
                "{} and {} have the same file name: outputs are named after their input (and seeded by that name), so one would overwrite the other",
                first.display(),
                img.display()
            );
        }
    }
    if let Ok(out) = args.out.canonicalize() {
        for img in &args.images {
            let dir = img
                .canonicalize()
                .ok()
                .and_then(|p| p.parent().map(|d| d.to_path_buf()));
            if dir.as_ref() == Some(&out) {
                bail!(
                    "{}: the output folder is the image's own folder; choose another --out",
                    img.display()
                );
            }
        }
    }
    let mut generator = args
        .generator
        .as_deref()
        .map(|g| args.gen_opts.load(g))
        .transpose()?;
    let calibs: Vec<KittiCalib> = args
        .calib
        .iter()
        .map(|p| KittiCalib::from_file(p))
        .collect::<Result<_, _>>()?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("{}: cannot create the output folder", args.out.display()))?;
    let base = RainParams::new(args.rate)
        .exposure_s(args.exposure)
        .ego_speed_m_s(args.ego_speed);
    let bar = super::progress_bar(n, "images", args.quiet);
    let (mut streaks, mut covered) = (0u64, 0.0f64);
    let started = std::time::Instant::now();
    for (i, path) in args.images.iter().enumerate() {
        let mut image = read_rgb(path)?;
        if let Some(g) = generator.as_mut() {
            image = g.translate(&image)?;
        }
        let (w, h) = image.dimensions();
        let calib = calibs.get(i).or(calibs.first());
        let depth = if let Some(d) = args.depth.get(i) {
            DepthMap::from_png16(d, args.depth_scale, &Densify::default())?
        } else {
            let scan = &args.lidar[i];
            let cloud = read_cloud(scan, &ReadOptions::default())?;
            let calib = calib.context("--lidar needs --calib")?;
            DepthMap::from_lidar(
                &cloud,
                calib,
                w,
                h,
                &Densify::default(),
                &scan.display().to_string(),
            )?
        };
        let name = path
            .file_name()
            .with_context(|| format!("{}: not a file", path.display()))?;
        let key = name.to_string_lossy();
        let seed = derive(args.seed, &key, Purpose::RainImage).to_u64();
        let mut params = base.clone().seed(seed);
        if let Some(c) = calib {
            params = params.intrinsics(c.intrinsics());
        }
        let (rainy, stats) = params.check()?.render_with_stats(&image, &depth)?;
        write_rgb_atomic(&args.out.join(name), &rainy)?;
        streaks += stats.streaks as u64;
        covered += stats.covered_share;
        bar.inc(1);
    }
    bar.finish_and_clear();
    outln!(
        "{n} image{} at {} mm/h{} → {} in {:.2} s: {streaks} streaks, {:.2} % of pixels covered on average",
        if n == 1 { "" } else { "s" },
        args.rate,
        args.generator
            .as_ref()
            .map(|g| format!(" on the translations of {}", g.display()))
            .unwrap_or_default(),
        args.out.display(),
        started.elapsed().as_secs_f64(),
        100.0 * covered / n.max(1) as f64
    );
    Ok(())
}
