//! The cores of `[threads]`: do they exist, may this process run on them,
//! is the RSI core isolated from other work (`isolcpus=`, `nohz_full=`, a
//! cpuset partition), does it share a physical core with a busy SMT
//! sibling, and does its frequency governor keep it at speed.
//!
//! Reads `/sys/devices/system/cpu/{online,isolated,nohz_full}`,
//! `cpuN/topology/thread_siblings_list`, `cpuN/cpufreq/scaling_{governor,driver}`,
//! `/sys/fs/cgroup/cpuset.cpus.isolated`, `/proc/cmdline` and
//! `Cpus_allowed_list` of `/proc/self/status`.

use std::collections::BTreeMap;

use super::sysfs::{CpuSet, cmdline_param, format_cpu_list, isolcpus_cpus, parse_cpu_list, status_field};
use super::{Check, Findings, Host};
use crate::config::{DaemonConfig, RsiWait};

/// One thread the configuration pins (or leaves free).
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Pinned {
    /// The configuration key (`threads.rsi_core`).
    pub key: &'static str,
    /// The thread's name (`rsi`).
    pub thread: &'static str,
    pub core: Option<usize>,
    /// A hot path (ingest, estimator, RSI) rather than a cold thread.
    pub hot: bool,
}

/// The daemon's threads and their configured cores (the logo thread only
/// when it is enabled).
pub(crate) fn pinned(cfg: &DaemonConfig) -> Vec<Pinned> {
    let t = &cfg.threads;
    let mut v = vec![
        Pinned { key: "threads.ingest_core", thread: "ingest", core: t.ingest_core.0, hot: true },
        Pinned { key: "threads.estimator_core", thread: "estimator", core: t.estimator_core.0, hot: true },
        Pinned { key: "threads.rsi_core", thread: "rsi", core: t.rsi_core.0, hot: true },
        Pinned { key: "threads.telemetry_core", thread: "telemetry", core: t.telemetry_core.0, hot: false },
    ];
    if cfg.logo.enabled {
        v.push(Pinned { key: "logo.core", thread: "logo", core: cfg.logo.core.0, hot: false });
    }
    v
}

fn online(host: &Host) -> Result<CpuSet, String> {
    let path = "/sys/devices/system/cpu/online";
    let text = host.root.read(path).map_err(|e| e.to_string())?;
    parse_cpu_list(&text).ok_or_else(|| format!("{path}: {:?} is not a CPU list", text.trim()))
}

/// The CPUs kept free of other work, and where that was read. `Err` when
/// no source could be read at all.
pub(crate) fn isolated(host: &Host) -> Result<(CpuSet, Vec<&'static str>), String> {
    let mut set = CpuSet::new();
    let mut sources = Vec::new();
    let mut readable = false;
    match host.root.read("/sys/devices/system/cpu/isolated") {
        Ok(t) => {
            readable = true;
            if let Some(s) = parse_cpu_list(&t).filter(|s| !s.is_empty()) {
                set.extend(s);
                sources.push("isolcpus");
            }
        }
        // Older kernels: the command line is the only record.
        Err(_) => {
            if let Ok(cmdline) = host.root.read("/proc/cmdline") {
                readable = true;
                if let Some(s) = cmdline_param(&cmdline, "isolcpus").and_then(isolcpus_cpus).filter(|s| !s.is_empty()) {
                    set.extend(s);
                    sources.push("isolcpus");
                }
            }
        }
    }
    // cgroup v2 isolated partitions (kernel 6.7+ lists them, with isolcpus, here).
    if let Ok(t) = host.root.read("/sys/fs/cgroup/cpuset.cpus.isolated") {
        readable = true;
        if let Some(s) = parse_cpu_list(&t).filter(|s| !s.is_subset(&set)) {
            set.extend(s);
            sources.push("cpuset partition");
        }
    }
    if readable {
        Ok((set, sources))
    } else {
        Err("cannot read /sys/devices/system/cpu/isolated or /proc/cmdline".to_owned())
    }
}

