//! Radar no-change rates (the seed's §4.3, Table 7).
//!
//! Radar detections are sparse and have no fixed firing grid, so they are
//! paired by nearest neighbour (kiddo k-d trees) within a distance tolerance
//! instead of by cell:
//!
//! 1. **Reference.** A detection of a clear recording is a reference
//!    candidate when detections of at least `radar_min_presence` of the other
//!    clear recordings lie within the tolerance (it recurs: a structure, not
//!    noise). Candidates are thinned so that no two reference points are
//!    within the tolerance of each other, most recurrent first.
//! 2. **Rate.** A recording's no-change rate is the share of reference points
//!    that have one of its detections within the tolerance.
//! 3. **Clear baseline.** Each clear recording is scored against a reference
//!    built without it: the clear recordings are split into `k = min(n, 10)`
//!    interleaved folds and each fold is scored against the reference of the
//!    others, so the baseline does not score a recording against itself.

use kiddo::{ImmutableKdTree, SquaredEuclidean};

/// One radar recording's detections, `[x, y, z]` metres.
pub type Detections = Vec<[f64; 3]>;

type Tree = ImmutableKdTree<f64, 3>;

/// A k-d tree over `points` (which must not be empty).
fn tree(points: &[[f64; 3]]) -> Result<Tree, String> {
    Tree::new_from_slice(points)
        .map_err(|e| format!("cannot index {} detections: {e}", points.len()))
}

/// The radar reference of a set of clear recordings.
#[derive(Debug, Clone, PartialEq)]
pub struct RadarReference {
    points: Vec<[f64; 3]>,
}

/// All clear detections with, per detection, how many *other* recordings of
/// each fold have a detection within the tolerance.
struct Candidates {
    points: Vec<[f64; 3]>,
    rec: Vec<usize>,
    per_fold: Vec<u32>,
    folds: usize,
    /// Neighbours (within tolerance) of each detection, by index.
    near: Vec<Vec<u32>>,
}

impl Candidates {
    fn new(
        clear: &[Detections],
        tol: f64,
        fold_of: &[usize],
        folds: usize,
    ) -> Result<Candidates, String> {
        let mut points = Vec::new();
        let mut rec = Vec::new();
        for (r, d) in clear.iter().enumerate() {
            points.extend_from_slice(d);
            rec.extend(std::iter::repeat_n(r, d.len()));
        }
        let mut per_fold = vec![0u32; points.len() * folds];
        let mut near = Vec::with_capacity(points.len());
        if !points.is_empty() {
            let tree = tree(&points)?;
            let mut seen = vec![usize::MAX; clear.len()];
            for (i, p) in points.iter().enumerate() {
                let mut n: Vec<u32> = tree
                    .query(p)
                    .within::<SquaredEuclidean<f64>>(tol * tol)
                    .unsorted()
                    .execute()
                    .into_iter()
                    .map(|n| n.item)
                    .collect();
                n.sort_unstable();
                for &j in &n {
                    let r = rec[j as usize];
                    if r != rec[i] && seen[r] != i {
                        seen[r] = i;
                        per_fold[i * folds + fold_of[r]] += 1;
                    }
                }
                near.push(n);
            }
        }
        Ok(Candidates {
            points,
            rec,
            per_fold,
            folds,
            near,
        })
    }

    /// The thinned reference from the recordings outside fold `skip` (`None`:
    /// all of them), `n_used` recordings in all.
    fn reference(
        &self,
        fold_of: &[usize],
        skip: Option<usize>,
        n_used: usize,
        min_presence: f64,
    ) -> RadarReference {
        let need = min_presence * n_used.saturating_sub(1) as f64;
        let mut cand: Vec<(u32, usize)> = (0..self.points.len())
            .filter(|&i| skip != Some(fold_of[self.rec[i]]))
            .filter_map(|i| {
                let row = &self.per_fold[i * self.folds..(i + 1) * self.folds];
                let total: u32 = row
                    .iter()
                    .enumerate()
                    .filter(|(f, _)| skip != Some(*f))
                    .map(|(_, c)| *c)
                    .sum();
                (total as f64 >= need).then_some((total, i))
            })
            .collect();
        cand.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
        let mut kept = vec![false; self.points.len()];
        let mut points = Vec::new();
        for (_, i) in cand {
            if self.near[i].iter().any(|&j| kept[j as usize]) {
                continue;
            }
            kept[i] = true;
            points.push(self.points[i]);
        }
        RadarReference { points }
    }
}

