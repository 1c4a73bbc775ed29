//! Near-range returns: ghost points (3–10 m) and the ring / "fake wall"
//! (< 3 m) of the seed report §3.4.5, placed on the sensor's rays as the
//! fog paper's perturbation step 3 describes (seed 004 §4.2).
//!
//! For each kind, the number of returns of a scan is Poisson with the
//! table's expected count at the MOR; each return draws its range and
//! calibrated reflectivity from the table's (truncated) Gaussian laws and a
//! ray: a ring drawn uniformly among the rings the input scan has, and an
//! azimuth drawn uniformly on the sensor's azimuth grid (each ring's grid
//! shifted onto the scan's own firings where they keep one phase, so that
//! a wedge holds its firing's return and not half of two). With count terms
//! along `ring`, `elevation` or `azimuth` (from `murk diagnose`) the rings
//! and azimuths are drawn in proportion to the terms' values and the
//! expected counts scale with their means ([`murk_types::RayDensity`]).
//! With count terms along the returns' own `range` (the seed-004 per-echo
//! range law), each kind's distance is drawn from its truncated Gaussian
//! reweighted by the terms — tabulated once per applier over
//! equal-probability cells of the law ([`murk_types::RangeCells`]), still
//! one uniform per draw — and its expected count scales by the terms' mean
//! under that law.
//! Then, on that ray:
//!
//! - if the ray has returns (after vanishing), one of them is the return of
//!   the firing the soft target interrupts (drawn uniformly: an accumulated
//!   recording holds many revolutions of the same ray). When the soft target
//!   is closer, it **replaces** that return: same beam direction, same ring
//!   and time, the soft target's range and reflectivity. When it is farther,
//!   the target hides it: it is **occluded** and nothing changes. Where the
//!   table's occlusion test found the weather's near returns *replace* the
//!   returns it loses ([`murk_types::OcclusionTest`]: a strongest-return
//!   sensor reports the fog's echo only where the hard echo is gone), the
//!   soft target's ray is instead one of the scan's rays drawn uniformly:
//!   a kept return's (the soft target is **occluded**, whatever its
//!   range), a lost return's (it is **added** in front of it, along its
//!   beam) or the sky's (**added** on a wedge without a return);
//! - if the ray has no return (sky, or everything on it vanished), the soft
//!   target is the only echo: it is **added** on the grid ray, at the ring's
//!   elevation (from the sensor description, else measured on the scan as
//!   `atan2(Σz, Σ√(x²+y²))` over the ring's points).
//!
//! Draws happen in a fixed order from one stream (ghost count, ring count,
//! then per return: ring, azimuth, range, reflectivity, pick, time), so the
//! result does not depend on threads.

use std::collections::HashMap;

use murk_types::{LidarSpec, PointCloud, RayDensity};
use rand::RngExt;
use rand::rngs::ChaCha8Rng;
use rand_distr::{Distribution, Poisson};
use rayon::prelude::*;
use serde::Serialize;

use crate::error::InferError;
use crate::model::NearLaw;
use crate::sampling::{CHUNK, Purpose, ScanSeed};

/// What became of the near-range returns of one kind in one scan.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
#[non_exhaustive]
pub struct NearRangeCounts {
    /// Expected count per scan (the Poisson mean).
    pub expected: f64,
    /// Where the expectation comes from: `count_law` or `points_per_scan`.
    pub count_source: &'static str,
    /// Returns drawn.
    pub drawn: u64,
    /// Returns that replaced a farther return of their ray.
    pub replaced: u64,
    /// Returns added on an empty ray.
    pub added: u64,
    /// Returns hidden by a closer return on their ray (or by a later, closer
    /// soft target on the same return).
    pub occluded: u64,
    /// Returns that could not be placed: the scan has no ring to put them on.
    pub unplaced: u64,
}

impl NearRangeCounts {
    /// Adds another scan's counts (the expectation adds too).
    pub fn add(&mut self, o: &NearRangeCounts) {
        self.expected += o.expected;
        if self.count_source.is_empty() {
            self.count_source = o.count_source;
        }
        self.drawn += o.drawn;
        self.replaced += o.replaced;
        self.added += o.added;
        self.occluded += o.occluded;
        self.unplaced += o.unplaced;
    }

    /// Returns present in the output (replaced + added).
    pub fn in_output(&self) -> u64 {
        self.replaced + self.added
    }
}

