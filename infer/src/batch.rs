//! Batch application over files and folders: plan (which input goes to
//! which output), then run (read, apply, write, in parallel).
//!
//! - Inputs are files or folders. A folder is walked recursively in name
//!   order ([`murk_types::walk_folder`], shared with `murk convert`); files
//!   in it whose extension is not a point-cloud format, hidden files, and
//!   symbolic links back into folders already walked (a loop such as `sub/up
//!   -> ..`) are listed in [`Plan::skipped`] with the reason (never dropped
//!   silently). A file named explicitly must be a point cloud.
//! - Outputs keep the relative path (a file argument: its name; a file found
//!   in a folder: its path below the folder) under the output folder, with
//!   the extension of the output format. Two inputs that map to the same
//!   output, or an output that would overwrite an input, are errors.
//! - The scan key that seeds the random draws is that relative path, so a
//!   scan's output does not depend on where the batch lives or what else is
//!   in it.
//! - Same format in and out: intensities are written in the input's scale,
//!   untouched points bit for bit (a PCD output records a scale other than
//!   calibrated in its header, see `murk_io`). CSV to CSV goes further (see
//!   [`run_job`]): kept rows are copied byte for byte, header and extra
//!   columns included. Another format, and every KITTI `.bin` output
//!   (always `xyzi`, 0–1): intensities are converted to the scale
//!   [`murk_io::portable_scale`] names, so that reading the output with
//!   default options gives the same reflectivities.
//! - A `.pcap` capture is applied **per revolution**: its output is a folder
//!   `<stem>/` of `frame-000001.<ext>`, `frame-000002.<ext>`, … (as `murk
//!   convert` names them), one scan each, seeded by its own key
//!   `<stem>/frame-000001.<ext>`. Partial first and last revolutions (not a
//!   full 360°) are left out and said so in the warnings unless
//!   [`BatchOptions::keep_partial`]: a scan with a missing wedge would be
//!   read as a whole revolution downstream. Packets that are not the
//!   sensor's are skipped and counted in the warnings; a capture cut short
//!   keeps the revolutions before the cut.
//! - Each [`FileReport`] says in which intensity scale its input was read
//!   and whether that scale was declared, recorded in the file or assumed,
//!   and which of the input's fields the output does not carry.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use murk_io::{CsvNeeds, PcdData, ReadOptions, RowEdit, WriteOptions};
use murk_types::{PointCloud, PointFormat, StagedFile};
use rayon::prelude::*;
use serde::Serialize;

use crate::applier::Applier;
use crate::error::InferError;
use crate::model::ModelSummary;
use crate::summary::{ApplySummary, SUMMARY_FORMAT};

/// One input file and where its output goes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[non_exhaustive]
pub struct Job {
    /// The input file.
    pub input: PathBuf,
    /// The output file.
    pub output: PathBuf,
    /// Relative path with `/` separators: the output's name below the output
    /// folder and the seed key of the scan.
    pub key: String,
    /// Format the input is read as.
    #[serde(skip)]
    pub format_in: PointFormat,
    /// Format written.
    #[serde(skip)]
    pub format_out: PointFormat,
}

/// A file found in an input folder and left out.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[non_exhaustive]
pub struct Skipped {
    /// The file.
    pub path: PathBuf,
    /// Why it was left out.
    pub reason: String,
}

/// Inputs matched with outputs, checked before anything is written.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
#[non_exhaustive]
pub struct Plan {
    /// The files to process, in argument order (folders in name order).
    pub jobs: Vec<Job>,
    /// Files of input folders that are not point clouds.
    pub skipped: Vec<Skipped>,
}

/// How to read and write the files of a batch.
#[derive(Debug, Clone, Default)]
pub struct BatchOptions {
    /// Reader settings (forced format, ring elevations, intensity scale).
    pub read: ReadOptions,
    /// Output format; `None` keeps each input's format.
    pub format: Option<PointFormat>,
    /// PCD `DATA` encoding of PCD outputs.
    pub pcd_data: PcdData,
    /// Also apply to (and write) the partial first and last revolutions of
    /// a `.pcap` capture.
    pub keep_partial: bool,
}

