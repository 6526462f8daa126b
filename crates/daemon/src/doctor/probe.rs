//! The wake-up jitter probe: a thread set up as the daemon sets up its RSI
//! thread (pinned to `threads.rsi_core`, SCHED_FIFO at
//! `threads.rsi_priority` when `threads.realtime`, with a note where the OS
//! refuses) sleeps in the kernel to absolute 4 ms deadlines
//! ([`clock::sleep_until_in_kernel`], cyclictest's measure) and records how
//! late each wake-up is. A blocked RSI thread waits for the controller's
//! datagram the same way, so this lateness comes on top of every answer.
//!
//! The verdict ([`assess`]), against the 4 ms cycle and DESIGN §9's budget
//! (datagram in → answer out p99.9 < 100 µs, of which the wake-up is a
//! part):
//! - pass: p99.9 ≤ [`BUDGET_P999`] (100 µs) and max ≤ [`MARGIN_MAX`] (1 ms, a quarter cycle);
//! - warn: worse than that, every wake-up still within the cycle;
//! - fail: a wake-up late by a whole [`CYCLE`] (4 ms) or more: that cycle's
//!   answer would be late and the KR C4 counts it.
//!
//! The probe is skipped (warn) while a `topspin run` process is alive: on
//! the RSI core at the RSI priority it would compete with the daemon's own
//! RSI thread.

use hdrhistogram::Histogram;
use topspin_core::time::Duration;

use super::sysfs::pids;
use super::{Check, Host};
use crate::clock;
use crate::config::DaemonConfig;
use crate::runtime::rt::{self, RtRefused};

/// The RSI cycle (`#IPO_FAST`).
pub const CYCLE: Duration = Duration::from_millis(4);
/// Pass: p99.9 of the lateness at most this (DESIGN §9's p99.9 budget from
/// datagram in to answer out; the wake-up is inside it).
pub const BUDGET_P999: Duration = Duration::from_micros(100);
/// Pass: no wake-up later than this (a quarter cycle).
pub const MARGIN_MAX: Duration = Duration::from_millis(1);
/// `--probe-seconds` when not given.
pub const DEFAULT_SECONDS: f64 = 10.0;
/// The largest lateness the histogram keeps exactly (60 s); later ones count at this value.
const HISTOGRAM_MAX_NS: u64 = 60_000_000_000;

const NAME: &str = "jitter_probe";

/// What one probe run measured.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ProbeResult {
    /// The core the thread ran pinned to (`None`: not pinned).
    pub core: Option<usize>,
    /// The SCHED_FIFO priority it ran at (`None`: normal scheduling).
    pub fifo: Option<i32>,
    /// Deadlines in the run: each was woken for (`samples`) or passed
    /// while the thread was still late for an earlier one (`missed`).
    pub deadlines: u64,
    /// Deadlines the thread was woken for.
    pub samples: u64,
    /// Deadlines that passed while the thread was late for an earlier one.
    pub missed: u64,
    /// The median lateness of the wake-ups, ns.
    pub p50_ns: u64,
    /// The 99th percentile of the wake-ups' lateness, ns.
    pub p99_ns: u64,
    /// The 99.9th percentile of the wake-ups' lateness, ns.
    pub p999_ns: u64,
    /// The latest wake-up's lateness, ns.
    pub max_ns: u64,
    /// What the OS refused or the configuration left out, one line each.
    pub notes: Vec<String>,
}

fn refused(w: &rt::RtWarning) -> String {
    match w.what {
        RtRefused::Pin { core } => {
            format!("could not pin to core {core} (no such core, or a cpuset forbids it): not pinned")
        }
        RtRefused::Fifo { priority, errno } => {
            format!("SCHED_FIFO {priority} refused (errno {errno}): measured with normal scheduling")
        }
        RtRefused::Mlock { errno } => format!("mlockall refused (errno {errno})"),
    }
}

