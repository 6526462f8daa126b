//! Real-time set-up of the daemon's threads (DESIGN §4, §10): pin a thread
//! to a core, give it SCHED_FIFO at a priority, lock the process's memory.
//! Where the OS refuses (no CAP_SYS_NICE / CAP_IPC_LOCK, not root), the
//! refusal is returned as a warning naming what was refused and how to
//! allow it; the daemon logs it once and carries on.

use std::fmt;

/// One refused real-time request.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RtWarning {
    /// The thread's name (`ingest`, `rsi`, …), or `process` for the memory lock.
    pub thread: &'static str,
    /// What was refused.
    pub what: RtRefused,
}

/// What the OS refused.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RtRefused {
    /// Pinning to the core failed (no such core, or not permitted).
    Pin {
        /// The core asked for.
        core: usize,
    },
    /// `pthread_setschedparam(SCHED_FIFO)` failed with this errno.
    Fifo {
        /// The priority asked for.
        priority: i32,
        /// The OS's error number.
        errno: i32,
    },
    /// `mlockall` failed with this errno.
    Mlock {
        /// The OS's error number.
        errno: i32,
    },
}

impl fmt::Display for RtWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.what {
            RtRefused::Pin { core } => write!(
                f,
                "{}: could not pin to core {core} (does it exist? is the service's CPUAffinity narrower?)",
                self.thread
            ),
            RtRefused::Fifo { priority, errno } => write!(
                f,
                "{}: SCHED_FIFO priority {priority} refused (errno {errno}): grant CAP_SYS_NICE and LimitRTPRIO \
                 (deploy/topspin.service) or run with threads.realtime = false; running with normal scheduling",
                self.thread
            ),
            RtRefused::Mlock { errno } => write!(
                f,
                "{}: mlockall refused (errno {errno}): grant CAP_IPC_LOCK and LimitMEMLOCK=infinity; memory may page",
                self.thread
            ),
        }
    }
}

/// Pins the calling thread to `core`.
pub fn pin_current(thread: &'static str, core: usize) -> Result<(), RtWarning> {
    let ok = core_affinity::get_core_ids()
        .and_then(|ids| ids.into_iter().find(|c| c.id == core))
        .is_some_and(core_affinity::set_for_current);
    if ok { Ok(()) } else { Err(RtWarning { thread, what: RtRefused::Pin { core } }) }
}

/// Pins the calling thread to `core` even where its inherited affinity
/// leaves that core out (an `isolcpus` core is outside a login shell's
/// set): `topspin doctor`'s probe measures the core the service will be
/// given, wherever doctor itself was started.
pub(crate) fn pin_current_anywhere(thread: &'static str, core: usize) -> Result<(), RtWarning> {
    let ok = core <= crate::config::MAX_CORE && core_affinity::set_for_current(core_affinity::CoreId { id: core });
    if ok { Ok(()) } else { Err(RtWarning { thread, what: RtRefused::Pin { core } }) }
}

fn errno() -> i32 {
    std::io::Error::last_os_error().raw_os_error().unwrap_or(0)
}

/// Gives the calling thread SCHED_FIFO at `priority` (1–99).
#[allow(unsafe_code)]
pub fn fifo_current(thread: &'static str, priority: i32) -> Result<(), RtWarning> {
    let param = libc::sched_param { sched_priority: priority };
    // SAFETY: pthread_self() is the calling thread's valid handle and
    // `param` a valid sched_param that outlives the call.
    let rc = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
    if rc == 0 { Ok(()) } else { Err(RtWarning { thread, what: RtRefused::Fifo { priority, errno: rc } }) }
}

/// Locks all current and future pages of the process in memory.
#[allow(unsafe_code)]
pub(crate) fn lock_memory() -> Result<(), RtWarning> {
    // SAFETY: mlockall takes flags only and touches no Rust-managed memory.
    let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
    if rc == 0 { Ok(()) } else { Err(RtWarning { thread: "process", what: RtRefused::Mlock { errno: errno() } }) }
}

/// Pins and prioritises the calling thread as configured; returns what was
/// refused.
pub fn setup_current(thread: &'static str, core: Option<usize>, priority: Option<i32>) -> Vec<RtWarning> {
    let mut warnings = Vec::new();
    if let Some(c) = core
        && let Err(w) = pin_current(thread, c)
    {
        warnings.push(w);
    }
    if let Some(p) = priority
        && let Err(w) = fifo_current(thread, p)
    {
        warnings.push(w);
    }
    warnings
}

/// The CPUs this process may run on (its affinity mask, which `taskset`,
/// a cgroup's cpuset or the unit's `CPUAffinity=` narrow), ascending;
/// empty where the mask cannot be read.
pub fn allowed_cpus() -> Vec<usize> {
    let mut ids: Vec<usize> = core_affinity::get_core_ids().unwrap_or_default().into_iter().map(|c| c.id).collect();
    ids.sort_unstable();
    ids
}

/// Whether this process may use SCHED_FIFO: a throw-away thread asks for
/// priority 1. `Err(errno)` where refused (EPERM without CAP_SYS_NICE or
/// an `RLIMIT_RTPRIO`).
pub fn fifo_permitted() -> Result<(), i32> {
    std::thread::spawn(|| fifo_current("probe", 1)).join().map_err(|_| 0)?.map_err(|w| match w.what {
        RtRefused::Fifo { errno, .. } => errno,
        _ => 0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusals_are_warnings_not_failures() {
        // Whatever this machine permits, the calls return and say what was refused.
        let w = setup_current("test", Some(usize::MAX), None);
        assert_eq!(w, vec![RtWarning { thread: "test", what: RtRefused::Pin { core: usize::MAX } }]);
        assert!(w[0].to_string().contains("core"));
        let msg = RtWarning { thread: "rsi", what: RtRefused::Fifo { priority: 80, errno: 1 } }.to_string();
        assert!(msg.contains("CAP_SYS_NICE"), "{msg}");
    }
}
