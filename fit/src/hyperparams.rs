//! Hyperparameters of a fit: [`FitParams`] (unchecked, with setters) and
//! [`FitValidParams`] (checked once by [`FitParams::check`], then used by every
//! step).

use serde::Serialize;

use crate::FitError;

/// Shape of the soft survival edge: the shared definition of murk-types
/// (both shapes at unit variance, so the edge width means the same thing
/// whichever is chosen).
pub use murk_types::EdgeShape;

/// Parses the `edge` parameter (`probit`/`normal`, `logistic`/`logit`).
pub fn parse_edge(s: &str) -> Result<EdgeShape, FitError> {
    s.parse::<EdgeShape>()
        .map_err(|reason| FitError::InvalidParam {
            name: "edge",
            value: s.to_string(),
            reason,
        })
}

/// A reflectivity band `[min, max)`; `max = None` is unbounded.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Band {
    /// Lower edge (inclusive), calibrated reflectivity.
    pub min: f64,
    /// Upper edge (exclusive); `None` is unbounded.
    pub max: Option<f64>,
}

impl Band {
    /// The contiguous bands `[e0, e1), [e1, e2), …, [e_last, ∞)` of sorted edges.
    pub fn from_edges(edges: &[f64]) -> Vec<Band> {
        edges
            .iter()
            .enumerate()
            .map(|(i, &min)| Band {
                min,
                max: edges.get(i + 1).copied(),
            })
            .collect()
    }

    /// True when `x` lies in the band.
    pub fn contains(&self, x: f64) -> bool {
        x >= self.min && self.max.is_none_or(|m| x < m)
    }
}

fn yes() -> bool {
    true
}

