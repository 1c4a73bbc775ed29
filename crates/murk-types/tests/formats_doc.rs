//! Keeps `docs/formats.md` in step with the coefficient table: every field
//! name a table can carry must appear in the document (as `` `name` ``).
//!
//! The table below sets every optional field and fills every list, so its
//! JSON shows every field serde writes; a field added to the types later
//! shows up here too, because re-serialising writes it (with its default)
//! even when this JSON does not set it, unless it is skipped when empty.

use std::collections::BTreeSet;
use std::path::Path;

use murk_types::CoefficientTable;
use serde_json::Value;

/// A table with every field present.
const FULL: &str = r#"{
  "format": "weather-noise-coefficients/1",
  "campaign": "doc",
  "lidar": { "model": "VLP16", "range_scale": 1.0 },
  "weathers": {
    "rain": {
      "recordings": 3, "mor_min_m": 50.0, "mor_max_m": 200.0,
      "vanishing_slope": [
        { "reflectivity_min": 0.0, "reflectivity_max": 10.0, "slope": 0.3, "points": 10,
          "reason": "r", "std_error": 0.01, "edge_width": 0.1,
          "mor_bins": [ { "mor_m": 55.0, "mor_lo_m": 50.0, "mor_hi_m": 60.0, "recordings": 2,
                          "q99_range_m": 16.0, "points": 5, "censored": false, "used": true,
                          "reason": "r" } ],
          "law": { "kind": "power", "a": 1.2, "b": 0.75 },
          "survival_bins": [ { "mor_m": 55.0, "mor_lo_m": 50.0, "mor_hi_m": 60.0, "recordings": 2,
                               "trials": 100, "half_survival_range_m": 30.0,
                               "ci95": { "low": 28.0, "high": 32.0, "level": 0.95,
                                         "method": "bootstrap over recordings" },
                               "line_m": 31.0, "law_m": 30.5, "reason": "r" } ],
          "lack_of_fit": { "statistic": 3.0, "dof": 2, "bins": 3, "p_value": 0.22,
                           "alpha": 0.05, "lack_of_fit": false, "worst_ratio": 0.9 } },
        { "reflectivity_min": 10.0, "reflectivity_max": null, "slope": 0.35, "points": 10 }
      ],
      "vanishing_slope_q99": [
        { "reflectivity_min": 0.0, "reflectivity_max": null, "slope": 0.3, "points": 10 }
      ],
      "quantile": 0.99,
      "mor_bins": [ { "mor_m": 55.0, "q99_range_m": 16.0, "points": 5 } ],
      "survival": { "edge": "probit", "dropout": 0.1, "dropout_clear": 0.05, "residual": 0.01,
                    "neg_log_likelihood": 1.0, "trials": 100 },
      "no_change_rate": 0.4,
      "no_change_rate_uncertainty": { "std": 0.01, "ci95_low": 0.38, "ci95_high": 0.42,
                                      "replicates": 100 },
      "no_change_rate_reason": "r",
      "ghost": {
        "distance_m": { "mean": 5.0, "std": 1.7, "lower": 3.0, "upper": 10.0,
                        "mean_std_error": 0.1, "std_std_error": 0.1 },
        "reflectivity": { "mean": 4.0, "std": 11.0, "lower": 0.0 },
        "points_per_scan": 41.0, "points": 1000, "visible_fraction": 0.9,
        "count_law": { "law": "power", "n_ref": 40.0, "mor_ref_m": 100.0, "exponent": 1.0,
                       "n_ref_std_error": 1.0, "exponent_std_error": 0.1,
                       "n_ref_ci95": { "low": 38.0, "high": 42.0, "level": 0.95, "method": "m" },
                       "exponent_ci95": { "low": 0.8, "high": 1.2, "level": 0.95, "method": "m" } },
        "count_law_reason": "r",
        "count_law_choice": { "chosen": "power", "folds": 5, "power_heldout_log_likelihood": -10.0,
                              "onset_heldout_log_likelihood": -11.0, "onset_gain_p": 0.5,
                              "reason": "r" }
      },
      "ghost_reason": "r",
      "ghost_returns": { "points": 1000, "distance_mean_m": 5.5, "distance_std_m": 1.5,
                         "reflectivity_mean": 9.0, "reflectivity_std": 8.0 },
      "ring": {
        "distance_m": { "mean": 1.3, "std": 0.2, "lower": 0.0, "upper": 3.0, "reason": "r" },
        "reflectivity": { "mean": 2.0, "std": 3.0, "lower": 0.0 },
        "points_per_scan": 4.0, "points": 100,
        "count_law": { "law": "onset", "n_ref": 10.0, "mor_ref_m": 100.0, "exponent": 0.5,
                       "onset_mor_m": 80.0, "onset_steepness": 4.0,
                       "n_ref_ci95": { "low": 8.0, "high": 12.0, "level": 0.95, "method": "m" },
                       "exponent_ci95": { "low": 0.1, "high": 0.9, "level": 0.95, "method": "m" },
                       "onset_mor_ci95": { "low": 70.0, "high": 90.0, "level": 0.95, "method": "m" },
                       "onset_steepness_ci95": { "low": 2.0, "high": 8.0, "level": 0.95, "method": "m" } }
      },
      "ring_reason": "r",
      "ring_returns": { "points": 100, "distance_mean_m": 1.3, "distance_std_m": 0.2,
                        "reflectivity_mean": 2.0, "reflectivity_std": 3.0 },
      "mor_from_rain_rate": { "slope": -0.8, "intercept": 159.0, "points": 42,
                              "slope_std_error": 0.1, "intercept_std_error": 1.0,
                              "rain_rate_min": 1.0, "rain_rate_max": 100.0,
                              "zero_mor_rain_rate": 190.0, "slope_ols": -0.7,
                              "intercept_ols": 150.0, "rain_rate_reliability": 0.9 },
      "mor_from_rain_rate_reason": "r",
      "reflectivity_sweep": [ { "reflectivity_min": 0.0, "reflectivity_max": 5.0, "slope": 0.3,
                                "slope_q99": 0.29, "points": 10 } ],
      "extensions": [
        { "observable": "survival", "covariate": "range",
          "function": { "kind": "bins", "edges": [10.0], "values": [1.0, 0.9] },
          "default": 1.0, "description": "d" },
        { "observable": "count", "covariate": "Road state",
          "function": { "kind": "categories", "values": { "wet": 1.2 } },
          "default": 1.0, "description": "d" }
      ],
      "law_choice": { "chosen": "power", "exponents": [0.75, null], "gain_nats_per_recording": 2.0,
                      "recordings_better": 30, "recordings": 36, "p_value": 0.001,
                      "alpha": 0.01, "folds": 5, "reason": "r" }
    }
  },
  "absent": { "snow": "no recording" },
  "clear": { "recordings": 4, "reference_cells": 1000, "no_change_rate": 0.9,
             "no_change_rate_uncertainty": { "std": 0.01, "ci95_low": 0.88, "ci95_high": 0.92,
                                             "replicates": 100 },
             "no_change_rate_reason": "r" },
  "radar": { "no_change_rate": { "clear": 0.97 },
             "uncertainty": { "clear": { "std": 0.01, "ci95_low": 0.95, "ci95_high": 0.99,
                                         "replicates": 100 } },
             "recordings": { "clear": 4 }, "absent": { "fog": "no radar file" },
             "tolerance_m": 0.5 },
  "excluded_recordings": [ { "recording": "r1", "weather": "fog", "reason": "r" } ],
  "provenance": { "tool": "doc 0", "inputs_sha256": "00", "inputs": [ { "path": "p", "sha256": "00" } ],
                  "parameters": { "free": "form" } }
}"#;

