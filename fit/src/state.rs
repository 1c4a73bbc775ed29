//! The fit as map and merge: the statistics of any subset of a campaign's
//! recordings as a serialisable, mergeable [`FitState`].
//!
//! Pairing a degraded recording needs the finished clear reference, so a
//! distributed fit runs in two phases:
//!
//! 1. **clear**: shards of the clear recordings are mapped
//!    ([`FitState::map`] without a reference): each keeps its recordings'
//!    cell images, file digests and radar detections, and the firing
//!    geometry, measured from the same first ≤ 8 clear recordings as the
//!    one-shot fit (so every shard measures the same one). Merged, they
//!    make the *clear state*.
//! 2. **degraded**: shards of the degraded recordings are mapped against the
//!    clear state ([`FitState::map`] with it as reference): each pairs its
//!    recordings with the reference and folds them into per-weather
//!    accumulators ([`WeatherAcc`]: integer counts and one row per recording,
//!    sorted by recording when finished), and records the digest of the clear
//!    part it was paired against.
//!
//! [`FitState::merge`] sums the counts and unites the per-recording rows, so
//! it is associative and commutative; [`FitState::finish`] needs every
//! selected recording of the campaign and gives the table byte for byte as
//! one [`FitValidParams::fit`] over everything (which is itself map over
//! everything, then finish). States of another campaign, other parameters or
//! another murk version, and degraded states paired against another clear
//! reference, are refused at merge with an error naming both states and what
//! differs.
//!
//! On disk a state is versioned ([`STATE_FORMAT`]) and checksummed: the magic
//! bytes, the format, a header (tool, digests of parameters and campaign),
//! then the body in bincode (floats as their bits, so they round-trip
//! exactly) and the SHA-256 of everything before it.
//!
//! ```
//! use murk_fit::{FitInputs, FitParams, FitState, Selection};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! # let dir = tempfile::tempdir()?;
//! # let d = dir.path();
//! # std::fs::write(d.join("campaign.toml"), "name = \"demo\"\nrules = \"pdd-2022-2023\"\n[lidar]\nmodel = \"toy\"\nelevation_deg = [0.0]\nazimuth_resolution_deg = 10.0\n")?;
//! # std::fs::write(d.join("weather.csv"), "recording,timestamp,PWD12_Weather Type,PWD12_Rain intensity (mm/h),PWD12_MOR (m),VS2K_MOR (m),WXT530_Rain intensity (mm/h)\nc1,2023-01-14T05:00:00Z,Clear,0,2500,2500,0\nc2,2023-01-14T06:00:00Z,Clear,0,2500,2500,0\nf1,2023-01-14T07:00:00Z,Fog,0,50,50,0\nf2,2023-01-14T08:00:00Z,Fog,0,100,100,0\n")?;
//! # std::fs::create_dir(d.join("lidar"))?;
//! # for (id, mor) in [("c1", 1e9), ("c2", 1e9), ("f1", 50.0), ("f2", 100.0)] {
//! #     let mut csv = String::from("x,y,z,intensity,ring\n");
//! #     for k in 0..36 {
//! #         let (az, r) = ((k as f64 * 10.0 + 5.0).to_radians(), 4.0 + k as f64);
//! #         if r < 0.3 * mor { csv += &format!("{},{},0,20,0\n", r * az.cos(), r * az.sin()); }
//! #     }
//! #     std::fs::write(d.join("lidar").join(format!("{id}.csv")), csv)?;
//! # }
//! // `d` holds a campaign of two clear and two foggy recordings.
//! let inputs = FitInputs::from_campaign(&murk_campaign::Campaign::open(d)?);
//! let params = FitParams::default().min_points_per_bin(1).bootstrap_replicates(0).check()?;
//! // Phase 1: the clear recordings in two shards, merged.
//! let c1 = params.fit_partial(&inputs, &Selection::Shard { k: 1, n: 2 }, None)?;
//! let c2 = params.fit_partial(&inputs, &Selection::Shard { k: 2, n: 2 }, None)?;
//! let clear = c2.merge(c1)?;
//! // Phase 2: the degraded recordings, one by one, against the clear state.
//! let f1 = params.fit_partial(&inputs, &Selection::recordings(["f1"]), Some(&clear))?;
//! let f2 = params.fit_partial(&inputs, &Selection::recordings(["f2"]), Some(&clear))?;
//! assert!(clear.clone().merge(f1.clone())?.finish().is_err()); // f2 is missing
//! let table = clear.merge(f2)?.merge(f1)?.finish()?;
//! assert_eq!(table.to_json()?, params.fit_inputs(&inputs)?.to_json()?);
//! # Ok(())
//! # }
//! ```

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

use murk_types::{ExcludedRecording, SensorGeometry, WeatherClass};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::accumulate::WeatherAcc;
use crate::assemble::{RainSample, rain_conversion};
use crate::driver::{
    DegradedJob, FitInputs, RecordingInput, accumulate_degraded, clear_images, measure_geometry,
    read_file, read_radar, relative, sha256_hex,
};
use crate::images::{ClearImages, StoredImage, StoredImages};
use crate::radar::Detections;
use crate::reference::{CellGrid, CellImage, ClearReference};
use crate::survival::Partition;
use crate::{FitError, FitParams, FitValidParams, FittedTable, TOOL};

/// Version of the state file layout; a state of another format is refused.
/// Format 2: the parameters gained `compare_laws`; format 3:
/// `reference_min_agreement` and the recordings' MOR readings; format 4:
/// `reflectivity_law_edges`; format 5: each recording's hidden returns and
/// the cells beyond the noise windows (the occlusion test); format 6: the
/// stretches of each recording's rays masked by the near scene.
pub const STATE_FORMAT: u32 = 6;

const MAGIC: &[u8; 8] = b"MURKFITS";

/// Which recordings a partial fit maps.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Selection {
    /// Every recording of the phase (the clear ones without a reference, the
    /// degraded ones with one).
    All,
    /// These recording ids (all clear without a reference, all degraded with
    /// one).
    Recordings(Vec<String>),
    /// Block `k` (1-based) of `n` contiguous, nearly equal blocks of the
    /// phase's recordings in campaign order.
    Shard {
        /// Which block, 1 to `n`.
        k: usize,
        /// How many blocks.
        n: usize,
    },
}

