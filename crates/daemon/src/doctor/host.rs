//! What `topspin doctor` knows about the PC: the files under a [`SysRoot`]
//! and the few facts only a system call gives (resource limits, the
//! network interfaces and their addresses, the kernel's clock
//! synchronisation status). [`Host::live`] asks this PC; the tests build a
//! [`Host`] by hand around a fake tree, so the checks never see the
//! difference.
//!
//! Nothing here needs root: `getrlimit`, `getifaddrs` and a read-only
//! `ntp_adjtime` (modes 0) are open to every user. A call that fails is kept
//! as its error text, for the check to report.

use std::ffi::CStr;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr};

use super::sysfs::SysRoot;

/// A resource limit; `None` is unlimited.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct Limit {
    /// The soft limit, the one in force.
    pub soft: Option<u64>,
    /// The hard limit, the ceiling for the soft one.
    pub hard: Option<u64>,
}

/// One address of one network interface.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Interface {
    /// The kernel's name (`eth0`, `enp3s0`, `lo`).
    pub name: String,
    /// The address.
    pub addr: IpAddr,
    /// The netmask's length in bits.
    pub prefix_len: u8,
}

impl Interface {
    /// Whether `ip` lies in this address's subnet.
    pub fn covers(&self, ip: IpAddr) -> bool {
        match (self.addr, ip) {
            (IpAddr::V4(a), IpAddr::V4(b)) => {
                let bits = u32::from(self.prefix_len.min(32));
                let mask = if bits == 0 { 0 } else { u32::MAX << (32 - bits) };
                u32::from(a) & mask == u32::from(b) & mask
            }
            (IpAddr::V6(a), IpAddr::V6(b)) => {
                let bits = u32::from(self.prefix_len.min(128));
                let mask = if bits == 0 { 0 } else { u128::MAX << (128 - bits) };
                u128::from(a) & mask == u128::from(b) & mask
            }
            _ => false,
        }
    }
}

/// The kernel clock's synchronisation status (`adjtimex`).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct ClockSync {
    /// Neither `TIME_ERROR` nor `STA_UNSYNC`: a time daemon disciplines the clock.
    pub synced: bool,
    /// The kernel's estimate of its error, µs.
    pub est_error_us: i64,
}

/// The PC as the checks see it.
#[derive(Clone, Debug)]
pub struct Host {
    /// `/proc`, `/sys`, `/run` under a root.
    pub root: SysRoot,
    /// `RLIMIT_RTPRIO` of this process.
    pub rtprio: Result<Limit, String>,
    /// `RLIMIT_MEMLOCK` of this process, bytes.
    pub memlock: Result<Limit, String>,
    /// Every IP address of every interface.
    pub interfaces: Result<Vec<Interface>, String>,
    /// The kernel clock's status.
    pub clock_sync: Result<ClockSync, String>,
    /// This process's id (to tell a running daemon from ourselves).
    pub pid: u32,
}

impl Host {
    /// This PC, as this process sees it.
    pub fn live() -> Host {
        Host {
            root: SysRoot::live(),
            rtprio: rlimit(libc::RLIMIT_RTPRIO),
            memlock: rlimit(libc::RLIMIT_MEMLOCK),
            interfaces: interfaces(),
            clock_sync: clock_sync(),
            pid: std::process::id(),
        }
    }
}

fn os_error() -> String {
    std::io::Error::last_os_error().to_string()
}

#[allow(unsafe_code)]
fn rlimit(resource: libc::__rlimit_resource_t) -> Result<Limit, String> {
    let mut r = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
    // SAFETY: `r` is a valid rlimit the call fills; `resource` is a libc constant.
    if unsafe { libc::getrlimit(resource, &mut r) } != 0 {
        return Err(os_error());
    }
    let value = |v: libc::rlim_t| (v != libc::RLIM_INFINITY).then_some(v);
    Ok(Limit { soft: value(r.rlim_cur), hard: value(r.rlim_max) })
}

