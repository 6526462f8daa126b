//! Real-time readiness of the kernel and of this process: the kernel's
//! preemption model (`/sys/kernel/realtime`, `/proc/version`, `preempt=` on
//! `/proc/cmdline`), the right to SCHED_FIFO at the configured priorities
//! and to lock memory (`RLIMIT_RTPRIO`, `RLIMIT_MEMLOCK`, `CapEff` of
//! `/proc/self/status`), and RT throttling (`/proc/sys/kernel/sched_rt_*`).
//!
//! The limits and capabilities are this process's: run as a login user the
//! checks say what that user may do, which is not what the service gets
//! from `deploy/topspin.service` (`AmbientCapabilities=`, `LimitRTPRIO=`,
//! `LimitMEMLOCK=`); the fixes say so.

use super::sysfs::{cmdline_param, status_field};
use super::{Check, Host};
use crate::config::{DaemonConfig, RsiWait};

/// `CAP_IPC_LOCK`'s bit in a capability mask (linux/capability.h).
pub(crate) const CAP_IPC_LOCK: u32 = 14;
/// `CAP_SYS_NICE`'s bit.
pub(crate) const CAP_SYS_NICE: u32 = 23;

/// What the unit gives the service (the fix when this process lacks it).
const SERVICE_RIGHTS: &str = "the service gets them from deploy/topspin.service (AmbientCapabilities=CAP_SYS_NICE CAP_IPC_LOCK, \
LimitRTPRIO=99, LimitMEMLOCK=infinity); to run by hand: /etc/security/limits.d/topspin.conf with `USER - rtprio 99` and \
`USER - memlock unlimited`, or run doctor as the service runs (docs/guide/doctor.md)";

/// This process's effective capabilities (`CapEff`).
pub(crate) fn cap_eff(host: &Host) -> Result<u64, String> {
    let path = "/proc/self/status";
    let status = host.root.read(path).map_err(|e| e.to_string())?;
    let hex = status_field(&status, "CapEff").ok_or_else(|| format!("{path} has no CapEff line"))?;
    u64::from_str_radix(hex, 16).map_err(|_| format!("{path}: CapEff {hex:?} is not a hex mask"))
}

fn has_cap(mask: u64, cap: u32) -> bool {
    mask >> cap & 1 == 1
}

/// Whether this process may lock all its memory (`CAP_IPC_LOCK`, or an
/// unlimited `RLIMIT_MEMLOCK`); `None` when neither could be read.
pub(crate) fn memlock_allowed(host: &Host) -> Option<bool> {
    let cap = cap_eff(host).ok().map(|m| has_cap(m, CAP_IPC_LOCK));
    let limit = host.memlock.as_ref().ok().map(|l| l.soft.is_none());
    match (cap, limit) {
        (Some(true), _) | (_, Some(true)) => Some(true),
        (None, None) => None,
        _ => Some(false),
    }
}

/// The kernel's release (`6.1.0-18-rt-amd64`) from `/proc/version`.
fn release(version: &str) -> &str {
    version.split_whitespace().nth(2).unwrap_or("?")
}

const RT_KERNEL_FIX: &str = "install a PREEMPT_RT kernel (Debian: linux-image-rt-amd64; Ubuntu: `pro enable realtime-kernel`; \
or build with CONFIG_PREEMPT_RT, in mainline since 6.12) and run the jitter probe again";

/// `kernel`: PREEMPT_RT (pass) or any other preemption model (warn; the
/// jitter probe says whether it is good enough).
pub(crate) fn kernel(host: &Host) -> Check {
    const NAME: &str = "kernel";
    let realtime = host.root.read_trim("/sys/kernel/realtime").ok();
    let version = host.root.read_trim("/proc/version");
    let words: Vec<&str> = version.as_deref().map(|v| v.split_whitespace().collect()).unwrap_or_default();
    let rel = version.as_deref().map_or("?", release);
    // Old RT patches printed "PREEMPT RT", newer ones "PREEMPT_RT".
    let rt_words = words.contains(&"PREEMPT_RT") || words.windows(2).any(|w| w == ["PREEMPT", "RT"]);
    if realtime.as_deref() == Some("1") || rt_words {
        let how = if realtime.as_deref() == Some("1") { "/sys/kernel/realtime = 1" } else { "/proc/version" };
        return Check::pass(NAME, format!("PREEMPT_RT kernel {rel} ({how})"));
    }
    if let Err(e) = version {
        return Check::unknown(NAME, e);
    }
    let detail = if words.contains(&"PREEMPT_DYNAMIC") {
        let cmdline = host.root.read("/proc/cmdline").unwrap_or_default();
        let mode = cmdline_param(&cmdline, "preempt")
            .map_or("the build's default model".to_owned(), |m| format!("booted with preempt={m}"));
        format!("kernel {rel} is PREEMPT_DYNAMIC ({mode}), not PREEMPT_RT")
    } else if words.contains(&"PREEMPT") {
        format!("kernel {rel} is PREEMPT (preemptible, not real-time)")
    } else {
        format!(
            "kernel {rel} has no kernel preemption (PREEMPT_NONE or VOLUNTARY): a long kernel path can hold the RSI thread off for milliseconds"
        )
    };
    Check::warn(NAME, detail, RT_KERNEL_FIX)
}

