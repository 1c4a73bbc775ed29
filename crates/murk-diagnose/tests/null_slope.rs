//! A table whose slope is null where the fit saw no edge (issue #12) is
//! refused by the diagnosis with the fit's reason, not simulated with a
//! made-up slope and not a panic.

use murk_diagnose::DiagnoseParams;
use murk_types::{CoefficientTable, WeatherClass};

fn table(slope_low: Option<f64>) -> CoefficientTable {
    let v = serde_json::json!({
      "format": "weather-noise-coefficients/1", "campaign": "seed",
      "lidar": { "model": "VLP16", "range_scale": 1.0 },
      "weathers": {
        "fog": { "recordings": 28, "quantile": 0.99, "no_change_rate": 0.38,
          "vanishing_slope": [
            { "reflectivity_min": 0, "reflectivity_max": 10, "slope": slope_low, "points": 5000,
              "reason": if slope_low.is_none() { Some("no edge: on held-out recordings survival by r/MOR predicts no better than survival by range alone") } else { None } },
            { "reflectivity_min": 10, "reflectivity_max": null, "slope": 0.34634364, "points": 1 } ],
          "ghost": null, "ring": null } },
      "provenance": { "tool": "test", "inputs_sha256": "", "parameters": {} }
    });
    serde_json::from_value(v).unwrap()
}

#[test]
fn a_table_with_a_null_slope_is_refused_with_the_reason() {
    let e = match DiagnoseParams::new(WeatherClass::Fog)
        .coefficients(Some(table(None)))
        .check()
    {
        Ok(_) => panic!("a null slope was accepted"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("band 0") && e.contains("no edge"), "{e}");
    // The same table with the slope present is accepted.
    assert!(
        DiagnoseParams::new(WeatherClass::Fog)
            .coefficients(Some(table(Some(0.3))))
            .check()
            .is_ok()
    );
}
