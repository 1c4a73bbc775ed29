//! The thin I/O driver: streams a campaign's recordings through the
//! statistical core.
//!
//! 0. The firing geometry is measured from the first clear recordings
//!    ([`measure_geometry`]); the cell grid is centred on it.
//! 1. The clear recordings are read in parallel and reduced to cell images;
//!    the [`ClearReference`] is built from them and the images dropped.
//!    A `.pcap` is read as its revolutions ([`read_scans`]); every count a
//!    cell expects is per scan, times the recording's scans.
//! 2. The degraded recordings are read in parallel by a fixed pool of workers
//!    (one per rayon thread), each pairing its recordings with the reference
//!    and adding them to its own per-weather accumulators; the accumulators
//!    are merged at the end. Memory is one accumulator per worker plus the
//!    files in flight: it does not grow with the number of recordings beyond
//!    one row of scalars each.
//! 3. Every file read is hashed (SHA-256) from the same bytes that are parsed.
//!
//! Errors are deterministic: a bad file does not stop the other workers, and
//! the error reported is the one of the first bad recording in campaign order.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use murk_campaign::Campaign;
use murk_io::ReadOptions;
use murk_types::{
    ExcludedRecording, LidarSpec, PointCloud, PointFormat, SensorGeometry, WeatherClass,
};
use rayon::prelude::*;
use sha2::{Digest, Sha256};

use crate::accumulate::{CellTable, WeatherAcc};
use crate::geometry::GeometryAcc;
use crate::images::{ClearImages, StoredImage};
use crate::pairing::{masked_stretches, pair_frames};
use crate::radar::Detections;
use crate::reference::{CellGrid, CellImage, CellPoint, ClearReference, cell_points};
use crate::survival::Partition;
use crate::{FitError, FitValidParams};

/// One recording as the fit sees it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RecordingInput {
    /// Recording id.
    pub id: String,
    /// Weather class after the rules and the review.
    pub class: WeatherClass,
    /// MOR, metres, when the visibility sensors gave one.
    pub mor: Option<f64>,
    /// Every non-empty reading of the rule set's visibility (MOR) columns,
    /// metres, of which `mor` is the mean: their disagreement measures the
    /// reading noise that widens the edge the survival fit sees (see
    /// `SlopeBand::edge_width_corrected` in murk-types).
    pub mor_readings: Vec<f64>,
    /// Rain rate, mm/h, when known (the rule set's first non-empty gauge).
    pub rain_rate: Option<f64>,
    /// Every non-empty reading of the rule set's rain-rate gauges, mm/h: their
    /// disagreement measures the gauge noise that the rain conversion corrects.
    pub rain_readings: Vec<f64>,
    /// The point-cloud file.
    pub lidar: PathBuf,
    /// The radar file, when there is one.
    pub radar: Option<PathBuf>,
}

/// Everything a fit reads: the campaign's metadata and the selected
/// recordings (see [`FitInputs::from_campaign`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitInputs {
    /// Campaign folder (input paths are reported relative to it).
    pub dir: PathBuf,
    /// Campaign name.
    pub name: String,
    /// The LiDAR.
    #[serde(with = "crate::state::json")]
    pub lidar: LidarSpec,
    /// Selected recordings, in campaign order.
    pub recordings: Vec<RecordingInput>,
    /// Metadata files to hash (campaign.toml, weather.csv, review.csv, rules).
    pub metadata: Vec<PathBuf>,
    /// Why a degraded weather has no recording (from the selection).
    pub absent: BTreeMap<WeatherClass, String>,
}

impl FitInputs {
    /// The kept recordings of every class of `campaign` (rules + review).
    pub fn from_campaign(campaign: &Campaign) -> FitInputs {
        let selection = campaign.select();
        let recordings: Vec<RecordingInput> = selection
            .recordings()
            .iter()
            .filter(|r| r.kept())
            .filter_map(|r| {
                // The finite readings of `columns` (the visibility or the
                // rain-rate columns of the rule set).
                let readings = |columns: &[String]| -> Vec<f64> {
                    columns
                        .iter()
                        .filter_map(|c| r.value(c).and_then(|v| v.as_f64()))
                        .filter(|v| v.is_finite())
                        .collect()
                };
                Some(RecordingInput {
                    id: r.id().to_string(),
                    class: r.class()?,
                    mor: r.mor(),
                    mor_readings: readings(campaign.rules().intensity()),
                    rain_rate: r.rain_rate(),
                    rain_readings: readings(campaign.rules().rain_rate()),
                    lidar: r.lidar().path.clone(),
                    radar: r.radar().map(Path::to_path_buf),
                })
            })
            .collect();
        let mut absent = BTreeMap::new();
        for class in WeatherClass::DEGRADED {
            if recordings.iter().any(|r| r.class == class) {
                continue;
            }
            let reason = match selection.summary().class(class) {
                None => "the campaign's rules do not define this class".to_string(),
                Some(s) if s.before_review == 0 => {
                    "no recording matched this class's rules".to_string()
                }
                Some(s) => format!(
                    "{} recordings matched the rules, the review kept none",
                    s.before_review
                ),
            };
            absent.insert(class, reason);
        }
        let dir = campaign.dir().to_path_buf();
        let mut metadata = vec![
            dir.join(murk_campaign::layout::CAMPAIGN_TOML),
            dir.join(murk_campaign::layout::WEATHER_CSV),
        ];
        if let Some(r) = campaign.review_file() {
            metadata.push(r.to_path_buf());
        }
        let origin = campaign.rules().origin();
        if origin.is_file() {
            metadata.push(origin.to_path_buf());
        }
        FitInputs {
            dir,
            name: campaign.name().to_string(),
            lidar: campaign.lidar().clone(),
            recordings,
            metadata,
            absent,
        }
    }
}

