//! `topspin doctor`: is this PC ready for a 4 ms RSI loop? A list of
//! checks, each `pass`, `warn` or `fail` with a detail and a fix, read from
//! `/proc` and `/sys` (never as root, never changing anything) and one
//! measurement, the wake-up jitter of a thread on the RSI core.
//!
//! - `sysfs`: the root folder the files are read under (`/`, or a fake
//!   tree in the tests) and the kernel's list formats.
//! - `host`: that root plus the facts only a system call gives (limits,
//!   interfaces, clock synchronisation).
//! - `cpu`: the configured cores, their isolation, SMT siblings and
//!   frequency governor.
//! - `rt`: the kernel's preemption model, the rights to SCHED_FIFO and
//!   locked memory, RT throttling.
//! - `net`: the configured addresses and the NIC that holds `rsi_bind`
//!   (link, IRQ affinity).
//! - `system`: swap and time synchronisation.
//! - [`probe`]: the wake-up jitter probe on the RSI core.
//!
//! Each check is a plain function of a [`Host`] and the daemon's
//! configuration returning a [`Check`]; only [`probe`] touches the clock
//! and the scheduler. A failure is something that stops the loop from
//! meeting its 4 ms cycle (a core that does not exist, a busy-polling RSI
//! thread on a core another thread needs, an address no NIC holds, a link
//! that is down, RT threads that get no CPU time, a wake-up a whole cycle
//! late); a warning is something that costs margin or could not be
//! checked. Where a file cannot be read the check says `warn` and which
//! file, never panics.

pub(crate) mod cpu;
pub(crate) mod host;
pub(crate) mod net;
pub mod probe;
pub mod robot;
pub(crate) mod rt;
pub(crate) mod sysfs;
pub(crate) mod system;

use std::fmt::Write as _;

use serde::Serialize;

pub use host::{ClockSync, Host, Interface, Limit};
pub use sysfs::{SysRoot, Unreadable};

use crate::config::DaemonConfig;

/// The names of the checks, in the order they are reported.
pub const CHECKS: [&str; 13] = [
    "kernel",
    "cores",
    "isolation",
    "smt",
    "governor",
    "rtprio",
    "memlock",
    "rt_throttling",
    "addresses",
    "rsi_nic",
    "swap",
    "time_sync",
    "jitter_probe",
];

/// A check's verdict.
#[derive(Copy, Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Ready.
    Pass,
    /// Works, with less margin than it could have, or could not be checked.
    Warn,
    /// The 4 ms loop cannot be relied on until this is fixed.
    Fail,
}

impl Status {
    /// `PASS`, `WARN`, `FAIL`.
    pub fn label(self) -> &'static str {
        match self {
            Status::Pass => "PASS",
            Status::Warn => "WARN",
            Status::Fail => "FAIL",
        }
    }
}

/// One check's result.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Check {
    /// One of [`CHECKS`].
    pub name: &'static str,
    /// The check's verdict.
    pub status: Status,
    /// What was found, one line.
    pub detail: String,
    /// What to do about it (`None` when nothing needs doing).
    pub fix: Option<String>,
}

impl Check {
    /// A passed check.
    pub fn pass(name: &'static str, detail: impl Into<String>) -> Check {
        Check { name, status: Status::Pass, detail: detail.into(), fix: None }
    }

    /// A warning and its fix.
    pub fn warn(name: &'static str, detail: impl Into<String>, fix: impl Into<String>) -> Check {
        Check { name, status: Status::Warn, detail: detail.into(), fix: Some(fix.into()) }
    }

    /// A failure and its fix.
    pub fn fail(name: &'static str, detail: impl Into<String>, fix: impl Into<String>) -> Check {
        Check { name, status: Status::Fail, detail: detail.into(), fix: Some(fix.into()) }
    }

    /// A warning for a check that could not read what it needs.
    pub fn unknown(name: &'static str, why: impl std::fmt::Display) -> Check {
        Check::warn(
            name,
            format!("could not check: {why}"),
            "run `topspin doctor` on the robot PC itself, with /proc and /sys mounted (not in a restricted container)",
        )
    }
}

