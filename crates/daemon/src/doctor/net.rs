//! The network side: every configured bind address is held by an
//! interface of this PC and every configured sender is on one of its
//! networks (`addresses`), and the NIC that holds `network.rsi_bind` is up
//! with its interrupts where the RSI thread wants them (`rsi_nic`).
//!
//! Addresses come from `getifaddrs` ([`Host::interfaces`]); the NIC's link
//! from `/sys/class/net/IF/{operstate,speed}`; its IRQs from
//! `/sys/class/net/IF/device/msi_irqs` (or the PCI parent's, as for
//! virtio), `device/irq`, or the lines of `/proc/interrupts` naming it;
//! their affinity from `/proc/irq/N/effective_affinity_list` (else
//! `smp_affinity_list`).

use std::collections::BTreeMap;
use std::net::IpAddr;

use super::host::Interface;
use super::sysfs::{CpuSet, format_cpu_list, parse_cpu_list};
use super::{Check, Findings, Host};
use crate::config::{DaemonConfig, RsiWait};

const RSI_BIND_FIX: &str =
    "set network.rsi_bind to the address of the NIC cabled to the KR C4 (the IP:PORT of rsi/topspin_ethernet.xml)";

/// `addresses`: each bind address is on an interface (fail if not: the
/// daemon cannot bind it), no bind is the wildcard and each sender is on a
/// directly connected network (warn if not).
pub(crate) fn addresses(host: &Host, cfg: &DaemonConfig) -> Check {
    const NAME: &str = "addresses";
    let ifs = match &host.interfaces {
        Ok(v) => v,
        Err(e) => return Check::unknown(NAME, format!("getifaddrs: {e}")),
    };
    let n = &cfg.network;
    let mut binds = vec![("network.tracker_bind", n.tracker_bind.ip()), ("network.rsi_bind", n.rsi_bind.ip())];
    let mut sources =
        vec![("network.tracker_source", n.tracker_source), ("network.controller_source", n.controller_source)];
    if cfg.logo.enabled {
        binds.push(("logo.crops_bind", cfg.logo.crops_bind.ip()));
        sources.push(("logo.crops_source", cfg.logo.crops_source));
    }
    if cfg.viewer.live {
        binds.push(("viewer.live_bind", cfg.viewer.live_bind.ip()));
    }
    let mut f = Findings::new(NAME);
    for (key, ip) in binds {
        if ip.is_unspecified() {
            f.warn(
                format!("{key} {ip} listens on every interface"),
                format!("bind {key} to the address of the one NIC it is for"),
            );
        } else if let Some(i) = ifs.iter().find(|i| i.addr == ip) {
            f.note(format!("{key} {ip} on {}", i.name));
        } else {
            f.fail(
                format!("{key} {ip} is on no interface: the daemon cannot bind it (EADDRNOTAVAIL)"),
                format!("give the NIC that address (`ip addr add {ip}/24 dev IF`, or netplan / NetworkManager) or correct {key}"),
            );
        }
    }
    let rsi_if = ifs.iter().find(|i| i.addr == n.rsi_bind.ip()).map(|i| i.name.as_str());
    for (key, ip) in sources {
        let via: Vec<&Interface> = ifs.iter().filter(|i| i.covers(ip)).collect();
        match via.first() {
            None => f.warn(
                format!(
                    "{key} {ip} is on none of this PC's networks: its datagrams would have to come through a router"
                ),
                format!("connect that sender to a NIC of this PC on its subnet, or correct {key}"),
            ),
            Some(first) => {
                if key == "network.controller_source"
                    && let Some(r) = rsi_if
                    && !via.iter().any(|i| i.name == r)
                {
                    f.warn(
                        format!("{key} {ip} is reached through {}, but network.rsi_bind is on {r}", first.name),
                        "put the KR C4 and network.rsi_bind on the same NIC and subnet",
                    );
                } else {
                    f.note(format!("{key} {ip} via {}", first.name));
                }
            }
        }
    }
    f.finish()
}

/// The IRQ numbers of interface `name` (empty when none are found: a
/// virtual interface).
pub(crate) fn nic_irqs(host: &Host, name: &str) -> Vec<u32> {
    let dev = format!("/sys/class/net/{name}/device");
    for dir in [format!("{dev}/msi_irqs"), format!("{dev}/../msi_irqs")] {
        if let Ok(list) = host.root.list(&dir) {
            let irqs: Vec<u32> = list.iter().filter_map(|n| n.parse().ok()).collect();
            if !irqs.is_empty() {
                return irqs;
            }
        }
    }
    if let Some(irq) =
        host.root.read_trim(&format!("{dev}/irq")).ok().and_then(|t| t.parse::<u32>().ok()).filter(|i| *i > 0)
    {
        return vec![irq];
    }
    // Last resort: /proc/interrupts lines whose action names the interface
    // (`eth0`, `eth0-TxRx-0`, `enp3s0-rx-1`).
    let Ok(table) = host.root.read("/proc/interrupts") else { return Vec::new() };
    table
        .lines()
        .filter(|l| {
            l.split_whitespace()
                .last()
                .is_some_and(|a| a == name || a.strip_prefix(name).is_some_and(|r| r.starts_with('-')))
        })
        .filter_map(|l| l.split(':').next()?.trim().parse().ok())
        .collect()
}

