//! The runtime layer: the only place that reads the monotonic clock
//! (DESIGN §2, STYLE habit 1), the daemon's threads ([`daemon`]), their
//! real-time set-up ([`rt`]) and telemetry ([`telemetry`]). Sockets live
//! here and in the thin loops `rsi::server`, `mock_krc::runner` and
//! `sim::stream`; the core gets `Instant`s from here.

use std::sync::OnceLock;

pub mod daemon;
pub mod rt;
pub mod telemetry;

use crate::time::{Duration, Instant};

/// How early a deadline sleep wakes before spinning (DESIGN §10).
pub const SPIN_BEFORE_DEADLINE: Duration = Duration::from_micros(300);

fn epoch() -> std::time::Instant {
    static EPOCH: OnceLock<std::time::Instant> = OnceLock::new();
    *EPOCH.get_or_init(std::time::Instant::now)
}

/// Now on the process's monotonic clock (ns since the first call).
pub fn now() -> Instant {
    Instant(epoch().elapsed().as_nanos() as u64)
}

/// Unix time (ns) minus [`now`], taken once per process: `now() + offset`
/// is wall-clock time, for the log times of the recording and the live view
/// (Foxglove's timeline), while everything else stays on the monotonic clock.
pub fn unix_offset_ns() -> u64 {
    static OFFSET: OnceLock<u64> = OnceLock::new();
    *OFFSET.get_or_init(|| {
        let mono = now().as_nanos();
        let unix =
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64);
        unix.saturating_sub(mono)
    })
}

/// Waits until `deadline`: sleeps until `spin` before it, then spins.
pub fn sleep_until(deadline: Instant, spin: Duration) {
    let t = now();
    if deadline <= t {
        return;
    }
    let left = deadline - t;
    if left > spin {
        std::thread::sleep(std::time::Duration::from_nanos((left - spin).0));
    }
    while now() < deadline {
        std::hint::spin_loop();
    }
}

impl std::ops::Sub<Duration> for Duration {
    type Output = Duration;
    fn sub(self, rhs: Duration) -> Duration {
        Duration(self.0.saturating_sub(rhs.0))
    }
}