/// One processed file.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[non_exhaustive]
pub struct FileReport {
    /// The input file.
    pub input: PathBuf,
    /// The file written.
    pub output: PathBuf,
    /// What applying did.
    pub summary: ApplySummary,
    /// The intensity scale the input was read in (`kitti`, `calibrated`, …).
    pub intensity_scale: String,
    /// Where that scale came from (`declared`, `recorded in the file`,
    /// `assumed (format default)`).
    pub intensity_scale_source: &'static str,
    /// Fields of the input the output does not have (a PCD's `rgb`, a
    /// CSV's extra columns written to another format).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub dropped_fields: Vec<String>,
    /// True for a partial revolution of a capture (kept with
    /// [`BatchOptions::keep_partial`]).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub partial: bool,
}

/// The report of a batch (`murk-apply-summary/1`).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[non_exhaustive]
pub struct BatchReport {
    /// Always [`SUMMARY_FORMAT`].
    pub format: &'static str,
    /// What was applied.
    pub model: ModelSummary,
    /// Counts summed over every file; its `warnings` are the scans' own, in
    /// plan order (the model's are in `model.warnings`, once).
    pub totals: ApplySummary,
    /// Per file, in plan order.
    pub files: Vec<FileReport>,
    /// Files of input folders that were left out.
    pub skipped: Vec<Skipped>,
}

impl BatchReport {
    /// The report as pretty JSON (deterministic), newline-terminated.
    pub fn to_json(&self) -> String {
        let mut s = serde_json::to_string_pretty(self)
            .unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"));
        s.push('\n');
        s
    }

    /// Writes the JSON report atomically (temporary file, then rename).
    pub fn write(&self, path: &Path) -> Result<(), InferError> {
        write_atomic(path, self.to_json().as_bytes())
    }
}

/// Writes `bytes` to `path` atomically ([`murk_types::write_atomic`]).
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), InferError> {
    murk_types::write_atomic(path, bytes).map_err(fs_error(path))
}

/// The error of a failed atomic write of `path`.
fn fs_error(path: &Path) -> impl Fn(murk_types::AtomicWriteError) -> InferError + '_ {
    move |e| InferError::Fs {
        path: path.to_path_buf(),
        action: e.action,
        source: e.source,
    }
}

/// `name` without the extension of `format` (`a.pcd.bin` → `a`).
fn stem_of(name: &str, format: PointFormat) -> String {
    let ext = format!(".{}", format.extension());
    if name.len() > ext.len() && name.to_ascii_lowercase().ends_with(&ext) {
        name[..name.len() - ext.len()].to_string()
    } else {
        Path::new(name)
            .file_stem()
            .map_or_else(|| name.to_string(), |s| s.to_string_lossy().into_owned())
    }
}

fn canonical(p: &Path) -> Result<PathBuf, InferError> {
    p.canonicalize().map_err(|source| InferError::Fs {
        path: p.to_path_buf(),
        action: "resolve path",
        source,
    })
}

