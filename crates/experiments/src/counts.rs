//! Rates of rare events over an exposure (falls per walking minute): exact 95% intervals for
//! one Poisson rate, and for the ratio of two. Fall counts are small (often 0 to 5 per
//! condition), where normal approximations give intervals below zero or far too narrow, so the
//! intervals are the exact ones (Garwood; Clopper-Pearson on the conditional binomial), found
//! by bisection on the distribution functions.

use serde::Serialize;

/// Events over an exposure: the rate and its exact two-sided 95% interval (Garwood).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RateEstimate {
    pub events: u64,
    /// In the rate's unit of time (minutes of walking).
    pub exposure: f64,
    /// Events per unit of exposure; NaN without exposure.
    pub rate: f64,
    pub low: f64,
    pub high: f64,
}

impl RateEstimate {
    pub fn of(events: u64, exposure: f64) -> RateEstimate {
        if !(exposure.is_finite() && exposure > 0.0) {
            return RateEstimate {
                events,
                exposure,
                rate: f64::NAN,
                low: f64::NAN,
                high: f64::NAN,
            };
        }
        let (low, high) = poisson_mean_interval(events);
        RateEstimate {
            events,
            exposure,
            rate: events as f64 / exposure,
            low: low / exposure,
            high: high / exposure,
        }
    }

    /// "0.12 (0.03 to 0.45)", with `decimals` digits.
    pub fn show(&self, decimals: usize) -> String {
        if !self.rate.is_finite() {
            return "n/a".to_owned();
        }
        format!(
            "{:.*} ({:.*} to {:.*})",
            decimals, self.rate, decimals, self.low, decimals, self.high
        )
    }
}

/// The ratio of two rates `a / b` with its exact two-sided 95% interval: given the total count
/// `a + b`, `a`'s events are binomial with p = ratio t_a / (ratio t_a + t_b), whose
/// Clopper-Pearson interval carries over to the ratio.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RateRatio {
    /// Infinite when `b` had no events and `a` some.
    pub ratio: f64,
    pub low: f64,
    /// Infinite when `b` had no events.
    pub high: f64,
}

/// `None` when there is nothing to compare: no events in either, or no exposure in one.
pub fn rate_ratio(a: &RateEstimate, b: &RateEstimate) -> Option<RateRatio> {
    let n = a.events + b.events;
    let exposures_known = [a.exposure, b.exposure].iter().all(|t| t.is_finite() && *t > 0.0);
    if n == 0 || !exposures_known {
        return None;
    }
    let (p_low, p_high) = binomial_interval(a.events, n);
    let scale = b.exposure / a.exposure;
    let odds = |p: f64| if p >= 1.0 { f64::INFINITY } else { p / (1.0 - p) * scale };
    let ratio =
        if b.events == 0 { f64::INFINITY } else { a.events as f64 / b.events as f64 * scale };
    Some(RateRatio { ratio, low: odds(p_low), high: odds(p_high) })
}

/// The exact two-sided 95% interval of a Poisson mean from one count `k`.
pub fn poisson_mean_interval(k: u64) -> (f64, f64) {
    let tail = 0.025;
    let top = 10.0 * (k as f64 + 10.0);
    // P(X >= k; low) = tail, and P(X <= k; high) = tail; the distribution function falls
    // as the mean grows.
    let low =
        if k == 0 { 0.0 } else { bisect(0.0, top, |mean| 1.0 - poisson_cdf(k - 1, mean) < tail) };
    let high = bisect(0.0, top, |mean| poisson_cdf(k, mean) > tail);
    (low, high)
}

/// The Clopper-Pearson two-sided 95% interval of a proportion: `x` successes in `n` trials.
pub fn binomial_interval(x: u64, n: u64) -> (f64, f64) {
    let tail = 0.025;
    let low =
        if x == 0 { 0.0 } else { bisect(0.0, 1.0, |p| 1.0 - binomial_cdf(x - 1, n, p) < tail) };
    let high = if x >= n { 1.0 } else { bisect(0.0, 1.0, |p| binomial_cdf(x, n, p) > tail) };
    (low, high)
}

