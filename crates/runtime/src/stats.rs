//! Per-module statistics, the same on both hosts: cycles, rates, compute time, latency, and
//! what happened on each input. These are the figures of the paper's Table 6.

use std::fmt::{self, Write as _};
use std::num::NonZeroU16;
use std::time::Duration;

use hdrhistogram::Histogram;
use serde::{Deserialize, Serialize};

use crate::connection::{ConnectionCounters, PolicyKind};
use crate::time::Time;

/// Histograms span 1 ns to 1000 s with two significant digits (1% resolution), which keeps a
/// hundred modules' histograms within a few megabytes.
const HISTOGRAM_MAX_NS: u64 = 1_000_000_000_000;
const HISTOGRAM_SIGFIG: u8 = 2;

fn new_histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, HISTOGRAM_MAX_NS, HISTOGRAM_SIGFIG)
        .unwrap_or_else(|_| unreachable!("the histogram bounds are constants and valid"))
}

/// `log2` of half the number of sub-buckets hdrhistogram gives each power of two: enough for
/// `HISTOGRAM_SIGFIG` digits (2 * 10^2 = 200 values, rounded up to 256 sub-buckets).
const SUB_BUCKET_HALF_MAGNITUDE: u32 =
    u64::BITS - (2 * 10u64.pow(HISTOGRAM_SIGFIG as u32) - 1).leading_zeros() - 1;

/// Counts of durations in hdrhistogram's buckets for `[1 ns, HISTOGRAM_MAX_NS]` at
/// `HISTOGRAM_SIGFIG` digits, and nothing else: the figures are computed by an hdrhistogram
/// rebuilt from the counts when a snapshot is taken, so they are the same to the bit. Every
/// cycle records two or three durations, and hdrhistogram's own record (range checks,
/// minimum, maximum, saturating counts, out of line) was a tenth of the host's own time.
#[derive(Debug, Clone, Default)]
struct Durations {
    /// By hdrhistogram's index; grown as longer durations come.
    counts: Vec<u64>,
}

impl Durations {
    /// hdrhistogram's index of `ns` (already clamped to `[1, HISTOGRAM_MAX_NS]`), for a lowest
    /// discernible value of 1: the power of two above the sub-buckets, and the sub-bucket.
    const fn index(ns: u64) -> usize {
        let sub_bucket_mask = (1u64 << (SUB_BUCKET_HALF_MAGNITUDE + 1)) - 1;
        let bucket =
            (u64::BITS - SUB_BUCKET_HALF_MAGNITUDE - 1) - (ns | sub_bucket_mask).leading_zeros();
        let sub_bucket = (ns >> bucket) as usize;
        ((bucket as usize + 1) << SUB_BUCKET_HALF_MAGNITUDE) + sub_bucket
            - (1 << SUB_BUCKET_HALF_MAGNITUDE)
    }

    /// The lowest duration of an index's bucket (hdrhistogram's `value_for`).
    fn lowest_at(index: usize) -> u64 {
        let half = 1usize << SUB_BUCKET_HALF_MAGNITUDE;
        match (index >> SUB_BUCKET_HALF_MAGNITUDE).checked_sub(1) {
            None => index as u64,
            Some(bucket) => ((index & (half - 1)) + half) as u64 * (1u64 << bucket),
        }
    }

    /// The index of `ns` (clamped), small enough for an [`Uncounted`] entry: indices of
    /// durations of 1 ns and more start at 1.
    fn small_index(ns: u64) -> NonZeroU16 {
        const { assert!(Durations::index(HISTOGRAM_MAX_NS) <= u16::MAX as usize) };
        u16::try_from(Self::index(ns)).ok().and_then(NonZeroU16::new).unwrap_or_else(|| {
            unreachable!("a clamped duration's index is between 1 and the largest one's")
        })
    }

    fn record(&mut self, ns: u64) {
        self.count(Self::index(ns));
    }

    fn count(&mut self, index: usize) {
        if index >= self.counts.len() {
            self.counts.resize(index + 1, 0);
        }
        self.counts[index] += 1;
    }