/// Settings the near-range step needs.
pub(crate) struct NearSettings<'a> {
    pub ghost: Option<&'a NearLaw>,
    pub ring: Option<&'a NearLaw>,
    pub lidar: Option<&'a LidarSpec>,
    pub azimuth_resolution_deg: f64,
    /// Count the sky's rays of a replacing weather on each scan's measured
    /// firing step ([`scan_step`]), `azimuth_resolution_deg` only where
    /// the scan shows none.
    pub measure_azimuth_step: bool,
    /// Where the returns fall over the rays (the table's point-level count
    /// terms; uniform without them).
    pub density: &'a RayDensity,
    /// A near return is the weather's echo where the hard one was lost (a
    /// strongest-return sensor, as the table's occlusion test found): on a
    /// ray that still has a return it is not reported, whatever its range.
    pub replaces_lost: bool,
    /// Per point of the input scan, 1 when it was kept (vanishing's mask):
    /// where `replaces_lost` places its soft targets.
    pub kept: &'a [u8],
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Outcome {
    Replaced,
    Added,
    Occluded,
    Unplaced,
}

/// One drawn soft target.
struct Event {
    ghost: bool,
    ring: u16,
    distance: f64,
    reflectivity: f64,
    pick: f64,
    time: f64,
    /// Wedge edges (unit vectors) of the azimuth bin.
    d0: (f32, f32),
    d1: (f32, f32),
    /// Centre of the wedge, degrees: where an added return goes.
    azimuth_deg: f64,
}

/// Per ring (index up to the largest in `rings`), the phase of the scan's
/// firings on the azimuth grid of `res` degrees: the circular mean of
/// `azimuth mod res`, so that the wedges a soft target looks for its ray in
/// are centred on the firings rather than split by them (a scan firing
/// half a step off the grid would otherwise put two returns in one wedge
/// and none in the next, and a soft target on the empty one would read the
/// ray as empty). 0 where the firings show no single phase (resultant
/// length under ½: a free-running or sparse ring) and where the phase is
/// within 10⁻⁶ of a step of the grid's (the grid as it was). Read on at
/// most [`PHASE_SAMPLES`] points, spread over the scan by the golden-ratio
/// sequence (a plain stride could fall in step with the rings' order and
/// read one ring only): a phase needs few firings, and the pass costs three
/// trigonometric calls a point.
fn ring_phases(input: &PointCloud, rings: &[u16], res: f64) -> Vec<f64> {
    let n = rings.last().map_or(0, |&r| r as usize + 1);
    let mut sums = vec![(0.0f64, 0.0f64, 0u64); n];
    let k = std::f64::consts::TAU / res;
    let points = input.len();
    for j in 0..points.min(PHASE_SAMPLES) {
        let i = if points <= PHASE_SAMPLES {
            j
        } else {
            ((j as f64 * GOLDEN).fract() * points as f64) as usize
        };
        if let Some(s) = sums.get_mut(input.ring[i] as usize) {
            let az = (input.y[i] as f64).atan2(input.x[i] as f64).to_degrees();
            let t = az * k;
            s.0 += t.cos();
            s.1 += t.sin();
            s.2 += 1;
        }
    }
    sums.iter()
        .map(|&(c, si, m)| {
            if m == 0 || (c * c + si * si).sqrt() < 0.5 * m as f64 {
                return 0.0;
            }
            let phase = si.atan2(c) / k;
            if phase.abs() < 1e-6 * res { 0.0 } else { phase }
        })
        .collect()
}

