//! Round histogram bin widths, shared by the campaign summary's MOR
//! histogram and the figures so that a table and its plot bin alike.
//!
//! ```
//! assert_eq!(murk_types::nice_step(12.3), 20.0);
//! assert_eq!(murk_types::nice_step(2.2), 2.5);
//! ```

/// The smallest of 1, 2, 2.5, 5 × 10ᵏ that is ≥ `raw` (1 for `raw` ≤ 0 or
/// NaN).
pub fn nice_step(raw: f64) -> f64 {
    if raw.is_nan() || raw <= 0.0 {
        return 1.0;
    }
    let base = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 2.5, 5.0, 10.0]
        .into_iter()
        .map(|m| m * base)
        .find(|s| *s >= raw * (1.0 - 1e-12))
        .unwrap_or(10.0 * base)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_steps() {
        assert_eq!(nice_step(12.3), 20.0);
        assert_eq!(nice_step(2.2), 2.5);
        assert_eq!(nice_step(0.0), 1.0);
        assert_eq!(nice_step(40.0), 50.0);
        assert_eq!(nice_step(100.0), 100.0);
    }
}