impl Selection {
    /// [`Selection::Recordings`] from any list of ids.
    pub fn recordings<I: IntoIterator<Item = S>, S: Into<String>>(ids: I) -> Selection {
        Selection::Recordings(ids.into_iter().map(Into::into).collect())
    }

    /// Parses `K/N` (1 ≤ K ≤ N) into [`Selection::Shard`].
    pub fn parse_shard(s: &str) -> Result<Selection, FitError> {
        let bad = |reason: &str| FitError::Selection {
            reason: format!("shard {s:?}: {reason}"),
        };
        let (k, n) = s
            .split_once('/')
            .ok_or_else(|| bad("expected K/N, for example 1/8"))?;
        let k: usize = k
            .trim()
            .parse()
            .map_err(|_| bad("K is not a whole number"))?;
        let n: usize = n
            .trim()
            .parse()
            .map_err(|_| bad("N is not a whole number"))?;
        let sel = Selection::Shard { k, n };
        sel.check()?;
        Ok(sel)
    }

    fn check(&self) -> Result<(), FitError> {
        if let Selection::Shard { k, n } = *self
            && (n == 0 || k == 0 || k > n)
        {
            return Err(FitError::Selection {
                reason: format!("shard {k}/{n}: K must lie in 1..=N and N be at least 1"),
            });
        }
        Ok(())
    }

    /// The positions in `phase` (recording positions in campaign order)
    /// this selection takes.
    fn pick(
        &self,
        inputs: &FitInputs,
        phase: &[usize],
        clear_phase: bool,
    ) -> Result<Vec<usize>, FitError> {
        self.check()?;
        match self {
            Selection::All => Ok(phase.to_vec()),
            Selection::Shard { k, n } => {
                let len = phase.len();
                Ok(phase[(k - 1) * len / n..k * len / n].to_vec())
            }
            Selection::Recordings(ids) => {
                let mut out = BTreeSet::new();
                for id in ids {
                    let Some(i) = inputs.recordings.iter().position(|r| &r.id == id) else {
                        return Err(FitError::Selection {
                            reason: format!(
                                "recording {id:?} is not one of the {} recordings the campaign's rules and review select",
                                inputs.recordings.len()
                            ),
                        });
                    };
                    if !phase.contains(&i) {
                        let class = inputs.recordings[i].class;
                        return Err(FitError::Selection {
                            reason: match clear_phase {
                                true => format!(
                                    "recording {id:?} is {class}: degraded recordings are mapped against a clear state (give a reference)"
                                ),
                                false => format!(
                                    "recording {id:?} is clear: clear recordings are mapped without a reference"
                                ),
                            },
                        });
                    }
                    out.insert(i);
                }
                Ok(out.into_iter().collect())
            }
        }
    }
}

/// What makes states mergeable: the tool, the parameters, the campaign.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Header {
    tool: String,
    params_sha256: String,
    campaign_sha256: String,
}

/// One mapped clear recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct ClearEntry {
    /// SHA-256 of its file.
    digest: String,
    /// Its cell image (in memory, or in the map's temporary file: see
    /// [`crate::images`]); `None` when the file holds no point.
    image: Option<StoredImage>,
}

/// One mapped degraded recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct DegradedEntry {
    /// SHA-256 of its file; `None` when it was not read (no usable MOR).
    digest: Option<String>,
    /// Its file holds no point.
    empty: bool,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct Body {
    params: FitValidParams,
    inputs: FitInputs,
    /// SHA-256 of every metadata file (campaign.toml, weather.csv, …).
    metadata: Vec<(PathBuf, String)>,
    /// The measured firing geometry and its warnings (every state that holds
    /// a clear recording or was paired against a clear state).
    #[serde(with = "json")]
    geometry: Option<(SensorGeometry, Vec<String>)>,
    /// Mapped clear recordings by position in `inputs.recordings`.
    clear: BTreeMap<usize, ClearEntry>,
    /// Digest of the clear part the degraded recordings were paired against.
    reference_sha256: Option<String>,
    /// Mapped degraded recordings by position in `inputs.recordings`.
    degraded: BTreeMap<usize, DegradedEntry>,
    /// Per degraded weather, the accumulated statistics.
    accs: BTreeMap<WeatherClass, WeatherAcc>,
    /// Radar detections and file digest by recording position.
    radar: BTreeMap<usize, (Detections, String)>,
}

/// The statistics of a subset of a campaign's recordings (see the module
/// documentation): mergeable, serialisable, and finished into the table
/// when it holds every selected recording.
#[derive(Debug, Clone)]
pub struct FitState {
    header: Header,
    body: Body,
    /// How errors name this state (its file, or what it holds).
    label: String,
    /// The digest of the clear part, once computed.
    clear_sha256: OnceLock<String>,
    /// The clear reference, once built.
    reference: OnceLock<Arc<ClearReference>>,
    /// The clear images were released after the reference and the clear
    /// digest were built ([`ClearPart`]): the state can still pair and
    /// finish, but not be written.
    released: bool,
}

/// The clear part of a fit, mapped once: the clear reference and its
/// digest, the measured geometry, the clear recordings' file digests and
/// radar detections, but not their cell images (released once the reference
/// was built). Several fits over the same clear recordings and different
/// degraded ones (murk diagnose's folds) share one
/// ([`FitValidParams::fit_inputs_with`]) instead of each reading every clear
/// recording and holding its image again.
///
/// ```no_run
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// use murk_fit::{FitInputs, FitParams};
/// let campaign = murk_campaign::Campaign::open("fixtures/default-campaign")?;
/// let inputs = FitInputs::from_campaign(&campaign);
/// let params = FitParams::default().check()?;
/// let clear = params.map_clear(&inputs)?;
/// // The same table as `params.fit_inputs(&inputs)`.
/// let table = params.fit_inputs_with(&inputs, &clear)?;
/// # let _ = table;
/// # Ok(())
/// # }
/// ```
#[derive(Debug, Clone)]
pub struct ClearPart {
    state: FitState,
}

