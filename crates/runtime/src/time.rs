//! Time as modules see it: nanoseconds since their host started.
//!
//! Modules never read the wall clock. The threaded host hands them monotonic time since it
//! started; the lockstep host hands them simulated time. Both use the same [`Time`] type, so a
//! stamp means the same thing in a live robot, a simulated match and a replayed log.

use std::fmt;
use std::ops::{Add, AddAssign, Sub};
use std::time::Duration;

use serde::{Deserialize, Serialize};

/// An instant on a host's clock, in nanoseconds since the host started.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
)]
#[serde(transparent)]
pub struct Time(u64);

impl Time {
    /// The instant the host started.
    pub const ZERO: Time = Time(0);
    /// Later than every instant a host will reach.
    pub const MAX: Time = Time(u64::MAX);

    pub const fn from_nanos(nanos: u64) -> Time {
        Time(nanos)
    }

    pub fn from_secs_f64(secs: f64) -> Time {
        Time((secs.max(0.0) * 1e9).round() as u64)
    }

    pub fn from_duration(duration: Duration) -> Time {
        Time(u64::try_from(duration.as_nanos()).unwrap_or(u64::MAX))
    }

    pub const fn as_nanos(self) -> u64 {
        self.0
    }

    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 * 1e-9
    }

    pub const fn as_duration(self) -> Duration {
        Duration::from_nanos(self.0)
    }

    /// The time elapsed from `earlier` to `self`, zero if `earlier` is later.
    pub fn saturating_since(self, earlier: Time) -> Duration {
        Duration::from_nanos(self.0.saturating_sub(earlier.0))
    }
}

impl Add<Duration> for Time {
    type Output = Time;
    fn add(self, rhs: Duration) -> Time {
        Time(self.0.saturating_add(u64::try_from(rhs.as_nanos()).unwrap_or(u64::MAX)))
    }
}

impl AddAssign<Duration> for Time {
    fn add_assign(&mut self, rhs: Duration) {
        *self = *self + rhs;
    }
}

impl Sub for Time {
    type Output = Duration;
    /// Saturates at zero: a stamp from the future yields no negative age.
    fn sub(self, rhs: Time) -> Duration {
        self.saturating_since(rhs)
    }
}

impl fmt::Display for Time {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:.6} s", self.as_secs_f64())
    }
}

/// The one way module code learns the time.
pub trait Clock: Send + Sync {
    fn now(&self) -> Time;
}

/// Real monotonic time since the clock was created (threaded host).
#[derive(Debug, Clone, Copy)]
pub struct MonotonicClock {
    origin: std::time::Instant,
}

impl MonotonicClock {
    pub fn start() -> MonotonicClock {
        MonotonicClock { origin: std::time::Instant::now() }
    }

    pub fn at(&self, instant: std::time::Instant) -> Time {
        Time::from_duration(instant.saturating_duration_since(self.origin))
    }

    pub fn instant(&self, time: Time) -> std::time::Instant {
        self.origin + time.as_duration()
    }
}

impl Clock for MonotonicClock {
    fn now(&self) -> Time {
        self.at(std::time::Instant::now())
    }
}

/// A clock that only moves when told to (tests, lockstep host, replay).
#[derive(Debug, Default)]
pub struct ManualClock {
    nanos: std::sync::atomic::AtomicU64,
}

impl ManualClock {
    pub fn new(start: Time) -> ManualClock {
        ManualClock { nanos: std::sync::atomic::AtomicU64::new(start.as_nanos()) }
    }

    pub fn set(&self, time: Time) {
        self.nanos.store(time.as_nanos(), std::sync::atomic::Ordering::Release);
    }
}

impl Clock for ManualClock {
    fn now(&self) -> Time {
        Time(self.nanos.load(std::sync::atomic::Ordering::Acquire))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arithmetic_saturates_instead_of_wrapping() {
        let t = Time::from_nanos(5);
        assert_eq!(t - Time::from_nanos(10), Duration::ZERO);
        assert_eq!(Time::MAX + Duration::from_secs(1), Time::MAX);
        assert_eq!((t + Duration::from_nanos(7)).as_nanos(), 12);
    }

    #[test]
    fn seconds_round_trip() {
        let t = Time::from_secs_f64(1.25);
        assert_eq!(t.as_nanos(), 1_250_000_000);
        assert!((t.as_secs_f64() - 1.25).abs() < 1e-12);
        assert_eq!(Time::from_secs_f64(-3.0), Time::ZERO);
    }
}