/// The firing step of a scan, degrees dividing the turn: the step of the
/// azimuth differences between consecutive returns of each ring (file
/// order, which is firing order) over its first [`STEP_POINTS`] points, by
/// the estimator that measures the fit's clear recordings
/// ([`murk_types::firing::mode_step`]). `None` where they show no clear
/// step (a shuffled or sparse file) or one beyond 45°: the given grid
/// stays. A unit's firings are not always its datasheet's (a VLP-16 at
/// 600 rpm fires every 0.398°, not 0.4°): a replacing weather's returns
/// show on the rays without a return, so the sky's number must be the
/// scan's. (The hiding placement keeps the given grid: on it the
/// diagnosis's count terms were measured, and on the measured one the
/// semi-real downward-ghost step fell to p 0.056 — not yet understood.)
fn scan_step(input: &PointCloud) -> Option<f64> {
    use murk_types::firing::{MIN_STEP_DEG, azimuth_deg, circ_diff, firings_per_turn, mode_step};
    let m = input.len().min(STEP_POINTS);
    let mut last: Vec<f64> = Vec::new();
    let mut diffs = Vec::with_capacity(m);
    for i in 0..m {
        let (x, y) = (input.x[i], input.y[i]);
        if !(x.is_finite() && y.is_finite()) || (x == 0.0 && y == 0.0) {
            continue;
        }
        let r = input.ring[i] as usize;
        if r >= last.len() {
            last.resize(r + 1, f64::NAN);
        }
        let az = azimuth_deg(x, y);
        if last[r].is_finite() {
            let d = circ_diff(az, last[r]);
            if d >= MIN_STEP_DEG {
                diffs.push(d as f32);
            }
        }
        last[r] = az;
    }
    let (step, _) = mode_step(&diffs)?;
    (step <= 45.0).then(|| firings_per_turn(step).1)
}

/// Points a scan's firing step is read on at most.
const STEP_POINTS: usize = 16_384;

/// Points a scan's firing phases are read on at most.
const PHASE_SAMPLES: usize = 4096;
/// `(√5 − 1)/2`, the step of the sample sequence.
const GOLDEN: f64 = 0.618_033_988_749_894_9;

/// The distinct ring ids of `cloud`, ascending.
fn present_rings(cloud: &PointCloud) -> Vec<u16> {
    const WORDS: usize = 1 << 10; // 65536 bits
    let bits = cloud
        .ring
        .par_chunks(CHUNK)
        .map(|c| {
            let mut b = vec![0u64; WORDS];
            for &r in c {
                b[(r >> 6) as usize] |= 1 << (r & 63);
            }
            b
        })
        .reduce(
            || vec![0u64; WORDS],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(&b) {
                    *x |= y;
                }
                a
            },
        );
    (0..=u16::MAX)
        .filter(|&r| bits[(r >> 6) as usize] >> (r & 63) & 1 == 1)
        .collect()
}

fn poisson(rng: &mut ChaCha8Rng, lambda: f64) -> u64 {
    if lambda > 0.0 {
        // `NearLaw::new` bounds λ, so construction cannot fail.
        Poisson::new(lambda).map_or(0, |p| p.sample(rng) as u64)
    } else {
        0
    }
}