impl ClearPart {
    /// Maps the clear recordings of `inputs`, builds the reference and
    /// the clear digest, and releases the images.
    fn map(inputs: &FitInputs, params: &FitValidParams) -> Result<ClearPart, FitError> {
        let mut state = FitState::map(inputs, params, &Selection::All, None)?;
        state.clear_reference()?;
        state.clear_sha256();
        for e in state.body.clear.values_mut() {
            if let Some(image) = &mut e.image {
                *image = StoredImage::memory(CellImage::default());
            }
        }
        state.released = true;
        state.label = format!("the clear part of {}", inputs.name);
        Ok(ClearPart { state })
    }

    /// The parameters the part was mapped under.
    pub fn params(&self) -> &FitValidParams {
        &self.state.body.params
    }

    /// Whether a fit under `params` can use the part: its parameters equal
    /// the part's but for those only a fit's finish reads (`compare_laws`,
    /// `apply_bend`: the law comparison and the bend, computed from the
    /// degraded recordings' trials), so one part serves murk diagnose's
    /// fold fits (no law comparison) and its fit on every recording.
    pub fn serves(&self, params: &FitValidParams) -> bool {
        clear_params_sha256(params) == clear_params_sha256(&self.state.body.params)
    }

    /// The clear reference the part built.
    pub fn reference(&self) -> Result<Arc<ClearReference>, FitError> {
        self.state.clear_reference()
    }

    /// The part re-keyed for `inputs` (the positions of its clear
    /// recordings in `inputs`), refused unless `inputs` selects exactly
    /// the same clear recordings, files and parameters.
    fn for_inputs(
        &self,
        inputs: &FitInputs,
        params: &FitValidParams,
    ) -> Result<FitState, FitError> {
        let c = &self.state;
        let err = |reason: String| FitError::StateMismatch {
            a: c.label.clone(),
            b: format!("the fit of {}", inputs.name),
            reason,
        };
        let (header, mut body) = FitState::skeleton(inputs, params)?;
        if !self.serves(params) {
            return Err(err("fitted with different parameters".into()));
        }
        let (mine, theirs) = (clear_recordings(inputs), clear_recordings(&c.body.inputs));
        if mine != theirs {
            return Err(err(format!(
                "different clear recordings ({} against {}): a clear part serves fits of the same clear recordings only",
                mine.len(),
                theirs.len()
            )));
        }
        // Positions in the part's campaign → positions in `inputs`.
        let to_mine: BTreeMap<usize, usize> = clear_positions(&c.body.inputs)
            .into_iter()
            .zip(clear_positions(inputs))
            .collect();
        body.clear = c
            .body
            .clear
            .iter()
            .map(|(i, e)| (to_mine[i], e.clone()))
            .collect();
        body.radar = c
            .body
            .radar
            .iter()
            .filter_map(|(i, d)| Some((*to_mine.get(i)?, d.clone())))
            .collect();
        body.geometry = c.body.geometry.clone();
        Ok(FitState {
            header,
            body,
            label: c.label.clone(),
            clear_sha256: c.clear_sha256.clone(),
            reference: c.reference.clone(),
            released: true,
        })
    }
}

impl FitValidParams {
    /// Maps the clear part of `inputs` once, for several fits over the same
    /// clear recordings ([`FitValidParams::fit_inputs_with`]).
    pub fn map_clear(&self, inputs: &FitInputs) -> Result<ClearPart, FitError> {
        ClearPart::map(inputs, self)
    }

    /// [`FitValidParams::fit_inputs`] with the clear part already mapped:
    /// the same table, byte for byte, as long as `inputs` selects the same
    /// clear recordings as the part's campaign (else an error says how they
    /// differ); its degraded recordings may be any subset.
    pub fn fit_inputs_with(
        &self,
        inputs: &FitInputs,
        clear: &ClearPart,
    ) -> Result<crate::FittedTable, FitError> {
        let state = clear.for_inputs(inputs, self)?;
        FitState::fit_with(inputs, self, state)
    }
}

/// A murk-types value inside the binary body as its JSON text: those types
/// leave out empty fields and read untagged values, which only a
/// self-describing format can carry. serde_json reads floats back to the
/// same bits (`float_roundtrip`, on in the workspace).
pub(crate) mod json {
    use serde::de::DeserializeOwned;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<T: Serialize, S: Serializer>(v: &T, s: S) -> Result<S::Ok, S::Error> {
        let text = serde_json::to_string(v).map_err(serde::ser::Error::custom)?;
        s.serialize_str(&text)
    }

    pub fn deserialize<'de, T: DeserializeOwned, D: Deserializer<'de>>(
        d: D,
    ) -> Result<T, D::Error> {
        let text = String::deserialize(d)?;
        serde_json::from_str(&text).map_err(serde::de::Error::custom)
    }
}

fn campaign_sha256(inputs: &FitInputs, metadata: &[(PathBuf, String)]) -> String {
    let rel = |p: &Path| relative(&inputs.dir, p);
    let recordings: Vec<serde_json::Value> = inputs
        .recordings
        .iter()
        .map(|r| {
            serde_json::json!({
                "id": r.id, "class": r.class, "mor": r.mor, "rain_rate": r.rain_rate,
                "rain_readings": r.rain_readings, "lidar": rel(&r.lidar),
                "radar": r.radar.as_deref().map(rel),
            })
        })
        .collect();
    let meta: Vec<(String, &String)> = metadata.iter().map(|(p, d)| (rel(p), d)).collect();
    let v = serde_json::json!({
        "name": inputs.name, "lidar": inputs.lidar, "recordings": recordings,
        "metadata": meta, "absent": inputs.absent,
    });
    sha256_hex(v.to_string().as_bytes())
}

/// A writer that feeds a SHA-256 (so an encoding is hashed without being
/// held). Written here because digest 0.11 no longer implements
/// `std::io::Write` for its hashers (that moved to the `digest-io` crate):
/// eight lines rather than a dependency for one call.
struct HashWriter(Sha256);

