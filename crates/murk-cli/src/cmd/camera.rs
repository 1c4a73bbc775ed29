//! `murk camera`: run a CycleGAN weather generator (ONNX) over images.
//!
//! Glue only: flags → [`murk_infer::camera::GeneratorParams`] → one
//! translation per image → an atomic write under `--out` with the input's
//! file name. Arguments may be image files or folders (their `.png`,
//! `.jpg` and `.jpeg` files, sorted by name, not recursive).
//!
//! ```text
//! murk camera --generator fog_heavy.onnx clear/ extra.png --out foggy/
//! ```

use std::collections::BTreeMap;

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use murk_infer::camera::{Generator, GeneratorParams, TranslateTimes, read_rgb, write_rgb_atomic};

/// Arguments of `murk camera`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The generator: a CycleGAN resnet generator exported to ONNX
    /// (scripts/pth_to_onnx.py turns a latest_net_G_A.pth into one).
    #[arg(long)]
    pub generator: PathBuf,
    /// Images (PNG or JPEG) and folders of images.
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
    /// Output folder (created; file names are kept).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub gen_opts: GeneratorOpts,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Generator flags shared by `murk camera` and `murk rain --generator`.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct GeneratorOpts {
    /// Run the generator at WIDTHxHEIGHT (bicubic resize in and back out),
    /// e.g. its training size 448x256; default: the image's own size,
    /// reflect-padded to multiples of 4.
    #[arg(long, value_name = "WIDTHxHEIGHT", value_parser = parse_size)]
    pub work_size: Option<(u32, u32)>,
    /// ONNX Runtime library (libonnxruntime.so.1.*, >= 1.24, e.g. from
    /// `pip install onnxruntime`) for a murk built with `--features native`;
    /// default: $ORT_DYLIB_PATH. The default build runs generators on
    /// pure-Rust tract and refuses this flag.
    #[arg(long, value_name = "PATH")]
    pub ort_lib: Option<PathBuf>,
    /// Threads of the native ONNX Runtime (tract uses one).
    #[arg(long)]
    pub threads: Option<usize>,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}`: expected WIDTHxHEIGHT, e.g. 448x256"))?;
    let num = |t: &str| {
        t.trim()
            .parse::<u32>()
            .map_err(|e| format!("`{s}`: `{t}` is not a whole number of pixels ({e})"))
    };
    Ok((num(w)?, num(h)?))
}

impl GeneratorOpts {
    /// Loads `path` with these options.
    pub fn load(&self, path: &Path) -> anyhow::Result<Generator> {
        let mut params = GeneratorParams::new();
        if let Some((w, h)) = self.work_size {
            params = params.work_size(w, h);
        }
        if let Some(lib) = &self.ort_lib {
            params = params.ort_lib(lib);
        }
        if let Some(n) = self.threads {
            params = params.threads(n);
        }
        Ok(params.load(path)?)
    }
}

fn is_image(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"))
}

/// Expands folders into their images and checks that no two inputs share a
/// file name (they would share an output) and that none lies in `out`.
pub fn collect_images(args: &[PathBuf], out: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut images = Vec::new();
    for a in args {
        if a.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(a)
                .with_context(|| format!("{}: cannot list the folder", a.display()))?
                .map(|e| e.map(|e| e.path()))
                .collect::<Result<_, _>>()
                .with_context(|| format!("{}: cannot list the folder", a.display()))?;
            found.retain(|p| p.is_file() && is_image(p));
            found.sort();
            if found.is_empty() {
                bail!(
                    "{}: no .png, .jpg or .jpeg images in the folder",
                    a.display()
                );
            }
            images.extend(found);
        } else if a.is_file() {
            if !is_image(a) {
                bail!(
                    "{}: not an image (expected .png, .jpg or .jpeg)",
                    a.display()
                );
            }
            images.push(a.clone());
        } else {
            bail!("{}: no such file or folder", a.display());
        }
    }
    let mut names: BTreeMap<&std::ffi::OsStr, &Path> = BTreeMap::new();
    for img in &images {
        let name = img
            .file_name()
            .with_context(|| format!("{}: not a file", img.display()))?;
        if let Some(other) = names.insert(name, img) {
            bail!(
                "{} and {} would both be written to {}; translate them into separate folders",
                other.display(),
                img.display(),
                out.join(name).display()
            );
        }
    }
    if let Ok(out) = out.canonicalize() {
        for img in &images {
            let dir = img
                .canonicalize()
                .ok()
                .and_then(|p| p.parent().map(Path::to_path_buf));
            if dir.as_ref() == Some(&out) {
                bail!(
                    "{}: the output folder is the image's own folder; choose another --out",
                    img.display()
                );
            }
        }
    }
    Ok(images)
}

/// Runs `murk camera`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let images = collect_images(&args.images, &args.out)?;
    let mut generator = args.gen_opts.load(&args.generator)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("{}: cannot create the output folder", args.out.display()))?;
    let n = images.len();
    let bar = super::progress_bar(n, "images", args.quiet);
    let started = std::time::Instant::now();
    let mut times = TranslateTimes::default();
    let mut pixels = 0u64;
    for path in &images {
        let image = read_rgb(path)?;
        let (out, t) = generator.translate_timed(&image)?;
        let name = path
            .file_name()
            .with_context(|| format!("{}: not a file", path.display()))?;
        write_rgb_atomic(&args.out.join(name), &out)?;
        times += t;
        pixels += u64::from(image.width()) * u64::from(image.height());
        bar.inc(1);
    }
    bar.finish_and_clear();
    let secs = started.elapsed().as_secs_f64();
    outln!(
        "{n} {} through {} ({}) → {} in {secs:.2} s ({:.2} images/s, {:.1} Mpixel): {:.2} s in the network, \
         {:.1} % of the translation time in pre/post-processing",
        if n == 1 { "image" } else { "images" },
        args.generator.display(),
        murk_infer::camera::gan::backend(),
        args.out.display(),
        n as f64 / secs.max(1e-9),
        pixels as f64 / 1e6,
        times.run.as_secs_f64(),
        100.0 * times.outside_share()
    );
    Ok(())
}
