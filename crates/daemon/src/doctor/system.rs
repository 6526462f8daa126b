//! The rest of the PC: swap (`/proc/swaps`), which can page the daemon out
//! unless it locks its memory, and time synchronisation (systemd-timesyncd's
//! `/run/systemd/timesync/synchronized`, the kernel's `adjtimex` status,
//! and whether chronyd, ntpd, systemd-timesyncd or ptp4l runs, from
//! `/proc/N/comm`), which the recordings' and logs' wall times depend on.
//! Neither can stop the loop, so neither fails.

use super::rt::memlock_allowed;
use super::sysfs::pids;
use super::{Check, Host};
use crate::config::DaemonConfig;

/// `swap`: no swap, or swap that cannot reach the daemon's locked memory
/// (pass); swap and no right to lock memory (warn).
pub(crate) fn swap(host: &Host, cfg: &DaemonConfig) -> Check {
    const NAME: &str = "swap";
    let table = match host.root.read("/proc/swaps") {
        Ok(t) => t,
        Err(e) => return Check::unknown(NAME, e),
    };
    // Filename Type Size Used Priority (sizes in KiB), after a header line.
    let areas: Vec<String> = table
        .lines()
        .skip(1)
        .filter_map(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            let mib = w.get(2)?.parse::<u64>().ok()? >> 10;
            Some(format!("{} {mib} MiB", w[0]))
        })
        .collect();
    if areas.is_empty() {
        return Check::pass(NAME, "no swap");
    }
    let areas = areas.join(", ");
    if cfg.threads.realtime && memlock_allowed(host) == Some(true) {
        Check::pass(
            NAME,
            format!("swap on ({areas}), but memory locking is allowed: the daemon's mlockall keeps it in RAM"),
        )
    } else {
        Check::warn(
            NAME,
            format!(
                "swap on ({areas}) and the daemon's memory is not locked: its pages can be swapped out and fault back in mid-cycle"
            ),
            "let the daemon lock its memory (threads.realtime = true, CAP_IPC_LOCK and LimitMEMLOCK=infinity as in deploy/topspin.service), or `sudo swapoff -a` and drop swap from /etc/fstab",
        )
    }
}

/// The names (`comm`) of the time-sync daemons that run.
const TIME_DAEMONS: [&str; 6] = ["chronyd", "ntpd", "systemd-timesyn", "ptp4l", "phc2sys", "openntpd"];

fn time_daemons(host: &Host) -> Vec<&'static str> {
    let mut found: Vec<&'static str> = pids(&host.root)
        .into_iter()
        .filter_map(|pid| host.root.read_trim(&format!("/proc/{pid}/comm")).ok())
        .filter_map(|comm| TIME_DAEMONS.iter().find(|d| **d == comm).copied())
        .collect();
    found.sort_unstable();
    found.dedup();
    found
}

/// `time_sync`: the kernel clock is disciplined by a time daemon (pass),
/// or not (yet) (warn).
pub(crate) fn time_sync(host: &Host) -> Check {
    const NAME: &str = "time_sync";
    let daemons = time_daemons(host);
    let running = if daemons.is_empty() { String::new() } else { format!(" ({} running)", daemons.join(", ")) };
    if host.root.exists("/run/systemd/timesync/synchronized") {
        return Check::pass(NAME, format!("systemd-timesyncd: synchronised{running}"));
    }
    match (&host.clock_sync, daemons.is_empty()) {
        (Ok(s), _) if s.synced => {
            Check::pass(NAME, format!("kernel clock synchronised (estimated error {} µs){running}", s.est_error_us))
        }
        (_, false) => Check::warn(
            NAME,
            format!("{} runs but the kernel clock is not synchronised yet", daemons.join(", ")),
            "give it time (`chronyc tracking`, `timedatectl timesync-status`), and check that its servers are reachable",
        ),
        (status, true) => Check::warn(
            NAME,
            format!(
                "no time synchronisation: {} and no chronyd, ntpd, systemd-timesyncd or ptp4l runs",
                match status {
                    Ok(_) => "the kernel clock is unsynchronised".to_owned(),
                    Err(e) => format!("adjtimex: {e}"),
                }
            ),
            "install chrony (or enable systemd-timesyncd) against the lab's time server: the recordings' and logs' wall times depend on it (the tracker's clock mapping does not)",
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::super::Status;
    use super::super::fake::Fake;
    use super::super::host::{ClockSync, Limit};
    use super::*;

    const HEADER: &str = "Filename\t\t\t\tType\t\tSize\t\tUsed\t\tPriority\n";

    #[test]
    fn swap_pass_and_warn() {
        let mut f = Fake::new();
        f.file("/proc/swaps", HEADER).file("/proc/self/status", "CapEff:\t0000000000000000\n");
        f.host.memlock = Ok(Limit { soft: Some(65536), hard: Some(65536) });
        let cfg = DaemonConfig::default();
        assert_eq!(swap(&f.host, &cfg), Check::pass("swap", "no swap"));
        f.file("/proc/swaps", &format!("{HEADER}/swap.img\t\t\t\tfile\t\t2097148\t\t0\t\t-2\n"));
        let c = swap(&f.host, &cfg);
        assert_eq!(c.status, Status::Warn);
        assert!(
            c.detail.starts_with("swap on (/swap.img 2047 MiB) and the daemon's memory is not locked"),
            "{}",
            c.detail
        );
        f.file("/proc/self/status", "CapEff:\t0000000000004000\n");
        let c = swap(&f.host, &cfg);
        assert_eq!(c.status, Status::Pass);
        assert!(c.detail.contains("memory locking is allowed"));
        let mut off = cfg.clone();
        off.threads.realtime = false;
        assert_eq!(swap(&f.host, &off).status, Status::Warn);
        let f = Fake::new();
        assert_eq!(swap(&f.host, &cfg).detail, "could not check: cannot read /proc/swaps: no such file");
    }

    #[test]
    fn time_sync_pass_and_warn() {
        let mut f = Fake::new();
        f.file("/proc/1/comm", "systemd\n").file("/proc/812/comm", "chronyd\n");
        let c = time_sync(&f.host);
        assert_eq!(c, Check::pass("time_sync", "kernel clock synchronised (estimated error 100 µs) (chronyd running)"));

        f.host.clock_sync = Ok(ClockSync { synced: false, est_error_us: 16_000_000 });
        let c = time_sync(&f.host);
        assert_eq!(
            (c.status, c.detail.as_str()),
            (Status::Warn, "chronyd runs but the kernel clock is not synchronised yet")
        );

        f.file("/run/systemd/timesync/synchronized", "");
        assert_eq!(time_sync(&f.host).status, Status::Pass);

        let mut f = Fake::new();
        f.host.clock_sync = Ok(ClockSync { synced: false, est_error_us: 16_000_000 });
        let c = time_sync(&f.host);
        assert_eq!(c.status, Status::Warn);
        assert_eq!(
            c.detail,
            "no time synchronisation: the kernel clock is unsynchronised and no chronyd, ntpd, systemd-timesyncd or ptp4l runs"
        );
        f.host.clock_sync = Err("Operation not permitted".into());
        assert!(time_sync(&f.host).detail.contains("adjtimex: Operation not permitted"));
    }
}