/// Where IRQ `irq` may run (the effective affinity where the kernel shows it).
fn irq_affinity(host: &Host, irq: u32) -> Option<CpuSet> {
    ["effective_affinity_list", "smp_affinity_list"]
        .iter()
        .find_map(|f| host.root.read(&format!("/proc/irq/{irq}/{f}")).ok().and_then(|t| parse_cpu_list(&t)))
        .filter(|s| !s.is_empty())
}

/// `rsi_nic`: the NIC holding `network.rsi_bind` is a real one (warn on
/// loopback or the wildcard), its link is up (fail if down), and its IRQs
/// go where the wait strategy wants them: to the RSI core when it blocks
/// (the receive wakes it without crossing cores, ≈ 30 µs each way, DESIGN
/// §10), away from it when it busy-polls (the spinning SCHED_FIFO thread
/// would hold the receive work off).
pub(crate) fn rsi_nic(host: &Host, cfg: &DaemonConfig) -> Check {
    const NAME: &str = "rsi_nic";
    let bind = cfg.network.rsi_bind;
    let ip: IpAddr = bind.ip();
    if ip.is_unspecified() {
        return Check::warn(
            NAME,
            format!("network.rsi_bind {bind} is every interface: no one NIC to check"),
            RSI_BIND_FIX,
        );
    }
    let ifs = match &host.interfaces {
        Ok(v) => v,
        Err(e) => return Check::unknown(NAME, format!("getifaddrs: {e}")),
    };
    let Some(nic) = ifs.iter().find(|i| i.addr == ip) else {
        return Check::warn(NAME, format!("no NIC holds network.rsi_bind {ip} (see addresses)"), RSI_BIND_FIX);
    };
    let name = nic.name.as_str();
    if ip.is_loopback() || name == "lo" {
        return Check::warn(
            NAME,
            format!("network.rsi_bind {bind} is on {name} (loopback): only a mock KR C4 on this PC can reach it"),
            RSI_BIND_FIX,
        );
    }
    let mut f = Findings::new(NAME);
    match host.root.read_trim(&format!("/sys/class/net/{name}/operstate")) {
        Ok(s) if s == "down" || s == "lowerlayerdown" || s == "notpresent" => f.fail(
            format!("{name} (holds {ip}) link is {s}: no cable, or the KR C4 is off"),
            format!("cable {name} to the KR C4's KLI port and check `ip link show {name}`"),
        ),
        Ok(s) => f.note(format!("{name} (holds {ip}) {s}")),
        Err(e) => f.note(format!("{name} (holds {ip}), link unknown ({e})")),
    }
    if let Some(speed) =
        host.root.read_trim(&format!("/sys/class/net/{name}/speed")).ok().and_then(|s| s.parse::<i64>().ok())
        && speed > 0
    {
        f.note(format!("{speed} Mb/s"));
    }
    let irqs = nic_irqs(host, name);
    if irqs.is_empty() {
        f.warn(
            format!("no IRQs found for {name} (a virtual interface, or a driver that does not name them)"),
            format!("find {name}'s queues in /proc/interrupts and set their /proc/irq/N/smp_affinity_list by hand"),
        );
        return f.finish();
    }
    let Some(rsi) = cfg.threads.rsi_core.0 else {
        f.warn(
            "the RSI thread is not pinned (threads.rsi_core = \"none\"): no core to steer the IRQs to",
            "pin it: threads.rsi_core = N",
        );
        return f.finish();
    };
    let mut by_affinity: BTreeMap<String, Vec<u32>> = BTreeMap::new();
    let mut unknown = Vec::new();
    let mut off_rsi = false;
    let mut on_rsi = false;
    for irq in &irqs {
        match irq_affinity(host, *irq) {
            Some(set) => {
                off_rsi |= set != CpuSet::from([rsi]);
                on_rsi |= set.contains(&rsi);
                by_affinity.entry(format_cpu_list(&set)).or_default().push(*irq);
            }
            None => unknown.push(*irq),
        }
    }
    let list = |v: &[u32]| v.iter().map(u32::to_string).collect::<Vec<_>>().join(",");
    let mut placed: Vec<String> =
        by_affinity.iter().map(|(cores, irqs)| format!("IRQ {} → core {cores}", list(irqs))).collect();
    if !unknown.is_empty() {
        placed.push(format!("IRQ {} → unreadable", list(&unknown)));
    }
    let placed = placed.join(", ");
    let pin = |cores: &str| {
        format!(
            "for each IRQ: `echo {cores} | sudo tee /proc/irq/N/smp_affinity_list` (N in {}), and keep irqbalance off them (IRQBALANCE_BANNED_CPULIST, or stop it)",
            list(&irqs)
        )
    };
    let other = if rsi == 0 { "1" } else { "0" };

    match cfg.threads.rsi_wait {
        RsiWait::Blocking if off_rsi || !unknown.is_empty() => f.warn(
            format!("{placed}: a datagram may wake the blocked RSI thread (core {rsi}) from another core (≈ 30 µs each way)"),
            pin(&rsi.to_string()),
        ),
        RsiWait::Blocking => f.note(format!("{placed} (the RSI core: the receive wakes it without crossing cores)")),
        RsiWait::BusyPoll if on_rsi || !unknown.is_empty() => f.warn(
            format!("{placed}: the receive work may run on core {rsi}, where the RSI thread spins at SCHED_FIFO, and wait behind it"),
            format!("{} (any core but {rsi})", pin(other)),
        ),
        RsiWait::BusyPoll => f.note(format!("{placed} (off the busy-polling RSI core {rsi})")),
    }
    f.finish()
}