impl std::io::Write for HashWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.update(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

fn params_sha256(params: &FitValidParams) -> String {
    sha256_hex(params.to_json().to_string().as_bytes())
}

/// The digest of the parameters a clear part depends on: all of them but
/// `compare_laws` and `apply_bend`, which only the finish reads, and
/// `reflectivity_law_edges`, which only the degraded recordings' histograms
/// read ([`ClearPart::serves`]).
fn clear_params_sha256(params: &FitValidParams) -> String {
    let mut p = params.clone();
    p.compare_laws = true;
    p.apply_bend = false;
    p.reflectivity_law_edges = Vec::new();
    params_sha256(&p)
}

/// The degraded recordings' MORs: the rain conversion from the metadata,
/// the jobs (recordings with a usable MOR, in campaign order) and the
/// recordings left out for want of one.
pub(crate) struct Degraded<'a> {
    pub conversion: Option<Result<murk_types::RainConversion, String>>,
    pub jobs: Vec<DegradedJob<'a>>,
    pub excluded: Vec<(usize, ExcludedRecording)>,
}

pub(crate) fn degraded_jobs(inputs: &FitInputs) -> Degraded<'_> {
    // Rain conversion from the metadata, before any point is read: rain
    // recordings without a MOR borrow it.
    let rain_pairs: Vec<RainSample> = inputs
        .recordings
        .iter()
        .filter(|r| r.class == WeatherClass::Rain)
        .filter_map(|r| {
            let readings = match r.rain_readings.is_empty() {
                true => vec![r.rain_rate?],
                false => r.rain_readings.clone(),
            };
            Some(RainSample {
                readings,
                mor: r.mor?,
            })
        })
        .collect();
    let has_rain = inputs
        .recordings
        .iter()
        .any(|r| r.class == WeatherClass::Rain);
    let conversion = has_rain.then(|| rain_conversion(&rain_pairs));
    let mut jobs = Vec::new();
    let mut excluded = Vec::new();
    for (i, r) in inputs.recordings.iter().enumerate() {
        if r.class == WeatherClass::Clear {
            continue;
        }
        let mor = match (r.mor, r.rain_rate, &conversion) {
            (Some(m), _, _) if m.is_finite() && m > 0.0 => Ok(m),
            (Some(m), _, _) => Err(format!("MOR {m} is not a positive distance")),
            (None, Some(rate), Some(Ok(c))) if c.mor(rate) > 0.0 => Ok(c.mor(rate)),
            (None, Some(rate), Some(Ok(c))) => Err(format!(
                "no MOR, and the rain conversion gives {:.1} m at {rate} mm/h",
                c.mor(rate)
            )),
            (None, _, _) => {
                Err("no MOR (every visibility column is empty) and no rain conversion".to_string())
            }
        };
        match mor {
            Ok(mor) => jobs.push(DegradedJob {
                index: jobs.len(),
                recording: i,
                input: r,
                mor,
            }),
            Err(reason) => excluded.push((
                i,
                ExcludedRecording {
                    recording: r.id.clone(),
                    weather: r.class,
                    reason,
                },
            )),
        }
    }
    Degraded {
        conversion,
        jobs,
        excluded,
    }
}

/// The partition of reflectivity the survival histograms use.
pub(crate) fn partition(params: &FitValidParams) -> Partition {
    Partition::new(
        params
            .bands()
            .iter()
            .chain(params.sweep_bands().iter())
            .map(|b| b.min)
            .chain(params.reflectivity_law_edges().iter().copied()),
    )
}

fn clear_positions(inputs: &FitInputs) -> Vec<usize> {
    (0..inputs.recordings.len())
        .filter(|&i| inputs.recordings[i].class == WeatherClass::Clear)
        .collect()
}

fn degraded_positions(inputs: &FitInputs) -> Vec<usize> {
    (0..inputs.recordings.len())
        .filter(|&i| inputs.recordings[i].class != WeatherClass::Clear)
        .collect()
}

fn read_radars(
    inputs: &FitInputs,
    picked: &[usize],
) -> Result<BTreeMap<usize, (Detections, String)>, FitError> {
    let with: Vec<(usize, &Path)> = picked
        .iter()
        .filter_map(|&i| Some((i, inputs.recordings[i].radar.as_deref()?)))
        .collect();
    let read: Vec<Result<(Detections, String), FitError>> =
        with.par_iter().map(|(_, p)| read_radar(p)).collect();
    with.iter()
        .zip(read)
        .map(|((i, _), r)| Ok((*i, r?)))
        .collect()
}

/// The clear recordings of `inputs`: (id, LiDAR file) in campaign order.
fn clear_recordings(inputs: &FitInputs) -> Vec<(&str, &Path)> {
    clear_positions(inputs)
        .into_iter()
        .map(|i| {
            let r = &inputs.recordings[i];
            (r.id.as_str(), r.lidar.as_path())
        })
        .collect()
}

fn names(inputs: &FitInputs, idx: &[usize]) -> String {
    const SHOWN: usize = 5;
    let mut s: Vec<String> = idx
        .iter()
        .take(SHOWN)
        .map(|&i| inputs.recordings[i].id.clone())
        .collect();
    if idx.len() > SHOWN {
        s.push(format!("and {} more", idx.len() - SHOWN));
    }
    s.join(", ")
}

impl FitValidParams {
    /// Maps the recordings `selection` picks into a [`FitState`]: without
    /// `reference`, clear recordings (phase 1); with `reference` (a state
    /// holding every clear recording, merged from phase 1), degraded ones
    /// paired against it (phase 2).
    pub fn fit_partial(
        &self,
        inputs: &FitInputs,
        selection: &Selection,
        reference: Option<&FitState>,
    ) -> Result<FitState, FitError> {
        FitState::map(inputs, self, selection, reference)
    }
}