/// Adds the near-range returns of one scan to `out` (the scan after
/// vanishing and perturbation); `input` is the scan as read. The indices
/// of `out` whose point a soft target replaced go to `replaced`, ascending
/// (a writer that copies the other cells of a row must not give them to
/// a fog echo).
pub(crate) fn add_near_range(
    input: &PointCloud,
    out: &mut PointCloud,
    s: &NearSettings<'_>,
    seed: ScanSeed,
    key: &str,
    warnings: &mut Vec<String>,
    replaced: &mut Vec<usize>,
) -> Result<(Option<NearRangeCounts>, Option<NearRangeCounts>), InferError> {
    let mut rings = present_rings(input);
    if let Some(spec) = s.lidar {
        if let Some(&bad) = rings.iter().find(|&&r| r as usize >= spec.rings()) {
            let point = input.ring.iter().position(|&r| r == bad).unwrap_or(0);
            return Err(InferError::RingOutsideSpec {
                scan: key.to_string(),
                point,
                ring: bad,
                rings: spec.rings(),
            });
        }
        if rings.is_empty() {
            rings = (0..spec.rings() as u16).collect();
        }
    }

    let res = s.azimuth_resolution_deg;
    let bins = ((360.0 / res).round() as u64).max(1);
    // Point-level count terms: cumulative weights of the rings and azimuth
    // bins, and the factor on the expected counts.
    let (ring_cdf, bin_cdf, total) = if s.density.is_uniform() {
        (None, None, 1.0)
    } else {
        let g = if s.density.has_beam_terms() && !rings.is_empty() {
            let elevation: Vec<f64> = match s.lidar {
                Some(spec) => rings
                    .iter()
                    .map(|&r| spec.elevation_deg.get(r as usize).copied().unwrap_or(0.0))
                    .collect(),
                None => {
                    let max = *rings.last().unwrap_or(&0) as usize;
                    let mut needs = vec![false; max + 1];
                    for &r in &rings {
                        needs[r as usize] = true;
                    }
                    let el = measured_elevation(input, &needs);
                    rings.iter().map(|&r| el[r as usize].to_degrees()).collect()
                }
            };
            let with: Vec<(u16, f64)> = rings.iter().copied().zip(elevation).collect();
            s.density.ring_weights(&with)
        } else {
            Vec::new()
        };
        let h = if s.density.has_azimuth_terms() {
            let az: Vec<f64> = (0..bins).map(|b| b as f64 * res).collect();
            s.density.azimuth_weights(&az)
        } else {
            Vec::new()
        };
        let total = s.density.total_factor(&g, &h);
        (cumulative(&g), cumulative(&h), total)
    };
    let mut rng = seed.rng(Purpose::NearRange, 0);
    // The range terms' factor comes with each law (`NearLaw::range_factor`).
    let expected = |l: &NearLaw| l.expected * total * l.range_factor;
    let n_ghost = s.ghost.map_or(0, |l| poisson(&mut rng, expected(l)));
    let n_ring = s.ring.map_or(0, |l| poisson(&mut rng, expected(l)));
    let (tmin, tmax) = match &input.time {
        Some(t) if !t.is_empty() => t
            .par_iter()
            .fold(
                || (f32::INFINITY, f32::NEG_INFINITY),
                |(a, b), &v| (a.min(v), b.max(v)),
            )
            .reduce(
                || (f32::INFINITY, f32::NEG_INFINITY),
                |(a, b), (c, d)| (a.min(c), b.max(d)),
            ),
        _ => (0.0, 0.0),
    };

    let phase = if n_ghost + n_ring > 0 {
        ring_phases(input, &rings, res)
    } else {
        Vec::new()
    };
    let grid = Wedges {
        rings: &rings,
        phase: &phase,
        res,
        bins,
    };
    let mut events = Vec::with_capacity((n_ghost + n_ring) as usize);
    for (law, n, ghost) in [(s.ghost, n_ghost, true), (s.ring, n_ring, false)] {
        let Some(law) = law else { continue };
        for _ in 0..n {
            let ring_u: f64 = rng.random();
            let bin = match &bin_cdf {
                None => rng.random_range(0..bins),
                Some(c) => pick_index(c, rng.random()) as u64,
            };
            let distance = law.sample_distance(&mut rng);
            let reflectivity = law.reflectivity.sample(&mut rng);
            let pick: f64 = rng.random();
            let time_u: f64 = rng.random();
            let ring = if rings.is_empty() {
                u16::MAX
            } else if let Some(c) = &ring_cdf {
                rings[pick_index(c, ring_u)]
            } else {
                rings[((ring_u * rings.len() as f64) as usize).min(rings.len() - 1)]
            };
            let centre = grid.azimuth_deg(ring, bin);
            let a0 = (centre - 0.5 * res).to_radians();
            let a1 = (centre + 0.5 * res).to_radians();
            events.push(Event {
                ghost,
                ring,
                distance,
                reflectivity,
                pick,
                time: tmin as f64 + time_u * (tmax as f64 - tmin as f64),
                d0: (a0.cos() as f32, a0.sin() as f32),
                d1: (a1.cos() as f32, a1.sin() as f32),
                azimuth_deg: centre,
            });
        }
    }

    let mut outcome = vec![Outcome::Unplaced; events.len()];
    if rings.is_empty() && !events.is_empty() {
        warnings.push(format!(
            "scan {key}: {} near-range returns not placed: the scan has no point, hence no ring, and no sensor description was given",
            events.len()
        ));
    } else if !events.is_empty() {
        if s.replaces_lost {
            // The sky's rays are the scan's firings without a return: on
            // the scan's own step where it shows one.
            let own = s
                .measure_azimuth_step
                .then(|| scan_step(input))
                .flatten()
                .filter(|&st| st != res);
            let own_phase = own.map_or_else(Vec::new, |st| ring_phases(input, &rings, st));
            let fired = own.map(|st| Wedges {
                rings: &rings,
                phase: &own_phase,
                res: st,
                bins: murk_types::firing::firings_per_turn(st).0,
            });
            let sky = fired.as_ref().unwrap_or(&grid);
            place_replacing(input, out, s, &events, &mut outcome, sky);
        } else {
            place(input, out, s, &events, &mut outcome, replaced);
        }
    }

    let tally = |law: Option<&NearLaw>, ghost: bool| {
        law.map(|l| {
            let mut c = NearRangeCounts {
                expected: expected(l),
                count_source: l.count_source,
                ..NearRangeCounts::default()
            };
            for (e, o) in events.iter().zip(&outcome) {
                if e.ghost != ghost {
                    continue;
                }
                c.drawn += 1;
                match o {
                    Outcome::Replaced => c.replaced += 1,
                    Outcome::Added => c.added += 1,
                    Outcome::Occluded => c.occluded += 1,
                    Outcome::Unplaced => c.unplaced += 1,
                }
            }
            c
        })
    };
    Ok((tally(s.ghost, true), tally(s.ring, false)))
}