/// The CPUs without the periodic scheduler tick (`nohz_full=`).
fn nohz_full(host: &Host) -> CpuSet {
    host.root
        .read("/sys/devices/system/cpu/nohz_full")
        .ok()
        .and_then(|t| parse_cpu_list(&t))
        .or_else(|| {
            host.root.read("/proc/cmdline").ok().and_then(|c| cmdline_param(&c, "nohz_full").and_then(parse_cpu_list))
        })
        .unwrap_or_default()
}

/// `core 2` or `cores 1-3`.
fn cores_label(set: &CpuSet) -> String {
    if set.len() == 1 { format!("core {}", format_cpu_list(set)) } else { format!("cores {}", format_cpu_list(set)) }
}

fn on_core(pins: &[Pinned], core: usize, except: &str) -> Vec<&'static str> {
    pins.iter().filter(|p| p.core == Some(core) && p.thread != except).map(|p| p.thread).collect()
}

/// A warning when the RSI core is known not to be online (the `cores`
/// check fails on it; nothing more to say about it here).
fn offline(host: &Host, name: &'static str, rsi: usize) -> Option<Check> {
    let online = online(host).ok()?;
    (!online.contains(&rsi)).then(|| {
        Check::warn(name, format!("RSI core {rsi} is not online (see cores)"), "set threads.rsi_core to an online core")
    })
}

/// `cores`: every configured core is online (fail if not), this process may
/// run on them, the RSI thread is pinned, and what shares its core.
pub(crate) fn cores(host: &Host, cfg: &DaemonConfig) -> Check {
    const NAME: &str = "cores";
    let online = match online(host) {
        Ok(s) => s,
        Err(e) => return Check::unknown(NAME, e),
    };
    let pins = pinned(cfg);
    let mut f = Findings::new(NAME);
    let missing: Vec<String> = pins
        .iter()
        .filter_map(|p| p.core.filter(|c| !online.contains(c)).map(|c| format!("{} = {c}", p.key)))
        .collect();
    if !missing.is_empty() {
        f.fail(
            format!("{}: no such core online (online: {})", missing.join(", "), format_cpu_list(&online)),
            format!("set them to online cores ({}) in the configuration", format_cpu_list(&online)),
        );
    }
    let assigned: Vec<String> =
        pins.iter().map(|p| format!("{} {}", p.thread, p.core.map_or("none".to_owned(), |c| c.to_string()))).collect();
    f.note(format!("online {}; {}", format_cpu_list(&online), assigned.join(", ")));

    let t = &cfg.threads;
    match t.rsi_core.0 {
        None => f.warn(
            "the RSI thread is not pinned (threads.rsi_core = \"none\"): the scheduler may move it mid-cycle",
            "pin it: threads.rsi_core = N",
        ),
        Some(c) => {
            let sharing = on_core(&pins, c, "rsi");
            if !sharing.is_empty() {
                let who = sharing.join(" and ");
                if t.rsi_wait == RsiWait::BusyPoll {
                    f.fail(
                        format!("rsi_wait = busy_poll spins the RSI thread on core {c}, which the {who} thread shares: it gets no CPU time (SCHED_FIFO) or half of it"),
                        format!("move the {who} thread off core {c}, or set threads.rsi_wait = \"blocking\""),
                    );
                } else if t.realtime {
                    f.note(format!(
                        "the RSI thread shares core {c} with {who} (SCHED_FIFO {} preempts them)",
                        t.rsi_priority
                    ));
                } else {
                    f.warn(
                        format!("the RSI thread shares core {c} with {who} without SCHED_FIFO (threads.realtime = false): it waits its turn"),
                        "set threads.realtime = true, or give threads.rsi_core a core of its own",
                    );
                }
            }
        }
    }

    // A core outside this process's affinity cannot be pinned to from here
    // (rt::pin_current only picks cores of the inherited set); isolcpus
    // cores are outside a login shell's set.
    if let Some(allowed) = host
        .root
        .read("/proc/self/status")
        .ok()
        .and_then(|s| status_field(&s, "Cpus_allowed_list").and_then(parse_cpu_list))
    {
        let outside: CpuSet =
            pins.iter().filter_map(|p| p.core).filter(|c| online.contains(c) && !allowed.contains(c)).collect();
        if !outside.is_empty() {
            f.warn(
                format!(
                    "{} {} outside this process's CPU affinity ({}): `topspin run` started like this one could not pin to them",
                    cores_label(&outside),
                    if outside.len() == 1 { "is" } else { "are" },
                    format_cpu_list(&allowed)
                ),
                format!(
                    "list them in CPUAffinity= of the service (deploy/topspin.service), or start with `taskset -c {}`",
                    format_cpu_list(&allowed.union(&outside).copied().collect())
                ),
            );
        }
    }
    f.finish()
}

