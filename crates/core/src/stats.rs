//! Summary statistics of error samples (NaN-free inputs expected).

use serde::Serialize;

/// Median, mean, standard deviation, 90th percentile and count.
#[derive(Copy, Clone, Debug, Default, PartialEq, Serialize)]
pub struct Summary {
    /// Number of finite samples summarised (non-finite ones are dropped).
    pub n: usize,
    /// Median (0.5-quantile), in the samples' unit.
    pub median: f64,
    /// Arithmetic mean, in the samples' unit.
    pub mean: f64,
    /// Sample standard deviation (divisor `n - 1`), in the samples' unit.
    pub std: f64,
    /// 90th percentile (0.9-quantile), in the samples' unit.
    pub p90: f64,
}

/// The `q`-quantile (0…1) of sorted values by linear interpolation.
pub fn quantile_sorted(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let pos = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}

impl Summary {
    /// Summarises the finite values of `values`; all statistics are NaN
    /// (and `n` is 0) when none are finite.
    pub fn of(values: &[f64]) -> Summary {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return Summary { n: 0, median: f64::NAN, mean: f64::NAN, std: f64::NAN, p90: f64::NAN };
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let mean = v.iter().sum::<f64>() / n as f64;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n.max(2) - 1) as f64;
        Summary { n, median: quantile_sorted(&v, 0.5), mean, std: var.sqrt(), p90: quantile_sorted(&v, 0.9) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_of_known_values() {
        let s = Summary::of(&[4.0, 1.0, 3.0, 2.0, f64::NAN]);
        assert_eq!(s.n, 4);
        assert_eq!(s.median, 2.5);
        assert_eq!(s.mean, 2.5);
        assert!((s.std - (5.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert!(Summary::of(&[]).median.is_nan());
    }
}
