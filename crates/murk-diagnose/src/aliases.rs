//! Scan-level columns that are one quantity with the recording's MOR.
//!
//! A campaign logs its visibility sensors as columns (`PWD12_MOR (m)`,
//! `VS2K_MOR (m)` in the PDD campaigns), and the MOR a recording is
//! simulated at is made from them. A dependence along such a column is a
//! dependence along `mor`, and must be reported once, under `mor`. Which
//! columns read the MOR is decided from the values, never from the names: a
//! numeric column whose logarithm correlates with the logarithm of the MOR
//! used at `|r| ≥` [`MOR_ALIAS_R`] over the weather's recordings (raw values
//! when a column has a value ≤ 0).
//!
//! ```
//! use murk_diagnose::aliases::mor_aliases;
//! let mor = [40.0, 80.0, 120.0, 200.0, 300.0, 60.0];
//! let sensor: Vec<Option<f64>> = mor.iter().map(|m| Some(m * 1.02)).collect();
//! let wind: Vec<Option<f64>> = (0..6).map(|i| Some((i * 37 % 11) as f64)).collect();
//! let cols = vec![("VIS".to_string(), sensor), ("wind".to_string(), wind)];
//! let a = mor_aliases(&mor, &cols);
//! assert!(a.contains_key("VIS"));
//! assert!(!a.contains_key("wind"));
//! ```

use std::collections::BTreeMap;

use murk_types::CovariateValue;

use crate::data::Loaded;

/// Smallest |correlation| with the MOR for a column to read the MOR.
pub const MOR_ALIAS_R: f64 = 0.95;

/// Fewest recordings with a value for the correlation to decide.
pub const MIN_ALIAS_RECORDINGS: usize = 4;

/// Columns (by name) whose values read `mor` (one value per recording;
/// `None` is an empty cell), with their correlation.
pub fn mor_aliases(mor: &[f64], columns: &[(String, Vec<Option<f64>>)]) -> BTreeMap<String, f64> {
    let mut out = BTreeMap::new();
    for (name, vals) in columns {
        let pairs: Vec<(f64, f64)> = mor
            .iter()
            .zip(vals)
            .filter_map(|(m, v)| Some((*m, (*v)?)))
            .filter(|(m, v)| m.is_finite() && v.is_finite())
            .collect();
        if pairs.len() < MIN_ALIAS_RECORDINGS {
            continue;
        }
        let logs = pairs.iter().all(|(m, v)| *m > 0.0 && *v > 0.0);
        let t = |x: f64| if logs { x.ln() } else { x };
        let xs: Vec<(f64, f64)> = pairs.iter().map(|(m, v)| (t(*m), t(*v))).collect();
        if let Some(r) = correlation(&xs)
            && r.abs() >= MOR_ALIAS_R
        {
            out.insert(name.clone(), r);
        }
    }
    out
}

/// Pearson correlation (`None` when either side is constant).
fn correlation(xy: &[(f64, f64)]) -> Option<f64> {
    let n = xy.len() as f64;
    let mx = xy.iter().map(|p| p.0).sum::<f64>() / n;
    let my = xy.iter().map(|p| p.1).sum::<f64>() / n;
    let sxy: f64 = xy.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = xy.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let syy: f64 = xy.iter().map(|p| (p.1 - my).powi(2)).sum();
    (sxx > 0.0 && syy > 0.0).then(|| sxy / (sxx * syy).sqrt())
}

/// The columns of `loaded` (other than `mor` itself) that read the MOR of
/// its recordings.
pub fn of_loaded(loaded: &Loaded) -> BTreeMap<String, f64> {
    let mor: Vec<f64> = loaded.recs.iter().map(|r| r.mor).collect();
    let cols: Vec<(String, Vec<Option<f64>>)> = loaded
        .columns
        .iter()
        .filter(|c| c.as_str() != "mor")
        .map(|c| {
            let v = loaded
                .recs
                .iter()
                .map(|r| match r.scan.get(c) {
                    Some(CovariateValue::Number(x)) => Some(*x),
                    _ => None,
                })
                .collect();
            (c.clone(), v)
        })
        .collect();
    mor_aliases(&mor, &cols)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_noisy_reading_is_an_alias_and_a_loose_proxy_is_not() {
        let mor: Vec<f64> = (0..30).map(|i| 40.0 * 1.08f64.powi(i)).collect();
        let noise = |i: usize| ((i * 7919 % 101) as f64 / 101.0 - 0.5) * 0.06;
        let reading: Vec<Option<f64>> = mor
            .iter()
            .enumerate()
            .map(|(i, m)| (i % 5 != 0).then(|| m * (1.0 + noise(i))))
            .collect();
        // Half MOR, half unrelated: r ≈ 0.7.
        let proxy: Vec<Option<f64>> = mor
            .iter()
            .enumerate()
            .map(|(i, m)| Some(m.ln() + 3.0 * ((i * 31 % 17) as f64 / 17.0)))
            .collect();
        let text: Vec<Option<f64>> = vec![None; 30];
        let a = mor_aliases(
            &mor,
            &[
                ("reading".into(), reading),
                ("proxy".into(), proxy),
                ("outage".into(), text),
            ],
        );
        assert_eq!(a.keys().collect::<Vec<_>>(), vec!["reading"]);
        assert!(a["reading"] > 0.99);
    }
}
