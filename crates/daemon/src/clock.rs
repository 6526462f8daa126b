//! The process's one clock reader (DESIGN §2, STYLE habit 1): everything
//! below gets its `Instant`s from here, and clippy refuses
//! `std::time::Instant::now` / `SystemTime::now` anywhere else
//! (`clippy.toml`).

use std::sync::OnceLock;

use topspin_core::time::{Duration, Instant};

/// How early a deadline sleep wakes before spinning (DESIGN §10).
pub const SPIN_BEFORE_DEADLINE: Duration = Duration::from_micros(300);

#[allow(clippy::disallowed_methods)] // the one clock read
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
#[allow(clippy::disallowed_methods)] // the one wall-clock read
pub(crate) fn unix_offset_ns() -> u64 {
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

/// Unix time now, ns (the monotonic clock plus [`unix_offset_ns`]).
pub fn unix_now_ns() -> u64 {
    now().as_nanos().saturating_add(unix_offset_ns())
}

/// Seconds elapsed since `t` on the process clock.
pub fn secs_since(t: Instant) -> f64 {
    (now() - t).as_secs_f64()
}