/// Lower-case hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The path of `path` relative to `dir`, `/`-separated.
pub fn relative(dir: &Path, path: &Path) -> String {
    let p = path.strip_prefix(dir).unwrap_or(path);
    p.components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect::<Vec<_>>()
        .join("/")
}

/// Reads a file for hashing and parsing.
pub fn read_file(path: &Path) -> Result<Vec<u8>, FitError> {
    std::fs::read(path).map_err(|e| FitError::File {
        path: path.to_path_buf(),
        reason: format!("cannot read: {e}"),
    })
}

/// Reads one LiDAR recording as scans: one per revolution of a `.pcap`
/// (partial first and last revolutions left out, see the private `full_revolutions`), the
/// whole file for every other format; calibrated intensity, points nearer
/// than the declared `min_range_m` left out (not returns of the scene).
/// Returns the scans and the file's SHA-256.
pub fn read_scans(path: &Path, spec: &LidarSpec) -> Result<(Vec<PointCloud>, String), FitError> {
    let opts = ReadOptions {
        lidar: Some(spec.clone()),
        intensity_scale: spec.intensity_scale,
        ..Default::default()
    };
    let format = opts.format_of(path)?;
    let (mut frames, digest) = if format == PointFormat::Pcap {
        let frames = murk_io::read_frames_noted(path, &opts)?;
        if frames.notes.both_returns {
            return Err(FitError::File {
                path: path.to_path_buf(),
                reason: "a dual-return capture (each firing's strongest and last returns): murk's weather model has one return per firing, and the two read together count a fog echo in front of a kept target as a ghost beside it, which neither return mode sees; say which to read in campaign.toml, [lidar] pcap_return = \"strongest\" (a sensor's default mode) or \"last\"".into(),
            });
        }
        (full_revolutions(frames), sha256_hex(&read_file(path)?))
    } else {
        let bytes = read_file(path)?;
        let digest = sha256_hex(&bytes);
        (
            vec![murk_io::parse_cloud(&bytes, format, path, &opts)?],
            digest,
        )
    };
    for f in &mut frames {
        f.to_calibrated();
        if spec.min_range_m.is_some() {
            let keep: Vec<bool> = (0..f.len()).map(|i| spec.is_return(f.range(i))).collect();
            f.retain_mask(&keep);
        }
    }
    Ok((frames, digest))
}

/// A capture's full revolutions: the first and last ones that murk-io flags
/// partial (they do not cover 360°: a capture starts and stops anywhere in a
/// turn) are left out, interior revolutions are all kept however few their
/// returns (dense fog). A capture shorter than one full revolution is kept
/// whole, as one partial scan is better than none.
pub fn full_revolutions(frames: murk_io::Frames) -> Vec<PointCloud> {
    if frames.partial.iter().all(|&p| p) {
        return frames.clouds;
    }
    frames
        .clouds
        .into_iter()
        .zip(frames.partial)
        .filter_map(|(c, p)| (!p).then_some(c))
        .collect()
}

/// Reads one LiDAR recording: its points placed in the grid, its number of
/// scans and the file's SHA-256.
pub fn read_lidar_frames(
    path: &Path,
    spec: &LidarSpec,
    grid: &CellGrid,
) -> Result<(Vec<CellPoint>, u32, String), FitError> {
    let (frames, digest) = read_scans(path, spec)?;
    let mut points = Vec::with_capacity(frames.iter().map(PointCloud::len).sum());
    for f in &frames {
        points.extend(cell_points(grid, f, path)?);
    }
    Ok((points, frames.len().max(1) as u32, digest))
}

/// Reads one LiDAR recording: its points (every scan) placed in the grid and
/// the file's SHA-256.
pub fn read_lidar(
    path: &Path,
    spec: &LidarSpec,
    grid: &CellGrid,
) -> Result<(Vec<CellPoint>, String), FitError> {
    let (points, _, digest) = read_lidar_frames(path, spec, grid)?;
    Ok((points, digest))
}

