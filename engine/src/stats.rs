//! Small statistics over frame times (benchmarks report medians and percentiles, not means).

/// The p-th percentile (0..=100) by nearest rank of unsorted samples; `None` when empty.
pub fn percentile(samples: &[f64], p: f64) -> Option<f64> {
    if samples.is_empty() {
        return None;
    }
    let mut v = samples.to_vec();
    v.sort_by(|a, b| a.total_cmp(b));
    let rank = ((p / 100.0) * (v.len() - 1) as f64).round() as usize;
    Some(v[rank.min(v.len() - 1)])
}

pub fn median(samples: &[f64]) -> Option<f64> {
    percentile(samples, 50.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_and_percentiles() {
        assert_eq!(median(&[]), None);
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(percentile(&[5.0, 1.0, 4.0, 2.0, 3.0], 100.0), Some(5.0));
        assert_eq!(percentile(&[5.0, 1.0, 4.0, 2.0, 3.0], 0.0), Some(1.0));
    }
}