/// `isolation`: the RSI core is kept free of other work (pass) or not (warn).
pub(crate) fn isolation(host: &Host, cfg: &DaemonConfig) -> Check {
    const NAME: &str = "isolation";
    let Some(rsi) = cfg.threads.rsi_core.0 else {
        return Check::warn(
            NAME,
            "the RSI thread is not pinned (threads.rsi_core = \"none\"): no core to isolate",
            "pin it: threads.rsi_core = N",
        );
    };
    if let Some(c) = offline(host, NAME, rsi) {
        return c;
    }
    let (isolated, sources) = match isolated(host) {
        Ok(x) => x,
        Err(e) => return Check::unknown(NAME, e),
    };
    let nohz = nohz_full(host);
    let hot: CpuSet = pinned(cfg).iter().filter(|p| p.hot).filter_map(|p| p.core).collect();
    let mut f = Findings::new(NAME);
    if isolated.contains(&rsi) {
        f.note(format!("RSI core {rsi} isolated ({})", sources.join(", ")));
        if nohz.contains(&rsi) {
            f.note(format!("nohz_full on {rsi}"));
        } else {
            f.note(format!("no nohz_full on {rsi} (the scheduler tick still interrupts it)"));
        }
        let others: CpuSet = hot.iter().copied().filter(|c| !isolated.contains(c)).collect();
        if !others.is_empty() {
            f.note(format!("other hot cores not isolated: {}", format_cpu_list(&others)));
        }
    } else if rsi == 0 {
        f.warn(
            "the RSI thread is on core 0, which keeps the kernel's housekeeping (timers, RCU, unbound work) and cannot be isolated",
            "pin the RSI thread to another core (threads.rsi_core) and isolate that one",
        );
    } else {
        f.warn(
            format!(
                "RSI core {rsi} is not isolated (isolated: {}): any task may run there and delay the RSI thread",
                format_cpu_list(&isolated)
            ),
            format!(
                "boot with isolcpus={rsi} nohz_full={rsi} rcu_nocbs={rsi} (GRUB_CMDLINE_LINUX, then update-grub) and keep core {rsi} in the service's CPUAffinity="
            ),
        );
    }
    f.finish()
}

/// `smt`: the RSI core's hyper-threading siblings run nothing that could
/// slow it (pass), or they do / could (warn).
pub(crate) fn smt(host: &Host, cfg: &DaemonConfig) -> Check {
    const NAME: &str = "smt";
    let Some(rsi) = cfg.threads.rsi_core.0 else {
        return Check::warn(
            NAME,
            "the RSI thread is not pinned (threads.rsi_core = \"none\")",
            "pin it: threads.rsi_core = N",
        );
    };
    if let Some(c) = offline(host, NAME, rsi) {
        return c;
    }
    let path = format!("/sys/devices/system/cpu/cpu{rsi}/topology/thread_siblings_list");
    let siblings = match host.root.read(&path) {
        Ok(t) => match parse_cpu_list(&t) {
            Some(s) => s,
            None => return Check::unknown(NAME, format!("{path}: {:?} is not a CPU list", t.trim())),
        },
        Err(e) => return Check::unknown(NAME, e),
    };
    let others: CpuSet = siblings.iter().copied().filter(|c| *c != rsi).collect();
    if others.is_empty() {
        let control = host.root.read_trim("/sys/devices/system/cpu/smt/control").unwrap_or_default();
        let why = match control.as_str() {
            "off" | "forceoff" => " (SMT off)",
            "notsupported" | "notimplemented" => " (no SMT on this CPU)",
            _ => "",
        };
        return Check::pass(NAME, format!("RSI core {rsi} has no SMT sibling{why}"));
    }
    let isolated = isolated(host).map(|(s, _)| s).unwrap_or_default();
    let pins = pinned(cfg);
    let mut f = Findings::new(NAME);
    let fix = format!(
        "keep topspin's other threads off {list}, isolate it too (isolcpus={all}), or turn SMT off (`nosmt` on the kernel command line)",
        list = format_cpu_list(&others),
        all = format_cpu_list(&siblings)
    );
    for s in &others {
        let threads = on_core(&pins, *s, "rsi");
        if !threads.is_empty() {
            f.warn(
                format!(
                    "RSI core {rsi}'s SMT sibling {s} runs the {} thread: they share one physical core",
                    threads.join(" and ")
                ),
                fix.clone(),
            );
        } else if !isolated.contains(s) {
            f.warn(
                format!("RSI core {rsi}'s SMT sibling {s} is not isolated: any task there shares the RSI thread's physical core"),
                fix.clone(),
            );
        } else {
            f.note(format!("RSI core {rsi}'s SMT sibling {s} is isolated and runs no topspin thread"));
        }
    }
    f.finish()
}