/// The firing geometry measured from the first 8 clear recordings of
/// `inputs` (up to 20 scans each; `geometry::MAX_RECORDINGS` and
/// `MAX_FRAMES_PER_RECORDING`), and what it contradicts in the declared
/// LiDAR.
pub fn measure_geometry(inputs: &FitInputs) -> Result<(SensorGeometry, Vec<String>), FitError> {
    let clear: Vec<&RecordingInput> = inputs
        .recordings
        .iter()
        .filter(|r| r.class == WeatherClass::Clear)
        .take(crate::geometry::MAX_RECORDINGS)
        .collect();
    let accs: Vec<Result<GeometryAcc, FitError>> = clear
        .par_iter()
        .map(|r| {
            let (frames, _) = read_scans(&r.lidar, &inputs.lidar)?;
            let mut acc = GeometryAcc::new();
            acc.start_recording();
            for f in frames
                .iter()
                .take(crate::geometry::MAX_FRAMES_PER_RECORDING)
            {
                acc.add_frame(f);
            }
            Ok(acc)
        })
        .collect();
    let mut all = GeometryAcc::new();
    for a in accs {
        all.merge(a?);
    }
    let g = all.finish(&inputs.lidar);
    let mut w = crate::geometry::warnings(&g, &inputs.lidar);
    w.extend(all.near_points_warning(&inputs.lidar));
    Ok((g, w))
}

/// Reads a radar file (`x,y,z,rcs,velocity` with a header).
pub fn read_radar(path: &Path) -> Result<(Detections, String), FitError> {
    let bytes = read_file(path)?;
    let digest = sha256_hex(&bytes);
    let err = |line: usize, reason: String| FitError::Radar {
        path: path.to_path_buf(),
        line,
        reason,
    };
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .from_reader(bytes.as_slice());
    let headers = rdr.headers().map_err(|e| err(1, e.to_string()))?.clone();
    let col = |name: &str| {
        headers.iter().position(|h| h == name).ok_or_else(|| {
            err(
                1,
                format!("missing column {name:?} (expected x,y,z,rcs,velocity)"),
            )
        })
    };
    let (ix, iy, iz) = (col("x")?, col("y")?, col("z")?);
    let mut out = Vec::new();
    for (k, rec) in rdr.records().enumerate() {
        let line = k + 2;
        let rec = rec.map_err(|e| err(line, e.to_string()))?;
        let mut p = [0.0; 3];
        for (slot, (i, name)) in p.iter_mut().zip([(ix, "x"), (iy, "y"), (iz, "z")]) {
            let s = rec.get(i).unwrap_or("");
            let v: f64 = s
                .parse()
                .map_err(|_| err(line, format!("column {name}: {s:?} is not a number")))?;
            if !v.is_finite() {
                return Err(err(line, format!("column {name}: {s:?} is not finite")));
            }
            *slot = v;
        }
        out.push(p);
    }
    Ok((out, digest))
}

/// Runs `job` over `0..n` on one worker per rayon thread, each folding into
/// its own state; returns the states and, when any job failed, the error of
/// the lowest failing index.
pub fn worker_pool<S: Send, F, I>(n: usize, init: I, job: F) -> Result<Vec<S>, FitError>
where
    I: Fn() -> S + Sync,
    F: Fn(usize, &mut S) -> Result<(), FitError> + Sync,
{
    let next = AtomicUsize::new(0);
    let first_err: Mutex<Option<(usize, FitError)>> = Mutex::new(None);
    let workers = rayon::current_num_threads().clamp(1, n.max(1));
    let states: Vec<S> = (0..workers)
        .into_par_iter()
        .map(|_| {
            let mut s = init();
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= n {
                    break;
                }
                if let Err(e) = job(i, &mut s) {
                    let mut g = first_err.lock().unwrap_or_else(|p| p.into_inner());
                    if g.as_ref().is_none_or(|(j, _)| i < *j) {
                        *g = Some((i, e));
                    }
                }
            }
            s
        })
        .collect();
    match first_err.into_inner().unwrap_or_else(|p| p.into_inner()) {
        Some((_, e)) => Err(e),
        None => Ok(states),
    }
}

/// The exclusion of a recording whose file holds no point: it says nothing
/// about the weather (a recorder that saved nothing), and counted it would
/// read as every return lost.
fn no_points(r: &RecordingInput) -> ExcludedRecording {
    ExcludedRecording {
        recording: r.id.clone(),
        weather: r.class,
        reason: format!("{}: the file holds no point", r.lidar.display()),
    }
}