#[cfg(test)]
mod tests {
    use super::super::Status;
    use super::super::fake::{Fake, iface};
    use super::*;
    use crate::config::Core;

    /// The robot cell's network: the KR C4 on eth1, the tracker on eth0.
    fn cell() -> DaemonConfig {
        let mut c = DaemonConfig::default();
        c.network.rsi_bind = "192.168.1.2:49152".parse().unwrap();
        c.network.controller_source = "192.168.1.147".parse().unwrap();
        c.network.tracker_bind = "10.0.0.5:41000".parse().unwrap();
        c.network.tracker_source = "10.0.0.7".parse().unwrap();
        c.threads.rsi_core = Core(Some(2));
        c
    }

    fn cell_pc() -> Fake {
        let mut f = Fake::new();
        f.host.interfaces =
            Ok(vec![iface("lo", "127.0.0.1", 8), iface("eth0", "10.0.0.5", 24), iface("eth1", "192.168.1.2", 24)]);
        // eth1 is a PCI NIC with two MSI-X vectors, both on core 2.
        f.link("/sys/class/net/eth1/device", "../../../devices/pci0000:00/0000:00:1c.0")
            .file("/sys/devices/pci0000:00/0000:00:1c.0/msi_irqs/41", "msix\n")
            .file("/sys/devices/pci0000:00/0000:00:1c.0/msi_irqs/42", "msix\n")
            .file("/sys/class/net/eth1/operstate", "up\n")
            .file("/sys/class/net/eth1/speed", "1000\n")
            .file("/proc/irq/41/smp_affinity_list", "2\n")
            .file("/proc/irq/42/smp_affinity_list", "0-3\n")
            .file("/proc/irq/42/effective_affinity_list", "2\n");
        f
    }

    #[test]
    fn addresses_pass_warn_and_fail() {
        let f = cell_pc();
        let c = addresses(&f.host, &cell());
        assert_eq!(c.status, Status::Pass, "{c:?}");
        assert_eq!(
            c.detail,
            "network.tracker_bind 10.0.0.5 on eth0; network.rsi_bind 192.168.1.2 on eth1; \
             network.tracker_source 10.0.0.7 via eth0; network.controller_source 192.168.1.147 via eth1"
        );
        // The defaults are all loopback, and loopback holds them.
        assert_eq!(addresses(&f.host, &DaemonConfig::default()).status, Status::Pass);

        let mut cfg = cell();
        cfg.network.controller_source = "10.0.0.9".parse().unwrap();
        let c = addresses(&f.host, &cfg);
        assert_eq!(c.status, Status::Warn);
        assert!(
            c.detail.contains(
                "network.controller_source 10.0.0.9 is reached through eth0, but network.rsi_bind is on eth1"
            )
        );
        cfg.network.controller_source = "172.16.0.1".parse().unwrap();
        assert!(addresses(&f.host, &cfg).detail.contains("172.16.0.1 is on none of this PC's networks"));
        cfg.network.tracker_bind = "0.0.0.0:41000".parse().unwrap();
        assert!(addresses(&f.host, &cfg).detail.contains("network.tracker_bind 0.0.0.0 listens on every interface"));

        let mut cfg = cell();
        cfg.network.rsi_bind = "192.168.7.2:49152".parse().unwrap();
        let c = addresses(&f.host, &cfg);
        assert_eq!(c.status, Status::Fail);
        assert!(
            c.detail.contains("network.rsi_bind 192.168.7.2 is on no interface: the daemon cannot bind it"),
            "{}",
            c.detail
        );

        let mut f = Fake::new();
        f.host.interfaces = Err("Operation not permitted".into());
        assert_eq!(addresses(&f.host, &cell()).detail, "could not check: getifaddrs: Operation not permitted");
    }