/// `rtprio`: this process may use SCHED_FIFO at the configured priorities
/// (pass) or not (warn: the daemon then runs with normal scheduling).
pub(crate) fn rtprio(host: &Host, cfg: &DaemonConfig) -> Check {
    const NAME: &str = "rtprio";
    let t = &cfg.threads;
    if !t.realtime {
        return Check::warn(
            NAME,
            "threads.realtime = false: the daemon's threads run without SCHED_FIFO",
            "set threads.realtime = true",
        );
    }
    let need = u64::from(t.rsi_priority.max(t.ingest_priority).max(t.estimator_priority));
    let caps = cap_eff(host);
    if let Ok(m) = caps
        && has_cap(m, CAP_SYS_NICE)
    {
        return Check::pass(NAME, format!("CAP_SYS_NICE in effect: SCHED_FIFO up to 99 (configured up to {need})"));
    }
    match (&host.rtprio, caps) {
        (Ok(l), _) if l.soft.is_none_or(|s| s >= need) => Check::pass(
            NAME,
            format!(
                "RLIMIT_RTPRIO {} ≥ {need}: SCHED_FIFO allowed",
                l.soft.map_or("unlimited".to_owned(), |s| s.to_string())
            ),
        ),
        (Ok(l), Ok(_)) => Check::warn(
            NAME,
            format!(
                "this process may not use SCHED_FIFO {need} (RLIMIT_RTPRIO {}, no CAP_SYS_NICE): run like this the daemon gets EPERM and normal scheduling",
                l.soft.unwrap_or(0)
            ),
            SERVICE_RIGHTS,
        ),
        (Err(e), _) => Check::unknown(NAME, format!("getrlimit(RLIMIT_RTPRIO): {e}")),
        (Ok(_), Err(e)) => Check::unknown(NAME, e),
    }
}

fn bytes(n: u64) -> String {
    if n >= 1 << 20 { format!("{} MiB", n >> 20) } else { format!("{} KiB", n >> 10) }
}

/// `memlock`: this process may lock all its memory (pass) or not (warn:
/// `mlockall` fails with ENOMEM and pages may be swapped or faulted).
pub(crate) fn memlock(host: &Host, cfg: &DaemonConfig) -> Check {
    const NAME: &str = "memlock";
    if !cfg.threads.realtime {
        return Check::warn(
            NAME,
            "threads.realtime = false: the daemon does not lock its memory",
            "set threads.realtime = true",
        );
    }
    let caps = cap_eff(host);
    if let Ok(m) = caps
        && has_cap(m, CAP_IPC_LOCK)
    {
        return Check::pass(NAME, "CAP_IPC_LOCK in effect: mlockall allowed");
    }
    match (&host.memlock, caps) {
        (Ok(l), _) if l.soft.is_none() => Check::pass(NAME, "RLIMIT_MEMLOCK unlimited: mlockall allowed"),
        (Ok(l), Ok(_)) => Check::warn(
            NAME,
            format!(
                "RLIMIT_MEMLOCK {} and no CAP_IPC_LOCK: run like this the daemon's mlockall fails (ENOMEM) and its memory may page",
                bytes(l.soft.unwrap_or(0))
            ),
            SERVICE_RIGHTS,
        ),
        (Err(e), _) => Check::unknown(NAME, format!("getrlimit(RLIMIT_MEMLOCK): {e}")),
        (Ok(_), Err(e)) => Check::unknown(NAME, e),
    }
}