/// Normalised cumulative sums of `w` (`None` when empty or all zero: the
/// draw is then uniform).
///
/// Not `rand_distr::weighted::WeightedIndex`, on purpose: the ring's
/// weighted draw inverts the same uniform `ring_u` the uniform draw reads
/// (drawn before, for every return), so the rings follow the terms without
/// moving any other draw of the stream; the code without count terms is the
/// old path, untouched, so such tables keep their outputs byte for byte.
fn cumulative(w: &[f64]) -> Option<Vec<f64>> {
    let total: f64 = w.iter().sum();
    if w.is_empty() || !(total > 0.0 && total.is_finite()) {
        return None;
    }
    let mut acc = 0.0;
    Some(
        w.iter()
            .map(|x| {
                acc += x;
                acc / total
            })
            .collect(),
    )
}

/// The index whose cumulative share first exceeds `u` in `[0, 1)`.
fn pick_index(cdf: &[f64], u: f64) -> usize {
    cdf.partition_point(|&c| c <= u).min(cdf.len() - 1)
}

/// The (ring, azimuth) wedges of a scan: its rings, each ring's grid of
/// `bins` wedges of `res` degrees shifted by its firing phase.
struct Wedges<'a> {
    rings: &'a [u16],
    phase: &'a [f64],
    res: f64,
    bins: u64,
}

impl Wedges<'_> {
    /// Number of wedges.
    fn len(&self) -> u64 {
        self.rings.len() as u64 * self.bins
    }

    /// The firing phase of `ring`, degrees (0 where none was measured).
    fn phase(&self, ring: u16) -> f64 {
        self.phase.get(ring as usize).copied().unwrap_or(0.0)
    }

    /// Centre of wedge `bin` of `ring`, degrees.
    fn azimuth_deg(&self, ring: u16, bin: u64) -> f64 {
        self.phase(ring) + bin as f64 * self.res
    }

    /// The wedge of point `i` of `cloud`, if its ring is one of the scan's.
    fn of(&self, cloud: &PointCloud, i: usize) -> Option<u64> {
        let r = self.rings.binary_search(&cloud.ring[i]).ok()?;
        let az = (cloud.y[i] as f64).atan2(cloud.x[i] as f64).to_degrees();
        let b = ((az - self.phase(cloud.ring[i])) / self.res + 0.5).floor() as i64;
        Some(r as u64 * self.bins + b.rem_euclid(self.bins as i64) as u64)
    }

    /// `(ring, azimuth in degrees)` of wedge `w`.
    fn centre(&self, w: u64) -> (u16, f64) {
        let ring = self.rings[(w / self.bins) as usize];
        (ring, self.azimuth_deg(ring, w % self.bins))
    }
}