    /// The histogram of the counts and of `uncounted` (indices not counted yet).
    fn histogram(&self, uncounted: impl Iterator<Item = NonZeroU16>) -> Histogram<u64> {
        let mut histogram = new_histogram();
        for (index, &count) in self.counts.iter().enumerate().filter(|(_, c)| **c > 0) {
            let _ = histogram.record_n(Self::lowest_at(index), count);
        }
        for index in uncounted {
            let _ = histogram.record(Self::lowest_at(usize::from(index.get())));
        }
        histogram
    }
}

/// One cycle's durations as bucket indices, not counted yet.
#[derive(Debug, Clone, Copy)]
struct Uncounted {
    period: Option<NonZeroU16>,
    compute: NonZeroU16,
    latency: Option<NonZeroU16>,
}

/// How many cycles a collector holds before counting their durations.
const UNCOUNTED: usize = 64;

/// A distribution of durations recorded one at a time, summarized like a module's compute
/// time: for figures a platform or a command measures outside the modules (the compute of a
/// whole robot per sensor cycle), with the same resolution and the same percentiles.
#[derive(Debug, Clone, Default)]
pub struct DurationRecorder {
    durations: Durations,
    count: u64,
}

impl DurationRecorder {
    pub fn record(&mut self, duration: Duration) {
        self.durations.record(clamp_ns(duration));
        self.count += 1;
    }

    pub fn count(&self) -> u64 {
        self.count
    }

    pub fn summary(&self) -> Summary {
        Summary::of(&self.durations.histogram(std::iter::empty()))
    }
}

/// Collects one module's statistics as its cycles run.
#[derive(Debug, Clone)]
pub struct StatsCollector {
    /// The rate window in nanoseconds: cycles compare and subtract times as integers.
    window_ns: u64,
    cycles: u64,
    first_start: Option<Time>,
    last_start: Option<Time>,
    window_first: Option<Time>,
    window_intervals: u64,
    min_rate: Option<f64>,
    max_rate: Option<f64>,
    compute: Durations,
    latency: Durations,
    period: Durations,
    /// The latest cycles' durations, counted in `compute`, `latency` and `period` only once
    /// `UNCOUNTED` have gathered. The counts lie apart in memory, and a match runs a hundred
    /// other modules between two cycles of one, so counting each cycle as it ended waited for
    /// three evicted cache lines (about 4 % of a match's time, `perf record`); a batch fetches
    /// each line it touches once. Inline, beside the fields every cycle writes anyway.
    uncounted: [Uncounted; UNCOUNTED],
    uncounted_len: usize,
    errors: u64,
    pub(crate) scheduling: Scheduling,
}

impl StatsCollector {
    /// `window`: the span over which a rate is measured for the min/max figures; a window
    /// closes at the first cycle at least `window` after it opened, so slow modules get a rate
    /// from whole intervals.
    pub fn new(window: Duration) -> StatsCollector {
        StatsCollector {
            window_ns: u64::try_from(window.as_nanos()).unwrap_or(u64::MAX),
            cycles: 0,
            first_start: None,
            last_start: None,
            window_first: None,
            window_intervals: 0,
            min_rate: None,
            max_rate: None,
            compute: Durations::default(),
            latency: Durations::default(),
            period: Durations::default(),
            uncounted: [Uncounted { period: None, compute: NonZeroU16::MIN, latency: None };
                UNCOUNTED],
            uncounted_len: 0,
            errors: 0,
            scheduling: Scheduling::Default,
        }
    }

    /// Records how the host scheduled the module's thread (reported with the statistics).
    pub fn set_scheduling(&mut self, scheduling: Scheduling) {
        self.scheduling = scheduling;
    }