impl FitState {
    /// See [`FitValidParams::fit_partial`].
    pub fn map(
        inputs: &FitInputs,
        params: &FitValidParams,
        selection: &Selection,
        reference: Option<&FitState>,
    ) -> Result<FitState, FitError> {
        let (header, mut body) = FitState::skeleton(inputs, params)?;
        let clear_pos = clear_positions(inputs);
        let label;
        match reference {
            None => {
                let picked = selection.pick(inputs, &clear_pos, true)?;
                let geometry = measure_geometry(inputs)?;
                let grid = grid_of(&geometry.0, inputs, params);
                let recs: Vec<&RecordingInput> =
                    picked.iter().map(|&i| &inputs.recordings[i]).collect();
                let images = clear_images(inputs, &recs, &grid, &mut ClearImages::new())?;
                body.radar = read_radars(inputs, &picked)?;
                for (&i, (image, digest)) in picked.iter().zip(images) {
                    body.clear.insert(i, ClearEntry { digest, image });
                }
                body.geometry = Some(geometry);
                label = format!(
                    "partial state of {} clear recordings of {}",
                    picked.len(),
                    inputs.name
                );
            }
            Some(r) => {
                let own = FitState {
                    header: header.clone(),
                    body: body.clone(),
                    label: "this partial fit".into(),
                    clear_sha256: OnceLock::new(),
                    reference: OnceLock::new(),
                    released: false,
                };
                own.compatible(r)?;
                r.require_clear()?;
                let reference = r.clear_reference()?;
                let picked = selection.pick(inputs, &degraded_positions(inputs), false)?;
                let d = degraded_jobs(inputs);
                let set: BTreeSet<usize> = picked.iter().copied().collect();
                let jobs: Vec<DegradedJob<'_>> = d
                    .jobs
                    .into_iter()
                    .filter(|j| set.contains(&j.recording))
                    .collect();
                let (accs, digests, empty) =
                    accumulate_degraded(inputs, &jobs, &reference, &partition(params), params)?;
                body.radar = read_radars(inputs, &picked)?;
                for &i in &picked {
                    body.degraded.insert(
                        i,
                        DegradedEntry {
                            digest: None,
                            empty: false,
                        },
                    );
                }
                for (i, dg) in digests {
                    if let Some(e) = body.degraded.get_mut(&i) {
                        e.digest = Some(dg);
                    }
                }
                for i in empty {
                    if let Some(e) = body.degraded.get_mut(&i) {
                        e.empty = true;
                    }
                }
                body.accs = accs;
                body.geometry = r.body.geometry.clone();
                body.reference_sha256 = Some(r.clear_sha256().to_string());
                label = format!(
                    "partial state of {} degraded recordings of {}",
                    picked.len(),
                    inputs.name
                );
            }
        }
        Ok(FitState {
            header,
            body,
            label,
            clear_sha256: OnceLock::new(),
            reference: OnceLock::new(),
            released: false,
        })
    }

    /// The header and an empty body of a state of `inputs` under `params`
    /// (the campaign checked, its metadata files digested).
    fn skeleton(inputs: &FitInputs, params: &FitValidParams) -> Result<(Header, Body), FitError> {
        inputs.lidar.validate().map_err(|e| FitError::File {
            path: inputs.dir.join("campaign.toml"),
            reason: e.to_string(),
        })?;
        let clear_pos = clear_positions(inputs);
        if clear_pos.is_empty() {
            return Err(FitError::NoClearReference {
                path: inputs.dir.clone(),
                reason: "no recording was selected as clear (rules and review), so no degraded recording can be paired".into(),
            });
        }
        let meta: Vec<Result<(PathBuf, String), FitError>> = inputs
            .metadata
            .par_iter()
            .map(|p| Ok((p.clone(), sha256_hex(&read_file(p)?))))
            .collect();
        let metadata = meta.into_iter().collect::<Result<Vec<_>, _>>()?;
        let header = Header {
            tool: TOOL.to_string(),
            params_sha256: params_sha256(params),
            campaign_sha256: campaign_sha256(inputs, &metadata),
        };
        let body = Body {
            params: params.clone(),
            inputs: inputs.clone(),
            metadata,
            geometry: None,
            clear: BTreeMap::new(),
            reference_sha256: None,
            degraded: BTreeMap::new(),
            accs: BTreeMap::new(),
            radar: BTreeMap::new(),
        };
        Ok((header, body))
    }

    /// Maps every recording (both phases) into one complete state: what
    /// [`FitValidParams::fit_inputs`] finishes.
    pub fn map_all(inputs: &FitInputs, params: &FitValidParams) -> Result<FitState, FitError> {
        let clear = FitState::map(inputs, params, &Selection::All, None)?;
        let degraded = FitState::map(inputs, params, &Selection::All, Some(&clear))?;
        clear.merge(degraded)
    }

    /// Maps every recording and finishes: what
    /// [`FitValidParams::fit_inputs`] does. The same statistics as
    /// `map_all(..)?.finish()`, but the clear images (16 bytes per occupied
    /// cell of every clear recording, a campaign's largest summaries) are
    /// released as soon as the reference and the clear part's digest are
    /// built, before the first degraded recording is read
    /// ([`ClearPart`]): at a thousand recordings of HDL-64 size they are
    /// about 300 MB of a fit's peak.
    pub(crate) fn fit_all(
        inputs: &FitInputs,
        params: &FitValidParams,
    ) -> Result<FittedTable, FitError> {
        let clear = ClearPart::map(inputs, params)?;
        FitState::fit_with(inputs, params, clear.state)
    }

    /// Pairs the degraded recordings of `inputs` against a released clear
    /// part of the same clear recordings and finishes.
    fn fit_with(
        inputs: &FitInputs,
        params: &FitValidParams,
        clear: FitState,
    ) -> Result<FittedTable, FitError> {
        let degraded = FitState::map(inputs, params, &Selection::All, Some(&clear))?;
        clear.merge(degraded)?.finish()
    }

    /// How errors name this state: its file when read from one.
    pub fn label(&self) -> &str {
        &self.label
    }

    /// Renames the state in error messages (for example after the file it
    /// is written to).
    pub fn with_label(mut self, label: impl Into<String>) -> FitState {
        self.label = label.into();
        self
    }

    /// The campaign's name.
    pub fn campaign(&self) -> &str {
        &self.body.inputs.name
    }

    /// The fit parameters of the state.
    pub fn params(&self) -> &FitValidParams {
        &self.body.params
    }