/// Hyperparameters of a fit, before checking.
///
/// | Name | Default | Purpose | Range |
/// |---|---|---|---|
/// | `quantile` | 0.99 | quantile of the clear range of *no change* returns per MOR bin (the seed's estimator) | (0, 1) |
/// | `mor_bin_width_m` | 10 | width of the MOR bins of the quantile estimate, metres | > 0 |
/// | `band_edges` | [0, 10] | reflectivity bands of the table: `[0,10)`, `[10,∞)` (Table 4) | finite, strictly increasing |
/// | `sweep_edges` | [0, 5, 10, 15, 20, 30, 40, 60, 100] | bands of the slope-vs-reflectivity sweep (Figure 27) | finite, strictly increasing |
/// | `ring_range_m` | [0, 3) | range window of *ring* returns | 0 ≤ lo < hi |
/// | `ghost_range_m` | [3, 10) | range window of *ghost* returns | ring hi ≤ lo < hi |
/// | `pairing_tolerance_m` | 0.5 | absolute range tolerance for a degraded return to pair with the clear one | ≥ 0 |
/// | `pairing_tolerance_rel` | 0.02 | relative range tolerance (the larger of the two applies; a reference cell widens it by how far its firings' ranges wander, at most to twice: see the `reference` module) | ≥ 0 |
/// | `declared_geometry` | false | pair on campaign.toml's azimuth grid instead of the firing grid measured from the clear recordings (see [`observe`](crate::observe)); disagreements are warned either way | |
/// | `azimuth_neighbours` | 1 | azimuth bins either side searched when the own cell does not pair | 0–4 |
/// | `reference_min_presence` | 0.5 | share of clear recordings a cell must return in to enter the reference | (0, 1] |
/// | `reference_min_agreement` | 0.8 | share of a cell's clear recordings whose range must lie within the pairing tolerance of the cell's median for the cell to be stable (a direction that sees one surface in some revolutions and another in others — a depth edge inside the cell, which a free-running unit samples at a new azimuth every revolution — is not a trial: its losses would read as dropout) | [0.5, 1] |
/// | `min_points_per_bin` | 50 | *no change* returns a MOR bin needs for its quantile | ≥ 1 |
/// | `censor_fraction` | 0.02 | a MOR bin is censored when fewer than this share of the band's clear returns lie beyond its quantile (or beyond slope × MOR) | [0, 1) |
/// | `censor_min_points` | 10 | … or fewer than this many | ≥ 0 |
/// | `edge` | probit | shape of the soft survival edge | probit, logistic |
/// | `shared_edge_width` | true | one edge width for all bands (else one per band) | |
/// | `free_dropout` | true | fit the dropout ε per weather (else fix it to the clear-weather value) | |
/// | `edge_test_folds` | 5 | folds over recordings of the held-out test of the edge model against survival by range alone (a slope is reported only when the edge predicts held-out recordings better) | 2–50 |
/// | `require_edge` | true | report a slope only where the held-out edge test sees an edge, null with the test's reason otherwise (false: the slope is kept and the verdict goes in the band's `reason` as a warning). The test's null is "the weather does nothing": each return's clear survival, measured on the clear recordings, times one rate (see `EdgeTest` in murk-types) | |
/// | `apply_bend` | false | write the bending law `a·MOR^b` into a band (`law`, used by `murk apply` and `murk diagnose`) when it predicts held-out recordings better than the line (`law_choice` records the comparison either way). Off by default: on a generated campaign whose survival depends on the beam's elevation (linear truth in r/MOR), the pooled data bend (exponents 1.14 and 1.4, held-out p 1e-5), and `murk diagnose` then reports survival × MOR falsely; a bend chosen from pooled recordings cannot tell a law that bends from a covariate left out | |
/// | `compare_laws` | true | compare the bending law with the line on held-out recordings in every band with a slope (the band's `law_choice`: exponents, their intervals, the held-out gain); false skips it — about 370 survival fits per weather, most of a fit's time — and `law_choice` says it was not compared. `murk diagnose` turns it off for its per-fold baselines, which only need the applied law. Must be true with `apply_bend` | |
/// | `reflectivity_law_edges` | [] (off) | reflectivity classes inside the bands for a reflectivity term in the vanishing law, `D·(max(x, x₀)/x_ref)^k` per band (`x₀` the first edge), fitted beside the chosen law and compared with it on held-out recordings (`law_choice.reflectivity`); written into the bands' `law` when it wins and `apply_bend` is on. The lidar equation in fog gives each return its own distance by its reflectivity, so a band spanning a 25-fold range of reflectivity has no one distance. [`DEFAULT_REFLECTIVITY_LAW_EDGES`] is a grid of ratio 1.5 (`murk fit --reflectivity-law`). Empty: off, the survival histograms keep the bands' classes | finite, > 0, strictly increasing; needs `compare_laws` |
/// | `edge_test_alpha` | 0.01 | level of the one-sided sign-flip test of the held-out gains over recordings (an edge needs at least ⌈log₂(1/α)⌉ recordings: 7 at 1 %) | (0, 0.5] |
/// | `survival_log_step` | 0.01 | bin width of ln(r / MOR) in the survival histogram (1 % in range: far finer than any edge or slope the data resolve) | (0, 0.1] |
/// | `reflectivity_floor` | 0 | lower truncation of the ghost/ring reflectivity laws | finite |
/// | `count_mor_ref_m` | 100 | reference MOR of the count-per-scan power law, metres | > 0 |
/// | `bootstrap_replicates` | 1000 | bootstrap-over-recordings replicates for rate uncertainties (0: none) | 0–100 000 |
/// | `seed` | 0 | seed of the bootstrap | any |
/// | `radar_tolerance_m` | 0.5 | nearest-neighbour pairing distance of radar detections, metres | > 0 |
/// | `radar_min_presence` | 0.5 | share of clear radar recordings a detection must recur in to enter the radar reference | (0, 1] |
#[derive(Debug, Clone, PartialEq)]
pub struct FitParams(FitValidParams);

/// The reflectivity classes [`FitParams::reflectivity_law`] turns on:
/// calibrated reflectivity from 1 to about 200 at a ratio of 1.5 (a class
/// spans 0.41 in `ln x`, so at an exponent `k` of 0.2 a return's distance
/// is placed within 4 % of its own by its class's mean).
pub const DEFAULT_REFLECTIVITY_LAW_EDGES: [f64; 14] = [
    1.0, 1.5, 2.25, 3.375, 5.0625, 7.59, 11.39, 17.09, 25.63, 38.44, 57.67, 86.5, 129.7, 194.6,
];

