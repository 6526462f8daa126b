//! Mapping the tracker's clock onto ours (DESIGN §5.1): the tracker may run
//! on another PC with its own monotonic clock. The offset is the minimum of
//! (arrival − capture) over a sliding window of recent datagrams — the
//! least-delayed datagram bounds the offset from above — plus a configured
//! fixed latency (the part of the delay that is always there). A clock that
//! jumps is detected and the window restarts.
//!
//! Allocation-free: the sliding minimum is a monotonic deque of named
//! capacity, O(1) amortised per datagram.

use heapless::Deque;

use crate::time::Instant;

/// Datagrams the sliding minimum spans (≈ 2 s at 250 Hz).
pub(crate) const CLOCK_WINDOW: usize = 512;

/// A clock jump: the apparent delay moved by more than this, ns.
pub(crate) const JUMP_NS: i128 = 50_000_000;

/// Datagrams in a row far above the minimum that mean the tracker clock
/// went back (a few late datagrams alone do not).
pub(crate) const JUMP_RUN: usize = 8;

/// Tracker clock → our clock.
#[derive(Debug, Clone)]
pub struct ClockMap {
    fixed_latency_ns: i128,
    /// (index, delay) pairs with increasing delay: the sliding minimum.
    window: Deque<(u64, i128), CLOCK_WINDOW>,
    count: u64,
    jumps: u64,
    /// Datagrams in a row far above the minimum.
    far_run: usize,
}

impl ClockMap {
    /// `fixed_latency_ns`: the delay every datagram has at least (exposure
    /// to triangulation), added to the measured minimum.
    pub fn new(fixed_latency_ns: u64) -> Self {
        ClockMap { fixed_latency_ns: fixed_latency_ns as i128, window: Deque::new(), count: 0, jumps: 0, far_run: 0 }
    }

    /// Clock jumps seen so far.
    pub fn jumps(&self) -> u64 {
        self.jumps
    }

    /// The current offset (our time = tracker time + offset), ns, if any
    /// datagram has been seen.
    pub(crate) fn offset_ns(&self) -> Option<i128> {
        self.window.front().map(|&(_, d)| d - self.fixed_latency_ns)
    }

    /// Takes one datagram's capture time (tracker clock) and arrival time
    /// (ours) and returns the capture time on our clock.
    pub fn map(&mut self, capture_ns: u64, arrival: Instant) -> Instant {
        let delay = arrival.as_nanos() as i128 - capture_ns as i128;
        if let Some(&(_, min)) = self.window.front() {
            // Far below the minimum: the tracker clock jumped forward. A run
            // far above it: the tracker clock went back. Either way, start over.
            self.far_run = if delay - min > JUMP_NS { self.far_run + 1 } else { 0 };
            if min - delay > JUMP_NS || self.far_run >= JUMP_RUN {
                self.window.clear();
                self.jumps += 1;
                self.far_run = 0;
            }
        }
        // Sliding minimum: drop larger delays from the back, old ones from the front.
        while self.window.back().is_some_and(|&(_, d)| d >= delay) {
            self.window.pop_back();
        }
        if self.window.is_full() {
            self.window.pop_front();
        }
        let _ = self.window.push_back((self.count, delay));
        while self.window.front().is_some_and(|&(i, _)| i + (CLOCK_WINDOW as u64) <= self.count) {
            self.window.pop_front();
        }
        self.count += 1;
        let offset = self.offset_ns().unwrap_or(0);
        let mapped = capture_ns as i128 + offset;
        Instant::from_nanos(mapped.clamp(0, arrival.as_nanos() as i128) as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offset_is_the_least_delay_plus_fixed_latency() {
        let mut m = ClockMap::new(2_000_000);
        // Tracker clock 10 s behind ours; delays 3–7 ms.
        for i in 0..100u64 {
            let capture = 1_000_000_000 + i * 6_666_667;
            let delay = 3_000_000 + (i * 7919 % 4_000_000);
            let arrival = Instant::from_nanos(capture + 10_000_000_000 + delay);
            let mapped = m.map(capture, arrival);
            assert!(mapped <= arrival);
        }
        assert_eq!(m.offset_ns(), Some(10_000_000_000 + 3_000_000 - 2_000_000));
    }

    #[test]
    fn a_jumping_tracker_clock_is_followed() {
        let mut m = ClockMap::new(0);
        let mut arrival = 5_000_000_000u64;
        for i in 0..50u64 {
            arrival += 5_000_000;
            m.map(1_000 + i * 5_000_000, Instant::from_nanos(arrival));
        }
        let before = m.offset_ns().unwrap();
        // The tracker's clock jumps back by 3 s.
        for i in 0..50u64 {
            arrival += 5_000_000;
            m.map(1_000 + i * 5_000_000, Instant::from_nanos(arrival));
        }
        assert_eq!(m.jumps(), 1);
        assert!((m.offset_ns().unwrap() - before - 250_000_000).abs() < 1_000, "{:?}", m.offset_ns());
        // ... and forward by 10 s.
        for i in 0..50u64 {
            arrival += 5_000_000;
            m.map(20_000_000_000 + i * 5_000_000, Instant::from_nanos(arrival));
        }
        assert_eq!(m.jumps(), 2);
        let mapped = m.map(20_000_000_000 + 50 * 5_000_000, Instant::from_nanos(arrival + 5_000_000));
        assert_eq!(mapped.as_nanos(), arrival + 5_000_000);
    }
}