/// Runs the probe for `seconds` in a thread of its own, pinned to `core` and
/// at SCHED_FIFO `priority` where given and allowed.
pub fn measure(core: Option<usize>, priority: Option<i32>, seconds: f64) -> ProbeResult {
    let run = move || {
        let mut notes = Vec::new();
        let core = match core {
            Some(c) => match rt::pin_current_anywhere("probe", c) {
                Ok(()) => Some(c),
                Err(w) => {
                    notes.push(refused(&w));
                    None
                }
            },
            None => {
                notes.push("threads.rsi_core = \"none\": not pinned".to_owned());
                None
            }
        };
        let fifo = match priority {
            Some(p) => match rt::fifo_current("probe", p) {
                Ok(()) => Some(p),
                Err(w) => {
                    notes.push(refused(&w));
                    None
                }
            },
            None => {
                notes.push("threads.realtime = false: normal scheduling".to_owned());
                None
            }
        };
        let deadlines = (seconds.max(0.0) / CYCLE.as_secs_f64()).floor() as u64;
        let mut late = Histogram::<u64>::new_with_bounds(1, HISTOGRAM_MAX_NS, 3).expect("valid bounds");
        let mut missed = 0;
        let start = clock::now() + CYCLE;
        let mut k = 0;
        while k < deadlines {
            let lateness = clock::sleep_until_in_kernel(start + Duration(CYCLE.0 * k));
            late.saturating_record(lateness.0);
            // Deadlines that passed while this wake-up was late are missed, not slept for.
            let skip = (lateness.0 / CYCLE.0).min(deadlines - k - 1);
            missed += skip;
            k += 1 + skip;
        }
        ProbeResult {
            core,
            fifo,
            deadlines,
            samples: late.len(),
            missed,
            p50_ns: late.value_at_quantile(0.5),
            p99_ns: late.value_at_quantile(0.99),
            p999_ns: late.value_at_quantile(0.999),
            max_ns: late.max(),
            notes,
        }
    };
    // Its own thread: pinning and SCHED_FIFO must not stay on the caller.
    match std::thread::Builder::new().name("doctor-probe".to_owned()).spawn(run).map(|h| h.join()) {
        Ok(Ok(r)) => r,
        Ok(Err(_)) => ProbeResult::failed(core, "the probe thread panicked"),
        Err(e) => ProbeResult::failed(core, &format!("could not start the probe thread: {e}")),
    }
}

impl ProbeResult {
    fn failed(core: Option<usize>, why: &str) -> ProbeResult {
        ProbeResult {
            core,
            fifo: None,
            deadlines: 0,
            samples: 0,
            missed: 0,
            p50_ns: 0,
            p99_ns: 0,
            p999_ns: 0,
            max_ns: 0,
            notes: vec![why.to_owned()],
        }
    }
}

fn us(ns: u64) -> String {
    let us = ns as f64 / 1e3;
    if us < 10.0 { format!("{us:.1} µs") } else { format!("{us:.0} µs") }
}

/// The verdict on a probe run (see the module doc for the thresholds).
pub fn assess(r: &ProbeResult) -> Check {
    let mut setup = vec![
        r.core.map_or("unpinned".to_owned(), |c| format!("core {c}")),
        r.fifo.map_or("SCHED_OTHER".to_owned(), |p| format!("SCHED_FIFO {p}")),
    ];
    setup.extend(r.notes.iter().cloned());
    let setup = setup.join(", ");
    if r.samples == 0 {
        return Check::warn(
            NAME,
            format!("no wake-ups measured ({setup})"),
            "run the probe for longer (--probe-seconds 10)",
        );
    }
    let mut detail = format!(
        "{} wake-ups every 4 ms ({setup}): late by median {}, p99 {}, p99.9 {}, max {}",
        r.samples,
        us(r.p50_ns),
        us(r.p99_ns),
        us(r.p999_ns),
        us(r.max_ns)
    );
    if r.missed > 0 {
        let s = if r.missed == 1 { "" } else { "s" };
        detail.push_str(&format!("; {} cycle{s} passed unwoken", r.missed));
    }
    let mut fix = String::new();
    if r.fifo.is_none() {
        fix.push_str("probe with SCHED_FIFO (threads.realtime = true and the rights of the rtprio check); ");
    }
    fix.push_str("fix the kernel, isolation, governor and IRQ warnings above, then probe again");
    if r.max_ns >= CYCLE.0 {
        detail.push_str(" (a wake-up a whole 4 ms cycle late: that answer would be late)");
        Check::fail(NAME, detail, fix)
    } else if r.p999_ns > BUDGET_P999.0 || r.max_ns > MARGIN_MAX.0 {
        detail.push_str(" (pass needs p99.9 ≤ 100 µs and max ≤ 1 ms)");
        Check::warn(NAME, detail, fix)
    } else {
        Check::pass(NAME, detail)
    }
}

/// A `topspin run` process other than this one, by pid.
pub(crate) fn running_daemon(host: &Host) -> Option<u32> {
    pids(&host.root).into_iter().filter(|p| *p != host.pid).find(|pid| {
        let Ok(cmdline) = host.root.read(&format!("/proc/{pid}/cmdline")) else { return false };
        let mut args = cmdline.split('\0');
        let exe = args.next().unwrap_or("");
        exe.rsplit('/').next() == Some("topspin") && args.next() == Some("run")
    })
}

