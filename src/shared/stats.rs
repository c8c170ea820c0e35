//! Means and standard deviations, in the two conventions nuno's reports use.

/// Mean and population standard deviation (numpy's default), as D4RL reports
/// an evaluation's returns.
pub fn mean_std_population(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

/// Mean and sample standard deviation (over n − 1), as a table over seeds
/// reports them; the deviation of fewer than two values is 0.
pub fn mean_std_sample(values: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = values.clone().count();
    let mean = values.clone().sum::<f64>() / n.max(1) as f64;
    if n < 2 {
        return (mean, 0.0);
    }
    let var = values.map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    (mean, var.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn population_and_sample_deviations_by_hand() {
        // 2, 4, 4, 4, 5, 5, 7, 9: mean 5, squared deviations sum to 32.
        let values = [2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0];
        assert_eq!(mean_std_population(&values), (5.0, 2.0));
        let (mean, std) = mean_std_sample(values.iter().copied());
        assert_eq!(mean, 5.0);
        assert!((std - (32.0f64 / 7.0).sqrt()).abs() < 1e-15);
        assert_eq!(mean_std_sample([3.0].into_iter()), (3.0, 0.0));
    }
}