/// Object keys under which the JSON holds a map (weather names, categories,
/// free-form parameters), not field names.
const MAPS: &[&str] = &[
    "weathers",
    "absent",
    "no_change_rate",
    "uncertainty",
    "recordings",
    "parameters",
];

/// Every field name in `v`, skipping the keys of maps.
fn field_names(v: &Value, parent: Option<&str>, out: &mut BTreeSet<String>) {
    match v {
        Value::Object(m) => {
            let is_map = parent.is_some_and(|p| MAPS.contains(&p))
                || (parent == Some("values") && !m.is_empty());
            for (k, child) in m {
                if !is_map {
                    out.insert(k.clone());
                }
                field_names(child, if is_map { None } else { Some(k) }, out);
            }
        }
        Value::Array(a) => {
            for child in a {
                field_names(child, parent, out);
            }
        }
        _ => {}
    }
}

#[test]
fn every_table_field_is_documented_in_docs_formats_md() {
    let table = CoefficientTable::from_json(FULL).expect("the full table is valid");
    let json: Value = serde_json::from_str(&table.to_json().expect("a table writes JSON")).unwrap();
    let mut names = BTreeSet::new();
    field_names(&json, None, &mut names);
    // The full table really is full: the optional parts came through.
    for sure in [
        "count_law",
        "onset_steepness_ci95",
        "ghost_returns",
        "rain_rate_reliability",
        "extensions",
        "inputs",
        "edge_width",
        "law_choice",
        "survival_bins",
        "lack_of_fit",
    ] {
        assert!(names.contains(sure), "{sure} missing from {names:?}");
    }
    let doc_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/formats.md");
    let doc = std::fs::read_to_string(&doc_path)
        .unwrap_or_else(|e| panic!("{}: {e}", doc_path.display()));
    let missing: Vec<&String> = names
        .iter()
        .filter(|n| !doc.contains(&format!("`{n}`")) && !doc.contains(&format!(".{n}`")))
        .collect();
    assert!(
        missing.is_empty(),
        "table fields not described in docs/formats.md: {missing:?}"
    );
}