/// Checked hyperparameters (see [`FitParams`] for the table).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct FitValidParams {
    pub(crate) quantile: f64,
    pub(crate) mor_bin_width_m: f64,
    pub(crate) band_edges: Vec<f64>,
    pub(crate) sweep_edges: Vec<f64>,
    pub(crate) ring_range_m: [f64; 2],
    pub(crate) ghost_range_m: [f64; 2],
    pub(crate) pairing_tolerance_m: f64,
    pub(crate) pairing_tolerance_rel: f64,
    pub(crate) declared_geometry: bool,
    pub(crate) azimuth_neighbours: u32,
    pub(crate) reference_min_presence: f64,
    pub(crate) reference_min_agreement: f64,
    pub(crate) min_points_per_bin: u64,
    pub(crate) censor_fraction: f64,
    pub(crate) censor_min_points: u64,
    pub(crate) edge: EdgeShape,
    pub(crate) shared_edge_width: bool,
    pub(crate) free_dropout: bool,
    pub(crate) edge_test_folds: u32,
    pub(crate) require_edge: bool,
    #[serde(default)]
    pub(crate) apply_bend: bool,
    // Left out of `to_json` when on (the default), so the parameters of
    // every table written before it existed read and hash the same. (Not
    // `skip_serializing_if`: a state file's body is a positional binary
    // encoding, which cannot skip a field.)
    #[serde(default = "yes")]
    pub(crate) compare_laws: bool,
    // Left out of `to_json` when empty (the default), as `compare_laws`.
    #[serde(default)]
    pub(crate) reflectivity_law_edges: Vec<f64>,
    pub(crate) edge_test_alpha: f64,
    pub(crate) survival_log_step: f64,
    pub(crate) reflectivity_floor: f64,
    pub(crate) count_mor_ref_m: f64,
    pub(crate) bootstrap_replicates: u32,
    pub(crate) seed: u64,
    pub(crate) radar_tolerance_m: f64,
    pub(crate) radar_min_presence: f64,
}

impl Default for FitParams {
    fn default() -> Self {
        FitParams(FitValidParams {
            quantile: 0.99,
            mor_bin_width_m: 10.0,
            band_edges: vec![0.0, 10.0],
            sweep_edges: vec![0.0, 5.0, 10.0, 15.0, 20.0, 30.0, 40.0, 60.0, 100.0],
            ring_range_m: [0.0, 3.0],
            ghost_range_m: [3.0, 10.0],
            pairing_tolerance_m: 0.5,
            pairing_tolerance_rel: 0.02,
            declared_geometry: false,
            azimuth_neighbours: 1,
            reference_min_presence: 0.5,
            reference_min_agreement: 0.8,
            min_points_per_bin: 50,
            censor_fraction: 0.02,
            censor_min_points: 10,
            edge: EdgeShape::Probit,
            shared_edge_width: true,
            free_dropout: true,
            edge_test_folds: 5,
            require_edge: true,
            apply_bend: false,
            compare_laws: true,
            reflectivity_law_edges: Vec::new(),
            edge_test_alpha: 0.01,
            survival_log_step: 0.01,
            reflectivity_floor: 0.0,
            count_mor_ref_m: 100.0,
            bootstrap_replicates: 1000,
            seed: 0,
            radar_tolerance_m: 0.5,
            radar_min_presence: 0.5,
        })
    }
}

