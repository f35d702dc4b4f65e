//! Order statistics shared by the stages, and the summary of timing samples (mean, median,
//! 95th percentile) the benchmarks report.

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

/// Mean, median and 95th percentile of timing samples (e.g. frame times in milliseconds), as
/// a benchmark reports them. Single precision, as the samples are taken.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimingSummary {
    pub mean: f32,
    /// Nearest-rank median ([`quantile`] at ½).
    pub median: f32,
    /// Nearest-rank 95th percentile ([`quantile`] at 0.95).
    pub p95: f32,
}

impl TimingSummary {
    /// The summary of `samples`; every statistic is 0 when there are none.
    pub fn of(samples: &[f32]) -> Self {
        let quantile_of = |q: f64| {
            let mut values: Vec<f64> = samples.iter().map(|&v| v as f64).collect();
            let value = quantile(&mut values, q);
            if value.is_nan() { 0.0 } else { value as f32 }
        };
        Self {
            mean: samples.iter().sum::<f32>() / samples.len().max(1) as f32,
            median: quantile_of(0.5),
            p95: quantile_of(0.95),
        }
    }
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
    #[test]
    fn timing_summaries_bound_the_samples_and_ignore_their_order() {
        let mut samples: Vec<f32> = (0..200)
            .map(|k| ((k * 37) % 101) as f32 * 0.25 + 3.0)
            .collect();
        let summary = TimingSummary::of(&samples);
        let (lo, hi) = samples
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        assert!(lo <= summary.median && summary.median <= summary.p95 && summary.p95 <= hi);
        assert!(lo <= summary.mean && summary.mean <= hi);
        // Ranks: at least 95 % of the samples at or below the 95th percentile, at least
        // half at or below the median and at or above it.
        let at_most = |x: f32| samples.iter().filter(|&&v| v <= x).count();
        assert!(at_most(summary.p95) * 100 >= 95 * samples.len());
        assert!(at_most(summary.median) * 2 >= samples.len());
        assert!(samples.iter().filter(|&&v| v >= summary.median).count() * 2 >= samples.len());
        // The same samples in another order: the same median and percentile.
        samples.reverse();
        let reversed = TimingSummary::of(&samples);
        assert_eq!(
            (reversed.median, reversed.p95),
            (summary.median, summary.p95)
        );
        assert!((reversed.mean - summary.mean).abs() < 1e-3);
        // A constant series summarises to its value; no samples to zeros.
        let constant = TimingSummary::of(&[16.5; 7]);
        assert_eq!(
            (constant.mean, constant.median, constant.p95),
            (16.5, 16.5, 16.5)
        );
        let empty = TimingSummary::of(&[]);
        assert_eq!((empty.mean, empty.median, empty.p95), (0.0, 0.0, 0.0));
    }
}