/// `governor`: the hot cores run the `performance` frequency governor
/// (pass), another one or none visible (warn).
pub(crate) fn governor(host: &Host, cfg: &DaemonConfig) -> Check {
    const NAME: &str = "governor";
    let mut cores: CpuSet = pinned(cfg).iter().filter(|p| p.hot).filter_map(|p| p.core).collect();
    if cores.is_empty() {
        match online(host) {
            Ok(s) => cores = s,
            Err(e) => return Check::unknown(NAME, e),
        }
    }
    let mut by_governor: BTreeMap<String, CpuSet> = BTreeMap::new();
    let mut no_cpufreq = CpuSet::new();
    for c in &cores {
        let dir = format!("/sys/devices/system/cpu/cpu{c}/cpufreq");
        match host.root.read_trim(&format!("{dir}/scaling_governor")) {
            Ok(g) => {
                let driver = host.root.read_trim(&format!("{dir}/scaling_driver")).unwrap_or_else(|_| "?".to_owned());
                by_governor.entry(format!("{g} ({driver})")).or_default().insert(*c);
            }
            Err(_) => {
                no_cpufreq.insert(*c);
            }
        }
    }
    let mut f = Findings::new(NAME);
    for (g, set) in &by_governor {
        let cores = cores_label(set);
        if g.starts_with("performance ") {
            f.note(format!("{cores}: {g}"));
        } else {
            f.warn(
                format!("{cores}: {g}: the cores slow down between datagrams and take longer to wake and to answer"),
                format!(
                    "`sudo cpupower frequency-set -g performance` (or echo performance > /sys/devices/system/cpu/cpu{}/cpufreq/scaling_governor); keep it across boots (tuned latency-performance, or a unit)",
                    set.first().copied().unwrap_or(0)
                ),
            );
        }
    }
    if !no_cpufreq.is_empty() {
        f.warn(
            format!(
                "{}: no cpufreq: the frequency policy is not visible here (a virtual machine, or no scaling driver)",
                cores_label(&no_cpufreq)
            ),
            "on the robot PC: set the firmware's power profile to maximum performance, or load the scaling driver and choose the performance governor",
        );
    }
    f.finish()
}

#[cfg(test)]
mod tests {
    use super::super::Status;
    use super::super::fake::Fake;
    use super::*;
    use crate::config::Core;

    /// The RSI thread alone on core 2 of a 4-core PC.
    fn four_cores() -> DaemonConfig {
        let mut c = DaemonConfig::default();
        c.threads.ingest_core = Core(Some(1));
        c.threads.estimator_core = Core(Some(3));
        c.threads.rsi_core = Core(Some(2));
        c.threads.telemetry_core = Core(Some(0));
        c
    }