/// The boundary between `below` (true up to it) and false above, in [lo, hi].
fn bisect(mut lo: f64, mut hi: f64, below: impl Fn(f64) -> bool) -> f64 {
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if below(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-12 * hi.max(1.0) {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// P(X <= k) for X Poisson with `mean`, summed in log space (no overflow for large k).
fn poisson_cdf(k: u64, mean: f64) -> f64 {
    if mean <= 0.0 {
        return 1.0;
    }
    let ln_mean = mean.ln();
    let mut ln_term = -mean;
    let mut sum = ln_term.exp();
    for i in 1..=k {
        ln_term += ln_mean - (i as f64).ln();
        sum += ln_term.exp();
    }
    sum.min(1.0)
}

/// P(X <= x) for X binomial(n, p).
fn binomial_cdf(x: u64, n: u64, p: f64) -> f64 {
    if p <= 0.0 {
        return 1.0;
    }
    if p >= 1.0 {
        return if x >= n { 1.0 } else { 0.0 };
    }
    let (ln_p, ln_q) = (p.ln(), (1.0 - p).ln());
    let mut ln_choose = 0.0;
    let mut sum = 0.0;
    for i in 0..=x.min(n) {
        if i > 0 {
            ln_choose += ((n - i + 1) as f64).ln() - (i as f64).ln();
        }
        sum += (ln_choose + i as f64 * ln_p + (n - i) as f64 * ln_q).exp();
    }
    sum.min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tolerance: f64) -> bool {
        (a - b).abs() <= tolerance
    }

    #[test]
    fn poisson_intervals_match_the_published_tables() {
        // Garwood's exact limits (e.g. Ulm 1990, Table 1).
        let (low, high) = poisson_mean_interval(0);
        assert_eq!(low, 0.0);
        assert!(close(high, 3.689, 1e-3), "{high}");
        let (low, high) = poisson_mean_interval(1);
        assert!(close(low, 0.0253, 1e-4) && close(high, 5.572, 1e-3), "{low} {high}");
        let (low, high) = poisson_mean_interval(10);
        assert!(close(low, 4.795, 1e-3) && close(high, 18.390, 1e-3), "{low} {high}");
    }

    #[test]
    fn clopper_pearson_intervals_match_the_published_values() {
        let (low, high) = binomial_interval(0, 10);
        assert_eq!(low, 0.0);
        assert!(close(high, 0.3085, 1e-4), "{high}");
        let (low, high) = binomial_interval(5, 10);
        assert!(close(low, 0.1871, 1e-4) && close(high, 0.8129, 1e-4), "{low} {high}");
        assert_eq!(binomial_interval(4, 4).1, 1.0);
    }

    #[test]
    fn a_rate_is_events_per_exposure_with_the_interval_scaled_alike() {
        let r = RateEstimate::of(2, 4.0);
        assert_eq!(r.rate, 0.5);
        let (low, high) = poisson_mean_interval(2);
        assert!(close(r.low, low / 4.0, 1e-12) && close(r.high, high / 4.0, 1e-12));
        assert!(RateEstimate::of(3, 0.0).rate.is_nan());
        assert_eq!(RateEstimate::of(0, 2.0).show(2), "0.00 (0.00 to 1.84)");
    }

    #[test]
    fn the_ratio_of_equal_rates_has_an_interval_around_one() {
        let a = RateEstimate::of(5, 10.0);
        let b = RateEstimate::of(5, 10.0);
        let r = rate_ratio(&a, &b).expect("events to compare");
        assert!(close(r.ratio, 1.0, 1e-12));
        assert!(r.low < 1.0 && r.high > 1.0, "{r:?}");
        // Twice the exposure for the same count halves the rate and the ratio.
        let half = rate_ratio(&RateEstimate::of(5, 20.0), &b).expect("events");
        assert!(close(half.ratio, 0.5, 1e-12) && close(half.low, r.low / 2.0, 1e-9));
    }

    #[test]
    fn many_more_events_in_one_condition_exclude_one() {
        let r =
            rate_ratio(&RateEstimate::of(12, 10.0), &RateEstimate::of(0, 10.0)).expect("events");
        assert!(r.ratio.is_infinite() && r.high.is_infinite());
        assert!(r.low > 1.0, "{r:?}");
        assert!(rate_ratio(&RateEstimate::of(0, 1.0), &RateEstimate::of(0, 1.0)).is_none());
        assert!(rate_ratio(&RateEstimate::of(1, 0.0), &RateEstimate::of(0, 1.0)).is_none());
    }
}