    /// Ids of the recordings mapped into this state, in campaign order.
    pub fn recordings(&self) -> Vec<String> {
        let mut idx: Vec<usize> = self
            .body
            .clear
            .keys()
            .chain(self.body.degraded.keys())
            .copied()
            .collect();
        idx.sort_unstable();
        idx.iter()
            .map(|&i| self.body.inputs.recordings[i].id.clone())
            .collect()
    }

    fn missing(&self) -> (Vec<usize>, Vec<usize>) {
        let inputs = &self.body.inputs;
        let clear = clear_positions(inputs)
            .into_iter()
            .filter(|i| !self.body.clear.contains_key(i))
            .collect();
        let degraded = degraded_positions(inputs)
            .into_iter()
            .filter(|i| !self.body.degraded.contains_key(i))
            .collect();
        (clear, degraded)
    }

    /// What the state lacks before it can give a table (`None` when
    /// complete): the clear and degraded recordings not mapped yet.
    pub fn missing_description(&self) -> Option<String> {
        let (c, d) = self.missing();
        let inputs = &self.body.inputs;
        let mut parts = Vec::new();
        if !c.is_empty() {
            parts.push(format!(
                "{} of {} clear recordings not mapped ({})",
                c.len(),
                clear_positions(inputs).len(),
                names(inputs, &c)
            ));
        }
        if !d.is_empty() {
            parts.push(format!(
                "{} of {} degraded recordings not mapped ({}){}",
                d.len(),
                degraded_positions(inputs).len(),
                names(inputs, &d),
                match c.is_empty() && !self.body.clear.is_empty() {
                    true => ": map them with this state (its clear part) as the reference",
                    false => "",
                }
            ));
        }
        (!parts.is_empty()).then(|| parts.join("; "))
    }

    /// Whether the state holds every selected recording (it can be finished).
    pub fn is_complete(&self) -> bool {
        self.missing_description().is_none()
    }

    fn require_clear(&self) -> Result<(), FitError> {
        let (c, _) = self.missing();
        if c.is_empty() {
            return Ok(());
        }
        Err(FitError::Incomplete {
            state: self.label.clone(),
            missing: format!(
                "{} of {} clear recordings not mapped ({}): a reference needs every clear recording",
                c.len(),
                clear_positions(&self.body.inputs).len(),
                names(&self.body.inputs, &c)
            ),
        })
    }

    /// Digest of the clear part (geometry and every clear entry).
    ///
    /// The encoding is hashed as it is written, not gathered first: the
    /// clear entries hold every clear recording's cell image, and a copy of
    /// their encoding beside them was as large again (at 200 clear
    /// recordings of 100 k points, about 300 MB at the peak of a fit's or a
    /// diagnosis's memory). The bytes hashed are the same.
    fn clear_sha256(&self) -> &str {
        self.clear_sha256.get_or_init(|| {
            let cfg = bincode::config::standard();
            let mut w = HashWriter(Sha256::new());
            let h = match bincode::serde::encode_into_std_write(
                (&self.body.geometry, &self.body.clear),
                &mut w,
                cfg,
            ) {
                Ok(_) => w.0,
                // As before: an encoding that fails hashes nothing.
                Err(_) => Sha256::new(),
            };
            h.finalize().iter().map(|b| format!("{b:02x}")).collect()
        })
    }

    /// The clear reference of a state holding every clear recording.
    pub(crate) fn clear_reference(&self) -> Result<Arc<ClearReference>, FitError> {
        if let Some(r) = self.reference.get() {
            return Ok(r.clone());
        }
        self.require_clear()?;
        let inputs = &self.body.inputs;
        let params = &self.body.params;
        let Some((geometry, _)) = &self.body.geometry else {
            return Err(FitError::Incomplete {
                state: self.label.clone(),
                missing: "no measured geometry (no clear recording mapped)".into(),
            });
        };
        let grid = grid_of(geometry, inputs, params);
        // Borrowed, not loaded: the reference reads the images a block of
        // rings at a time, from memory or the map's temporary file.
        let images: Vec<&StoredImage> = self
            .body
            .clear
            .values()
            .filter_map(|e| e.image.as_ref())
            .collect();
        let n_clear = self.body.clear.len();
        if images.is_empty() {
            return Err(FitError::NoClearReference {
                path: inputs.dir.clone(),
                reason: format!("every one of the {n_clear} clear recordings holds no point"),
            });
        }
        let reference = ClearReference::build_from(grid, &StoredImages::new(&images), params)?;
        if reference.present().is_empty() {
            return Err(FitError::NoClearReference {
                path: inputs.dir.clone(),
                reason: format!(
                    "the {} clear recordings share no stable return (presence ≥ {})",
                    images.len(),
                    params.reference_min_presence()
                ),
            });
        }
        Ok(self.reference.get_or_init(|| Arc::new(reference)).clone())
    }

    /// Checks that `other` is a state of the same murk, parameters and
    /// campaign; the error names both states and what differs.
    fn compatible(&self, other: &FitState) -> Result<(), FitError> {
        let err = |reason: String| FitError::StateMismatch {
            a: self.label.clone(),
            b: other.label.clone(),
            reason,
        };
        let (a, b) = (&self.header, &other.header);
        if a.tool != b.tool {
            return Err(err(format!(
                "written by {} and {}: states of different murk versions cannot be merged",
                a.tool, b.tool
            )));
        }
        if a.params_sha256 != b.params_sha256 {
            let (pa, pb) = (self.body.params.to_json(), other.body.params.to_json());
            let mut diff = Vec::new();
            if let (Some(oa), Some(ob)) = (pa.as_object(), pb.as_object()) {
                for (k, va) in oa {
                    if ob.get(k) != Some(va) {
                        diff.push(format!(
                            "{k} = {va} vs {}",
                            ob.get(k).cloned().unwrap_or_default()
                        ));
                    }
                }
            }
            return Err(err(format!(
                "fitted with different parameters ({})",
                diff.join(", ")
            )));
        }
        if a.campaign_sha256 != b.campaign_sha256 {
            let (ia, ib) = (&self.body.inputs, &other.body.inputs);
            let ids = |i: &FitInputs| {
                i.recordings
                    .iter()
                    .map(|r| r.id.clone())
                    .collect::<Vec<_>>()
            };
            let what = if ia.name != ib.name {
                format!("campaigns {:?} and {:?}", ia.name, ib.name)
            } else if ids(ia) != ids(ib) {
                format!(
                    "campaign {:?} with different selected recordings ({} vs {})",
                    ia.name,
                    ia.recordings.len(),
                    ib.recordings.len()
                )
            } else if self.body.metadata.iter().map(|m| &m.1).ne(other
                .body
                .metadata
                .iter()
                .map(|m| &m.1))
            {
                format!(
                    "campaign {:?} with different metadata files (campaign.toml, weather.csv, review, rules)",
                    ia.name
                )
            } else {
                format!(
                    "campaign {:?} with different recording classes, MORs or LiDAR description",
                    ia.name
                )
            };
            return Err(err(format!("states of different campaigns: {what}")));
        }
        Ok(())
    }

