//! Order statistics shared by the stages.

/// The median of the finite values (the upper one for an even count); `None` without any.
pub fn median(values: impl IntoIterator<Item = f64>) -> Option<f64> {
    let mut finite: Vec<f64> = values.into_iter().filter(|v| v.is_finite()).collect();
    finite.sort_by(f64::total_cmp);
    finite.get(finite.len() / 2).copied()
}

/// The value at fraction `q` (0..=1) of an ascending slice, by nearest rank; NaN when empty.
pub fn quantile_sorted(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let index = ((sorted.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    sorted[index.min(sorted.len() - 1)]
}

/// The value at fraction `q` of `values` by nearest rank (sorts them); NaN when empty.
pub fn quantile(values: &mut [f64], q: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    quantile_sorted(values, q)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn medians_skip_non_finite_values_and_quantiles_use_nearest_rank() {
        assert_eq!(median([3.0, f64::NAN, 1.0, 2.0]), Some(2.0));
        assert_eq!(median([4.0, 1.0, 3.0, 2.0]), Some(3.0));
        assert_eq!(median([f64::INFINITY]), None);
        let sorted = [0.0, 1.0, 2.0, 3.0, 4.0];
        assert_eq!(quantile_sorted(&sorted, 0.0), 0.0);
        assert_eq!(quantile_sorted(&sorted, 0.5), 2.0);
        assert_eq!(quantile_sorted(&sorted, 0.9), 4.0);
        assert_eq!(quantile_sorted(&sorted, 2.0), 4.0);
        assert!(quantile_sorted(&[], 0.5).is_nan());
        assert_eq!(quantile(&mut [4.0, 0.0, 3.0, 1.0, 2.0], 0.9), 4.0);
    }
}