/// Places the events of a weather whose near returns replace the returns
/// it loses: each event's ray is one of the scan's rays drawn uniformly (its
/// `pick`) — an input return, or one of the rays without one (as many as
/// the sensor's wedges exceed the returns: the sky). On a kept return's ray
/// the event is occluded (the hard echo is the stronger); on a lost
/// return's ray it is added in front of it, along its direction; on the
/// sky it is added on a wedge without an input return (the rest of its
/// `pick` chooses which). So the share of events shown is the share of
/// rays without a kept return, the open share the fit restored the count
/// with (`murk_fit`'s occlusion test), however regular the scan's
/// azimuths are.
fn place_replacing(
    input: &PointCloud,
    out: &mut PointCloud,
    s: &NearSettings<'_>,
    events: &[Event],
    outcome: &mut [Outcome],
    grid: &Wedges<'_>,
) {
    let n = input.len();
    let rays = (n as u64).max(grid.len()).max(1);
    // The wedges without a return, where the sky's events go (needed only
    // when there is sky: more wedges than returns).
    let empty: Vec<u64> = if rays > n as u64 {
        let mut full = vec![false; grid.len() as usize];
        for i in 0..n {
            if let Some(w) = grid.of(input, i) {
                full[w as usize] = true;
            }
        }
        (0..grid.len()).filter(|&w| !full[w as usize]).collect()
    } else {
        Vec::new()
    };
    // The ray of an event and, on the sky, its wedge.
    let ray_of = |ev: &Event| -> (usize, Option<(u16, f64)>) {
        let x = ev.pick * rays as f64;
        let ray = (x as u64).min(rays - 1) as usize;
        if ray < n || empty.is_empty() {
            return (ray, None);
        }
        let k = ((x - ray as f64) * empty.len() as f64) as usize;
        (ray, Some(grid.centre(empty[k.min(empty.len() - 1)])))
    };
    let mut needs = vec![false; grid.rings.last().map_or(0, |&r| r as usize + 1)];
    for ev in events {
        if let (_, Some((ring, _))) = ray_of(ev) {
            needs[ring as usize] = true;
        }
    }
    let elevation = ring_elevations(input, s, &needs);
    let scale = out.intensity_scale;
    for (e, ev) in events.iter().enumerate() {
        let (ray, sky) = ray_of(ev);
        let it = scale.from_calibrated(ev.reflectivity as f32);
        let (x, y, z, ring) = if ray < n {
            if s.kept.get(ray).is_none_or(|&k| k != 0) {
                outcome[e] = Outcome::Occluded;
                continue;
            }
            let (px, py, pz) = (
                input.x[ray] as f64,
                input.y[ray] as f64,
                input.z[ray] as f64,
            );
            let r = (px * px + py * py + pz * pz).sqrt();
            if !(r > 0.0) {
                outcome[e] = Outcome::Occluded;
                continue;
            }
            let f = ev.distance / r;
            (px * f, py * f, pz * f, input.ring[ray])
        } else if let Some((ring, azimuth_deg)) = sky {
            let el = elevation.get(ring as usize).copied().unwrap_or(0.0);
            let (x, y, z) = on_ray(ev.distance, el, azimuth_deg);
            (x, y, z, ring)
        } else {
            // No wedge without a return: the sky is full.
            outcome[e] = Outcome::Occluded;
            continue;
        };
        outcome[e] = Outcome::Added;
        if out.time.is_some() {
            let t = if ray < n {
                input.time.as_ref().map_or(ev.time, |t| t[ray] as f64)
            } else {
                ev.time
            };
            out.push_timed(x as f32, y as f32, z as f32, it, ring, t as f32);
        } else {
            out.push(x as f32, y as f32, z as f32, it, ring);
        }
    }
}

/// The point `distance` metres out at elevation `el` (radians) and azimuth
/// `azimuth_deg`.
fn on_ray(distance: f64, el: f64, azimuth_deg: f64) -> (f64, f64, f64) {
    let az = azimuth_deg.to_radians();
    (
        distance * el.cos() * az.cos(),
        distance * el.cos() * az.sin(),
        distance * el.sin(),
    )
}

/// Elevation (radians) of every ring up to `needs.len()`: the sensor
/// description's, else measured on the scan for the rings `needs` flags
/// (those that get a return added on their own wedge; 0 for the others).
fn ring_elevations(input: &PointCloud, s: &NearSettings<'_>, needs: &[bool]) -> Vec<f64> {
    match s.lidar {
        Some(spec) => (0..needs.len())
            .map(|r| {
                spec.elevation_deg
                    .get(r)
                    .copied()
                    .unwrap_or(0.0)
                    .to_radians()
            })
            .collect(),
        None if needs.iter().any(|&b| b) => measured_elevation(input, needs),
        None => vec![0.0; needs.len()],
    }
}