/// A check built up from several findings: the worst status wins, the
/// details and fixes are joined in the order they were found.
#[derive(Debug)]
pub(crate) struct Findings {
    name: &'static str,
    worst: Status,
    details: Vec<String>,
    fixes: Vec<String>,
}

impl Findings {
    pub(crate) fn new(name: &'static str) -> Findings {
        Findings { name, worst: Status::Pass, details: Vec::new(), fixes: Vec::new() }
    }

    /// Something found that needs nothing done.
    pub(crate) fn note(&mut self, detail: impl Into<String>) {
        self.details.push(detail.into());
    }

    fn add(&mut self, status: Status, detail: impl Into<String>, fix: impl Into<String>) {
        self.worst = self.worst.max(status);
        self.details.push(detail.into());
        let fix = fix.into();
        if !self.fixes.contains(&fix) {
            self.fixes.push(fix);
        }
    }

    pub(crate) fn warn(&mut self, detail: impl Into<String>, fix: impl Into<String>) {
        self.add(Status::Warn, detail, fix);
    }

    pub(crate) fn fail(&mut self, detail: impl Into<String>, fix: impl Into<String>) {
        self.add(Status::Fail, detail, fix);
    }

    pub(crate) fn finish(self) -> Check {
        Check {
            name: self.name,
            status: self.worst,
            detail: self.details.join("; "),
            fix: (!self.fixes.is_empty()).then(|| self.fixes.join("; ")),
        }
    }
}

/// How many checks ended in each status.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Summary {
    /// Checks that passed.
    pub pass: usize,
    /// Checks that warned.
    pub warn: usize,
    /// Checks that failed.
    pub fail: usize,
}

/// Every check, in [`CHECKS`] order, and the count per status (the JSON of
/// `topspin doctor --json`).
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Report {
    /// The checks' results, in [`CHECKS`] order.
    pub checks: Vec<Check>,
    /// The count per status.
    pub summary: Summary,
}

impl Report {
    /// The report of these checks.
    pub fn new(checks: Vec<Check>) -> Report {
        let mut summary = Summary::default();
        for c in &checks {
            match c.status {
                Status::Pass => summary.pass += 1,
                Status::Warn => summary.warn += 1,
                Status::Fail => summary.fail += 1,
            }
        }
        Report { checks, summary }
    }

    /// The process's exit code: 1 when a check failed, else 0.
    pub fn exit_code(&self) -> i32 {
        i32::from(self.summary.fail > 0)
    }

    /// One line per check, `STATUS  name  detail  fix: …`, then the counts.
    pub fn text(&self) -> String {
        let width = self.checks.iter().map(|c| c.name.len()).max().unwrap_or(0);
        let mut s = String::new();
        for c in &self.checks {
            let _ = write!(s, "{}  {:<width$}  {}", c.status.label(), c.name, c.detail);
            if let Some(f) = &c.fix {
                let _ = write!(s, "  fix: {f}");
            }
            s.push('\n');
        }
        let Summary { pass, warn, fail } = self.summary;
        let _ = writeln!(s, "{pass} pass, {warn} warn, {fail} fail");
        s
    }
}

/// Runs every check against `host` for the configuration `cfg`; the jitter
/// probe runs for `probe_seconds` on the RSI core, or not at all (`None`,
/// reported as a warning that it was skipped).
pub fn diagnose(host: &Host, cfg: &DaemonConfig, probe_seconds: Option<f64>) -> Report {
    Report::new(vec![
        rt::kernel(host),
        cpu::cores(host, cfg),
        cpu::isolation(host, cfg),
        cpu::smt(host, cfg),
        cpu::governor(host, cfg),
        rt::rtprio(host, cfg),
        rt::memlock(host, cfg),
        rt::throttling(host, cfg),
        net::addresses(host, cfg),
        net::rsi_nic(host, cfg),
        system::swap(host, cfg),
        system::time_sync(host),
        probe::check(host, cfg, probe_seconds),
    ])
}