macro_rules! setter {
    ($(#[$m:meta])* $name:ident: $t:ty) => {
        $(#[$m])*
        pub fn $name(mut self, v: $t) -> Self {
            self.0.$name = v;
            self
        }
    };
}

impl FitParams {
    /// The defaults of the table above.
    pub fn new() -> Self {
        Self::default()
    }

    setter!(/// Sets `quantile`.
        quantile: f64);
    setter!(/// Sets `mor_bin_width_m`.
        mor_bin_width_m: f64);
    setter!(/// Sets `band_edges` (the table's reflectivity bands).
        band_edges: Vec<f64>);
    setter!(/// Sets `sweep_edges` (Figure 27).
        sweep_edges: Vec<f64>);
    setter!(/// Sets `ring_range_m`.
        ring_range_m: [f64; 2]);
    setter!(/// Sets `ghost_range_m`.
        ghost_range_m: [f64; 2]);
    setter!(/// Sets `pairing_tolerance_m`.
        pairing_tolerance_m: f64);
    setter!(/// Sets `pairing_tolerance_rel`.
        pairing_tolerance_rel: f64);
    setter!(/// Sets `declared_geometry`.
        declared_geometry: bool);
    setter!(/// Sets `azimuth_neighbours`.
        azimuth_neighbours: u32);
    setter!(/// Sets `reference_min_presence`.
        reference_min_presence: f64);
    setter!(/// Sets `reference_min_agreement`.
        reference_min_agreement: f64);
    setter!(/// Sets `min_points_per_bin`.
        min_points_per_bin: u64);
    setter!(/// Sets `censor_fraction`.
        censor_fraction: f64);
    setter!(/// Sets `censor_min_points`.
        censor_min_points: u64);
    setter!(/// Sets `edge`.
        edge: EdgeShape);
    setter!(/// Sets `shared_edge_width`.
        shared_edge_width: bool);
    setter!(/// Sets `free_dropout`.
        free_dropout: bool);
    setter!(/// Sets `edge_test_folds`.
        edge_test_folds: u32);
    setter!(/// Sets `require_edge`.
        require_edge: bool);
    setter!(/// Sets `apply_bend`.
        apply_bend: bool);
    setter!(/// Sets `compare_laws`.
        compare_laws: bool);
    setter!(/// Sets `reflectivity_law_edges` (empty: no reflectivity term).
        reflectivity_law_edges: Vec<f64>);

    /// Turns the reflectivity term on with [`DEFAULT_REFLECTIVITY_LAW_EDGES`]
    /// (`true`) or off (`false`).
    pub fn reflectivity_law(self, on: bool) -> Self {
        self.reflectivity_law_edges(if on {
            DEFAULT_REFLECTIVITY_LAW_EDGES.to_vec()
        } else {
            Vec::new()
        })
    }

    setter!(/// Sets `edge_test_alpha`.
        edge_test_alpha: f64);
    setter!(/// Sets `survival_log_step`.
        survival_log_step: f64);
    setter!(/// Sets `reflectivity_floor`.
        reflectivity_floor: f64);
    setter!(/// Sets `count_mor_ref_m`.
        count_mor_ref_m: f64);
    setter!(/// Sets `bootstrap_replicates`.
        bootstrap_replicates: u32);
    setter!(/// Sets `seed`.
        seed: u64);
    setter!(/// Sets `radar_tolerance_m`.
        radar_tolerance_m: f64);
    setter!(/// Sets `radar_min_presence`.
        radar_min_presence: f64);

    /// The parameters of a state file, to be checked again.
    pub(crate) fn from_valid(p: FitValidParams) -> FitParams {
        FitParams(p)
    }

    /// Checks every parameter against its range; the first violation is
    /// returned by name.
    pub fn check(self) -> Result<FitValidParams, FitError> {
        let p = self.0;
        let bad = |name: &'static str, value: String, reason: &str| {
            Err(FitError::InvalidParam {
                name,
                value,
                reason: reason.to_string(),
            })
        };
        if !(p.quantile > 0.0 && p.quantile < 1.0) {
            return bad("quantile", p.quantile.to_string(), "must lie in (0, 1)");
        }
        if !(p.mor_bin_width_m.is_finite() && p.mor_bin_width_m > 0.0) {
            return bad(
                "mor_bin_width_m",
                p.mor_bin_width_m.to_string(),
                "must be > 0",
            );
        }
        for (name, edges) in [
            ("band_edges", &p.band_edges),
            ("sweep_edges", &p.sweep_edges),
        ] {
            if edges.is_empty() {
                return bad(name, "[]".into(), "needs at least one edge");
            }
            if edges.iter().any(|e| !e.is_finite()) || edges.windows(2).any(|w| w[1] <= w[0]) {
                return bad(
                    name,
                    format!("{edges:?}"),
                    "edges must be finite and strictly increasing",
                );
            }
        }
        let [rlo, rhi] = p.ring_range_m;
        let [glo, ghi] = p.ghost_range_m;
        if !(rlo.is_finite() && rhi.is_finite() && rlo >= 0.0 && rlo < rhi) {
            return bad(
                "ring_range_m",
                format!("{:?}", p.ring_range_m),
                "needs 0 ≤ lo < hi",
            );
        }
        if !(glo.is_finite() && ghi.is_finite() && glo >= rhi && glo < ghi) {
            return bad(
                "ghost_range_m",
                format!("{:?}", p.ghost_range_m),
                "needs ring hi ≤ lo < hi (the windows must not overlap)",
            );
        }
        for (name, v) in [
            ("pairing_tolerance_m", p.pairing_tolerance_m),
            ("pairing_tolerance_rel", p.pairing_tolerance_rel),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(name, v.to_string(), "must be finite and ≥ 0");
            }
        }
        if p.pairing_tolerance_m == 0.0 && p.pairing_tolerance_rel == 0.0 {
            return bad(
                "pairing_tolerance_m",
                "0".into(),
                "an absolute or a relative tolerance must be > 0",
            );
        }
        if p.azimuth_neighbours > 4 {
            return bad(
                "azimuth_neighbours",
                p.azimuth_neighbours.to_string(),
                "must be 0–4",
            );
        }
        for (name, v) in [
            ("reference_min_presence", p.reference_min_presence),
            ("radar_min_presence", p.radar_min_presence),
        ] {
            if !(v > 0.0 && v <= 1.0) {
                return bad(name, v.to_string(), "must lie in (0, 1]");
            }
        }
        if !(0.5..=1.0).contains(&p.reference_min_agreement) {
            return bad(
                "reference_min_agreement",
                p.reference_min_agreement.to_string(),
                "must lie in [0.5, 1] (below a half the median is not the cell's range)",
            );
        }
        if p.min_points_per_bin == 0 {
            return bad("min_points_per_bin", "0".into(), "must be ≥ 1");
        }
        if !(p.censor_fraction >= 0.0 && p.censor_fraction < 1.0) {
            return bad(
                "censor_fraction",
                p.censor_fraction.to_string(),
                "must lie in [0, 1)",
            );
        }
        if !(2..=50).contains(&p.edge_test_folds) {
            return bad(
                "edge_test_folds",
                p.edge_test_folds.to_string(),
                "must lie in 2–50",
            );
        }
        if p.apply_bend && !p.compare_laws {
            return bad(
                "compare_laws",
                "false".into(),
                "apply_bend needs the held-out comparison that chooses the law",
            );
        }
        if !p.reflectivity_law_edges.is_empty() {
            let e = &p.reflectivity_law_edges;
            if e.iter().any(|x| !(x.is_finite() && *x > 0.0)) || e.windows(2).any(|w| w[1] <= w[0])
            {
                return bad(
                    "reflectivity_law_edges",
                    format!("{e:?}"),
                    "must be finite, > 0 and strictly increasing",
                );
            }
            if !p.compare_laws {
                return bad(
                    "compare_laws",
                    "false".into(),
                    "a reflectivity term (reflectivity_law_edges) is chosen by the held-out comparison",
                );
            }
        }
        if !(p.edge_test_alpha > 0.0 && p.edge_test_alpha <= 0.5) {
            return bad(
                "edge_test_alpha",
                p.edge_test_alpha.to_string(),
                "must lie in (0, 0.5]",
            );
        }
        if !(p.survival_log_step > 0.0 && p.survival_log_step <= 0.1) {
            return bad(
                "survival_log_step",
                p.survival_log_step.to_string(),
                "must lie in (0, 0.1]",
            );
        }
        if !p.reflectivity_floor.is_finite() {
            return bad(
                "reflectivity_floor",
                p.reflectivity_floor.to_string(),
                "must be finite",
            );
        }
        if !(p.count_mor_ref_m.is_finite() && p.count_mor_ref_m > 0.0) {
            return bad(
                "count_mor_ref_m",
                p.count_mor_ref_m.to_string(),
                "must be > 0",
            );
        }
        if p.bootstrap_replicates > 100_000 {
            return bad(
                "bootstrap_replicates",
                p.bootstrap_replicates.to_string(),
                "must be ≤ 100000",
            );
        }
        if !(p.radar_tolerance_m.is_finite() && p.radar_tolerance_m > 0.0) {
            return bad(
                "radar_tolerance_m",
                p.radar_tolerance_m.to_string(),
                "must be > 0",
            );
        }
        Ok(p)
    }
}