    /// Records a cycle that started at `start`, took `compute`, and whose outputs became
    /// visible `latency` after the event that triggered it (None if it sent nothing).
    pub fn record_cycle(&mut self, start: Time, compute: Duration, latency: Option<Duration>) {
        self.cycles += 1;
        let mut period = None;
        if let Some(last) = self.last_start {
            let interval_ns = start.as_nanos().saturating_sub(last.as_nanos());
            period = Some(Durations::small_index(interval_ns.clamp(1, HISTOGRAM_MAX_NS)));
            self.window_intervals += 1;
        }
        self.first_start.get_or_insert(start);
        self.last_start = Some(start);
        let window_first = *self.window_first.get_or_insert(start);
        let elapsed_ns = start.as_nanos().saturating_sub(window_first.as_nanos());
        if elapsed_ns >= self.window_ns && self.window_intervals > 0 {
            let elapsed = start - window_first;
            let rate = self.window_intervals as f64 / elapsed.as_secs_f64();
            self.min_rate = Some(self.min_rate.map_or(rate, |m| m.min(rate)));
            self.max_rate = Some(self.max_rate.map_or(rate, |m| m.max(rate)));
            self.window_first = Some(start);
            self.window_intervals = 0;
        }
        self.uncounted[self.uncounted_len] = Uncounted {
            period,
            compute: Durations::small_index(clamp_ns(compute)),
            latency: latency.map(|latency| Durations::small_index(clamp_ns(latency))),
        };
        self.uncounted_len += 1;
        if self.uncounted_len == UNCOUNTED {
            self.count_uncounted();
        }
    }

    fn count_uncounted(&mut self) {
        for entry in &self.uncounted[..self.uncounted_len] {
            if let Some(period) = entry.period {
                self.period.count(usize::from(period.get()));
            }
            self.compute.count(usize::from(entry.compute.get()));
            if let Some(latency) = entry.latency {
                self.latency.count(usize::from(latency.get()));
            }
        }
        self.uncounted_len = 0;
    }

    pub fn record_error(&mut self) {
        self.errors += 1;
    }

    pub fn cycles(&self) -> u64 {
        self.cycles
    }

    pub fn snapshot(&self, name: &str, inputs: Vec<InputStats>) -> ModuleStats {
        let mean = match (self.first_start, self.last_start) {
            (Some(first), Some(last)) if last > first && self.cycles > 1 => {
                (self.cycles - 1) as f64 / (last - first).as_secs_f64()
            }
            _ => 0.0,
        };
        // Before a first window closes (short runs), the overall mean is the best estimate.
        let rate = RateStats {
            min_hz: self.min_rate.unwrap_or(mean),
            mean_hz: mean,
            max_hz: self.max_rate.unwrap_or(mean),
        };
        let uncounted = self.uncounted[..self.uncounted_len].iter();
        ModuleStats {
            name: name.to_owned(),
            cycles: self.cycles,
            errors: self.errors,
            rate,
            compute_time: Summary::of(
                &self.compute.histogram(uncounted.clone().map(|u| u.compute)),
            ),
            latency: Summary::of(
                &self.latency.histogram(uncounted.clone().filter_map(|u| u.latency)),
            ),
            period: Summary::of(&self.period.histogram(uncounted.filter_map(|u| u.period))),
            inputs,
            scheduling: self.scheduling.clone(),
        }
    }
}

fn clamp_ns(duration: Duration) -> u64 {
    u64::try_from(duration.as_nanos()).unwrap_or(u64::MAX).clamp(1, HISTOGRAM_MAX_NS)
}

/// Min / mean / max cycle rate (the columns of Table 6).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RateStats {
    pub min_hz: f64,
    pub mean_hz: f64,
    pub max_hz: f64,
}

/// A distribution of durations, in microseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub count: u64,
    pub mean_us: f64,
    pub min_us: f64,
    pub p50_us: f64,
    pub p90_us: f64,
    pub p99_us: f64,
    pub max_us: f64,
}

impl Summary {
    fn of(histogram: &Histogram<u64>) -> Summary {
        if histogram.is_empty() {
            return Summary::default();
        }
        let us = |ns: u64| ns as f64 / 1000.0;
        Summary {
            count: histogram.len(),
            mean_us: histogram.mean() / 1000.0,
            min_us: us(histogram.min()),
            p50_us: us(histogram.value_at_quantile(0.5)),
            p90_us: us(histogram.value_at_quantile(0.9)),
            p99_us: us(histogram.value_at_quantile(0.99)),
            max_us: us(histogram.max()),
        }
    }
}

/// One input port's policy and counters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InputStats {
    pub port: String,
    pub policy: PolicyKind,
    #[serde(flatten)]
    pub counters: ConnectionCounters,
}