#[cfg(test)]
pub(crate) mod fake {
    //! A fake `/proc` + `/sys` tree for the checks' tests.

    use std::net::IpAddr;

    use super::host::{ClockSync, Host, Interface, Limit};
    use super::sysfs::SysRoot;

    /// A temporary root and the host built on it (limits, interfaces and
    /// clock status set by the test).
    pub(crate) struct Fake {
        pub dir: tempfile::TempDir,
        pub host: Host,
    }

    impl Fake {
        /// An empty tree; unlimited limits, only loopback, clock synced.
        pub(crate) fn new() -> Fake {
            let dir = tempfile::tempdir().unwrap();
            let host = Host {
                root: SysRoot::new(dir.path()),
                rtprio: Ok(Limit { soft: None, hard: None }),
                memlock: Ok(Limit { soft: None, hard: None }),
                interfaces: Ok(vec![iface("lo", "127.0.0.1", 8)]),
                clock_sync: Ok(ClockSync { synced: true, est_error_us: 100 }),
                pid: 1000,
            };
            Fake { dir, host }
        }

        /// Writes `abs` (e.g. `/proc/cmdline`) under the root.
        pub(crate) fn file(&self, abs: &str, text: &str) -> &Self {
            let p = self.dir.path().join(abs.trim_start_matches('/'));
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, text).unwrap();
            self
        }

        /// A symbolic link `abs` → `target` (relative to the link's folder, as sysfs has them).
        pub(crate) fn link(&self, abs: &str, target: &str) -> &Self {
            let p = self.dir.path().join(abs.trim_start_matches('/'));
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::os::unix::fs::symlink(target, &p).unwrap();
            self
        }

        /// `cpuN` for N in `cpus` online, each its own SMT thread.
        pub(crate) fn cpus(&self, n: usize) -> &Self {
            self.file("/sys/devices/system/cpu/online", &format!("0-{}\n", n - 1));
            for c in 0..n {
                self.file(&format!("/sys/devices/system/cpu/cpu{c}/topology/thread_siblings_list"), &format!("{c}\n"));
            }
            self
        }
    }

    pub(crate) fn iface(name: &str, addr: &str, prefix_len: u8) -> Interface {
        Interface { name: name.to_owned(), addr: addr.parse::<IpAddr>().unwrap(), prefix_len }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_report_counts_and_prints_one_line_per_check() {
        let r = Report::new(vec![
            Check::pass("kernel", "PREEMPT_RT"),
            Check::warn("swap", "on", "swapoff -a"),
            Check::fail("cores", "core 7 is not online", "set threads.rsi_core"),
        ]);
        assert_eq!(r.summary, Summary { pass: 1, warn: 1, fail: 1 });
        assert_eq!(r.exit_code(), 1);
        assert_eq!(
            r.text(),
            "PASS  kernel  PREEMPT_RT\nWARN  swap    on  fix: swapoff -a\n\
             FAIL  cores   core 7 is not online  fix: set threads.rsi_core\n1 pass, 1 warn, 1 fail\n"
        );
        let json = serde_json::to_value(&r).unwrap();
        assert_eq!(
            json["checks"][0],
            serde_json::json!({"name": "kernel", "status": "pass", "detail": "PREEMPT_RT", "fix": null})
        );
        assert_eq!(json["summary"], serde_json::json!({"pass": 1, "warn": 1, "fail": 1}));
        assert_eq!(Report::new(vec![Check::warn("swap", "on", "x")]).exit_code(), 0);
    }

    #[test]
    fn every_check_reports_once_in_order_even_on_an_empty_tree() {
        // Nothing readable: every check still answers (warn, why), none panics.
        let f = fake::Fake::new();
        let r = diagnose(&f.host, &DaemonConfig::default(), None);
        let names: Vec<&str> = r.checks.iter().map(|c| c.name).collect();
        assert_eq!(names, CHECKS);
        assert_eq!(r.checks.iter().find(|c| c.name == "jitter_probe").unwrap().status, Status::Warn);
    }
}