/// Matches every input with its output under `out_dir` (created if needed)
/// and checks that nothing would be overwritten or written twice.
pub fn plan(inputs: &[PathBuf], out_dir: &Path, opts: &BatchOptions) -> Result<Plan, InferError> {
    std::fs::create_dir_all(out_dir).map_err(|source| InferError::Fs {
        path: out_dir.to_path_buf(),
        action: "create output folder",
        source,
    })?;
    let out_canon = canonical(out_dir)?;
    let mut found: Vec<(PathBuf, String, bool)> = Vec::new();
    let mut skipped = Vec::new();
    for inp in inputs {
        let meta = std::fs::metadata(inp).map_err(|source| InferError::Fs {
            path: inp.clone(),
            action: "open input",
            source,
        })?;
        if meta.is_dir() {
            if canonical(inp)? == out_canon {
                return Err(InferError::Input {
                    path: inp.clone(),
                    reason:
                        "is the output folder: outputs would overwrite inputs; choose another --out"
                            .into(),
                });
            }
            // The one folder walk of murk: name order, hidden entries and
            // the output folder left out, symbolic-link loops detected.
            let walk = murk_types::walk_folder(inp, std::slice::from_ref(&out_canon))?;
            skipped.extend(walk.left_out.into_iter().map(|l| Skipped {
                path: l.path,
                reason: l.reason,
            }));
            found.extend(walk.files.into_iter().map(|f| (f.path, f.key, false)));
        } else {
            let name = inp
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .ok_or_else(|| InferError::Input {
                    path: inp.clone(),
                    reason: "has no file name".into(),
                })?;
            found.push((inp.clone(), name, true));
        }
    }

    let mut jobs = Vec::with_capacity(found.len());
    let mut kept_skipped = skipped;
    for (path, key, explicit) in found {
        let format_in = match opts.read.format_of(&path) {
            Ok(f) => f,
            Err(e) if !explicit => {
                kept_skipped.push(Skipped {
                    path,
                    reason: format!("not a point-cloud file ({e})"),
                });
                continue;
            }
            Err(e) => return Err(e.into()),
        };
        let format_out = opts.format.unwrap_or(format_in);
        if !format_out.writable() {
            return Err(InferError::Input {
                path,
                reason: format!(
                    "{format_out:?} files cannot be written: choose an output format (pcd, bin, nuscenes, csv, parquet)"
                ),
            });
        }
        let key = if format_in == PointFormat::Pcap {
            // A folder of frames.
            let (dir, name) = match key.rsplit_once('/') {
                Some((d, n)) => (format!("{d}/"), n.to_string()),
                None => (String::new(), key.clone()),
            };
            format!("{dir}{}", stem_of(&name, format_in))
        } else if format_out == format_in && opts.format.is_none() {
            key
        } else {
            let (dir, name) = match key.rsplit_once('/') {
                Some((d, n)) => (format!("{d}/"), n.to_string()),
                None => (String::new(), key.clone()),
            };
            format!(
                "{dir}{}.{}",
                stem_of(&name, format_in),
                format_out.extension()
            )
        };
        let output = key.split('/').fold(out_canon.clone(), |p, c| p.join(c));
        jobs.push(Job {
            input: path,
            output,
            key,
            format_in,
            format_out,
        });
    }

    // Nothing written twice, no input overwritten.
    let mut seen: HashMap<&str, &Path> = HashMap::new();
    for j in &jobs {
        if let Some(other) = seen.insert(&j.key, &j.input) {
            return Err(InferError::Input {
                path: j.input.clone(),
                reason: format!(
                    "would be written to {} like {}: give the two inputs different names or apply them separately",
                    j.output.display(),
                    other.display()
                ),
            });
        }
    }
    let canon_inputs: HashMap<PathBuf, &Path> = jobs
        .iter()
        .map(|j| Ok((canonical(&j.input)?, j.input.as_path())))
        .collect::<Result<_, InferError>>()?;
    for j in &jobs {
        if j.output.exists()
            && let Some(inp) = canon_inputs.get(&canonical(&j.output)?)
        {
            return Err(InferError::OutputIsInput {
                output: j.output.clone(),
                input: inp.to_path_buf(),
            });
        }
    }
    let dirs: HashSet<&Path> = jobs
        .iter()
        .filter_map(|j| {
            if j.format_in == PointFormat::Pcap {
                Some(j.output.as_path())
            } else {
                j.output.parent()
            }
        })
        .collect();
    for d in dirs {
        std::fs::create_dir_all(d).map_err(|source| InferError::Fs {
            path: d.to_path_buf(),
            action: "create output folder",
            source,
        })?;
    }
    Ok(Plan {
        jobs,
        skipped: kept_skipped,
    })
}

/// Runs one job: read, apply, write.
///
/// **CSV to CSV** is row-preserving and parallel inside the file: the file
/// is read once, its rows parsed in pieces in parallel, only the columns the
/// model uses decoded (x, y, z, intensity; ring and time too with near-range
/// returns), and the output is the input's header and kept rows **byte for
/// byte** (extra columns, number spelling and line breaks kept). Rows whose
/// point the model changed (near-range replacement, range noise,
/// attenuation) get new x, y, z and intensity cells and keep the others;
/// added near-range returns are appended with empty cells in the columns
/// murk does not know. Cells of columns the model does not use are copied,
/// not checked. Files with quoted data cells take the general path (read,
/// apply, write `x,y,z,intensity,ring[,time]`).
///
/// A `.pcap` job gives one report per revolution written (see the module
/// docs); every other job one.
pub fn run_job(
    applier: &Applier,
    job: &Job,
    opts: &BatchOptions,
) -> Result<Vec<FileReport>, InferError> {
    let mut reports = Vec::new();
    for (report, staged) in stage_job(applier, job, opts)? {
        commit(staged)?;
        reports.push(report);
    }
    Ok(reports)
}