/// Everything measured about one module.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModuleStats {
    pub name: String,
    pub cycles: u64,
    /// Cycles that returned an error (the host stops at the first).
    pub errors: u64,
    pub rate: RateStats,
    /// Threaded host: measured wall time of each cycle. Lockstep host: the modelled
    /// processing time.
    pub compute_time: Summary,
    /// From the event that triggered a cycle to its outputs becoming visible.
    pub latency: Summary,
    /// Intervals between consecutive cycle starts (their spread is the jitter).
    pub period: Summary,
    pub inputs: Vec<InputStats>,
    /// How the module's thread was scheduled (threaded host).
    #[serde(default)]
    pub scheduling: Scheduling,
}

/// How the threaded host scheduled a module's thread.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "policy")]
pub enum Scheduling {
    /// The operating system's default policy: every module of the lockstep host, and those the
    /// threaded host was not asked to run in real time.
    #[default]
    Default,
    /// `SCHED_FIFO` at this priority: the module's thread preempts every default-policy thread.
    RealTime { priority: u8 },
    /// A real-time priority was asked for and refused; the thread runs with the default policy.
    RealTimeRefused { priority: u8, reason: String },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HostKind {
    Threaded,
    Lockstep,
}

/// The statistics of every module of a host, as one serializable value.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HostStats {
    pub host: HostKind,
    /// Host time elapsed (simulated time on the lockstep host).
    pub elapsed_s: f64,
    /// Wall-clock time the host ran.
    pub wall_s: f64,
    pub modules: Vec<ModuleStats>,
}

impl HostStats {
    pub fn module(&self, name: &str) -> Option<&ModuleStats> {
        self.modules.iter().find(|m| m.name == name)
    }

    /// Queue overflows (dropped packages) summed over every input of every module.
    pub fn total_dropped(&self) -> u64 {
        self.modules.iter().flat_map(|m| &m.inputs).map(|i| i.counters.dropped).sum()
    }

    /// A fixed-width table for terminals.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{:<28} {:>8} {:>9} {:>9} {:>9} {:>10} {:>10} {:>10} {:>8}",
            "module",
            "cycles",
            "min Hz",
            "mean Hz",
            "max Hz",
            "cpu p50us",
            "cpu p99us",
            "lat p99us",
            "dropped"
        );
        for m in &self.modules {
            let dropped: u64 = m.inputs.iter().map(|i| i.counters.dropped).sum();
            let _ = writeln!(
                out,
                "{:<28} {:>8} {:>9.2} {:>9.2} {:>9.2} {:>10.1} {:>10.1} {:>10.1} {:>8}",
                truncate(&m.name, 28),
                m.cycles,
                m.rate.min_hz,
                m.rate.mean_hz,
                m.rate.max_hz,
                m.compute_time.p50_us,
                m.compute_time.p99_us,
                m.latency.p99_us,
                dropped
            );
        }
        out
    }
}

impl fmt::Display for HostStats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.table())
    }
}