/// Matches events to the returns of their rays and applies them.
fn place(
    input: &PointCloud,
    out: &mut PointCloud,
    s: &NearSettings<'_>,
    events: &[Event],
    outcome: &mut [Outcome],
    replaced: &mut Vec<usize>,
) {
    // Events by ring.
    let max_ring = events.iter().map(|e| e.ring).max().unwrap_or(0) as usize;
    let mut by_ring: Vec<Vec<u32>> = vec![Vec::new(); max_ring + 1];
    for (i, e) in events.iter().enumerate() {
        by_ring[e.ring as usize].push(i as u32);
    }

    // Candidate returns of every event, in point order.
    let found: Vec<Vec<(u32, u32)>> = out
        .x
        .par_chunks(CHUNK)
        .zip(out.y.par_chunks(CHUNK))
        .zip(out.ring.par_chunks(CHUNK))
        .enumerate()
        .map(|(c, ((x, y), ring))| {
            let mut hits = Vec::new();
            for i in 0..x.len() {
                let Some(list) = by_ring.get(ring[i] as usize) else {
                    continue;
                };
                for &e in list {
                    let ev = &events[e as usize];
                    let c0 = ev.d0.0 * y[i] - ev.d0.1 * x[i];
                    let c1 = ev.d1.0 * y[i] - ev.d1.1 * x[i];
                    if c0 >= 0.0 && c1 < 0.0 {
                        hits.push((e, (c * CHUNK + i) as u32));
                    }
                }
            }
            hits
        })
        .collect();
    let mut candidates: Vec<Vec<usize>> = vec![Vec::new(); events.len()];
    for hits in &found {
        for &(e, i) in hits {
            candidates[e as usize].push(i as usize);
        }
    }

    // Elevation of the rings that need one (added returns, no description).
    let mut needs = vec![false; max_ring + 1];
    for (ev, c) in events.iter().zip(&candidates) {
        if c.is_empty() {
            needs[ev.ring as usize] = true;
        }
    }
    let elevation = ring_elevations(input, s, &needs);

    let scale = out.intensity_scale;
    let mut owner: HashMap<usize, usize> = HashMap::new();
    let mut added = Vec::new();
    for (e, ev) in events.iter().enumerate() {
        let cand = &candidates[e];
        if cand.is_empty() {
            outcome[e] = Outcome::Added;
            added.push(e);
            continue;
        }
        let j = cand[((ev.pick * cand.len() as f64) as usize).min(cand.len() - 1)];
        let (px, py, pz) = (out.x[j] as f64, out.y[j] as f64, out.z[j] as f64);
        let r = (px * px + py * py + pz * pz).sqrt();
        if ev.distance < r && r > 0.0 {
            let f = ev.distance / r;
            out.x[j] = (px * f) as f32;
            out.y[j] = (py * f) as f32;
            out.z[j] = (pz * f) as f32;
            out.intensity[j] = scale.from_calibrated(ev.reflectivity as f32);
            if let Some(prev) = owner.insert(j, e) {
                outcome[prev] = Outcome::Occluded;
            }
            outcome[e] = Outcome::Replaced;
        } else {
            outcome[e] = Outcome::Occluded;
        }
    }
    let first = replaced.len();
    replaced.extend(owner.keys().copied());
    replaced[first..].sort_unstable();
    for e in added {
        let ev = &events[e];
        let el = elevation[ev.ring as usize];
        let (x, y, z) = on_ray(ev.distance, el, ev.azimuth_deg);
        let it = scale.from_calibrated(ev.reflectivity as f32);
        if out.time.is_some() {
            out.push_timed(x as f32, y as f32, z as f32, it, ev.ring, ev.time as f32);
        } else {
            out.push(x as f32, y as f32, z as f32, it, ev.ring);
        }
    }
}

/// `atan2(Σz, Σ√(x²+y²))` over the points of each ring flagged in `needs`.
fn measured_elevation(input: &PointCloud, needs: &[bool]) -> Vec<f64> {
    let n = needs.len();
    let per_chunk = input
        .x
        .par_chunks(CHUNK)
        .zip(input.y.par_chunks(CHUNK))
        .zip(input.z.par_chunks(CHUNK))
        .zip(input.ring.par_chunks(CHUNK))
        .map(|(((x, y), z), ring)| {
            let mut acc = vec![(0f64, 0f64); n];
            for i in 0..x.len() {
                let r = ring[i] as usize;
                if r < n && needs[r] {
                    acc[r].0 += z[i] as f64;
                    acc[r].1 += (x[i] as f64).hypot(y[i] as f64);
                }
            }
            acc
        })
        // Collected, then summed in chunk order: a rayon `reduce` would add
        // in a thread-dependent order, and f64 addition is not associative.
        .collect::<Vec<_>>();
    let mut sums = vec![(0f64, 0f64); n];
    for acc in &per_chunk {
        for (p, q) in sums.iter_mut().zip(acc) {
            p.0 += q.0;
            p.1 += q.1;
        }
    }
    sums.iter().map(|&(sz, sh)| sz.atan2(sh)).collect()
}
