//! `murk convert`: point clouds from one format to another.
//!
//! ```text
//! murk convert INPUT... --out DIR --format pcd|bin|nuscenes|csv|parquet
//!              [--pcd-data ascii|binary|binary_compressed]
//!              [--intensity-scale NAME] [--input-intensity-scale NAME]
//!              [--columns x,y,z,intensity,ring] [--bin-layout xyzi|xyzir|xyzit]
//!              [--keep-partial]
//! ```
//!
//! - An INPUT is a file or a folder; folders are walked recursively
//!   ([`murk_types::walk_folder`]) and every file with a point-cloud
//!   extension (`.pcd .bin .pcd.bin .csv .parquet .pcap`) is taken, in
//!   sorted order; hidden entries and symbolic links back into folders
//!   already walked are left out and listed on stderr. A file given by name
//!   must have one.
//! - Output names keep the input's stem: `DIR/<stem>.<ext>`; files found in
//!   a folder keep their path relative to that folder
//!   (`DIR/<sub>/<stem>.<ext>`), so equal stems in different subfolders do
//!   not collide.
//! - A `.pcap` always becomes a folder of frames, one per revolution:
//!   `DIR/<stem>/frame-000001.<ext>`, `frame-000002.<ext>`, … (numbered from
//!   1 over every revolution of the capture), whether one capture or many
//!   are converted. The partial first and last revolutions (not a full
//!   360°) are left out, and said so, unless `--keep-partial`: each output
//!   file claims to be one revolution, and a revolution with a missing
//!   wedge would be read as a full one (per-scan counts, near-range
//!   returns). Their numbers are kept either way, so a frame's name does not
//!   depend on the flag. Packets that are not the sensor's (ARP, GPS) are
//!   skipped and counted; a capture cut mid-packet keeps the revolutions
//!   before the cut (warned).
//! - **Intensity keeps its meaning.** A PCD output records the scale it is
//!   written in (`# murk: intensity_scale kitti` in its header), so values
//!   are written as read. The other formats cannot record a scale: their
//!   values are converted to the format's own default (CSV, Parquet,
//!   nuScenes: calibrated 0–255; KITTI `.bin`: 0–1), so that reading the
//!   output back without flags gives the same reflectivities, and the line
//!   of the file says so (`intensity kitti → calibrated`).
//!   `--intensity-scale` names the scale to write instead (a warning says
//!   when the output cannot record it); `--input-intensity-scale` overrides
//!   the scale the inputs are taken to be in (default: what the file
//!   records, else the format's, see `murk_types::IntensityScale`).
//! - `--columns` names the columns of header-less CSV inputs (RADIATE:
//!   `x,y,z,intensity,ring`); `--bin-layout` the record layout of `.bin`
//!   inputs (Seeing Through Fog: `xyzir`). A `.bin` whose size fits several
//!   layouts is refused unless told (see `murk_io::parse_kitti`).
//! - Fields a cloud cannot carry (a PCD's `rgb` or `label`, a CSV's extra
//!   columns) are not written; a warning names them.
//! - Nothing is written when two inputs would land on the same output or an
//!   output would overwrite an input. Every file is written atomically.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use murk_io::{PcdData, ReadOptions, WriteOptions, read_frames_noted, write_cloud_with};
use murk_types::{BinLayout, IntensityScale, PcapReturn, PointFormat};