fn truncate(s: &str, width: usize) -> String {
    if s.chars().count() <= width {
        s.to_owned()
    } else {
        let mut t: String = s.chars().take(width.saturating_sub(1)).collect();
        t.push('…');
        t
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    #[test]
    fn a_duration_recorder_summarizes_what_it_recorded() {
        let mut recorder = DurationRecorder::default();
        assert_eq!(recorder.summary(), Summary::default());
        for us in 1..=100 {
            recorder.record(Duration::from_micros(us));
        }
        let summary = recorder.summary();
        assert_eq!((recorder.count(), summary.count), (100, 100));
        // Two significant digits: within 1 %.
        assert!((summary.p50_us - 50.0).abs() <= 0.5, "{summary:?}");
        assert!((summary.p99_us - 99.0).abs() <= 1.0, "{summary:?}");
        assert!((summary.max_us - 100.0).abs() <= 1.0, "{summary:?}");
    }

    #[test]
    fn duration_buckets_are_hdrhistograms() {
        let reference = new_histogram();
        let mut values: Vec<u64> = (1..=70_000).collect();
        for k in 1..40 {
            values.extend([(1u64 << k) - 1, 1 << k, (1 << k) + 1, 3 << (k - 1)]);
        }
        // A deterministic spread over the whole range.
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..100_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            values.push(1 + x % HISTOGRAM_MAX_NS);
        }
        values.push(HISTOGRAM_MAX_NS);
        values.sort_unstable();
        let mut previous = 0;
        for v in values {
            let index = Durations::index(v);
            assert_eq!(Durations::lowest_at(index), reference.lowest_equivalent(v), "{v} ns");
            assert!(index >= previous, "{v} ns");
            previous = index;
        }
    }

    proptest! {
        /// The statistics from bucket counts against hdrhistograms recorded the plain way.
        #[test]
        fn summaries_are_those_of_plain_hdrhistograms(
            cycles in proptest::collection::vec(
                (0u64..50_000_000, 0u64..20_000_000, proptest::option::of(0u64..2_000_000_000)),
                1..300,
            ),
        ) {
            let mut stats = StatsCollector::new(Duration::from_secs(1));
            let (mut compute, mut latency, mut period) =
                (new_histogram(), new_histogram(), new_histogram());
            let mut start = Time::ZERO;
            for (i, &(gap, compute_ns, latency_ns)) in cycles.iter().enumerate() {
                start += Duration::from_nanos(gap);
                stats.record_cycle(
                    start,
                    Duration::from_nanos(compute_ns),
                    latency_ns.map(Duration::from_nanos),
                );
                if i > 0 {
                    period.record(gap.max(1)).expect("in range");
                }
                compute.record(compute_ns.max(1)).expect("in range");
                if let Some(ns) = latency_ns {
                    latency.record(ns.max(1)).expect("in range");
                }
            }
            let s = stats.snapshot("m", Vec::new());
            prop_assert_eq!(s.compute_time, Summary::of(&compute));
            prop_assert_eq!(s.latency, Summary::of(&latency));
            prop_assert_eq!(s.period, Summary::of(&period));
        }
    }

    #[test]
    fn rates_from_regular_cycles() {
        let mut stats = StatsCollector::new(Duration::from_secs(1));
        for i in 0..=200u64 {
            stats.record_cycle(Time::from_nanos(i * 10_000_000), Duration::from_micros(5), None);
        }
        let s = stats.snapshot("m", Vec::new());
        assert_eq!(s.cycles, 201);
        assert!((s.rate.mean_hz - 100.0).abs() < 1e-6, "{:?}", s.rate);
        assert!((s.rate.min_hz - 100.0).abs() < 1e-6, "{:?}", s.rate);
        assert!((s.rate.max_hz - 100.0).abs() < 1e-6, "{:?}", s.rate);
        assert!((s.compute_time.p50_us - 5.0).abs() < 0.1);
    }

    #[test]
    fn a_stall_lowers_the_minimum_rate() {
        let mut stats = StatsCollector::new(Duration::from_secs(1));
        let mut t = 0u64;
        for _ in 0..300 {
            stats.record_cycle(Time::from_nanos(t), Duration::ZERO, None);
            t += 10_000_000;
        }
        t += 4_000_000_000; // the module stalls for 4 s
        for _ in 0..300 {
            stats.record_cycle(Time::from_nanos(t), Duration::ZERO, None);
            t += 10_000_000;
        }
        let s = stats.snapshot("m", Vec::new());
        // The window holding the stall averages it with its other cycles...
        assert!(s.rate.min_hz < 25.0, "{:?}", s.rate);
        // ...and the period distribution keeps the stall itself.
        assert!(s.period.max_us >= 3.9e6, "{:?}", s.period);
        assert!((s.rate.max_hz - 100.0).abs() < 1e-6);
    }

    #[test]
    fn slow_modules_get_rates_from_whole_intervals() {
        let mut stats = StatsCollector::new(Duration::from_secs(1));
        for i in 0..20u64 {
            stats.record_cycle(Time::from_nanos(i * 625_000_000), Duration::ZERO, None);
        }
        let s = stats.snapshot("deliberative", Vec::new());
        assert!((s.rate.mean_hz - 1.6).abs() < 1e-9);
        assert!((s.rate.min_hz - 1.6).abs() < 1e-9);
    }
}