    #[test]
    fn cores_pass_warn_and_fail() {
        let f = Fake::new();
        f.cpus(4).file("/proc/self/status", "Name:\ttopspin\nCpus_allowed_list:\t0-3\n");
        let c = cores(&f.host, &four_cores());
        assert_eq!(c.status, Status::Pass, "{c:?}");
        assert_eq!(c.detail, "online 0-3; ingest 1, estimator 3, rsi 2, telemetry 0");
        assert_eq!(c.fix, None);

        // The defaults on 4 cores: RSI and estimator share core 1, SCHED_FIFO decides.
        let c = cores(&f.host, &DaemonConfig::default());
        assert_eq!(c.status, Status::Pass, "{c:?}");
        assert!(c.detail.contains("shares core 1 with estimator (SCHED_FIFO 80 preempts them)"), "{}", c.detail);

        let mut cfg = DaemonConfig::default();
        cfg.threads.realtime = false;
        assert_eq!(cores(&f.host, &cfg).status, Status::Warn);
        cfg.threads.realtime = true;
        cfg.threads.rsi_core = Core(None);
        let c = cores(&f.host, &cfg);
        assert_eq!(c.status, Status::Warn);
        assert_eq!(c.fix.as_deref(), Some("pin it: threads.rsi_core = N"));

        // Busy polling on a shared core starves the other thread.
        let mut cfg = DaemonConfig::default();
        cfg.threads.rsi_wait = RsiWait::BusyPoll;
        let c = cores(&f.host, &cfg);
        assert_eq!(c.status, Status::Fail, "{c:?}");
        assert!(c.detail.contains("which the estimator thread shares"), "{}", c.detail);

        // A core that does not exist.
        let mut cfg = four_cores();
        cfg.threads.rsi_core = Core(Some(7));
        let c = cores(&f.host, &cfg);
        assert_eq!(c.status, Status::Fail);
        assert!(c.detail.starts_with("threads.rsi_core = 7: no such core online (online: 0-3)"), "{}", c.detail);
    }

    #[test]
    fn cores_outside_this_process_affinity_warn() {
        let f = Fake::new();
        f.cpus(4).file("/proc/self/status", "Cpus_allowed_list:\t0-1\n");
        let c = cores(&f.host, &four_cores());
        assert_eq!(c.status, Status::Warn);
        assert!(c.detail.contains("cores 2-3 are outside this process's CPU affinity (0-1)"), "{}", c.detail);
        assert!(c.fix.unwrap().contains("taskset -c 0-3"));
    }

    #[test]
    fn cores_unreadable_warns_with_the_file() {
        let f = Fake::new();
        let c = cores(&f.host, &four_cores());
        assert_eq!(c.status, Status::Warn);
        assert_eq!(c.detail, "could not check: cannot read /sys/devices/system/cpu/online: no such file");
    }

    #[test]
    fn isolation_pass_and_warn() {
        let f = Fake::new();
        f.cpus(4).file("/sys/devices/system/cpu/isolated", "2-3\n").file("/sys/devices/system/cpu/nohz_full", "2-3\n");
        let c = isolation(&f.host, &four_cores());
        assert_eq!(c.status, Status::Pass, "{c:?}");
        assert_eq!(c.detail, "RSI core 2 isolated (isolcpus); nohz_full on 2; other hot cores not isolated: 1");

        // Isolated through a cpuset partition only, no nohz_full.
        let f = Fake::new();
        f.cpus(4)
            .file("/sys/devices/system/cpu/isolated", "\n")
            .file("/sys/devices/system/cpu/nohz_full", "(null)\n")
            .file("/sys/fs/cgroup/cpuset.cpus.isolated", "2\n");
        let c = isolation(&f.host, &four_cores());
        assert_eq!(c.status, Status::Pass);
        assert!(c.detail.starts_with("RSI core 2 isolated (cpuset partition); no nohz_full on 2"), "{}", c.detail);

        // Nothing isolated.
        let f = Fake::new();
        f.cpus(4).file("/sys/devices/system/cpu/isolated", "\n");
        let c = isolation(&f.host, &four_cores());
        assert_eq!(c.status, Status::Warn);
        assert_eq!(
            c.detail,
            "RSI core 2 is not isolated (isolated: none): any task may run there and delay the RSI thread"
        );
        assert!(c.fix.unwrap().starts_with("boot with isolcpus=2 nohz_full=2 rcu_nocbs=2"));

        // An old kernel without the sysfs file: the command line counts.
        let f = Fake::new();
        f.file("/proc/cmdline", "ro quiet isolcpus=domain,managed_irq,2 nohz_full=2\n");
        assert_eq!(isolation(&f.host, &four_cores()).status, Status::Pass);

        // The RSI thread on core 0 cannot be isolated.
        let mut cfg = four_cores();
        cfg.threads.rsi_core = Core(Some(0));
        let c = isolation(&f.host, &cfg);
        assert_eq!(c.status, Status::Warn);
        assert!(c.detail.contains("core 0"));

        // Nothing readable.
        let f = Fake::new();
        assert!(isolation(&f.host, &four_cores()).detail.starts_with("could not check"));

        // A core that is not there: the cores check fails it, this one says so.
        f.cpus(2);
        let c = isolation(&f.host, &four_cores());
        assert_eq!((c.status, c.detail.as_str()), (Status::Warn, "RSI core 2 is not online (see cores)"));
        assert_eq!(smt(&f.host, &four_cores()).detail, "RSI core 2 is not online (see cores)");
    }