/// `rt_throttling`: SCHED_FIFO threads get CPU time (fail if the kernel
/// gives them none) and the configured wait strategy stays clear of the
/// throttle (warn when a busy-polling RSI thread can hit it).
pub(crate) fn throttling(host: &Host, cfg: &DaemonConfig) -> Check {
    const NAME: &str = "rt_throttling";
    let read = |p: &str| -> Result<i64, String> {
        let t = host.root.read_trim(p).map_err(|e| e.to_string())?;
        t.parse().map_err(|_| format!("{p}: {t:?} is not a number"))
    };
    let (runtime, period) =
        match (read("/proc/sys/kernel/sched_rt_runtime_us"), read("/proc/sys/kernel/sched_rt_period_us")) {
            (Ok(r), Ok(p)) => (r, p),
            (Err(e), _) | (_, Err(e)) => return Check::unknown(NAME, e),
        };
    if !cfg.threads.realtime {
        return Check::pass(NAME, "no SCHED_FIFO threads (threads.realtime = false)");
    }
    if runtime < 0 {
        return Check::pass(NAME, "RT throttling off (sched_rt_runtime_us = -1)");
    }
    if runtime == 0 {
        return Check::fail(
            NAME,
            "sched_rt_runtime_us = 0: SCHED_FIFO threads get no CPU time",
            "`sudo sysctl -w kernel.sched_rt_runtime_us=950000` (the default) and keep it in /etc/sysctl.d/",
        );
    }
    let pct = runtime as f64 * 100.0 / period.max(1) as f64;
    if cfg.threads.rsi_wait == RsiWait::BusyPoll {
        let stop = (period - runtime).max(0);
        Check::warn(
            NAME,
            format!(
                "RT throttling leaves SCHED_FIFO threads {runtime} of every {period} µs ({pct:.0} %): the busy-polling RSI thread (rsi_wait = busy_poll) can be stopped for {stop} µs ({} cycles) each period",
                stop / 4_000
            ),
            "`sudo sysctl -w kernel.sched_rt_runtime_us=-1` (keep it in /etc/sysctl.d/), or threads.rsi_wait = \"blocking\"",
        )
    } else {
        Check::pass(
            NAME,
            format!(
                "RT throttling at {pct:.0} % ({runtime}/{period} µs); the RSI thread blocks between datagrams and stays far below it"
            ),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::super::Status;
    use super::super::fake::Fake;
    use super::super::host::Limit;
    use super::*;

    const NO_CAPS: &str = "Name:\ttopspin\nCapEff:\t0000000000000000\n";
    /// CAP_SYS_NICE and CAP_IPC_LOCK, as the unit grants them.
    const UNIT_CAPS: &str = "Name:\ttopspin\nCapEff:\t0000000000804000\n";

    #[test]
    fn kernel_pass_and_warn() {
        let f = Fake::new();
        f.file(
            "/proc/version",
            "Linux version 6.1.0-18-rt-amd64 (debian-kernel@lists.debian.org) #1 SMP PREEMPT_RT Debian 6.1.76-1\n",
        );
        assert_eq!(kernel(&f.host), Check::pass("kernel", "PREEMPT_RT kernel 6.1.0-18-rt-amd64 (/proc/version)"));
        f.file("/sys/kernel/realtime", "1\n");
        assert_eq!(kernel(&f.host).detail, "PREEMPT_RT kernel 6.1.0-18-rt-amd64 (/sys/kernel/realtime = 1)");

        let f = Fake::new();
        f.file(
            "/proc/version",
            "Linux version 6.8.0-45-generic (buildd@lcy02) #45-Ubuntu SMP PREEMPT_DYNAMIC Fri Aug 30\n",
        )
        .file("/proc/cmdline", "BOOT_IMAGE=/vmlinuz ro preempt=full\n");
        let c = kernel(&f.host);
        assert_eq!(c.status, Status::Warn);
        assert_eq!(c.detail, "kernel 6.8.0-45-generic is PREEMPT_DYNAMIC (booted with preempt=full), not PREEMPT_RT");
        assert!(c.fix.unwrap().starts_with("install a PREEMPT_RT kernel"));

        f.file("/proc/version", "Linux version 4.18.0-513.el8.x86_64 (mockbuild@x86-vm-07) #1 SMP Wed Oct 25\n");
        assert!(kernel(&f.host).detail.contains("has no kernel preemption"));
        f.file("/proc/version", "Linux version 5.4.0 (u@h) #1 SMP PREEMPT Mon Jan 1\n");
        assert_eq!(kernel(&f.host).detail, "kernel 5.4.0 is PREEMPT (preemptible, not real-time)");
        f.file("/proc/version", "Linux version 4.19.0-rt (u@h) #1 SMP PREEMPT RT Mon Jan 1\n");
        assert_eq!(kernel(&f.host).status, Status::Pass);

        let f = Fake::new();
        assert_eq!(kernel(&f.host).detail, "could not check: cannot read /proc/version: no such file");
    }

    #[test]
    fn rtprio_and_memlock_pass_and_warn() {
        let cfg = DaemonConfig::default();
        let mut f = Fake::new();
        f.file("/proc/self/status", UNIT_CAPS);
        f.host.rtprio = Ok(Limit { soft: Some(0), hard: Some(0) });
        f.host.memlock = Ok(Limit { soft: Some(8 << 20), hard: Some(8 << 20) });
        assert_eq!(
            rtprio(&f.host, &cfg),
            Check::pass("rtprio", "CAP_SYS_NICE in effect: SCHED_FIFO up to 99 (configured up to 80)")
        );
        assert_eq!(memlock(&f.host, &cfg), Check::pass("memlock", "CAP_IPC_LOCK in effect: mlockall allowed"));

        // A login user: no capabilities, the distribution's limits.
        f.file("/proc/self/status", NO_CAPS);
        let c = rtprio(&f.host, &cfg);
        assert_eq!(c.status, Status::Warn);
        assert!(
            c.detail.starts_with("this process may not use SCHED_FIFO 80 (RLIMIT_RTPRIO 0, no CAP_SYS_NICE)"),
            "{}",
            c.detail
        );
        assert!(c.fix.unwrap().contains("LimitRTPRIO=99"));
        let c = memlock(&f.host, &cfg);
        assert_eq!(c.status, Status::Warn);
        assert!(c.detail.starts_with("RLIMIT_MEMLOCK 8 MiB and no CAP_IPC_LOCK"), "{}", c.detail);
        assert_eq!(memlock_allowed(&f.host), Some(false));

        // limits.d grants instead of capabilities.
        f.host.rtprio = Ok(Limit { soft: Some(99), hard: Some(99) });
        f.host.memlock = Ok(Limit { soft: None, hard: None });
        assert_eq!(rtprio(&f.host, &cfg).detail, "RLIMIT_RTPRIO 99 ≥ 80: SCHED_FIFO allowed");
        assert_eq!(memlock(&f.host, &cfg).detail, "RLIMIT_MEMLOCK unlimited: mlockall allowed");
        assert_eq!(memlock_allowed(&f.host), Some(true));

        // Real-time turned off in the configuration.
        let mut off = cfg.clone();
        off.threads.realtime = false;
        assert_eq!(rtprio(&f.host, &off).status, Status::Warn);
        assert_eq!(memlock(&f.host, &off).status, Status::Warn);

        // Unreadable status file with a too-low limit: say so.
        let mut f = Fake::new();
        f.host.rtprio = Ok(Limit { soft: Some(0), hard: Some(0) });
        assert!(rtprio(&f.host, &cfg).detail.starts_with("could not check: cannot read /proc/self/status"));
    }

    #[test]
    fn throttling_pass_warn_and_fail() {
        let f = Fake::new();
        f.file("/proc/sys/kernel/sched_rt_period_us", "1000000\n")
            .file("/proc/sys/kernel/sched_rt_runtime_us", "950000\n");
        let mut cfg = DaemonConfig::default();
        assert_eq!(
            throttling(&f.host, &cfg),
            Check::pass(
                "rt_throttling",
                "RT throttling at 95 % (950000/1000000 µs); the RSI thread blocks between datagrams and stays far below it"
            )
        );
        cfg.threads.rsi_wait = RsiWait::BusyPoll;
        let c = throttling(&f.host, &cfg);
        assert_eq!(c.status, Status::Warn);
        assert!(c.detail.ends_with("can be stopped for 50000 µs (12 cycles) each period"), "{}", c.detail);
        f.file("/proc/sys/kernel/sched_rt_runtime_us", "-1\n");
        assert_eq!(throttling(&f.host, &cfg).status, Status::Pass);
        f.file("/proc/sys/kernel/sched_rt_runtime_us", "0\n");
        let c = throttling(&f.host, &cfg);
        assert_eq!(
            (c.status, c.detail.as_str()),
            (Status::Fail, "sched_rt_runtime_us = 0: SCHED_FIFO threads get no CPU time")
        );
        let f = Fake::new();
        assert_eq!(throttling(&f.host, &cfg).status, Status::Warn);
    }
}
