//! The runtime layer's clock: the only place that reads the monotonic
//! clock (DESIGN §2, STYLE habit 1). Threads and sockets live beside it
//! (`rsi::server`, `mock_krc::runner`); the core gets `Instant`s from here.

use std::sync::OnceLock;

pub mod rt;

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