    /// Merges two states of the same campaign and parameters: counts are
    /// summed and per-recording rows united (the result does not depend on
    /// the order or grouping of merges). A recording mapped in both, or
    /// degraded recordings paired against different clear references, are
    /// errors naming both states.
    pub fn merge(self, other: FitState) -> Result<FitState, FitError> {
        self.compatible(&other)?;
        let err = |reason: String| FitError::StateMismatch {
            a: self.label.clone(),
            b: other.label.clone(),
            reason,
        };
        let both: Vec<usize> = self
            .body
            .clear
            .keys()
            .filter(|k| other.body.clear.contains_key(k))
            .chain(
                self.body
                    .degraded
                    .keys()
                    .filter(|k| other.body.degraded.contains_key(k)),
            )
            .copied()
            .collect();
        if !both.is_empty() {
            return Err(err(format!(
                "{} recordings are in both ({}): each recording must be mapped once",
                both.len(),
                names(&self.body.inputs, &both)
            )));
        }
        match (&self.body.reference_sha256, &other.body.reference_sha256) {
            (Some(x), Some(y)) if x != y => {
                return Err(err(
                    "their degraded recordings were paired against different clear references"
                        .into(),
                ));
            }
            _ => {}
        }
        // A complete clear part must be the one the degraded part was paired
        // against.
        for (c, d) in [(&self, &other), (&other, &self)] {
            if let Some(r) = &d.body.reference_sha256
                && !c.body.clear.is_empty()
                && c.missing().0.is_empty()
                && c.clear_sha256() != r
            {
                return Err(FitError::StateMismatch {
                    a: c.label.clone(),
                    b: d.label.clone(),
                    reason: format!(
                        "the degraded recordings of {} were paired against a different clear reference than the clear recordings of {}",
                        d.label, c.label
                    ),
                });
            }
        }
        if let (Some(x), Some(y)) = (&self.body.geometry, &other.body.geometry)
            && x != y
        {
            return Err(err("they measured different firing geometries".into()));
        }
        let label = match self.label.len() + other.label.len() < 160 {
            true => format!("{} + {}", self.label, other.label),
            false => format!("merged state of {}", self.body.inputs.name),
        };
        // Caches of the clear part survive when only one side has one.
        let (clear_sha256, reference) =
            match (self.body.clear.is_empty(), other.body.clear.is_empty()) {
                (false, true) => (self.clear_sha256.clone(), self.reference.clone()),
                (true, false) => (other.clear_sha256.clone(), other.reference.clone()),
                _ => (OnceLock::new(), OnceLock::new()),
            };
        let released = self.released || other.released;
        let FitState {
            header, mut body, ..
        } = self;
        let o = other.body;
        body.geometry = body.geometry.or(o.geometry);
        body.reference_sha256 = body.reference_sha256.or(o.reference_sha256);
        body.clear.extend(o.clear);
        body.degraded.extend(o.degraded);
        body.radar.extend(o.radar);
        for (k, a) in o.accs {
            match body.accs.get_mut(&k) {
                Some(m) => m.merge(a),
                None => {
                    body.accs.insert(k, a);
                }
            }
        }
        for a in body.accs.values_mut() {
            a.finish();
        }
        Ok(FitState {
            header,
            body,
            label,
            clear_sha256,
            reference,
            released,
        })
    }

    /// The table of a complete state; an incomplete one is an error saying
    /// which recordings are missing.
    pub fn finish(&self) -> Result<FittedTable, FitError> {
        if let Some(missing) = self.missing_description() {
            return Err(FitError::Incomplete {
                state: self.label.clone(),
                missing,
            });
        }
        if let Some(r) = &self.body.reference_sha256
            && r != self.clear_sha256()
        {
            return Err(FitError::State {
                state: self.label.clone(),
                reason: "its degraded recordings were paired against a different clear reference than its clear recordings".into(),
            });
        }
        let reference = self.clear_reference()?;
        let b = &self.body;
        let inputs = &b.inputs;
        let Some((geometry, warnings)) = b.geometry.clone() else {
            return Err(FitError::Incomplete {
                state: self.label.clone(),
                missing: "no measured geometry (no clear recording mapped)".into(),
            });
        };
        let empty_clear: Vec<ExcludedRecording> = b
            .clear
            .iter()
            .filter(|(_, e)| e.image.is_none())
            .map(|(&i, _)| crate::driver::empty_recording(&inputs.recordings[i]))
            .collect();
        let mut digests: Vec<(PathBuf, String)> = b
            .clear
            .iter()
            .map(|(&i, e)| (inputs.recordings[i].lidar.clone(), e.digest.clone()))
            .collect();
        digests.extend(
            b.degraded.iter().filter_map(|(&i, e)| {
                Some((inputs.recordings[i].lidar.clone(), e.digest.clone()?))
            }),
        );
        let empty_degraded: Vec<usize> = b
            .degraded
            .iter()
            .filter(|(_, e)| e.empty)
            .map(|(&i, _)| i)
            .collect();
        crate::algorithm::assemble_table(crate::algorithm::Parts {
            inputs,
            params: &b.params,
            geometry: (self.geometry_for_table(geometry), warnings),
            reference: &reference,
            empty_clear,
            lidar_digests: digests,
            empty_degraded,
            accs: &b.accs,
            radar: &b.radar,
            metadata: &b.metadata,
        })
    }

