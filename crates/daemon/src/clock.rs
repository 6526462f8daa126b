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

/// CLOCK_MONOTONIC's reading, ns (the clock `std::time::Instant` reads on Linux).
#[allow(unsafe_code)]
fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid timespec the call fills; CLOCK_MONOTONIC
    // always exists on Linux, so the call cannot fail.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    (ts.tv_sec as u64).saturating_mul(1_000_000_000).saturating_add(ts.tv_nsec as u64)
}

/// CLOCK_MONOTONIC at [`now`]'s zero, ns: the smallest of a few paired
/// reads (each pair overestimates it by the time between its two reads).
fn monotonic_at_epoch() -> u64 {
    static AT: OnceLock<u64> = OnceLock::new();
    *AT.get_or_init(|| {
        (0..8)
            .map(|_| {
                let n = now().0;
                monotonic_ns().saturating_sub(n)
            })
            .min()
            .unwrap_or(0)
    })
}

/// Sleeps in the kernel until `deadline`, without spinning
/// (`clock_nanosleep` on CLOCK_MONOTONIC with `TIMER_ABSTIME`), and returns
/// how late the thread woke: the wake-up latency a thread blocked until a
/// deadline sees, cyclictest's measure (`topspin doctor`'s jitter probe).
/// The lateness is read on CLOCK_MONOTONIC itself, so it does not depend on
/// how exactly `deadline` maps onto that clock.
#[allow(unsafe_code)]
pub fn sleep_until_in_kernel(deadline: Instant) -> Duration {
    let target = deadline.0.saturating_add(monotonic_at_epoch());
    let ts = libc::timespec { tv_sec: (target / 1_000_000_000) as _, tv_nsec: (target % 1_000_000_000) as _ };
    loop {
        // SAFETY: `ts` is a valid timespec; with TIMER_ABSTIME the
        // remaining-time pointer may be null. Returns an error number.
        let rc =
            unsafe { libc::clock_nanosleep(libc::CLOCK_MONOTONIC, libc::TIMER_ABSTIME, &ts, std::ptr::null_mut()) };
        if rc != libc::EINTR {
            break;
        }
    }
    Duration(monotonic_ns().saturating_sub(target))
}

/// Unix time now, ns (the monotonic clock plus `unix_offset_ns`).
pub fn unix_now_ns() -> u64 {
    now().as_nanos().saturating_add(unix_offset_ns())
}

/// Seconds elapsed since `t` on the process clock.
pub fn secs_since(t: Instant) -> f64 {
    (now() - t).as_secs_f64()
}
