//! Least-squares lines through linfa-linear: the zero-intercept fit of the
//! seed's quantile estimator and the rain-rate → MOR conversion.

use linfa::Dataset;
use linfa::traits::Fit;
use linfa_linear::LinearRegression;
use ndarray::{Array1, Array2};

fn dataset(x: &[f64], y: &[f64]) -> Option<Dataset<f64, f64, ndarray::Ix1>> {
    if x.len() != y.len() || x.is_empty() {
        return None;
    }
    let records = Array2::from_shape_vec((x.len(), 1), x.to_vec()).ok()?;
    Some(Dataset::new(records, Array1::from(y.to_vec())))
}

/// Slope `a` of `y = a·x` by least squares. `None` without data or when every
/// `x` is 0.
pub fn zero_intercept_slope(x: &[f64], y: &[f64]) -> Option<f64> {
    if x.iter().all(|v| *v == 0.0) {
        return None;
    }
    let ds = dataset(x, y)?;
    let fitted = LinearRegression::new()
        .with_intercept(false)
        .fit(&ds)
        .ok()?;
    let a = fitted.params()[0];
    a.is_finite().then_some(a)
}

/// `(slope, intercept)` of `y = a·x + b` by least squares. `None` with fewer
/// than two distinct `x`.
pub fn line(x: &[f64], y: &[f64]) -> Option<(f64, f64)> {
    let first = *x.first()?;
    if x.iter().all(|v| *v == first) {
        return None;
    }
    let ds = dataset(x, y)?;
    let fitted = LinearRegression::new().fit(&ds).ok()?;
    let (a, b) = (fitted.params()[0], fitted.intercept());
    (a.is_finite() && b.is_finite()).then_some((a, b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_intercept_known_answer() {
        // Σxy/Σx² = (1·2 + 2·4.2 + 3·5.7)/(1+4+9) = 27.5/14.
        let a = zero_intercept_slope(&[1.0, 2.0, 3.0], &[2.0, 4.2, 5.7]).unwrap();
        assert!((a - 27.5 / 14.0).abs() < 1e-12);
        assert_eq!(zero_intercept_slope(&[0.0], &[1.0]), None);
        assert_eq!(zero_intercept_slope(&[], &[]), None);
    }

    #[test]
    fn line_recovers_the_seed_conversion() {
        // Points exactly on MOR = −0.8308·R + 159.16.
        let r = [0.5, 5.0, 20.0, 60.0];
        let m: Vec<f64> = r.iter().map(|x| -0.8308 * x + 159.16).collect();
        let (a, b) = line(&r, &m).unwrap();
        assert!((a + 0.8308).abs() < 1e-9 && (b - 159.16).abs() < 1e-9);
        assert_eq!(line(&[2.0, 2.0], &[1.0, 3.0]), None);
    }
}