/// [`run_job`] up to the outputs' temporary files: the reports and the
/// staged outputs, which [`commit`] syncs and renames into place.
fn stage_job(
    applier: &Applier,
    job: &Job,
    opts: &BatchOptions,
) -> Result<Vec<(FileReport, StagedFile)>, InferError> {
    let mut read = opts.read.clone();
    read.format = Some(job.format_in);
    if job.format_in == PointFormat::Csv
        && job.format_out == PointFormat::Csv
        && (applier.identity || applier.extensions.is_empty())
        && let Some(staged) = stage_csv_rows(applier, job, &read)?
    {
        return Ok(vec![staged]);
    }
    if job.format_in == PointFormat::Pcap {
        return stage_capture(applier, job, opts, &read);
    }
    let (cloud, notes) = murk_io::read_cloud_noted(&job.input, &read)?;
    let staged = stage_scan(
        applier,
        job,
        opts,
        &cloud,
        &notes,
        &job.key,
        &job.output,
        false,
    )?;
    Ok(vec![staged])
}

/// Applies the model to one scan and stages its output at `output`.
#[allow(clippy::too_many_arguments)]
fn stage_scan(
    applier: &Applier,
    job: &Job,
    opts: &BatchOptions,
    cloud: &PointCloud,
    notes: &murk_io::ReadNotes,
    key: &str,
    output: &Path,
    partial: bool,
) -> Result<(FileReport, StagedFile), InferError> {
    let (mut out, mut summary) = applier.apply(cloud, key)?;
    if job.format_out != job.format_in || job.format_out == PointFormat::KittiBin {
        out.to_scale(murk_io::portable_scale(job.format_out, out.intensity_scale));
    }
    let w = WriteOptions {
        format: job.format_out,
        pcd_data: opts.pcd_data,
    };
    let staged = murk_io::stage_cloud_with(output, &out, &w)?;
    summary.warnings.extend(notes.warnings.iter().cloned());
    if !notes.dropped_fields.is_empty() {
        summary.warnings.push(format!(
            "{}: fields {} are not carried into {} (murk's clouds hold x, y, z, intensity, ring and time)",
            job.input.display(),
            notes.dropped_fields.join(", "),
            output.display()
        ));
    }
    Ok((
        FileReport {
            input: job.input.clone(),
            output: output.to_path_buf(),
            summary,
            intensity_scale: cloud.intensity_scale.describe(),
            intensity_scale_source: notes.scale_source.describe(),
            dropped_fields: notes.dropped_fields.clone(),
            partial,
        },
        staged,
    ))
}

/// A capture, applied per revolution (see the module docs).
fn stage_capture(
    applier: &Applier,
    job: &Job,
    opts: &BatchOptions,
    read: &ReadOptions,
) -> Result<Vec<(FileReport, StagedFile)>, InferError> {
    let frames = murk_io::read_frames_noted(&job.input, read)?;
    let ext = job.format_out.extension();
    let mut staged = Vec::with_capacity(frames.clouds.len());
    let mut dropped = Vec::new();
    let mut notes = frames.notes.clone();
    for (k, (cloud, &partial)) in frames.clouds.iter().zip(&frames.partial).enumerate() {
        let name = format!("frame-{:06}.{ext}", k + 1);
        if partial && !opts.keep_partial {
            dropped.push(format!("{name} ({} points)", cloud.len()));
            continue;
        }
        let key = format!("{}/{name}", job.key);
        let output = job.output.join(&name);
        staged.push(stage_scan(
            applier, job, opts, cloud, &notes, &key, &output, partial,
        )?);
        // The capture's notes go with its first output only.
        notes.warnings.clear();
    }
    if !dropped.is_empty() {
        let warning = format!(
            "{}: left out {} partial revolution{} (not a full 360°): {}; --keep-partial applies to them too",
            job.input.display(),
            dropped.len(),
            if dropped.len() == 1 { "" } else { "s" },
            dropped.join(", ")
        );
        match staged.first_mut() {
            Some((report, _)) => report.summary.warnings.push(warning),
            None => {
                return Err(InferError::Input {
                    path: job.input.clone(),
                    reason: format!("{warning}, and it holds no full one"),
                });
            }
        }
    }
    Ok(staged)
}

/// Syncs a staged output and renames it into place.
fn commit(staged: StagedFile) -> Result<(), InferError> {
    let path = staged.path().to_path_buf();
    staged.commit().map_err(fs_error(&path))
}