impl FitValidParams {
    /// Quantile of the seed's estimator.
    pub fn quantile(&self) -> f64 {
        self.quantile
    }
    /// MOR bin width, metres.
    pub fn mor_bin_width_m(&self) -> f64 {
        self.mor_bin_width_m
    }
    /// The table's reflectivity bands.
    pub fn bands(&self) -> Vec<Band> {
        Band::from_edges(&self.band_edges)
    }
    /// The sweep bands of Figure 27.
    pub fn sweep_bands(&self) -> Vec<Band> {
        Band::from_edges(&self.sweep_edges)
    }
    /// Ring window `[lo, hi)`, metres.
    pub fn ring_range_m(&self) -> [f64; 2] {
        self.ring_range_m
    }
    /// Ghost window `[lo, hi)`, metres.
    pub fn ghost_range_m(&self) -> [f64; 2] {
        self.ghost_range_m
    }
    /// Far end of the noise windows (ghost and ring), metres: a return at
    /// or beyond it has every near return of its ray in front of it.
    pub fn noise_reach_m(&self) -> f64 {
        self.ghost_range_m[1].max(self.ring_range_m[1])
    }
    /// Pairing tolerance at clear range `r`: the larger of the absolute and
    /// the relative tolerance.
    pub fn pairing_tolerance(&self, r: f64) -> f64 {
        self.pairing_tolerance_m.max(self.pairing_tolerance_rel * r)
    }
    /// The ranges `d` that lie within the pairing tolerance (taken at `d`,
    /// as pairing does) of `[lo, hi]`: `d + tol(d) ≥ lo` and
    /// `d − tol(d) ≤ hi`.
    pub(crate) fn tolerance_span(&self, lo: f64, hi: f64) -> [f64; 2] {
        let (a, rel) = (self.pairing_tolerance_m, self.pairing_tolerance_rel);
        let low = (lo - a).min(lo / (1.0 + rel));
        let high = if rel < 1.0 {
            (hi + a).max(hi / (1.0 - rel))
        } else {
            f64::INFINITY
        };
        [low, high]
    }
    /// Pair on the declared grid rather than the measured one.
    pub fn declared_geometry(&self) -> bool {
        self.declared_geometry
    }
    /// Azimuth bins searched either side.
    pub fn azimuth_neighbours(&self) -> u32 {
        self.azimuth_neighbours
    }
    /// Presence share for a reference cell.
    pub fn reference_min_presence(&self) -> f64 {
        self.reference_min_presence
    }
    /// Share of a cell's clear recordings that must agree with its median
    /// range for the cell to be stable.
    pub fn reference_min_agreement(&self) -> f64 {
        self.reference_min_agreement
    }
    /// Minimum *no change* returns per MOR bin.
    pub fn min_points_per_bin(&self) -> u64 {
        self.min_points_per_bin
    }
    /// Censoring share.
    pub fn censor_fraction(&self) -> f64 {
        self.censor_fraction
    }
    /// Censoring count.
    pub fn censor_min_points(&self) -> u64 {
        self.censor_min_points
    }
    /// Edge shape.
    pub fn edge(&self) -> EdgeShape {
        self.edge
    }
    /// One edge width for all bands.
    pub fn shared_edge_width(&self) -> bool {
        self.shared_edge_width
    }
    /// Dropout fitted per weather.
    pub fn free_dropout(&self) -> bool {
        self.free_dropout
    }
    /// `edge_test_folds`.
    pub fn edge_test_folds(&self) -> u32 {
        self.edge_test_folds
    }