    fn geometry_for_table(&self, measured: SensorGeometry) -> SensorGeometry {
        match self.body.params.declared_geometry() {
            true => crate::geometry::declared(&self.body.inputs.lidar),
            false => measured,
        }
    }

    /// The state's bytes: magic, [`STATE_FORMAT`], header, body (bincode),
    /// SHA-256 of all before it.
    pub fn to_bytes(&self) -> Result<Vec<u8>, FitError> {
        if self.released {
            return Err(FitError::State {
                state: self.label.clone(),
                reason: "its clear images were released once its reference was built; only a state that keeps them can be written".into(),
            });
        }
        let cfg = bincode::config::standard();
        let enc = |e: bincode::error::EncodeError| FitError::State {
            state: self.label.clone(),
            reason: format!("cannot encode: {e}"),
        };
        let header = bincode::serde::encode_to_vec(&self.header, cfg).map_err(enc)?;
        let body = bincode::serde::encode_to_vec(&self.body, cfg).map_err(enc)?;
        let mut out = Vec::with_capacity(body.len() + header.len() + 64);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&STATE_FORMAT.to_le_bytes());
        out.extend_from_slice(&(header.len() as u64).to_le_bytes());
        out.extend_from_slice(&header);
        out.extend_from_slice(&(body.len() as u64).to_le_bytes());
        out.extend_from_slice(&body);
        let sum = Sha256::digest(&out);
        out.extend_from_slice(&sum);
        Ok(out)
    }

    /// Reads a state from its bytes; `label` names it in errors (its file).
    /// A truncated or corrupted state, one of another format or murk
    /// version, or one whose parameters do not pass the check, is an error.
    pub fn from_bytes(bytes: &[u8], label: &str) -> Result<FitState, FitError> {
        let bad = |reason: String| FitError::State {
            state: label.to_string(),
            reason,
        };
        if bytes.len() < MAGIC.len() + 4 || &bytes[..MAGIC.len()] != MAGIC {
            return Err(bad(
                "not a murk fit state (written by `murk fit --partial`)".into(),
            ));
        }
        let mut at = MAGIC.len();
        let format = u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap_or_default());
        at += 4;
        if format != STATE_FORMAT {
            return Err(bad(format!(
                "state format {format}; this murk ({TOOL}) reads format {STATE_FORMAT}"
            )));
        }
        let truncated = || bad(format!("truncated ({} bytes)", bytes.len()));
        let header_bytes = take(bytes, &mut at).ok_or_else(truncated)?;
        let body_bytes = take(bytes, &mut at).ok_or_else(truncated)?;
        let sum = bytes.get(at..at + 32).ok_or_else(truncated)?;
        if bytes.len() != at + 32 {
            return Err(bad(format!(
                "{} bytes after the checksum: not one state file",
                bytes.len() - at - 32
            )));
        }
        if Sha256::digest(&bytes[..at]).as_slice() != sum {
            return Err(bad("corrupted (checksum mismatch)".into()));
        }
        let cfg = bincode::config::standard();
        let (header, _): (Header, usize) = bincode::serde::decode_from_slice(header_bytes, cfg)
            .map_err(|e| bad(format!("corrupted header: {e}")))?;
        if header.tool != TOOL {
            return Err(bad(format!(
                "written by {}; this is {TOOL}: states of different murk versions cannot be merged",
                header.tool
            )));
        }
        let (body, _): (Body, usize) = bincode::serde::decode_from_slice(body_bytes, cfg)
            .map_err(|e| bad(format!("corrupted body: {e}")))?;
        let params = FitParams::from_valid(body.params.clone())
            .check()
            .map_err(|e| bad(format!("its parameters do not pass the check: {e}")))?;
        if params_sha256(&params) != header.params_sha256
            || campaign_sha256(&body.inputs, &body.metadata) != header.campaign_sha256
        {
            return Err(bad("corrupted: its header does not match its body".into()));
        }
        Ok(FitState {
            header,
            body,
            label: label.to_string(),
            clear_sha256: OnceLock::new(),
            reference: OnceLock::new(),
            released: false,
        })
    }

    /// Reads a state file written by [`FitState::write`].
    pub fn read(path: &Path) -> Result<FitState, FitError> {
        let bytes = read_file(path)?;
        FitState::from_bytes(&bytes, &path.display().to_string())
    }

    /// Writes the state atomically (temporary file, then rename).
    pub fn write(&self, path: &Path) -> Result<(), FitError> {
        crate::write_atomic(path, &self.to_bytes()?)
    }
}

/// The length-prefixed (u64 little-endian) slice at `at`, moving `at`
/// past it; `None` when the bytes end first.
fn take<'a>(bytes: &'a [u8], at: &mut usize) -> Option<&'a [u8]> {
    let n = u64::from_le_bytes(bytes.get(*at..at.checked_add(8)?)?.try_into().ok()?);
    let start = *at + 8;
    let end = start.checked_add(usize::try_from(n).ok()?)?;
    let slice = bytes.get(start..end)?;
    *at = end;
    Some(slice)
}

fn grid_of(geometry: &SensorGeometry, inputs: &FitInputs, params: &FitValidParams) -> CellGrid {
    match params.declared_geometry() {
        true => CellGrid::from_geometry(&crate::geometry::declared(&inputs.lidar)),
        false => CellGrid::from_geometry(geometry),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_clear_digest_is_the_hash_of_the_whole_encoding() {
        // Hashed as written, it must be the digest of the encoding gathered
        // in one buffer (what it was, and what other states hold).
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/default-campaign");
        let inputs = FitInputs::from_campaign(&murk_campaign::Campaign::open(&dir).unwrap());
        let params = crate::FitParams::default().check().unwrap();
        let state = FitState::map(&inputs, &params, &Selection::All, None).unwrap();
        assert!(!state.body.clear.is_empty());
        let bytes = bincode::serde::encode_to_vec(
            (&state.body.geometry, &state.body.clear),
            bincode::config::standard(),
        )
        .unwrap();
        assert!(bytes.len() > 100_000, "{}", bytes.len());
        assert_eq!(state.clear_sha256(), sha256_hex(&bytes));
    }
}