/// The row-preserving CSV path of [`stage_job`]; `None` when the file has
/// quoted data cells.
fn stage_csv_rows(
    applier: &Applier,
    job: &Job,
    read: &ReadOptions,
) -> Result<Option<(FileReport, StagedFile)>, InferError> {
    let needs = CsvNeeds {
        ring: applier.near_range,
        time: applier.near_range,
    };
    // The file's bytes stay in murk-io's per-thread read buffer; kept rows
    // are streamed from them to the output file.
    let staged = murk_io::with_file_bytes(&job.input, |bytes| {
        let Some(rows) = murk_io::parse_csv_rows(bytes, &job.input, read, needs)? else {
            return Ok(None);
        };
        let mut mask = Vec::new();
        let mut replaced = Vec::new();
        let (out, summary) =
            applier.apply_marked(&rows.cloud, &job.key, &mut mask, false, &mut replaced)?;
        let (edits, added) = match &out {
            Some(out) => changed_rows(&rows.cloud, &mask, out, &replaced),
            None => (Vec::new(), None),
        };
        let staged = murk_types::stage_atomic_with(&job.output, |w| {
            rows.write_subset(bytes, &mask, &edits, added.as_ref(), w)
        })
        .map_err(fs_error(&job.output))?;
        Ok::<_, InferError>(Some((summary, staged)))
    })??;
    let source = if read.declared_scale().is_some() {
        murk_io::ScaleSource::Declared
    } else {
        murk_io::ScaleSource::Default
    };
    Ok(staged.map(|(summary, staged)| {
        (
            FileReport {
                input: job.input.clone(),
                output: job.output.clone(),
                summary,
                intensity_scale: read.scale_for(PointFormat::Csv).describe(),
                intensity_scale_source: source.describe(),
                dropped_fields: Vec::new(),
                partial: false,
            },
            staged,
        )
    }))
}

/// The kept input points whose x, y, z or intensity `out` changed (bit
/// comparison), and the points `out` adds after the kept ones. `replaced`
/// (ascending output indices) marks the kept points a near-range return
/// replaced: their rows are fresh points ([`RowEdit::fresh`]).
fn changed_rows(
    input: &PointCloud,
    mask: &[u8],
    out: &PointCloud,
    replaced: &[usize],
) -> (Vec<RowEdit>, Option<PointCloud>) {
    let mut edits = Vec::new();
    let mut j = 0usize;
    let mut r = 0usize;
    for (i, &m) in mask.iter().enumerate() {
        if m == 0 {
            continue;
        }
        let fresh = r < replaced.len() && replaced[r] == j;
        if fresh {
            r += 1;
        }
        let new = [out.x[j], out.y[j], out.z[j], out.intensity[j]];
        let old = [input.x[i], input.y[i], input.z[i], input.intensity[i]];
        if fresh
            || new
                .iter()
                .zip(&old)
                .any(|(a, b)| a.to_bits() != b.to_bits())
        {
            edits.push(RowEdit {
                row: i,
                values: new,
                fresh,
            });
        }
        j += 1;
    }
    let added = (j < out.len()).then(|| PointCloud {
        x: out.x[j..].to_vec(),
        y: out.y[j..].to_vec(),
        z: out.z[j..].to_vec(),
        intensity: out.intensity[j..].to_vec(),
        ring: out.ring[j..].to_vec(),
        time: out.time.as_ref().map(|t| t[j..].to_vec()),
        intensity_scale: out.intensity_scale,
    });
    (edits, added)
}

/// Threads that sync and rename finished outputs while the rayon workers
/// go on computing (see [`run`]).
const COMMITTERS: usize = 4;

/// Outputs staged but not yet committed, at most: bounds the open files
/// (and temporary files) a batch of thousands of scans holds at once.
const STAGED_MAX: usize = 64;

/// Runs every job of `plan` in parallel; `progress` is called once per
/// finished file (from committing threads), after its output is in place.
/// On failure the error of the first failing file in plan order is
/// returned (files that succeeded are written).
///
/// Workers (rayon) read, apply and write each output to a temporary file;
/// four plain threads sync those files and rename them into
/// place. A sync waits on the disk rather than working, so this keeps the
/// cores busy, and concurrent syncs let the file system commit many files
/// at once. Each output is still synced before it appears under its name.
pub fn run(
    applier: &Applier,
    plan: &Plan,
    opts: &BatchOptions,
    progress: &(dyn Fn(&FileReport) + Sync),
) -> Result<BatchReport, InferError> {
    run_until(
        applier,
        plan,
        opts,
        progress,
        &std::sync::atomic::AtomicBool::new(false),
    )
}