/// The cell image of every recording of `recs` (`None` when its file holds
/// no point), put in `store` as it is read, and its file's SHA-256, in the
/// order of `recs`; the error of the first bad recording in that order.
///
/// Read in parallel a few recordings at a time (four per thread), so that
/// what is held at once is those recordings' points and the store's
/// budget, not every clear recording's image.
pub(crate) fn clear_images(
    inputs: &FitInputs,
    recs: &[&RecordingInput],
    grid: &CellGrid,
    store: &mut ClearImages,
) -> Result<Vec<(Option<StoredImage>, String)>, FitError> {
    let chunk = 4 * rayon::current_num_threads().max(1);
    let mut out = Vec::with_capacity(recs.len());
    for part in recs.chunks(chunk) {
        let images: Vec<Result<(Option<CellImage>, String), FitError>> = part
            .par_iter()
            .map(|r| {
                let (points, frames, digest) = read_lidar_frames(&r.lidar, &inputs.lidar, grid)?;
                let img = (!points.is_empty())
                    .then(|| CellImage::from_frames(&points, frames, grid.cells()));
                Ok((img, digest))
            })
            .collect();
        for r in images {
            let (img, digest) = r?;
            let img = img.map(|i| store.store(i)).transpose()?;
            out.push((img, digest));
        }
    }
    Ok(out)
}

/// The exclusion of a recording whose file holds no point.
pub fn empty_recording(r: &RecordingInput) -> ExcludedRecording {
    no_points(r)
}

/// The per-weather accumulators of one worker.
pub struct WorkerState {
    /// Per degraded weather.
    pub accs: BTreeMap<WeatherClass, WeatherAcc>,
    /// `(job index, file digest)`.
    pub digests: Vec<(usize, String)>,
    /// Jobs left out because their file holds no point.
    pub empty: Vec<usize>,
}

/// A degraded recording ready for pairing: its input and its MOR.
#[derive(Debug, Clone)]
pub struct DegradedJob<'a> {
    /// Position in the fit's list of degraded jobs (the row index: the
    /// order of every float summary), the same in every shard.
    pub index: usize,
    /// Position of the recording in [`FitInputs::recordings`].
    pub recording: usize,
    /// The recording.
    pub input: &'a RecordingInput,
    /// MOR used (measured, or converted from the rain rate).
    pub mor: f64,
}

/// What [`accumulate_degraded`] returns: the accumulator of every weather,
/// the SHA-256 of every file read and the recordings (positions in
/// [`FitInputs::recordings`]) left out because their file holds no point,
/// both ascending.
pub type Accumulated = (
    BTreeMap<WeatherClass, WeatherAcc>,
    Vec<(usize, String)>,
    Vec<usize>,
);

/// Streams the degraded recordings through pairing into accumulators.
pub fn accumulate_degraded(
    inputs: &FitInputs,
    jobs: &[DegradedJob<'_>],
    reference: &ClearReference,
    partition: &Partition,
    params: &FitValidParams,
) -> Result<Accumulated, FitError> {
    let cells = CellTable::new(reference, partition, params);
    let grid = reference.grid();
    let rs = inputs.lidar.range_scale;
    let states = worker_pool(
        jobs.len(),
        || WorkerState {
            accs: BTreeMap::new(),
            digests: Vec::new(),
            empty: Vec::new(),
        },
        |i, s| {
            let job = &jobs[i];
            let (points, frames, digest) =
                read_lidar_frames(&job.input.lidar, &inputs.lidar, grid)?;
            s.digests.push((i, digest));
            if points.is_empty() {
                s.empty.push(i);
                return Ok(());
            }
            let tally = pair_frames(reference, &points, frames, params);
            let masked = masked_stretches(reference, &cells.scene, &points);
            s.accs
                .entry(job.input.class)
                .or_insert_with(|| WeatherAcc::new(params, partition))
                .add(
                    job.index,
                    &job.input.id,
                    job.mor,
                    job.input.rain_rate,
                    &tally,
                    &masked,
                    &cells,
                    params,
                    rs,
                );
            Ok(())
        },
    )?;
    let mut accs: BTreeMap<WeatherClass, WeatherAcc> = BTreeMap::new();
    let mut digests = Vec::new();
    let mut empty = Vec::new();
    for s in states {
        empty.extend(s.empty);
        for (k, a) in s.accs {
            match accs.get_mut(&k) {
                Some(m) => m.merge(a),
                None => {
                    accs.insert(k, a);
                }
            }
        }
        digests.extend(s.digests);
    }
    for a in accs.values_mut() {
        a.finish();
    }
    let mut digests: Vec<(usize, String)> = digests
        .into_iter()
        .map(|(i, d)| (jobs[i].recording, d))
        .collect();
    digests.sort();
    let mut empty: Vec<usize> = empty.into_iter().map(|i| jobs[i].recording).collect();
    empty.sort_unstable();
    Ok((accs, digests, empty))
}