/// Arguments of `murk convert`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Files or folders to convert (folders are searched recursively).
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Output folder (created when missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Output format: pcd, bin (KITTI), nuscenes (.pcd.bin), csv or parquet.
    #[arg(long, value_parser = parse_writable_format)]
    pub format: PointFormat,
    /// PCD data encoding: ascii, binary or binary_compressed.
    #[arg(long, default_value = "binary")]
    pub pcd_data: PcdData,
    /// Scale to write intensity in (calibrated, kitti, six-bit, …); default:
    /// the values as read, unconverted.
    #[arg(long)]
    pub intensity_scale: Option<IntensityScale>,
    /// Scale the inputs' intensity is in; default: what each file records,
    /// else its format's own.
    #[arg(long)]
    pub input_intensity_scale: Option<IntensityScale>,
    /// Column names of header-less CSV inputs, in order (e.g.
    /// x,y,z,intensity,ring).
    #[arg(long, value_delimiter = ',', value_name = "NAMES")]
    pub columns: Option<Vec<String>>,
    /// Record layout of `.bin` inputs: xyzi (KITTI), xyzir (Seeing Through
    /// Fog), xyzit; default: KITTI where the file size leaves no doubt.
    #[arg(long, value_name = "LAYOUT")]
    pub bin_layout: Option<BinLayout>,
    /// Which return of each firing to read from dual-return `.pcap`
    /// inputs: strongest or last (default: as recorded, both).
    #[arg(long, value_name = "RETURN")]
    pub pcap_return: Option<PcapReturn>,
    /// Also write the partial first and last revolutions of captures.
    #[arg(long)]
    pub keep_partial: bool,
}

fn parse_writable_format(s: &str) -> Result<PointFormat, String> {
    match PointFormat::from_name(s) {
        Ok(f) if f.writable() => Ok(f),
        _ => Err(format!(
            "{s:?} is not a format murk writes: expected pcd, bin, nuscenes, csv or parquet"
        )),
    }
}

/// One input file and where its output goes.
#[derive(Debug)]
struct Job {
    input: PathBuf,
    /// Output path relative to `--out`, without extension (a pcap: the
    /// folder of its frames).
    stem: PathBuf,
    is_pcap: bool,
}

/// `stem` with `.ext` appended (not `with_extension`, which would eat a dot
/// inside the stem: `scan.v2` + `csv` must give `scan.v2.csv`).
fn with_ext(stem: &Path, ext: &str) -> PathBuf {
    let mut name = stem.file_name().unwrap_or_default().to_os_string();
    name.push(".");
    name.push(ext);
    stem.with_file_name(name)
}

/// The file name of `path` without its point-cloud extension.
fn stem_of(path: &Path) -> anyhow::Result<String> {
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .with_context(|| format!("{}: file name is not UTF-8", path.display()))?;
    let format = PointFormat::from_path(path)?;
    // `.pcd.bin` is two extensions; the others one (any letter case).
    let ext_len = format.extension().len() + 1;
    Ok(name[..name.len() - ext_len].to_string())
}

/// The inputs to convert and their output stems, in order.
fn plan(inputs: &[PathBuf], out: &Path) -> anyhow::Result<Vec<Job>> {
    let mut jobs = Vec::new();
    let mut seen = BTreeSet::new();
    // An output folder inside an input folder is not an input.
    let exclude: Vec<PathBuf> = std::fs::canonicalize(out).into_iter().collect();
    for input in inputs {
        let mut found = Vec::new();
        let base: &Path;
        if input.is_dir() {
            // The one folder walk of murk (shared with `murk apply`):
            // hidden entries and symbolic-link loops are left out, and said.
            let walk = murk_types::walk_folder(input, &exclude)?;
            for l in &walk.left_out {
                errln!("murk: skipped {}: {}", l.path.display(), l.reason);
            }
            found.extend(
                walk.files
                    .into_iter()
                    .filter(|f| PointFormat::from_path(&f.path).is_ok())
                    .map(|f| PathBuf::from(f.key)),
            );
            base = input;
        } else if input.is_file() {
            PointFormat::from_path(input)?;
            found.push(PathBuf::from(input.file_name().unwrap_or_default()));
            base = input.parent().unwrap_or(Path::new(""));
        } else {
            bail!("{}: no such file or folder", input.display());
        }
        for rel in found {
            let path = base.join(&rel);
            let key = std::fs::canonicalize(&path)
                .with_context(|| format!("{}: cannot resolve", path.display()))?;
            if !seen.insert(key) {
                continue; // the same file reached twice (folder and file, or twice listed)
            }
            let stem = rel.with_file_name(stem_of(&path)?);
            let is_pcap = PointFormat::from_path(&path)? == PointFormat::Pcap;
            jobs.push(Job {
                input: path,
                stem,
                is_pcap,
            });
        }
    }
    Ok(jobs)
}