    #[test]
    fn rsi_nic_pass_warn_and_fail() {
        let f = cell_pc();
        let c = rsi_nic(&f.host, &cell());
        assert_eq!(c.status, Status::Pass, "{c:?}");
        assert_eq!(
            c.detail,
            "eth1 (holds 192.168.1.2) up; 1000 Mb/s; IRQ 41,42 → core 2 (the RSI core: the receive wakes it without crossing cores)"
        );

        // irqbalance spread one vector elsewhere.
        f.file("/proc/irq/42/effective_affinity_list", "0\n");
        let c = rsi_nic(&f.host, &cell());
        assert_eq!(c.status, Status::Warn);
        assert!(c.detail.ends_with("IRQ 42 → core 0, IRQ 41 → core 2: a datagram may wake the blocked RSI thread (core 2) from another core (≈ 30 µs each way)"), "{}", c.detail);
        assert!(
            c.fix.unwrap().starts_with("for each IRQ: `echo 2 | sudo tee /proc/irq/N/smp_affinity_list` (N in 41,42)")
        );

        // Busy polling wants them elsewhere: IRQ 41 on the RSI core is wrong now.
        let mut busy = cell();
        busy.threads.rsi_wait = RsiWait::BusyPoll;
        let c = rsi_nic(&f.host, &busy);
        assert_eq!(c.status, Status::Warn);
        assert!(c.detail.contains("may run on core 2, where the RSI thread spins"), "{}", c.detail);
        f.file("/proc/irq/41/smp_affinity_list", "1\n");
        assert_eq!(rsi_nic(&f.host, &busy).status, Status::Pass);

        // The link is down.
        f.file("/sys/class/net/eth1/operstate", "down\n");
        let c = rsi_nic(&f.host, &cell());
        assert_eq!(c.status, Status::Fail);
        assert!(c.detail.starts_with("eth1 (holds 192.168.1.2) link is down"), "{}", c.detail);

        // Loopback (the defaults), and an address no NIC holds.
        let c = rsi_nic(&f.host, &DaemonConfig::default());
        assert_eq!(c.status, Status::Warn);
        assert_eq!(
            c.detail,
            "network.rsi_bind 127.0.0.1:49152 is on lo (loopback): only a mock KR C4 on this PC can reach it"
        );
        let mut cfg = cell();
        cfg.network.rsi_bind = "192.168.7.2:49152".parse().unwrap();
        assert_eq!(rsi_nic(&f.host, &cfg).status, Status::Warn);
    }

    #[test]
    fn nic_irqs_from_a_virtio_parent_or_proc_interrupts() {
        let mut f = Fake::new();
        f.host.interfaces = Ok(vec![iface("eth0", "10.0.0.5", 24)]);
        // virtio: the net device's parent PCI function holds the vectors.
        f.link("/sys/class/net/eth0/device", "../../../devices/pci0000:00/0000:00:03.0/virtio2")
            .file("/sys/devices/pci0000:00/0000:00:03.0/virtio2/vendor", "0x1af4\n")
            .file("/sys/devices/pci0000:00/0000:00:03.0/msi_irqs/38", "msix\n")
            .file("/sys/devices/pci0000:00/0000:00:03.0/msi_irqs/39", "msix\n");
        assert_eq!(nic_irqs(&f.host, "eth0"), vec![38, 39]);
        // No device folder: the names in /proc/interrupts.
        f.file(
            "/proc/interrupts",
            "           CPU0       CPU1\n 130:   5   0  IR-PCI-MSI 524288-edge  enp3s0-rx-0\n \
             131:  0  7  IR-PCI-MSI 524289-edge  enp3s0-tx-0\n 132: 0 0 IR-PCI-MSI 1-edge enp3s01\nLOC: 1 2 Local timer interrupts\n",
        );
        assert_eq!(nic_irqs(&f.host, "enp3s0"), vec![130, 131]);
        assert_eq!(nic_irqs(&f.host, "wlan0"), Vec::<u32>::new());
    }
}