/// `jitter_probe`: runs the probe for `seconds` (`None`: skipped, warn) on
/// the configured RSI core at the RSI priority, unless a daemon runs.
pub fn check(host: &Host, cfg: &DaemonConfig, seconds: Option<f64>) -> Check {
    let Some(seconds) = seconds else {
        return Check::warn(NAME, "not run (--no-probe)", "run `topspin doctor` without --no-probe");
    };
    if let Some(pid) = running_daemon(host) {
        return Check::warn(
            NAME,
            format!("not run: a topspin daemon runs (pid {pid}); the probe would compete with its RSI thread"),
            "stop it (`sudo systemctl stop topspin`) and run `topspin doctor` again",
        );
    }
    let t = &cfg.threads;
    assess(&measure(t.rsi_core.0, t.realtime.then_some(i32::from(t.rsi_priority)), seconds))
}

#[cfg(test)]
mod tests {
    use super::super::Status;
    use super::super::fake::Fake;
    use super::*;

    fn result(p50_us: u64, p999_us: u64, max_us: u64) -> ProbeResult {
        ProbeResult {
            core: Some(1),
            fifo: Some(80),
            deadlines: 2500,
            samples: 2500,
            missed: 0,
            p50_ns: p50_us * 1000,
            p99_ns: p999_us * 500,
            p999_ns: p999_us * 1000,
            max_ns: max_us * 1000,
            notes: vec![],
        }
    }

    #[test]
    fn the_verdict_follows_the_cycle_and_the_budget() {
        let c = assess(&result(4, 40, 90));
        assert_eq!(c.status, Status::Pass, "{c:?}");
        assert_eq!(
            c.detail,
            "2500 wake-ups every 4 ms (core 1, SCHED_FIFO 80): late by median 4.0 µs, p99 20 µs, p99.9 40 µs, max 90 µs"
        );
        // Exactly on the thresholds still passes; just past them warns.
        assert_eq!(assess(&result(4, 100, 1000)).status, Status::Pass);
        assert_eq!(assess(&result(4, 101, 900)).status, Status::Warn);
        assert_eq!(assess(&result(4, 60, 1001)).status, Status::Warn);
        let mut r = result(95, 700, 4000);
        r.missed = 1;
        r.samples = 2499;
        r.fifo = None;
        r.notes = vec!["SCHED_FIFO 80 refused (errno 1): measured with normal scheduling".into()];
        let c = assess(&r);
        assert_eq!(c.status, Status::Fail);
        assert!(
            c.detail.starts_with("2499 wake-ups every 4 ms (core 1, SCHED_OTHER, SCHED_FIFO 80 refused (errno 1)"),
            "{}",
            c.detail
        );
        assert!(
            c.detail
                .ends_with("; 1 cycle passed unwoken (a wake-up a whole 4 ms cycle late: that answer would be late)")
        );
        assert!(c.fix.unwrap().starts_with("probe with SCHED_FIFO"));
        let mut none = result(0, 0, 0);
        none.samples = 0;
        assert_eq!(assess(&none).status, Status::Warn);
    }

    #[test]
    fn every_deadline_is_woken_for_or_counted_missed() {
        // 0.2 s = 50 deadlines, on this machine as it is (no timing asserted).
        let r = measure(Some(0), None, 0.2);
        assert_eq!(r.deadlines, 50);
        assert_eq!(r.samples + r.missed, 50, "{r:?}");
        assert_eq!(r.core, Some(0));
        assert!(r.p50_ns <= r.p99_ns && r.p99_ns <= r.p999_ns && r.p999_ns <= r.max_ns, "{r:?}");
        assert_eq!(r.notes, vec!["threads.realtime = false: normal scheduling".to_owned()]);
        // A core that does not exist: noted, measured unpinned.
        let r = measure(Some(crate::config::MAX_CORE), None, 0.02);
        assert_eq!((r.core, r.samples + r.missed), (None, 5));
        assert!(r.notes[0].starts_with("could not pin to core 1023"), "{r:?}");
    }

    #[test]
    fn the_probe_stays_off_a_running_daemon_and_skips_on_request() {
        let f = Fake::new();
        f.file("/proc/1000/cmdline", "/usr/local/bin/topspin\0doctor\0")
            .file("/proc/4242/cmdline", "/usr/local/bin/topspin\0run\0--config\0/etc/topspin/topspin.toml\0")
            .file("/proc/77/cmdline", "/usr/bin/topspin-other\0run\0");
        assert_eq!(running_daemon(&f.host), Some(4242));
        let c = check(&f.host, &DaemonConfig::default(), Some(0.1));
        assert_eq!(c.status, Status::Warn);
        assert!(c.detail.starts_with("not run: a topspin daemon runs (pid 4242)"));
        assert_eq!(check(&f.host, &DaemonConfig::default(), None).detail, "not run (--no-probe)");
    }
}