    /// `require_edge`.
    pub fn require_edge(&self) -> bool {
        self.require_edge
    }

    /// `apply_bend`.
    pub fn apply_bend(&self) -> bool {
        self.apply_bend
    }

    /// `compare_laws`.
    pub fn compare_laws(&self) -> bool {
        self.compare_laws
    }

    /// `reflectivity_law_edges` (empty: no reflectivity term).
    pub fn reflectivity_law_edges(&self) -> &[f64] {
        &self.reflectivity_law_edges
    }

    /// `edge_test_alpha`.
    pub fn edge_test_alpha(&self) -> f64 {
        self.edge_test_alpha
    }

    /// Survival histogram resolution in ln(r/MOR).
    pub fn survival_log_step(&self) -> f64 {
        self.survival_log_step
    }
    /// Lower truncation of reflectivity laws.
    pub fn reflectivity_floor(&self) -> f64 {
        self.reflectivity_floor
    }
    /// Reference MOR of count laws.
    pub fn count_mor_ref_m(&self) -> f64 {
        self.count_mor_ref_m
    }
    /// Bootstrap replicates.
    pub fn bootstrap_replicates(&self) -> u32 {
        self.bootstrap_replicates
    }
    /// Bootstrap seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }
    /// Radar pairing distance.
    pub fn radar_tolerance_m(&self) -> f64 {
        self.radar_tolerance_m
    }
    /// Radar reference presence share.
    pub fn radar_min_presence(&self) -> f64 {
        self.radar_min_presence
    }
    /// Every parameter as JSON (for provenance), `compare_laws` only when off
    /// and `reflectivity_law_edges` only when set (so tables written before
    /// they existed read and hash the same).
    pub fn to_json(&self) -> serde_json::Value {
        let mut v = serde_json::to_value(self).unwrap_or(serde_json::Value::Null);
        if let Some(o) = v.as_object_mut() {
            if self.compare_laws {
                o.remove("compare_laws");
            }
            if self.reflectivity_law_edges.is_empty() {
                o.remove("reflectivity_law_edges");
            }
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_pass_the_check() {
        let p = FitParams::default().check().unwrap();
        assert_eq!(p.bands().len(), 2);
        assert_eq!(
            p.bands()[1],
            Band {
                min: 10.0,
                max: None
            }
        );
        assert_eq!(p.pairing_tolerance(100.0), 2.0);
        assert_eq!(p.pairing_tolerance(1.0), 0.5);
    }

    fn rejected(p: FitParams, name: &str) {
        let e = p.check().unwrap_err().to_string();
        assert!(e.contains(name), "{e}");
    }

    #[test]
    fn quantile_outside_unit_interval_is_rejected() {
        rejected(FitParams::new().quantile(1.0), "quantile");
    }

    #[test]
    fn unsorted_band_edges_are_rejected() {
        rejected(FitParams::new().band_edges(vec![10.0, 0.0]), "band_edges");
    }

    #[test]
    fn overlapping_windows_are_rejected() {
        rejected(FitParams::new().ghost_range_m([2.0, 10.0]), "ghost_range_m");
    }

    #[test]
    fn zero_mor_bin_width_is_rejected() {
        rejected(FitParams::new().mor_bin_width_m(0.0), "mor_bin_width_m");
    }

    #[test]
    fn zero_pairing_tolerances_are_rejected() {
        rejected(
            FitParams::new()
                .pairing_tolerance_m(0.0)
                .pairing_tolerance_rel(0.0),
            "pairing_tolerance",
        );
    }

    #[test]
    fn presence_of_zero_is_rejected() {
        rejected(
            FitParams::new().reference_min_presence(0.0),
            "reference_min_presence",
        );
    }

    #[test]
    fn agreement_below_a_half_or_above_one_is_rejected() {
        for v in [0.49, 1.01, f64::NAN] {
            rejected(
                FitParams::new().reference_min_agreement(v),
                "reference_min_agreement",
            );
        }
        assert!(
            FitParams::new()
                .reference_min_agreement(0.5)
                .check()
                .is_ok()
        );
    }

    #[test]
    fn band_contains_is_half_open() {
        let b = Band {
            min: 0.0,
            max: Some(10.0),
        };
        assert!(b.contains(0.0) && b.contains(9.999) && !b.contains(10.0));
    }
}