/// `""` for one, `"s"` otherwise.
fn plural<N: PartialEq + From<u8>>(n: N) -> &'static str {
    if n == N::from(1) { "" } else { "s" }
}

/// Runs `murk convert`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let jobs = plan(&args.inputs, &args.out)?;
    if jobs.is_empty() {
        bail!("no point-cloud file found in the inputs");
    }
    let ext = args.format.extension();
    // Refuse collisions and overwriting an input before writing anything.
    let inputs: BTreeSet<PathBuf> = jobs
        .iter()
        .map(|j| std::fs::canonicalize(&j.input))
        .collect::<Result<_, _>>()?;
    let mut claimed: BTreeMap<PathBuf, &Path> = BTreeMap::new();
    for j in &jobs {
        if j.is_pcap {
            continue; // frames go into their own folder, checked when written
        }
        let out = args.out.join(with_ext(&j.stem, ext));
        if let Some(prev) = claimed.insert(out.clone(), &j.input) {
            bail!(
                "{} and {} would both be written to {}",
                prev.display(),
                j.input.display(),
                out.display()
            );
        }
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("{}: cannot create output folder", args.out.display()))?;
    let refuse_input = |out: &Path| -> anyhow::Result<()> {
        if let (Some(dir), Some(name)) = (out.parent(), out.file_name())
            && let Ok(dir) = std::fs::canonicalize(dir)
            && inputs.contains(&dir.join(name))
        {
            bail!("{}: refusing to overwrite an input file", out.display());
        }
        Ok(())
    };
    for j in &jobs {
        if !j.is_pcap {
            refuse_input(&args.out.join(with_ext(&j.stem, ext)))?;
        }
    }

    let read_opts = ReadOptions {
        intensity_scale: args.input_intensity_scale,
        bin_layout: args.bin_layout,
        csv_columns: args.columns.clone(),
        pcap_return: args.pcap_return,
        ..ReadOptions::default()
    };
    let write_opts = WriteOptions {
        format: args.format,
        pcd_data: args.pcd_data,
    };
    let stop = super::interrupt_flag()?;
    super::clean_stale(
        std::iter::once(args.out.clone()).chain(jobs.iter().map(|j| {
            if j.is_pcap {
                args.out.join(&j.stem)
            } else {
                let out = args.out.join(with_ext(&j.stem, ext));
                out.parent()
                    .map_or_else(|| args.out.clone(), Path::to_path_buf)
            }
        })),
    );
    let bar = super::progress_bar(jobs.len(), "inputs", false);
    let (mut done, mut files, mut points) = (0usize, 0usize, 0usize);
    // The intensity conversions made, for the summary line.
    let mut conversions: BTreeMap<(String, String), usize> = BTreeMap::new();
    for j in &jobs {
        bar.set_message(j.input.display().to_string());
        let frames = read_frames_noted(&j.input, &read_opts)?;
        for w in &frames.notes.warnings {
            bar.suspend(|| errln!("murk: warning: {w}"));
        }
        if !frames.notes.dropped_fields.is_empty() {
            bar.suspend(|| {
                errln!(
                    "murk: warning: {}: fields {} are not written (murk's clouds hold x, y, z, intensity, ring and time)",
                    j.input.display(),
                    frames.notes.dropped_fields.join(", ")
                )
            });
        }
        let mut partial_left = Vec::new();
        let mut partial_kept = 0usize;
        let mut clouds = Vec::with_capacity(frames.clouds.len());
        let outputs: Vec<PathBuf> = if j.is_pcap {
            let dir = args.out.join(&j.stem);
            std::fs::create_dir_all(&dir)
                .with_context(|| format!("{}: cannot create folder", dir.display()))?;
            let mut outputs = Vec::new();
            for (k, (cloud, &partial)) in frames.clouds.into_iter().zip(&frames.partial).enumerate()
            {
                let name = format!("frame-{:06}.{ext}", k + 1);
                if partial && !args.keep_partial {
                    partial_left.push(format!("{name} ({} points)", cloud.len()));
                    continue;
                }
                partial_kept += usize::from(partial);
                outputs.push(dir.join(name));
                clouds.push(cloud);
            }
            outputs
        } else {
            clouds = frames.clouds;
            let out = args.out.join(with_ext(&j.stem, ext));
            if let Some(dir) = out.parent() {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("{}: cannot create folder", dir.display()))?;
            }
            vec![out]
        };
        let mut warned_scale = false;
        for (mut cloud, out) in clouds.into_iter().zip(&outputs) {
            if stop.load(std::sync::atomic::Ordering::Relaxed) {
                bar.finish_and_clear();
                return Err(super::Interrupted(format!(
                    "interrupted: {done} of {} input{} converted ({files} {ext} file{}, each \
                     complete) in {}; the rest was not written",
                    jobs.len(),
                    plural(jobs.len()),
                    plural(files),
                    args.out.display()
                ))
                .into());
            }
            refuse_input(out)?;
            let from = cloud.intensity_scale;
            let to = args
                .intensity_scale
                .unwrap_or_else(|| murk_io::portable_scale(args.format, from));
            cloud.to_scale(to);
            if !murk_io::records_intensity_scale(args.format)
                && to != args.format.default_intensity_scale()
                && !warned_scale
            {
                warned_scale = true;
                bar.suspend(|| {
                    errln!(
                        "murk: warning: {}: intensity written as {to}, which .{ext} files cannot record: read it back with --intensity-scale {to}",
                        out.display()
                    )
                });
            }
            *conversions
                .entry((from.to_string(), to.to_string()))
                .or_insert(0) += 1;
            // Atomic: a Ctrl-C during the write waits for it to end.
            write_cloud_with(out, &cloud, &write_opts)?;
            points += cloud.len();
            files += 1;
        }
        // What a capture lost or kept is said per capture (a batch of
        // ordinary files says nothing per file: one line per file would be
        // thousands).
        let mut notes = Vec::new();
        if !partial_left.is_empty() {
            notes.push(format!(
                "left out {} partial revolution{}: {}; --keep-partial writes them",
                partial_left.len(),
                plural(partial_left.len()),
                partial_left.join(", ")
            ));
        }
        if partial_kept > 0 {
            notes.push(format!(
                "{partial_kept} of the {} frames written are partial revolutions",
                outputs.len()
            ));
        }
        if frames.notes.foreign_packets > 0 {
            notes.push(format!(
                "{} foreign packet{} skipped",
                frames.notes.foreign_packets,
                plural(frames.notes.foreign_packets)
            ));
        }
        if !notes.is_empty() {
            bar.suspend(|| {
                outln!(
                    "{} -> {} ({} frames): {}",
                    j.input.display(),
                    args.out.join(&j.stem).display(),
                    outputs.len(),
                    notes.join("; ")
                )
            });
        }
        done += 1;
        bar.inc(1);
    }
    bar.finish_and_clear();
    // One line for the whole batch (one per file would be thousands).
    let pcaps = jobs.iter().filter(|j| j.is_pcap).count();
    let intensity = conversions
        .iter()
        .map(|((from, to), n)| {
            let what = if from == to {
                format!("intensity {from}")
            } else {
                format!("intensity {from} → {to}")
            };
            if conversions.len() > 1 {
                format!("{what} in {n} file{}", plural(*n))
            } else {
                what
            }
        })
        .collect::<Vec<_>>()
        .join(", ");
    outln!(
        "converted {} input{}{} into {files} {ext} file{} ({points} point{}{}) in {}",
        jobs.len(),
        plural(jobs.len()),
        if pcaps > 0 {
            format!(
                " ({pcaps} pcap capture{} split into one file per frame)",
                plural(pcaps)
            )
        } else {
            String::new()
        },
        plural(files),
        plural(points),
        if intensity.is_empty() {
            String::new()
        } else {
            format!("; {intensity}")
        },
        args.out.display()
    );
    Ok(())
}
