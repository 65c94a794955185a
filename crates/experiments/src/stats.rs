//! The statistics every experiment reports: means with Student-t 95% confidence intervals over
//! independent runs, percentiles of samples within a run.

use serde::{Deserialize, Serialize};

/// A mean over independent runs with the half width of its 95% confidence interval.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    pub mean: f64,
    /// Half width of the 95% confidence interval (Student t, n - 1 degrees of freedom); zero
    /// with fewer than two runs, where no interval can be given.
    pub ci95: f64,
    pub n: usize,
}

impl Estimate {
    /// The estimate of the mean of `values` (non-finite values are left out).
    pub fn of(values: &[f64]) -> Estimate {
        let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
        let n = finite.len();
        if n == 0 {
            return Estimate { mean: f64::NAN, ci95: f64::NAN, n: 0 };
        }
        let mean = mean(&finite);
        let ci95 = if n >= 2 { t_975(n - 1) * std_dev(&finite) / (n as f64).sqrt() } else { 0.0 };
        Estimate { mean, ci95, n }
    }

    /// "12.3 ± 0.4", scaled by `scale` (100 for percentages), with `decimals` digits.
    pub fn show(&self, scale: f64, decimals: usize) -> String {
        if !self.mean.is_finite() {
            return "n/a".to_owned();
        }
        if self.n < 2 {
            return format!("{:.*}", decimals, self.mean * scale);
        }
        format!("{:.*} ± {:.*}", decimals, self.mean * scale, decimals, self.ci95 * scale)
    }

    pub fn low(&self) -> f64 {
        self.mean - self.ci95
    }

    pub fn high(&self) -> f64 {
        self.mean + self.ci95
    }
}

pub fn mean(values: &[f64]) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.iter().sum::<f64>() / values.len() as f64
}

/// Sample standard deviation (n - 1 in the denominator).
pub fn std_dev(values: &[f64]) -> f64 {
    if values.len() < 2 {
        return 0.0;
    }
    let m = mean(values);
    let ss: f64 = values.iter().map(|v| (v - m) * (v - m)).sum();
    (ss / (values.len() - 1) as f64).sqrt()
}

/// The 97.5% quantile of Student's t distribution with `df` degrees of freedom: the factor of a
/// two-sided 95% confidence interval.
pub fn t_975(df: usize) -> f64 {
    const TABLE: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    match df {
        0 => f64::NAN,
        1..=30 => TABLE[df - 1],
        // Beyond the table, the Cornish-Fisher expansion around the normal quantile is within
        // 1e-3 of the exact value.
        _ => {
            let z: f64 = 1.959_964;
            let v = df as f64;
            z + (z.powi(3) + z) / (4.0 * v)
                + (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / (96.0 * v * v)
        }
    }
}

/// The `q`-quantile (0..=1) of `values` by linear interpolation between order statistics;
/// NaN for no values.
pub fn percentile(values: &[f64], q: f64) -> f64 {
    let mut sorted: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted.sort_by(f64::total_cmp);
    let position = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let below = position.floor() as usize;
    let above = position.ceil() as usize;
    let t = position - below as f64;
    sorted[below] * (1.0 - t) + sorted[above] * t
}

/// Fraction of `true` in a trace sampled at a constant period: the fraction of the time.
pub fn fraction_true(samples: impl IntoIterator<Item = bool>) -> f64 {
    let (mut yes, mut all) = (0usize, 0usize);
    for s in samples {
        all += 1;
        yes += usize::from(s);
    }
    if all == 0 { f64::NAN } else { yes as f64 / all as f64 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn confidence_interval_of_a_hand_computed_sample() {
        // Mean 3, sample standard deviation sqrt(2.5); t(4) = 2.776.
        let e = Estimate::of(&[1.0, 2.0, 3.0, 4.0, 5.0]);
        assert_eq!(e.n, 5);
        assert!((e.mean - 3.0).abs() < 1e-12);
        let expected = 2.776 * 2.5f64.sqrt() / 5f64.sqrt();
        assert!((e.ci95 - expected).abs() < 1e-9, "{e:?}");
        assert_eq!(e.show(1.0, 2), "3.00 ± 1.96");
    }

    #[test]
    fn a_single_run_has_no_interval_and_nan_is_left_out() {
        let e = Estimate::of(&[0.25, f64::NAN]);
        assert_eq!((e.mean, e.ci95, e.n), (0.25, 0.0, 1));
        assert_eq!(e.show(100.0, 1), "25.0");
        assert_eq!(Estimate::of(&[]).show(1.0, 1), "n/a");
    }

    #[test]
    fn t_quantiles_match_tables_and_approach_the_normal_quantile() {
        assert!((t_975(1) - 12.706).abs() < 1e-9);
        assert!((t_975(30) - 2.042).abs() < 1e-9);
        assert!((t_975(40) - 2.021).abs() < 2e-3, "{}", t_975(40));
        assert!((t_975(120) - 1.980).abs() < 2e-3, "{}", t_975(120));
        assert!(t_975(100_000) > 1.959 && t_975(100_000) < 1.961);
    }

    #[test]
    fn percentiles_interpolate_between_order_statistics() {
        let v = [5.0, 1.0, 4.0, 2.0, 3.0];
        assert_eq!(percentile(&v, 0.0), 1.0);
        assert_eq!(percentile(&v, 0.5), 3.0);
        assert_eq!(percentile(&v, 1.0), 5.0);
        assert!((percentile(&v, 0.95) - 4.8).abs() < 1e-12);
        assert!(percentile(&[], 0.5).is_nan());
    }

    #[test]
    fn fraction_of_a_trace() {
        let trace = [true, false, false, false, true, false, false, false];
        assert_eq!(fraction_true(trace), 0.25);
        assert!(fraction_true([]).is_nan());
    }
}

/// A within-run sample's spread: count, median, 95th percentile, extremes and mean.
#[derive(Clone, Debug, Serialize)]
pub struct Distribution {
    pub n: usize,
    pub median: f64,
    pub p95: f64,
    pub min: f64,
    pub max: f64,
    pub mean: f64,
}

impl Distribution {
    pub fn of(values: &[f64]) -> Distribution {
        Distribution {
            n: values.len(),
            median: percentile(values, 0.5),
            p95: percentile(values, 0.95),
            min: values.iter().copied().fold(f64::NAN, f64::min),
            max: values.iter().copied().fold(f64::NAN, f64::max),
            mean: mean(values),
        }
    }
}