/// [`run`] that stops early when `stop` becomes true (Ctrl-C): no new
/// file is started, the files being worked on are finished, committed and
/// reported to `progress`, and the result is
/// [`InferError::Interrupted`] saying how many files are in place. Every
/// output then present is complete (outputs appear only by rename) and no
/// temporary file is left.
pub fn run_until(
    applier: &Applier,
    plan: &Plan,
    opts: &BatchOptions,
    progress: &(dyn Fn(&FileReport) + Sync),
    stop: &std::sync::atomic::AtomicBool,
) -> Result<BatchReport, InferError> {
    use std::sync::atomic::Ordering;
    let n = plan.jobs.len();
    // Jobs never started because of `stop`.
    let not_started = std::sync::atomic::AtomicUsize::new(0);
    type Staged = Vec<(FileReport, StagedFile)>;
    let (tx, rx) = std::sync::mpsc::sync_channel::<(usize, Staged)>(STAGED_MAX);
    // Shared by the committers only: when the last of them ends (even by a
    // panic), the receiver goes and a worker's send fails instead of
    // waiting forever.
    let rx = std::sync::Arc::new(std::sync::Mutex::new(rx));
    let (staged, committed) = std::thread::scope(|scope| {
        let committers: Vec<_> = (0..COMMITTERS.min(n.max(1)))
            .map(|_| {
                let rx = std::sync::Arc::clone(&rx);
                scope.spawn(move || {
                    let mut done = Vec::new();
                    loop {
                        // The lock is held only to take the next file.
                        let next = rx.lock().unwrap_or_else(|p| p.into_inner()).recv();
                        let Ok((i, outputs)) = next else {
                            break;
                        };
                        let mut reports = Vec::with_capacity(outputs.len());
                        let mut r = Ok(());
                        for (report, staged) in outputs {
                            // After a failure the rest are dropped (their
                            // temporary files removed), not committed.
                            if r.is_ok() {
                                r = commit(staged);
                                reports.push(report);
                            }
                        }
                        let r = r.map(|()| {
                            if let Some(last) = reports.last() {
                                progress(last);
                            }
                            reports
                        });
                        done.push((i, r));
                    }
                    done
                })
            })
            .collect();
        drop(rx);
        let staged: Vec<Option<InferError>> = plan
            .jobs
            .par_iter()
            .enumerate()
            .map_with(tx, |tx, (i, j)| {
                if stop.load(Ordering::Relaxed) {
                    not_started.fetch_add(1, Ordering::Relaxed);
                    return Some(InferError::Interrupted { done: 0, total: n });
                }
                match stage_job(applier, j, opts) {
                    // A send fails only when every committer is gone (a panic,
                    // re-raised below); the temporary files are then dropped.
                    Ok(outputs) => tx
                        .send((i, outputs))
                        .err()
                        .map(|_| InferError::Conflict("the committing threads stopped".into())),
                    Err(e) => Some(e),
                }
            })
            .collect();
        let committed: Vec<(usize, Result<Vec<FileReport>, InferError>)> = committers
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect();
        (staged, committed)
    });
    let mut results: Vec<Option<Result<Vec<FileReport>, InferError>>> =
        staged.into_iter().map(|e| e.map(Err)).collect();
    for (i, r) in committed {
        results[i] = Some(r);
    }
    let results: Vec<Result<Vec<FileReport>, InferError>> = results
        .into_iter()
        .map(|r| r.expect("every job is staged or failed"))
        .collect();
    if not_started.load(Ordering::Relaxed) > 0 {
        let done = results.iter().filter(|r| r.is_ok()).count();
        return Err(InferError::Interrupted { done, total: n });
    }
    let mut files = Vec::with_capacity(results.len());
    for r in results {
        files.extend(r?);
    }
    let mut totals = ApplySummary::empty("total", applier.bands());
    totals.identity = applier.is_identity();
    for f in &files {
        totals.add(&f.summary);
    }
    Ok(BatchReport {
        format: SUMMARY_FORMAT,
        model: applier.describe(),
        totals,
        files,
        skipped: plan.skipped.clone(),
    })
}