impl RadarReference {
    /// The reference of all clear recordings, and each clear recording's
    /// `(paired, reference size)` against the reference of the other folds.
    pub fn build(
        clear: &[Detections],
        tolerance_m: f64,
        min_presence: f64,
    ) -> Result<(RadarReference, Vec<(u64, u64)>), String> {
        let n = clear.len();
        let folds = n.clamp(1, 10);
        let fold_of: Vec<usize> = (0..n).map(|i| i % folds).collect();
        let c = Candidates::new(clear, tolerance_m, &fold_of, folds)?;
        let all = c.reference(&fold_of, None, n, min_presence);
        let mut baseline = vec![(0, 0); n];
        if n >= 2 {
            for f in 0..folds {
                let used = fold_of.iter().filter(|&&g| g != f).count();
                let r = c.reference(&fold_of, Some(f), used, min_presence);
                for (i, d) in clear.iter().enumerate() {
                    if fold_of[i] == f {
                        baseline[i] = r.score(d, tolerance_m)?;
                    }
                }
            }
        }
        Ok((all, baseline))
    }

    /// `(reference points with a detection of `detections` within
    /// `tolerance_m`, reference points)`.
    pub fn score(&self, detections: &[[f64; 3]], tolerance_m: f64) -> Result<(u64, u64), String> {
        let total = self.points.len() as u64;
        if detections.is_empty() || total == 0 {
            return Ok((0, total));
        }
        let tree = tree(detections)?;
        let t2 = tolerance_m * tolerance_m;
        let paired = self
            .points
            .iter()
            .filter(|p| {
                tree.query(p)
                    .nearest_one::<SquaredEuclidean<f64>>()
                    .execute()
                    .distance
                    <= t2
            })
            .count() as u64;
        Ok((paired, total))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng, rngs::ChaCha8Rng};

    /// 100 fixed structures on a plane (z = 0, many equal coordinates), each
    /// seen with probability `p` and 5 cm jitter, plus 20 noise detections.
    fn recording(p: f64, rng: &mut ChaCha8Rng) -> Detections {
        let mut d = Vec::new();
        for k in 0..100 {
            if rng.random_range(0.0..1.0) < p {
                let (x, y) = ((k % 10) as f64 * 5.0, (k / 10) as f64 * 5.0);
                d.push([
                    x + rng.random_range(-0.05..0.05),
                    y + rng.random_range(-0.05..0.05),
                    0.0,
                ]);
            }
        }
        for _ in 0..20 {
            d.push([
                rng.random_range(0.0..50.0),
                rng.random_range(60.0..90.0),
                0.0,
            ]);
        }
        d
    }

    #[test]
    fn rates_follow_the_detection_probability() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let clear: Vec<Detections> = (0..12).map(|_| recording(0.97, &mut rng)).collect();
        let (r, base) = RadarReference::build(&clear, 0.5, 0.5).unwrap();
        // The 100 structures, none of the noise.
        assert_eq!(r.points.len(), 100);
        let (k, t): (u64, u64) = base.iter().fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        // 1 200 trials at p = 0.97: SE 0.005; allow 0.02.
        assert!((k as f64 / t as f64 - 0.97).abs() < 0.02, "{k}/{t}");
        let foggy: Vec<Detections> = (0..12).map(|_| recording(0.9, &mut rng)).collect();
        let (k, t) = foggy
            .iter()
            .map(|d| r.score(d, 0.5).unwrap())
            .fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        assert!((k as f64 / t as f64 - 0.9).abs() < 0.03, "{k}/{t}");
    }

    #[test]
    fn empty_recording_pairs_nothing() {
        let r = RadarReference {
            points: vec![[0.0, 0.0, 0.0]],
        };
        assert_eq!(r.score(&[], 0.5), Ok((0, 1)));
    }
}