    #[test]
    fn smt_pass_and_warn() {
        let f = Fake::new();
        f.cpus(4).file("/sys/devices/system/cpu/smt/control", "off\n");
        let c = smt(&f.host, &four_cores());
        assert_eq!((c.status, c.detail.as_str()), (Status::Pass, "RSI core 2 has no SMT sibling (SMT off)"));

        // Siblings 0/2 and 1/3 (typical numbering), sibling 0 runs the telemetry thread.
        let smt_pc = || {
            let f = Fake::new();
            f.cpus(4);
            for (c, s) in [(0, "0,2"), (1, "1,3"), (2, "0,2"), (3, "1,3")] {
                f.file(&format!("/sys/devices/system/cpu/cpu{c}/topology/thread_siblings_list"), s);
            }
            f
        };
        let f = smt_pc();
        let c = smt(&f.host, &four_cores());
        assert_eq!(c.status, Status::Warn);
        assert_eq!(c.detail, "RSI core 2's SMT sibling 0 runs the telemetry thread: they share one physical core");

        let mut cfg = four_cores();
        cfg.threads.telemetry_core = Core(Some(1));
        let c = smt(&f.host, &cfg);
        assert_eq!(c.status, Status::Warn);
        assert!(c.detail.contains("sibling 0 is not isolated"), "{}", c.detail);

        // Sibling 0 free of topspin's threads and isolated.
        f.file("/sys/devices/system/cpu/isolated", "0,2\n");
        let c = smt(&f.host, &cfg);
        assert_eq!(c.status, Status::Pass, "{c:?}");
        assert_eq!(c.detail, "RSI core 2's SMT sibling 0 is isolated and runs no topspin thread");

        let f = Fake::new();
        assert!(
            smt(&f.host, &cfg).detail.starts_with("could not check: cannot read /sys/devices/system/cpu/cpu2/topology")
        );
    }

    #[test]
    fn governor_pass_and_warn() {
        let f = Fake::new();
        f.cpus(4);
        for c in 1..4 {
            f.file(&format!("/sys/devices/system/cpu/cpu{c}/cpufreq/scaling_governor"), "performance\n");
            f.file(&format!("/sys/devices/system/cpu/cpu{c}/cpufreq/scaling_driver"), "intel_pstate\n");
        }
        let c = governor(&f.host, &four_cores());
        assert_eq!((c.status, c.detail.as_str()), (Status::Pass, "cores 1-3: performance (intel_pstate)"));

        f.file("/sys/devices/system/cpu/cpu2/cpufreq/scaling_governor", "powersave\n");
        let c = governor(&f.host, &four_cores());
        assert_eq!(c.status, Status::Warn);
        assert!(c.detail.starts_with(
            "cores 1,3: performance (intel_pstate); core 2: powersave (intel_pstate): the cores slow down"
        ));
        assert!(c.fix.unwrap().starts_with("`sudo cpupower frequency-set -g performance`"));

        // A virtual machine: no cpufreq at all.
        let f = Fake::new();
        f.cpus(2);
        let c = governor(&f.host, &DaemonConfig::default());
        assert_eq!(c.status, Status::Warn);
        assert!(c.detail.starts_with("cores 0-1: no cpufreq"), "{}", c.detail);
    }
}