/// The IP address in a `sockaddr`, if it is one.
///
/// # Safety
/// `sa` is null or points to a socket address whose storage matches its
/// `sa_family` (as `getifaddrs` returns them).
#[allow(unsafe_code)]
unsafe fn ip_of(sa: *const libc::sockaddr) -> Option<IpAddr> {
    if sa.is_null() {
        return None;
    }
    // SAFETY (all three): the caller's contract; the family says which struct it is.
    match i32::from(unsafe { (*sa).sa_family }) {
        libc::AF_INET => {
            let sin = unsafe { &*sa.cast::<libc::sockaddr_in>() };
            Some(IpAddr::V4(Ipv4Addr::from(u32::from_be(sin.sin_addr.s_addr))))
        }
        libc::AF_INET6 => {
            let sin6 = unsafe { &*sa.cast::<libc::sockaddr_in6>() };
            Some(IpAddr::V6(Ipv6Addr::from(sin6.sin6_addr.s6_addr)))
        }
        _ => None,
    }
}

fn prefix_len(mask: IpAddr) -> u8 {
    match mask {
        IpAddr::V4(m) => u32::from(m).leading_ones() as u8,
        IpAddr::V6(m) => u128::from(m).leading_ones() as u8,
    }
}

#[allow(unsafe_code)]
fn interfaces() -> Result<Vec<Interface>, String> {
    let mut head: *mut libc::ifaddrs = std::ptr::null_mut();
    // SAFETY: getifaddrs writes the head of a list it allocates; freed below.
    if unsafe { libc::getifaddrs(&mut head) } != 0 {
        return Err(os_error());
    }
    let mut out = Vec::new();
    let mut node = head;
    while !node.is_null() {
        // SAFETY: `node` is a node of the list getifaddrs returned, valid
        // until freeifaddrs; its name is a NUL-terminated string and its
        // addresses are null or match their family.
        let ifa = unsafe { &*node };
        if let Some(addr) = unsafe { ip_of(ifa.ifa_addr) } {
            let full = if addr.is_ipv4() { 32 } else { 128 };
            let prefix_len = unsafe { ip_of(ifa.ifa_netmask) }.map_or(full, prefix_len);
            let name = unsafe { CStr::from_ptr(ifa.ifa_name) }.to_string_lossy().into_owned();
            out.push(Interface { name, addr, prefix_len });
        }
        node = ifa.ifa_next;
    }
    // SAFETY: `head` came from getifaddrs and is freed once; no reference into it survives.
    unsafe { libc::freeifaddrs(head) };
    Ok(out)
}

#[allow(unsafe_code)]
fn clock_sync() -> Result<ClockSync, String> {
    // SAFETY: an all-zero timex is valid; modes = 0 asks for a read only,
    // which needs no privilege and changes nothing.
    let mut tx: libc::timex = unsafe { std::mem::zeroed() };
    // SAFETY: `tx` is a valid timex the call fills.
    let state = unsafe { libc::ntp_adjtime(&mut tx) };
    if state < 0 {
        return Err(os_error());
    }
    Ok(ClockSync { synced: state != libc::TIME_ERROR && tx.status & libc::STA_UNSYNC == 0, est_error_us: tx.esterror })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subnets_cover_their_addresses_only() {
        let i = Interface { name: "eth1".into(), addr: "192.168.1.2".parse().unwrap(), prefix_len: 24 };
        assert!(i.covers("192.168.1.147".parse().unwrap()));
        assert!(!i.covers("192.168.2.1".parse().unwrap()));
        assert!(!i.covers("::1".parse().unwrap()));
        let lo = Interface { name: "lo".into(), addr: "127.0.0.1".parse().unwrap(), prefix_len: 8 };
        assert!(lo.covers("127.3.0.1".parse().unwrap()));
        assert_eq!(prefix_len("255.255.255.0".parse().unwrap()), 24);
    }

    #[test]
    fn this_pc_answers_without_root() {
        let h = Host::live();
        // Every PC has a loopback address and readable limits.
        let ifs = h.interfaces.unwrap();
        assert!(ifs.iter().any(|i| i.addr.is_loopback()), "{ifs:?}");
        h.rtprio.unwrap();
        h.memlock.unwrap();
    }
}
