//! Time as the core sees it: a monotonic instant in nanoseconds, passed in.
//!
//! Nothing in the estimation, planning or protocol code reads a clock; the
//! runtime layer (threads, sockets) does, and hands `Instant`s down. The same
//! code therefore runs on wall time in the daemon and on virtual time in the
//! simulator, in replay and in tests.

use std::ops::{Add, Sub};

/// A point on one monotonic clock, in nanoseconds since an arbitrary epoch.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Instant(pub u64);

impl Instant {
    /// The instant `ns` nanoseconds after the epoch.
    pub const fn from_nanos(ns: u64) -> Self {
        Instant(ns)
    }

    /// Nanoseconds since the epoch.
    pub const fn as_nanos(self) -> u64 {
        self.0
    }

    /// The instant `s` seconds after the epoch (negative or non-finite
    /// values saturate to the epoch).
    pub fn from_secs_f64(s: f64) -> Self {
        if s.is_finite() && s > 0.0 { Instant((s * 1e9).round() as u64) } else { Instant(0) }
    }

    /// Seconds since the epoch.
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 * 1e-9
    }

    /// Signed seconds from `earlier` to `self`.
    pub fn secs_since(self, earlier: Instant) -> f64 {
        (self.0 as i128 - earlier.0 as i128) as f64 * 1e-9
    }
}

/// A span of time in nanoseconds.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Duration(pub u64);

impl Duration {
    /// A span of `ns` nanoseconds.
    pub const fn from_nanos(ns: u64) -> Self {
        Duration(ns)
    }
    /// A span of `us` microseconds.
    pub const fn from_micros(us: u64) -> Self {
        Duration(us * 1_000)
    }
    /// A span of `ms` milliseconds.
    pub const fn from_millis(ms: u64) -> Self {
        Duration(ms * 1_000_000)
    }
    /// The span in seconds.
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 * 1e-9
    }
}

impl Add<Duration> for Instant {
    type Output = Instant;
    fn add(self, d: Duration) -> Instant {
        Instant(self.0.saturating_add(d.0))
    }
}

impl Sub<Instant> for Instant {
    type Output = Duration;
    /// Saturating difference (zero if `rhs` is later).
    fn sub(self, rhs: Instant) -> Duration {
        Duration(self.0.saturating_sub(rhs.0))
    }
}

impl Sub<Duration> for Duration {
    type Output = Duration;
    /// Saturating difference (zero if `rhs` is longer).
    fn sub(self, rhs: Duration) -> Duration {
        Duration(self.0.saturating_sub(rhs.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_round_trip() {
        let t = Instant::from_secs_f64(1.25);
        assert_eq!(t.as_nanos(), 1_250_000_000);
        assert_eq!(t.as_secs_f64(), 1.25);
        assert_eq!(Instant::from_secs_f64(f64::NAN), Instant(0));
        assert_eq!(Instant(5).secs_since(Instant(15)), -10e-9);
        assert_eq!(Instant(5) - Instant(15), Duration(0));
        assert_eq!(Instant(5) + Duration::from_micros(1), Instant(1005));
    }
}
